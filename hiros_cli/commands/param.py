"""Read and change a running node's parameters (thin over rclpy's parameter services).

For an install from PyPI, where there is no ``ros2`` command; with a ROS 2 installation
``ros2 param`` does the same. A value given to ``set`` is read as YAML and converted to the
parameter's declared type (``4`` sets a double to 4.0); the node checks it and refuses what it
cannot apply, with the reason (exit 1).

Examples:
  hiros param list /filter
  hiros param describe /filter cutoff_frequency
  hiros param get /filter cutoff_frequency measurement_noise
  hiros param set /filter cutoff_frequency 4
  hiros param dump /tracker > tracker.yaml      # a parameter file: --params-file tracker.yaml

"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

import yaml

from hiros_cli.commands._ros import answer, cli_node
from hiros_core.errors import ConfigError

HELP = "list, describe, get, set or dump a running node's parameters"

_TYPE_NAMES = {
    1: "bool", 2: "integer", 3: "double", 4: "string", 5: "byte array", 6: "bool array",
    7: "integer array", 8: "double array", 9: "string array",
}  # fmt: skip
"""rcl_interfaces ParameterType values -> the names ``describe`` prints."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``hiros param ACTION NODE [NAME ...] [VALUE]``."""
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    for action, text in (
        ("list", "the node's parameter names"),
        ("describe", "description, type, range and whether it applies while running"),
        ("get", "the current values"),
        ("dump", "every value, as a parameter file (--params-file)"),
    ):
        child = actions.add_parser(action, help=text, description=text)
        child.add_argument("node", help="fully qualified node name, e.g. /filter")
        if action in ("describe", "get"):
            child.add_argument("names", nargs="*" if action == "describe" else "+")
        _timeout(child)
    child = actions.add_parser("set", help="change one value", description="change one value")
    child.add_argument("node", help="fully qualified node name, e.g. /filter")
    child.add_argument("name")
    child.add_argument("value", help="YAML: 4.0, true, '[k01, k02]', text")
    _timeout(child)


def _timeout(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--timeout", type=float, default=5.0, help="seconds to wait for the node (default 5)"
    )


def run(args: argparse.Namespace) -> int:
    """Connect to the node's parameter services, do the action, print the result."""
    from rclpy.parameter_client import AsyncParameterClient

    node_name = args.node if args.node.startswith("/") else f"/{args.node}"
    with cli_node("hiros_param") as node:
        client = AsyncParameterClient(node, node_name)
        if not client.wait_for_services(timeout_sec=args.timeout):
            msg = f"no node {node_name} answers (is it running, with this ROS_DOMAIN_ID?)"
            raise ConfigError(msg)
        session = _Session(node, client, node_name, args.timeout)
        return getattr(session, args.action)(args)


class _Session:
    """One command's calls to one node's parameter services."""

    def __init__(self, node: Any, client: Any, node_name: str, timeout: float) -> None:
        self.node, self.client, self.node_name, self.timeout = node, client, node_name, timeout

    def _call(self, future: Any) -> Any:
        return answer(self.node, future, self.timeout, self.node_name)

    def names(self) -> list[str]:
        return sorted(self._call(self.client.list_parameters()).result.names)

    def values(self, names: list[str]) -> dict[str, Any]:
        from rclpy.parameter import parameter_value_to_python

        got = self._call(self.client.get_parameters(names)).values
        pairs = zip(names, got, strict=True)
        return {name: parameter_value_to_python(value) for name, value in pairs}

    def list(self, args: argparse.Namespace) -> int:
        print("\n".join(self.names()))
        return 0

    def get(self, args: argparse.Namespace) -> int:
        unknown = sorted(set(args.names) - set(self.names()))
        if unknown:
            msg = f"{self.node_name} has no parameter {', '.join(unknown)}"
            raise ConfigError(msg)
        for name, value in self.values(args.names).items():
            print(f"{name}: {_yaml_value(value)}")
        return 0

    def dump(self, args: argparse.Namespace) -> int:
        values = {k: v for k, v in self.values(self.names()).items() if v is not None}
        tree: dict[str, Any] = {}
        for name, value in values.items():
            *groups, leaf = name.split(".")
            branch = tree
            for group in groups:
                branch = branch.setdefault(group, {})
            branch[leaf] = list(value) if isinstance(value, list | tuple) else value
        document = {self.node_name: {"ros__parameters": tree}}
        sys.stdout.write(yaml.safe_dump(document, sort_keys=False))
        return 0

    def describe(self, args: argparse.Namespace) -> int:
        names = args.names or self.names()
        for descriptor in self._call(self.client.describe_parameters(names)).descriptors:
            print(f"{descriptor.name} ({_TYPE_NAMES.get(descriptor.type, 'not set')})")
            if descriptor.description:
                print(f"  {descriptor.description}")
            for span in (*descriptor.floating_point_range, *descriptor.integer_range):
                print(f"  range: {_bound(span.from_value)} .. {_bound(span.to_value)}")
            if descriptor.additional_constraints:
                print(f"  {descriptor.additional_constraints}")
            if descriptor.read_only:
                print("  read-only")
        return 0

    def set(self, args: argparse.Namespace) -> int:
        from rclpy.parameter import Parameter

        (descriptor,) = self._call(self.client.describe_parameters([args.name])).descriptors
        value = _typed(args.value, descriptor.type, args.name)
        response = self._call(self.client.set_parameters([Parameter(args.name, value=value)]))
        result = response.results[0]
        if not result.successful:
            refusal = f"{self.node_name} refused {args.name} = {value!r}: {result.reason}"
            print(refusal, file=sys.stderr)
            return 1
        print(f"{self.node_name}: {args.name} = {_yaml_value(value)}")
        return 0


def _typed(text: str, kind: int, name: str) -> Any:
    """``text`` read as YAML and converted to the declared type (ints to doubles)."""
    if kind == 0:
        msg = f"no parameter {name}"
        raise ConfigError(msg)
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        value = text
    if kind == 3 and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind == 8 and isinstance(value, list):
        return [float(v) for v in value]
    if kind == 4 and not isinstance(value, str):
        return text
    return value


def _yaml_value(value: Any) -> str:
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("\n...")


def _bound(value: float) -> str:
    """A range end as a reader wants it: ``any`` for none (inf, or int32's largest)."""
    return "any" if math.isinf(value) or abs(value) >= 2**31 - 1 else f"{value:g}"
