"""The reliability weights of each camera's joints, known before the robust mean.

Joint ``j`` of the detection ``c`` of track ``m``, brought to the output time by its
velocity (``detections_at``), weighs::

    w = max(conf, confidence_floor)^confidence_power     (0 where the joint is not finite)
        / (1 + (age / staleness_scale)²)                  staleness
        × (1 + depth_gain · |p - camera|)^-2              depth, where the camera is known
        × flipped_weight                                  if the detection points backwards
        / (1 + oblique_gain · |sin θ|)²                   θ: the camera's angle to the body front
        × occlusion_weight                                another track's torso on its ray

``facing_weights`` judges the flips and views against the front of the track's detections
(a flipped detection is first reflected back, ``reflect``), ``occluded`` the occlusions
against the weighted median of the detections (see ``merger.py``'s docstring for why each
factor is there).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_core.compiled import refresh_stale_caches
from hiros_merger import numerics
from hiros_merger.kernel_args import BodyLayout, Observations, TrackDetections, WeightSettings
from hiros_merger.numerics import finite3, power, unit3

__all__ = ["detections_at", "facing_weights", "known_cameras", "occluded"]


@njit(cache=True, error_model="numpy")
def known_cameras(cameras: np.ndarray) -> np.ndarray:
    """``(M, C)`` whether each detection's camera position ``(M, C, 3)`` is known (finite)."""
    n_tracks, n_slots = cameras.shape[:2]
    known = np.zeros((n_tracks, n_slots), dtype=np.bool_)
    for m in range(n_tracks):
        for c in range(n_slots):
            known[m, c] = finite3(cameras[m, c, 0], cameras[m, c, 1], cameras[m, c, 2])
    return known


@njit(cache=True, error_model="numpy")
def detections_at(
    detections: TrackDetections, settings: WeightSettings, n_joints: int, known: np.ndarray
) -> Observations:
    """Each detection's joints at the output time, and the weights known before fusing.

    A joint's position is ``p + v · clip(age, ±max_extrapolation)`` (a non-finite velocity
    counts 0); an absent joint or a padding slot reads as NaN. Its
    confidence is the SDK's (1 where it is not finite). The weight is the module docstring's
    product of confidence, staleness and depth.

    ``known`` ``(M, C)``: whether each detection's camera position is.
    """
    rows, present, table = detections.rows, detections.present, detections.table
    n_tracks, n_slots = table.shape
    positions = np.empty((n_tracks, n_slots, n_joints, 3))
    velocities = np.empty((n_tracks, n_slots, n_joints, 3))
    finite = np.zeros((n_tracks, n_slots, n_joints), dtype=np.bool_)
    weight = np.zeros((n_tracks, n_slots, n_joints))
    confidences = np.empty((n_tracks, n_slots, n_joints))
    for m in range(n_tracks):
        for c in range(n_slots):
            s = table[m, c]
            age = detections.ages[m, c]
            dt = min(max(age, -settings.max_extrapolation), settings.max_extrapolation)
            stale = age / settings.staleness_scale
            for j in range(n_joints):
                valid = s >= 0 and present[s, j]
                is_finite = True
                for a in range(3):
                    p = rows[s, j, 1 + a] if valid else np.nan
                    v = rows[s, j, 8 + a] if valid else np.nan
                    velocities[m, c, j, a] = v
                    p = p + (v if math.isfinite(v) else 0.0) * dt
                    positions[m, c, j, a] = p
                    is_finite = is_finite and math.isfinite(p)
                finite[m, c, j] = is_finite
                confidence = rows[s, j, 0] if valid else np.nan
                confidence = confidence if math.isfinite(confidence) else 1.0
                confidences[m, c, j] = confidence
                w = power(max(confidence, settings.confidence_floor), settings.confidence_power)
                if not is_finite:
                    w = 0.0
                w = w / (1.0 + stale * stale)
                if known[m, c]:
                    dx = positions[m, c, j, 0] - detections.cameras[m, c, 0]
                    dy = positions[m, c, j, 1] - detections.cameras[m, c, 1]
                    dz = positions[m, c, j, 2] - detections.cameras[m, c, 2]
                    depth = math.sqrt(dx * dx + dy * dy + dz * dz)
                    w = w * math.pow(1.0 + settings.depth_gain * depth, -2.0)
                weight[m, c, j] = w
    return Observations(positions, velocities, finite, confidences, weight)


