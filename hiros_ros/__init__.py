"""hiros_ros: where rclpy meets the stages — node base, parameters, QoS, stage nodes."""

from hiros_ros.environment import prepare_ros_environment

prepare_ros_environment()

from hiros_ros.node import HirosNode, make_executor, run_node  # noqa: E402 - environment first
from hiros_ros.params import NodeParameters, declare_params, parameter_specs  # noqa: E402
from hiros_ros.stage_node import StageNode, stage_main  # noqa: E402

__all__ = [
    "HirosNode",
    "NodeParameters",
    "StageNode",
    "declare_params",
    "make_executor",
    "parameter_specs",
    "prepare_ros_environment",
    "run_node",
    "stage_main",
]
