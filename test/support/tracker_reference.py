"""The tracker's kernels stated in numpy: the readable specification of ``hiros_tracker``'s maths.

One function per compiled kernel the tracker calls (``hiros_tracker.kernels`` and the rigid
moves of ``hiros_tracker.rigid``; the association's are in ``tracker_reference_association``),
written from the kernels' docstrings with whole-array
formulas where they read best and plain loops where the maths is sequential (tracks changed in
place one after another). The kernels' private helpers (``_sides_axis``, ``_reference_axis``,
``_steadiness``, ``_follow_walk``, ``_facing_evidence``, ``_walking``, ``_update_up``,
``_hit_one``, ``_rebase``, ``_solve_one``, ``_turn_quaternion``, ...) are restated here as
functions of the same meaning and held to the kernels through their callers.
``test/hiros_tracker/test_kernel_reference.py`` holds each kernel equal to this module on
random inputs. Shapes: ``T`` tracks, ``D`` detections, ``U`` matched pairs, ``J`` joints,
``K`` mirror parts, ``C`` cameras, ``R`` record slots.

Where a function changes ``TrackFields`` in place, it does so like its kernel, so that a test
can run both on copies of one state and compare every field.
"""

from __future__ import annotations

import numpy as np
from tracker_reference_association import vector_norm

from hiros_tracker.facing import (
    CLEAR_CONTRADICTION,
    CONTRADICTING_VIEWS,
    DOUBT_LIMIT,
    VERDICT_LIFETIME_S,
)
from hiros_tracker.kernel_args import (
    FacingBody,
    FacingPriors,
    FacingView,
    FrameRows,
    HeldSides,
    HitLayout,
    Hits,
    HitSettings,
    MirrorLayout,
    SideLayout,
    StackedRows,
    TrackFields,
    UpdateSettings,
)
from hiros_tracker.labels import (
    CAMERA_GAP,
    CAMERA_WEIGHT,
    CLEAR_AXIS,
    REVERSED_COS,
    SIDE_MEMORY,
    WALK_MEMORY,
    WALK_SPEED,
)
from hiros_tracker.track_update import REBASE_NS

DETERMINED = 1e-5
"""A joint's slope is determined when its centred time spread ``sum (t - tc)^2`` (s²) is above."""


def copy_fields(fields: TrackFields) -> TrackFields:
    """A ``TrackFields`` of copies: the state one run changes in place, apart from another's."""
    return TrackFields(*(np.copy(field) for field in fields))


def _unit_or_nan(vector: np.ndarray) -> np.ndarray:
    """``vector / |vector|``; NaN for a zero (or NaN) vector (``facing._unit3``)."""
    size = vector_norm(vector)
    return vector / size if size != 0.0 else np.full(3, np.nan)


