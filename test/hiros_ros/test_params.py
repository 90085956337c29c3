"""Parameters from a dataclass: YAML defaults, command-line overrides, nested names."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

pytest.importorskip("rclpy")

import rclpy

from hiros_ros.params import declare_params, load_config_defaults


@dataclass
class Gate:
    max_distance: float = 0.5


@dataclass
class DemoParams:
    rate: float = 30.0
    cameras: list[str] = field(default_factory=list)
    name: str = "x"
    gate: Gate = field(default_factory=Gate)


def test_yaml_then_command_line(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "demo_params.yaml").write_text(
        "demo_params:\n  ros__parameters:\n    rate: 15.0\n    gate: {max_distance: 0.8}\n"
    )
    monkeypatch.setenv("HIROS_CONFIG_DIR", str(tmp_path))
    assert load_config_defaults("demo_params") == {"rate": 15.0, "gate.max_distance": 0.8}
    context = rclpy.Context()
    rclpy.init(args=["--ros-args", "-p", "name:=override"], context=context)
    try:
        node = rclpy.create_node("demo_params", context=context)
        params = declare_params(node, DemoParams)
        assert params.rate == 15.0
        assert params.gate.max_distance == 0.8
        assert params.name == "override"
        assert params.cameras == []
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
