"""Relabelling: detections put in their tracks' labelling, tracks and outputs relabelled.

A detection's mirror parts may be swapped against its track's (left taken for right):
``canonical_poses`` reorders its joints into the track's labelling, holding hips, eyes and
ears to the shoulders' side and the body's sides to the track's; ``relabel`` reorders a
track's own per-joint state when the facing check finds the track reversed; ``label_rows``
relabels an output detection and fills its velocities.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_tracker.kernel_args import (
    FacingView,
    HeldSides,
    MirrorLayout,
    SideLayout,
    StackedRows,
    TrackFields,
)

__all__ = [
    "REVERSED_COS",
    "canonical_poses",
    "hold_axes",
    "label_frame",
    "label_rows",
    "relabel",
]


@njit(cache=True, error_model="numpy")
def _order(flips: np.ndarray, part: np.ndarray, mirror: np.ndarray, out: np.ndarray) -> None:
    """Joint order relabelling the parts flagged in ``flips`` ``(K,)``, written to ``out``."""
    for j in range(len(part)):
        out[j] = mirror[j] if part[j] >= 0 and flips[part[j]] else j


@njit(cache=True, error_model="numpy")
def canonical_poses(  # noqa: PLR0917 - one frame's pairs, the layout and the tracks
    positions: np.ndarray,
    rows: np.ndarray,
    flips: np.ndarray,
    layout: MirrorLayout,
    align: bool,
    sides: SideLayout,
    held: HeldSides,
) -> tuple[np.ndarray, np.ndarray]:
    """Matched detections in their tracks' labelling, hips/eyes/ears put on the shoulders' side.

    ``positions`` ``(D, J, 3)`` are the frame's detections, ``rows`` ``(U,)`` those matched
    and ``flips`` ``(U, K)`` the parts to relabel in each (``layout`` as in ``match_costs``;
    the input is not changed): joint ``j`` of pose ``u`` is ``positions[rows[u], o_j]`` with
    ``o_j = mirror[j]`` where ``part[j]`` is flipped, else ``j``.

    With ``align``, the shoulders' part first follows the detection's torso as its camera
    labelled it: with ``c`` the cosine of its left-right axis (``_sides_cosine``, left
    shoulder and hip less the right ones) with its track's held axis (``_reference_axis``:
    ``held.axes``, else the pose's), the part is flipped
    when ``c < -0.5`` and not when ``c > 0.5``, whatever the part's mean joint distance said:
    a flipped detection's shoulders and hips only trade labels, while its noisy or swinging
    hands can make the arms' labels look right. Then each other part whose top pair points
    against the shoulders flips, unless the joints below it point along them
    (``_follow_shoulders``, once, on the pose relabelled so far). Then the whole
    body's sides are held to the track's (``_reversed_sides`` against the same axis;
    ``held.left`` empty: not held): a reversed pose flips every part.

    Returns:
        ``(U, J, 3)`` canonical poses and ``(U, K)`` the flips used.

    """
    part, mirror = layout.part, layout.mirror
    shoulders, pairs = sides.shoulders, sides.pairs
    n_pairs, n_joints = len(rows), positions.shape[1]
    flips = flips.copy()
    canonical = np.empty((n_pairs, n_joints, 3))
    order = np.empty(n_joints, dtype=np.int64)
    track_rows, left, right = held.track_rows, held.left, held.right
    torso = align and len(left) > 0 and len(shoulders) == 2
    for u in range(n_pairs):
        if torso:
            reference = _reference_axis(held, track_rows[u])
            _follow_torso(flips[u], part[shoulders[0]], positions[rows[u]], reference, held)
        _order(flips[u], part, mirror, order)
        for j in range(n_joints):
            canonical[u, j] = positions[rows[u], order[j]]
        if not align or len(shoulders) < 2 or len(pairs) == 0:
            continue
        if _follow_shoulders(flips[u], canonical[u], sides):
            _order(flips[u], part, mirror, order)
            for j in range(n_joints):
                canonical[u, j] = positions[rows[u], order[j]]
    for u in range(n_pairs if align and len(left) else 0):
        reference = _reference_axis(held, track_rows[u])
        if _reversed_sides(canonical[u], reference, left, right):
            for k in range(flips.shape[1]):
                flips[u, k] = not flips[u, k]
            _order(flips[u], part, mirror, order)
            for j in range(n_joints):
                canonical[u, j] = positions[rows[u], order[j]]
    return canonical, flips


@njit(cache=True, error_model="numpy")
def _follow_shoulders(flips: np.ndarray, pose: np.ndarray, sides: SideLayout) -> bool:
    """Flip the parts of ``flips`` ``(K,)`` that ``pose`` ``(J, 3)`` has against its shoulders.

    A part (legs, eyes, ears) is against the shoulders ``s = p[left shoulder] - p[right]`` when
    its top pair ``(a, b)`` of ``sides.pairs`` is, ``(p_a - p_b)·s < -0.5 |p_a - p_b| |s|``
    (hips, eyes and ears sit on the shoulders' side on every body), unless the sum of its
    pairs below (``sides.below``: knees, ankles, feet) clearly points along them (the same
    test, over 0.5). SDKs report the hips about 10 cm apart, and a few centimetres of noise
    point them anywhere, while the rest of a correctly labelled leg still says which side it
    is on. The joints below can only keep a part's labels, never flip them: knees and feet
    cross the midline on a turning step, hips do not. Nothing is flipped where a joint of the
    top pair or a shoulder is missing; a missing joint below adds nothing. Returns whether
    any part flipped.
    """
    shoulders = sides.shoulders
    side = pose[shoulders[0]] - pose[shoulders[1]]
    below = np.zeros((len(flips), 3))
    for q in range(len(sides.below)):
        vector = pose[sides.below[q, 0]] - pose[sides.below[q, 1]]
        if math.isfinite(vector[0]) and math.isfinite(vector[1]) and math.isfinite(vector[2]):
            below[sides.below_parts[q]] += vector
    changed = False
    for p in range(len(sides.pairs)):
        k = sides.pair_parts[p]
        top = pose[sides.pairs[p, 0]] - pose[sides.pairs[p, 1]]
        # clearly only (0.5): eyes must not toggle on noise; a missing joint gives cosine 0
        if _cosine(top, side) < -0.5 and not _cosine(below[k], side) > 0.5:
            flips[k] = not flips[k]
            changed = True
    return changed


REVERSED_COS = 0.5
"""A detection's left-right axis against its track's beyond this (cos < -it) is reversed."""
SIDE_MEMORY = 0.2
"""Seconds over which a track's held left-right axis follows its detections' (``hold_axes``):
long enough that one camera's noisy torso, taken with its labels, cannot turn it, short
enough to follow a person turning on the spot."""
WALK_SPEED = 0.7
"""m/s across the up above which a track is walking, so faces where it goes (``hold_axes``):
clearly faster than a step aside or back, and than the error of a slow walker's velocity
(noisy-sdk: 0.56 m/s estimated for 0.2-0.3 m/s true)."""
WALK_MEMORY = 0.3
"""Seconds over which a walking track's held left-right axis turns to face where it goes
(``hold_axes``)."""
CAMERA_WEIGHT = 0.8
"""Weight of a camera's last detection's axis beside the track's held one (both unit) in what
the camera's next detection is held to (``_reference_axis``): under 1, so that the held axis
decides where the two point apart (a camera whose labels went wrong is put back)."""
CAMERA_GAP = 0.2
"""Seconds within which a camera's last detection of a track still tells its next one's sides
(``_reference_axis``): a few frames at 15-30 Hz; longer, the person may have turned."""
CLEAR_AXIS = 0.25
"""Metres of a detection's left-right axis (left shoulder and hip less the right ones) below
which it counts less, by ``(length / CLEAR_AXIS)^2`` (``_clearness``), in its track's held
axis (``hold_axes``) and in what its camera's next detection is held to
(``_reference_axis``). An adult's measures about 0.5 m; a camera that sees the body from
the side sees it along its depth, with the far shoulder and hip hidden, and SDKs then report
it a few centimetres long, pointing anywhere."""


@njit(cache=True, error_model="numpy")
def _reversed_sides(
    detection: np.ndarray, reference: np.ndarray, left: np.ndarray, right: np.ndarray
) -> bool:
    """Whether a detection's left points to its track's right (its sides then all swapped).

    The left-right axis is the left shoulder and hip less the right ones: they lie in the
    body's frontal plane, so a front/back flip (a reflection through that plane) leaves them
    where they were and only exchanges their labels, whereas hands, feet and the head swing
    out of it; relabelling part by part on every joint can then keep a flipped detection's
    labels and drag its track into the mirrored labelling. Reversed is a cosine under -0.5;
    nothing is said where a joint is missing.
    """
    return _sides_cosine(detection, reference, left, right) < -REVERSED_COS


@njit(cache=True, error_model="numpy")
def _follow_torso(
    flips: np.ndarray, arms: int, detection: np.ndarray, reference: np.ndarray, held: HeldSides
) -> None:
    """Flip part ``arms`` of ``flips`` ``(K,)`` to what the detection's torso says, if clear.

    Flipped when the detection's left-right axis points against its track's (cosine under
    ``-REVERSED_COS``), not flipped when along it (over ``REVERSED_COS``), else unchanged.
    """
    along = _sides_cosine(detection, reference, held.left, held.right)
    if abs(along) > REVERSED_COS:
        flips[arms] = along < 0.0


@njit(cache=True, error_model="numpy")
def _sides_axis(pose: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """``(3,)`` a pose's left-right axis: the sum of its ``left`` joints less its ``right``."""
    axis = np.zeros(3)
    for i in range(len(left)):
        for a in range(3):
            axis[a] += pose[left[i], a] - pose[right[i], a]
    return axis


@njit(cache=True, error_model="numpy")
def _reference_axis(held: HeldSides, r: int) -> np.ndarray:
    """``(3,)`` the left-right axis the detections of track ``r`` are held to.

    The track's held axis (``held.axes[r]``, ``hold_axes``) once it has one, else its pose's, as
    a unit vector; plus ``CAMERA_WEIGHT`` times the clearness times the unit axis of the frame's
    camera's last detection of the track as labelled (``held.camera_axes``) when that is at most
    ``CAMERA_GAP`` old. A person turns continuously in every camera's stream, whereas the
    track's held axis, averaged over ``SIDE_MEMORY`` across cameras, lags a fast turn at the end
    of a walk far enough that correct detections would count as reversed and be relabelled into
    the mirror; the camera's own last axis has turned with the body, and its drifting bias is
    the same one frame later. With a weight under 1 the camera's axis wins unless the two point
    nearly opposite ways, so a camera whose labels went wrong is still put back by a track that
    disagrees with it outright; an SDK flip reverses the detection against both. The camera's
    axis counts by its ``_clearness``: a camera that saw the body side-on, its axis a few
    centimetres long and swinging, would otherwise carry whatever labelling that noise reached
    into its next detections, correct ones included, once it sees the body squarely again.
    """
    axis = held.axes[r]
    if axis[0] == 0.0 and axis[1] == 0.0 and axis[2] == 0.0:
        axis = _sides_axis(held.tracks[r], held.left, held.right)
    size = math.sqrt(np.sum(axis * axis))
    reference = axis / size if size > 0.0 else axis.copy()
    if held.camera >= held.camera_axes.shape[1]:
        return reference
    last = held.camera_axes[r, held.camera]
    last_size = math.sqrt(np.sum(last * last))
    recent = (held.stamp_ns - held.camera_ns[r, held.camera]) * 1e-9 <= CAMERA_GAP
    if last_size > 0.0 and recent:
        weight = CAMERA_WEIGHT * _clearness(last_size)
        for a in range(3):
            reference[a] += weight * last[a] / last_size
    return reference


@njit(cache=True, error_model="numpy")
def _cosine(a: np.ndarray, b: np.ndarray) -> float:
    """Cosine of two ``(3,)`` vectors; 0 where either is zero."""
    scale = math.sqrt(np.sum(a * a) * np.sum(b * b))
    return np.sum(a * b) / scale if scale > 0.0 else 0.0


@njit(cache=True, error_model="numpy")
def _sides_cosine(
    detection: np.ndarray, reference: np.ndarray, left: np.ndarray, right: np.ndarray
) -> float:
    """Cosine of a detection's left-right axis with ``reference`` ``(3,)``.

    NaN where a joint is missing.
    """
    axis = _sides_axis(detection, left, right)
    along = axis[0] * reference[0] + axis[1] * reference[1] + axis[2] * reference[2]
    scale = math.sqrt(np.sum(axis * axis) * np.sum(reference * reference))
    return along / scale if scale > 0.0 else np.nan


@njit(cache=True, error_model="numpy")
def hold_axes(
    held: HeldSides, canonical: np.ndarray, last_hit_ns: np.ndarray, view: FacingView
) -> None:
    """Fold each detection's left-right axis (in its track's labelling) into its track's.

    ``axes[r] <- k axes[r] + (1 - k) axis(canonical[u])`` for ``r = held.track_rows[u]``,
    ``axis`` the left shoulder and hip less the right ones (m), ``k = exp(-c dt /
    SIDE_MEMORY)``, ``dt`` s since the axis last took a detection's (``_last_fold_ns``; the
    track's previous hit, ``last_hit_ns`` ``(T,)``, before any) and ``c`` how steady the
    detection's axis is in its camera's stream (``_steadiness``: the cosine with the
    camera's last, at least 0) times how plainly it shows (``_clearness``): a detection that
    continues its camera's counts fully, one that jumped across the body not at all, one seen
    from the side, its axis a few centimetres long, hardly. A
    track without an axis yet (0) takes the detection's, and the axis is kept as its camera's
    last (``held.camera_axes``, ``_reference_axis``). A detection missing one of those joints
    adds nothing. Before that, a track walking faster than
    ``WALK_SPEED`` (its body velocity across the up, ``view.up``) has its axis pulled
    towards that of a body facing where it walks (``_follow_walk``), unless it is sure of
    its sides (``held.facing``) and faces away from its walk. ``held.axes`` and
    ``held.camera_axes`` change in place.

    The held axis is what the next detections' sides are held to (``_reference_axis``): the
    track's pose follows each detection by ``position_smoothing``, so a run of noisy
    detections whose torsos point 90-120 deg away (not clearly reversed, so kept as
    labelled) can turn its shoulders through each other within a tenth of a second, and
    the detections after are then relabelled to the mirror (repeated-motion, noisy-sdk).
    The walking direction is evidence no SDK error moves: it comes from where the body is,
    not from its labels. A noisy detection whose axis jumped from its camera's last is
    what turned the held axis part of the way without a turn of the body: folded in whole,
    a few of them carried it far enough that the next detections, correct, counted as
    reversed. Weighed by the stream's steadiness instead of against the held axis itself,
    the axis still follows a fast turn (each camera's stream turns with the body), where
    it would stall on its own lag. A camera that sees the body side-on gives a steady stream
    of axes a few centimetres long that swing anywhere; weighed whole, with the person
    stepping back, they turned a right track's axis half round in 0.3 s while the other
    cameras' detections (and the pose) did not turn (docs/stages-robustness.md, session 24).
    """
    upright = view.up[3] != 0.0
    for u in range(len(held.track_rows)):
        r = held.track_rows[u]
        axis = _sides_axis(canonical[u], held.left, held.right)
        if not (math.isfinite(axis[0]) and math.isfinite(axis[1]) and math.isfinite(axis[2])):
            continue
        known = held.axes[r, 0] != 0.0 or held.axes[r, 1] != 0.0 or held.axes[r, 2] != 0.0
        elapsed = max(view.stamp_ns - _last_fold_ns(held, r, last_hit_ns[r]), 0) * 1e-9
        keep = 0.0
        if known:
            clear = _clearness(math.sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]))
            weight = _steadiness(held, r, axis, view) * clear
            keep = math.exp(-elapsed * weight / SIDE_MEMORY)
        if known and upright:
            _follow_walk(held.axes[r], held.velocity[r], view.up, elapsed, held.facing[r] > 0.0)
        for a in range(3):
            held.axes[r, a] = keep * held.axes[r, a] + (1.0 - keep) * axis[a]
        if view.camera < held.camera_axes.shape[1]:
            held.camera_axes[r, view.camera] = axis
            held.camera_ns[r, view.camera] = view.stamp_ns