@njit(cache=True, error_model="numpy")
def body_axes(
    detections: np.ndarray, fused: np.ndarray, body: BodyLayout, up: np.ndarray
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """A track's up and front unit vectors, from its detections ``(C, J, 3)``.

    Up is the scene's ``up`` ``(3,)`` (people's mean vertical, ``Merger``), or where that is
    not known yet the ``fused`` ``(J, 3)`` skeleton's root -> neck. Front is ``side × up``,
    ``side`` the sum over the detections with all their side joints of the left hip and
    shoulder less the right ones (the tracker labels every detection of a track alike): the
    detections' torsos, which a front/back flip leaves in place, rather than the per-coordinate
    median of them, whose hips and shoulders may each come from another camera.
    """
    ux, uy, uz = up[0], up[1], up[2]
    if not finite3(ux, uy, uz):
        root, neck = body.root, body.neck
        ux, uy, uz = unit3(
            fused[neck, 0] - fused[root, 0],
            fused[neck, 1] - fused[root, 1],
            fused[neck, 2] - fused[root, 2],
        )
    sx = sy = sz = 0.0
    for c in range(len(detections)):
        dx = dy = dz = 0.0
        for i in range(len(body.left)):
            left, right = body.left[i], body.right[i]
            dx += detections[c, left, 0] - detections[c, right, 0]
            dy += detections[c, left, 1] - detections[c, right, 1]
            dz += detections[c, left, 2] - detections[c, right, 2]
        if finite3(dx, dy, dz):
            sx += dx
            sy += dy
            sz += dz
    front = unit3(sy * uz - sz * uy, sz * ux - sx * uz, sx * uy - sy * ux)
    return (ux, uy, uz), front


@njit(cache=True, error_model="numpy")
def reflect(
    positions: np.ndarray, velocities: np.ndarray, root: int, front: tuple[float, float, float]
) -> None:
    """Reflect a detection's joints ``(J, 3)`` through its frontal plane, in place.

    The plane passes through the detection's ``root`` with ``front`` as its normal; the
    velocities' components along the front are reversed alike. A front/back flip is this
    reflection with left and right relabelled (the SDK fits a body facing its camera to a
    person seen from behind): the tracker has undone the labels, this undoes the positions.
    """
    fx, fy, fz = front
    rx, ry, rz = positions[root, 0], positions[root, 1], positions[root, 2]
    if not (finite3(rx, ry, rz) and finite3(fx, fy, fz)):
        return
    for j in range(len(positions)):
        depth = (positions[j, 0] - rx) * fx + (positions[j, 1] - ry) * fy
        depth += (positions[j, 2] - rz) * fz
        speed = velocities[j, 0] * fx + velocities[j, 1] * fy + velocities[j, 2] * fz
        positions[j, 0] -= 2.0 * depth * fx
        positions[j, 1] -= 2.0 * depth * fy
        positions[j, 2] -= 2.0 * depth * fz
        velocities[j, 0] -= 2.0 * speed * fx
        velocities[j, 1] -= 2.0 * speed * fy
        velocities[j, 2] -= 2.0 * speed * fz


@njit(cache=True, error_model="numpy")
def points_backwards(
    detection: np.ndarray,
    pointers: np.ndarray,
    up: tuple[float, float, float],
    front: tuple[float, float, float],
) -> bool:
    """Whether a detection's ``(J, 3)`` forward ``pointers`` point against ``front``.

    Their sum of unit vectors across ``up`` (a non-finite component counts 0) is compared
    with the front: a front/back flip the tracker relabelled keeps its feet and nose
    reflected.
    """
    ux, uy, uz = up
    sx = sy = sz = 0.0
    for i in range(len(pointers)):
        a, b = pointers[i, 0], pointers[i, 1]
        px = detection[b, 0] - detection[a, 0]
        py = detection[b, 1] - detection[a, 1]
        pz = detection[b, 2] - detection[a, 2]
        along = px * ux + py * uy + pz * uz
        px, py, pz = unit3(px - along * ux, py - along * uy, pz - along * uz)
        sx += px if math.isfinite(px) else 0.0
        sy += py if math.isfinite(py) else 0.0
        sz += pz if math.isfinite(pz) else 0.0
    sx, sy, sz = unit3(sx, sy, sz)
    return sx * front[0] + sy * front[1] + sz * front[2] < 0


@njit(cache=True, error_model="numpy")
def view_weight(
    camera: np.ndarray,
    root: np.ndarray,
    front: tuple[float, float, float],
    settings: WeightSettings,
) -> float:
    """The view factor of a camera at ``camera`` for a body at ``root`` facing ``front``.

    ``1 / (1 + oblique_gain · |sin θ|)²``, θ the angle between the front and the direction to
    the camera (NaN: undefined).
    """
    tx, ty, tz = unit3(camera[0] - root[0], camera[1] - root[1], camera[2] - root[2])
    cosine = front[0] * tx + front[1] * ty + front[2] * tz
    if not math.isfinite(cosine):
        return cosine
    view = 1.0
    if settings.oblique_gain > 0:
        sine = math.sqrt(max(1.0 - cosine * cosine, 0.0))
        view = view / power(1.0 + settings.oblique_gain * sine, 2.0)
    return view


@njit(cache=True, error_model="numpy")
def facing_weights(  # noqa: PLR0917 - the fusion's arrays
    fused: np.ndarray,
    seen: Observations,
    cameras: np.ndarray,
    known: np.ndarray,
    body: BodyLayout,
    settings: WeightSettings,
    up: np.ndarray,
) -> None:
    """Undo each detection's front/back flip and multiply ``seen.weight`` by its view factor.

    Judged against each track's front (``body_axes``, with the scene's ``up``): a detection
    that ``points_backwards`` is reflected back (``reflect``, its positions and velocities in
    ``seen``) and weighs ``flipped_weight`` times its weight; one whose camera is known weighs
    its ``view_weight`` (a NaN view leaves the weight as it is), seen from the ``fused``
    ``(M, J, 3)`` root.
    """
    positions, weight = seen.positions, seen.weight
    n_tracks, n_slots, n_joints = weight.shape
    for m in range(n_tracks):
        up_m, front = body_axes(positions[m], fused[m], body, up)
        for c in range(n_slots):
            backwards = len(body.pointers) and points_backwards(
                positions[m, c], body.pointers, up_m, front
            )
            if backwards:
                reflect(positions[m, c], seen.velocities[m, c], body.root, front)
                for j in range(n_joints):
                    weight[m, c, j] = weight[m, c, j] * settings.flipped_weight
            if known[m, c]:
                view = view_weight(cameras[m, c], fused[m, body.root], front, settings)
                if math.isfinite(view):
                    for j in range(n_joints):
                        weight[m, c, j] = weight[m, c, j] * view


@njit(cache=True, error_model="numpy")
def rays(positions: np.ndarray, camera: np.ndarray, radius: float, out: np.ndarray) -> float:
    """Each joint's unit direction from ``camera`` and distance into ``out`` ``(J, 4)``.

    Returns the squared distance beyond which a point blocks no joint's ray (see
    ``occluded``; -1 when no joint is farther than ``radius``).
    """
    reach = -1.0
    for j in range(len(positions)):
        rx = positions[j, 0] - camera[0]
        ry = positions[j, 1] - camera[1]
        rz = positions[j, 2] - camera[2]
        length = math.sqrt(rx * rx + ry * ry + rz * rz)
        out[j, 0], out[j, 1], out[j, 2] = rx / length, ry / length, rz / length
        out[j, 3] = length
        if length - radius > 0:
            reach = max(reach, (length - radius) ** 2 + radius * radius + 1e-6)
    return reach


@njit(cache=True, error_model="numpy")
def torso_points(  # noqa: PLR0917
    fused: np.ndarray,
    m: int,
    torso: np.ndarray,
    camera: np.ndarray,
    reach: float,
    points: np.ndarray,
) -> int:
    """Other tracks' torso points ``q - camera`` and their squared norm into ``points``.

    Only those nearer than ``reach`` (squared); returns how many.
    """
    count = 0
    for other in range(len(fused)):
        if other == m:
            continue
        for t in torso:
            qx = fused[other, t, 0] - camera[0]
            qy = fused[other, t, 1] - camera[1]
            qz = fused[other, t, 2] - camera[2]
            squared = qx * qx + qy * qy + qz * qz
            if squared < reach:
                points[count, 0], points[count, 1] = qx, qy
                points[count, 2], points[count, 3] = qz, squared
                count += 1
    return count


@njit(cache=True, error_model="numpy")
def occluded(  # noqa: PLR0917
    fused: np.ndarray,
    positions: np.ndarray,
    cameras: np.ndarray,
    known: np.ndarray,
    torso: np.ndarray,
    radius: float,
    weight: np.ndarray,
    factor: float,
) -> None:
    """Multiply ``weight`` by ``factor`` where the camera ray passes another track's torso.

    A torso point ``q`` blocks the ray from camera ``o`` to joint ``p`` when it lies within
    ``radius`` of the ray (|rel|² - along² decides, except within 1e-9 m² of the radius where
    the point minus its projection does) and between ``o`` and ``p``. Per detection, only the
    torso points nearer to the camera than ``reach`` are tried: one farther than
    ``sqrt((|p - o| - radius)² + radius²)`` for every joint ``p`` blocks none (the bound has
    1e-6 m² to spare over the test's 1e-9 and its rounding, so the result is the same).
    """
    n_tracks, n_slots, n_joints = positions.shape[:3]
    directions = np.empty((n_joints, 4))  # each joint's unit direction from the camera, distance
    points = np.empty((n_tracks * len(torso), 4))  # torso points near enough: q - o, |q - o|²
    limit = radius * radius
    for m in range(n_tracks):
        for c in range(n_slots):
            if not known[m, c]:
                continue
            reach = rays(positions[m, c], cameras[m, c], radius, directions)
            count = torso_points(fused, m, torso, cameras[m, c], reach, points)
            for j in range(n_joints):
                dx, dy, dz = directions[j, 0], directions[j, 1], directions[j, 2]
                length = directions[j, 3]
                for i in range(count):
                    qx, qy, qz = points[i, 0], points[i, 1], points[i, 2]
                    along = dx * qx + dy * qy + dz * qz
                    across_sq = points[i, 3] - along * along
                    close = across_sq < limit
                    if abs(across_sq - limit) < 1e-9:
                        ex = qx - along * dx
                        ey = qy - along * dy
                        ez = qz - along * dz
                        close = math.sqrt(ex * ex + ey * ey + ez * ez) < radius
                    if close and along > 0 and along < length - radius:
                        weight[m, c, j] *= factor
                        break


refresh_stale_caches(globals(), numerics)  # the kernels above call numerics' kernels
