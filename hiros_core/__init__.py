"""hiros_core: the ROS-free foundation — skeleton model, layouts, geometry, calibration, codec."""

from hiros_core.calibration import (
    Calibration,
    CameraCalibration,
    load_calibration,
    save_calibration,
)
from hiros_core.errors import (
    CalibrationError,
    CodecError,
    ConfigError,
    HirosError,
    LayoutError,
    RecordingError,
)
from hiros_core.geometry import RigidTransform
from hiros_core.layouts import AZURE_KINECT, KINECT_V2, Layout, get_layout, load_layout
from hiros_core.model import (
    Skeleton,
    SkeletonGroup,
    SkeletonRows,
    camera_from_frame,
    ns_to_sec,
    sec_to_ns,
    shared_stack,
    stack_rows,
)

__all__ = [
    "AZURE_KINECT",
    "KINECT_V2",
    "Calibration",
    "CalibrationError",
    "CameraCalibration",
    "CodecError",
    "ConfigError",
    "HirosError",
    "Layout",
    "LayoutError",
    "RecordingError",
    "RigidTransform",
    "Skeleton",
    "SkeletonGroup",
    "SkeletonRows",
    "camera_from_frame",
    "get_layout",
    "load_calibration",
    "load_layout",
    "ns_to_sec",
    "save_calibration",
    "sec_to_ns",
    "shared_stack",
    "stack_rows",
]