@njit(cache=True, error_model="numpy")
def _last_fold_ns(held: HeldSides, r: int, last_hit_ns: int) -> int:
    """When track ``r``'s held axis last took a detection's: its cameras' latest axis stamp.

    ``last_hit_ns`` (the track's previous hit) where no camera has given an axis yet. A hit
    without a torso (a shoulder or hip occluded) adds nothing to the axis, so it must not use
    up the time the next detection's fold is weighed by: with two cameras, one of them
    missing the torso for a while halved how fast the axis followed a turn.
    """
    latest = 0
    for c in range(held.camera_ns.shape[1]):
        latest = max(latest, held.camera_ns[r, c])
    return latest if latest > 0 else last_hit_ns


@njit(cache=True, error_model="numpy")
def _steadiness(held: HeldSides, r: int, axis: np.ndarray, view: FacingView) -> float:
    """How much a detection's left-right axis ``(3,)`` counts in its track's held one, 0..1.

    The cosine with the axis of its camera's last detection of the track (``held.camera_axes``,
    as labelled), at least 0, where that is at most ``CAMERA_GAP`` old; else 1. A body turns
    a few degrees between two frames of a camera and the camera's bias drifts slowly, so an
    axis far from the camera's last is the SDK's noise of this frame.
    """
    if view.camera >= held.camera_axes.shape[1]:
        return 1.0
    last = held.camera_axes[r, view.camera]
    if (view.stamp_ns - held.camera_ns[r, view.camera]) * 1e-9 > CAMERA_GAP:
        return 1.0
    if last[0] == 0.0 and last[1] == 0.0 and last[2] == 0.0:
        return 1.0
    return max(_cosine(axis, last), 0.0)


