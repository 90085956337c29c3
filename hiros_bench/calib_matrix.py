"""The calibration's robustness matrix: one row per simulator condition, default settings.

Each row is a ``hiros_sim`` preset (log times in each camera's host clock, repeated
Bandai-Namco motion, one person, two cameras 45° apart, a noisier SDK, 15 Hz, 5 % drops, one
person exercising on one spot before the pair, the same timed with the poses of a walk
before the same cameras, then all of them together, and that timed with a walk's poses too)
simulated over
several seeds and calibrated by ``Calibrator`` with its default parameters and the
recording's own log times, as ``hiros calibrate`` would.

Every run ends one of three ways: **calibrated** (no camera flagged), **flagged** (written,
but some camera marked doubtful), or **refused** (an error saying why). A camera whose result
is off by more than 50 ms, 2° or 10 cm is *wrong*; wrong and not flagged is **silently
wrong**, the one outcome that must never happen. Success is a calibrated run with no wrong
camera. Errors (median and 95th percentile over the non-reference cameras of successful runs)
are relative to the reference camera: time (ms, mean absolute over the recording),
rotation (deg), translation (cm).

Real data: the four KinectMultiTrack sessions (two Kinect v2 on independent device clocks, the
recorder's server clock as log times; ``../shared/data``) have no truth; their offsets are
printed with the difference from the values main gave before the calibration was made to hold
on other data (``KINECT_MULTITRACK_BEFORE``).
"""

from __future__ import annotations

import copy
import tempfile
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hiros_bench.seeds import seeds_text
from hiros_calib.calibrator import Calibrator, CalibratorParams
from hiros_calib.lags import REPEATS_EXACTLY
from hiros_calib.quality import ON_ONE_SPOT
from hiros_core.calibration import Calibration, save_calibration
from hiros_core.errors import CalibrationError, ConfigError, RecordingError
from hiros_eval.calibration import compare_calibration
from hiros_sim import simulate
from hiros_sim.presets import PRESETS, preset_params

__all__ = ["MATRIX_ROWS", "WRONG", "run"]

MATRIX_ROWS = (
    "default",
    "host-clocks",
    "repeated-motion",
    "one-person",
    "two-cameras-45",
    "noisy-sdk",
    "15hz",
    "drops-5",
    "crossing-host",
    "walk-pair-host",
    "exercise-on-spot",
    "exercise+walk",
    "all",
    "all+walk",
)
"""The rows of the matrix, in order: ``hiros_sim.presets`` and ``KNOWN_POSES_ROWS``."""

KNOWN_POSES_ROWS = {
    "exercise+walk": (
        "exercise-on-spot",
        "two-cameras-45",
        "exercise-on-spot timed with the poses of a walk (two-cameras-45 motion) before the "
        "same cameras, calibrated first (hiros calibrate --poses-from)",
    ),
    "all+walk": ("all", "two-cameras-45", "all, timed with the poses of a walk likewise"),
}
"""Rows whose take (first preset) is calibrated with the poses of another recording before the
same cameras (second preset), itself calibrated first: per row the two presets and what the
row is."""

WALK_SEED_OFFSET = 1000
"""The walk of a ``KNOWN_POSES_ROWS`` run is simulated with the take's seed plus this, so that
its clocks and people are drawn apart from the take's."""

UNDECIDABLE = "the lag is ambiguous"
"""How a refusal begins when neither the motion nor the skeletons single out one lag."""

WRONG = (50.0, 2.0, 10.0)
"""A camera off by more than this time (ms), rotation (deg) or translation (cm) is wrong."""

KINECT_MULTITRACK_BEFORE = {
    "Study_10_Kinect_1_Time_4_10_14_PM.csv": -33658.17772,
    "Study_10_Kinect_2_Time_4_14_06_PM.csv": -33658.13241,
    "Study_21_Kinect_1_Time_2_09_50_PM.csv": -223551.19581,
    "Study_24_Kinect_1_Time_2_49_46_PM.csv": -223551.12023,
}
"""Offsets (s) main (306de27) gave for the second camera of each session."""


