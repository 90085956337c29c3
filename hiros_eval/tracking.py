"""Identity and accuracy figures of the tracker and the merger against the truth.

Identity (Ristani et al., "Performance measures and a data set for multi-target,
multi-camera tracking", ECCV 2016 workshops, for IDF1; CLEAR MOT, Bernardin & Stiefelhagen 2008,
for switches and fragments): the output is cut into *frames*, one per (source frame, stamp), so
that the tracker's output (one skeleton per camera detection) is scored per camera and the
merger's (one skeleton per person) per output instant. In each frame a hypothesis (an output
skeleton with its id) and a true person correspond when their root joints (pelvis) are closer
than ``threshold`` (who a skeleton is follows from where the body is, not from its limbs).

* IDF1 = 2 IDTP / (2 IDTP + IDFP + IDFN), with IDTP from the one-to-one mapping of track ids to
  people that maximises the frames they correspond in (Hungarian on the frame counts).
* ID switches: a person matched (per frame, previous matches kept while valid) to a different
  track id than at their previous match in the same source.
* Fragments: a person's match in a source interrupted and resumed.
* Coverage: the share of (frame, present person) pairs matched. For the tracker's per-camera
  frames this counts people a camera cannot see as unmatched; it is meant for merged output.

MPJPE uses ``hiros_eval.body.mpjpe`` on each output skeleton against the person it matched,
the truth interpolated to the skeleton's ``src_time``.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.optimize import linear_sum_assignment

from hiros_core.calibration import Calibration
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_eval.body import mpjpe
from hiros_tracker.correction import CameraCorrection

__all__ = [
    "DetectionLabels",
    "IdentityMetrics",
    "MirroredOutput",
    "TruthLike",
    "arrival_order",
    "camera_mpjpe",
    "detection_labels",
    "identity_metrics",
    "match_to_truth",
    "mirrored_output",
    "mirrored_share",
    "output_mpjpe",
]


class TruthLike(Protocol):
    """What the figures need of the truth (``hiros_sim.Truth`` fits)."""

    times: np.ndarray
    positions: np.ndarray

    def at(self, times: np.ndarray) -> np.ndarray:
        """``(P, N, J, 3)`` positions at reference times ``(N,)``."""
        ...


@dataclass
class IdentityMetrics:
    """Identity figures of one output stream (see the module docstring)."""

    idf1: float
    idp: float
    idr: float
    id_switches: int
    fragments: int
    coverage: float
    true_people: int
    tracks: int
    frames: int
    ids_per_person: dict[int, list[int]] = field(default_factory=dict)
    """Per true person, the track ids matched to them, most frequent first."""

    def summary(self) -> str:
        """One line for a report."""
        ids = max((len(v) for v in self.ids_per_person.values()), default=0)
        return (
            f"IDF1 {self.idf1:.3f} (IDP {self.idp:.3f}, IDR {self.idr:.3f}), "
            f"ID switches {self.id_switches}, fragments {self.fragments}, "
            f"coverage {self.coverage:.3f}, {self.tracks} tracks for {self.true_people} people "
            f"(at most {ids} ids per person)"
        )


@dataclass
class _Frame:
    source: str
    stamp_ns: int
    ids: np.ndarray  # (H,)
    positions: np.ndarray  # (H, J, 3)
    refs: list[tuple[int, int]]  # (group index, skeleton index) of each hypothesis
    root: int  # root joint of the layout


def _frames(groups: Sequence[SkeletonGroup]) -> list[_Frame]:
    """Output skeletons cut into frames by (src_frame, src_time), in time order."""
    cut: dict[tuple[str, int], list[tuple[int, int]]] = defaultdict(list)
    for g, group in enumerate(groups):
        for s, skeleton in enumerate(group.skeletons):
            cut[skeleton.src_frame, skeleton.src_time_ns].append((g, s))
    frames = []
    for (source, stamp), refs in sorted(cut.items(), key=lambda item: item[0][1]):
        skeletons = [groups[g].skeletons[s] for g, s in refs]
        positions = np.stack(
            [np.where(s.marker_present[:, None], s.positions, np.nan) for s in skeletons]
        )
        ids = np.array([s.id for s in skeletons], dtype=np.int64)
        root = skeletons[0].layout.parents.index(-1)
        frames.append(_Frame(source, stamp, ids, positions, refs, root))
    return frames


def _distances(truth: np.ndarray, hypotheses: np.ndarray, root: int) -> np.ndarray:
    """``(G, H)`` distance of the root joints, else mean joint distance; inf if nothing shared.

    Who a skeleton is follows from where its body is: the root (pelvis) distance does not
    change when a camera's front/back flip throws the limbs a metre off.
    """
    distance = np.linalg.norm(truth[:, None] - hypotheses[None], axis=3)
    finite = np.isfinite(distance)
    count = finite.sum(axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(finite, distance, 0.0).sum(axis=2) / count
    mean[count == 0] = np.inf
    return np.where(finite[..., root], distance[..., root], mean)


def _truth_at(truth: TruthLike, frames: list[_Frame]) -> np.ndarray:
    """``(N, P, J, 3)`` truth at each frame's stamp."""
    if not frames:
        p, _, j, _ = truth.positions.shape
        return np.empty((0, p, j, 3))
    times = np.array([f.stamp_ns for f in frames], dtype=np.float64) * 1e-9
    return np.moveaxis(truth.at(times), 1, 0)


