"""Tracker and merger: time per frame beside Hi-ROS, identity and accuracy, norfair alongside.

Three measurements on simulator recordings (``hiros_sim``, 3 Azure Kinects, people walking and
crossing, SDK mistakes on: flips, swaps, ghosts, id changes):

* time per frame of ``Tracker.update`` (one camera frame in) and ``Merger.update`` (one tracker
  output in) for 1, 2, 3 and 4 people, best of a few full runs, printed beside the figures Hi-ROS
  published for its C++ nodes (Guidolin et al., CVIU 2023: tracker 0.19-0.86 ms, merger
  0.55-0.88 ms for 1-4 people; only the end points are quoted here);
* identity and accuracy on 4 people over 60 s for several seeds: IDF1, ID switches and
  fragments of the merged output (distance to the truth), ID switches of the tracker's
  per-detection output (from the simulator's labels), merged MPJPE against the best single
  camera;
* a peer tracker from PyPI, ``norfair`` (Kalman filter + greedy matching, the usual choice for
  a quick multi-object tracker), fed the same world-frame detections in the same order (core
  joints as its points, threshold 0.5 m): its ID switches and time per frame beside ours.
  norfair is given detections already in the world frame; our time includes applying the
  calibration.

Times are CPU seconds of this process (best of a few runs for the per-people table): the
machine may be shared, and other processes' load inflates wall time far more.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hiros_core.model import SkeletonGroup
from hiros_eval.tracking import (
    arrival_order,
    camera_mpjpe,
    detection_labels,
    identity_metrics,
    output_mpjpe,
)
from hiros_merger import Merger, MergerParams
from hiros_tracker import Tracker, TrackerParams
from hiros_tracker.correction import CameraCorrection

__all__ = ["HIROS_MERGER_MS", "HIROS_TRACKER_MS", "run"]

HIROS_TRACKER_MS = {1: 0.19, 4: 0.86}
"""Hi-ROS tracker, ms per frame by number of people (published end points)."""
HIROS_MERGER_MS = {1: 0.55, 4: 0.88}
"""Hi-ROS merger, ms per frame by number of people (published end points)."""

_NORFAIR_JOINTS = ("Pelvis", "SpineNaval", "SpineChest", "Neck", "HipLeft", "HipRight")


@dataclass
class _Accuracy:
    seed: int
    merged_idf1: float
    merged_switches: int
    merged_fragments: int
    coverage: float
    tracks: int
    people: int
    tracker_switches: int
    norfair_switches: int
    norfair_idf1: float
    tracker_idf1: float
    merged_mpjpe: float
    best_camera_mpjpe: float
    tracker_ms: float
    norfair_ms: float


def _simulate(n_people: int, seed: int, duration: float, *, enter_leave: bool = True):  # noqa: ANN202
    from hiros_sim import SimParams, simulate

    return simulate(
        SimParams(
            n_cameras=3, n_people=n_people, duration=duration, seed=seed, enter_leave=enter_leave
        )
    )


def _best_of(repeats: int, work: Callable[[], int]) -> float:
    """CPU seconds per item of ``work`` (which returns how many items it did), best of repeats.

    CPU time of this process, not wall time: on a shared machine other processes' load
    inflates wall time far more than it does the work done here.
    """
    best = float("inf")
    for _ in range(repeats):
        start = time.process_time()
        items = work()
        best = min(best, (time.process_time() - start) / max(items, 1))
    return best


def _time_stages(result: object, repeats: int) -> tuple[float, float]:
    """Seconds per ``Tracker.update`` and per ``Merger.update`` over a whole recording."""
    frames = arrival_order(result.camera_groups, result.calibration)  # type: ignore[attr-defined]
    calibration = result.calibration  # type: ignore[attr-defined]
    tracked: list[SkeletonGroup] = []

    def track() -> int:
        tracker = Tracker(TrackerParams(), calibration)
        tracked[:] = [tracker.update(frame) for frame in frames]
        return len(frames)

    def merge() -> int:
        merger = Merger(MergerParams(), calibration)
        for group in tracked:
            merger.update(group)
        return len(tracked)

    return _best_of(repeats, track), _best_of(repeats, merge)


def _norfair(world_frames: list[SkeletonGroup]) -> tuple[list[SkeletonGroup], float]:
    """Norfair over the world-frame detections: outputs with its ids, seconds per frame."""
    from norfair import Detection
    from norfair import Tracker as NorfairTracker

    tracker = NorfairTracker(
        distance_function="mean_euclidean",
        distance_threshold=0.5,
        hit_counter_max=30,
        initialization_delay=8,
    )
    outputs = []
    start = time.process_time()
    for k, frame in enumerate(world_frames):
        detections = []
        for i, skeleton in enumerate(frame.skeletons):
            core = [skeleton.layout.index(name) for name in _NORFAIR_JOINTS]
            points = skeleton.positions[core]
            if np.isfinite(points).all():
                detections.append(Detection(points=points, data=(k, i)))
        out = []
        for tracked in tracker.update(detections):
            frame_index, index = tracked.last_detection.data
            if frame_index == k:
                skeleton = frame.skeletons[index].copy()
                skeleton.id = int(tracked.id)
                out.append(skeleton)
        outputs.append(SkeletonGroup(frame.stamp_ns, frame.frame_id, out))
    return outputs, (time.process_time() - start) / max(len(world_frames), 1)


def _accuracy(seed: int, duration: float) -> _Accuracy:
    result = _simulate(4, seed, duration)
    frames = arrival_order(result.camera_groups, result.calibration)
    tracker = Tracker(TrackerParams(), result.calibration)
    merger = Merger(MergerParams(), result.calibration)
    start = time.process_time()
    tracked = [tracker.update(frame) for frame in frames]
    tracker_s = (time.process_time() - start) / len(frames)
    tracked.append(tracker.flush())
    merged = [merger.update(group) for group in tracked]

    correction = CameraCorrection(result.calibration)
    world = [g for g in (correction.apply(frame) for frame in frames) if g is not None]
    norfair_out, norfair_s = _norfair(world)

    labels = detection_labels(result.camera_groups, result.labels, result.calibration)
    merged_ids = identity_metrics(merged, result.truth)
    tracker_ids = identity_metrics(tracked, result.truth, labels=labels)
    norfair_ids = identity_metrics(norfair_out, result.truth, labels=labels)
    cameras = camera_mpjpe(result.camera_groups, result.calibration, result.truth)
    return _Accuracy(
        seed=seed,
        merged_idf1=merged_ids.idf1,
        merged_switches=merged_ids.id_switches,
        merged_fragments=merged_ids.fragments,
        coverage=merged_ids.coverage,
        tracks=merged_ids.tracks,
        people=merged_ids.true_people,
        tracker_switches=tracker_ids.id_switches,
        tracker_idf1=tracker_ids.idf1,
        norfair_switches=norfair_ids.id_switches,
        norfair_idf1=norfair_ids.idf1,
        merged_mpjpe=next(iter(output_mpjpe(merged, result.truth).values())),
        best_camera_mpjpe=min(cameras.values()),
        tracker_ms=tracker_s * 1e3,
        norfair_ms=norfair_s * 1e3,
    )


def _quoted(figures: dict[int, float], people: int) -> str:
    """A published figure, or a dash where the paper's end points do not say."""
    return f"{figures[people]:7.2f}" if people in figures else f"{'-':>7s}"


