"""The three per-track estimators of the filter stage, each batched over all joints.

- :class:`ButterworthBank`: causal low-pass (scipy ``butter`` + ``sosfilt`` with kept state)
  on every coordinate of every joint at once, ``(J*3,)`` channels.
- :class:`ConstantAccelerationKalman`: one Kalman filter per joint with state
  ``[position, velocity, acceleration]`` per axis under a continuous white-jerk model; all
  joints and axes share one predict/update in numpy (the model matrices come from filterpy).
- :func:`slerp`: spherical interpolation of unit quaternions, for smoothing on SO(3).

Shapes: ``J`` joints; positions ``(J, 3)`` metres; quaternions ``(J, 4)`` x, y, z, w.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from filterpy.common import Q_continuous_white_noise
from scipy.signal import butter, sosfilt, sosfilt_zi

__all__ = ["ButterworthBank", "ConstantAccelerationKalman", "slerp"]


@dataclass
class ButterworthBank:
    """Causal Butterworth low-pass on ``channels`` signals sampled at ``sample_frequency``.

    Attributes:
        order: filter order.
        cutoff_frequency: -3 dB frequency in Hz (clamped below Nyquist).
        sample_frequency: Hz the coefficients are designed for.
        channels: number of parallel signals (``J * 3`` for one skeleton).

    """

    order: int
    cutoff_frequency: float
    sample_frequency: float
    channels: int
    sos: np.ndarray = field(init=False, repr=False)
    state: np.ndarray = field(init=False, repr=False)
    _unit_state: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        nyquist = 0.5 * self.sample_frequency
        cutoff = min(self.cutoff_frequency, 0.9 * nyquist)
        self.sos = butter(self.order, cutoff, fs=self.sample_frequency, output="sos")
        self._unit_state = sosfilt_zi(self.sos)  # steady state for a constant input of 1
        self.state = np.zeros((self.sos.shape[0], self.channels, 2))

    def reset(self, channels: np.ndarray, values: np.ndarray) -> None:
        """Put ``channels`` at rest on ``values``: as if they had been constant forever."""
        self.state[:, channels, :] = self._unit_state[:, None, :] * values[None, :, None]

    def step(self, samples: np.ndarray) -> np.ndarray:
        """Filter ``(channels, n)`` consecutive samples; returns the ``(channels,)`` last output."""
        filtered, self.state = sosfilt(self.sos, samples, axis=-1, zi=self.state)
        return filtered[:, -1]


@dataclass
class ConstantAccelerationKalman:
    """Kalman filters with state ``[p, v, a]`` per joint and axis, sharing one covariance per joint.

    x and y and z of a joint get the same measurement noise, so their covariances are equal
    and one ``(3, 3)`` matrix per joint serves all three axes.

    Attributes:
        jerk_spectral_density: ``q`` of the continuous white-jerk model, m^2/s^5.
        measurement_noise: standard deviation of a position measurement, metres.
        state: ``(J, 3, 3)``: joint, [position, velocity, acceleration], axis.
        covariance: ``(J, 3, 3)`` per joint, over [position, velocity, acceleration].

    """

    jerk_spectral_density: float
    measurement_noise: float
    n_joints: int
    initial_velocity_sd: float = 1.0
    initial_acceleration_sd: float = 5.0
    state: np.ndarray = field(init=False, repr=False)
    covariance: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.state = np.zeros((self.n_joints, 3, 3))
        self.covariance = np.zeros((self.n_joints, 3, 3))

    def reset(self, joints: np.ndarray, positions: np.ndarray) -> None:
        """Start ``joints`` at rest at ``positions`` with a wide velocity/acceleration prior."""
        self.state[joints] = 0.0
        self.state[joints, 0] = positions
        self.covariance[joints] = np.diag(
            [
                self.measurement_noise**2,
                self.initial_velocity_sd**2,
                self.initial_acceleration_sd**2,
            ]
        )

    def predict(self, dt: float) -> None:
        """Advance every joint by ``dt`` seconds (any dt: the model is continuous-time)."""
        transition = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        noise = Q_continuous_white_noise(dim=3, dt=dt, spectral_density=self.jerk_spectral_density)
        self.state = np.einsum("ab,jbk->jak", transition, self.state)
        self.covariance = transition @ self.covariance @ transition.T + noise

    def update(self, joints: np.ndarray, positions: np.ndarray) -> None:
        """Correct ``joints`` with measured ``(n, 3)`` positions (H = [1, 0, 0] per axis)."""
        covariance = self.covariance[joints]
        innovation_variance = covariance[:, 0, 0] + self.measurement_noise**2
        gain = covariance[:, :, 0] / innovation_variance[:, None]  # (n, 3)
        innovation = positions - self.state[joints, 0]  # (n, 3 axes)
        self.state[joints] += gain[:, :, None] * innovation[:, None, :]
        self.covariance[joints] = covariance - gain[:, :, None] * covariance[:, None, 0, :]

    @property
    def positions(self) -> np.ndarray:
        """``(J, 3)`` filtered positions."""
        return self.state[:, 0]

    @property
    def velocities(self) -> np.ndarray:
        """``(J, 3)`` filtered velocities, m/s."""
        return self.state[:, 1]

    @property
    def accelerations(self) -> np.ndarray:
        """``(J, 3)`` filtered accelerations, m/s^2."""
        return self.state[:, 2]


def slerp(start: np.ndarray, end: np.ndarray, fraction: float | np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)`` a ``fraction`` of the way from ``start`` to ``end`` on SO(3).

    Takes the short way (``end`` is sign-flipped into ``start``'s hemisphere, since q and -q
    are the same rotation) and falls back to normalised linear interpolation for tiny angles.
    """
    fraction = np.asarray(fraction, dtype=float)[..., None]
    dot = np.sum(start * end, axis=-1, keepdims=True)
    end = np.where(dot < 0, -end, end)
    dot = np.clip(np.abs(dot), -1.0, 1.0)
    angle = np.arccos(dot)
    sin_angle = np.sin(angle)
    small = sin_angle < 1e-6
    safe = np.where(small, 1.0, sin_angle)
    weight_start = np.where(small, 1.0 - fraction, np.sin((1.0 - fraction) * angle) / safe)
    weight_end = np.where(small, fraction, np.sin(fraction * angle) / safe)
    result = weight_start * start + weight_end * end
    return result / np.linalg.norm(result, axis=-1, keepdims=True)
