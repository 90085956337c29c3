"""Every node's parameter file holds its dataclass's names and defaults; every parameter is
described, with a range that holds its default.

The parameter files in config/ are what users copy and pass with ``--params-file``; the nodes
read none of them unasked, so a file that drifts from the dataclass would make the same node
behave differently by entry point (as the optimizer's prior_weight once did: 0.05 in the file,
0.01 in the dataclass).
"""

from __future__ import annotations

import importlib
import math
from pathlib import Path

import pytest

from hiros_core.parameters import load_config_defaults
from hiros_ros.params import ParameterSpec, parameter_specs

CONFIG = Path(__file__).resolve().parents[2] / "config"

NODES = {
    "azure_bridge": ("hiros_azure_bridge.node", "BridgeNodeParams", ()),
    "calib": ("hiros_calib.node", "CalibNodeParams", "LIVE"),
    "tracker": ("hiros_tracker.node", "TrackerNodeParams", "LIVE"),
    "merger": ("hiros_merger.node", "MergerNodeParams", "LIVE"),
    "optimizer": ("hiros_optimizer.node", "OptimizerNodeParams", "LIVE"),
    "filter": ("hiros_filter.node", "FilterNodeParams", "LIVE"),
    "pipeline": ("hiros_pipeline.node", "PipelineNodeParams", "LIVE"),
    "visualizer": ("hiros_visualizer.node", "VisualizerNodeParams", "LIVE"),
}
"""Node name -> (module, parameters dataclass, its live names)."""

EXAMPLES = {"generic_bridge": "azure_bridge"}
"""Files that configure a node for another driver: their names must be the node's."""


def node_specs(node: str) -> dict[str, ParameterSpec]:
    module_name, type_name, live_name = NODES[node]
    module = importlib.import_module(module_name)
    live = getattr(module, live_name) if live_name else ()
    return {spec.name: spec for spec in parameter_specs(getattr(module, type_name), live)}


@pytest.mark.parametrize("node", sorted(NODES))
def test_the_parameter_file_holds_every_name_and_default(node: str) -> None:
    specs = node_specs(node)
    values = load_config_defaults(node, CONFIG / f"{node}.yaml")
    assert set(values) <= set(specs), f"{node}.yaml has names the node lacks"
    assert {name: values[name] for name in values} == {name: specs[name].default for name in values}
    # Nested stage parameters (pipeline's tracker.*) may be left to the stages' own files.
    top_level = {name for name in specs if "." not in name}
    assert top_level <= set(values), f"{node}.yaml lacks {sorted(top_level - set(values))}"


@pytest.mark.parametrize(("example", "node"), sorted(EXAMPLES.items()))
def test_an_example_file_uses_the_node_s_names(example: str, node: str) -> None:
    values = load_config_defaults(example, CONFIG / f"{example}.yaml")
    assert set(values) == {name for name in node_specs(node) if "." not in name}


def test_every_file_belongs_to_a_node() -> None:
    files = {path.stem for path in CONFIG.glob("*.yaml")}
    assert files == set(NODES) | set(EXAMPLES)


@pytest.mark.parametrize("node", sorted(NODES))
def test_every_parameter_is_described_and_its_default_allowed(node: str) -> None:
    for spec in node_specs(node).values():
        assert spec.description, f"{node}: {spec.name} has no description"
        assert spec.check(spec.default) == "", spec.name
        if spec.limits is not None:
            low, high = spec.limits
            assert low <= high
            assert not math.isnan(low)
            assert not math.isnan(high)
        descriptor = spec.descriptor()
        assert descriptor.read_only == spec.read_only
        assert descriptor.description == spec.description


@pytest.mark.parametrize("node", sorted(NODES))
def test_topics_qos_and_layout_are_read_only(node: str) -> None:
    fixed = {"input_topic", "output_topic", "input_topics", "camera_topic", "topics",
             "input_qos", "camera_qos", "cameras", "camera_names", "layout", "input"}  # fmt: skip
    for spec in node_specs(node).values():
        if spec.name in fixed:
            assert spec.read_only, f"{node}: {spec.name} is not read-only"
