"""``ros2 run hiros optimizer``: /hiros/merger -> Optimizer.update -> /hiros/optimizer.

Besides the stage node's data flow it offers the person-calibration services of DESIGN.md,
``~/calibrate`` (Calibrate: learn these tracks' limb lengths again) and ``~/change_id``
(ChangeId: track ``from_id`` is person ``to_id`` from now on), and the calibration file:
``load_calibration`` reads ``calibration_file`` at start, ``export_calibration`` rewrites it
whenever a person calibration is accepted or moved.

The same two services are also offered where Hi-ROS's optimizer offers them, ``/hiros/calibrate``
and ``/hiros/change_id``, so that Hi-ROS's clients work unchanged; their types are Hi-ROS's
(``hiros_skeleton_optimizer/srv/...``, the same fields as ours) when that package is installed
beside hiros, and ours otherwise (``service_types``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hiros_core.errors import ConfigError
from hiros_optimizer.calibration_file import read_person_calibrations, write_person_calibrations
from hiros_optimizer.optimizer import Optimizer, OptimizerParams
from hiros_ros import StageNode, run_node

__all__ = [
    "HIROS_SERVICES",
    "LIVE",
    "OptimizerNode",
    "OptimizerNodeParams",
    "main",
    "service_types",
]

HIROS_SERVICES = ("/hiros/calibrate", "/hiros/change_id")
"""Where Hi-ROS's optimizer (node skeleton_optimizer in namespace hiros) offers its services."""

LIVE = ("export_calibration",)
"""Parameters applied while the node runs; the fit's are fixed when a layout is first seen."""


@dataclass
class OptimizerNodeParams(OptimizerParams):
    """The optimizer's parameters plus the node's topics."""

    input_topic: str = "/hiros/merger"
    output_topic: str = "/hiros/optimizer"
    input_qos: str = "reliable"


class OptimizerNode(StageNode):
    """The optimizer stage node with its services and calibration file."""

    def __init__(self) -> None:
        super().__init__("optimizer", OptimizerNodeParams, Optimizer, live=LIVE)
        if self.params.load_calibration:
            self._load()
        calibrate, change_id = service_types()
        for calibrate_name, change_id_name in (("~/calibrate", "~/change_id"), HIROS_SERVICES):
            self.create_service(calibrate, calibrate_name, self.on_calibrate)
            self.create_service(change_id, change_id_name, self.on_change_id)

    def _apply(self, params: OptimizerNodeParams) -> None:
        """Nothing to hand over: ``export_calibration`` is read at each export."""

    def on_group(self, data: bytes) -> None:
        """Run the stage; export when links were learnt, warn of people past the timeout."""
        super().on_group(data)
        if self.stage.new_calibrations:
            ids = ", ".join(str(i) for i in self.stage.new_calibrations)
            self.get_logger().info(f"limb lengths calibrated for track(s) {ids}")
            self._export()
        if self.stage.new_overdue:
            report = self.stage.report()
            for track in self.stage.new_overdue:  # once per person
                self.get_logger().warning(f"limb lengths of track {track}: {report[track]}")

    def on_calibrate(self, request: Any, response: Any) -> Any:
        """``~/calibrate``: forget and re-learn the given tracks' limb lengths."""
        response.ok = self.stage.calibrate(list(request.track_ids))
        self.get_logger().info(f"calibrate {list(request.track_ids)}: ok={response.ok}")
        return response

    def on_change_id(self, request: Any, response: Any) -> Any:
        """``~/change_id``: track ``from_id`` becomes person ``to_id`` (with its calibration)."""
        response.ok = self.stage.change_id(request.from_id, request.to_id)
        self.get_logger().info(f"change_id {request.from_id} -> {request.to_id}: ok={response.ok}")
        if response.ok:
            self._export()
        return response

    def _load(self) -> None:
        path = self.params.calibration_file
        try:
            ids = self.stage.load_calibrations(read_person_calibrations(path))
        except ConfigError as exc:
            self.get_logger().error(f"person calibrations not loaded: {exc}")
            return
        self.get_logger().info(f"loaded limb lengths of person(s) {ids} from {path}")

    def _export(self) -> None:
        if not self.params.export_calibration:
            return
        try:
            write_person_calibrations(
                self.params.calibration_file, self.stage.export_calibrations()
            )
        except ConfigError as exc:
            self.error("calibration file not written", str(exc))


def service_types() -> tuple[type, type]:
    """Calibrate and ChangeId: Hi-ROS's when its hiros_skeleton_optimizer is installed, else ours.

    A service has one type, and Hi-ROS's clients call with theirs. In a workspace holding
    both projects, our hiros_skeleton_msgs is left out (Hi-ROS's package of that name has the
    same messages, no services): the node then needs Hi-ROS's service types.
    """
    try:
        from hiros_skeleton_optimizer.srv import Calibrate, ChangeId
    except ImportError:
        from hiros_skeleton_msgs.srv import Calibrate, ChangeId
    return Calibrate, ChangeId


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run hiros optimizer``."""
    run_node(OptimizerNode, args)
