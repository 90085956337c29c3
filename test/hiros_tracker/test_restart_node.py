"""Issue 21 case 18 live: the tracker node's output resumes after a replay, and says so."""

from __future__ import annotations

import numpy as np

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.codec import encode_group
from hiros_core.model import Skeleton, SkeletonGroup

T0 = 1_700_000_000_000_000_000


def _frame(index: int) -> bytes:
    stamp = T0 + index * 33_333_333
    rest = np.tile([0.0, 0.0, 3.0], (32, 1))
    rest[:, 1] -= np.linspace(0.0, 1.6, 32)
    skeleton = Skeleton.from_positions(rest, skeleton_id=1, src_time_ns=stamp,
                                       src_frame="k01_depth_camera_link")  # fmt: skip
    return encode_group(SkeletonGroup(stamp, "k01_depth_camera_link", [skeleton]))


def test_case18_a_replay_resumes_the_output_with_an_event_on_diagnostics(ros_context) -> None:
    from hiros_tracker.node import TrackerNode

    node = TrackerNode()
    published: list[object] = []
    try:
        node._on_calibration(  # what the calib node or a calibration file would give
            Calibration("k01", cameras={"k01": CameraCalibration("k01_depth_camera_link")})
        )
        node._diagnostics.publish = published.append
        node.publish_raw = lambda _publisher, data: published.append(data)
        frames = [_frame(k) for k in range(150)]  # 5 s
        for data in frames:
            node.on_group(data)
        first = sum(isinstance(p, bytes) for p in published)
        for data in frames:  # the same recording again: its stamps go back 5 s
            node.on_group(data)
        second = sum(isinstance(p, bytes) for p in published) - first
        node.publish_diagnostics()
    finally:
        node.destroy_node()
    assert first > 100
    assert second >= first - 5
    (status,) = published[-1].status
    values = {v.key: v.value for v in status.values}
    assert values["restarts"].startswith("1 (last: k01 went back")
    assert "dropped.late frame" not in values
