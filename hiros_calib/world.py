"""A gravity-aligned world frame from the people: z up, the floor at z = 0 (REP-103).

The calibration solves every camera's pose relative to the reference camera, whose optical
frame has y down and z forward and is tilted as the camera happens to be. People stand on the
floor, so they tell where it is:

- **Up.** Things that stay at one height as people walk lie on planes parallel to the
  floor: the places their feet rest (a foot joint that hardly moves), all on the floor itself,
  and each person's torso (the mean of the spine joints), at that person's own height. Up is
  the tilt that levels them all at once (a Cauchy-reweighted least-squares fit of the two tilt
  angles, each torso with its own height). A group tells the tilt only along the directions
  it spreads over: one person walking to and fro on one line says nothing about the tilt
  across it. Where the groups together do not spread in two directions (gestures on the
  spot), the body's mean vertical (pelvis to neck, averaged over the frames) is used instead,
  kept perpendicular to the direction the resting feet do spread along.
- **The floor.** The resting feet's median height along up, less the height of the foot
  joint above the floor when the foot rests (:data:`FOOT_JOINT_HEIGHT`).
- **The axes.** x along the reference camera's view projected on the floor, y to its left,
  the origin on the floor below the reference camera.

Every camera's pose then becomes ``world <- reference <- camera``. The fit's figures (how far
the resting feet lie from the plane, the tilt it corrected, what up came from) go into the
reference camera's quality, with why the floor may be doubtful (:meth:`FloorFit.doubts`).
How well this does on the simulator, and what was tried: docs/world-frame.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_calib.tracks import BodyTrack
from hiros_core.calibration import Calibration
from hiros_core.geometry import RigidTransform

__all__ = [
    "FOOT_JOINT_HEIGHT",
    "FloorFit",
    "align_to_floor",
    "fit_floor",
    "place_in_world",
    "resting_feet",
    "speed_over_baseline",
]

FOOT_JOINT_HEIGHT = {"Foot": 0.11, "Ankle": 0.18}
"""Height (m) of a resting foot's joint above the floor, by joint, as the Azure Kinect SDK
reports it: on the UNIPD-BPE take (against an Xsens suit whose floor is known) its foot joint
rests 11 cm and its ankle 18 cm above the floor, bent over or upright, well above the
anatomical joints (docs/world-frame.md, session 15). The only real reference: Kinect v2
skeletons use the same."""

RESTING_SPEED = 0.15
"""A foot joint slower than this (m/s) is taken to rest on the floor."""

SPEED_BASELINE = 0.4
"""Seconds over which a foot's speed is measured."""

MIN_SPREAD = 0.25
"""A group of points (the resting feet, one person's torso) tells the tilt only along the
directions it spreads over this far (m, standard deviation)."""

MIN_COVERAGE = 0.1
"""The groups together must tell the tilt over this spread (m, standard deviation over all
samples) in every direction; otherwise up is the body's vertical. Two groups each spread along
nearly the same line would pin the tilt across it only by the small angle between them."""

SEEN_WEIGHT = 0.99
"""A torso joint counts where its weight is the best the camera reports (seen, not predicted;
files without confidences have weight 1 everywhere)."""

DOUBT_POINTS = 200
"""Fewer resting-foot samples than this make the floor doubtful."""

DOUBT_FLOOR_ERROR = 0.01
"""A floor height whose standard error (m, :func:`_floor_error`) is above this is doubtful: its
95 % interval (two standard errors) is then wider than the 2 cm the world is meant to hold."""

DOUBT_SPREAD = 1.0
"""Up moving more than this (deg) when one camera is left out makes it doubtful."""

DOUBT_POSE_UNCERTAINTY = 1.0
"""A camera pose whose rotation is uncertain by more than this (deg) makes up doubtful: every
sample it gives reaches up through it, so up can be off by about as much."""

TORSO_JOINTS = (("Pelvis", "SpineNaval", "SpineChest", "Neck"), ("SpineBase", "SpineMid",
                "SpineShoulder", "Neck"))  # fmt: skip
"""The torso joints whose mean keeps one height as a person walks (Azure Kinect, Kinect v2)."""


