"""Parameters from a dataclass: descriptors, command-line overrides, no implicit file, live
changes checked and applied or refused with the reason."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

pytest.importorskip("rclpy")

import rclpy
from rclpy.parameter import Parameter

from hiros_core.errors import ConfigError
from hiros_ros.params import declare_params


@dataclass
class Gate:
    """A nested group.

    Attributes:
        max_distance: metres, the gate.

    """

    max_distance: float = 0.5


@dataclass
class DemoParams:
    rate: float = 30.0
    """Hz of the output."""
    cameras: list[str] = field(default_factory=list)
    """Camera names."""
    name: str = "x"
    """A name fixed at start."""
    filter: str = "kalman"
    """Which filter."""
    order: int = 2
    """Filter order."""
    gate: Gate = field(default_factory=Gate)

    def __post_init__(self) -> None:
        if self.rate > 1000:
            msg = "rate above 1000 Hz: no camera is that fast"
            raise ConfigError(msg)


LIVE = ("rate", "filter", "gate.max_distance")


@pytest.fixture
def make_node(ros_env):
    """``make_node(*ros_args, name=...)``: a node built with those ``--ros-args``, destroyed
    after."""
    made = []

    def make(*ros_args: str, name: str = "demo_params"):
        context = rclpy.Context()
        rclpy.init(args=["--ros-args", *ros_args], context=context)
        made.append((rclpy.create_node(name, context=context), context))
        return made[-1][0]

    yield make
    for node, context in made:
        node.destroy_node()
        rclpy.shutdown(context=context)


@pytest.fixture
def node(make_node):
    return make_node()


def test_command_line_overrides_and_no_file_is_read(make_node, tmp_path, monkeypatch) -> None:
    (tmp_path / "demo_params.yaml").write_text("demo_params:\n  ros__parameters:\n    rate: 15.0\n")
    monkeypatch.setenv("HIROS_CONFIG_DIR", str(tmp_path))
    node = make_node("-p", "name:=override", "-p", "gate.max_distance:=0.8")
    params = declare_params(node, DemoParams, live=LIVE).params
    assert params.rate == 30.0  # the node's file is not read unasked
    assert params.gate.max_distance == 0.8
    assert params.name == "override"
    assert params.cameras == []
    # a list whose default is empty takes the given list (rclpy alone wants a byte array)
    node = make_node("-p", "cameras:=[k01, k02]")
    assert declare_params(node, DemoParams).params.cameras == ["k01", "k02"]


def _keep_warnings(node: rclpy.node.Node, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The list that the node's logger's warnings go to from now on."""
    logged: list[str] = []

    class Logger:  # the node's logger, keeping what it is told
        def warning(self, message: str) -> None:
            logged.append(message)

    monkeypatch.setattr(node, "get_logger", Logger)
    return logged


def test_a_removed_parameter_given_is_ignored_with_a_warning(make_node, monkeypatch) -> None:
    node = make_node("-p", "compiled:=true", "-p", "rate:=20.0", name="filter")
    logged = _keep_warnings(node, monkeypatch)
    assert declare_params(node, DemoParams).params.rate == 20.0
    assert not node.has_parameter("compiled")
    assert len(logged) == 1
    assert "parameter compiled is ignored" in logged[0]


def test_a_parameter_another_node_retired_is_not_reported(make_node, monkeypatch) -> None:
    """The filter's and the optimizer's retired names are no concern of the tracker's."""
    node = make_node("-p", "compiled:=true", "-p", "sweeps:=1", name="tracker")
    logged = _keep_warnings(node, monkeypatch)
    declare_params(node, DemoParams)
    assert logged == []


def test_a_name_one_node_retired_is_reported_by_that_node_only(make_node, monkeypatch) -> None:
    """The merger's max_jump is a constant; the tracker's is a parameter."""
    merger = make_node("-p", "max_jump:=2.0", name="merger")
    logged = _keep_warnings(merger, monkeypatch)
    declare_params(merger, DemoParams)
    assert logged == [
        "parameter max_jump is ignored (hiros_merger fixes it as the constant MAX_JUMP); "
        "remove it from the parameter file"
    ]
    tracker = make_node("-p", "max_jump:=2.0", name="tracker")
    logged = _keep_warnings(tracker, monkeypatch)
    declare_params(tracker, DemoParams)
    assert logged == []


