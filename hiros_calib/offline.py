"""Calibrate a recording: its camera streams read, its log times judged, the Calibrator run.

What ``hiros calibrate``, ``hiros run --calibration auto`` and ``hiros demo`` do between the
file and the result; they only add a progress bar and print what it returns.
"""

from __future__ import annotations

from pathlib import Path

from hiros_calib.calibrator import CalibrationResult, Calibrator, CalibratorParams, Progress
from hiros_core.calibration import Calibration
from hiros_core.errors import RecordingError
from hiros_core.model import SkeletonGroup
from hiros_core.recording import read_camera_groups, require_camera_topics

__all__ = ["READING", "STAMPS_AS_LOG_TIMES", "calibrate_recording"]

READING = "reading the recording"
"""The stage ``calibrate_recording`` reports first, at 0; the Calibrator's stages follow."""

READ_SHARE = 0.1
"""The part of the work ``progress`` gives the reading; the calibration has the rest."""

STAMPS_AS_LOG_TIMES = (
    "the recording's log times are the frames' own stamps (no receiver clock): "
    "every lag is searched"
)
"""The note of a recording whose every frame was logged at its own stamp."""


def calibrate_recording(
    recording: str | Path,
    params: CalibratorParams | None = None,
    *,
    use_arrival: bool = True,
    progress: Progress | None = None,
    problems: list[str] | None = None,
    known_poses: Calibration | None = None,
) -> CalibrationResult:
    """The calibration of a recording's cameras, with every detail (``result.calibration``).

    Args:
        recording: a rosbag2 folder or an ``.mcap``/``.db3`` file with camera skeleton topics.
        params: the Calibrator's; default ``CalibratorParams()``.
        use_arrival: let the log (arrival) times narrow each clock search. Log times that
            are each frame's own stamp (a file converted without a receiver clock) carry no
            arrival and are ignored either way, with a note in ``result.notes``.
        progress: called with ``(stage, done)``, ``done`` the fraction of the whole work
            from 0 to 1: ``READING`` at 0, then the Calibrator's stages.
        problems: list that receives the reader's sentences on what it could not read (a
            truncated file, a damaged chunk), even when this raises.
        known_poses: an earlier calibration of the same cameras whose poses and world are
            kept; only the clocks are found (see ``Calibrator.calibrate``).

    Raises:
        RecordingError: the recording cannot be read, holds no camera skeleton topic, or
            skeletons of fewer than two cameras.
        CalibrationError: the data cannot determine some camera's clock or pose (the
            message says which and why).

    """
    report = progress or (lambda _stage, _done: None)
    report(READING, 0.0)
    require_camera_topics(recording)
    groups, arrivals = read_camera_groups(recording, problems=problems)
    if len(groups) < 2:
        msg = (
            f"{recording}: calibration needs skeletons of two or more cameras, "
            f"found {sorted(groups)}"
        )
        raise RecordingError(msg)
    stamps = _log_times_are_stamps(groups, arrivals)
    calibrator = Calibrator(params)
    calibrator.calibrate(
        groups,
        progress=lambda stage, done: report(stage, READ_SHARE + (1 - READ_SHARE) * done),
        arrival_ns=arrivals if use_arrival and not stamps else None,
        known_poses=known_poses,
    )
    result = calibrator.result
    assert result is not None  # calibrate() sets it or raises
    if use_arrival and stamps:
        result.notes.insert(0, STAMPS_AS_LOG_TIMES)
    return result


def _log_times_are_stamps(
    groups: dict[str, list[SkeletonGroup]], arrivals: dict[str, list[int]]
) -> bool:
    """True when every frame was logged at exactly its own stamp: no arrival information."""
    return all(
        all(log == group.stamp_ns for group, log in zip(groups[c], arrivals[c], strict=True))
        for c in groups
    )