@dataclass
class FloorFit:
    """Up and the floor in the reference camera's frame, with how well they were found."""

    up: np.ndarray
    """``(3,)`` unit vector, reference camera frame."""
    floor_height: float
    """The floor's position along ``up`` (m): points ``p`` with ``p @ up == floor_height``."""
    residual_m: float
    """RMS distance of the resting feet from their plane (m)."""
    points: int
    """Resting-foot samples used."""
    source: str
    """``"feet and torsos"`` (their planes) or ``"body"`` (the mean pelvis-to-neck direction)."""
    up_spread_deg: float = math.nan
    """How far up moves (deg) when any one camera is left out; NaN with one camera or when up
    is the body's."""
    floor_error_m: float = math.nan
    """Standard error of ``floor_height`` (m, :func:`_floor_error`); NaN where it cannot be
    told (resting feet from fewer than two cameras)."""
    doubtful_poses: tuple[str, ...] = ()
    """Cameras whose pose the calibration flags as doubtful (:func:`align_to_floor`): their
    samples went into up and the floor through that pose."""
    pose_uncertainty_deg: float = math.nan
    """The largest rotation uncertainty (deg) the split halves of the cameras' pair poses give
    (``pose_uncertainty_deg`` in their quality, :func:`align_to_floor`); NaN with one camera."""

    def quality(self) -> dict[str, Any]:
        """The figures for the calibration file."""
        # from the camera's vertical axis: y down (Azure Kinect) or y up (Kinect v2)
        tilt = math.degrees(math.acos(float(np.clip(abs(self.up[1]), 0.0, 1.0))))
        return {
            "floor_residual_cm": round(100 * self.residual_m, 2),
            "floor_tilt_deg": round(tilt, 2),
            "floor_points": self.points,
            "floor_up_from": self.source,
            "floor_up_spread_deg": (
                round(self.up_spread_deg, 2) if math.isfinite(self.up_spread_deg) else None
            ),
            "floor_height_error_cm": (
                round(100 * self.floor_error_m, 2) if math.isfinite(self.floor_error_m) else None
            ),
            "floor_doubtful": "; ".join(self.doubts()),
        }

    def doubts(self) -> list[str]:
        """Why this floor may be off by more than 2 cm or up by more than 1 deg (empty: none seen).

        The floor's own uncertainty decides, not how noisy the feet are: many noisy samples
        can pin a floor down, and a few quiet ones with one offset cannot. The other limits are
        where the simulator's scenes went wrong; see docs/world-frame.md.
        """
        doubts = []
        if self.points < DOUBT_POINTS:
            doubts.append(f"only {self.points} resting-foot samples (< {DOUBT_POINTS})")
        if self.floor_error_m > DOUBT_FLOOR_ERROR:
            doubts.append(
                f"the floor height is known to {100 * self.floor_error_m:.1f} cm (standard "
                f"error over the cameras, > {100 * DOUBT_FLOOR_ERROR:.0f} cm)"
            )
        if self.doubtful_poses:
            doubts.append(
                f"up and the floor rest on the pose of {', '.join(self.doubtful_poses)}, which "
                "the calibration flags as doubtful"
            )
        if self.pose_uncertainty_deg > DOUBT_POSE_UNCERTAINTY:
            doubts.append(
                f"up rests on camera poses whose split halves leave their rotation uncertain "
                f"by {self.pose_uncertainty_deg:.1f} deg (> {DOUBT_POSE_UNCERTAINTY:g})"
            )
        if self.source != "feet and torsos":
            doubts.append("up is the bodies' mean vertical: people lean")
        elif self.up_spread_deg > DOUBT_SPREAD:
            doubts.append(
                f"up moves {self.up_spread_deg:.1f} deg when one camera is left out "
                f"(> {DOUBT_SPREAD:g})"
            )
        return doubts


def _joint(track: BodyTrack, names: tuple[str, ...]) -> list[int]:
    return [track.layout.joint_names.index(n) for n in names if n in track.layout.joint_names]


def resting_feet(track: BodyTrack) -> tuple[np.ndarray, float] | None:
    """``(N, 3)`` resting foot positions (camera frame) and their joint's height, or None.

    The foot joint where the layout has one, else the ankle; a joint rests where it moves
    slower than :data:`RESTING_SPEED` over :data:`SPEED_BASELINE`.
    """
    for kind, height in FOOT_JOINT_HEIGHT.items():
        joints = _joint(track, (f"{kind}Left", f"{kind}Right"))
        if len(joints) == 2 and len(track.times) >= 3:
            positions = track.positions[:, joints]  # (T, 2, 3)
            resting = (speed_over_baseline(positions, track.times) < RESTING_SPEED) & (
                track.weights[:, joints] > 0
            )
            return positions[resting], height
    return None


