"""hiros_optimizer: each tracked person keeps their own limb lengths in every frame."""

from hiros_optimizer.calibration_file import read_person_calibrations, write_person_calibrations
from hiros_optimizer.optimizer import Optimizer, OptimizerParams, PersonCalibration

__all__ = [
    "Optimizer",
    "OptimizerParams",
    "PersonCalibration",
    "read_person_calibrations",
    "write_person_calibrations",
]