@njit(cache=True, error_model="numpy")
def _clearness(length: float) -> float:
    """``min(1, (length / CLEAR_AXIS)^2)``: how plainly a left-right axis that long shows."""
    return min(1.0, (length / CLEAR_AXIS) ** 2)


@njit(cache=True, error_model="numpy")
def _follow_walk(
    axis: np.ndarray, velocity: np.ndarray, up: np.ndarray, elapsed: float, sure: bool
) -> None:
    """Pull ``axis`` ``(3,)`` towards the left-right axis of a body facing where it walks.

    With ``v`` the ``velocity`` ``(3,)`` across the unit ``up`` (the first three of ``up``),
    faster than ``WALK_SPEED``: ``axis <- k axis + (1 - k) |axis| unit(up x v)``, ``k =
    exp(-elapsed / WALK_MEMORY)`` (``up x forward`` is the left of a body facing forward).
    In place; slower, unchanged. A track ``sure`` of its sides (facing log-odds above 0)
    whose axis faces away from the walk (``axis · (up x v) <= 0``) is not pulled: people
    step back and aside, and its cameras say which way it faces; a track in doubt is pulled
    round, which puts a mirrored track walking forwards right.
    """
    normal = up[:3]
    flat = velocity - np.sum(velocity * normal) * normal
    speed = math.sqrt(np.sum(flat * flat))
    if not speed > WALK_SPEED:
        return
    left = np.array(
        [
            normal[1] * flat[2] - normal[2] * flat[1],
            normal[2] * flat[0] - normal[0] * flat[2],
            normal[0] * flat[1] - normal[1] * flat[0],
        ]
    )
    if sure and np.sum(axis * left) <= 0.0:
        return
    size = math.sqrt(np.sum(axis * axis)) / speed
    keep = math.exp(-elapsed / WALK_MEMORY)
    for a in range(3):
        axis[a] = keep * axis[a] + (1.0 - keep) * size * left[a]


