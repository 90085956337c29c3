"""New filter parameters while running: tracks keep their state and the new values apply."""

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

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


def _rigid_outputs(stage: Filter, change: dict, at: int = 30) -> np.ndarray:
    """``(60, J, 16)`` marker columns 1:17 of a rigid body turning and moving, ``change`` at ``at``.

    A rigid body's links keep their input lengths, so ``keep_link_lengths`` holds them all.
    """
    rng = np.random.default_rng(4)
    body = rng.normal(scale=0.3, size=(J, 3))
    turns = Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.1, size=(60, 3)), axis=0))
    out = []
    for k in range(60):
        if k == at:
            stage.set_params(dataclasses.replace(stage.params, **change))
        t = sec_to_ns(k / RATE)
        pose = turns[k].apply(body) + np.array([0.03 * k, 0.0, 0.0])
        skeleton = Skeleton.from_positions(pose, skeleton_id=0, src_time_ns=t)
        group = stage.update(SkeletonGroup(t, "world", [skeleton]))
        out.append(group.skeletons[0].markers[:J, 1:17])
    return np.array(out)


@pytest.mark.parametrize("keep", [True, False])
def test_keep_link_lengths_set_while_running_reaches_the_kernel(keep: bool) -> None:
    """From the change on, the output is that of a filter made with the new value.

    ``Filter.set_params`` drops the kernel's cached arguments (``_Tracks.retune``), which hold
    the flag. The nodes do not change it while running (it is not in ``LIVE``: read-only).
    """
    switched = _rigid_outputs(
        Filter(FilterParams(keep_link_lengths=keep)), {"keep_link_lengths": not keep}
    )
    unchanged = _rigid_outputs(Filter(FilterParams(keep_link_lengths=keep)), {})
    other = _rigid_outputs(Filter(FilterParams(keep_link_lengths=not keep)), {})
    np.testing.assert_array_equal(switched[:30], unchanged[:30])
    np.testing.assert_array_equal(switched[30:], other[30:])
    assert not np.allclose(switched[30:], unchanged[30:], equal_nan=True)


def test_orientation_cutoff_set_while_running_reaches_the_kernel() -> None:
    """An orientation that turns at the change: a 0.01 Hz cutoff holds the old one, 6 Hz follows."""
    before, after = Rotation.from_euler("z", 0.0), Rotation.from_euler("z", 1.0)

    def run(stage: Filter, change: dict) -> np.ndarray:
        out = []
        for k in range(60):
            if k == 30:
                stage.set_params(dataclasses.replace(stage.params, **change))
            t = sec_to_ns(k / RATE)
            skeleton = Skeleton.from_positions(np.zeros((J, 3)), skeleton_id=0, src_time_ns=t)
            skeleton.markers[:J, 4:8] = (before if k < 30 else after).as_quat()
            group = stage.update(SkeletonGroup(t, "world", [skeleton]))
            out.append(Rotation.from_quat(group.skeletons[0].markers[0, 4:8]).magnitude())
        return np.array(out)

    slow = run(Filter(), {"orientation_cutoff_frequency": 0.01})
    unchanged = run(Filter(), {})
    np.testing.assert_array_equal(slow[:30], unchanged[:30])
    assert unchanged[-1] > 0.99  # turned with the input
    assert slow[-1] < 0.1  # the new cutoff smooths the turn away


def test_the_filter_nodes_change_only_the_live_parameters() -> None:
    from hiros_filter.node import LIVE, FilterNodeParams
    from hiros_ros.params import parameter_specs

    read_only = {spec.name: spec.read_only for spec in parameter_specs(FilterNodeParams, LIVE)}
    assert read_only["keep_link_lengths"]
    assert not read_only["orientation_cutoff_frequency"]
