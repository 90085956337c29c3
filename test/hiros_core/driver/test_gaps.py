"""Issue 21 case 19: frames lost before the bridge received them are counted from the stamps."""

from __future__ import annotations

import numpy as np

from hiros_core.codec import encode_marker_array
from hiros_core.driver import DriverBridge, group_to_driver_markers
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup

T0 = 1_700_000_000_000_000_000
PERIOD = 33_333_333


def _message(stamp_ns: int) -> bytes:
    skeleton = Skeleton.empty(AZURE_KINECT, skeleton_id=1, src_time_ns=stamp_ns,
                              src_frame="k01_depth_camera_link")  # fmt: skip
    skeleton.marker_present[:] = True
    skeleton.positions[:] = [0.0, 0.0, 2.0]
    group = SkeletonGroup(stamp_ns, "k01_depth_camera_link", [skeleton])
    return encode_marker_array(group_to_driver_markers(group))


def test_case19_gaps_in_the_driver_stamps_count_lost_frames() -> None:
    rng = np.random.default_rng(0)
    frames = np.arange(300)
    received = frames[(frames < 20) | (rng.random(300) < 0.25)]  # 24 % after the first 20
    bridge = DriverBridge()
    for k in received.tolist():
        assert bridge.update_bytes(_message(T0 + k * PERIOD)) is not None
    lost = int(received[-1] + 1 - len(received))
    assert bridge.lost_before_reception == lost
    assert bridge.diagnostics() == {"lost_before_reception": str(lost)}
    assert bridge.accounted == len(received)  # never received: outside the frame balance


def test_a_restart_a_pause_and_empty_arrays_are_not_lost_frames() -> None:
    bridge = DriverBridge()
    stamps = [T0 + k * PERIOD for k in range(30)]
    stamps += [T0 + 10 * 10**9 + k * PERIOD for k in range(10)]  # a 9 s pause
    stamps += [T0 + k * PERIOD for k in range(10)]  # the source restarted
    for stamp in stamps:
        bridge.update_bytes(_message(stamp))
    empty = encode_marker_array(group_to_driver_markers(SkeletonGroup(T0, "k01", [])))
    bridge.update_bytes(empty, arrival_ns=T0 + 11 * PERIOD)  # nobody in view for a while
    bridge.update_bytes(_message(T0 + 40 * PERIOD))
    assert bridge.lost_before_reception == 0
    assert bridge.diagnostics() == {}
