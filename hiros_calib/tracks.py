"""Per-camera body tracks: one body's joint positions over time, as arrays.

Calibration works on whole time series, not on single frames, so the per-frame
``SkeletonGroup`` lists are regrouped into :class:`BodyTrack` objects: for one camera and
one SDK body id, the camera-clock times ``(T,)``, joint positions ``(T, J, 3)`` and joint
weights ``(T, J)``. A track ends where the body id disappears for longer than ``max_gap``
(SDKs reuse ids for new people), so a track is one person as far as the camera can tell.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from hiros_core.layouts import Layout
from hiros_core.model import SkeletonGroup

__all__ = ["BodyTrack", "extract_tracks", "joint_weights"]


@dataclass
class BodyTrack:
    """One body seen by one camera.

    Attributes:
        camera: camera name.
        body_id: the SDK body id of the skeletons.
        layout: joint layout of the skeletons.
        times: ``(T,)`` camera-clock seconds, strictly increasing.
        positions: ``(T, J, 3)`` joint positions in the camera frame (m), NaN when absent.
        weights: ``(T, J)`` joint reliability in 0..1 (0 where absent or not trusted).

    """

    camera: str
    body_id: int
    layout: Layout
    times: np.ndarray
    positions: np.ndarray
    weights: np.ndarray

    @property
    def duration(self) -> float:
        """Seconds between the first and last frame."""
        return float(self.times[-1] - self.times[0]) if len(self.times) else 0.0

    @property
    def start(self) -> float:
        """First camera-clock time (s)."""
        return float(self.times[0])

    @property
    def end(self) -> float:
        """Last camera-clock time (s)."""
        return float(self.times[-1])

    def window(self, start: float, end: float) -> BodyTrack | None:
        """The part of the track with ``start <= t < end``, or None when it is empty."""
        keep = (self.times >= start) & (self.times < end)
        if keep.sum() < 2:
            return None
        return BodyTrack(
            self.camera,
            self.body_id,
            self.layout,
            self.times[keep],
            self.positions[keep],
            self.weights[keep],
        )

    def at(self, times: np.ndarray, max_gap: float) -> tuple[np.ndarray, np.ndarray]:
        """Positions ``(N, J, 3)`` and weights ``(N, J)`` linearly interpolated at ``times``.

        An instant outside the track, or between frames further apart than ``max_gap`` (s),
        gets weight 0 (its position is the nearest frames' blend, not to be used).
        """
        t = self.times
        idx = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
        gap = t[idx + 1] - t[idx]
        frac = (times - t[idx]) / gap
        inside = (times >= t[0]) & (times <= t[-1]) & (gap <= max_gap)
        frac = np.clip(frac, 0.0, 1.0)[:, None, None]
        positions = self.positions[idx] * (1 - frac) + self.positions[idx + 1] * frac
        weights = np.minimum(self.weights[idx], self.weights[idx + 1])
        weights = np.where(inside[:, None] & np.isfinite(positions).all(axis=2), weights, 0.0)
        return positions, weights


def joint_weights(
    confidences: np.ndarray, present: np.ndarray, min_confidence: float
) -> np.ndarray:
    """Joint reliability in 0..1 from driver confidences.

    Drivers differ in scale (Azure Kinect reports levels 0..3, others 0..1, Kinect v2 files
    none), so confidences are divided by the largest one seen; unknown confidences (NaN)
    count as fully reliable, and joints below ``min_confidence`` of that scale get weight 0,
    which leaves out the joints a camera sees badly.
    """
    conf = np.where(np.isfinite(confidences), confidences, np.nan)
    finite = conf[np.isfinite(conf)]
    scale = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
    weights = np.where(np.isfinite(conf), conf / scale, 1.0)
    weights = np.where(present & (weights >= min_confidence), weights, 0.0)
    return np.clip(weights, 0.0, 1.0)


def extract_tracks(
    groups: Iterable[SkeletonGroup],
    camera: str,
    *,
    max_gap: float = 0.25,
    min_frames: int = 10,
    min_confidence: float = 0.5,
    drops: Counter[str] | None = None,
) -> list[BodyTrack]:
    """Regroup one camera's frames into body tracks.

    Args:
        groups: the camera's SkeletonGroups (camera frame, camera clock), any order.
        camera: the camera's name, stored on the tracks.
        max_gap: a body id absent for longer than this (s) starts a new track.
        min_frames: shorter tracks are dropped (``short_track``).
        min_confidence: joints below this fraction of the confidence scale get weight 0.
        drops: counter of dropped inputs by reason.

    Returns:
        Tracks sorted by start time. Skeletons of another layout than the first one, repeated
        stamps and skeletons without any joint are dropped with a counted reason.

    """
    drops = drops if drops is not None else Counter()
    # per body id: stamps, marker rows (J, 20) and presence masks, stacked once per body
    samples: dict[int, tuple[list[int], list[np.ndarray], list[np.ndarray]]] = {}
    layout: Layout | None = None
    for group in groups:
        for skeleton in group.skeletons:
            if layout is None:
                layout = skeleton.layout
            if skeleton.layout.n_joints != layout.n_joints:
                drops["other_layout"] += 1
                continue
            stamp_ns = skeleton.src_time_ns if skeleton.src_time_ns > 0 else group.stamp_ns
            body = samples.get(skeleton.id)
            if body is None:
                body = samples[skeleton.id] = ([], [], [])
            body[0].append(stamp_ns)
            body[1].append(skeleton.markers)
            body[2].append(skeleton.marker_present)
    if layout is None:
        return []
    tracks: list[BodyTrack] = []
    for body_id, (stamps, marker_rows, present_rows) in samples.items():
        markers, present = np.stack(marker_rows), np.stack(present_rows)
        some = present.any(axis=1)
        drops["no_joints"] += int((~some).sum())
        if not some.any():
            continue
        times = np.array(stamps, dtype=np.int64)[some] * 1e-9
        markers, present = markers[some], present[some]
        order = np.argsort(times, kind="stable")
        times, markers, present = times[order], markers[order], present[order]
        positions, confidences = markers[..., 1:4], markers[..., 0]
        present = present & np.isfinite(positions).all(axis=2)
        repeated = np.concatenate([[False], np.diff(times) <= 0])
        drops["repeated_stamp"] += int(repeated.sum())
        keep = ~repeated
        times, positions, confidences, present = (
            times[keep],
            positions[keep],
            confidences[keep],
            present[keep],
        )
        weights = joint_weights(confidences, present, min_confidence)
        positions = np.where(present[..., None], positions, np.nan)
        breaks = np.flatnonzero(np.diff(times) > max_gap) + 1
        for idx in np.split(np.arange(len(times)), breaks):
            if len(idx) < min_frames:
                drops["short_track"] += 1
                continue
            tracks.append(
                BodyTrack(camera, int(body_id), layout, times[idx], positions[idx], weights[idx])
            )
    tracks.sort(key=lambda t: t.start)
    return tracks
