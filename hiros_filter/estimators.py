"""The per-joint estimators of the filter stage, batched over tracks and joints.

State lives in arrays with one row per track slot, so that one frame of every person costs a
fixed number of numpy calls, whatever the number of people:

- :class:`ButterworthBank`: causal low-pass (scipy ``butter`` + ``sosfilt`` with kept state) on
  every coordinate of every joint of every track, ``(S, J*3)`` channels.
- :class:`KalmanBank`: one constant-acceleration Kalman filter per joint, state
  ``[position, velocity, acceleration]`` per axis under a continuous white-jerk model (process
  noise as filterpy's ``Q_continuous_white_noise``); predict and update are ``einsum`` over
  all slots and joints.
- :func:`slerp` and :func:`rotation_vectors`: quaternion smoothing and angular velocity on SO(3).

Shapes: ``S`` track slots, ``J`` joints; positions ``(J, 3)`` metres; quaternions x, y, z, w.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

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

    def predict(self, slots: np.ndarray, dt: np.ndarray) -> None:
        """Advance each slot by its own ``dt`` seconds (the model is continuous-time).

        ``x ← F x`` and ``P ← F P Fᵀ + Q`` with ``F = [[1, dt, dt²/2], [0, 1, dt], [0, 0, 1]]``,
        written out row by row and column by column on whole blocks: numpy's batched 3×3
        products cost a call per matrix, these a few calls per frame.
        """
        index = _block(slots)
        step = dt[:, None, None]
        half_square = (0.5 * dt * dt)[:, None, None]
        Q = np.array([_process_noise(round(float(s), 6), self.q) for s in dt])
        x = self.x[index]  # a view when the slots are one block
        x[:, 0] += step * x[:, 1] + half_square * x[:, 2]
        x[:, 1] += step * x[:, 2]
        P = self.P[index]
        P[:, 0] += step * P[:, 1] + half_square * P[:, 2]  # F P, row by row
        P[:, 1] += step * P[:, 2]
        P[:, :, 0] += step * P[:, :, 1] + half_square * P[:, :, 2]  # (F P) Fᵀ, column by column
        P[:, :, 1] += step * P[:, :, 2]
        P += Q[..., None] * self.scale[index][:, None, None, :]
        if not isinstance(index, slice):
            self.x[index] = x
            self.P[index] = P

    def step(
        self, slots: np.ndarray, dt: np.ndarray, mask: np.ndarray, positions: np.ndarray
    ) -> None:
        """:meth:`predict` then :meth:`correct`, as one numba kernel (same numbers)."""
        from hiros_filter.compiled import kalman_step

        dt = np.asarray(dt, dtype=float)
        kalman_step(
            self.x, self.P, self.scale, np.asarray(slots, dtype=np.int64), dt, np.round(dt, 6),
            np.asarray(mask, dtype=bool), np.ascontiguousarray(positions, dtype=float),
            float(self.q), float(self.r), float(self.max_noise_scale),
            float(self.adaptation_rate),
        )  # fmt: skip

    def update(self, slots: np.ndarray, joints: np.ndarray, positions: np.ndarray) -> None:
        """Correct (slot, joint) pairs with measured ``(n, 3)`` positions (H = [1, 0, 0])."""
        P = self.P[slots, :, :, joints]  # (n, 3, 3)
        gain = P[:, :, 0] / (P[:, 0, 0] + self.r)[:, None]  # (n, 3)
        innovation = positions - self.x[slots, 0, :, joints]  # (n, 3 axes)
        if self.max_noise_scale > 1.0:
            surprise = np.sum(innovation**2, axis=-1) / (3.0 * (P[:, 0, 0] + self.r))
            smoothed = self.scale[slots, joints] + self.adaptation_rate * (
                surprise - self.scale[slots, joints]
            )
            self.scale[slots, joints] = np.clip(smoothed, 1.0, self.max_noise_scale)
        self.x[slots, :, :, joints] += gain[:, :, None] * innovation[:, None, :]
        self.P[slots, :, :, joints] = P - gain[:, :, None] * P[:, None, 0, :]

    def correct(self, slots: np.ndarray, mask: np.ndarray, positions: np.ndarray) -> None:
        """:meth:`update` of the (slot, joint) pairs where ``mask`` ``(n, J)`` is set.

        ``positions`` is ``(n, J, 3)`` (ignored where the mask is clear). Every joint of the
        slots is computed and the masked ones kept: the same numbers as :meth:`update`, with
        whole-block numpy calls instead of scattered pairs.
        """
        index = _block(slots)
        P = self.P[index]  # (n, 3, 3, J), a view when the slots are one block
        x = self.x[index]
        variance = P[:, 0, 0] + self.r  # (n, J)
        everywhere = mask.all()
        with np.errstate(invalid="ignore", over="ignore"):
            gain = P[:, :, 0] / variance[:, None]  # (n, 3, J)
            innovation = positions.transpose(0, 2, 1) - x[:, 0]  # (n, 3 axes, J)
            if self.max_noise_scale > 1.0:
                surprise = np.sum(innovation**2, axis=1) / (3.0 * variance)
                scale = self.scale[index]
                smoothed = np.clip(
                    scale + self.adaptation_rate * (surprise - scale), 1.0, self.max_noise_scale
                )
                self.scale[index] = smoothed if everywhere else np.where(mask, smoothed, scale)
            x_step = gain[:, :, None] * innovation[:, None]
            P_step = gain[:, :, None] * P[:, None, 0]
        if everywhere:
            x += x_step
            P -= P_step
        else:
            keep = mask[:, None, None]
            x += np.where(keep, x_step, 0.0)
            P -= np.where(keep, P_step, 0.0)
        if not isinstance(index, slice):
            self.x[index] = x
            self.P[index] = P


def _block(slots: np.ndarray) -> slice | np.ndarray:
    """``slots`` as a slice when they are consecutive (views instead of copies), else as is."""
    first = int(slots[0])
    if slots.tolist() == list(range(first, first + len(slots))):
        return slice(first, first + len(slots))
    return slots


@lru_cache(maxsize=256)
def _process_noise(dt: float, spectral_density: float) -> np.ndarray:
    """Q of the white-jerk model for one ``dt`` (µs-rounded, cached: frames repeat their dt).

    filterpy's ``Q_continuous_white_noise(dim=3, dt, spectral_density)``, term for term (a
    test checks it), without its per-call ``block_diag``: a frame's dt rarely repeats exactly.
    """
    return (
        np.array(
            [
                [(dt**5) / 20.0, (dt**4) / 8.0, (dt**3) / 6.0],
                [(dt**4) / 8.0, (dt**3) / 3.0, (dt**2) / 2.0],
                [(dt**3) / 6.0, (dt**2) / 2.0, dt],
            ]
        )
        * spectral_density
    )


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