@njit(cache=True, error_model="numpy")
def relabel(tracks: TrackFields, r: int, permutation: np.ndarray) -> None:
    """Reorder track ``r``'s joints (swap the sides of some parts) in every per-joint field.

    ``permutation`` ``(J,)``: joint ``j`` takes what joint ``permutation[j]`` held, in the
    pose, joint velocities, running sums and the window's records.
    """
    positions, velocities = tracks.positions, tracks.velocities
    sums, record_terms = tracks.sums, tracks.record_terms
    record_start, record_count = tracks.record_start, tracks.record_count
    positions[r] = positions[r][permutation]
    velocities[r] = velocities[r][permutation]
    for c in range(sums.shape[1]):
        sums[r, c] = sums[r, c][permutation]
    slots = record_terms.shape[1]
    for i in range(record_count[r]):
        slot = (record_start[r] + i) % slots
        record_terms[r, slot] = record_terms[r, slot][permutation]


@njit(cache=True, error_model="numpy")
def label_frame(  # noqa: PLR0917 - the frame's rows, its pairs and their tracks
    stacked: StackedRows,
    index: np.ndarray,
    flips: np.ndarray,
    layout: MirrorLayout,
    velocities: np.ndarray,
    rows: np.ndarray,
    confirmed: np.ndarray,
) -> None:
    """``label_rows`` on a stacked frame: each pair ``u`` whose track ``rows[u]`` is confirmed.

    ``stacked``'s markers ``(N, J, 20)``, presence ``(N, J)`` and the links alike are the
    frame's detections; pair ``u`` is stacked row
    ``index[u]`` with flips ``flips[u]`` and its track's ``velocities[rows[u]]`` (``(T, J,
    3)``, ``confirmed`` ``(T,)``: the track table's).
    """
    markers, present = stacked.markers, stacked.present
    links, link_present = stacked.links, stacked.link_present
    for u in range(len(rows)):
        if confirmed[rows[u]]:
            d = index[u]
            label_rows(
                markers[d],
                present[d],
                links[d],
                link_present[d],
                flips[u],
                layout,
                velocities[rows[u]],
            )


