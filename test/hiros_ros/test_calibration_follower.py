"""Calibration parameters from the calib node: good ones applied, malformed ones refused."""

import math

import numpy as np
import pytest

rcl = pytest.importorskip("rcl_interfaces.msg")

from hiros_core.calibration import Calibration  # noqa: E402
from hiros_ros.calibration_follower import CalibrationFollower  # noqa: E402


class _Node:
    def __init__(self):
        self.dropped = []

    def create_subscription(self, *_):
        return None

    def error(self, reason, detail=""):
        self.dropped.append(detail)


def _parameter(name, **value):
    kind = {
        "double_value": rcl.ParameterType.PARAMETER_DOUBLE,
        "string_value": rcl.ParameterType.PARAMETER_STRING,
        "double_array_value": rcl.ParameterType.PARAMETER_DOUBLE_ARRAY,
    }[next(iter(value))]
    return rcl.Parameter(name=name, value=rcl.ParameterValue(type=kind, **value))


def _follow(*parameters):
    node, changes = _Node(), []
    follower = CalibrationFollower(node, Calibration(reference=""), changes.append)
    follower._on_event(rcl.ParameterEvent(node="/calib", changed_parameters=list(parameters)))
    return follower.calibration, node.dropped, changes


def test_good_values_are_applied():
    calibration, dropped, changes = _follow(
        _parameter("cameras.k02.time_offset", double_value=0.25),
        _parameter("cameras.k02.translation", double_array_value=[1.0, 2.0, 3.0]),
        _parameter("cameras.k02.rotation", double_array_value=[0.0, 0.0, 0.0, 1.0]),
    )
    camera = calibration.cameras["k02"]
    assert camera.time_offset == 0.25
    np.testing.assert_array_equal(camera.translation, [1.0, 2.0, 3.0])
    assert dropped == []
    assert len(changes) == 1


def test_malformed_values_are_refused_and_counted():
    calibration, dropped, changes = _follow(
        _parameter("cameras.k02.rotation", double_value=1.0),  # not an array: used to raise
        _parameter("cameras.k02.rotation", string_value="abcd"),
        _parameter("cameras.k02.translation", double_array_value=[math.nan, 0.0, 0.0]),
        _parameter("cameras.k02.time_offset", string_value="soon"),
        _parameter("cameras.k02.drift", double_value=math.inf),
        _parameter("cameras.k02.frame_id", string_value=""),
    )
    assert len(dropped) == 6
    assert "k02" not in calibration.cameras
    assert changes == []
