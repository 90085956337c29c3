"""The Azure driver's empty MarkerArray, with its arrival time, is "nobody in view"."""

from hiros_core.codec import MarkerArrayData
from hiros_core.driver import DriverBridge, group_to_driver_markers
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup

FRAME = "k02_depth_camera_link"
STAMP = 1_700_000_000_000_000_000
TRANSIT = 40_000_000  # ns from the camera's stamp to the message's arrival


def _seen(stamp: int) -> MarkerArrayData:
    skeleton = Skeleton.from_positions(
        [[0.0, 0.0, 2.0]] * AZURE_KINECT.n_joints, AZURE_KINECT, skeleton_id=1,
        src_time_ns=stamp, src_frame=FRAME,
    )  # fmt: skip
    return group_to_driver_markers(SkeletonGroup(stamp, FRAME, [skeleton]))


def test_an_empty_array_is_an_empty_group_on_the_camera_s_clock() -> None:
    bridge = DriverBridge(default_frame="k02_depth_camera_link")
    assert len(bridge.update(_seen(STAMP), STAMP + TRANSIT).skeletons) == 1
    period = 33_000_000
    for k in (1, 2):
        nobody = bridge.update(MarkerArrayData.new(0), STAMP + TRANSIT + k * period)
        assert nobody.skeletons == []
        assert nobody.stamp_ns == STAMP + k * period  # arrival less the last transit
        assert nobody.frame_id == FRAME
    # arriving early (less transit than before) it still never goes back in time
    early = bridge.update(MarkerArrayData.new(0), STAMP + 2 * period + 1)
    assert early.stamp_ns == STAMP + 2 * period + 1
    assert (bridge.processed, bridge.nobody_in_view, bridge.drops.frame_total) == (4, 3, 0)
    # and a frame stamped after it is taken as usual
    assert bridge.update(_seen(STAMP + 3 * period), STAMP + 3 * period + TRANSIT) is not None


def test_before_any_frame_the_receiver_s_clock_and_the_default_frame() -> None:
    bridge = DriverBridge(default_frame="k02_depth_camera_link")
    nobody = bridge.update(MarkerArrayData.new(0), STAMP)
    assert (nobody.stamp_ns, nobody.frame_id, nobody.skeletons) == (STAMP, FRAME, [])
    assert DriverBridge().update(MarkerArrayData.new(0)) is None  # no arrival time: a drop
