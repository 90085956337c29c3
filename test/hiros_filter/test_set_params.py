"""New filter parameters while running: tracks keep their state and the new values apply."""

import dataclasses

import numpy as np
import pytest

from hiros_core.model import Skeleton, SkeletonGroup, sec_to_ns
from hiros_filter import Filter, FilterParams

RATE = 30.0
J = 32


def _outputs(stage: Filter, positions: np.ndarray, start: int) -> np.ndarray:
    """``(T, J, 3)`` filtered positions of frames ``start``, ``start + 1``, ... at RATE."""
    out = []
    for k, pose in enumerate(positions, start):
        t = sec_to_ns(k / RATE)
        skeleton = Skeleton.from_positions(pose, skeleton_id=0, src_time_ns=t)
        out.append(stage.update(SkeletonGroup(t, "world", [skeleton])).skeletons[0].positions)
    return np.array(out)


@pytest.mark.parametrize(
    ("mode", "change"),
    [
        ("butterworth", {"cutoff_frequency": 0.5}),
        ("kalman", {"measurement_noise": 0.2, "jerk_spectral_density": 1.0}),
    ],
)
def test_smoother_settings_take_effect_without_a_jump(mode: str, change: dict) -> None:
    rng = np.random.default_rng(3)
    still = rng.normal(size=(J, 3))
    noisy = still + rng.normal(scale=0.02, size=(180, J, 3))
    stage = Filter(FilterParams(filter=mode, cutoff_frequency=10.0))
    before = _outputs(stage, noisy[:90], 0)
    stage.set_params(dataclasses.replace(stage.params, **change))
    after = _outputs(stage, noisy[90:], 90)
    # the state carries over: the first output after the change is where the last one was
    assert np.abs(after[0] - before[-1]).max() < 0.1
    assert np.abs(after - still).max() < 0.1
    # and the smoother settings smooth: frame-to-frame motion of a still pose falls
    jitter_before = np.abs(np.diff(before[45:], axis=0)).mean()
    jitter_after = np.abs(np.diff(after[45:], axis=0)).mean()
    assert jitter_after < 0.5 * jitter_before
