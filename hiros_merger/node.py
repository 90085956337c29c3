"""``merger`` node: tracked detections in, one fused skeleton per person out.

    /hiros/tracker (raw CDR)  ->  Merger.update  ->  /hiros/merger

Camera positions (for the depth, view and occlusion weights) come from ``calibration_file`` and,
live, from the ``calib`` node's parameters; without them those weights are left out.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from hiros_core.calibration import Calibration, load_calibration
from hiros_core.errors import CalibrationError
from hiros_merger.merger import Merger, MergerParams
from hiros_ros import StageNode, run_node
from hiros_ros.calibration_follower import CalibrationFollower

__all__ = ["LIVE", "MergerNode", "MergerNodeParams", "main"]

LIVE = tuple(f.name for f in fields(MergerParams))
"""Every fusion parameter is applied while the node runs (``Merger.set_params``)."""


@dataclass
class MergerNodeParams(MergerParams):
    """The merger's parameters plus its topics and where the camera poses come from."""

    input_topic: str = "/hiros/tracker"
    output_topic: str = "/hiros/merger"
    input_qos: str = "reliable"
    calibration_file: str = ""
    calib_node: str = "/calib"


class MergerNode(StageNode):
    """``/hiros/tracker`` -> ``Merger.update`` -> ``/hiros/merger``."""

    def __init__(self) -> None:
        super().__init__("merger", MergerNodeParams, Merger, live=LIVE)
        calibration = Calibration(reference="")
        if self.params.calibration_file:
            try:
                calibration = load_calibration(self.params.calibration_file)
            except CalibrationError as exc:
                self.get_logger().fatal(str(exc))
                raise SystemExit(1) from None
            self.stage.set_calibration(calibration)
        self.follower = CalibrationFollower(
            self, calibration, self.stage.set_calibration, self.params.calib_node
        )


def main(args: list[str] | None = None) -> None:
    """``ros2 run hiros merger``."""
    run_node(MergerNode, args)
