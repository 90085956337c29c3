"""The bridge nodes' parameter files agree with the parameters dataclass."""

import dataclasses
from pathlib import Path

import pytest
import yaml

from hiros_azure_bridge import DriverBridge, load_bridge_params

CONFIG = Path(__file__).resolve().parents[2] / "config"


def test_azure_bridge_yaml_holds_the_defaults():
    node = pytest.importorskip("hiros_azure_bridge.node")
    values = yaml.safe_load((CONFIG / "azure_bridge.yaml").read_text())["azure_bridge"]
    defaults = dataclasses.asdict(node.BridgeNodeParams())
    assert values["ros__parameters"] == defaults


def test_generic_bridge_yaml_is_a_valid_description():
    params, extra = load_bridge_params(CONFIG / "generic_bridge.yaml")
    assert params.layout == "kinect_v2"
    assert extra["cameras"] == ["kinect_left", "kinect_right"]
    assert DriverBridge(params).layout.n_joints == 25
