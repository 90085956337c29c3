"""Declare a stage's parameters dataclass as ROS parameters (see ``hiros_core.parameters``).

Precedence, lowest first: the dataclass default, other nodes' files given as ``extra_defaults``,
the node's own YAML file, then the command line (``-p``/``--params-file``, applied by rclpy).
"""

from __future__ import annotations

import typing
from typing import Any, TypeVar

from hiros_core.parameters import (
    build_params,
    dataclass_defaults,
    load_config_defaults,
    stage_config_defaults,
)

T = TypeVar("T")

__all__ = ["declare_params", "load_config_defaults", "stage_config_defaults"]


def declare_params(
    node: Any,
    params_type: type[T],
    node_name: str | None = None,
    extra_defaults: dict[str, Any] | None = None,
) -> T:
    """Declare every field of ``params_type`` on ``node`` and return the resolved dataclass.

    ``extra_defaults`` (e.g. other nodes' files) sit between the dataclass and this node's file.
    """
    defaults = dataclass_defaults(params_type)
    defaults.update({k: v for k, v in (extra_defaults or {}).items() if k in defaults})
    defaults.update(
        {
            k: v
            for k, v in load_config_defaults(node_name or node.get_name()).items()
            if k in defaults
        }
    )
    values = {}
    for name, default in defaults.items():
        value = list(default) if isinstance(default, tuple) else default
        if isinstance(value, list) and not value:
            from rcl_interfaces.msg import ParameterDescriptor, ParameterType

            kind = _empty_list_type(params_type, name)
            descriptor = ParameterDescriptor(type=getattr(ParameterType, kind))
            parameter = node.declare_parameter(name, value, descriptor)
        else:
            parameter = node.declare_parameter(name, value)
        values[name] = parameter.value
    return build_params(params_type, values)


def _empty_list_type(params_type: type, dotted: str) -> str:
    """The ROS parameter type of an empty list field, from its element annotation."""
    hint: Any = params_type
    for part in dotted.split("."):
        hint = typing.get_type_hints(hint)[part]
    item = (typing.get_args(hint) or (str,))[0]
    return {
        float: "PARAMETER_DOUBLE_ARRAY",
        int: "PARAMETER_INTEGER_ARRAY",
        bool: "PARAMETER_BOOL_ARRAY",
    }.get(item, "PARAMETER_STRING_ARRAY")
