"""Follow the ``calib`` node's published calibration through ``/parameter_events``.

The calib node keeps its result as its own parameters (``cameras.<cam>.time_offset``, ``.drift``,
``.drift_epoch``, ``.translation``, ``.rotation``, ``.frame_id``); any node can track them from
the parameter events, without a service call or a custom topic.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np
from rcl_interfaces.msg import ParameterEvent, ParameterType
from rclpy.node import Node

from hiros_core.calibration import Calibration, CameraCalibration

__all__ = ["CalibrationFollower"]

_FIELDS = {"time_offset", "drift", "drift_epoch", "translation", "rotation", "frame_id"}


def _value(parameter):  # noqa: ANN001, ANN202 - rcl_interfaces Parameter
    value = parameter.value
    return {
        ParameterType.PARAMETER_DOUBLE: lambda: value.double_value,
        ParameterType.PARAMETER_INTEGER: lambda: float(value.integer_value),
        ParameterType.PARAMETER_STRING: lambda: value.string_value,
        ParameterType.PARAMETER_DOUBLE_ARRAY: lambda: np.asarray(value.double_array_value),
    }.get(value.type, lambda: None)()


class CalibrationFollower:
    """Keeps a Calibration in step with the calib node's parameters and reports changes.

    Args:
        node: the node that subscribes.
        calibration: the starting calibration (e.g. from the file), updated in place.
        on_change: called with the new calibration after each event that changed it.
        calib_node: fully qualified name of the calib node.

    """

    def __init__(
        self,
        node: Node,
        calibration: Calibration,
        on_change: Callable[[Calibration], None],
        calib_node: str = "/calib",
    ) -> None:
        self.calibration = calibration
        self._on_change = on_change
        self._calib_node = calib_node
        self._node = node
        node.create_subscription(ParameterEvent, "/parameter_events", self._on_event, 100)

    def _on_event(self, event: ParameterEvent) -> None:
        if event.node != self._calib_node:
            return
        changed = False
        for parameter in (*event.new_parameters, *event.changed_parameters):
            parts = parameter.name.split(".")
            if len(parts) != 3 or parts[0] != "cameras" or parts[2] not in _FIELDS:
                continue
            value = _checked(parts[2], _value(parameter))
            if value is None:
                self._refused(parameter.name)
                continue
            camera = self.calibration.cameras.setdefault(
                parts[1], CameraCalibration(frame_id=f"{parts[1]}_depth_camera_link")
            )
            setattr(camera, parts[2], value)
            if not self.calibration.reference:
                self.calibration.reference = parts[1]
            changed = True
        if changed:
            self._on_change(copy.deepcopy(self.calibration))

    def _refused(self, name: str) -> None:
        """Count (and log, throttled) a calib parameter of the wrong type or out of range."""
        # A HirosNode counts it on /diagnostics as an error: no input frame is lost.
        error = getattr(self._node, "error", None)
        if error is not None:
            error("calibration parameter of the wrong type or not finite", name)
        else:
            self._node.get_logger().warning(f"ignored calibration parameter {name}")


def _checked(field: str, value: object) -> object | None:
    """The value if it fits the field (finite numbers, a unit quaternion, a name), else None.

    Anything may be set on the calib node's parameters by hand; a value of the wrong type
    must not reach the stages (or raise in this callback, which would stop the node).
    """
    if field == "frame_id":
        return value if isinstance(value, str) and value else None
    if field in {"translation", "rotation"}:
        size = 3 if field == "translation" else 4
        if not isinstance(value, np.ndarray) or value.shape != (size,):
            return None
        if not np.isfinite(value).all():
            return None
        if field == "rotation" and not np.isclose(np.linalg.norm(value), 1.0, atol=1e-3):
            return None
        return value
    return value if isinstance(value, float) and np.isfinite(value) else None
