"""The per-joint estimators of the filter stage, batched over tracks and joints.

State lives in arrays with one row per track slot, so that one frame of every person costs a
fixed number of numpy calls, whatever the number of people:

- :class:`ButterworthBank`: causal low-pass (scipy ``butter`` + ``sosfilt`` with kept state) on
  every coordinate of every joint of every track, ``(S, J*3)`` channels.
- :class:`KalmanBank`: one constant-acceleration Kalman filter per joint, state
  ``[position, velocity, acceleration]`` per axis under a continuous white-jerk model (process
  noise as filterpy's ``Q_continuous_white_noise``); a frame's predict and masked correction
  are one compiled kernel (``hiros_filter.compiled.kalman_step``), whose numpy statement is
  ``test/support/filter_reference.py``'s.

Shapes: ``S`` track slots, ``J`` joints; positions ``(J, 3)`` metres.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ButterworthBank", "KalmanBank"]


class ButterworthBank:
    """Causal Butterworth low-pass on ``slots × channels`` signals at ``sample_frequency`` Hz.

    Attributes:
        sample_frequency: Hz the coefficients are designed for.
        sos: second-order sections of the design.
        state: ``(sections, slots, channels, 2)`` filter memory.

    """

    def __init__(
        self, order: int, cutoff_frequency: float, sample_frequency: float, shape: tuple[int, int]
    ) -> None:
        # Imported here: scipy.signal takes ~0.5 s to import, which every process of the
        # pipeline paid at its start while the default filter is the Kalman one.
        from scipy.signal import butter, sosfilt, sosfilt_zi

        self._sosfilt = sosfilt
        self.sample_frequency = sample_frequency
        cutoff = min(cutoff_frequency, 0.45 * sample_frequency)  # must stay below Nyquist
        self.sos = butter(order, cutoff, fs=sample_frequency, output="sos")
        self._unit_state = sosfilt_zi(self.sos)  # steady state for a constant input of 1
        self.state = np.zeros((self.sos.shape[0], *shape, 2))

    def grow(self, slots: int) -> None:
        """Make room for ``slots`` rows (new rows at rest on 0)."""
        extra = slots - self.state.shape[1]
        if extra > 0:
            pad = np.zeros((self.state.shape[0], extra, *self.state.shape[2:]))
            self.state = np.concatenate([self.state, pad], axis=1)

    def reset(self, slots: np.ndarray, channels: np.ndarray, values: np.ndarray) -> None:
        """Put (slot, channel) pairs at rest on ``values``: as if constant forever."""
        self.state[:, slots, channels, :] = self._unit_state[:, None, :] * values[None, :, None]

    def step(self, slots: np.ndarray, samples: np.ndarray) -> np.ndarray:
        """Filter ``(n, channels, k)`` consecutive samples of ``slots``; the last outputs."""
        n, channels, k = samples.shape
        state = self.state[:, slots].reshape(self.state.shape[0], n * channels, 2)
        flat = samples.reshape(n * channels, k)
        filtered, state = self._sosfilt(self.sos, flat, axis=-1, zi=state)
        self.state[:, slots] = state.reshape(self.state.shape[0], n, channels, 2)
        return filtered[:, -1].reshape(n, channels)


class KalmanBank:
    """Constant-acceleration Kalman filters for ``(S, J)`` joints, x/y/z sharing a covariance.

    The three axes of a joint see the same measurement noise and model, so their covariances
    are equal and one ``(3, 3)`` matrix per joint serves all three (filterpy-style names).
    Joints are the last axis: every step is a few numpy calls on ``(n, ..., J)`` blocks with
    long contiguous inner loops (a trailing axis of 3 makes numpy loop 3 values at a time).

    Attributes:
        x: ``(S, 3, 3, J)`` slot, [position, velocity, acceleration], axis, joint.
        P: ``(S, 3, 3, J)`` covariance over [position, velocity, acceleration], per joint.
        q: spectral density of the white jerk, m^2/s^5.
        r: variance of a position measurement, m^2.
        initial: ``(3, 3)`` covariance a joint (re)starts from.
        scale: ``(S, J)`` adaptive factor on ``q``: the smoothed normalised innovation squared
            ``|ν|² / (3 S)`` (about 1 when the model fits), clipped to ``[1, max_noise_scale]``.

    """

    def __init__(
        self,
        shape: tuple[int, int],
        jerk_spectral_density: float,
        measurement_noise: float,
        *,
        initial_velocity_sd: float = 1.0,
        initial_acceleration_sd: float = 5.0,
        max_noise_scale: float = 1.0,
        adaptation_rate: float = 0.5,
    ) -> None:
        self.q = jerk_spectral_density
        self.max_noise_scale = max_noise_scale
        self.adaptation_rate = adaptation_rate
        self.scale = np.ones(shape)
        self.r = measurement_noise**2
        self.initial = np.diag([self.r, initial_velocity_sd**2, initial_acceleration_sd**2])
        slots, joints = shape
        self.x = np.zeros((slots, 3, 3, joints))
        self.P = np.zeros((slots, 3, 3, joints))

    def grow(self, slots: int) -> None:
        """Make room for ``slots`` rows."""
        extra = slots - self.x.shape[0]
        if extra > 0:
            self.x = np.concatenate([self.x, np.zeros((extra, *self.x.shape[1:]))])
            self.P = np.concatenate([self.P, np.zeros((extra, *self.P.shape[1:]))])
            self.scale = np.concatenate([self.scale, np.ones((extra, *self.scale.shape[1:]))])

    def reset(self, slots: np.ndarray, joints: np.ndarray, positions: np.ndarray) -> None:
        """Start (slot, joint) pairs at rest at ``(n, 3)`` positions, wide velocity prior."""
        self.x[slots, :, :, joints] = 0.0
        self.x[slots, 0, :, joints] = positions
        self.P[slots, :, :, joints] = self.initial
        self.scale[slots, joints] = 1.0

    def state(self, slots: np.ndarray) -> np.ndarray:
        """``(n, J, 3, 3)`` [position, velocity, acceleration] × axis of each joint of ``slots``."""
        return self.x[_block(slots)].transpose(0, 3, 1, 2)

    def step(
        self, slots: np.ndarray, dt: np.ndarray, mask: np.ndarray, positions: np.ndarray
    ) -> None:
        """Advance each of ``slots`` by its own ``dt`` s, then correct it where ``mask`` is set.

        ``x ← F x``, ``P ← F P Fᵀ + scale · Q(dt)`` with ``F = [[1, dt, dt²/2], [0, 1, dt],
        [0, 0, 1]]`` (``Q`` at dt rounded to the µs), then where ``mask`` ``(n, J)``: gain
        ``K = P[:, 0] / (P[0, 0] + r)``, ``x += K ν``, ``P -= K P[0, :]`` with the innovation
        ``ν`` of ``positions`` ``(n, J, 3)`` (H = [1, 0, 0]), and the adaptive ``scale``
        smoothed towards ``|ν|² / (3 (P[0, 0] + r))`` within ``[1, max_noise_scale]``.
        """
        from hiros_filter.compiled import kalman_step
        from hiros_filter.kernel_args import KalmanFrame, KalmanModel, KalmanState

        dt = np.asarray(dt, dtype=float)
        positions = np.ascontiguousarray(positions, dtype=float)
        rows = np.asarray(slots, dtype=np.int64)
        frame = KalmanFrame(rows, dt, np.round(dt, 6), np.asarray(mask, dtype=bool), positions)
        constants = (self.q, self.r, self.max_noise_scale, self.adaptation_rate)
        model = KalmanModel(*(float(value) for value in constants), initial=self.initial)
        kalman_step(KalmanState(self.x, self.P, self.scale), model, frame)


def _block(slots: np.ndarray) -> slice | np.ndarray:
    """``slots`` as a slice when they are consecutive (views instead of copies), else as is."""
    first = int(slots[0])
    if slots.tolist() == list(range(first, first + len(slots))):
        return slice(first, first + len(slots))
    return slots
