"""hiros_optimizer: each tracked person keeps their own limb lengths in every frame."""

from hiros_optimizer.calibration_file import read_person_calibrations, write_person_calibrations
from hiros_optimizer.optimizer import Optimizer, OptimizerParams, PersonCalibration

__all__ = [
    "Optimizer",
    "OptimizerParams",
    "PersonCalibration",
    "main",
    "read_person_calibrations",
    "write_person_calibrations",
]


def main(args: list[str] | None = None) -> None:
    """Run the ``optimizer`` node (rclpy is imported only here, so the class stays ROS-free)."""
    from hiros_optimizer.node import main as node_main

    node_main(args)
