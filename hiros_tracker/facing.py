"""Facing evidence: whether each track's sides are right, weighed detection by detection.

An SDK sometimes reports a body front/back flipped (its left labelled right). Each detection
of a track gives log-odds that the track's sides are right (``_facing_evidence``): the front
its sides say against the way its feet and nose point, each hypothesis weighted by the flip
prior of the view its camera would have, and walking forward as extra evidence. The log-odds
fade over the facing memory (a longer one while the track stands); a track whose log-odds fall
below minus the threshold is relabelled, and so is one whose doubt passes ``DOUBT_LIMIT``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_core.compiled import refresh_stale_caches
from hiros_tracker import labels
from hiros_tracker.kernel_args import FacingBody, FacingPriors, FacingView, TrackFields
from hiros_tracker.labels import relabel

__all__ = [
    "CLEAR_CONTRADICTION",
    "CONTRADICTING_VIEWS",
    "DOUBT_LIMIT",
    "VERDICT_LIFETIME_S",
    "turn_facing",
]

DOUBT_LIMIT = 40.0
"""Log-odds at which a track whose cameras keep disagreeing with it is turned at once.

A track's doubt sums its cameras' evidence against its sides (the walking term left out) over
an unbroken run of its detections that contradict it, never below 0 (a CUSUM, Page 1954), so
that a mirrored track is turned within a fraction of a second whatever its facing log-odds had
grown to over seconds of agreement (``_doubt_step``):

- a walking track's run lasts while it walks backwards by its sides (a clean 3-camera walk:
  turned after 0.5 s instead of 1.3 s). A right track at the end of a pass, still moving the
  old way while it faces the new one, walks backwards too, but its cameras agree with it;
- a standing track's run lasts while ``CONTRADICTING_VIEWS`` cameras clearly contradict it and
  none supports it. Weak contradictions (a person seen from behind, whom SDKs report facing
  them) do not feed it: a person standing with their back to every camera looks like that
  detection after detection, and the long standing memory must keep them."""

CLEAR_CONTRADICTION = 1.5
"""Log-odds against a track's sides beyond which a detection clearly contradicts it.

A camera that sees the body from the side gives about -2.2 (flip prior 0.1 under both
hypotheses). One that sees the track's front gives -1.1 and one that sees its back -0.25: the
other hypothesis puts the camera behind the person, where SDKs flip often (0.7)."""

CONTRADICTING_VIEWS = 2
"""Cameras whose last verdicts must clearly contradict a standing track to feed its doubt.

One camera is not enough: SDKs also flip in side views now and then, and a
person turned slightly away is a side view by the track's front and a back view by the SDK's."""

VERDICT_LIFETIME_S = 0.4
"""Seconds a camera's last verdict on a track counts towards the standing doubt."""


@njit(cache=True, error_model="numpy")
def _unit3(x: float, y: float, z: float) -> tuple[float, float, float]:
    """A vector scaled to unit length; zero or NaN gives NaN."""
    norm = math.sqrt(x * x + y * y + z * z)
    if norm == 0.0:
        return np.nan, np.nan, np.nan
    return x / norm, y / norm, z / norm


@njit(cache=True, error_model="numpy")
def _flat3(  # noqa: PLR0917 - two vectors as scalars (no arrays in the inner loop)
    x: float, y: float, z: float, ux: float, uy: float, uz: float
) -> tuple[float, float, float]:
    """A vector with its component along the unit ``u`` removed."""
    along = x * ux + y * uy + z * uz
    return x - along * ux, y - along * uy, z - along * uz


@njit(cache=True, error_model="numpy")
def _trunk_mean(
    positions: np.ndarray, rows: np.ndarray, root: int, neck: int
) -> tuple[np.ndarray, int]:
    """``(3,)`` mean unit root -> neck over tracks ``rows`` where it is finite, and how many."""
    mean = np.zeros(3)
    count = 0
    for r in rows:
        x, y, z = _unit3(
            positions[r, neck, 0] - positions[r, root, 0],
            positions[r, neck, 1] - positions[r, root, 1],
            positions[r, neck, 2] - positions[r, root, 2],
        )
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
            mean[0] += x
            mean[1] += y
            mean[2] += z
            count += 1
    if count:
        mean /= count
    return mean, count