def _ratio(ours: float, theirs: float) -> str:
    return f"{ours / theirs:.2f}" if theirs else ("0 / 0" if not ours else "inf")


def run(console, quick: bool = False) -> list[str]:  # noqa: ANN001 - rich Console
    """Print the three tables and return their lines."""
    duration, repeats = (8.0, 2) if quick else (20.0, 3)
    lines = [
        "time per frame (ms), 3 cameras; Hi-ROS C++ figures as published (1 and 4 people)",
        f"{'people':>6s} {'tracker':>9s} {'Hi-ROS':>7s} {'merger':>9s} {'Hi-ROS':>7s}",
    ]
    for people in (1, 2, 3, 4):
        result = _simulate(people, 0, duration, enter_leave=False)
        tracker_s, merger_s = _time_stages(result, repeats)
        lines.append(
            f"{people:6d} {tracker_s * 1e3:9.3f} {_quoted(HIROS_TRACKER_MS, people)} "
            f"{merger_s * 1e3:9.3f} {_quoted(HIROS_MERGER_MS, people)}"
        )

    seeds = (0,) if quick else (0, 1, 2)
    lines.append("")
    lines.append("identity and accuracy: 3 cameras x 4 people walking and crossing, 60 s per seed")
    lines.append(
        f"{'seed':>4s} {'IDF1':>6s} {'switch':>6s} {'frag':>5s} {'cover':>6s} {'tracks':>6s} "
        f"{'trk sw':>6s} {'nf sw':>6s} {'nf IDF1':>7s} {'MPJPE':>7s} {'best cam':>8s} "
        f"{'ratio':>6s} {'trk ms':>7s} {'nf ms':>6s}"
    )
    rows = []
    for seed in seeds:
        row = _accuracy(seed, 60.0)
        rows.append(row)
        lines.append(
            f"{row.seed:4d} {row.merged_idf1:6.3f} {row.merged_switches:6d} "
            f"{row.merged_fragments:5d} {row.coverage:6.3f} {row.tracks:3d}/{row.people:<2d} "
            f"{row.tracker_switches:6d} {row.norfair_switches:6d} {row.norfair_idf1:7.3f} "
            f"{row.merged_mpjpe:7.4f} {row.best_camera_mpjpe:8.4f} "
            f"{row.merged_mpjpe / row.best_camera_mpjpe:6.3f} {row.tracker_ms:7.3f} "
            f"{row.norfair_ms:6.3f}"
        )
    ours_sw = sum(r.tracker_switches for r in rows)
    peer_sw = sum(r.norfair_switches for r in rows)
    ours_ms = float(np.mean([r.tracker_ms for r in rows]))
    peer_ms = float(np.mean([r.norfair_ms for r in rows]))
    worst = max(r.merged_mpjpe / r.best_camera_mpjpe for r in rows)
    lines.append(
        f"tracking vs norfair: ID switches {ours_sw} vs {peer_sw} "
        f"(ratio {_ratio(ours_sw, peer_sw)}), time per frame {ours_ms:.3f} vs {peer_ms:.3f} ms "
        f"(ratio {_ratio(ours_ms, peer_ms)}); "
        f"merged switches {sum(r.merged_switches for r in rows)}, "
        f"worst MPJPE ratio to the best camera {worst:.3f} (target <= 0.75)"
    )
    for line in lines:
        console.print(line, highlight=False)
    return lines
