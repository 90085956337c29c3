"""The filter stage: smooth each person's joints and give them velocities and accelerations.

Per track id and per joint, three causal estimators run side by side
(:mod:`hiros_filter.estimators`), all tracks of a frame in one batch:

- a Butterworth low-pass (order ``BUTTERWORTH_ORDER``, ``cutoff_frequency``; Hi-ROS's filter) on
  every coordinate. Its coefficients assume a constant sampling rate, so the rate is estimated
  from the stamps (median interval of the recent frames); when the estimate moves by more than
  ``RATE_TOLERANCE`` the filter is re-designed and restarted at rest on its last output. A late
  frame (dt ≈ k sampling periods) is resampled: the k - 1 missing samples are interpolated
  linearly before it, so the filter keeps its time base;
- a constant-acceleration Kalman filter (continuous white jerk, any dt) that gives the
  velocities and accelerations, and the positions when ``filter`` is ``kalman``. Its process
  noise adapts per joint to the normalised innovation (Bar-Shalom's continuous noise-level
  adjustment): still joints are smoothed hard, a joint that starts moving is followed closely;
- exponential smoothing of the orientations on SO(3) by slerp, with the weight of the new
  sample ``1 - exp(-2π f_c dt)`` (the discrete first-order low-pass at
  ``orientation_cutoff_frequency``), and the angular velocity from consecutive outputs.

A track unseen for more than ``MAX_GAP`` seconds, or a joint absent that long, restarts from its
next measurement (no extrapolation across gaps, no blow-up); a joint absent for a shorter time
is carried by the Kalman prediction so the low-pass keeps a continuous input, and stays absent in
the output. Frames whose stamp is not after the track's last one are dropped with a count.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from hiros_core.accounting import Accounted, Drops
from hiros_core.errors import ConfigError
from hiros_core.layouts import Layout
from hiros_core.model import Skeleton, SkeletonGroup, SkeletonRows, link_rows
from hiros_core.stacking import LayoutRows, output_skeletons, stack_frame
from hiros_filter.estimators import ButterworthBank, KalmanBank
from hiros_filter.kernel_args import (
    FrameRows,
    KalmanModel,
    KalmanState,
    LengthState,
    LinkEnds,
    OrientationState,
    TrackStamps,
)
from hiros_filter.lengths import LengthKeeper

__all__ = [
    "BUTTERWORTH_ORDER",
    "MAX_GAP",
    "MAX_NOISE_SCALE",
    "RATE_TOLERANCE",
    "TRACK_TIMEOUT",
    "Filter",
    "FilterParams",
]

_FILTERS = ("butterworth", "kalman")
_RATE_WINDOW = 64  # recent frame intervals the sampling rate is estimated from
_NEVER = np.iinfo(np.int64).min // 2  # "joint never seen" stamp, far in the past

BUTTERWORTH_ORDER = 2
"""Order of the Butterworth low-pass (Hi-ROS's): its lag and smoothing are set by
``cutoff_frequency``."""

RATE_TOLERANCE = 0.15
"""Relative change of the estimated sampling rate that re-designs the Butterworth low-pass.

A camera's frame rate is fixed (15 or 30 Hz), so the estimate moves only with jitter or a
changed source: 15 % ignores the jitter and catches a 30 -> 15 Hz change."""

MAX_NOISE_SCALE = 10.0
"""Largest factor of the adaptive process noise: a joint whose innovations are larger than the
Kalman filter expects (a movement starting) gets its process noise scaled up by their
normalised size, smoothed, up to this factor."""

MAX_GAP = 0.5
"""Seconds a track or joint may be unseen before it restarts from its next measurement: longer
than a few dropped frames at 15 Hz, shorter than the motion stays predictable."""

TRACK_TIMEOUT = 5.0
"""Seconds after which an unseen track's state is freed (its id is the tracker's: a track
back after that restarts, as after ``MAX_GAP``)."""


@dataclass
class FilterParams:
    """Parameters of the filter node (ROS parameter names and defaults).

    The topics are the node's own parameters (``input_topic``, ``output_topic``), not the
    algorithm's.

    Attributes:
        filter: which estimate gives the positions: ``kalman`` (default: a few ms of lag) or
            ``butterworth`` (Hi-ROS's choice; a 2nd-order 6 Hz low-pass lags ~37 ms).
        cutoff_frequency: Hz, -3 dB point of the low-pass.
        jerk_spectral_density: Kalman process noise, m^2/s^5 (higher: follows faster, smooths less).
        measurement_noise: Kalman position noise, metres (standard deviation).
        orientation_cutoff_frequency: Hz of the orientation smoothing.
        keep_link_lengths: links whose input length does not change from frame to frame (the
            optimizer's calibrated links) keep that length in the output, with velocities and
            accelerations that agree with it (:mod:`hiros_filter.lengths`).

    """

    filter: str = "kalman"
    cutoff_frequency: float = 6.0
    jerk_spectral_density: float = 300.0
    measurement_noise: float = 0.01
    orientation_cutoff_frequency: float = 6.0
    keep_link_lengths: bool = True

    def __post_init__(self) -> None:
        if self.filter not in _FILTERS:
            msg = f"filter must be one of {_FILTERS}, got {self.filter!r}"
            raise ConfigError(msg)
        if self.cutoff_frequency <= 0:
            msg = "cutoff_frequency must be > 0 Hz"
            raise ConfigError(msg)
        if min(self.jerk_spectral_density, self.measurement_noise) <= 0:
            msg = "jerk_spectral_density and measurement_noise must be > 0"
            raise ConfigError(msg)
        if self.orientation_cutoff_frequency <= 0:
            msg = "orientation_cutoff_frequency must be > 0"
            raise ConfigError(msg)


class _Running(NamedTuple):
    """A skeleton of a running track: its place in the output group and its stack row."""

    index: int
    skeleton: Skeleton
    row: int


class _KernelArguments(NamedTuple):
    """The bundles :func:`~hiros_filter.compiled.filter_step` takes that last beyond a frame."""

    kalman: KalmanState
    model: KalmanModel
    lengths: LengthState
    orientations: OrientationState
    link_ends: LinkEnds


class _Tracks:
    """State of every track of one layout, one row (slot) per track id."""

    def __init__(self, layout: Layout, params: FilterParams) -> None:
        self.layout = layout
        self.n_joints = layout.n_joints
        capacity = 4
        self.slots: dict[int, int] = {}
        self.free: list[int] = list(range(capacity - 1, -1, -1))
        self.time_ns = np.zeros(capacity, dtype=np.int64)
        self.joint_time_ns = np.full((capacity, self.n_joints), _NEVER, dtype=np.int64)
        self.last_input = np.full((capacity, self.n_joints, 3), np.nan)
        self.last_output = np.full((capacity, self.n_joints, 3), np.nan)
        self.last_lengths = np.full((capacity, self.n_joints), np.nan)  # input link lengths
        self.keeper = LengthKeeper(layout.tree)
        self.link_parents = np.asarray(layout.link_parents, dtype=np.intp)
        self.link_children = np.asarray(layout.link_children, dtype=np.intp)
        self.quaternions = np.full((capacity, self.n_joints, 4), np.nan)
        self.angular_velocities = np.full((capacity, self.n_joints, 3), np.nan)
        self.angular_accelerations = np.full((capacity, self.n_joints, 3), np.nan)
        self.kalman = KalmanBank(
            (capacity, self.n_joints),
            params.jerk_spectral_density,
            params.measurement_noise,
            max_noise_scale=MAX_NOISE_SCALE,
        )
        self.low_pass: ButterworthBank | None = None
        self.designed_for = np.zeros(capacity)  # rate each slot's low-pass state belongs to
        self._kernel_arguments: _KernelArguments | None = None

    def retune(self, params: FilterParams) -> None:
        """Take new noise and low-pass parameters, keeping every track's state.

        The Kalman constants change in place, the covariances scaled with the measurement
        variance: the state keeps the weight it had against a measurement (kept as it was, a
        covariance tuned to a far smaller noise would make the filter coast on its old
        velocities), and settles to the new tuning over the next frames. The low-pass is
        designed anew on the next frame, each channel restarting at rest on its last output
        (as after a rate change).
        """
        kalman = self.kalman
        r = params.measurement_noise**2
        kalman.P *= r / kalman.r
        kalman.q = params.jerk_spectral_density
        kalman.r = r
        kalman.initial[0, 0] = kalman.r
        self.low_pass = None
        self.designed_for[:] = 0.0
        self._kernel_arguments = None

    def kernel_arguments(self, params: FilterParams) -> _KernelArguments:
        """The state and constants :func:`~hiros_filter.compiled.filter_step` takes, grouped.

        Built once (and again after the tables grow): packing them is a dozen attribute
        look-ups and conversions per frame otherwise.
        """
        if self._kernel_arguments is None:
            kalman = self.kalman
            self._kernel_arguments = _KernelArguments(
                kalman=KalmanState(x=kalman.x, P=kalman.P, scale=kalman.scale),
                model=KalmanModel(
                    q=float(kalman.q),
                    r=float(kalman.r),
                    max_scale=float(kalman.max_noise_scale),
                    rate=float(kalman.adaptation_rate),
                    initial=kalman.initial,
                ),
                lengths=LengthState(
                    keep=bool(params.keep_link_lengths),
                    parents=self.keeper.tree.parents,
                    order=self.keeper.tree.order,
                    last_lengths=self.last_lengths,
                ),
                orientations=self.orientations(params),
                link_ends=LinkEnds(parents=self.link_parents, children=self.link_children),
            )
        return self._kernel_arguments

    def orientations(self, params: FilterParams) -> OrientationState:
        """The tracks' orientations, as ``compiled.smooth_orientations`` takes them."""
        return OrientationState(
            quaternions=self.quaternions,
            velocities=self.angular_velocities,
            accelerations=self.angular_accelerations,
            cutoff=float(params.orientation_cutoff_frequency),
        )

    def slot(self, track_id: int) -> int:
        """The row of ``track_id``, allocating (and growing the arrays) when new."""
        if track_id in self.slots:
            return self.slots[track_id]
        if not self.free:
            self._grow(2 * len(self.time_ns))
        row = self.free.pop()
        self.slots[track_id] = row
        return row

    def release(self, track_id: int) -> None:
        self.free.append(self.slots.pop(track_id))

    def _grow(self, capacity: int) -> None:
        old = len(self.time_ns)
        self._kernel_arguments = None  # it holds the arrays being replaced
        self.free.extend(range(capacity - 1, old - 1, -1))
        for name, fill in (
            ("time_ns", 0),
            ("joint_time_ns", _NEVER),
            ("last_input", np.nan),
            ("last_output", np.nan),
            ("last_lengths", np.nan),
            ("quaternions", np.nan),
            ("angular_velocities", np.nan),
            ("angular_accelerations", np.nan),
            ("designed_for", 0.0),
        ):
            array = getattr(self, name)
            pad = np.full((capacity - old, *array.shape[1:]), fill, dtype=array.dtype)
            setattr(self, name, np.concatenate([array, pad]))
        self.kalman.grow(capacity)
        if self.low_pass is not None:
            self.low_pass.grow(capacity)


class Filter(Accounted):
    """Causal smoothing with velocities and accelerations (module docstring).

    Attributes:
        params: the parameters.
        drops: reason -> count of skeletons not filtered (a frame is never dropped whole:
            each ``update`` is processed, see ``Accounted``).

    """

    def __init__(self, params: FilterParams | None = None) -> None:
        self.params = params or FilterParams()
        self.drops = Drops()
        self._layouts: dict[str, _Tracks] = {}
        self._layout_of: dict[int, str] = {}
        self._intervals: deque[float] = deque(maxlen=_RATE_WINDOW)
        _warm_up()

    @property
    def sample_frequency(self) -> float | None:
        """Hz the low-pass is designed for, estimated from the stamps (None: no data yet)."""
        if not self._intervals:
            return None
        return 1.0 / float(np.median(self._intervals))

    def set_params(self, params: FilterParams) -> None:
        """Filter with ``params`` from the next frame on; the tracks keep their state.

        Meant for the noise, cutoff and timing parameters (the node's live ones); ``filter``
        is chosen at construction.
        """
        self.params = params
        for tracks in self._layouts.values():
            tracks.retune(params)

    def reset(self) -> None:
        """Forget every track (e.g. when a recording restarts)."""
        self._layouts.clear()
        self._layout_of.clear()
        self._intervals.clear()

    def update(self, group: SkeletonGroup) -> SkeletonGroup:
        """Filter every tracked person of ``group``; returns new skeletons, input untouched."""
        out = SkeletonGroup(group.stamp_ns, group.frame_id, [])
        batches: dict[str, tuple[list[Skeleton], list[_Running], LayoutRows]] = {}
        seen: set[int] = set()
        max_gap_ns = round(MAX_GAP * 1e9)
        places = stack_frame(group.skeletons, self.drops) if group.skeletons else []
        for skeleton, place in zip(group.skeletons, places, strict=True):
            if place is None or not self._valid(skeleton, seen):
                if skeleton.id < 0 and skeleton.markers.shape[0] == skeleton.layout.n_joints:
                    out.skeletons.append(skeleton.copy())
                continue
            tracks = self._tracks_for(skeleton)
            starts, steps, _ = batches.setdefault(skeleton.layout.name, ([], [], place[0]))
            if skeleton.id not in tracks.slots:
                result = skeleton.copy()
                starts.append(result)
            else:
                elapsed = skeleton.src_time_ns - tracks.time_ns.item(tracks.slots[skeleton.id])
                continues = self._continues(elapsed, max_gap_ns)
                if continues is None:
                    continue
                if not continues:
                    result = skeleton.copy()
                    starts.append(result)
                else:
                    self._intervals.append(elapsed * 1e-9)
                    # Its output is built by ``_step`` from the batch; hold its place.
                    steps.append(_Running(len(out.skeletons), skeleton, place[1]))
                    result = skeleton
            out.skeletons.append(result)
        for name, (starts, steps, stack) in batches.items():
            tracks = self._layouts[name]
            if starts:
                self._start(tracks, starts)
            if steps:
                results = self._step(tracks, stack, steps)
                for step, result in zip(steps, results, strict=True):
                    out.skeletons[step.index] = result
        self._forget_old_tracks(group.stamp_ns)
        self.processed += 1  # (once it went through: a frame whose update raised is not)
        return out

    # ------------------------------------------------------------------------ internals

    def _continues(self, elapsed_ns: int, max_gap_ns: int) -> bool | None:
        """Whether a track's new frame continues it (True), restarts it (False) or is dropped.

        A frame far (over ``MAX_GAP``) before the track's previous one restarts the track:
        the previous stamp was a glitch or the source restarted, and dropping would stop
        the track for good after one frame stamped far in the future.
        """
        if -max_gap_ns <= elapsed_ns <= 0:
            self.drops.detections("stamp not after the track's previous one")
            return None
        if elapsed_ns < 0:
            self.drops.detections("stamp far before the track's previous one (restarted)")
        return 0 < elapsed_ns <= max_gap_ns

    def _valid(self, skeleton: Skeleton, seen: set[int]) -> bool:
        """Whether a usable skeleton (:func:`stack_frame`) has a new track id (else counted)."""
        if skeleton.id < 0:
            self.drops.detections("no track id (passed through)")
            return False
        if skeleton.id in seen:
            self.drops.detections("track id repeated within a group")
            return False
        seen.add(skeleton.id)
        return True

    def _tracks_for(self, skeleton: Skeleton) -> _Tracks:
        name = skeleton.layout.name
        previous = self._layout_of.get(skeleton.id)
        if previous is not None and previous != name:  # the layout changed under this id
            self._layouts[previous].release(skeleton.id)
        self._layout_of[skeleton.id] = name
        if name not in self._layouts:
            self._layouts[name] = _Tracks(skeleton.layout, self.params)
        return self._layouts[name]

    def _start(self, tracks: _Tracks, skeletons: list[Skeleton]) -> None:
        """New (or restarting) tracks: every estimator at rest on the measurement."""
        rows = np.array([tracks.slot(s.id) for s in skeletons])
        present = np.array([s.marker_present for s in skeletons])
        positions = np.array([s.positions for s in skeletons])
        positions = np.where(present[..., None], positions, np.nan)
        tracks.time_ns[rows] = [s.src_time_ns for s in skeletons]
        tracks.joint_time_ns[rows] = np.where(present, tracks.time_ns[rows, None], _NEVER)
        tracks.last_input[rows] = positions
        tracks.last_output[rows] = positions
        tracks.last_lengths[rows] = tracks.keeper.lengths(positions)
        tracks.designed_for[rows] = 0.0  # low-pass state restarts from last_output when used
        slot_index, joints = np.nonzero(present)
        tracks.kalman.reset(rows[slot_index], joints, positions[slot_index, joints])
        tracks.quaternions[rows] = np.nan
        markers = np.array([s.markers for s in skeletons])
        self._smooth_orientations(tracks, rows, markers, present, dt=None)
        markers[..., 8:11][present] = 0.0
        markers[..., 14:17][present] = 0.0
        for n, skeleton in enumerate(skeletons):  # the stage's own copies: rows replaced
            skeleton.markers = markers[n]

    def _step(self, tracks: _Tracks, stack: LayoutRows, steps: list[_Running]) -> list[Skeleton]:
        """Continue running tracks: the filtered copies of their skeletons (input untouched).

        Every track of the frame in one batch: their rows of the frame's stack (already
        copies) are filtered in place, and the output skeletons are views of them (links
        rebuilt for all of them at once, boxes copied). In Kalman mode that is one kernel
        call (``compiled.filter_step``); in Butterworth mode, the Kalman, length and
        orientation kernels around the low-pass (``_step_rows``).
        """
        skeletons = [step.skeleton for step in steps]
        indices = [step.row for step in steps]
        markers, present = stack.take(indices)
        rows = np.array([tracks.slots[s.id] for s in skeletons], dtype=np.int64)
        stamps = np.array([s.src_time_ns for s in skeletons], dtype=np.int64)
        if self.params.filter == "kalman":
            links, link_present = self._step_compiled(tracks, rows, stamps, markers, present)
        else:
            self._step_rows(tracks, rows, stamps, markers, present)
            links, link_present = link_rows(markers, present, tracks.layout)
        filtered = SkeletonRows(markers, present, links, link_present, stack.input_boxes(indices))
        return output_skeletons(skeletons, [s.id for s in skeletons], filtered)

    def _step_compiled(
        self,
        tracks: _Tracks,
        rows: np.ndarray,
        stamps: np.ndarray,
        markers: np.ndarray,
        present: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_step_rows` and the links in Kalman mode, as one kernel call (same numbers)."""
        from hiros_filter.compiled import filter_step

        bundles = tracks.kernel_arguments(self.params)
        stamped = TrackStamps(
            rows=rows,
            time_ns=tracks.time_ns,
            joint_time_ns=tracks.joint_time_ns,
            max_gap_ns=round(MAX_GAP * 1e9),
        )
        frame = FrameRows(markers=markers, present=present, stamps=stamps)
        return filter_step(
            bundles.kalman,
            bundles.model,
            stamped,
            frame,
            bundles.lengths,
            bundles.orientations,
            bundles.link_ends,
        )

    def _step_rows(
        self,
        tracks: _Tracks,
        rows: np.ndarray,
        stamps: np.ndarray,
        markers: np.ndarray,
        present: np.ndarray,
    ) -> None:
        """Filter the ``(n, J, 20)`` rows of running tracks in place (and their state)."""
        dt = (stamps - tracks.time_ns[rows]) * 1e-9
        measured = markers[..., 1:4]
        max_gap_ns = round(MAX_GAP * 1e9)
        joint_time_ns = tracks.joint_time_ns[rows]
        restart = present & (stamps[:, None] - joint_time_ns > max_gap_ns)
        kalman = tracks.kalman
        any_restart = restart.any()
        self._kalman_step(
            tracks, rows, dt, present & ~restart if any_restart else present, measured
        )
        if any_restart:
            index, joints = np.nonzero(restart)
            kalman.reset(rows[index], joints, measured[index, joints])
        tracks.joint_time_ns[rows] = np.where(present, stamps[:, None], joint_time_ns)
        state = kalman.state(rows)  # (n, J, [position, velocity, acceleration], axis)
        if self.params.filter == "kalman":
            smoothed = state[:, :, 0]
        else:
            # Joints lost for too long leave the low-pass input until they return.
            lost = stamps[:, None] - tracks.joint_time_ns[rows] > max_gap_ns
            low_pass_input = np.where(present[..., None], measured, state[:, :, 0])
            low_pass_input[lost] = np.nan
            smoothed = self._low_pass(tracks, rows, low_pass_input, restart, dt)
        states = (smoothed, state[:, :, 1], state[:, :, 2])
        if self.params.keep_link_lengths:
            states = self._keep_lengths(tracks, rows, states, measured, present)
        smoothed, velocities, accelerations = states
        tracks.time_ns[rows] = stamps
        self._smooth_orientations(tracks, rows, markers, present, dt)
        mask = present[..., None]
        np.copyto(markers[..., 1:4], smoothed, where=mask)
        np.copyto(markers[..., 8:11], velocities, where=mask)
        np.copyto(markers[..., 14:17], accelerations, where=mask)

    def _kalman_step(
        self,
        tracks: _Tracks,
        rows: np.ndarray,
        dt: np.ndarray,
        mask: np.ndarray,
        measured: np.ndarray,
    ) -> None:
        """Predict the ``rows``' Kalman states by ``dt`` and correct them where ``mask`` is set."""
        tracks.kalman.step(rows, dt, mask, measured)

    def _keep_lengths(
        self,
        tracks: _Tracks,
        rows: np.ndarray,
        states: tuple[np.ndarray, np.ndarray, np.ndarray],
        measured: np.ndarray,
        present: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``states`` with the links held in the input kept at their length (``lengths``)."""
        from hiros_filter.compiled import keep_lengths

        stacked = np.array(states)
        tracks.last_lengths[rows] = keep_lengths(
            tracks.keeper.tree.parents,
            tracks.keeper.tree.order,
            stacked,
            np.ascontiguousarray(measured),
            present,
            tracks.last_lengths[rows],
        )
        return stacked[0], stacked[1], stacked[2]

    def _low_pass(
        self,
        tracks: _Tracks,
        rows: np.ndarray,
        samples: np.ndarray,
        restart: np.ndarray,
        dt: np.ndarray,
    ) -> np.ndarray:
        """Butterworth output ``(n, J, 3)`` for this frame, resampled to the design rate."""
        rate = self.sample_frequency
        n, n_joints = samples.shape[:2]
        channels = 3 * n_joints
        if tracks.low_pass is None or (
            abs(tracks.low_pass.sample_frequency - rate) > RATE_TOLERANCE * rate
        ):
            tracks.low_pass = ButterworthBank(
                BUTTERWORTH_ORDER,
                self.params.cutoff_frequency,
                rate,
                (len(tracks.time_ns), channels),
            )
        flat = samples.reshape(n, channels)
        previous = tracks.last_input[rows].reshape(n, channels)
        # Restarting channels (new design, restarted or first-seen joints) begin at rest on
        # their last output or new value; lost channels hold still.
        redesigned = tracks.designed_for[rows] != tracks.low_pass.sample_frequency
        tracks.designed_for[rows] = tracks.low_pass.sample_frequency
        old = tracks.last_output[rows].reshape(n, channels)
        settle = redesigned[:, None] & np.isfinite(old)
        slot, channel = np.nonzero(settle)
        tracks.low_pass.reset(rows[slot], channel, old[slot, channel])
        begin = np.repeat(restart, 3, axis=1) | (~np.isfinite(previous) & np.isfinite(flat))
        slot, channel = np.nonzero(begin)
        tracks.low_pass.reset(rows[slot], channel, flat[slot, channel])
        previous = np.where(begin, flat, previous)
        flat = np.nan_to_num(np.where(np.isfinite(flat), flat, previous))
        previous = np.nan_to_num(previous)
        limit = max(1, round(MAX_GAP * rate))
        steps = np.clip(np.round(dt * rate).astype(int), 1, limit)
        output = np.empty((n, channels))
        for count in np.unique(steps):  # usually one: every track shares the frame's dt
            group = np.flatnonzero(steps == count)
            fractions = np.arange(1, count + 1) / count
            resampled = previous[group, :, None] + (flat - previous)[group, :, None] * fractions
            output[group] = tracks.low_pass.step(rows[group], resampled)
        output = output.reshape(samples.shape)
        known = np.isfinite(samples)
        tracks.last_input[rows] = np.where(known, samples, tracks.last_input[rows])
        tracks.last_output[rows] = np.where(known, output, tracks.last_output[rows])
        return output

    def _smooth_orientations(
        self,
        tracks: _Tracks,
        rows: np.ndarray,
        markers: np.ndarray,
        present: np.ndarray,
        dt: np.ndarray | None,
    ) -> None:
        """Slerp-smooth the orientations of ``markers`` ``(n, J, 20)`` in place (and the state).

        Orientations, angular velocities and accelerations of the valid joints are written
        into ``markers``; every joint is computed at once and the results are kept by mask.
        """
        if dt is not None:
            from hiros_filter.compiled import smooth_orientations

            smooth_orientations(markers, present, rows, dt, tracks.orientations(self.params))
            return
        # A start: the valid orientations as they are, without angular rates.
        quaternions = markers[..., 4:8]
        norms = np.sqrt(np.add.reduce(quaternions * quaternions, axis=-1))  # as np.linalg.norm
        valid = present & np.isfinite(norms) & (norms > 0.5)
        unit = quaternions / np.where(valid, norms, 1.0)[..., None]
        keep = valid[..., None]
        tracks.quaternions[rows] = np.where(keep, unit, tracks.quaternions[rows])
        for rates in (tracks.angular_velocities, tracks.angular_accelerations):
            rates[rows] = np.where(keep, np.nan, rates[rows])
        np.copyto(markers[..., 4:8], tracks.quaternions[rows], where=keep)
        np.copyto(markers[..., 11:14], tracks.angular_velocities[rows], where=keep)
        np.copyto(markers[..., 17:20], tracks.angular_accelerations[rows], where=keep)

    def _forget_old_tracks(self, stamp_ns: int) -> None:
        timeout_ns = round(TRACK_TIMEOUT * 1e9)
        for tracks in self._layouts.values():
            times = tracks.time_ns.tolist()  # Python ints: cheaper to compare one by one
            for track_id, row in list(tracks.slots.items()):
                if stamp_ns - times[row] > timeout_ns:
                    tracks.release(track_id)
                    self._layout_of.pop(track_id, None)


_WARM = False


def _warm_up() -> None:
    """Compile (or load from numba's disk cache) the kernels when the first stage is built.

    Once per process, so a live node does not stall on its first frames: two frames of one
    person through each mode (Kalman: the one-call frame kernel; Butterworth: the Kalman,
    length and orientation kernels one by one).
    """
    global _WARM  # noqa: PLW0603 - once per process
    if _WARM:
        return
    _WARM = True
    from hiros_core.layouts import AZURE_KINECT

    positions = np.zeros((AZURE_KINECT.n_joints, 3))
    for mode in _FILTERS:
        stage = Filter(FilterParams(filter=mode))
        for frame in range(2):
            stamp = frame * 33_333_333
            skeleton = Skeleton.from_positions(
                positions, AZURE_KINECT, skeleton_id=0, src_time_ns=stamp
            )
            stage.update(SkeletonGroup(stamp, "world", [skeleton]))