@njit(cache=True, error_model="numpy")
def _facing_evidence(  # noqa: PLR0917 - one loop over the frame's pairs
    tracks: TrackFields,
    rows: np.ndarray,
    canonical: np.ndarray,
    up: np.ndarray,
    view: FacingView,
    body: FacingBody,
    priors: FacingPriors,
) -> tuple[np.ndarray, np.ndarray]:
    """``(U,)`` log-odds each detection's view, ``(U,)`` its track's walk, give on its sides.

    Tracks ``rows`` ``(U,)`` were hit by ``canonical`` ``(U, J, 3)``; ``up`` ``(3,)`` is the
    world's up (NaN: unknown, no evidence). With ``flat(v) = v - (v·up) up``:

    - the track's front ``f = unit(L × up)``, ``L`` the sum of its left shoulder and hip less
      the right ones (of the track's pose);
    - the detection's forward ``a = unit(sum_i unit(flat(p_b - p_a)))`` over the forward
      ``pointers`` ``(a, b)`` (a pair with a missing joint adds nothing); it looks flipped
      when ``a·f < 0``;
    - with the camera's position known, ``cos = f·unit(flat(camera - root))``: the track seen
      from the back (cos < -0.5) takes ``flip_prior_back``, else ``flip_prior``, under each
      hypothesis (reversed: front ``-f``); the evidence is ``_independent_evidence``; without
      it ``±log((1 - p) / p)``, ``p`` the flip prior, negative when flipped;
    - a track moving faster than ``walking_speed`` (its ``flat`` body velocity) adds
      ``walking_evidence`` when it moves along ``f``, subtracts it when against.

    Evidence that is not finite counts 0; a track without walking evidence (slower than
    ``walking_speed``, or of unknown front) stands.

    """
    positions, velocity = tracks.positions, tracks.velocity
    camera, has_camera = view.camera_position, view.has_camera
    root, left, right, pointers = body.root, body.left, body.right, body.pointers
    flip_prior, flip_prior_back = priors.flip_prior, priors.flip_prior_back
    walking_speed, walking_evidence = priors.walking_speed, priors.walking_evidence
    n_pairs = len(rows)
    view_evidence = np.zeros(n_pairs)
    walk_evidence = np.zeros(n_pairs)
    ux, uy, uz = up[0], up[1], up[2]
    for u in range(n_pairs):
        r = rows[u]
        lx = ly = lz = 0.0
        for i in range(len(left)):
            lx += positions[r, left[i], 0]
            ly += positions[r, left[i], 1]
            lz += positions[r, left[i], 2]
        rx = ry = rz = 0.0
        for i in range(len(right)):
            rx += positions[r, right[i], 0]
            ry += positions[r, right[i], 1]
            rz += positions[r, right[i], 2]
        lx, ly, lz = lx - rx, ly - ry, lz - rz
        fx, fy, fz = _unit3(ly * uz - lz * uy, lz * ux - lx * uz, lx * uy - ly * ux)
        ax = ay = az = 0.0
        for i in range(len(pointers)):
            a, b = pointers[i, 0], pointers[i, 1]
            sx, sy, sz = _flat3(
                canonical[u, b, 0] - canonical[u, a, 0],
                canonical[u, b, 1] - canonical[u, a, 1],
                canonical[u, b, 2] - canonical[u, a, 2],
                ux,
                uy,
                uz,
            )
            sx, sy, sz = _unit3(sx, sy, sz)
            ax += sx if math.isfinite(sx) else 0.0
            ay += sy if math.isfinite(sy) else 0.0
            az += sz if math.isfinite(sz) else 0.0
        ax, ay, az = _unit3(ax, ay, az)
        agreement = ax * fx + ay * fy + az * fz
        flipped = agreement < 0
        if has_camera:
            cx, cy, cz = _flat3(
                camera[0] - positions[r, root, 0],
                camera[1] - positions[r, root, 1],
                camera[2] - positions[r, root, 2],
                ux,
                uy,
                uz,
            )
            cx, cy, cz = _unit3(cx, cy, cz)
            cosine = fx * cx + fy * cy + fz * cz
            prior_right = flip_prior_back if cosine < -0.5 else flip_prior
            prior_wrong = flip_prior_back if -cosine < -0.5 else flip_prior
            value = _independent_evidence(flipped, prior_right, prior_wrong)
        else:  # no camera pose: a flipped-looking detection is simply evidence against
            value = (-1.0 if flipped else 1.0) * math.log((1.0 - flip_prior) / flip_prior)
        if not math.isfinite(agreement):  # no forward pointer seen, or no front: no evidence
            value = 0.0
        walk = _walking(velocity[r], (fx, fy, fz), up, walking_speed, walking_evidence)
        view_evidence[u] = value if math.isfinite(value) else 0.0
        walk_evidence[u] = walk if math.isfinite(walk) else 0.0
    return view_evidence, walk_evidence