@dataclass
class _Row:
    """What the runs of one condition gave."""

    runs: int = 0
    calibrated: int = 0
    flagged: int = 0
    refused: int = 0
    undecidable: int = 0
    silently_wrong: int = 0
    wrong_flagged: int = 0
    time_ms: list[float] = field(default_factory=list)
    rotation_deg: list[float] = field(default_factory=list)
    translation_cm: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    reasons: Counter[str] = field(default_factory=Counter)

    @property
    def success(self) -> int:
        return self.calibrated


def _wrong(time_ms: float, rotation_deg: float, translation_cm: float) -> bool:
    values = (time_ms, rotation_deg, translation_cm)
    return any(not (v <= limit) for v, limit in zip(values, WRONG, strict=True))


def _short(reason: str) -> str:
    """A refusal or flag reason without its numbers, to count alike reasons together."""
    head = reason.split(": ", 2)[-1]
    for marker in (" (", ", so lags", " by "):
        head = head.split(marker)[0]
    return head[:70]


def _known_poses(walk_preset: str, truth: Calibration, seed: int, duration: float) -> Calibration:
    """The calibration of a walk simulated before the cameras of ``truth`` (its clocks apart).

    Raises:
        CalibrationError: the walk cannot be calibrated.

    """
    cameras = copy.deepcopy(truth)
    for camera in cameras.cameras.values():
        camera.time_offset, camera.drift = 0.0, 0.0  # the walk draws clocks of its own
    with tempfile.TemporaryDirectory() as folder:
        setup = Path(folder) / "cameras.yaml"
        save_calibration(cameras, setup)
        walk = simulate(preset_params(walk_preset, seed=seed, duration=duration, setup=str(setup)))
    return Calibrator(CalibratorParams(reference="k01")).calibrate(
        walk.camera_groups, arrival_ns=walk.receive_ns
    )


def one_run(name: str, seed: int, duration: float, row: _Row) -> None:
    """Simulate one seed of row ``name``, calibrate it with the defaults, judge the result."""
    preset, walk_preset, _ = KNOWN_POSES_ROWS.get(name, (name, None, ""))
    result = simulate(preset_params(preset, seed=seed, duration=duration))
    truth = result.calibration
    calibrator = Calibrator(CalibratorParams(reference="k01"))
    row.runs += 1
    known = None
    try:
        if walk_preset is not None:
            known = _known_poses(walk_preset, truth, seed + WALK_SEED_OFFSET, duration)
    except CalibrationError as exc:
        row.refused += 1
        row.reasons[f"refused (the walk): {_short(str(exc))}"] += 1
        return
    started = time.perf_counter()
    try:
        estimate = calibrator.calibrate(
            result.camera_groups, arrival_ns=result.receive_ns, known_poses=known
        )
    except CalibrationError as exc:
        row.refused += 1
        row.undecidable += UNDECIDABLE in str(exc)
        row.reasons[f"refused: {_short(str(exc))}"] += 1
        return
    finally:
        row.seconds.append(time.perf_counter() - started)
    times = {c: np.array([g.stamp for g in gs])[::15] for c, gs in result.camera_groups.items()}
    accuracy = compare_calibration(estimate, truth, times)
    flagged = estimate.flagged
    for why in flagged.values():
        row.reasons[f"flagged: {_short(why)}"] += 1
    wrong = {
        camera: _wrong(acc.time_error_ms, acc.rotation_error_deg, acc.translation_error_cm)
        for camera, acc in accuracy.items()
    }
    row.silently_wrong += sum(w and camera not in flagged for camera, w in wrong.items())
    row.wrong_flagged += sum(w and camera in flagged for camera, w in wrong.items())
    if flagged:
        row.flagged += 1
        row.undecidable += any(
            marker in why for why in flagged.values() for marker in (ON_ONE_SPOT, REPEATS_EXACTLY)
        )
        return
    if any(wrong.values()):
        return
    row.calibrated += 1
    for acc in accuracy.values():
        row.time_ms.append(acc.time_error_ms)
        row.rotation_deg.append(acc.rotation_error_deg)
        row.translation_cm.append(acc.translation_error_cm)


def _stats(values: list[float]) -> str:
    if not values:
        return "-"
    return f"{np.median(values):.2f}/{np.percentile(values, 95):.2f}"


