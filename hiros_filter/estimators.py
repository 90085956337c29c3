"""The per-joint estimators of the filter stage, batched over tracks and joints.

State lives in arrays with one row per track slot, so that one frame of every person costs a
fixed number of numpy calls, whatever the number of people:

- :class:`ButterworthBank`: causal low-pass (scipy ``butter`` + ``sosfilt`` with kept state) on
  every coordinate of every joint of every track, ``(S, J*3)`` channels.
- :class:`KalmanBank`: one constant-acceleration Kalman filter per joint, state
  ``[position, velocity, acceleration]`` per axis under a continuous white-jerk model (process
  noise from filterpy's ``Q_continuous_white_noise``); predict and update are ``einsum`` over
  all slots and joints.
- :func:`slerp` and :func:`rotation_vectors`: quaternion smoothing and angular velocity on SO(3).

Shapes: ``S`` track slots, ``J`` joints; positions ``(J, 3)`` metres; quaternions x, y, z, w.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from filterpy.common import Q_continuous_white_noise
from scipy.signal import butter, sosfilt, sosfilt_zi

__all__ = ["ButterworthBank", "KalmanBank", "rotation_vectors", "slerp"]


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
        filtered, state = sosfilt(self.sos, samples.reshape(n * channels, k), axis=-1, zi=state)
        self.state[:, slots] = state.reshape(self.state.shape[0], n, channels, 2)
        return filtered[:, -1].reshape(n, channels)


class KalmanBank:
    """Constant-acceleration Kalman filters for ``(S, J)`` joints, x/y/z sharing a covariance.

    The three axes of a joint see the same measurement noise and model, so their covariances
    are equal and one ``(3, 3)`` matrix per joint serves all three (filterpy-style names).

    Attributes:
        x: ``(S, J, 3, 3)`` slot, joint, [position, velocity, acceleration], axis.
        P: ``(S, J, 3, 3)`` covariance over [position, velocity, acceleration].
        q: spectral density of the white jerk, m^2/s^5.
        r: variance of a position measurement, m^2.
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
        self._initial = np.diag([self.r, initial_velocity_sd**2, initial_acceleration_sd**2])
        self.x = np.zeros((*shape, 3, 3))
        self.P = np.zeros((*shape, 3, 3))

    def grow(self, slots: int) -> None:
        """Make room for ``slots`` rows."""
        extra = slots - self.x.shape[0]
        if extra > 0:
            self.x = np.concatenate([self.x, np.zeros((extra, *self.x.shape[1:]))])
            self.P = np.concatenate([self.P, np.zeros((extra, *self.P.shape[1:]))])
            self.scale = np.concatenate([self.scale, np.ones((extra, *self.scale.shape[1:]))])

    def reset(self, slots: np.ndarray, joints: np.ndarray, positions: np.ndarray) -> None:
        """Start (slot, joint) pairs at rest at ``(n, 3)`` positions, wide velocity prior."""
        self.x[slots, joints] = 0.0
        self.x[slots, joints, 0] = positions
        self.P[slots, joints] = self._initial
        self.scale[slots, joints] = 1.0

    def predict(self, slots: np.ndarray, dt: np.ndarray) -> None:
        """Advance each slot by its own ``dt`` seconds (the model is continuous-time)."""
        F = np.zeros((len(dt), 3, 3))
        F[:, 0, 0] = F[:, 1, 1] = F[:, 2, 2] = 1.0
        F[:, 0, 1] = F[:, 1, 2] = dt
        F[:, 0, 2] = 0.5 * dt * dt
        Q = np.stack([_process_noise(round(float(step), 6), self.q) for step in dt])
        self.x[slots] = np.einsum("nab,njbk->njak", F, self.x[slots])
        self.P[slots] = F[:, None] @ self.P[slots] @ F[:, None].transpose(0, 1, 3, 2)
        self.P[slots] += Q[:, None] * self.scale[slots][..., None, None]

    def update(self, slots: np.ndarray, joints: np.ndarray, positions: np.ndarray) -> None:
        """Correct (slot, joint) pairs with measured ``(n, 3)`` positions (H = [1, 0, 0])."""
        P = self.P[slots, joints]
        gain = P[:, :, 0] / (P[:, 0, 0] + self.r)[:, None]  # (n, 3)
        innovation = positions - self.x[slots, joints, 0]  # (n, 3 axes)
        if self.max_noise_scale > 1.0:
            surprise = np.sum(innovation**2, axis=-1) / (3.0 * (P[:, 0, 0] + self.r))
            smoothed = self.scale[slots, joints] + self.adaptation_rate * (
                surprise - self.scale[slots, joints]
            )
            self.scale[slots, joints] = np.clip(smoothed, 1.0, self.max_noise_scale)
        self.x[slots, joints] += gain[:, :, None] * innovation[:, None, :]
        self.P[slots, joints] = P - gain[:, :, None] * P[:, None, 0, :]


@lru_cache(maxsize=256)
def _process_noise(dt: float, spectral_density: float) -> np.ndarray:
    """Q of the white-jerk model for one ``dt`` (µs-rounded, cached: frames repeat their dt)."""
    return Q_continuous_white_noise(dim=3, dt=dt, spectral_density=spectral_density)


def slerp(start: np.ndarray, end: np.ndarray, fraction: float | np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` a ``fraction`` of the way from ``start`` to ``end`` on SO(3).

    Takes the short way (``end`` is sign-flipped into ``start``'s hemisphere, since q and -q
    are the same rotation) and falls back to normalised linear interpolation for tiny angles.
    """
    fraction = np.asarray(fraction, dtype=float)[..., None]
    dot = np.sum(start * end, axis=-1, keepdims=True)
    end = np.where(dot < 0, -end, end)
    angle = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    sin_angle = np.sin(angle)
    small = sin_angle < 1e-6
    safe = np.where(small, 1.0, sin_angle)
    weight_start = np.where(small, 1.0 - fraction, np.sin((1.0 - fraction) * angle) / safe)
    weight_end = np.where(small, fraction, np.sin(fraction * angle) / safe)
    result = weight_start * start + weight_end * end
    return result / np.linalg.norm(result, axis=-1, keepdims=True)


def rotation_vectors(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """``(..., 3)`` rotation vectors (axis × angle, world frame) turning ``start`` into ``end``.

    The relative rotation is ``end ⊗ start⁻¹``; its vector part over ``sin(θ/2)`` is the
    axis, taken the short way (w >= 0).
    """
    x0, y0, z0, w0 = np.moveaxis(start, -1, 0)
    x1, y1, z1, w1 = np.moveaxis(end, -1, 0)
    # end ⊗ conj(start)
    w = w1 * w0 + x1 * x0 + y1 * y0 + z1 * z0
    vector = np.stack(
        [
            x1 * w0 - w1 * x0 - y1 * z0 + z1 * y0,
            y1 * w0 - w1 * y0 - z1 * x0 + x1 * z0,
            z1 * w0 - w1 * z0 - x1 * y0 + y1 * x0,
        ],
        axis=-1,
    )
    sign = np.where(w < 0, -1.0, 1.0)[..., None]
    vector = vector * sign
    sine = np.linalg.norm(vector, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(sine, np.abs(w)[..., None])
    scale = np.where(sine > 1e-12, angle / np.where(sine > 1e-12, sine, 1.0), 2.0)
    return vector * scale
