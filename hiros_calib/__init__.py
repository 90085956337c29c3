"""hiros_calib: spatio-temporal camera calibration from people's own motion."""

from hiros_calib.calibrator import CalibrationResult, Calibrator, CalibratorParams
from hiros_calib.extrinsics import ExtrinsicsParams
from hiros_calib.live import LiveCalibrator, LiveCalibratorParams
from hiros_calib.sync import SyncParams

__all__ = [
    "CalibrationResult",
    "Calibrator",
    "CalibratorParams",
    "ExtrinsicsParams",
    "LiveCalibrator",
    "LiveCalibratorParams",
    "SyncParams",
]
