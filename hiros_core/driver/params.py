"""How a driver numbers its markers: ``DriverBridgeParams``, the bridge nodes' parameters."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["RESET_AFTER_BACKWARDS", "DriverBridgeParams"]

RESET_AFTER_BACKWARDS = 1.0
"""Seconds: a stamp that jumps back by more than this is a restarted source (a replay looping),
not a late message, and the bridge starts over. A camera's messages are never a second late,
and a replay goes back by its whole length."""


@dataclass
class DriverBridgeParams:
    """How a driver numbers its markers; field names are the bridge nodes' ROS parameters.

    Attributes:
        layout: built-in layout name (``azure_kinect``, ``kinect_v2``) or a layout YAML file.
        id_stride: ids are ``body * id_stride + joint`` (``body_major``) or
            ``joint * id_stride + body`` (``joint_major``).
        id_scheme: ``body_major`` (the Azure driver) or ``joint_major``.
        joint_names: the driver's joint order by layout joint name, when it differs from the
            layout's order; empty means driver joint index = layout marker id.
        position_scale: metres per driver unit (0.001 for a driver publishing millimetres).
        confidence_levels: the driver's highest confidence level; model confidence is
            ``level / confidence_levels``.
        frame_id: frame written to the groups; empty keeps the markers' frame.

    """

    layout: str = "azure_kinect"
    id_stride: int = 100
    id_scheme: str = "body_major"
    joint_names: list[str] = field(default_factory=list)
    position_scale: float = 1.0
    confidence_levels: int = 3
    frame_id: str = ""