@njit(cache=True, error_model="numpy")
def _doubt_step(  # noqa: PLR0917 - one detection's verdict on its track
    tracks: TrackFields, r: int, camera: int, stamp_ns: int, view: float, walk: float
) -> float:
    """One detection's step of track ``r``'s doubt run (``DOUBT_LIMIT``); records its verdict.

    ``view`` and ``walk`` are its evidence on the track's sides. Walking: minus ``view`` while
    the track walks backwards by its sides, else 0 (the run ends). Standing, over the cameras'
    verdicts of the last ``VERDICT_LIFETIME_S``: minus ``view`` when ``CONTRADICTING_VIEWS``
    clearly contradict the sides and none supports them, else 0.
    """
    if camera < tracks.camera_verdicts.shape[1]:
        tracks.camera_verdicts[r, camera] = view
        tracks.camera_verdicts_ns[r, camera] = stamp_ns
    if walk != 0.0:
        return -view if walk < 0.0 else 0.0
    clear = 0
    for k in range(tracks.camera_verdicts.shape[1]):
        if stamp_ns - tracks.camera_verdicts_ns[r, k] > VERDICT_LIFETIME_S * 1e9:
            continue
        verdict = tracks.camera_verdicts[r, k]
        if verdict > 0.0:
            return 0.0
        if verdict < -CLEAR_CONTRADICTION:
            clear += 1
    return -view if clear >= CONTRADICTING_VIEWS else 0.0


@njit(cache=True, error_model="numpy")
def _walking(
    velocity: np.ndarray,
    front: tuple[float, float, float],
    up: np.ndarray,
    walking_speed: float,
    walking_evidence: float,
) -> float:
    """Log-odds a track's walk gives that it faces ``front`` (unit, across ``up``).

    ``walking_evidence`` when its ``velocity`` ``(3,)`` across the up is faster than
    ``walking_speed`` and along ``front``, minus it when against, else 0 (NaN: unknown front).
    """
    wx, wy, wz = _flat3(velocity[0], velocity[1], velocity[2], up[0], up[1], up[2])
    speed = math.sqrt(wx * wx + wy * wy + wz * wz)
    along = (wx * front[0] + wy * front[1] + wz * front[2]) / max(speed, 1e-9)
    if not speed > walking_speed:
        return 0.0
    if along > 0:
        return walking_evidence
    if along < 0:
        return -walking_evidence
    return along  # 0, or NaN


@njit(cache=True, error_model="numpy")
def _independent_evidence(flipped: bool, prior_right: float, prior_wrong: float) -> float:
    """Log-odds of one detection taken on its own (each hypothesis' view prior)."""
    likely_right = prior_right if flipped else 1.0 - prior_right
    likely_wrong = 1.0 - prior_wrong if flipped else prior_wrong
    return math.log(likely_right / likely_wrong)


