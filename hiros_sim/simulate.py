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

The knobs are ``hiros_sim.params.SimParams``; presets of them for the robustness conditions are
in ``hiros_sim.presets``. What each camera's SDK reports is ``hiros_sim.sdk``'s.

``SimParams(noise=False)`` switches every imperfection off (no joint noise, jitter, drops,
misses, flips, swaps, ghosts, id changes) but keeps clock offsets, drift, field of view and the
confidence levels, so a camera's stream is exactly the truth moved into it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from hiros_core.calibration import Calibration
from hiros_core.errors import ConfigError
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_sim.bvh import read_bvh
from hiros_sim.cameras import make_setup
from hiros_sim.noise import CONFIDENCE_OF_LEVEL
from hiros_sim.params import SimParams, default_bvh_files
from hiros_sim.people import Clip, PersonPath, Repetitions, prepare_clip
from hiros_sim.sdk import CameraStream, bumped_pose, observe
from hiros_sim.shared import bandai_files

__all__ = ["SimResult", "Truth", "simulate"]


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
    frame_id: str, stream: CameraStream, person_ids: np.ndarray
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
        stream = observe(
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