def test_a_calib_setting_that_became_a_constant_is_ignored_with_a_warning(
    make_node, monkeypatch
) -> None:
    node = make_node("-p", "grid_step:=0.02", "-p", "rate:=20.0", name="calib")
    logged = _keep_warnings(node, monkeypatch)
    assert declare_params(node, DemoParams).params.rate == 20.0
    assert not node.has_parameter("grid_step")
    assert logged == [
        "parameter grid_step is ignored (hiros_calib fixes it as the constant GRID_STEP); "
        "remove it from the parameter file"
    ]


def test_a_bridge_setting_that_became_a_constant_is_ignored_with_a_warning(
    make_node, monkeypatch
) -> None:
    node = make_node("-p", "reset_after_backwards:=2.0", "-p", "rate:=20.0", name="generic_bridge")
    logged = _keep_warnings(node, monkeypatch)
    assert declare_params(node, DemoParams).params.rate == 20.0
    assert not node.has_parameter("reset_after_backwards")
    assert len(logged) == 1
    assert "constant RESET_AFTER_BACKWARDS" in logged[0]


def test_descriptors_tell_description_range_and_read_only(node) -> None:
    declare_params(node, DemoParams, live=LIVE)
    rate, name, order, gate, choice = node.describe_parameters(
        ["rate", "name", "order", "gate.max_distance", "filter"]
    )
    assert rate.description == "Hz of the output."
    assert (rate.floating_point_range[0].from_value, rate.read_only) == (0.0, False)
    assert name.read_only
    assert "fixed at start" in name.additional_constraints
    assert order.integer_range[0].from_value == 0
    assert gate.description == "metres, the gate."
    assert "one of: kalman, butterworth, statespace" in choice.additional_constraints


def test_live_changes_are_applied_or_refused_with_the_reason(node) -> None:
    applied = []
    parameters = declare_params(node, DemoParams, live=LIVE, apply=applied.append)

    def result(name, value):
        return node.set_parameters([Parameter(name, value=value)])[0]

    assert result("rate", 60.0).successful
    assert parameters.params.rate == 60.0
    assert applied[-1].rate == 60.0
    assert result("gate.max_distance", 0.3).successful
    assert parameters.params.gate.max_distance == 0.3
    refused = {
        "rate": (-5.0, "out of range"),
        "filter": ("nonsense", "must be one of kalman, butterworth, statespace"),
        "name": ("other", "read-only"),
        "order": (3, "read-only"),
    }
    for name, (value, reason) in refused.items():
        outcome = result(name, value)
        assert not outcome.successful, name
        assert reason in outcome.reason, (name, outcome.reason)
    outcome = result("rate", 2000.0)
    assert not outcome.successful
    assert "no camera is that fast" in outcome.reason
    assert result("rate", 5).reason.startswith("Wrong parameter type")
    assert parameters.params.rate == 60.0
    assert len(applied) == 2
    assert node.get_parameter("rate").value == 60.0
    # Hi-ROS's name of the Kalman filter is taken, and means ours
    assert result("filter", "statespace").successful
    assert parameters.params.filter == "kalman"


def test_a_refusal_by_the_node_keeps_the_old_values(node) -> None:
    def apply(params: DemoParams) -> None:
        if params.rate > 100:
            msg = "the stage cannot run above 100 Hz"
            raise ValueError(msg)

    parameters = declare_params(node, DemoParams, live=LIVE, apply=apply)
    outcome = node.set_parameters([Parameter("rate", value=200.0)])[0]
    assert not outcome.successful
    assert outcome.reason == "the stage cannot run above 100 Hz"
    assert parameters.params.rate == 30.0
    assert node.get_parameter("rate").value == 30.0


def test_a_value_out_of_range_or_of_no_choice_at_start_is_refused(make_node) -> None:
    with pytest.raises(ConfigError, match="rate"):
        declare_params(make_node("-p", "rate:=-1.0"), DemoParams, live=LIVE)
    with pytest.raises(ConfigError, match="filter must be one of"):
        declare_params(make_node("-p", "filter:=nonsense"), DemoParams, live=LIVE)


def test_hiros_names_give_the_defaults_of_ours(make_node) -> None:
    node = make_node("-p", "fixed_delay:=0.25")
    parameters = declare_params(node, DemoParams, live=LIVE, aliases={"fixed_delay": "rate"})
    assert parameters.params.rate == 0.25
    assert node.describe_parameter("fixed_delay").read_only