def _flat(vector: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``vector`` less its component along the unit ``up`` (``facing._flat3``)."""
    return vector - np.dot(vector, up) * up


def _permutation(flips: np.ndarray, layout: MirrorLayout) -> np.ndarray:
    """``(J,)`` joint order relabelling the parts flagged in ``flips`` ``(K,)`` (``_order``)."""
    sided = layout.part >= 0
    flipped = np.zeros(len(layout.part), dtype=bool)
    flipped[sided] = flips[layout.part[sided]]
    return np.where(flipped, layout.mirror, np.arange(len(layout.part)))


# --------------------------------------------------------------------------------- labels
def sides_axis(pose: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """``(3,)`` a pose's left-right axis: its ``left`` joints less its ``right`` ones, summed."""
    return (pose[left] - pose[right]).sum(axis=0)


def _cosine_or(a: np.ndarray, b: np.ndarray, otherwise: float) -> float:
    """The cosine of two vectors, ``otherwise`` where either is zero (or NaN)."""
    scale = np.sqrt(np.sum(a * a) * np.sum(b * b))
    return float(np.sum(a * b) / scale) if scale > 0.0 else otherwise


def clearness(axis: np.ndarray) -> float:
    """``_clearness`` of an axis: ``min(1, (|axis| / CLEAR_AXIS)^2)``."""
    return min(1.0, (vector_norm(axis) / CLEAR_AXIS) ** 2)


def reference_axis(held: HeldSides, r: int) -> np.ndarray:
    """``(3,)`` what the detections of track ``r`` are held to (``_reference_axis``).

    The unit held axis (the pose's while none is held) plus ``CAMERA_WEIGHT`` times the unit
    axis of the frame's camera's last detection of the track, when at most ``CAMERA_GAP`` old,
    times that axis's clearness ``min(1, (|last| / CLEAR_AXIS)^2)``.
    """
    axis = held.axes[r]
    if not axis.any():
        axis = sides_axis(held.tracks[r], held.left, held.right)
    size = vector_norm(axis)
    reference = axis / size if size > 0.0 else axis.copy()
    if held.camera < held.camera_axes.shape[1]:
        last = held.camera_axes[r, held.camera]
        recent = (held.stamp_ns - held.camera_ns[r, held.camera]) * 1e-9 <= CAMERA_GAP
        if vector_norm(last) > 0.0 and recent:
            reference = reference + CAMERA_WEIGHT * clearness(last) * last / vector_norm(last)
    return reference


def sides_cosine(pose: np.ndarray, reference: np.ndarray, held: HeldSides) -> float:
    """Cosine of a pose's left-right axis with ``reference``; NaN where a joint is missing."""
    return _cosine_or(sides_axis(pose, held.left, held.right), reference, np.nan)


def _canonical_one(  # noqa: PLR0917 - one pair's detection, flips and context
    detection: np.ndarray,
    flips: np.ndarray,
    layout: MirrorLayout,
    align: bool,
    sides: SideLayout,
    held: HeldSides,
    row: int,
) -> tuple[np.ndarray, np.ndarray]:
    """One matched detection ``(J, 3)`` put in its track's labelling, and the flips used."""
    flips = flips.copy()
    has_sides = len(held.left) > 0
    if align and has_sides and len(sides.shoulders) == 2:  # the arms follow the torso
        along = sides_cosine(detection, reference_axis(held, row), held)
        if abs(along) > REVERSED_COS:
            flips[layout.part[sides.shoulders[0]]] = along < 0.0
    pose = detection[_permutation(flips, layout)]
    if align and len(sides.shoulders) == 2 and len(sides.pairs):  # pairs to the shoulders
        shoulders = pose[sides.shoulders[0]] - pose[sides.shoulders[1]]
        below = pose[sides.below[:, 0]] - pose[sides.below[:, 1]]
        below[~np.isfinite(below).all(axis=1)] = 0.0  # a missing joint below adds nothing
        below_sums = np.zeros((len(flips), 3))
        np.add.at(below_sums, sides.below_parts, below)
        toggle = np.zeros_like(flips)
        for (a, b), k in zip(sides.pairs, sides.pair_parts, strict=True):
            against = _cosine_or(pose[a] - pose[b], shoulders, 0.0) < -0.5
            toggle[k] ^= against and not _cosine_or(below_sums[k], shoulders, 0.0) > 0.5
        flips ^= toggle
        pose = detection[_permutation(flips, layout)]
    reversed_ = align and has_sides  # the whole body's sides held to the track's
    if reversed_ and sides_cosine(pose, reference_axis(held, row), held) < -REVERSED_COS:
        flips = ~flips
        pose = detection[_permutation(flips, layout)]
    return pose, flips


def reference_canonical_poses(  # noqa: PLR0917 - the kernel's inputs
    positions: np.ndarray,
    rows: np.ndarray,
    flips: np.ndarray,
    layout: MirrorLayout,
    align: bool,
    sides: SideLayout,
    held: HeldSides,
) -> tuple[np.ndarray, np.ndarray]:
    """``canonical_poses``: ``(U, J, 3)`` detections ``rows`` in their tracks' labelling, flips."""
    n_parts = flips.shape[1]
    canonical = np.empty((len(rows), positions.shape[1], 3))
    used = np.empty((len(rows), n_parts), dtype=bool)
    for u, d in enumerate(rows):
        canonical[u], used[u] = _canonical_one(
            positions[d], flips[u], layout, align, sides, held, held.track_rows[u]
        )
    return canonical, used


def follow_walk(
    axis: np.ndarray, velocity: np.ndarray, up: np.ndarray, elapsed: float, sure: bool
) -> None:
    """``_follow_walk``: ``axis`` pulled towards ``|axis| unit(up x v)`` when walking, in place,
    unless ``sure`` and facing away from the walk."""
    normal = up[:3]
    flat = _flat(velocity, normal)
    speed = vector_norm(flat)
    if not speed > WALK_SPEED:
        return
    keep = np.exp(-elapsed / WALK_MEMORY)
    facing_left = np.cross(normal, flat) / speed
    if sure and axis @ facing_left <= 0.0:
        return
    axis[:] = keep * axis + (1.0 - keep) * vector_norm(axis) * facing_left


def _steadiness(held: HeldSides, r: int, axis: np.ndarray, camera: int, stamp_ns: int) -> float:
    """How much a detection's axis counts: its cosine (>= 0) with its camera's recent last one."""
    if camera >= held.camera_axes.shape[1]:
        return 1.0
    last = held.camera_axes[r, camera]
    if (stamp_ns - held.camera_ns[r, camera]) * 1e-9 > CAMERA_GAP or not last.any():
        return 1.0
    return max(_cosine_or(axis, last, 0.0), 0.0)


def reference_hold_axes(
    held: HeldSides, canonical: np.ndarray, last_hit_ns: np.ndarray, view: FacingView
) -> None:
    """``hold_axes``: each detection's left-right axis folded into its track's, in place."""
    upright = view.up[3] != 0.0
    for u, r in enumerate(held.track_rows):
        axis = sides_axis(canonical[u], held.left, held.right)
        if not np.isfinite(axis).all():
            continue
        given = held.camera_ns[r][held.camera_ns[r] > 0]
        last_fold = given.max() if len(given) else last_hit_ns[r]
        elapsed = max(view.stamp_ns - last_fold, 0) * 1e-9
        keep = 0.0
        if held.axes[r].any():
            steady = _steadiness(held, r, axis, view.camera, view.stamp_ns)
            keep = np.exp(-elapsed * steady * clearness(axis) / SIDE_MEMORY)
            if upright:
                sure = held.facing[r] > 0.0
                follow_walk(held.axes[r], held.velocity[r], view.up, elapsed, sure)
        held.axes[r] = keep * held.axes[r] + (1.0 - keep) * axis
        if view.camera < held.camera_axes.shape[1]:
            held.camera_axes[r, view.camera] = axis
            held.camera_ns[r, view.camera] = view.stamp_ns


def live_records(tracks: TrackFields, r: int) -> np.ndarray:
    """Slots of track ``r``'s record ring that hold its window's detections, oldest first."""
    slots = tracks.record_ns.shape[1]
    return (tracks.record_start[r] + np.arange(tracks.record_count[r])) % slots


def reference_relabel(tracks: TrackFields, r: int, permutation: np.ndarray) -> None:
    """``relabel``: joint ``j`` of track ``r`` takes joint ``permutation[j]``'s state."""
    tracks.positions[r] = tracks.positions[r][permutation]
    tracks.velocities[r] = tracks.velocities[r][permutation]
    tracks.sums[r] = tracks.sums[r][:, permutation]
    live = live_records(tracks, r)
    tracks.record_terms[r, live] = tracks.record_terms[r, live][:, permutation]


def reference_label_rows(  # noqa: PLR0917 - the kernel's inputs
    markers: np.ndarray,
    present: np.ndarray,
    links: np.ndarray,
    link_present: np.ndarray,
    flips: np.ndarray,
    layout: MirrorLayout,
    track_velocities: np.ndarray,
) -> None:
    """``label_rows``: one detection's rows relabelled, missing velocities its track's."""
    order = _permutation(flips, layout)
    for field in (markers, present, links, link_present):
        field[: len(order)] = field[order]
    unknown = present & ~np.isfinite(markers[:, 8:11]).all(axis=1)
    markers[unknown, 8:11] = track_velocities[unknown]


def reference_label_frame(  # noqa: PLR0917 - the kernel's inputs
    stacked: StackedRows,
    index: np.ndarray,
    flips: np.ndarray,
    layout: MirrorLayout,
    velocities: np.ndarray,
    rows: np.ndarray,
    confirmed: np.ndarray,
) -> None:
    """``label_frame``: ``label_rows`` on stacked row ``index[u]`` for each confirmed track."""
    for u, r in enumerate(rows):
        if confirmed[r]:
            d = index[u]
            reference_label_rows(
                stacked.markers[d],
                stacked.present[d],
                stacked.links[d],
                stacked.link_present[d],
                flips[u],
                layout,
                velocities[r],
            )


# --------------------------------------------------------------------------------- facing
def update_up(
    up: np.ndarray, positions: np.ndarray, rows: np.ndarray, body: FacingBody
) -> np.ndarray:
    """``_update_up``: the world's up (state ``up`` ``(4,)`` in place), NaN before any trunk."""
    trunks = np.array(
        [_unit_or_nan(positions[r, body.neck] - positions[r, body.root]) for r in rows]
    )
    trunks = trunks.reshape(-1, 3)[np.isfinite(trunks.reshape(-1, 3)).all(axis=1)]
    if len(trunks):
        mean = trunks.sum(axis=0) / len(trunks)
        up[:3] = mean if up[3] == 0.0 else up[:3] + 0.01 * (mean - up[:3])
        up[:3] /= vector_norm(up[:3])
        up[3] = 1.0
    return up[:3].copy() if up[3] != 0.0 else np.full(3, np.nan)


def walking(velocity: np.ndarray, front: np.ndarray, up: np.ndarray, priors: FacingPriors) -> float:
    """``_walking``: ``±walking_evidence`` for a walk along/against ``front``, else 0 (NaN)."""
    flat = _flat(velocity, up)
    speed = vector_norm(flat)
    if not speed > priors.walking_speed:
        return 0.0
    along = np.dot(flat, front) / max(speed, 1e-9)
    if along > 0:
        return priors.walking_evidence
    if along < 0:
        return -priors.walking_evidence
    return along


def _view_evidence(  # noqa: PLR0917 - one detection's comparison and where it is seen from
    flipped: bool,
    front: np.ndarray,
    root: np.ndarray,
    up: np.ndarray,
    view: FacingView,
    priors: FacingPriors,
) -> float:
    """Log-odds that the track is right given whether its detection looks flipped.

    Each hypothesis (front ``f`` right, ``-f`` mirrored) takes the flip prior of the view the
    camera would have (``flip_prior_back`` when seen from the back, cos < -0.5); without a
    camera position, ``±log((1 - p) / p)``.
    """
    p, p_back = priors.flip_prior, priors.flip_prior_back
    if not view.has_camera:
        return (-1.0 if flipped else 1.0) * np.log((1.0 - p) / p)
    to_camera = _unit_or_nan(_flat(view.camera_position - root, up))
    cosine = np.dot(front, to_camera)
    prior_right = p_back if cosine < -0.5 else p
    prior_wrong = p_back if -cosine < -0.5 else p
    likely_right = prior_right if flipped else 1.0 - prior_right
    likely_wrong = 1.0 - prior_wrong if flipped else prior_wrong
    return np.log(likely_right / likely_wrong)


def facing_evidence(  # noqa: PLR0917 - the kernel's inputs
    tracks: TrackFields,
    rows: np.ndarray,
    canonical: np.ndarray,
    up: np.ndarray,
    view: FacingView,
    body: FacingBody,
    priors: FacingPriors,
) -> tuple[np.ndarray, np.ndarray]:
    """``_facing_evidence``: ``(U,)`` log-odds each detection's view gives, ``(U,)`` its walk's.

    A front or forward that cannot be computed (no forward pointer seen, an unknown up) gives
    no view evidence: the detection cannot look flipped or not.
    """
    views = np.zeros(len(rows))
    walks = np.zeros(len(rows))
    for u, r in enumerate(rows):
        pose = tracks.positions[r]
        across = pose[body.left].sum(axis=0) - pose[body.right].sum(axis=0)
        front = _unit_or_nan(np.cross(across, up))
        forward = np.zeros(3)
        for a, b in body.pointers:
            pointer = _unit_or_nan(_flat(canonical[u, b] - canonical[u, a], up))
            forward += np.where(np.isfinite(pointer), pointer, 0.0)
        agreement = np.dot(_unit_or_nan(forward), front)
        value = _view_evidence(bool(agreement < 0), front, pose[body.root], up, view, priors)
        if not np.isfinite(agreement):
            value = 0.0
        walk = walking(tracks.velocity[r], front, up, priors)
        views[u] = np.nan_to_num(value, nan=0.0, posinf=0.0, neginf=0.0)
        walks[u] = np.nan_to_num(walk, nan=0.0, posinf=0.0, neginf=0.0)
    return views, walks


def doubt_step(
    tracks: TrackFields, r: int, view: FacingView, evidence: float, walk: float
) -> float:
    """``_doubt_step``: the run's step (0: it ends), the camera's verdict recorded."""
    if view.camera < tracks.camera_verdicts.shape[1]:
        tracks.camera_verdicts[r, view.camera] = evidence
        tracks.camera_verdicts_ns[r, view.camera] = view.stamp_ns
    if walk:
        return -evidence if walk < 0 else 0.0
    age = (view.stamp_ns - tracks.camera_verdicts_ns[r]) * 1e-9
    recent = tracks.camera_verdicts[r][age <= VERDICT_LIFETIME_S]
    clear = np.count_nonzero(recent < -CLEAR_CONTRADICTION)
    if np.any(recent > 0.0) or clear < CONTRADICTING_VIEWS:
        return 0.0
    return -evidence


def reference_turn_facing(  # noqa: PLR0917 - the kernel's inputs
    tracks: TrackFields,
    rows: np.ndarray,
    canonical: np.ndarray,
    view: FacingView,
    body: FacingBody,
    priors: FacingPriors,
) -> np.ndarray:
    """``turn_facing``: the tracks' facing log-odds weighed, reversed ones relabelled (in place)."""
    up = update_up(view.up, tracks.positions, rows, body)
    views, walks = facing_evidence(tracks, rows, canonical, up, view, body, priors)
    turned = np.zeros(len(rows), dtype=bool)
    for u, r in enumerate(rows):
        elapsed = max(view.stamp_ns - tracks.facing_ns[r], 0) * 1e-9
        memory = priors.facing_memory if walks[u] else priors.facing_memory_standing
        fade = np.exp(-elapsed / memory)
        tracks.facing[r] = tracks.facing[r] * fade + views[u] + walks[u]
        tracks.facing_ns[r] = view.stamp_ns
        step = doubt_step(tracks, r, view, views[u], walks[u])
        tracks.doubt[r] = 0.0 if step == 0.0 else max(tracks.doubt[r] + step, 0.0)
        if tracks.doubt[r] > DOUBT_LIMIT:
            tracks.facing[r] = min(tracks.facing[r], -priors.facing_threshold - 1.0)
        if tracks.facing[r] < -priors.facing_threshold:
            reference_relabel(tracks, r, body.mirror)
            tracks.sides[r] = -tracks.sides[r]
            tracks.camera_sides[r] = -tracks.camera_sides[r]
            tracks.camera_verdicts[r] = -tracks.camera_verdicts[r]
            tracks.facing[r] = -tracks.facing[r]
            tracks.doubt[r] = 0.0
            turned[u] = True
    return turned


# --------------------------------------------------------------------------- track update
def fit_terms(pose: np.ndarray, t: float) -> np.ndarray:
    """``(J, 9)`` one detection's least-squares terms n, t, t², p, t·p; 0 where unmeasured."""
    measured = np.isfinite(pose).all(axis=1)
    terms = np.zeros((len(pose), 9))
    terms[measured, 0] = 1.0
    terms[measured, 1] = t
    terms[measured, 2] = t * t
    terms[measured, 3:6] = pose[measured]
    terms[measured, 6:9] = pose[measured] * t
    return terms


def smoothed_pose(  # noqa: PLR0917 - one track's state and its detection
    position: np.ndarray,
    velocity: np.ndarray,
    time_ns: int,
    detection: np.ndarray,
    stamp_ns: int,
    alpha: float,
    max_prediction: float,
) -> np.ndarray:
    """``(J, 3)`` a track's pose predicted to its newest time and moved ``alpha`` to its detection.

    An unmeasured joint (any coordinate NaN) keeps the prediction; a value that is not finite
    takes the detection's coordinate.
    """
    dt = np.clip((max(time_ns, stamp_ns) - time_ns) * 1e-9, -max_prediction, max_prediction)
    predicted = position + velocity * dt
    measured = np.isfinite(detection).all(axis=1, keepdims=True)
    value = np.where(measured, predicted + alpha * (detection - predicted), predicted)
    return np.where(np.isfinite(value), value, detection)


def window_velocities(
    stamps: np.ndarray, cameras: np.ndarray, poses: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The velocity fit over a track's window: one slope per joint, one intercept per camera.

    ``stamps`` ``(N,)`` ns, ``cameras`` ``(N,)``, ``poses`` ``(N, J, 3)`` (NaN: unmeasured).
    The slope of joint ``j`` is ``sum_c sum_i (t_i - tc)(p_i - pc) / sum_c sum_i (t_i - tc)^2``
    (``tc``, ``pc``: camera ``c``'s means of the measured records), 0 where that denominator
    is not above ``DETERMINED``; the body velocity is the ``weights`` mean of the determined
    numerators over their denominators' ``weights`` mean. Returns the ``(J, 3)`` slopes,
    ``(J,)`` the denominators and the ``(3,)`` body velocity.
    """
    n_joints = poses.shape[1]
    t = (stamps - stamps[0]) * 1e-9 if len(stamps) else stamps * 1e-9
    sxx = np.zeros(n_joints)
    sxy = np.zeros((n_joints, 3))
    for camera in np.unique(cameras):
        for j in range(n_joints):
            mine = (cameras == camera) & np.isfinite(poses[:, j]).all(axis=1)
            if not mine.any():
                continue
            dt = t[mine] - t[mine].mean()
            sxx[j] += (dt**2).sum()
            sxy[j] += (dt[:, None] * (poses[mine, j] - poses[mine, j].mean(axis=0))).sum(axis=0)
    determined = sxx > DETERMINED
    slopes = np.where(determined[:, None], sxy / np.where(determined, sxx, 1.0)[:, None], 0.0)
    pooled = (sxx * weights)[determined].sum()
    body = (sxy * weights[:, None])[determined].sum(axis=0) / max(pooled, 1e-12)
    return slopes, sxx, body


def _record_poses(tracks: TrackFields, r: int, live: np.ndarray) -> np.ndarray:
    """``(N, J, 3)`` the poses of track ``r``'s records ``live``, NaN where unmeasured."""
    terms = tracks.record_terms[r, live]
    return np.where(terms[..., :1] > 0, terms[..., 3:6], np.nan)


def _take_hit(tracks: TrackFields, u: int, hits: Hits, settings: UpdateSettings) -> None:
    """Hit ``u``'s track: its pose, counters and record window after its detection."""
    r, detection = hits.rows[u], hits.canonical[u]
    alpha = settings.smoothing if tracks.hits[r] else 1.0
    tracks.positions[r] = smoothed_pose(
        tracks.positions[r],
        tracks.velocity[r],
        tracks.time_ns[r],
        detection,
        hits.stamp_ns,
        alpha,
        settings.max_prediction,
    )
    tracks.time_ns[r] = max(tracks.time_ns[r], hits.stamp_ns)
    tracks.last_hit_ns[r] = max(tracks.last_hit_ns[r], hits.stamp_ns)
    tracks.hits[r] += 1
    tracks.body_ids[r, hits.camera] = hits.det_ids[u]
    tracks.seen[r, hits.camera] = True
    tracks.n_cameras[r] = max(tracks.n_cameras[r], hits.camera + 1)
    slots = tracks.record_ns.shape[1]
    slot = (tracks.record_start[r] + tracks.record_count[r]) % slots
    tracks.record_ns[r, slot] = hits.stamp_ns
    tracks.record_camera[r, slot] = hits.camera
    tracks.record_terms[r, slot] = fit_terms(detection, (hits.stamp_ns - tracks.epoch_ns[r]) * 1e-9)
    tracks.record_count[r] += 1
    while (
        tracks.record_count[r]
        and tracks.record_ns[r, tracks.record_start[r]] < hits.stamp_ns - settings.window_ns
    ):
        tracks.record_start[r] = (tracks.record_start[r] + 1) % slots
        tracks.record_count[r] -= 1
    live = live_records(tracks, r)
    if hits.stamp_ns - tracks.epoch_ns[r] > REBASE_NS:  # a new time origin, for precision
        tracks.epoch_ns[r] = hits.stamp_ns
        for slot, pose in zip(live, _record_poses(tracks, r, live), strict=True):
            t = (tracks.record_ns[r, slot] - hits.stamp_ns) * 1e-9
            tracks.record_terms[r, slot] = fit_terms(pose, t)
    tracks.sums[r] = 0.0
    for slot in live:
        tracks.sums[r, tracks.record_camera[r, slot]] += tracks.record_terms[r, slot]


def reference_fold_hits(tracks: TrackFields, hits: Hits, settings: UpdateSettings) -> bool:
    """``fold_hits``: each hit track's pose smoothed, window moved and velocities refitted.

    The running sums are restated as the sums of the window's records' terms, and the fit is
    made from the records' poses (``window_velocities``); a track keeps its velocities when
    none of its joints is determined. Returns whether a hit track's record ring is full.
    """
    for u in range(len(hits.rows)):
        _take_hit(tracks, u, hits, settings)
    full = False
    for r in hits.rows:
        live = live_records(tracks, r)
        poses = _record_poses(tracks, r, live)
        slopes, sxx, body = window_velocities(
            tracks.record_ns[r, live], tracks.record_camera[r, live], poses, settings.weights
        )
        if (sxx > DETERMINED).any():
            tracks.velocities[r] = slopes
            tracks.velocity[r] = body
        full |= tracks.record_count[r] == tracks.record_ns.shape[1]
    return bool(full)


def reference_live_tracks(  # noqa: PLR0917 - the kernel's inputs
    last_hit_ns: np.ndarray,
    confirmed: np.ndarray,
    n_tracks: int,
    now_ns: int,
    track_timeout: float,
    tentative_timeout: float,
) -> tuple[int, np.ndarray]:
    """``live_tracks``: how many of the first ``n_tracks`` were hit within their timeout, which."""
    timeout = np.where(confirmed[:n_tracks], track_timeout, tentative_timeout)
    keep = (now_ns - last_hit_ns[:n_tracks]) * 1e-9 <= timeout
    return int(keep.sum()), keep


# ------------------------------------------------------------------------------------ hit
def reference_hit_frame(  # noqa: PLR0917 - the kernel's inputs
    tracks: TrackFields,
    frame: FrameRows,
    pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
    view: FacingView,
    layout: HitLayout,
    settings: HitSettings,
) -> tuple[np.ndarray, bool, np.ndarray, int, np.ndarray, bool]:
    """``hit_frame``: canonical poses, held axes, fold, facing, then labels, in that order."""
    rows, dets, flips = pairs
    held = HeldSides(
        tracks=tracks.positions,
        axes=tracks.sides,
        velocity=tracks.velocity,
        track_rows=rows,
        left=layout.body.left,
        right=layout.body.right,
        camera_axes=tracks.camera_sides,
        camera_ns=tracks.camera_sides_ns,
        camera=view.camera,
        stamp_ns=view.stamp_ns,
        facing=tracks.facing,
    )
    canonical, flips = reference_canonical_poses(
        frame.positions, dets, flips, layout.mirror, settings.align, layout.sides, held
    )
    if settings.align and len(layout.body.left):
        reference_hold_axes(held, canonical, tracks.last_hit_ns, view)
    hits = Hits(rows, canonical, frame.det_ids[dets], view.camera, view.stamp_ns)
    full = reference_fold_hits(tracks, hits, settings.update)
    turned = np.zeros(len(rows), dtype=bool)
    if settings.weigh:
        turned = reference_turn_facing(tracks, rows, canonical, view, layout.body, settings.priors)
    flips[turned] = ~flips[turned]
    labelled = bool(settings.label and tracks.confirmed[rows].all())
    if labelled:
        labels = (layout.mirror, tracks.velocities, rows, tracks.confirmed)
        reference_label_frame(frame.stacked, frame.index[dets], flips, *labels)
    return flips, full, turned, int(turned.sum()), tracks.ids[rows], labelled


# ---------------------------------------------------------------------------------- rigid
def hamilton(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The Hamilton product ``q ⊗ p`` of quaternions stored x, y, z, w."""
    qv, qw, pv, pw = q[:3], q[3], p[:3], p[3]
    return np.array([*(qw * pv + pw * qv + np.cross(qv, pv)), qw * pw - np.dot(qv, pv)])


def reference_move_rows(
    rows: np.ndarray, rotation: np.ndarray, translation: np.ndarray, turn: np.ndarray
) -> None:
    """``move_rows``: marker/link rows ``(N, 20)`` moved by ``R``, ``t`` and quaternion ``turn``.

    Position (1:4) ``R p + t``; orientation (4:8) normalised, then ``turn ⊗ q``; the twist and
    acceleration vectors (8:11, 11:14, 14:17, 17:20) ``R v``. NaN spreads over a field, as the
    matrix products spread it; a zero quaternion becomes NaN.
    """
    rows[:, 1:4] = rows[:, 1:4] @ rotation.T + translation
    for start in (8, 11, 14, 17):
        rows[:, start : start + 3] = rows[:, start : start + 3] @ rotation.T
    _turn(rows[:, 4:8], turn)


def _turn(quaternions: np.ndarray, turn: np.ndarray) -> None:
    """Quaternions ``(N, 4)`` normalised and turned by ``turn ⊗ q``, in place (NaN spreads)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = quaternions / vector_norm(quaternions)[:, None]
    for i, q in enumerate(unit):
        quaternions[i] = hamilton(turn, q) if np.isfinite(q).all() else np.nan


def reference_move_frame(  # noqa: PLR0917 - the kernel's inputs
    markers: np.ndarray,
    links: np.ndarray,
    boxes: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    turn: np.ndarray,
) -> None:
    """``move_frame``: a frame's marker and link rows ``(D, N, 20)`` and boxes, in place."""
    for rows in (*markers, *links):
        reference_move_rows(rows, rotation, translation, turn)
    reference_move_boxes(boxes, rotation, translation, turn)


def reference_moved_frame(  # noqa: PLR0917 - the kernel's inputs
    markers: np.ndarray,
    present: np.ndarray,
    links: np.ndarray,
    link_present: np.ndarray,
    boxes: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    turn: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """``moved_frame``: ``reference_move_frame`` on copies of the five fields, in their order."""
    out = tuple(np.copy(field) for field in (markers, present, links, link_present, boxes))
    reference_move_frame(out[0], out[2], out[4], rotation, translation, turn)
    return out


def reference_move_boxes(
    boxes: np.ndarray, rotation: np.ndarray, translation: np.ndarray, turn: np.ndarray
) -> None:
    """``move_boxes``: boxes ``(N, 22)``, centre (0:3) ``R p + t``, orientation (3:7) turned."""
    boxes[:, 0:3] = boxes[:, 0:3] @ rotation.T + translation
    _turn(boxes[:, 3:7], turn)
