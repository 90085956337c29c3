"""The simulator's knobs: ``SimParams`` and the bundled clips it plays by default."""

from __future__ import annotations

import math
from dataclasses import dataclass

from hiros_core.errors import ConfigError
from hiros_data import DATA_DIR

__all__ = ["SimParams", "default_bvh_files"]

_MAX_PEOPLE = 6
_MOTIONS = ("bundled", "bandai")
_LOG_CLOCKS = ("receiver", "camera")


def default_bvh_files() -> tuple[str, ...]:
    """The bundled clips (hiros_data): three CMU walks/hops and the Xsens bending take."""
    return tuple(
        str(p)
        for p in (
            DATA_DIR / "mocap_cmu" / "131_01.bvh.gz",
            DATA_DIR / "mocap_cmu" / "131_02.bvh.gz",
            DATA_DIR / "mocap_cmu" / "131_03.bvh.gz",
            DATA_DIR / "unipd_bpe_sample" / "sbj01_bend1.bvh.gz",
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
    foot_height_bias: float = 0.005
    """Sigma of the ankles' and feet's offset along the world's up, per camera and person, the
    left and right alike, metres (their offset across the up is ``joint_bias``'s). Measured on
    the KinectMultiTrack sessions: each camera's floor under one person agrees with the
    other's to 0.14-0.46 cm, about 0.2 cm per camera; this is over twice that, those being
    Kinect v2 and four. It scales the left joints' ``joint_bias`` draws, so it is 0 too when
    ``joint_bias`` is."""
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
    planted_gain: float = 0.35
    """Sigma factor of a planted foot's ankle and foot (the SDK sees them against the floor).
    Fitted: the take's resting foot scatters 1.24 cm vertically about the suit's (its pelvis
    2.3 cm), the simulated one 1.26 cm on the take's scene (mean of seeds 0-3; one seed's
    figure, as ``hiros simulate --fit-noise`` prints it, moves by a few millimetres).
    The legs then bend to keep such a foot on its evidence (``hiros_sim.noise.plant_legs``)."""
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