def match_to_truth(
    groups: Sequence[SkeletonGroup], truth: TruthLike, *, threshold: float = 0.5
) -> tuple[list[_Frame], np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Per-frame correspondence of output skeletons and true people (CLEAR MOT style).

    Returns:
        the frames, the truth at them ``(N, P, J, 3)``, per frame the matched person of each
        hypothesis ``(H,)`` (-1 = none) and per frame the mean joint distances ``(P, H)``.

    """
    frames = _frames(groups)
    at = _truth_at(truth, frames)
    previous: dict[tuple[str, int], int] = {}
    matches, distances = [], []
    for frame, people in zip(frames, at, strict=True):
        distance = _distances(people, frame.positions, frame.root)
        valid = distance < threshold
        match = np.full(len(frame.ids), -1, dtype=np.int64)
        taken_people: set[int] = set()
        # CLEAR MOT: a correspondence of the previous match stays while it is valid.
        for h, track_id in enumerate(frame.ids):
            for p in range(len(people)):
                if previous.get((frame.source, p)) == track_id and valid[p, h]:
                    if p not in taken_people:
                        match[h] = p
                        taken_people.add(p)
                    break
        rows = [p for p in range(len(people)) if p not in taken_people]
        cols = [h for h in range(len(frame.ids)) if match[h] < 0]
        if rows and cols:
            sub = distance[np.ix_(rows, cols)]
            r, c = linear_sum_assignment(np.where(np.isfinite(sub), sub, 1e9))
            for i, j in zip(r, c, strict=True):
                if valid[rows[i], cols[j]]:
                    match[cols[j]] = rows[i]
        for h, p in enumerate(match):
            if p >= 0:
                previous[frame.source, int(p)] = int(frame.ids[h])
        matches.append(match)
        distances.append(distance)
    return frames, at, matches, distances


@dataclass
class _Scored:
    """One frame's correspondences, whichever way they were found."""

    source: str
    stamp_ns: int
    ids: np.ndarray  # (H,) track ids
    present: np.ndarray  # (P,) people that should be in the frame
    match: np.ndarray  # (H,) person of each hypothesis, -1 for none
    close: np.ndarray  # (P, H) pairs that may correspond (IDF1)


DetectionLabels = dict[tuple[str, int], tuple[np.ndarray, np.ndarray]]
"""(camera frame, corrected stamp) -> centroids ``(N, 3)`` and true persons ``(N,)`` (-1 ghost)."""


def detection_labels(
    camera_groups: dict[str, list[SkeletonGroup]],
    labels: dict[str, list[np.ndarray]],
    calibration: Calibration,
) -> DetectionLabels:
    """The simulator's truth of which person each camera detection is, keyed for the tracker.

    A tracker output is found again by its camera frame, corrected stamp and joint centroid
    (which relabelling the sides does not change).
    """
    correction = CameraCorrection(calibration)
    out: DetectionLabels = {}
    for name, groups in camera_groups.items():
        for group, persons in zip(groups, labels[name], strict=True):
            moved = correction.apply(group)
            if moved is None or not moved.skeletons:
                continue
            key = (moved.skeletons[0].src_frame, moved.skeletons[0].src_time_ns)
            out[key] = (np.stack([_centroid(s) for s in moved.skeletons]), persons)
    return out


def _centroid(skeleton: Skeleton) -> np.ndarray:
    positions = skeleton.positions[skeleton.marker_present]
    return positions.mean(axis=0) if len(positions) else np.full(3, np.nan)


def _scored_by_distance(
    groups: Sequence[SkeletonGroup], truth: TruthLike, threshold: float
) -> list[_Scored]:
    frames, at, matches, distances = match_to_truth(groups, truth, threshold=threshold)
    return [
        _Scored(
            f.source,
            f.stamp_ns,
            f.ids,
            np.isfinite(people).all(axis=2).any(axis=1),
            m,
            d < threshold,
        )
        for f, people, m, d in zip(frames, at, matches, distances, strict=True)
    ]


def _scored_by_label(
    groups: Sequence[SkeletonGroup], labels: DetectionLabels, n_people: int
) -> list[_Scored]:
    outputs: dict[tuple[str, int], list[Skeleton]] = defaultdict(list)
    for group in groups:
        for skeleton in group.skeletons:
            outputs[skeleton.src_frame, skeleton.src_time_ns].append(skeleton)
    scored = []
    for key in sorted(set(labels) | set(outputs), key=lambda k: k[1]):
        centroids, persons = labels.get(key, (np.empty((0, 3)), np.empty(0, dtype=np.int64)))
        present = np.zeros(n_people, dtype=bool)
        present[persons[persons >= 0]] = True
        skeletons = outputs.get(key, [])
        match = np.full(len(skeletons), -1, dtype=np.int64)
        for h, skeleton in enumerate(skeletons):
            if len(centroids):
                gap = np.linalg.norm(centroids - _centroid(skeleton), axis=1)
                nearest = int(np.nanargmin(gap)) if np.isfinite(gap).any() else -1
                if nearest >= 0 and gap[nearest] < 1e-6:
                    match[h] = persons[nearest]
        close = np.zeros((n_people, len(skeletons)), dtype=bool)
        hit = match >= 0
        close[match[hit], np.flatnonzero(hit)] = True
        ids = np.array([s.id for s in skeletons], dtype=np.int64)
        scored.append(_Scored(key[0], key[1], ids, present, match, close))
    return scored


def identity_metrics(
    groups: Sequence[SkeletonGroup],
    truth: TruthLike,
    *,
    threshold: float = 0.5,
    labels: DetectionLabels | None = None,
) -> IdentityMetrics:
    """IDF1, switches, fragments and coverage of an output stream (see the module docstring).

    With ``labels`` (the tracker's output only, see ``detection_labels``) each detection's
    person is known rather than guessed from distances, and the people a camera frame should
    hold are those the camera detected.
    """
    n_people = truth.positions.shape[0]
    if labels is None:
        scored = _scored_by_distance(groups, truth, threshold)
    else:
        scored = _scored_by_label(groups, labels, n_people)
    track_ids = sorted({int(i) for f in scored for i in f.ids})
    column = {track_id: k for k, track_id in enumerate(track_ids)}
    together = np.zeros((n_people, len(track_ids)))
    gt_total = hyp_total = matched_total = switches = fragments = 0
    last_id: dict[tuple[str, int], int] = {}
    state: dict[tuple[str, int], str] = {}
    ids_count: dict[int, dict[int, int]] = defaultdict(lambda: defaultdict(int))
    for frame in scored:
        gt_total += int(frame.present.sum())
        hyp_total += len(frame.ids)
        cols = [column[int(i)] for i in frame.ids]
        for p in np.flatnonzero(frame.present):
            together[p, cols] += frame.close[p]
        matched_people = {int(p): int(frame.ids[h]) for h, p in enumerate(frame.match) if p >= 0}
        matched_total += sum(frame.present[p] for p in matched_people)
        for p in np.flatnonzero(frame.present):
            key = (frame.source, int(p))
            if int(p) in matched_people:
                track_id = matched_people[int(p)]
                ids_count[int(p)][track_id] += 1
                if key in last_id and last_id[key] != track_id:
                    switches += 1
                if state.get(key) == "lost":
                    fragments += 1
                last_id[key] = track_id
                state[key] = "tracked"
            elif key in state:
                state[key] = "lost"
    idtp = 0.0
    if together.size:
        rows, cols = linear_sum_assignment(-together)
        idtp = float(together[rows, cols].sum())
    idfp, idfn = hyp_total - idtp, gt_total - idtp
    present_people = int(np.isfinite(truth.positions).all(axis=3).any(axis=(1, 2)).sum())
    return IdentityMetrics(
        idf1=2 * idtp / max(2 * idtp + idfp + idfn, 1.0),
        idp=idtp / max(hyp_total, 1),
        idr=idtp / max(gt_total, 1),
        id_switches=switches,
        fragments=fragments,
        coverage=matched_total / max(gt_total, 1),
        true_people=present_people,
        tracks=len(track_ids),
        frames=len(scored),
        ids_per_person={
            p: [i for i, _ in sorted(counts.items(), key=lambda kv: -kv[1])]
            for p, counts in sorted(ids_count.items())
        },
    )


def _matched_by_source(
    groups: Sequence[SkeletonGroup], truth: TruthLike, threshold: float
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Source frame -> matched output skeletons ``(N, J, 3)`` and their people's truth."""
    frames, at, matches, _ = match_to_truth(groups, truth, threshold=threshold)
    estimates: dict[str, list[np.ndarray]] = defaultdict(list)
    targets: dict[str, list[np.ndarray]] = defaultdict(list)
    for frame, people, match in zip(frames, at, matches, strict=True):
        for h, p in enumerate(match):
            if p >= 0:
                estimates[frame.source].append(frame.positions[h])
                targets[frame.source].append(people[p])
    return {
        source: (np.stack(estimates[source]), np.stack(targets[source]))
        for source in sorted(estimates)
    }


def _mirror_of(groups: Sequence[SkeletonGroup]) -> np.ndarray:
    """The left/right permutation of the groups' layout, from their first skeleton anywhere.

    Not from the first group's: a camera's first frames may see no one.
    """
    return next(s.layout.mirror for group in groups for s in group.skeletons)


def _mirrored(estimate: np.ndarray, target: np.ndarray, mirror: np.ndarray) -> np.ndarray:
    """``(N,)`` whether each skeleton with left and right swapped is closer to its truth."""
    with np.errstate(invalid="ignore"):
        as_labelled = np.nanmean(np.linalg.norm(estimate - target, axis=-1), axis=1)
        swapped = np.nanmean(np.linalg.norm(estimate[:, mirror] - target, axis=-1), axis=1)
    return swapped < as_labelled


def output_mpjpe(
    groups: Sequence[SkeletonGroup],
    truth: TruthLike,
    *,
    threshold: float = 0.5,
    oracle_sides: bool = False,
) -> dict[str, float]:
    """MPJPE (m) of matched output skeletons against their person, per source frame.

    Use it on the merger's output (one source: the world frame) or the tracker's (one entry per
    camera). ``oracle_sides`` scores each skeleton with its left and right labels as given or
    swapped, whichever fits its person better: the side mistakes an oracle would undo, so that
    only the skeleton's noise and bias remain.
    """
    out = {}
    for source, (labelled, target) in _matched_by_source(groups, truth, threshold).items():
        estimate = labelled
        if oracle_sides:
            mirror = _mirror_of(groups)
            swap = _mirrored(labelled, target, mirror)
            estimate = np.where(swap[:, None, None], labelled[:, mirror], labelled)
        out[source] = mpjpe(estimate, target)[0]
    return out


@dataclass
class MirroredOutput:
    """Which matched output skeletons are mirrored (left for right), per source and person.

    A skeleton is mirrored when swapping all its left and right joints brings it closer to its
    person's truth (:func:`mirrored_output`).
    """

    series: dict[tuple[str, int], tuple[np.ndarray, np.ndarray]]
    """``(source, person)`` -> ``(N,)`` stamps (ns, in time order) and whether each is mirrored."""

    @property
    def share(self) -> float:
        """Share of the matched skeletons that are mirrored; NaN when nothing is matched."""
        flags = [flags for _, flags in self.series.values()]
        return float(np.concatenate(flags).mean()) if flags else float("nan")

    @property
    def longest_run_s(self) -> float:
        """Seconds of the longest unbroken run of one person's mirrored skeletons.

        A run is consecutive mirrored skeletons of the person (per source), and it lasts as
        many frame intervals (the person's median) as it has skeletons, so one mirrored frame at
        30 Hz counts 0.033 s, and a person out of every view between two mirrored skeletons
        does not count as reported the wrong way round meanwhile. A flicker of a frame or two
        is what a downstream consumer smooths away; a run of seconds is a person reported the
        wrong way round. 0 when nothing is mirrored, NaN when nothing is matched.
        """
        if not self.series:
            return float("nan")
        return max(_longest_run(stamps, flags) for stamps, flags in self.series.values())


def mirrored_output(
    groups: Sequence[SkeletonGroup], truth: TruthLike, *, threshold: float = 0.5
) -> MirroredOutput:
    """Each matched output skeleton judged mirrored or not, in time order per person."""
    frames, at, matches, _ = match_to_truth(groups, truth, threshold=threshold)
    points: dict[tuple[str, int], list[tuple[int, bool]]] = defaultdict(list)
    mirror = _mirror_of(groups) if frames else np.zeros(0, dtype=np.int64)
    for frame, people, match in zip(frames, at, matches, strict=True):
        rows = np.flatnonzero(match >= 0)
        if rows.size:
            flags = _mirrored(frame.positions[rows], people[match[rows]], mirror)
            for h, flag in zip(rows, flags, strict=True):
                points[frame.source, int(match[h])].append((frame.stamp_ns, bool(flag)))
    return MirroredOutput({
        key: (np.array([p[0] for p in ordered], dtype=np.int64), np.array([p[1] for p in ordered]))
        for key, ordered in ((key, sorted(found)) for key, found in points.items())
    })  # fmt: skip


def mirrored_share(
    groups: Sequence[SkeletonGroup], truth: TruthLike, *, threshold: float = 0.5
) -> float:
    """Share of the matched output skeletons whose whole body is mirrored (left for right).

    See :class:`MirroredOutput`. NaN when nothing is matched.
    """
    return mirrored_output(groups, truth, threshold=threshold).share


def _longest_run(stamps: np.ndarray, flags: np.ndarray) -> float:
    """Seconds of the longest run of ``True`` in time-ordered ``flags`` at ``stamps`` (ns).

    Its length in frames times the median frame interval (0 with a single stamp: no interval
    to take).
    """
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    if not edges.size:
        return 0.0
    frames = int((edges[1::2] - edges[0::2]).max())
    step = float(np.median(np.diff(stamps))) * 1e-9 if len(stamps) > 1 else 0.0
    return frames * step


def camera_mpjpe(
    camera_groups: dict[str, list[SkeletonGroup]],
    calibration: Calibration,
    truth: TruthLike,
    *,
    threshold: float = 0.5,
    oracle_sides: bool = False,
) -> dict[str, float]:
    """MPJPE (m) of each camera alone: its raw detections moved into the world, no tracking.

    What one camera gives without the others (front/back flips and side swaps included;
    with ``oracle_sides``, the side swaps undone, see :func:`output_mpjpe`).
    """
    correction = CameraCorrection(calibration)
    out = {}
    for _name, groups in camera_groups.items():
        moved = [g for g in (correction.apply(group) for group in groups) if g is not None]
        out.update(output_mpjpe(moved, truth, threshold=threshold, oracle_sides=oracle_sides))
    return out


def arrival_order(
    camera_groups: dict[str, list[SkeletonGroup]],
    calibration: Calibration,
    *,
    latency: float = 0.0,
    seed: int = 0,
) -> list[SkeletonGroup]:
    """Every camera's groups interleaved as they would arrive live.

    Arrival = the frame's reference time plus a random latency, uniform in [0, ``latency``] s,
    so ``latency`` > 0 gives out-of-order arrival across cameras within that spread.
    """
    rng = np.random.default_rng(seed)
    keyed: list[tuple[float, int, SkeletonGroup]] = []
    for name, groups in camera_groups.items():
        camera = calibration.camera(name)
        for group in groups:
            arrival = float(camera.to_reference_time(group.stamp)) + rng.uniform(0.0, latency)
            keyed.append((arrival, len(keyed), group))
    keyed.sort(key=lambda item: (item[0], item[1]))
    return [group for _, _, group in keyed]
