"""Each node applies its live parameters to what uses them (built in the test's process)."""

from __future__ import annotations

from pathlib import Path

import pytest

pytestmark = pytest.mark.ros


def set_one(node, name: str, value):
    from rclpy.parameter import Parameter

    return node.set_parameters([Parameter(name, value=value)])[0]


def test_the_stage_nodes_hand_changes_to_their_stages(ros_context) -> None:
    from hiros_merger.node import MergerNode
    from hiros_pipeline.node import PipelineNode
    from hiros_tracker.node import TrackerNode

    nodes = [TrackerNode(), MergerNode(), PipelineNode()]
    tracker, merger, pipeline = nodes
    try:
        assert set_one(tracker, "gate_distance", 0.8).successful
        assert tracker.tracker.params.gate_distance == 0.8
        assert set_one(merger, "max_extrapolation", 0.05).successful
        assert merger.stage.params.max_extrapolation == 0.05
        assert set_one(pipeline, "merger.track_timeout", 0.5).successful
        assert set_one(pipeline, "filter.measurement_noise", 0.02).successful
        assert set_one(pipeline, "tracker.min_hits", 3).successful
        assert pipeline.pipeline.merger.params.track_timeout == 0.5
        assert pipeline.pipeline.filter.params.measurement_noise == 0.02
        assert pipeline.pipeline.tracker.params.min_hits == 3
        refused = set_one(pipeline, "optimizer.track_timeout", 0.5)  # built once: read-only
        assert not refused.successful
        assert "read-only" in refused.reason
        assert not set_one(tracker, "cameras", ["k09"]).successful
    finally:
        for node in nodes:
            node.destroy_node()


def test_calib_saves_where_save_file_says_now(ros_context, tmp_path: Path) -> None:
    from hiros_calib.node import CalibNode

    node = CalibNode()
    try:
        target = tmp_path / "moved.yaml"
        assert set_one(node, "save_file", str(target)).successful
        assert node._save_path() == target
        assert set_one(node, "update_period", 5.0).successful
        assert node.live.params.update_period == 5.0
        refused = set_one(node, "update_period", -1.0)
        assert not refused.successful
        assert node.live.params.update_period == 5.0
    finally:
        node._stop.set()
        node.destroy_node()


def test_calib_s_results_are_not_set_from_outside(ros_context) -> None:
    from hiros_calib.node import CalibNode
    from hiros_core.calibration import Calibration, CameraCalibration

    node = CalibNode()
    try:
        frame = "k01_depth_camera_link"
        node._latest = Calibration(
            reference="k01", cameras={"k01": CameraCalibration(frame_id=frame, time_offset=0.5)}
        )
        node.publish_result()  # the node sets its own results
        assert node.get_parameter("cameras.k01.time_offset").value == 0.5
        refused = set_one(node, "cameras.k01.time_offset", 0.1)
        assert not refused.successful
        assert "is a result of the calibration" in refused.reason
        assert node.get_parameter("cameras.k01.time_offset").value == 0.5
    finally:
        node._stop.set()
        node.destroy_node()
