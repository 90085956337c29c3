"""Each node's declared parameters, counted from its parameters dataclass (issue 24).

``python test/support/node_parameters.py`` (with the repository and ``test/support`` on
``PYTHONPATH``, and ROS 2's rclpy importable: the node modules hold the dataclasses) prints the
count per node. A node's count is its top-level parameters, the keys of ``config/<node>.yaml``:
the pipeline's stage sections (``tracker.*``, ...) are the stage nodes' own and counted there;
``generic_bridge`` is the ``azure_bridge`` node for another driver, counted again because its
file is one more for a user to read.
"""

from __future__ import annotations

import importlib

from hiros_ros.params import ParameterSpec, parameter_specs

__all__ = ["EXAMPLES", "NODES", "declared_parameters", "node_specs", "parameter_counts"]

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
    """Every parameter the node declares (dotted names for nested dataclasses), by name."""
    module_name, type_name, live_name = NODES[EXAMPLES.get(node, node)]
    module = importlib.import_module(module_name)
    live = getattr(module, live_name) if live_name else ()
    return {spec.name: spec for spec in parameter_specs(getattr(module, type_name), live)}


def declared_parameters(node: str) -> list[str]:
    """The node's own parameters: its top-level names (not the pipeline's stage sections)."""
    return [name for name in node_specs(node) if "." not in name]


def parameter_counts() -> dict[str, int]:
    """``{node: number of its parameters}`` for every node and example file."""
    return {node: len(declared_parameters(node)) for node in sorted({*NODES, *EXAMPLES})}


if __name__ == "__main__":
    counts = parameter_counts()
    for node, count in counts.items():
        print(f"{node:15} {count:3}")
    print(f"{'total':15} {sum(counts.values()):3}")