@njit(cache=True, error_model="numpy")
def turn_facing(  # noqa: PLR0917 - the tracks, the frame's pairs, the view, body and priors
    tracks: TrackFields,
    rows: np.ndarray,
    canonical: np.ndarray,
    view: FacingView,
    body: FacingBody,
    priors: FacingPriors,
) -> np.ndarray:
    """Weigh one frame's evidence on each hit track's facing; relabel tracks found reversed.

    For a detection (in its track's labelling) with anatomical forward ``a`` and a track
    front ``f``: if the track is right, the detection is flipped iff ``a·f < 0``; if the
    track is mirrored, the opposite, and its front is ``-f``. Each hypothesis' likelihood
    uses the flip prior for the view the camera would have (back: cos(f, to camera) < -0.5);
    walking forward adds evidence (``_facing_evidence``).

    Track ``r = rows[u]`` (hit by ``canonical[u]``) keeps log-odds ``facing[r]`` that its
    sides are right, set at ``facing_ns[r]``: ``facing[r] = facing[r] * exp(-dt /
    memory) + evidence[u]`` (``dt`` s since then, at least 0; the memory is ``facing_memory``,
    or ``facing_memory_standing`` for a track without walking evidence); its doubt
    (``DOUBT_LIMIT``) past the limit sets them below the threshold. Below
    ``-facing_threshold`` the track is relabelled with ``body.mirror`` (all parts,
    ``relabel``), its log-odds, held left-right axes (its own and its cameras') and its
    cameras' verdicts negated.
    ``tracks`` changes in place, and ``view.up`` too (``_update_up``, before the evidence).

    Returns:
        ``(U,)`` which tracks were relabelled.

    """
    facing, facing_ns = tracks.facing, tracks.facing_ns
    threshold, stamp_ns = priors.facing_threshold, view.stamp_ns
    world_up = _update_up(view.up, tracks.positions, rows, body.root, body.neck)
    views, walks = _facing_evidence(tracks, rows, canonical, world_up, view, body, priors)
    turned = np.zeros(len(rows), dtype=np.bool_)
    for u in range(len(rows)):
        r = rows[u]
        memory = priors.facing_memory if walks[u] != 0.0 else priors.facing_memory_standing
        fade = math.exp(-max(stamp_ns - facing_ns[r], 0) * 1e-9 / memory)
        facing[r] = facing[r] * fade + views[u] + walks[u]
        facing_ns[r] = stamp_ns
        step = _doubt_step(tracks, r, view.camera, stamp_ns, views[u], walks[u])
        tracks.doubt[r] = max(tracks.doubt[r] + step, 0.0) if step != 0.0 else 0.0
        if tracks.doubt[r] > DOUBT_LIMIT:
            facing[r] = min(facing[r], -threshold - 1.0)
        if facing[r] < -threshold:
            relabel(tracks, r, body.mirror)
            for a in range(3):
                tracks.sides[r, a] = -tracks.sides[r, a]
            tracks.camera_sides[r] = -tracks.camera_sides[r]
            tracks.camera_verdicts[r] = -tracks.camera_verdicts[r]
            facing[r] = -facing[r]
            turned[u] = True
            tracks.doubt[r] = 0.0
    return turned


@njit(cache=True, error_model="numpy")
def _update_up(
    up: np.ndarray, positions: np.ndarray, rows: np.ndarray, root: int, neck: int
) -> np.ndarray:
    """``(3,)`` the world's up: a running mean of the hit tracks' trunks (root -> neck).

    ``up`` ``(4,)`` is the state: x, y, z and whether it is known (0 before the first trunk;
    NaN is returned then). The world frame may be a camera's (y down) or z-up; people stand
    most of the time, and one bending person must not tilt the front the facing compares with.
    """
    mean, count = _trunk_mean(positions, rows, root, neck)
    if count:
        for a in range(3):
            up[a] = mean[a] if up[3] == 0.0 else up[a] + 0.01 * (mean[a] - up[a])
        norm = math.sqrt(up[0] * up[0] + up[1] * up[1] + up[2] * up[2])
        for a in range(3):
            up[a] = up[a] / norm
        up[3] = 1.0
    if up[3] == 0.0:
        return np.full(3, np.nan)
    return up[:3].copy()


refresh_stale_caches(globals(), labels)  # turn_facing calls labels.relabel