def _row_line(name: str, row: _Row) -> str:
    share = 100.0 * row.success / max(row.runs, 1)
    decidable = row.runs - row.undecidable
    decided = f"{100.0 * row.success / decidable:5.0f}%" if decidable else "    -"
    return (
        f"{name:<16s} {row.runs:5d} {share:5.0f}% {row.undecidable:6d} {decided} "
        f"{row.refused:4d} {row.flagged:4d} "
        f"{row.silently_wrong:6d} {_stats(row.time_ms):>12s} {_stats(row.rotation_deg):>11s} "
        f"{_stats(row.translation_cm):>11s} {np.median(row.seconds):6.1f}"
    )


def _kinect_multitrack_lines(console) -> list[str]:  # noqa: ANN001 - rich Console
    """The real sessions' offsets, beside main's before this matrix existed."""
    import tempfile

    from hiros_calib.offline import calibrate_recording
    from hiros_convert import convert

    folder = Path(__file__).resolve().parents[2] / "shared" / "data" / "kinect_multitrack"
    if not folder.exists():
        return [f"KinectMultiTrack sessions: {folder} is not available"]
    lines = ["KinectMultiTrack (real, two Kinect v2, server clock as log times): offset of the "
             "second camera, and its change from main before"]  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        for name, before in KINECT_MULTITRACK_BEFORE.items():
            with console.status(f"bench calib matrix: {name}"):
                recording = Path(tmp) / f"{Path(name).stem}.mcap"
                convert(folder / name, recording, skeleton_groups=True)
                try:  # as hiros calibrate does
                    estimate = calibrate_recording(recording).calibration
                except (CalibrationError, RecordingError) as exc:
                    lines.append(f"  {name}: refused: {exc}")
                    continue
            other = next(c for c in estimate.cameras if c != estimate.reference)
            cam = estimate.cameras[other]
            change = 1e3 * (cam.time_offset - before)
            lines.append(
                f"  {name}: {cam.time_offset:+.4f} s ({change:+.1f} ms from before)"
                + (f", FLAGGED: {cam.flagged}" if cam.flagged else "")
            )
    return lines


def run(
    console,  # noqa: ANN001 - rich Console
    *,
    quick: bool = False,
    seeds: Sequence[int] | None = None,
    duration: float | None = None,
    rows: Sequence[str] = MATRIX_ROWS,
) -> list[str]:
    """Run every row over the seeds; print the matrix and return its lines."""
    seeds = tuple(seeds) if seeds is not None else tuple(range(3 if quick else 10))
    duration = duration or (30.0 if quick else 60.0)
    lines = [
        f"calibration robustness matrix: default settings, {duration:.0f} s, seeds "
        f"{seeds_text(seeds)}; wrong = off by > {WRONG[0]:.0f} ms, {WRONG[1]:.0f} deg or "
        f"{WRONG[2]:.0f} cm; errors of successful runs, median/p95",
        f"{'condition':<16s} {'runs':>5s} {'succ.':>6s} {'undec.':>6s} {'of dec.':>6s} "
        f"{'ref.':>4s} {'flag':>4s} "
        f"{'silent':>6s} {'time ms':>12s} {'rot deg':>11s} {'transl cm':>11s} {'s/run':>6s}",
    ]
    notes = []
    for name in rows:
        row = _Row()
        try:
            for seed in seeds:
                with console.status(f"bench calib matrix: {name}, seed {seed}"):
                    one_run(name, seed, duration, row)
        except ConfigError as exc:  # a preset whose clips are not on this machine
            lines.append(f"{name:<16s} skipped: {exc}")
            continue
        lines.append(_row_line(name, row))
        notes.extend(f"  {name}: {count}x {reason}" for reason, count in row.reasons.most_common(3))
    lines.append(
        "undec. = refused because neither the motion nor the skeletons single out one lag "
        "(motion repeated over the whole recording, no usable log times), or flagged because "
        "the people stayed on one spot (nothing pins the rotation down against the body "
        "tracker's own errors) or a lag other body pairs support fits as well (the motion may "
        "repeat exactly): the data cannot decide; of dec. = success among the other runs"
    )
    lines.append("refusals and flags (most common per row):")
    lines.extend(notes or ["  none"])
    described = [
        f"{r} = {KNOWN_POSES_ROWS[r][2] if r in KNOWN_POSES_ROWS else PRESETS[r].description}"
        for r in rows
    ]
    lines.append(f"conditions: {', '.join(described)}")
    lines.extend(_kinect_multitrack_lines(console))
    for line in lines:
        console.print(line, highlight=False)
    return lines
