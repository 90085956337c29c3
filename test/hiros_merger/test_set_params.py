"""New merger parameters while running: the next fusion uses them."""

import dataclasses

import numpy as np

from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_merger import Merger

J = AZURE_KINECT.n_joints
T0 = 1_700_000_000_000_000_000


def _group(t_ns: int, offsets: dict[str, float], confidences: dict[str, float]) -> SkeletonGroup:
    pose = np.random.default_rng(0).normal(scale=0.3, size=(J, 3)) + np.array([0.0, 0.0, 1.0])
    skeletons = [
        Skeleton.from_positions(
            pose + np.array([offsets[camera], 0.0, 0.0]),
            skeleton_id=0,
            src_time_ns=t_ns,
            src_frame=f"{camera}_depth_camera_link",
            confidences=np.full(J, confidences[camera]),
        )
        for camera in offsets
    ]
    return SkeletonGroup(t_ns, "world", skeletons)


def test_new_confidence_weights_apply_from_the_next_frame() -> None:
    offsets, confidences = {"k01": 0.0, "k02": 0.04}, {"k01": 1.0, "k02": 1 / 3}
    merger = Merger()
    first = merger.update(_group(T0, offsets, confidences)).skeletons[0]
    merger.set_params(dataclasses.replace(merger.params, confidence_power=0.0))
    second = merger.update(_group(T0 + 33_000_000, offsets, confidences)).skeletons[0]
    pose_x = _group(T0, {"k01": 0.0}, {"k01": 1.0}).skeletons[0].positions[:, 0]
    # squared confidences weigh k01 9:1; without them the two views count alike
    shift_first = np.median(first.positions[:, 0] - pose_x)
    shift_second = np.median(second.positions[:, 0] - pose_x)
    assert shift_first < 0.01
    assert abs(shift_second - 0.02) < 0.005