def speed_over_baseline(positions: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``(T, K)`` speed (m/s) over ``SPEED_BASELINE``, NaN at the ends.

    Frame to frame, the SDKs' jitter alone would make a resting foot seem to move at
    decimetres per second.
    """
    speed = np.full(positions.shape[:2], np.nan)
    step = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    half = max(1, round(0.5 * SPEED_BASELINE / step)) if step > 0 else 1
    if len(times) <= 2 * half:
        return speed
    moved = np.linalg.norm(positions[2 * half :] - positions[: -2 * half], axis=2)
    elapsed = (times[2 * half :] - times[: -2 * half])[:, None]
    speed[half:-half] = moved / elapsed
    return speed


def _body_vertical(track: BodyTrack) -> np.ndarray | None:
    """``(T, 3)`` pelvis-to-neck unit vectors (camera frame), or None without those joints."""
    pairs = (_joint(track, names) for names in (("Pelvis", "Neck"), ("SpineBase", "SpineShoulder")))
    joints = next((pair for pair in pairs if len(pair) == 2), None)
    if joints is None:  # (Kinect v2 has a Neck but no Pelvis: both joints must be found)
        return None
    spine = track.positions[:, joints[1]] - track.positions[:, joints[0]]
    norm = np.linalg.norm(spine, axis=1, keepdims=True)
    ok = np.isfinite(norm[:, 0]) & (norm[:, 0] > 0.2)
    return spine[ok] / norm[ok]


def _torso_centres(track: BodyTrack) -> np.ndarray | None:
    """``(N, 3)`` the mean of the torso joints (camera frame) where all are seen, or None.

    Joints the SDK only predicts (hidden behind the body or another person) are left out:
    they are several times noisier.
    """
    for names in TORSO_JOINTS:
        joints = _joint(track, names)
        if len(joints) == len(names):
            seen = (track.weights[:, joints] >= SEEN_WEIGHT).all(axis=1)
            centres = track.positions[seen][:, joints].mean(axis=1)
            return centres[np.isfinite(centres).all(axis=1)]
    return None


@dataclass
class _Seen:
    """What one camera saw that lies on planes parallel to the floor (reference frame)."""

    camera: str
    feet: np.ndarray
    """``(N, 3)`` resting feet: all on the floor."""
    torsos: list[np.ndarray]
    """Per track, ``(M, 3)`` torso centres: each person at their own height."""


@dataclass
class _Source:
    """Points of one kind, each group on its own level plane, with one noise scale."""

    points: np.ndarray  # (N, 3) reference frame
    groups: np.ndarray  # (N,) group index 0..G-1
    weights: np.ndarray  # (N,) robust weights, updated by the fit

    @classmethod
    def of(cls, groups: list[np.ndarray]) -> _Source | None:
        """The groups' points, or None without any."""
        groups = [g for g in groups if len(g)]
        if not groups:
            return None
        points = np.concatenate(groups)
        index = np.concatenate([np.full(len(g), k) for k, g in enumerate(groups)])
        return cls(points, index, np.ones(len(points)))


def _sources(seen: list[_Seen]) -> list[_Source]:
    """The cameras' resting feet (one group: one floor) and torso centres (a group a track)."""
    feet = _Source.of([np.concatenate([s.feet for s in seen])])
    torsos = _Source.of([t for s in seen for t in s.torsos])
    return [source for source in (feet, torsos) if source is not None]


def _gather(
    tracks: dict[str, list[BodyTrack]], poses: dict[str, RigidTransform]
) -> tuple[list[_Seen], np.ndarray, list[np.ndarray]]:
    """Per camera its resting feet and torso centres; the feet's joint heights; body verticals.

    Everything in the reference frame.
    """
    seen, heights, verticals = [], [], []
    for camera, pose in poses.items():
        feet, torsos = [], []
        for track in tracks.get(camera, []):
            rest = resting_feet(track)
            if rest is not None and len(rest[0]):
                points = pose.apply(rest[0])
                feet.append(points[np.isfinite(points).all(axis=1)])
                heights.append(np.full(len(feet[-1]), rest[1]))
            centres = _torso_centres(track)
            if centres is not None and len(centres) >= 10:
                torsos.append(pose.apply(centres))
            vertical = _body_vertical(track)
            if vertical is not None and len(vertical):
                verticals.append(pose.rotate(vertical))
        seen.append(
            _Seen(
                camera,
                np.concatenate(feet) if feet else np.zeros((0, 3)),
                torsos,
            )
        )
    return seen, np.concatenate(heights) if heights else np.zeros(0), verticals


def fit_floor(
    tracks: dict[str, list[BodyTrack]], poses: dict[str, RigidTransform]
) -> FloorFit | None:
    """Up and the floor height in the reference frame from every camera's tracks.

    ``poses`` maps each camera to its ``reference <- camera`` transform. None when no
    camera saw a body with both a vertical and resting feet.
    """
    seen, joint_height, verticals = _gather(tracks, poses)
    points = np.concatenate([s.feet for s in seen]) if seen else np.zeros((0, 3))
    if len(points) < 10 or not verticals:
        return None
    body_up = np.concatenate(verticals).mean(axis=0)
    body_up /= np.linalg.norm(body_up)
    up = _tilt_fit(_sources(seen), body_up)
    if up is None:
        up, source, spread = *_body_up(points, body_up), math.nan
    else:
        up, source = (up if up @ body_up > 0 else -up), "feet and torsos"
        spread = _leave_one_out_spread(seen, up)
    along = points @ up - joint_height
    floor = float(np.median(along))
    scatter = along - floor
    inliers = np.abs(scatter) < 3 * max(1.4826 * float(np.median(np.abs(scatter))), 0.005)
    residual = float(np.sqrt(np.mean(scatter[inliers] ** 2)))
    cameras = np.concatenate([np.full(len(s.feet), k) for k, s in enumerate(seen)])
    error = _floor_error(along[inliers], cameras[inliers])
    return FloorFit(up, floor, residual, int(inliers.sum()), source, spread, error)


def _floor_error(heights: np.ndarray, cameras: np.ndarray) -> float:
    """Standard error (m) of the floor height from feet ``heights`` grouped by camera.

    The samples one camera gives are not independent: they share the SDK's offset of each
    person's feet in height (the left and the right alike on real data, see
    docs/world-frame.md), the camera's pose error, and noise correlated over a fraction of a
    second. So each camera gives one floor (its samples' median) and the floor's standard
    error is that of their sample-weighted mean, counted from how far they scatter (the
    clustered standard error, with its small-sample factor). NaN with fewer than two cameras.
    """
    labels, counts = np.unique(cameras, return_counts=True)
    if len(labels) < 2:
        return math.nan
    floors = np.array([np.median(heights[cameras == label]) for label in labels])
    weights = counts / counts.sum()
    mean = float(weights @ floors)
    variance = len(labels) / (len(labels) - 1) * float(weights**2 @ (floors - mean) ** 2)
    return math.sqrt(variance)


def _leave_one_out_spread(seen: list[_Seen], up: np.ndarray) -> float:
    """The largest angle (deg) by which up moves when one camera's samples are left out.

    What the scatter of the samples alone cannot show: a camera whose pose is off tilts
    everything it saw. NaN with a single camera.
    """
    angles = []
    for left_out in range(len(seen) if len(seen) > 1 else 0):
        others = _tilt_fit(_sources(seen[:left_out] + seen[left_out + 1 :]), up)
        if others is not None:
            angles.append(math.degrees(math.acos(min(1.0, abs(float(others @ up))))))
    return max(angles) if angles else math.nan


def _body_up(points: np.ndarray, body_up: np.ndarray) -> tuple[np.ndarray, str]:
    """Up where no plane is pinned down: the body's vertical, across the feet's line if any."""
    values, vectors = np.linalg.eigh(np.cov((points - np.median(points, axis=0)).T))
    if np.sqrt(max(values[2], 0.0)) >= MIN_SPREAD:
        # feet along one line (walking to and fro): up is perpendicular to it
        line = vectors[:, 2]
        up = body_up - (body_up @ line) * line
        return up / np.linalg.norm(up), "body"
    return body_up, "body"


def _basis(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``up`` and to each other."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    first = np.cross(up, helper)
    first /= np.linalg.norm(first)
    return first, np.cross(up, first)


def _tilt_fit(sources: list[_Source], up: np.ndarray, rounds: int = 10) -> np.ndarray | None:
    """Up that makes every group of every source level.

    Gauss-Newton on the two tilt angles about ``up``: each group keeps its own height (a
    person's torso) and a source its own Cauchy-reweighted scale; a group adds what it knows
    only along the directions it spreads over by at least :data:`MIN_SPREAD` (a person walking
    to and fro on one line says nothing about the tilt across it, where gait sway would bias
    it). None when the groups together do not spread in two directions.
    """
    for _ in range(rounds):
        first, second = _basis(up)
        information, gradient, coverage = np.zeros((2, 2)), np.zeros(2), np.zeros((2, 2))
        total = 0.0
        for source in sources:
            step = _normal_equations(source, up, np.stack([first, second], axis=1))
            information += step[0]
            gradient += step[1]
            coverage += step[2]
            total += float(source.weights.sum())
        if np.sqrt(max(np.linalg.eigvalsh(coverage / total)[0], 0.0)) < MIN_COVERAGE:
            return None
        tilt = np.linalg.solve(information, gradient)
        up = up + tilt[0] * first + tilt[1] * second
        up /= np.linalg.norm(up)
    return up


def _normal_equations(
    source: _Source, up: np.ndarray, across: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One source's information ``(2, 2)``, gradient ``(2,)`` and coverage ``(2, 2)``.

    The information and gradient are for the tilt about ``up``; the coverage is the weighted
    sum of the groups' spreads along their wide directions. ``across`` holds the two tilt
    directions as columns. The source's robust weights are updated from the heights' spread
    about their groups' means.
    """
    count = int(source.groups.max()) + 1

    def centred(values: np.ndarray) -> np.ndarray:
        total = np.bincount(source.groups, source.weights, count)
        means = np.bincount(source.groups, source.weights * values, count) / np.maximum(
            total, 1e-12
        )
        return values - means[source.groups]

    height = centred(source.points @ up)
    scale = max(1.4826 * float(np.median(np.abs(height))), 0.005)
    source.weights = 1.0 / (1.0 + (height / (2.0 * scale)) ** 2)
    height = centred(source.points @ up)
    plane = np.stack([centred(source.points @ axis) for axis in across.T], axis=1)
    information, gradient, coverage = np.zeros((2, 2)), np.zeros(2), np.zeros((2, 2))
    for group in range(count):
        member = source.groups == group
        wide = _wide_directions(plane[member], source.weights[member])
        if wide.shape[1] == 0:
            continue
        along = plane[member] @ wide
        weighted = along * source.weights[member][:, None]
        coverage += wide @ (weighted.T @ along) @ wide.T
        information += wide @ (weighted.T @ along) @ wide.T / scale**2
        gradient -= wide @ (weighted.T @ height[member]) / scale**2
    return information, gradient, coverage


def _wide_directions(plane: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``(2, K)`` the directions in which ``plane`` points spread at least MIN_SPREAD."""
    if len(plane) < 10 or weights.sum() <= 0:
        return np.zeros((2, 0))
    covariance = (plane * weights[:, None]).T @ plane / weights.sum()
    values, vectors = np.linalg.eigh(covariance)
    return vectors[:, np.sqrt(np.maximum(values, 0.0)) >= MIN_SPREAD]


def align_to_floor(calibration: Calibration, floor: FloorFit) -> None:
    """Re-express every camera's pose in the floor's world (in place), figures included.

    Before, the world is the reference camera's frame; after, z is up, the floor is z = 0 and
    x is the reference camera's view projected on the floor. A camera the calibration flags
    (:func:`~hiros_calib.quality.flag_cameras`, run before) makes the floor doubtful too: its
    samples reach up through its pose, and a pose tilted by a degree tilts up with it.
    """
    up = floor.up
    view = np.array([0.0, 0.0, 1.0]) - up[2] * up  # the optical z axis, on the floor
    if np.linalg.norm(view) < 1e-6:  # a camera looking straight down: its x axis instead
        view = np.array([1.0, 0.0, 0.0]) - up[0] * up
    x = view / np.linalg.norm(view)
    y = np.cross(up, x)
    rows = np.stack([x, y, up])  # reference frame -> world coordinates
    # the origin is the floor below the reference camera (the reference frame's origin)
    below = floor.floor_height * up
    # (re-orthonormalised: x, y and up are orthogonal up to rounding)
    rotation = Rotation.from_matrix(rows)
    place_in_world(calibration, RigidTransform(rotation, -rotation.apply(below)))
    flagged = tuple(name for name, cam in calibration.cameras.items() if cam.flagged)
    values = (cam.quality.get("pose_uncertainty_deg") for cam in calibration.cameras.values())
    # (NaN, where a camera's halves could not be told, would make max() depend on the order)
    uncertainties = [float(v) for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    floor = replace(
        floor,
        doubtful_poses=flagged,
        pose_uncertainty_deg=max(uncertainties, default=math.nan),
    )
    calibration.cameras[calibration.reference].quality.update(floor.quality())


def place_in_world(calibration: Calibration, world_from_reference: RigidTransform) -> None:
    """Re-express every pose of a calibration solved in its reference camera's frame (in place).

    ``world_from_reference`` is where the reference camera's frame sits in the new world.
    """
    for cam in calibration.cameras.values():
        placed = world_from_reference @ cam.extrinsics
        cam.translation, cam.rotation = placed.translation, placed.quaternion
