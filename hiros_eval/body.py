"""Accuracy of skeletons against the truth: joint error, limb lengths, joint angles, lag, jitter.

Everything takes plain arrays so that any stage's output can be scored: positions ``(T, J, 3)``
(frames × joints × xyz, metres, NaN where unknown) on the same frames as the truth (use
:func:`sample_truth` to bring the truth to the estimate's stamps). Angles are in degrees, lags in
seconds, jitter in metres per frame².

Joint angles are the included angles of the segments (0° = straight / hanging), not a
biomechanical Euler decomposition: knee and elbow are the angle between the upper and lower
segment; hip and shoulder flexion are the angle between the segment and the trunk's downward
axis (SpineChest -> Pelvis for the hip, Neck -> Pelvis for the shoulder), i.e. how far the thigh
or upper arm is raised, whatever the direction.
"""

from __future__ import annotations

import numpy as np

from hiros_core.layouts import AZURE_KINECT, Layout

__all__ = [
    "JOINT_ANGLES",
    "jitter",
    "joint_angle_rmse",
    "joint_angles",
    "lag",
    "limb_length_cv",
    "mpjpe",
    "parabola_vertex",
    "sample_truth",
]

# name -> (first segment (from, to), second segment (from, to)) by Azure Kinect joint names.
JOINT_ANGLES: dict[str, tuple[tuple[str, str], tuple[str, str]]] = {
    "knee_left": (("HipLeft", "KneeLeft"), ("KneeLeft", "AnkleLeft")),
    "knee_right": (("HipRight", "KneeRight"), ("KneeRight", "AnkleRight")),
    "hip_left": (("SpineChest", "Pelvis"), ("HipLeft", "KneeLeft")),
    "hip_right": (("SpineChest", "Pelvis"), ("HipRight", "KneeRight")),
    "elbow_left": (("ShoulderLeft", "ElbowLeft"), ("ElbowLeft", "WristLeft")),
    "elbow_right": (("ShoulderRight", "ElbowRight"), ("ElbowRight", "WristRight")),
    "shoulder_left": (("Neck", "Pelvis"), ("ShoulderLeft", "ElbowLeft")),
    "shoulder_right": (("Neck", "Pelvis"), ("ShoulderRight", "ElbowRight")),
}
"""The joint angles scored (Hi-ROS reports knee, hip, elbow and shoulder flexion)."""


