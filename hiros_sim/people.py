"""People in the simulated room: mocap clips placed on walking paths, with the truth they make.

Each clip is mapped to the Azure Kinect joints (``hiros_sim.mapping``), put on the floor
(``z = 0``), its foot and ankle joints moved to where the SDK rests them
(``SDK_FOOT_HEIGHTS``), started at the origin and turned so that it travels along +x. A
person plays one clip over and over along a straight path of the clip's length: forward, a
smooth 180° turn in place during the first ``turn_time`` seconds of the next repetition (the
clips start and end standing), back, and so on. Paths of different people have different
centres and directions so that they cross. A person whose clip travels less than 0.5 m
(bending, waving) stays on the spot and faces the opposite way on each repetition. Extra
people beyond the number of clips replay a clip mirrored (left and right swapped), with a
different phase.

Looped with variation (``Repetitions``): a person doing the same thing again and again never
repeats it exactly. Each repetition then plays at its own speed and with its own amplitude about
the clip's mean pose; neighbouring repetitions cross-fade over ``blend`` seconds around their
seam, and the faded pose is put back on the person's limb lengths (``fit_body_model``), so
there is no jump where the clip's end meets its start. A person on the spot may then keep
facing one way (``turn_on_spot=False``), as someone waving at a camera does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hiros_core.layouts import AZURE_KINECT
from hiros_sim.bvh import BvhMotion
from hiros_sim.mapping import map_to_azure
from hiros_sim.noise import fit_body_model

__all__ = ["Clip", "PersonPath", "Repetitions", "body_forward", "prepare_clip"]

_FOOT_ABOVE_FLOOR = 0.04
"""Height of the mocap's lowest foot or ankle joint above the floor (5th percentile), metres:
where a clip is put on the floor."""
SDK_FOOT_HEIGHTS = {"Foot": 0.110, "Ankle": 0.164}
"""Height (m) above the floor at which the simulated SDK's foot and ankle joints rest, by joint.

Fitted so that the simulated SDK, on the UNIPD take's own motion and view (``hiros_sim.fit``'s
scene: one camera 3.3 m away), reports them resting where the real Azure Kinect did on that
take: 11.0 cm and 17.6 cm above the suit's floor (docs/world-frame.md, sessions 15 and 16). The
mocap's own foot joints sit elsewhere (the CMU toe 6-7 cm, the Xsens toe 1.7 cm, the
Bandai-Namco toe 4-4.5 cm). The simulated SDK keeps a planted foot on its evidence
(``hiros_sim.noise.plant_legs``), but where its straight leg cannot reach, a little above it:
the foot rests 0.4 cm above the truth's there."""
_ROUNDS = 4
"""Rounds in which a moved foot joint's resting frames and height settle."""
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

    @property
    def mean_pose(self) -> np.ndarray:
        """``(32, 3)`` the clip's mean joint positions relative to the pelvis."""
        return (self.positions - self.positions[:, :1]).mean(axis=0)

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
    return Clip(motion.name, motion.rate, _as_the_sdk_defines(positions, motion.rate), travel)


def _as_the_sdk_defines(positions: np.ndarray, rate: float) -> np.ndarray:
    """The foot and ankle joints moved to rest at ``SDK_FOOT_HEIGHTS``, the foot link rigid.

    The Azure Kinect SDK's foot joint rests well above a mocap toe marker, and its ankle above
    the mocap's ankle (docs/world-frame.md); the truth uses the SDK's definitions, as for the
    other joints (``hiros_sim.mapping``). Each joint first moves by one constant distance
    along its shank (knee - ankle), chosen so that its median height where it rests becomes
    the SDK's. The foot then goes at one fixed distance from the ankle, in the direction it
    got (:func:`_rigid_foot`): two joints moved along a turning shank by different amounts
    would make the link between them vary in length, and the real SDK's foot link varies only
    with its body scale (3.5 %, as every other limb).
    """
    idx = AZURE_KINECT.index
    moved = positions.copy()
    for side in ("Left", "Right"):
        ankle, knee = positions[:, idx(f"Ankle{side}")], positions[:, idx(f"Knee{side}")]
        shank = (knee - ankle) / np.linalg.norm(knee - ankle, axis=-1, keepdims=True)
        for kind, height in SDK_FOOT_HEIGHTS.items():
            joint = idx(f"{kind}{side}")
            # moved along a turning shank, a joint rests on other frames: settle in a few rounds
            for _ in range(_ROUNDS):
                rest = _resting(moved[:, joint], rate)
                rise = float(np.median(shank[rest, 2]))  # the shank's vertical share at rest
                moved[:, joint] += (height - float(np.median(moved[rest, joint, 2]))) / rise * shank
        _rigid_foot(moved, idx(f"Ankle{side}"), idx(f"Foot{side}"), rate)
    return moved


