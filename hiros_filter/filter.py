"""The filter stage: smooth each person's joints and give them velocities and accelerations.

Per track id and per joint, three causal estimators run side by side
(:mod:`hiros_filter.estimators`):

- a Butterworth low-pass (``butterworth_order``, ``cutoff_frequency``; Hi-ROS's filter) on every
  coordinate. Its coefficients assume a constant sampling rate, so the rate is
  ``sample_frequency`` or, when that is <= 0, estimated from the stamps (median interval of the
  recent frames); when the estimate moves by more than ``rate_tolerance`` the filter is
  re-designed and restarted at rest on its last output. A late frame (dt ≈ k sampling periods)
  is resampled: the k - 1 missing samples are interpolated linearly before it, so the filter
  keeps its time base;
- a constant-acceleration Kalman filter (continuous white jerk, any dt) that gives the
  velocities and accelerations, and the positions when ``filter`` is ``kalman``;
- exponential smoothing of the orientations on SO(3) by slerp, with the weight of the new
  sample ``1 - exp(-2π f_c dt)`` (the discrete first-order low-pass at
  ``orientation_cutoff_frequency``), and the angular velocity from consecutive outputs.

A track unseen for more than ``max_gap`` seconds, or a joint absent that long, restarts from its
next measurement (no extrapolation across gaps, no blow-up); a joint absent for a shorter time
is carried by the Kalman prediction so the low-pass keeps a continuous input, and stays absent in
the output. Frames whose stamp is not after the track's last one are dropped with a count.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.errors import ConfigError
from hiros_core.model import Skeleton, SkeletonGroup, ns_to_sec
from hiros_filter.estimators import ButterworthBank, ConstantAccelerationKalman, slerp

__all__ = ["Filter", "FilterParams"]

_FILTERS = ("butterworth", "kalman")
_RATE_WINDOW = 64  # recent frame intervals the sampling rate is estimated from


@dataclass
class FilterParams:
    """Parameters of the filter node (ROS parameter names and defaults).

    Attributes:
        input_topic: optimised skeletons in.
        output_topic: filtered skeletons out.
        filter: which estimate gives the positions: ``kalman`` (default: a few ms of lag) or
            ``butterworth`` (Hi-ROS's choice; a 2nd-order 6 Hz low-pass lags ~37 ms).
        butterworth_order: order of the low-pass.
        cutoff_frequency: Hz, -3 dB point of the low-pass.
        sample_frequency: Hz of the input; <= 0 estimates it from the stamps.
        rate_tolerance: relative change of the estimated rate that re-designs the low-pass.
        jerk_spectral_density: Kalman process noise, m^2/s^5 (higher: follows faster, smooths less).
        measurement_noise: Kalman position noise, metres (standard deviation).
        orientation_cutoff_frequency: Hz of the orientation smoothing.
        max_gap: seconds a track or joint may be unseen before it restarts.
        track_timeout: seconds after which an unseen track's state is freed.

    """

    input_topic: str = "/hiros/optimizer"
    output_topic: str = "/hiros/filter"
    filter: str = "kalman"
    butterworth_order: int = 2
    cutoff_frequency: float = 6.0
    sample_frequency: float = -1.0
    rate_tolerance: float = 0.15
    jerk_spectral_density: float = 500.0
    measurement_noise: float = 0.01
    orientation_cutoff_frequency: float = 6.0
    max_gap: float = 0.5
    track_timeout: float = 5.0

    def __post_init__(self) -> None:
        if self.filter not in _FILTERS:
            msg = f"filter must be one of {_FILTERS}, got {self.filter!r}"
            raise ConfigError(msg)
        if self.butterworth_order < 1 or self.cutoff_frequency <= 0:
            msg = "butterworth_order must be >= 1 and cutoff_frequency > 0 Hz"
            raise ConfigError(msg)
        if self.jerk_spectral_density <= 0 or self.measurement_noise <= 0:
            msg = "jerk_spectral_density and measurement_noise must be > 0"
            raise ConfigError(msg)
        if self.orientation_cutoff_frequency <= 0 or self.max_gap <= 0:
            msg = "orientation_cutoff_frequency and max_gap must be > 0"
            raise ConfigError(msg)


@dataclass
class _Track:
    """Everything the stage keeps per track id."""

    time_ns: int
    kalman: ConstantAccelerationKalman
    joint_time_ns: np.ndarray  # (J,) last stamp each joint was measured; -1 never
    last_input: np.ndarray  # (J, 3) last low-pass input (measurement or prediction)
    last_output: np.ndarray  # (J, 3) last low-pass output
    quaternions: np.ndarray  # (J, 4) smoothed orientations, NaN unknown
    angular_velocities: np.ndarray  # (J, 3) rad/s
    angular_accelerations: np.ndarray  # (J, 3) rad/s^2
    bank: ButterworthBank | None = None


class Filter:
    """Causal smoothing with velocities and accelerations (module docstring).

    Attributes:
        params: the parameters.
        drops: reason -> count of skeletons not filtered.

    """

    def __init__(self, params: FilterParams | None = None) -> None:
        self.params = params or FilterParams()
        self.drops: Counter[str] = Counter()
        self._tracks: dict[int, _Track] = {}
        self._intervals: deque[float] = deque(maxlen=_RATE_WINDOW)

    @property
    def sample_frequency(self) -> float | None:
        """Hz the low-pass is designed for: the parameter, else the estimate (None: no data)."""
        if self.params.sample_frequency > 0:
            return self.params.sample_frequency
        if not self._intervals:
            return None
        return 1.0 / float(np.median(self._intervals))

    def update(self, group: SkeletonGroup) -> SkeletonGroup:
        """Filter every tracked person of ``group``; returns new skeletons, input untouched."""
        out = SkeletonGroup(group.stamp_ns, group.frame_id, [])
        seen: set[int] = set()
        for skeleton in group.skeletons:
            if skeleton.markers.shape[0] != skeleton.layout.n_joints:
                self.drops["marker rows do not match the layout"] += 1
                continue
            if not np.isfinite(skeleton.positions[skeleton.marker_present]).all():
                self.drops["non-finite position of a present joint"] += 1
                continue
            if skeleton.id < 0:
                self.drops["no track id (passed through)"] += 1
                out.skeletons.append(skeleton.copy())
                continue
            if skeleton.id in seen:
                self.drops["track id repeated within a group"] += 1
                continue
            seen.add(skeleton.id)
            result = self._filter(skeleton)
            if result is not None:
                out.skeletons.append(result)
        self._forget_old_tracks(group.stamp_ns)
        return out

    def reset(self) -> None:
        """Forget every track (e.g. when a recording restarts)."""
        self._tracks.clear()
        self._intervals.clear()

    # ------------------------------------------------------------------------ internals

    def _filter(self, skeleton: Skeleton) -> Skeleton | None:
        track = self._tracks.get(skeleton.id)
        if track is not None and len(track.joint_time_ns) != skeleton.layout.n_joints:
            track = None  # the layout changed under this id: start over
        if track is not None:
            dt = ns_to_sec(skeleton.src_time_ns - track.time_ns)
            if dt <= 0:
                self.drops["stamp not after the track's previous one"] += 1
                return None
            if dt > self.params.max_gap:
                track = None
            else:
                self._intervals.append(dt)
        result = skeleton.copy()
        if track is None:
            self._tracks[skeleton.id] = self._start(result)
            return result
        self._step(track, result, dt)
        return result

    def _start(self, skeleton: Skeleton) -> _Track:
        """A new track: every estimator at rest on the first measurement, output = input."""
        n_joints = skeleton.layout.n_joints
        present = skeleton.marker_present
        kalman = ConstantAccelerationKalman(
            self.params.jerk_spectral_density, self.params.measurement_noise, n_joints
        )
        positions = np.where(present[:, None], skeleton.positions, np.nan)
        kalman.reset(np.flatnonzero(present), positions[present])
        track = _Track(
            time_ns=skeleton.src_time_ns,
            kalman=kalman,
            joint_time_ns=np.where(present, skeleton.src_time_ns, -1),
            last_input=positions.copy(),
            last_output=positions.copy(),
            quaternions=np.full((n_joints, 4), np.nan),
            angular_velocities=np.full((n_joints, 3), np.nan),
            angular_accelerations=np.full((n_joints, 3), np.nan),
        )
        self._smooth_orientations(track, skeleton, dt=None)
        skeleton.velocities[present] = 0.0
        skeleton.accelerations[present] = 0.0
        return track

    def _step(self, track: _Track, skeleton: Skeleton, dt: float) -> None:
        present = skeleton.marker_present
        measured = skeleton.positions
        stale_after_ns = round(self.params.max_gap * 1e9)
        unseen_for = skeleton.src_time_ns - track.joint_time_ns
        restart = present & ((track.joint_time_ns < 0) | (unseen_for > stale_after_ns))
        carry = present & ~restart
        kalman = track.kalman
        kalman.predict(dt)
        kalman.update(np.flatnonzero(carry), measured[carry])
        kalman.reset(np.flatnonzero(restart), measured[restart])
        track.joint_time_ns[present] = skeleton.src_time_ns
        # Joints lost for too long are dropped from the low-pass input until they return.
        lost = (track.joint_time_ns < 0) | (
            skeleton.src_time_ns - track.joint_time_ns > stale_after_ns
        )
        low_pass_input = np.where(present[:, None], measured, kalman.positions)
        low_pass_input[lost] = np.nan

        smoothed = self._low_pass(track, low_pass_input, restart, dt)
        if self.params.filter == "kalman":
            smoothed = kalman.positions
        skeleton.positions[present] = smoothed[present]
        skeleton.velocities[present] = kalman.velocities[present]
        skeleton.accelerations[present] = kalman.accelerations[present]
        self._smooth_orientations(track, skeleton, dt)
        skeleton.update_links()
        track.time_ns = skeleton.src_time_ns

    def _low_pass(
        self, track: _Track, samples: np.ndarray, restart: np.ndarray, dt: float
    ) -> np.ndarray:
        """Butterworth output ``(J, 3)`` for this frame (resampled to the design rate)."""
        rate = self.sample_frequency
        channels = samples.size
        if track.bank is None or (
            abs(track.bank.sample_frequency - rate) > self.params.rate_tolerance * rate
        ):
            track.bank = ButterworthBank(
                self.params.butterworth_order, self.params.cutoff_frequency, rate, channels
            )
            rest = np.isfinite(track.last_output).ravel()
            track.bank.reset(np.flatnonzero(rest), track.last_output.ravel()[rest])
        flat_samples = samples.reshape(-1)
        previous = track.last_input.reshape(-1)
        # (Re)starting channels begin at rest on their new value; lost ones hold still.
        begin = np.repeat(restart, 3) | (~np.isfinite(previous) & np.isfinite(flat_samples))
        track.bank.reset(np.flatnonzero(begin), flat_samples[begin])
        previous = np.where(begin, flat_samples, previous)
        flat_samples = np.where(np.isfinite(flat_samples), flat_samples, previous)
        flat_samples = np.nan_to_num(flat_samples)
        previous = np.nan_to_num(previous)
        steps = int(np.clip(round(dt * rate), 1, max(1, round(self.params.max_gap * rate))))
        fractions = np.arange(1, steps + 1) / steps
        resampled = previous[:, None] + (flat_samples - previous)[:, None] * fractions[None, :]
        output = track.bank.step(resampled).reshape(samples.shape)
        known = np.isfinite(samples)
        track.last_input = np.where(known, samples, track.last_input)
        track.last_output = np.where(known, output, track.last_output)
        return output

    def _smooth_orientations(self, track: _Track, skeleton: Skeleton, dt: float | None) -> None:
        quaternions = skeleton.orientations
        norms = np.linalg.norm(quaternions, axis=-1)
        valid = skeleton.marker_present & np.isfinite(quaternions).all(axis=-1) & (norms > 0.5)
        fresh = valid.copy()
        if dt is not None:
            previous = track.quaternions
            carry = valid & np.isfinite(previous).all(axis=-1)
            fresh &= ~carry
            if carry.any():
                weight = 1.0 - np.exp(-2.0 * np.pi * self.params.orientation_cutoff_frequency * dt)
                smoothed = slerp(previous[carry], quaternions[carry] / norms[carry, None], weight)
                turn = Rotation.from_quat(smoothed) * Rotation.from_quat(previous[carry]).inv()
                angular_velocity = turn.as_rotvec() / dt
                last = track.angular_velocities[carry]
                angular_acceleration = np.where(
                    np.isfinite(last), (angular_velocity - last) / dt, 0.0
                )
                track.quaternions[carry] = smoothed
                track.angular_velocities[carry] = angular_velocity
                track.angular_accelerations[carry] = angular_acceleration
        track.quaternions[fresh] = quaternions[fresh] / norms[fresh, None]
        track.angular_velocities[fresh] = np.nan
        track.angular_accelerations[fresh] = np.nan
        skeleton.orientations[valid] = track.quaternions[valid]
        skeleton.angular_velocities[valid] = track.angular_velocities[valid]
        skeleton.angular_accelerations[valid] = track.angular_accelerations[valid]

    def _forget_old_tracks(self, stamp_ns: int) -> None:
        timeout_ns = round(self.params.track_timeout * 1e9)
        for track_id in [i for i, t in self._tracks.items() if stamp_ns - t.time_ns > timeout_ns]:
            del self._tracks[track_id]
