"""Small recordings made on the fly for the reader and writer tests."""

from types import SimpleNamespace

import numpy as np
import pytest

from hiros_core.driver import group_to_driver_markers
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup

T0 = 1_700_000_000_000_000_000
PERIOD = 33_333_333


def make_group(index, camera="k01", n_people=2):
    """A deterministic group of a camera at frame ``index``."""
    rng = np.random.default_rng(index)
    frame = f"{camera}_depth_camera_link"
    stamp = T0 + index * PERIOD
    skeletons = [
        Skeleton.from_positions(
            rng.normal([0.0, 0.0, 2.5], 0.3, size=(AZURE_KINECT.n_joints, 3)),
            skeleton_id=person + 1,
            src_time_ns=stamp,
            src_frame=frame,
            confidences=np.full(AZURE_KINECT.n_joints, 1.0),
        )
        for person in range(n_people)
    ]
    return SkeletonGroup(stamp, frame, skeletons)


def driver_frames(count=50):
    """``count`` frames of two cameras as (topic, group, markers)."""
    out = []
    for index in range(count):
        for camera in ("k01", "k02"):
            group = make_group(index, camera)
            out.append((f"/{camera}/body_tracking_data", group, group_to_driver_markers(group)))
    return out


@pytest.fixture
def samples():
    """The helpers above for tests (importlib import mode cannot import this module)."""
    return SimpleNamespace(T0=T0, PERIOD=PERIOD, make_group=make_group, driver_frames=driver_frames)
