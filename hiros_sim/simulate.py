"""The semi-synthetic multi-camera simulator: real mocap seen by simulated Azure Kinects.

``simulate(SimParams(...))`` places people (``hiros_sim.people``) and cameras
(``hiros_sim.cameras``) in a room, samples the truth at the mocap rate, and for every camera
produces what its body-tracking driver would publish: one ``SkeletonGroup`` per camera frame, in
the camera's depth frame (x right, y down, z forward) and on the camera's own clock, with the
Azure Kinect layout, SDK body ids and SDK confidences, and the mistakes of ``hiros_sim.noise``.

World frame: metres, Z up, floor at z = 0, room centre at the origin. Clock: the reference clock
is k01's; ``Truth.times`` are reference-clock seconds.

Frame timing: camera frames are ``1 / rate`` apart on the camera's own clock, plus a Gaussian
``jitter``; a frame's stamp is the instant it shows (so the truth at
``to_reference_time(stamp)`` is the clean skeleton). Frames are dropped with ``drop_rate``
(no message at all) and people are missed with ``miss_rate`` (a message without them).

Log times (``SimResult.receive_ns``, the recording's log times): with ``log_clock="receiver"``
one recorder receives every camera, so a message is logged at its capture instant on the
reference clock plus ``latency``; with ``log_clock="camera"`` each camera has its own recording
host on the camera's clock, and a message is logged at its stamp plus that host's constant
latency (drawn from ``host_latency``) plus ``host_jitter``. The truth is the same either way.

Presets of these knobs for the robustness conditions are in ``hiros_sim.presets``.

``SimParams(noise=False)`` switches every imperfection off (no joint noise, jitter, drops,
misses, flips, swaps, ghosts, id changes) but keeps clock offsets, drift, field of view and the
confidence levels, so a camera's stream is exactly the truth moved into it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.errors import ConfigError
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_data import DATA_DIR
from hiros_sim.bvh import read_bvh
from hiros_sim.cameras import camera_to_reference, make_setup, reference_to_camera
from hiros_sim.noise import (
    CONFIDENCE_OF_LEVEL,
    LEGS_SWAP,
    LEVEL_LOW,
    LEVEL_MEDIUM,
    LEVEL_NONE,
    ar1_noise,
    fit_body_model,
    flip_front_back,
    in_view,
    occluded,
)
from hiros_sim.people import Clip, PersonPath, Repetitions, body_forward, prepare_clip
from hiros_sim.shared import bandai_files

__all__ = ["SimParams", "SimResult", "Truth", "bumped_pose", "default_bvh_files", "simulate"]

_DATA = DATA_DIR
_IDX = AZURE_KINECT.index
_MAX_PEOPLE = 6
_THUMBS = np.array([_IDX("ThumbLeft"), _IDX("ThumbRight")])
_EXTREMITIES = np.array(
    [
        _IDX(f"{part}{side}")
        for part in ("Hand", "HandTip", "Thumb", "Ankle", "Foot", "Eye", "Ear")
        for side in ("Left", "Right")
    ]
    + [_IDX("Nose")]
)
"""Hands, feet and face: the joints a noisier SDK gets most wrong (``extremity_gain``)."""
_MOTIONS = ("bundled", "bandai")
_LOG_CLOCKS = ("receiver", "camera")


def default_bvh_files() -> tuple[str, ...]:
    """The bundled clips (hiros_data): three CMU walks/hops and the Xsens bending take."""
    return tuple(
        str(p)
        for p in (
            _DATA / "mocap_cmu" / "131_01.bvh.gz",
            _DATA / "mocap_cmu" / "131_02.bvh.gz",
            _DATA / "mocap_cmu" / "131_03.bvh.gz",
            _DATA / "unipd_bpe_sample" / "sbj01_bend1.bvh.gz",
        )
    )


@dataclass
class SimParams:
    """Every knob of the simulator, with defaults fitted to real data where data exists.

    Noise figures come from ``hiros simulate --fit-noise`` (``hiros_sim.fit``) on the
    UNIPD-BPE Azure Kinect vs Xsens take; clock figures are typical of Azure Kinect host stamps.
    """

    n_cameras: int = 3
    setup: str = "room"
    """``room``, ``facing``, ``ring`` or a calibration YAML file with camera poses."""
    n_people: int = 2
    duration: float = 60.0
    """Seconds of reference time."""
    seed: int = 0
    rate: float = 30.0
    """Camera frame rate, Hz (the Azure Kinect offers 30, 15 and 5)."""
    bvh_files: tuple[str, ...] = ()
    """Mocap clips; empty = the clips of ``motion``."""
    motion: str = "bundled"
    """``bundled``: the ``hiros_data`` clips (walks, a bend). ``bandai``: one Bandai-Namco clip
    per person from the shared data (``hiros_sim.shared``; gestures and walks repeated for the
    whole recording, a gesturing person keeps facing one way)."""
    loop_variation: float = 0.0
    """Per-repetition variation of the looped clips: speed uniform in ``1 ± v``, amplitude in
    ``1 ± v/2``, seams cross-faded over ``loop_blend``. 0 with ``bundled`` motion repeats the
    clips exactly (today's recordings)."""
    loop_blend: float = 0.5
    """Seconds over which one repetition fades into the next (varied or ``bandai`` loops)."""
    noise: bool = True
    """Master switch: False turns every imperfection off (see module docstring)."""

    # room and cameras
    camera_radius: float = 3.5
    camera_height: tuple[float, float] = (1.0, 2.0)
    camera_tilt: tuple[float, float] = (2.0, 8.0)
    """Degrees of extra downward pitch beyond aiming at 1 m above the room centre."""
    fov: tuple[float, float] = (75.0, 65.0)
    """Horizontal, vertical field of view in degrees (Azure Kinect NFOV depth mode)."""
    pair_angle: tuple[float, float] = (40.0, 50.0)
    """``pair`` setup: degrees between the two cameras' views, drawn in this range."""
    pair_baseline: tuple[float, float] = (1.3, 1.5)
    """``pair`` setup: metres between the two cameras, drawn in this range."""
    depth_range: tuple[float, float] = (0.5, 5.5)
    walk_area: float = 0.7
    """Path centres lie within this radius of the room centre, metres."""
    lane_width: float = 0.0
    """0: paths of random centres (within ``walk_area``) and directions. Otherwise parallel lanes
    this far apart (metres) across the room centre, neighbours setting off in opposite
    directions, so that they pass each other this close again and again."""
    enter_leave: bool = True
    """People after the first enter late or leave early."""

    # clocks
    clock_start: float = 1_700_000_000.0
    max_time_offset: float = 3.0
    drift_ppm: float = 30.0
    start_spread: float = 0.5
    """Cameras start recording within this many seconds of each other."""
    jitter: float = 0.00047
    """Std of the frame stamps around the regular grid, seconds (fitted: 0.47 ms)."""
    drop_rate: float = 0.0056
    """Frames never published (fitted: 0.56 %)."""
    latency: float = 0.06
    """Seconds from a frame's capture to its arrival at the recorder (the log time)."""
    log_clock: str = "receiver"
    """Clock of the log times: ``receiver`` (one recorder, reference clock, ``latency``) or
    ``camera`` (one recording host per camera, on that camera's clock: stamp plus the host's
    latency and jitter)."""
    host_latency: tuple[float, float] = (0.02, 0.03)
    """``log_clock="camera"``: each host's constant latency, seconds, drawn in this range."""
    host_jitter: float = 0.001
    """``log_clock="camera"``: scale of each message's extra latency, seconds (half-normal:
    a message is never logged before its host's constant latency)."""

    # joint noise (see hiros_sim.noise); figures from hiros_sim.fit on the UNIPD-BPE take
    noise_base: float = 0.012
    """Lateral joint noise sigma at depth 0, metres (fitted: 12.0 mm)."""
    noise_per_metre: float = 0.004
    """Growth of the sigma per metre of depth (fitted: 4.0 mm/m over 2.8-4.0 m)."""
    depth_axis_gain: float = 1.2
    """Sigma along the camera's z axis relative to x, y (fitted: 1.20)."""
    joint_bias: float = 0.026
    """Sigma of a per camera, person and joint offset, metres (fitted RMS: 25.6 mm)."""
    bias_drift_time: float = 0.0
    """Seconds for the joint offsets' autocorrelation to fall to 1/e (an Ornstein-Uhlenbeck
    drift, same sigma); 0 keeps them fixed for the whole recording (the take's)."""
    oblique_gain: float = 1.0
    """Extra sigma, as a fraction, for a body seen from the side (not in the take: a guess)."""
    occluded_gain: float = 2.0
    """Sigma factor of hidden joints (the take's ankles, hidden by the bending torso, err
    1.6-2.2x the median joint)."""
    extremity_gain: float = 1.0
    """Sigma factor of hands, feet and face joints (1 = as the rest of the body)."""
    out_of_view_gain: float = 4.0
    noise_correlation_time: float = 0.22
    """Seconds for the joint error's autocorrelation to fall to 1/e (fitted: 220 ms; the
    body scale's, 200 ms, is close enough to share it)."""
    noise_body_share: float = 0.5
    """Share of the evidence noise variance that is one shift of the whole body, 0..1 (tuned:
    a joint's error then correlates with its parent's by 0.6-0.75 per axis, 0.5-0.7 on the
    take)."""
    body_scale_cv: float = 0.035
    """CV of the SDK's per-frame whole-body scale (fitted: 3.5 %, which is also every limb's
    length CV on the take)."""
    thumb_length_cv: float = 0.048
    """Extra CV of the thumb links' length (fitted: 4.8 %; the SDK fits the thumbs apart)."""
    noise_residual: float = 0.0
    """Sigma of independent noise on top of the SDK's rigid model, metres, times the joint's
    occlusion, view and extremity factors (the take shows none: its limb lengths keep exact
    ratios)."""

    # SDK mistakes
    miss_rate: float = 0.0056
    """Frames where a visible person is not reported (fitted: 0.56 % empty frames)."""
    flip_probability: float = 0.5
    """Chance that a stretch of a person facing away is reported front/back flipped."""
    facing_away_cos: float = -0.5
    flip_rate: float = 3.0
    """Front/back flip episodes (0.5-3 s) per person per camera per minute in any view. The
    real take shows 37 % flipped frames on an upright subject facing the camera; the default
    (about 9 %) is milder."""
    swap_rate: float = 2.0
    """Left/right swap episodes per person per camera per minute."""
    ghost_rate: float = 1.0
    """Ghost bodies per camera per minute."""
    id_change_rate: float = 0.5
    """SDK body id changes per person per camera per minute."""
    reid_gap: float = 0.5
    """A person unseen for longer than this (s) comes back with a new SDK id."""
    truth_rate: float = 0.0
    """Truth sampling rate, Hz; 0 = the highest clip rate."""

    # a camera knocked mid-recording (for the live calibration's change detection)
    bump_camera: str = ""
    """Camera moved during the recording ("" = none); ``calibration`` keeps its first pose,
    :func:`bumped_pose` gives the second."""
    bump_time: float = 0.0
    """Seconds after the recording starts (reference clock) when it moves."""
    bump_rotation: float = 0.0
    """Degrees it turns about the vertical through its own position."""
    bump_shift: float = 0.0
    """Metres it slides along the world x axis."""

    def check(self) -> None:
        """Raise ConfigError for values the simulator cannot honour."""
        problems = []
        if not 1 <= self.n_people <= _MAX_PEOPLE:
            problems.append(f"n_people must be 1..{_MAX_PEOPLE}, not {self.n_people}")
        if self.n_cameras < 1:
            problems.append(f"n_cameras must be at least 1, not {self.n_cameras}")
        if not 2.0 * self.start_spread + 1.0 < self.duration < math.inf:  # NaN fails too
            problems.append(
                f"duration must be finite and exceed {2 * self.start_spread + 1.0:g} s, "
                f"not {self.duration}"
            )
        if not 0 < self.rate < math.inf:
            problems.append(f"rate must be positive and finite, not {self.rate}")
        if not 0.0 <= self.noise_body_share <= 1.0:
            problems.append(f"noise_body_share must be in 0..1, not {self.noise_body_share}")
        if self.motion not in _MOTIONS:
            problems.append(f"motion must be one of {', '.join(_MOTIONS)}, not {self.motion!r}")
        if self.log_clock not in _LOG_CLOCKS:
            problems.append(
                f"log_clock must be one of {', '.join(_LOG_CLOCKS)}, not {self.log_clock!r}"
            )
        if not 0.0 <= self.loop_variation < 1.0:
            problems.append(f"loop_variation must be in [0, 1), not {self.loop_variation}")
        if problems:
            raise ConfigError("; ".join(problems))


@dataclass
class Truth:
    """What really happened, in the world frame on the reference clock.

    Attributes:
        times: ``(T,)`` reference-clock seconds at the mocap rate.
        positions: ``(P, T, 32, 3)`` Azure Kinect joints, metres, NaN where a person is absent.
        person_ids: ``(P,)`` true person ids.
        clip_names: ``(P,)`` which mocap clip each person plays.

    """

    times: np.ndarray
    positions: np.ndarray
    person_ids: np.ndarray
    clip_names: tuple[str, ...] = ()

    @property
    def rate(self) -> float:
        """Samples per second."""
        return float((len(self.times) - 1) / (self.times[-1] - self.times[0]))

    def at(self, times: np.ndarray) -> np.ndarray:
        """``(P, N, 32, 3)`` positions at reference times by linear interpolation.

        NaN outside the truth's time span and where a person is absent at either neighbour.
        """
        times = np.asarray(times, dtype=float)
        upper = np.clip(np.searchsorted(self.times, times), 1, len(self.times) - 1)
        lower = upper - 1
        span = self.times[upper] - self.times[lower]
        w = ((times - self.times[lower]) / span)[None, :, None, None]
        out = (1.0 - w) * self.positions[:, lower] + w * self.positions[:, upper]
        outside = (times < self.times[0] - 1e-9) | (times > self.times[-1] + 1e-9)
        out[:, outside] = np.nan
        return out


@dataclass
class SimResult:
    """A simulated recording.

    Attributes:
        params: what it was made from.
        camera_groups: per camera name, its groups in time order (camera frame and clock).
        truth: the world-frame truth.
        calibration: true camera poses (camera -> world) and clocks.
        labels: per camera, for each group, the true person id of each skeleton (-1 = ghost).

    """

    params: SimParams
    camera_groups: dict[str, list[SkeletonGroup]]
    truth: Truth
    calibration: Calibration
    labels: dict[str, list[np.ndarray]] = field(default_factory=dict)
    receive_ns: dict[str, np.ndarray] = field(default_factory=dict)


@lru_cache(maxsize=16)
def _load_clip(path: str) -> Clip:
    return prepare_clip(read_bvh(path))


def _clip_files(params: SimParams) -> tuple[str, ...]:
    if params.bvh_files:
        return tuple(params.bvh_files)
    if params.motion == "bandai":
        return bandai_files(params.n_people, params.seed)
    return default_bvh_files()


def _repetitions(params: SimParams, clip: Clip, person: int) -> Repetitions | None:
    """Each repetition's variation, from its own random stream (None: exact repetitions)."""
    if params.motion != "bandai" and params.loop_variation == 0.0:
        return None
    shortest = clip.duration / (1.0 + params.loop_variation)
    count = int(np.ceil((params.duration + clip.duration) / shortest)) + 2
    rng = np.random.default_rng(np.random.SeedSequence([params.seed, 3, person]))
    return Repetitions.draw(rng, count, params.loop_variation, params.loop_blend)


def _people(params: SimParams, rng: np.random.Generator) -> list[PersonPath]:
    clips = [_load_clip(f) for f in _clip_files(params)]
    people = []
    duration = params.duration
    for p in range(params.n_people):
        clip = clips[p % len(clips)]
        if (p // len(clips)) % 2 == 1:
            clip = clip.mirrored()
        heading = np.pi * p / params.n_people + rng.uniform(-0.3, 0.3)
        radius = params.walk_area * np.sqrt(rng.uniform(0.0, 1.0))
        angle = rng.uniform(0.0, 2.0 * np.pi)
        centre = radius * np.array([np.cos(angle), np.sin(angle)])
        if params.lane_width > 0.0:
            lane = params.lane_width * (p - 0.5 * (params.n_people - 1))
            if p == 0:
                lanes_heading = heading
            centre = lane * np.array([-np.sin(lanes_heading), np.cos(lanes_heading)])
            heading = lanes_heading + np.pi * (p % 2)
        enter, leave = 0.0, duration
        if params.enter_leave and p > 0 and duration >= 20.0:
            if p % 2 == 1:
                enter = rng.uniform(0.05, 0.25) * duration
            else:
                leave = duration - rng.uniform(0.05, 0.25) * duration
        phase = rng.uniform(0.0, clip.duration)
        path = PersonPath(clip, centre, float(heading), float(phase), enter, leave)
        path.repetitions = _repetitions(params, clip, p)
        path.turn_on_spot = params.motion != "bandai"
        people.append(path)
    return people


def _truth(params: SimParams, people: list[PersonPath]) -> Truth:
    rate = params.truth_rate or max(p.clip.rate for p in people)
    count = int(np.floor(params.duration * rate)) + 1
    sim_times = np.arange(count) / rate
    positions = np.stack([person.positions(sim_times) for person in people])
    return Truth(
        times=params.clock_start + sim_times,
        positions=positions,
        person_ids=np.arange(len(people), dtype=np.int64),
        clip_names=tuple(person.clip.name for person in people),
    )


def _runs(mask: np.ndarray) -> np.ndarray:
    """``(P, N)`` run label of each True element (0 where False), unique across rows."""
    starts = mask & ~np.concatenate([np.zeros((mask.shape[0], 1), bool), mask[:, :-1]], axis=1)
    labels = np.cumsum(starts.ravel()).reshape(mask.shape)
    return np.where(mask, labels, 0)


@dataclass
class _Stream:
    """One camera's observations before they become groups."""

    stamps_ns: np.ndarray  # (N,)
    receive_ns: np.ndarray  # (N,) reference clock
    kept: np.ndarray  # (N,) frame published
    positions: np.ndarray  # (P, N, 32, 3) camera frame, with noise
    levels: np.ndarray  # (P, N, 32) SDK confidence levels
    detected: np.ndarray  # (P, N)
    ids: np.ndarray  # (P, N) SDK body ids
    ghosts: list[tuple[int, int, int, np.ndarray, np.ndarray]]  # start, stop, id, pos, levels


def bumped_pose(cam: CameraCalibration, params: SimParams) -> CameraCalibration:
    """The pose of ``cam`` after ``params``' bump (same clock).

    Turned about the vertical through its position by ``bump_rotation`` degrees, then slid
    ``bump_shift`` m along world x.
    """
    turn = Rotation.from_euler("z", params.bump_rotation, degrees=True)
    rotation = (turn * Rotation.from_quat(cam.rotation)).as_quat()
    translation = np.asarray(cam.translation, float) + np.array([params.bump_shift, 0.0, 0.0])
    return replace(cam, translation=translation, rotation=rotation)


def _in_camera(
    cam: CameraCalibration, world: np.ndarray, forward: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World points ``(P, N, 32, 3)`` and facing directions ``(P, N, 3)`` in ``cam``'s frame."""
    rotation = Rotation.from_quat(cam.rotation).as_matrix()
    return (world - cam.translation) @ rotation, forward @ rotation  # R^T (p - t)


def _observe(
    cam: CameraCalibration,
    truth: Truth,
    clips: list[Clip],
    params: SimParams,
    rng: np.random.Generator,
    *,
    host_rng: np.random.Generator,
    bump: CameraCalibration | None = None,
) -> _Stream:
    """Everything one camera reports, as arrays over its frames.

    ``host_rng`` draws the camera host's log-time latency (``log_clock="camera"``) apart from
    ``rng``, so that the rest of the stream does not depend on the log clock.
    """
    noisy = params.noise
    rate = params.rate
    start_ref = params.clock_start + rng.uniform(0.0, params.start_spread)
    start_ns = round(float(reference_to_camera(cam, np.array(start_ref))) * 1e9)
    n_frames = int((params.duration - params.start_spread - 2.0 / rate) * rate)
    offsets = np.arange(n_frames) / rate
    if noisy and params.jitter > 0:
        offsets = offsets + rng.normal(0.0, params.jitter, n_frames)
    stamps_ns = start_ns + np.round(offsets * 1e9).astype(np.int64)
    kept = rng.random(n_frames) >= params.drop_rate if noisy else np.ones(n_frames, bool)
    t_ref = camera_to_reference(cam, stamps_ns * 1e-9)
    if params.log_clock == "camera":
        latency = host_rng.uniform(*params.host_latency)
        latency = latency + params.host_jitter * np.abs(host_rng.standard_normal(n_frames))
        receive_ns = stamps_ns + np.round(latency * 1e9).astype(np.int64)
    else:
        receive_ns = np.round((t_ref + params.latency) * 1e9).astype(np.int64)

    world = truth.at(t_ref)  # (P, N, 32, 3)
    facing = body_forward(world)  # (P, N, 3) world frame
    positions, forward = _in_camera(cam, world, facing)
    if bump is not None:
        moved = t_ref >= params.clock_start + params.bump_time
        after, forward_after = _in_camera(bump, world, facing)
        positions = np.where(moved[None, :, None, None], after, positions)
        forward = np.where(moved[None, :, None], forward_after, forward)
    present = np.isfinite(world).all(axis=(2, 3))
    joint_in = in_view(positions, params.fov, params.depth_range)
    hidden = occluded(positions)
    levels = np.where(joint_in, np.where(hidden, LEVEL_LOW, LEVEL_MEDIUM), LEVEL_NONE)
    detected = present & (joint_in.mean(axis=-1) >= 0.5)
    if noisy:
        detected &= rng.random(detected.shape) >= params.miss_rate
        positions = _joint_noise(positions, forward, joint_in, hidden, params=params, rng=rng)
        _sdk_mistakes(positions, levels, forward, detected, params=params, rng=rng)
    ghosts_spec = []
    if noisy:
        for _ in range(rng.poisson(params.ghost_rate * params.duration / 60.0)):
            first = int(rng.integers(0, n_frames))
            stop = min(n_frames, first + max(1, int(rng.uniform(0.2, 1.5) * rate)))
            ghosts_spec.append((first, stop))
    ids, ghost_ids = _sdk_ids(detected, ghosts_spec, params, rng)
    ghosts = []
    for (first, stop), ghost_id in zip(ghosts_spec, ghost_ids, strict=True):
        pose, ghost_levels = _ghost_pose(cam, clips, rng)
        jitter = rng.normal(0.0, 0.03, (stop - first, *pose.shape))
        ghosts.append((first, stop, ghost_id, pose[None] + jitter, ghost_levels))
    return _Stream(stamps_ns, receive_ns, kept, positions, levels, detected, ids, ghosts)


def _facing_cos(positions: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """``(P, N)`` cosine between each body's facing and the direction to the camera."""
    pelvis = positions[:, :, _IDX("Pelvis")]
    with np.errstate(invalid="ignore", divide="ignore"):
        to_camera = -pelvis / np.linalg.norm(pelvis, axis=-1, keepdims=True)
        return np.einsum("pnc,pnc->pn", forward, to_camera)


def _joint_noise(
    positions: np.ndarray,
    forward: np.ndarray,
    joint_in: np.ndarray,
    hidden: np.ndarray,
    *,
    params: SimParams,
    rng: np.random.Generator,
) -> np.ndarray:
    """What the SDK reports for true ``(P, N, 32, 3)`` positions (model in ``hiros_sim.noise``).

    The evidence is each joint plus correlated noise (part of it one shift of the whole body)
    and a fixed bias; the SDK's rigid body model, scaled per frame, is fitted to it.
    """
    obliqueness = np.sqrt(np.clip(1.0 - _facing_cos(positions, forward) ** 2, 0.0, 1.0))
    depth = np.abs(positions[..., 2])
    sigma = (params.noise_base + params.noise_per_metre * depth) * (
        1.0 + params.oblique_gain * obliqueness
    )[..., None]
    gain = np.where(hidden, params.occluded_gain, 1.0)
    gain = gain * np.where(joint_in, 1.0, params.out_of_view_gain)
    if params.extremity_gain != 1.0:
        gain[..., _EXTREMITIES] *= params.extremity_gain
    sigma = sigma * gain
    rho = float(np.exp(-1.0 / (params.rate * params.noise_correlation_time)))
    n_people, n_frames, n_joints, _ = positions.shape
    share = params.noise_body_share
    own = ar1_noise(rng, positions.shape, rho)
    body = ar1_noise(rng, (n_people, n_frames, 1, 3), rho)
    error = (np.sqrt(1.0 - share) * own + np.sqrt(share) * body) * sigma[..., None]
    error[..., 2] *= params.depth_axis_gain
    if params.bias_drift_time > 0.0:
        rho_bias = float(np.exp(-1.0 / (params.rate * params.bias_drift_time)))
        bias = params.joint_bias * ar1_noise(rng, positions.shape, rho_bias)
    else:
        bias = rng.normal(0.0, params.joint_bias, (n_people, 1, n_joints, 3))
    scale = 1.0 + params.body_scale_cv * ar1_noise(rng, (n_people, n_frames), rho)
    length_gain = np.ones((n_people, n_frames, n_joints))
    length_gain[..., _THUMBS] += params.thumb_length_cv * ar1_noise(
        rng, (n_people, n_frames, _THUMBS.size), rho
    )
    fitted = fit_body_model(positions + error + bias, positions, scale, length_gain)
    if params.noise_residual > 0.0:
        fitted += params.noise_residual * gain[..., None] * ar1_noise(rng, positions.shape, rho)
    return fitted


def _sdk_mistakes(
    positions: np.ndarray,
    levels: np.ndarray,
    forward: np.ndarray,
    detected: np.ndarray,
    *,
    params: SimParams,
    rng: np.random.Generator,
) -> None:
    """Front/back flips and left/right swaps, in place."""
    n_people, n_frames = detected.shape
    rate = params.rate
    away = detected & (_facing_cos(positions, forward) < params.facing_away_cos)
    episodes = _runs(away)
    flip_episode = rng.random(episodes.max() + 1) < params.flip_probability
    flipped = away & flip_episode[episodes]
    for p in range(n_people):
        for _ in range(rng.poisson(params.flip_rate * params.duration / 60.0)):
            first = int(rng.integers(0, n_frames))
            flipped[p, first : first + int(rng.uniform(0.5, 3.0) * rate)] = True
    flipped &= detected
    if flipped.any():
        positions[flipped] = flip_front_back(positions[flipped], forward[flipped])
        levels[flipped] = levels[flipped][:, AZURE_KINECT.mirror]
    for p in range(n_people):
        for _ in range(rng.poisson(params.swap_rate * params.duration / 60.0)):
            first = rng.integers(0, n_frames)
            stop = min(n_frames, first + int(rng.uniform(0.2, 1.0) * rate))
            perm = LEGS_SWAP if rng.random() < 0.7 else AZURE_KINECT.mirror
            span = slice(first, stop)
            positions[p, span] = positions[p, span][:, perm]
            levels[p, span] = levels[p, span][:, perm]


def _sdk_ids(
    detected: np.ndarray,
    ghosts: list[tuple[int, int]],
    params: SimParams,
    rng: np.random.Generator,
) -> tuple[np.ndarray, list[int]]:
    """``(P, N)`` SDK body ids and each ghost's id.

    Like the SDK, ids count up from 1 in order of appearance; a person gets a new id when seen
    again after ``reid_gap`` seconds and at random changes (``id_change_rate``).
    """
    n_people, n_frames = detected.shape
    new_track = np.zeros_like(detected)
    gap = round(params.reid_gap * params.rate)
    for p in range(n_people):
        seen = np.flatnonzero(detected[p])
        if seen.size:
            new_track[p, seen[np.concatenate([[True], np.diff(seen) > gap])]] = True
        if params.noise:
            count = rng.poisson(params.id_change_rate * params.duration / 60.0)
            changes = rng.integers(0, n_frames, count)
            new_track[p, changes] |= detected[p, changes]
    events = [(int(f), 0, int(p)) for p, f in zip(*np.nonzero(new_track), strict=True)]
    events += [(first, 1, g) for g, (first, _) in enumerate(ghosts)]
    events.sort()
    ids = np.zeros((n_people, n_frames), dtype=np.int64)
    ghost_ids = [0] * len(ghosts)
    for next_id, (first, kind, who) in enumerate(events, start=1):
        if kind == 0:
            ids[who, first] = next_id
        else:
            ghost_ids[who] = next_id
    # each id holds until the person's next new track
    frame = np.arange(n_frames)
    for p in range(n_people):
        last = np.maximum.accumulate(np.where(ids[p] > 0, frame, -1))
        ids[p] = np.where(last >= 0, ids[p][np.maximum(last, 0)], 0)
    return ids, ghost_ids


def _ghost_pose(
    cam: CameraCalibration, clips: list[Clip], rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """A spurious body in the camera frame: a random mocap pose, somewhere in view, distorted."""
    clip = clips[int(rng.integers(len(clips)))]
    pose = clip.positions[int(rng.integers(clip.positions.shape[0]))]
    pose = pose - np.array([*pose[_IDX("Pelvis"), :2], 0.0])
    yaw = rng.uniform(0.0, 2.0 * np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    pose = pose @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T
    rotation = Rotation.from_quat(cam.rotation).as_matrix()
    ahead = rotation[:, 2].copy()
    ahead[2] = 0.0
    ahead /= np.linalg.norm(ahead)
    right = np.array([-ahead[1], ahead[0], 0.0])
    spot = cam.translation + rng.uniform(1.5, 4.5) * ahead + rng.uniform(-1.0, 1.0) * right
    world = pose + np.array([spot[0], spot[1], 0.0])
    world = world + rng.normal(0.0, 0.05, world.shape)
    positions = (world - cam.translation) @ rotation
    levels = np.where(rng.random(AZURE_KINECT.n_joints) < 0.7, LEVEL_LOW, LEVEL_MEDIUM)
    return positions, levels


def _rows(positions: np.ndarray, levels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Marker and link rows ``(..., 32, 20)`` of many skeletons at once (see hiros_core.model).

    Equivalent to ``Skeleton.from_positions`` with every joint present, without its per-skeleton
    cost: links are the midpoints of their joints with the smaller confidence.
    """
    shape = positions.shape[:-1]
    confidences = CONFIDENCE_OF_LEVEL[levels]
    markers = np.full((*shape, 20), np.nan)
    markers[..., 0] = confidences
    markers[..., 1:4] = positions
    links = np.full((*shape, 20), np.nan)
    parents, children = AZURE_KINECT.link_parents, AZURE_KINECT.link_children
    links[..., children, 0] = np.fmin(confidences[..., parents], confidences[..., children])
    links[..., children, 1:4] = 0.5 * (positions[..., parents, :] + positions[..., children, :])
    return markers, links


def _skeleton(
    markers: np.ndarray, links: np.ndarray, skeleton_id: int, stamp: int, frame_id: str
) -> Skeleton:
    link_present = np.zeros(AZURE_KINECT.n_joints, dtype=bool)
    link_present[AZURE_KINECT.link_children] = True
    return Skeleton(
        id=skeleton_id,
        src_time_ns=stamp,
        src_frame=frame_id,
        layout=AZURE_KINECT,
        markers=markers,
        links=links,
        marker_present=np.ones(AZURE_KINECT.n_joints, dtype=bool),
        link_present=link_present,
    )


def _groups(
    frame_id: str, stream: _Stream, person_ids: np.ndarray
) -> tuple[list[SkeletonGroup], list[np.ndarray]]:
    groups, labels = [], []
    markers, links = _rows(stream.positions, stream.levels)
    ghost_rows = [
        _rows(poses, np.broadcast_to(levels, poses.shape[:2]))
        for *_, poses, levels in stream.ghosts
    ]
    for n in np.flatnonzero(stream.kept):
        stamp = int(stream.stamps_ns[n])
        skeletons, truth_ids = [], []
        for p in np.flatnonzero(stream.detected[:, n]):
            skeletons.append(
                _skeleton(markers[p, n], links[p, n], int(stream.ids[p, n]), stamp, frame_id)
            )
            truth_ids.append(int(person_ids[p]))
        for (first, stop, ghost_id, _, _), (g_markers, g_links) in zip(
            stream.ghosts, ghost_rows, strict=True
        ):
            if first <= n < stop:
                skeletons.append(
                    _skeleton(g_markers[n - first], g_links[n - first], ghost_id, stamp, frame_id)
                )
                truth_ids.append(-1)
        order = np.argsort([s.id for s in skeletons], kind="stable")
        groups.append(SkeletonGroup(stamp, frame_id, [skeletons[i] for i in order]))
        labels.append(np.array(truth_ids, dtype=np.int64)[order])
    return groups, labels


def simulate(params: SimParams | None = None, progress: object = None) -> SimResult:
    """Run the simulator.

    Args:
        params: the knobs; defaults to ``SimParams()``.
        progress: optional callable ``progress(step: str, done: int, total: int)`` for a bar.

    Raises:
        ConfigError: impossible parameters (see ``SimParams.check``).
        RecordingError: a BVH file cannot be read or mapped.

    """
    params = params or SimParams()
    params.check()

    def report(step: str, done: int, total: int) -> None:
        if callable(progress):
            progress(step, done, total)

    seeds = np.random.SeedSequence(params.seed).spawn(2)
    report("people", 0, params.n_cameras + 2)
    people = _people(params, np.random.default_rng(seeds[0]))
    truth = _truth(params, people)
    report("cameras", 1, params.n_cameras + 2)
    calibration = make_setup(
        params.setup,
        params.n_cameras,
        np.random.default_rng(seeds[1]),
        radius=params.camera_radius,
        height_range=params.camera_height,
        tilt_range=params.camera_tilt,
        max_time_offset=params.max_time_offset,
        drift_ppm=params.drift_ppm,
        clock_start=params.clock_start,
        pair_angle=params.pair_angle,
        pair_baseline=params.pair_baseline,
    )
    if params.bump_camera and params.bump_camera not in calibration.cameras:
        names = sorted(calibration.cameras)
        msg = f"bump_camera must be one of {names}, not {params.bump_camera!r}"
        raise ConfigError(msg)
    clips = [person.clip for person in people]
    camera_groups, labels, receive = {}, {}, {}
    camera_seeds = np.random.SeedSequence([params.seed, 1]).spawn(len(calibration.cameras))
    for k, (name, cam) in enumerate(calibration.cameras.items()):
        bump = bumped_pose(cam, params) if name == params.bump_camera else None
        host_rng = np.random.default_rng(np.random.SeedSequence([params.seed, 2, k]))
        stream = _observe(
            cam,
            truth,
            clips,
            params,
            np.random.default_rng(camera_seeds[k]),
            bump=bump,
            host_rng=host_rng,
        )
        camera_groups[name], labels[name] = _groups(cam.frame_id, stream, truth.person_ids)
        receive[name] = stream.receive_ns[stream.kept]
        report(name, 2 + k, len(calibration.cameras) + 2)
    report("done", len(calibration.cameras) + 2, len(calibration.cameras) + 2)
    return SimResult(replace(params), camera_groups, truth, calibration, labels, receive)