@njit(cache=True, error_model="numpy")
def label_rows(  # noqa: PLR0917 - one detection's four row arrays, its flips and its track
    markers: np.ndarray,
    present: np.ndarray,
    links: np.ndarray,
    link_present: np.ndarray,
    flips: np.ndarray,
    layout: MirrorLayout,
    track_velocities: np.ndarray,
) -> None:
    """One output detection, in place: parts in ``flips`` relabelled, velocities filled.

    Link ids are child joint ids, so links take the joints' order. A present joint without a
    finite velocity takes its track's.
    """
    part, mirror = layout.part, layout.mirror
    n_joints = len(part)
    if flips.any():
        order = np.empty(n_joints, dtype=np.int64)
        _order(flips, part, mirror, order)
        moved_markers = markers[order].copy()
        moved_present = present[order].copy()
        moved_links = links[order].copy()
        moved_link_present = link_present[order].copy()
        markers[:] = moved_markers
        present[:] = moved_present
        links[:] = moved_links
        link_present[:] = moved_link_present
    for j in range(n_joints):
        known = (
            math.isfinite(markers[j, 8])
            and math.isfinite(markers[j, 9])
            and math.isfinite(markers[j, 10])
        )
        if present[j] and not known:
            markers[j, 8] = track_velocities[j, 0]
            markers[j, 9] = track_velocities[j, 1]
            markers[j, 10] = track_velocities[j, 2]
