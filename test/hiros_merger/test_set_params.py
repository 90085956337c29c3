"""New merger parameters while running: the next fusion uses them."""

import dataclasses

import numpy as np

from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_merger import Merger

J = AZURE_KINECT.n_joints
T0 = 1_700_000_000_000_000_000


def _group(t_ns: int, offsets: dict[str, float], ages: dict[str, int]) -> SkeletonGroup:
    """One detection per camera of ``offsets``, shifted along x by it, ``ages`` ns old."""
    pose = np.random.default_rng(0).normal(scale=0.3, size=(J, 3)) + np.array([0.0, 0.0, 1.0])
    skeletons = [
        Skeleton.from_positions(
            pose + np.array([offsets[camera], 0.0, 0.0]),
            skeleton_id=0,
            src_time_ns=t_ns - ages[camera],
            src_frame=f"{camera}_depth_camera_link",
        )
        for camera in offsets
    ]
    return SkeletonGroup(t_ns, "world", skeletons)


def test_a_new_window_applies_from_the_next_frame() -> None:
    """k02's detection, 70 ms old, is fused within the default 0.1 s window (weighed down by
    its age) and left out once the window is 0.05 s."""
    offsets, ages = {"k01": 0.0, "k02": 0.04}, {"k01": 0, "k02": 70_000_000}
    merger = Merger()
    first = merger.update(_group(T0, offsets, ages)).skeletons[0]
    merger.set_params(dataclasses.replace(merger.params, window=0.05))
    second = merger.update(_group(T0 + 33_000_000, offsets, ages)).skeletons[0]
    pose_x = _group(T0, {"k01": 0.0}, {"k01": 0}).skeletons[0].positions[:, 0]
    shift_first = np.median(first.positions[:, 0] - pose_x)
    shift_second = np.median(second.positions[:, 0] - pose_x)
    assert 0.005 < shift_first < 0.02
    assert abs(shift_second) < 1e-9
