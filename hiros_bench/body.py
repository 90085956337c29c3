"""Body stages: optimizer and filter time per frame beside Hi-ROS, accuracy, lag and jitter.

* Time per frame for 1-4 people, optimizer and filter, beside Hi-ROS's published C++ figures
  (Guidolin et al. 2023: optimizer 4.16-8.33 ms, filter 0.11-0.21 ms for 1-4 people).
* Accuracy of the chain on real human motion with the truth known: MPJPE, joint-angle RMSE,
  limb-length coefficient of variation (before/after the optimizer), lag and jitter.
* The filter's lag beside a One-Euro filter (``OneEuroFilter`` from PyPI) tuned, in the same
  run, to the same jitter: for each of a few ``beta`` the ``mincutoff`` is bisected until the
  jitters match, and the One-Euro setting with the least lag is kept (its best case).

Data: the simulator's truth (real mocap, ``hiros_sim``, noise off) at 30 Hz, with an Azure-like
error model applied here so that the figures do not move with the simulator's noise settings:
one body scale per frame (SD 3.5 %: the Body Tracking SDK fits a fixed-proportion body model,
and on the UNIPD-BPE Azure take every limb's length varies by the same 3.5 %), per-joint
correlated noise (8 mm, 50 ms AR(1)) plus 4 mm white noise, and 0.5 % of joints thrown 25 cm
off. That is the merger's output as the optimizer sees it: world frame, one skeleton per track.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from hiros_core.model import Skeleton, SkeletonGroup, sec_to_ns
from hiros_eval.body import jitter, joint_angle_rmse, lag, limb_length_cv, mpjpe, sample_truth
from hiros_filter import Filter, FilterParams
from hiros_optimizer import Optimizer, OptimizerParams

__all__ = ["run"]

RATE = 30.0
HIROS_OPTIMIZER_MS = {1: 4.16, 4: 8.33}
HIROS_FILTER_MS = {1: 0.11, 4: 0.21}
_ONE_EURO_BETAS = (0.0, 0.5, 2.0, 8.0)


@dataclass
class Motion:
    """People moving for the benchmark: ``(P, T, J, 3)`` truth and what a tracker reports."""

    times: np.ndarray
    truth: np.ndarray
    measured: np.ndarray

    def groups(self, people: int | None = None) -> list[SkeletonGroup]:
        """One SkeletonGroup per frame with the first ``people`` people as tracks 0, 1, ..."""
        people = len(self.truth) if people is None else people
        groups = []
        for frame, t in enumerate(self.times):
            stamp = sec_to_ns(t)
            skeletons = [
                Skeleton.from_positions(
                    self.measured[p, frame],
                    skeleton_id=p,
                    src_time_ns=stamp,
                    src_frame="world",
                    confidences=np.full(self.measured.shape[2], 2 / 3),  # SDK "medium"
                )
                for p in range(people)
            ]
            groups.append(SkeletonGroup(stamp, "world", skeletons))
        return groups


def _ar1(rng: np.random.Generator, shape: tuple[int, ...], correlation_time: float) -> np.ndarray:
    """Unit-variance AR(1) noise along axis 1 (frames)."""
    rho = float(np.exp(-1.0 / (RATE * correlation_time)))
    white = rng.standard_normal(shape)
    white[:, 0] /= np.sqrt(1.0 - rho * rho)
    return lfilter([np.sqrt(1.0 - rho * rho)], [1.0, -rho], white, axis=1)


def make_motion(people: int, duration: float, seed: int = 0) -> Motion:
    """Simulator truth at 30 Hz plus the Azure-like error model of the module docstring."""
    from hiros_sim import SimParams, simulate

    result = simulate(
        SimParams(
            n_cameras=1,
            n_people=people,
            duration=duration + 2.0,
            seed=seed,
            noise=False,
            enter_leave=False,
        )
    )
    start = result.truth.times[0] + 0.5
    times = np.arange(start, start + duration, 1.0 / RATE)
    truth = np.stack(
        [sample_truth(times, result.truth.times, person) for person in result.truth.positions]
    )
    rng = np.random.default_rng(seed)
    n_people, n_frames, n_joints, _ = truth.shape
    pelvis = truth[:, :, :1]
    scale = 1.0 + 0.035 * _ar1(rng, (n_people, n_frames, 1, 1), 0.1)
    measured = pelvis + (truth - pelvis) * scale
    measured += 0.008 * _ar1(rng, truth.shape, 0.05) + 0.004 * rng.standard_normal(truth.shape)
    thrown = rng.random((n_people, n_frames, n_joints)) < 0.005
    measured[thrown] += rng.normal(0.0, 0.25 / np.sqrt(3), (int(thrown.sum()), 3))
    return Motion(times, truth, measured)


def _ms_per_frame(make_stage: Callable[[], object], groups: list, warmup: int) -> float:
    """Best of 3 fresh runs: mean ms per frame after ``warmup`` frames (calibration)."""
    best = float("inf")
    for _ in range(3):
        stage = make_stage()
        for group in groups[:warmup]:
            stage.update(group)
        start = time.perf_counter()
        for group in groups[warmup:]:
            stage.update(group)
        best = min(best, (time.perf_counter() - start) / (len(groups) - warmup))
    return best * 1e3


def _positions(groups: list[SkeletonGroup], person: int = 0) -> np.ndarray:
    return np.stack([g.skeletons[person].positions for g in groups])


def _chain(groups: list[SkeletonGroup], *stages: object) -> list[SkeletonGroup]:
    out = []
    for group in groups:
        for stage in stages:
            group = stage.update(group)  # noqa: PLW2901 - each stage feeds the next
        out.append(group)
    return out


def one_euro(series: np.ndarray, times: np.ndarray, mincutoff: float, beta: float) -> np.ndarray:
    """``(T, ...)`` series through one ``OneEuroFilter`` per channel (the PyPI package)."""
    from OneEuroFilter import OneEuroFilter

    flat = series.reshape(len(series), -1)
    out = np.empty_like(flat)
    for channel in range(flat.shape[1]):
        euro = OneEuroFilter(RATE, mincutoff=mincutoff, beta=beta)
        out[:, channel] = [euro(v, t) for v, t in zip(flat[:, channel], times, strict=True)]
    return out.reshape(series.shape)


def tune_one_euro(
    series: np.ndarray, times: np.ndarray, truth: np.ndarray, target: float, iterations: int
) -> tuple[float, float, np.ndarray]:
    """The One-Euro setting with ``jitter == target`` and the least lag: (mincutoff, beta, out)."""
    best: tuple[float, float, float, np.ndarray] | None = None
    for beta in _ONE_EURO_BETAS:
        low, high = np.log(0.05), np.log(30.0)
        for _ in range(iterations):  # jitter grows with mincutoff: bisect in log space
            middle = 0.5 * (low + high)
            shaky = jitter(one_euro(series, times, np.exp(middle), beta), truth) > target
            low, high = (low, middle) if shaky else (middle, high)
        mincutoff = float(np.exp(0.5 * (low + high)))
        out = one_euro(series, times, mincutoff, beta)
        delay = lag(out, truth, RATE)
        if best is None or delay < best[2]:
            best = (mincutoff, beta, delay, out)
    assert best is not None
    return best[0], best[1], best[3]


def run(console, quick: bool = False) -> list[str]:  # noqa: ANN001 - rich Console
    """Print the tables and return their lines (the last four: the summary)."""
    duration = 12.0 if quick else 30.0
    motion = make_motion(4, duration, seed=0)
    warmup = OptimizerParams().number_of_frames_for_calibration + 10
    lines = [
        f"{'time per frame, ms':20s} {'people':>6s} {'optimizer':>10s} {'Hi-ROS':>7s} "
        f"{'filter':>7s} {'Hi-ROS':>7s}"
    ]
    timings = {}
    for people in (1, 2, 3, 4):
        groups = motion.groups(people)
        optimizer_ms = _ms_per_frame(Optimizer, groups, warmup)
        filter_ms = _ms_per_frame(Filter, groups, warmup)
        timings[people] = (optimizer_ms, filter_ms)
        hiros_opt = HIROS_OPTIMIZER_MS.get(people)
        hiros_filter = HIROS_FILTER_MS.get(people)
        lines.append(
            f"{'':20s} {people:6d} {optimizer_ms:10.2f} "
            f"{'' if hiros_opt is None else f'{hiros_opt:.2f}':>7s} {filter_ms:7.2f} "
            f"{'' if hiros_filter is None else f'{hiros_filter:.2f}':>7s}"
        )

    # Accuracy on one person, after the optimizer's calibration window.
    groups = motion.groups(1)
    truth = motion.truth[0, warmup:]
    times = motion.times[warmup:]
    raw = motion.measured[0, warmup:]
    optimized = _positions(_chain(groups, Optimizer()))[warmup:]
    kalman = _positions(_chain(groups, Optimizer(), Filter()))[warmup:]
    butterworth = _positions(
        _chain(groups, Optimizer(), Filter(FilterParams(filter="butterworth")))
    )[warmup:]
    target = jitter(kalman, truth)
    mincutoff, beta, euro = tune_one_euro(optimized, times, truth, target, 6 if quick else 10)
    rows = [
        ("input (tracker-like)", raw),
        ("optimizer", optimized),
        ("+ filter (kalman)", kalman),
        ("+ filter (butter 6 Hz)", butterworth),
        (f"+ One-Euro {mincutoff:.1f} Hz b={beta:g}", euro),
    ]
    lines.append(
        f"{'1 person':26s} {'MPJPE mm':>8s} {'angle °':>8s} {'limb CV%':>8s} {'lag ms':>7s} "
        f"{'jitter':>7s}"
    )
    figures = {}
    for name, estimate in rows:
        error, _ = mpjpe(estimate, truth)
        angle = joint_angle_rmse(estimate, truth)["mean"]
        cv = float(np.nanmean(limb_length_cv(estimate)))
        delay = lag(estimate, truth, RATE)
        shake = jitter(estimate, truth)
        figures[name] = (error, angle, cv, delay, shake)
        lines.append(
            f"{name:26s} {error * 1e3:8.1f} {angle:8.2f} {cv * 100:8.2f} {delay * 1e3:7.1f} "
            f"{shake * 1e3:7.2f}"
        )
    lines.append("(angle: joint-angle RMSE; jitter: RMS 2nd difference of the error, mm/frame²)")
    source, optimizer_figures = figures[rows[0][0]], figures["optimizer"]
    chain, euro_figures = figures["+ filter (kalman)"], figures[rows[-1][0]]
    lines += [
        f"limb CV {source[2] * 100:.1f} % -> {optimizer_figures[2] * 100:.2f} % after the "
        f"optimizer (target < 1 %)",
        f"joint-angle RMSE {source[1]:.2f} -> {chain[1]:.2f} deg "
        f"(-{(1 - chain[1] / source[1]) * 100:.0f} % by optimizer + filter)",
        f"filter lag {chain[3] * 1e3:.1f} ms vs One-Euro {euro_figures[3] * 1e3:.1f} ms "
        f"at the same jitter ({chain[4] * 1e3:.1f} mm/frame²)",
        f"4 people: optimizer {timings[4][0]:.2f} ms = {timings[4][0] / HIROS_OPTIMIZER_MS[4]:.2f}"
        f"x Hi-ROS, filter {timings[4][1]:.2f} ms = {timings[4][1] / HIROS_FILTER_MS[4]:.1f}x",
    ]
    for line in lines:
        console.print(line, highlight=False)
    return lines