def sample_truth(times: np.ndarray, truth_times: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Truth ``(T_truth, J, 3)`` linearly interpolated at ``times`` ``(T,)``; NaN outside it.

    A sample next to a NaN truth sample is NaN (a person entering or leaving is not invented).
    """
    times = np.asarray(times, dtype=float)
    index = np.searchsorted(truth_times, times, side="right") - 1
    inside = (index >= 0) & (index < len(truth_times) - 1)
    index = np.clip(index, 0, len(truth_times) - 2)
    span = truth_times[index + 1] - truth_times[index]
    fraction = ((times - truth_times[index]) / span)[:, None, None]
    out = (1.0 - fraction) * truth[index] + fraction * truth[index + 1]
    out[~inside] = np.nan
    return out


def mpjpe(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, np.ndarray]:
    """Mean per-joint position error (m): overall and ``(J,)`` per joint, over finite pairs."""
    error = np.linalg.norm(estimate - truth, axis=-1)
    error = error.reshape(-1, error.shape[-1])
    seen = np.isfinite(error)
    counts = seen.sum(axis=0)
    totals = np.where(seen, error, 0.0).sum(axis=0)
    per_joint = np.divide(totals, counts, out=np.full(len(counts), np.nan), where=counts > 0)
    overall = float(totals.sum() / counts.sum()) if counts.sum() else float("nan")
    return overall, per_joint


def limb_length_cv(positions: np.ndarray, layout: Layout = AZURE_KINECT) -> np.ndarray:
    """``(J,)`` coefficient of variation (SD / mean) of each link's length over time, by link id.

    NaN for the root and for links seen in fewer than two frames. ``positions`` is
    ``(T, J, 3)`` for one person.
    """
    parents = np.asarray(layout.parents)
    lengths = np.linalg.norm(positions - positions[:, np.maximum(parents, 0)], axis=-1)
    lengths[:, parents < 0] = np.nan
    enough = np.isfinite(lengths).sum(axis=0) >= 2
    cv = np.full(lengths.shape[1], np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        cv[enough] = np.nanstd(lengths[:, enough], axis=0) / np.nanmean(lengths[:, enough], axis=0)
    return cv


def joint_angles(positions: np.ndarray, layout: Layout = AZURE_KINECT) -> dict[str, np.ndarray]:
    """Each of :data:`JOINT_ANGLES` in degrees, shape ``positions.shape[:-2]``."""
    angles = {}
    for name, ((a0, a1), (b0, b1)) in JOINT_ANGLES.items():
        first = positions[..., layout.index(a1), :] - positions[..., layout.index(a0), :]
        second = positions[..., layout.index(b1), :] - positions[..., layout.index(b0), :]
        with np.errstate(invalid="ignore", divide="ignore"):
            cosine = np.sum(first * second, axis=-1) / (
                np.linalg.norm(first, axis=-1) * np.linalg.norm(second, axis=-1)
            )
        angles[name] = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    return angles


def joint_angle_rmse(
    estimate: np.ndarray, truth: np.ndarray, layout: Layout = AZURE_KINECT
) -> dict[str, float]:
    """RMSE (degrees) of each joint angle and their mean under ``"mean"``."""
    estimated, true = joint_angles(estimate, layout), joint_angles(truth, layout)
    rmse = {}
    for name in JOINT_ANGLES:
        error = estimated[name] - true[name]
        error = error[np.isfinite(error)]
        rmse[name] = float(np.sqrt(np.mean(error**2))) if error.size else float("nan")
    scored = [value for value in rmse.values() if np.isfinite(value)]
    rmse["mean"] = float(np.mean(scored)) if scored else float("nan")
    return rmse


def lag(estimate: np.ndarray, truth: np.ndarray, rate: float, max_lag: float = 0.5) -> float:
    """Delay (s) of ``estimate`` behind ``truth``, both ``(T, ...)`` sampled at ``rate`` Hz.

    The peak of the cross-correlation of the frame-to-frame changes (which removes the slow
    drift that would flatten the peak), pooled over every channel, refined to a fraction of a
    frame by a parabola through the peak and its neighbours. Positive = the estimate is late.
    """
    first = np.diff(estimate.reshape(len(estimate), -1), axis=0)
    second = np.diff(truth.reshape(len(truth), -1), axis=0)
    usable = np.isfinite(first) & np.isfinite(second)
    first = np.where(usable, first, 0.0)
    second = np.where(usable, second, 0.0)
    max_shift = max(1, min(round(max_lag * rate), len(first) // 2))
    shifts = np.arange(-max_shift, max_shift + 1)
    score = np.array(
        [
            np.sum(first[s:] * second[: len(second) - s])
            if s >= 0
            else np.sum(first[:s] * second[-s:])
            for s in shifts
        ]
    )
    peak = int(np.argmax(score))
    offset = parabola_vertex(*score[peak - 1 : peak + 2]) if 0 < peak < len(score) - 1 else 0.0
    return float((shifts[peak] + offset) / rate)


def parabola_vertex(left: float, middle: float, right: float) -> float:
    """Where the parabola through three evenly spaced samples turns, in steps from ``middle``.

    For refining the best of sampled values to a fraction of a step: with ``middle`` the
    largest (or smallest) of the three, the vertex lies within half a step of it. 0 when the
    three lie on a line or one is not finite.
    """
    curvature = left - 2 * middle + right
    if not (np.isfinite(curvature) and curvature != 0):
        return 0.0
    return float(0.5 * (left - right) / curvature)


def jitter(positions: np.ndarray, truth: np.ndarray | None = None) -> float:
    """RMS of the second difference over frames (m/frame²) of ``positions`` ``(T, ...)``.

    With ``truth`` given, of the error ``positions - truth``: the frame-to-frame shaking the
    estimate adds, without the body's own acceleration.
    """
    signal = positions if truth is None else positions - truth
    second = np.diff(signal, n=2, axis=0)
    second = second[np.isfinite(second)]
    return float(np.sqrt(np.mean(second**2))) if second.size else float("nan")
