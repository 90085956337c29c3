"""People in the simulated room: mocap clips placed on walking paths, with the truth they make.

Each clip is mapped to the Azure Kinect joints (``hiros_sim.mapping``), put on the floor
(``z = 0``), started at the origin and turned so that it travels along +x. A person plays one
clip over and over along a straight path of the clip's length: forward, a smooth 180° turn in
place during the first ``turn_time`` seconds of the next repetition (the clips start and end
standing), back, and so on. Paths of different people have different centres and directions so
that they cross. A person whose clip travels less than 0.5 m (bending, waving) stays on the
spot and faces the opposite way on each repetition. Extra people beyond the number of clips
replay a clip mirrored (left and right swapped), with a different phase.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hiros_core.layouts import AZURE_KINECT
from hiros_sim.bvh import BvhMotion
from hiros_sim.mapping import map_to_azure

__all__ = ["Clip", "PersonPath", "body_forward", "prepare_clip"]

_FOOT_ABOVE_FLOOR = 0.04
"""Height of the Kinect foot and ankle joints above the floor at rest, metres."""
_STILL = 0.5
"""A clip whose pelvis travels less than this (m) is played on the spot."""


@dataclass
class Clip:
    """A mocap clip as Azure joints in a clip frame: start at the origin, travelling along +x.

    Attributes:
        name: the BVH file's stem (``+mirror`` for mirrored copies).
        rate: frames per second.
        positions: ``(T, 32, 3)`` metres, floor at z = 0.
        travel: distance the pelvis travels along +x over the clip, 0 for clips on the spot.

    """

    name: str
    rate: float
    positions: np.ndarray
    travel: float

    @property
    def duration(self) -> float:
        """Seconds the clip plays before it repeats."""
        return self.positions.shape[0] / self.rate

    def mirrored(self) -> Clip:
        """The same motion with left and right exchanged (reflect y, swap joint labels)."""
        reflected = self.positions * np.array([1.0, -1.0, 1.0])
        return Clip(
            f"{self.name}+mirror", self.rate, reflected[:, AZURE_KINECT.mirror], self.travel
        )

    def sample(self, clip_time: np.ndarray) -> np.ndarray:
        """``(N, 32, 3)`` positions at times in [0, duration) by linear interpolation."""
        n = self.positions.shape[0]
        frame = np.clip(clip_time * self.rate, 0.0, n - 1.0)
        lower = np.floor(frame).astype(np.int64)
        upper = np.minimum(lower + 1, n - 1)
        w = (frame - lower)[:, None, None]
        return (1.0 - w) * self.positions[lower] + w * self.positions[upper]


def body_forward(positions: np.ndarray) -> np.ndarray:
    """``(..., 3)`` horizontal unit vector the body faces, from hips and shoulders (Z up)."""
    idx = AZURE_KINECT.index
    left = (
        positions[..., idx("HipLeft"), :]
        - positions[..., idx("HipRight"), :]
        + positions[..., idx("ShoulderLeft"), :]
        - positions[..., idx("ShoulderRight"), :]
    )
    # forward = left × up with up = +z
    forward = np.stack([left[..., 1], -left[..., 0], np.zeros(left.shape[:-1])], axis=-1)
    norm = np.linalg.norm(forward, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return forward / norm


def _rotation_z(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    zero, one = np.zeros_like(c), np.ones_like(c)
    return np.stack([c, -s, zero, s, c, zero, zero, zero, one], axis=-1).reshape(*c.shape, 3, 3)


def prepare_clip(motion: BvhMotion) -> Clip:
    """Map a BVH clip to Azure joints and normalise it (origin, +x travel, floor)."""
    positions = map_to_azure(motion)
    pelvis = positions[:, AZURE_KINECT.index("Pelvis")]
    travel_vector = pelvis[-1, :2] - pelvis[0, :2]
    travel = float(np.linalg.norm(travel_vector))
    if travel >= _STILL:
        heading = float(np.arctan2(travel_vector[1], travel_vector[0]))
    else:
        facing = body_forward(positions[0])
        heading = float(np.arctan2(facing[1], facing[0]))
        travel = 0.0
    positions = positions - np.array([pelvis[0, 0], pelvis[0, 1], 0.0])
    positions = positions @ _rotation_z(np.array(-heading)).T
    feet = [AZURE_KINECT.index(n) for n in ("FootLeft", "FootRight", "AnkleLeft", "AnkleRight")]
    lowest = positions[:, feet, 2].min(axis=1)
    positions[..., 2] -= np.percentile(lowest, 5) - _FOOT_ABOVE_FLOOR
    return Clip(motion.name, motion.rate, positions, travel)


@dataclass
class PersonPath:
    """Where and when one person plays a clip.

    Attributes:
        clip: the motion.
        centre: ``(2,)`` middle of the path on the floor, metres.
        heading: direction of the first pass, radians from +x.
        phase: seconds into the clip sequence at simulation time 0.
        enter: simulation time the person appears, seconds.
        leave: simulation time the person disappears, seconds.
        turn_time: seconds the 180° turn between passes takes.

    """

    clip: Clip
    centre: np.ndarray
    heading: float
    phase: float
    enter: float
    leave: float
    turn_time: float = 1.0

    def positions(self, times: np.ndarray) -> np.ndarray:
        """``(N, 32, 3)`` world positions at simulation times (s), NaN when absent."""
        clip = self.clip
        tau = np.asarray(times, dtype=float) + self.phase
        repetition = np.floor(tau / clip.duration)
        clip_time = tau - repetition * clip.duration
        local = clip.sample(clip_time)
        odd = (repetition % 2).astype(bool)
        direction = np.array([np.cos(self.heading), np.sin(self.heading)])
        start = self.centre - 0.5 * clip.travel * direction
        end = self.centre + 0.5 * clip.travel * direction
        origin = np.where(odd[:, None], end, start)
        yaw = self.heading + np.pi * repetition
        turning = (repetition > 0) & (clip_time < self.turn_time)
        progress = np.clip(clip_time / self.turn_time, 0.0, 1.0)
        smooth = progress * progress * (3.0 - 2.0 * progress)
        yaw = np.where(turning, yaw - np.pi * (1.0 - smooth), yaw)
        world = np.einsum("nab,njb->nja", _rotation_z(yaw), local)
        world[..., :2] += origin[:, None, :]
        absent = (times < self.enter) | (times > self.leave)
        world[absent] = np.nan
        return world