def _rigid_foot(positions: np.ndarray, ankle: int, foot: int, rate: float) -> None:
    """Put the ``foot`` joint at one distance from the ``ankle`` (in place), in its direction.

    The distance is the link's median length, then settled so that the foot still rests at
    ``SDK_FOOT_HEIGHTS["Foot"]``.
    """
    link = positions[:, foot] - positions[:, ankle]
    direction = link / np.linalg.norm(link, axis=-1, keepdims=True)
    length = float(np.median(np.linalg.norm(link, axis=-1)))
    for _ in range(_ROUNDS):
        positions[:, foot] = positions[:, ankle] + length * direction
        rest = _resting(positions[:, foot], rate)
        drop = float(np.median(direction[rest, 2]))  # the link's vertical share at rest (< 0)
        length += (SDK_FOOT_HEIGHTS["Foot"] - float(np.median(positions[rest, foot, 2]))) / drop
    positions[:, foot] = positions[:, ankle] + length * direction


def _resting(joint: np.ndarray, rate: float) -> np.ndarray:
    """``(T,)`` where a ``(T, 3)`` joint rests; its lowest 10 % of frames if it never does.

    Rests by the floor fit's rule (``hiros_calib.world``), so the simulated SDK puts its feet
    at ``SDK_FOOT_HEIGHTS`` where the floor fit will look for them.
    """
    # imported here: hiros_calib takes a quarter of a second to import, and every ``hiros``
    # command imports this package to list the simulator's presets in its help
    from hiros_calib.world import RESTING_SPEED, speed_over_baseline

    speed = speed_over_baseline(joint[:, None], np.arange(len(joint)) / rate)[:, 0]
    resting = speed < RESTING_SPEED  # NaN (the ends) never rests
    if not resting.any():
        resting = joint[:, 2] <= np.percentile(joint[:, 2], 10)
    return resting


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass
class Repetitions:
    """How each repetition of a looped clip differs from the recorded one.

    Attributes:
        speed: ``(R,)`` playback speed of each repetition (1 = as recorded).
        amplitude: ``(R,)`` scale of each repetition's movement about the clip's mean pose
            (pelvis-relative; 1 = as recorded).
        blend: seconds over which a repetition fades into the next around their seam.

    """

    speed: np.ndarray
    amplitude: np.ndarray
    blend: float = 0.5

    @classmethod
    def draw(
        cls, rng: np.random.Generator, count: int, variation: float, blend: float
    ) -> Repetitions:
        """``count`` repetitions: speed uniform in ``1 ± variation``, amplitude in half that."""
        speed = 1.0 + rng.uniform(-variation, variation, count)
        amplitude = 1.0 + rng.uniform(-0.5 * variation, 0.5 * variation, count)
        return cls(speed, amplitude, blend)


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
        repetitions: per-repetition variation; None repeats the clip exactly (with a jump
            where its end meets its start).
        turn_on_spot: a clip played on the spot faces the opposite way on each repetition.

    """

    clip: Clip
    centre: np.ndarray
    heading: float
    phase: float
    enter: float
    leave: float
    turn_time: float = 1.0
    repetitions: Repetitions | None = None
    turn_on_spot: bool = True

    def positions(self, times: np.ndarray) -> np.ndarray:
        """``(N, 32, 3)`` world positions at simulation times (s), NaN when absent."""
        clip = self.clip
        times = np.asarray(times, dtype=float)
        tau = times + self.phase
        if self.repetitions is None:
            repetition = np.floor(tau / clip.duration)
            clip_time = tau - repetition * clip.duration
            world = self._place(clip.sample(clip_time), repetition, clip_time)
        else:
            world = self._looped(tau, self.repetitions)
        absent = (times < self.enter) | (times > self.leave)
        world[absent] = np.nan
        return world

    def _looped(self, tau: np.ndarray, reps: Repetitions) -> np.ndarray:
        """``(N, 32, 3)`` world positions at clip-sequence times ``tau`` with variation.

        ``reps`` must cover every ``tau`` (beyond its last repetition the pose is held). Around
        each seam (``|tau - seam| < blend / 2``) the pose is the cross-fade of the two
        repetitions meeting there, each held at its end or start beyond its own span.
        """
        clip = self.clip
        bounds = np.concatenate([[0.0], np.cumsum(clip.duration / reps.speed)])
        current = np.clip(np.searchsorted(bounds, tau, side="right") - 1, 0, len(reps.speed) - 1)
        seam = np.where(tau - bounds[current] < bounds[current + 1] - tau, current, current + 1)
        half = 0.5 * reps.blend
        offset = tau - bounds[seam]
        near = (seam >= 1) & (np.abs(offset) < half)
        later = np.where(near, seam, current)
        earlier = np.where(near, seam - 1, current)
        weight = np.where(near, _smoothstep((offset + half) / max(reps.blend, 1e-9)), 0.0)
        first, first_recorded = self._repetition(earlier, tau, bounds, reps)
        second, _ = self._repetition(later, tau, bounds, reps)
        blended = (1.0 - weight)[:, None, None] * first + weight[:, None, None] * second
        # the cross-fade and the amplitude shorten limbs a little: back on the true lengths
        ones = np.ones(tau.shape)
        lengths = np.ones((*tau.shape, AZURE_KINECT.n_joints))
        return fit_body_model(blended, first_recorded, ones, lengths)

    def _repetition(
        self, repetition: np.ndarray, tau: np.ndarray, bounds: np.ndarray, reps: Repetitions
    ) -> tuple[np.ndarray, np.ndarray]:
        """World positions of ``repetition`` at ``tau`` (varied) and as recorded (same place)."""
        clip = self.clip
        speed, amplitude = reps.speed[repetition], reps.amplitude[repetition]
        clip_time = np.clip((tau - bounds[repetition]) * speed, 0.0, clip.duration)
        recorded = clip.sample(clip_time)
        pelvis = recorded[:, :1]
        mean = clip.mean_pose
        varied = pelvis + mean + amplitude[:, None, None] * (recorded - pelvis - mean)
        place = self._place
        return place(varied, repetition, clip_time), place(recorded, repetition, clip_time)

    def _place(
        self, local: np.ndarray, repetition: np.ndarray, clip_time: np.ndarray
    ) -> np.ndarray:
        """Clip-frame positions ``(N, 32, 3)`` of the given repetitions into the world."""
        clip = self.clip
        odd = (repetition % 2).astype(bool)
        direction = np.array([np.cos(self.heading), np.sin(self.heading)])
        start = self.centre - 0.5 * clip.travel * direction
        end = self.centre + 0.5 * clip.travel * direction
        origin = np.where(odd[:, None], end, start)
        if not self.turn_on_spot and clip.travel == 0.0:
            return self._turned(local, np.full(repetition.shape, self.heading), self.centre)
        yaw = self.heading + np.pi * repetition
        turning = (repetition > 0) & (clip_time < self.turn_time)
        smooth = _smoothstep(clip_time / self.turn_time)
        yaw = np.where(turning, yaw - np.pi * (1.0 - smooth), yaw)
        return self._turned(local, yaw, origin)

    @staticmethod
    def _turned(local: np.ndarray, yaw: np.ndarray, origin: np.ndarray) -> np.ndarray:
        world = np.einsum("nab,njb->nja", _rotation_z(yaw), local)
        world[..., :2] += np.broadcast_to(origin, (*yaw.shape, 2))[:, None, :]
        return world
