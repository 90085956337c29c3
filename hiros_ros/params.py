"""A node's ROS parameters, generated once from its parameters dataclass.

Every field of the dataclass (nested dataclasses as dotted names, ``merger.window``) becomes a
parameter whose descriptor a client can read (``ros2 param describe``):

- the description is the field's own documentation: the ``Attributes:`` entry of its class
  docstring or the string under the field (a subclass's wins over its bases');
- numbers carry their range (``RANGES``; anything else not negative), names from a fixed set
  their choices (``CHOICES``, in ``additional_constraints``);
- a parameter the node applies while running is one of its ``live`` names; every other one is
  ``read_only`` (topics, QoS, layout, what a stage builds once): rclpy refuses to change it.

The value is the dataclass default unless the command line (``-p``, ``--params-file``) gives
one; no parameter file is read unless given. A change of a live parameter goes through one
callback: the new values must build the dataclass (its own checks), then the node applies them
(``apply``); anything else is refused with the reason, and nothing changes.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import itertools
import math
import re
import textwrap
import typing
from collections.abc import Callable, Collection, Iterable
from typing import Any, Generic, TypeVar

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    ParameterValue,
    SetParametersResult,
)
from rclpy.exceptions import ParameterUninitializedException
from rclpy.parameter import Parameter

from hiros_core.errors import ConfigError
from hiros_core.parameters import build_params, dataclass_defaults, removed_parameters

T = TypeVar("T")

__all__ = [
    "CHOICES",
    "RANGES",
    "NodeParameters",
    "ParameterSpec",
    "declare_params",
    "field_descriptions",
    "parameter_specs",
]

_INT_MAX = 2**31 - 1
_QOS = ("sensor_data", "reliable")

RANGES: dict[str, tuple[float, float]] = {
    # fractions, probabilities and weights in [0, 1]
    **dict.fromkeys(
        (
            "blend",
            "confidence_floor",
            "flip_prior",
            "flip_prior_back",
            "joint_weight_decay",
            "max_ambiguity",
            "min_calibrated_fraction",
            "min_confidence",
            "min_peak",
            "position_smoothing",
        ),
        (0.0, 1.0),
    ),
    # counts of at least one
    **dict.fromkeys(
        (
            "confidence_levels",
            "id_stride",
            "min_cameras",
            "min_hits",
        ),
        (1, _INT_MAX),
    ),
    "number_of_frames_for_calibration": (3, _INT_MAX),
}
"""Range of a numeric parameter by (leaf) name; one not listed may be any value >= 0."""

CHOICES: dict[str, tuple[str, ...]] = {
    "filter": ("kalman", "butterworth", "statespace"),
    "input_qos": _QOS,
    "camera_qos": _QOS,
    "input": ("driver", "skeletons"),
    "id_scheme": ("body_major", "joint_major"),
    "world": ("floor", "camera"),
}
"""The values a string parameter may take, by (leaf) name."""

VALUE_ALIASES: dict[str, dict[str, str]] = {"filter": {"statespace": "kalman"}}
"""Hi-ROS's names of our values: Hi-ROS's ``statespace`` filter is a state-space (Kalman) one."""

SHARED_DESCRIPTIONS: dict[str, str] = {
    "input_topic": "Topic the node subscribes to (SkeletonGroup).",
    "output_topic": "Topic the node publishes its result on (SkeletonGroup).",
    "input_qos": "QoS of the input: sensor_data (best effort: hears every publisher) or reliable.",
    "camera_qos": "QoS of the camera topics: sensor_data (best effort: hears every publisher) "
    "or reliable.",
    "cameras": "Camera names: the topic namespaces (/<camera>/...).",
    "camera_topic": "Topic of each camera; {camera} is replaced by each name of cameras.",
    "calibration_file": "Calibration file (hiros calibrate's output) read at start; empty: "
    "follow the calib node's parameters.",
    "calib_node": "Fully qualified name of the calib node whose cameras.* parameters are "
    "followed live.",
}
"""Descriptions of the node-level parameters several nodes share, where a field has none."""


@dataclasses.dataclass(frozen=True)
class ParameterSpec:
    """What a client learns of one parameter (and what the node checks a change against).

    Attributes:
        name: dotted parameter name.
        default: the dataclass default (lists, never tuples).
        hint: the field's type annotation.
        description: the field's documentation, whitespace collapsed.
        limits: inclusive ``(low, high)`` of a number, None for other types.
        choices: the values a string may take (empty: any).
        read_only: not applied while the node runs.

    """

    name: str
    default: Any
    hint: Any
    description: str
    limits: tuple[float, float] | None
    choices: tuple[str, ...]
    read_only: bool

    def descriptor(self) -> ParameterDescriptor:
        """The rcl_interfaces descriptor a client reads with ``describe_parameters``."""
        descriptor = ParameterDescriptor(
            name=self.name,
            type=_parameter_type(self.hint, self.default),
            description=self.description,
            read_only=self.read_only,
        )
        constraints = []
        if self.choices:
            constraints.append("one of: " + ", ".join(self.choices))
        constraints.append(
            "fixed at start (restart the node to change it)"
            if self.read_only
            else "applied while running"
        )
        descriptor.additional_constraints = "; ".join(constraints)
        if self.limits is not None and self.hint is float:
            low, high = self.limits
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)
            ]
        elif self.limits is not None:
            low, high = self.limits
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high))]
        return descriptor

    def check(self, value: Any) -> str:
        """Why ``value`` is refused by its choices or range ('' when it is not)."""
        if self.choices and value not in self.choices:
            return f"{self.name} must be one of {', '.join(self.choices)}, not {value!r}"
        if self.limits is not None and isinstance(value, int | float):
            low, high = self.limits
            if not low <= value <= high:
                return f"{self.name} must be in [{low}, {high}], not {value}"
        return ""


def field_descriptions(params_type: type) -> dict[str, str]:
    """Each field's documentation: its ``Attributes:`` entry or the string under it.

    Bases first, so that a subclass's description of a field wins.
    """
    out: dict[str, str] = {}
    for cls in reversed(params_type.__mro__):
        if dataclasses.is_dataclass(cls):
            out.update(_attributes_section(cls.__doc__ or ""))
            out.update(_attribute_docstrings(cls))
    return out


_ENTRY = re.compile(r"^([A-Za-z_][\w]*(?:\s*,\s*[A-Za-z_][\w]*)*)\s*:\s*(.*)$")


def _attributes_section(docstring: str) -> dict[str, str]:
    """``{name: text}`` of a Google-style ``Attributes:`` section (``a, b: text`` gives both)."""
    lines = inspect.cleandoc(docstring).splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == "Attributes:")
    except StopIteration:
        return {}
    entries: dict[str, list[str]] = {}
    names: list[str] = []
    indent = None
    for line in lines[start + 1 :]:
        if not line.strip():
            continue
        depth = len(line) - len(line.lstrip())
        indent = depth if indent is None else indent
        if depth < indent:
            break
        match = _ENTRY.match(line.strip()) if depth == indent else None
        if match:
            names = [n.strip() for n in match.group(1).split(",")]
            for name in names:
                entries[name] = [match.group(2)]
        else:
            for name in names:
                entries[name].append(line.strip())
    return {name: _plain_text(" ".join(text)) for name, text in entries.items()}


def _plain_text(text: str) -> str:
    """Docstring text as a client shows it: one line, no reStructuredText literals."""
    text = re.sub(r":\w+:`~?([^`]*)`", r"\1", text)  # Sphinx roles: :meth:`name`
    return " ".join(text.replace("`", "").split())


def _attribute_docstrings(cls: type) -> dict[str, str]:
    """``{field: text}`` of the string literals that follow annotated fields in the class body."""
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError, SyntaxError):  # no source (built at run time, frozen)
        return {}
    body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
    out = {}
    for statement, following in itertools.pairwise(body):
        if (
            isinstance(statement, ast.AnnAssign)
            and isinstance(statement.target, ast.Name)
            and isinstance(following, ast.Expr)
            and isinstance(following.value, ast.Constant)
            and isinstance(following.value.value, str)
        ):
            out[statement.target.id] = _plain_text(following.value.value)
    return out


def parameter_specs(
    params_type: type, live: Collection[str] = (), prefix: str = ""
) -> list[ParameterSpec]:
    """One spec per (dotted) field of ``params_type``; ``live`` names are not read-only."""
    hints = typing.get_type_hints(params_type)
    descriptions = field_descriptions(params_type)
    defaults = dataclass_defaults(params_type)
    specs = []
    for f in dataclasses.fields(params_type):
        name = f"{prefix}{f.name}"
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            specs.extend(parameter_specs(hint, live, f"{name}."))
            continue
        default = defaults[f.name]
        specs.append(
            ParameterSpec(
                name=name,
                default=list(default) if isinstance(default, tuple) else default,
                hint=hint,
                description=descriptions.get(f.name) or SHARED_DESCRIPTIONS.get(f.name, ""),
                limits=_limits(f.name, hint),
                choices=CHOICES.get(f.name, ()),
                read_only=name not in live,
            )
        )
    return specs


def _limits(name: str, hint: Any) -> tuple[float, float] | None:
    if hint is float:
        return RANGES.get(name, (0.0, math.inf))
    if hint is int:
        return RANGES.get(name, (0, _INT_MAX))
    return None


def _parameter_type(hint: Any, default: Any) -> int:
    """The ROS parameter type of a field (from its annotation: an empty list has no type)."""
    scalar = {bool: "BOOL", int: "INTEGER", float: "DOUBLE", str: "STRING"}
    if hint in scalar:
        return getattr(ParameterType, f"PARAMETER_{scalar[hint]}")
    if typing.get_origin(hint) in (list, tuple):
        item = (typing.get_args(hint) or (str,))[0]
        return getattr(ParameterType, f"PARAMETER_{scalar.get(item, 'STRING')}_ARRAY")
    return Parameter.Type.from_parameter_value(default).value


def _plain(value: Any, name: str) -> Any:
    """A parameter value as the dataclass takes it (Hi-ROS's value names translated)."""
    if isinstance(value, str):
        return VALUE_ALIASES.get(name.rpartition(".")[2], {}).get(value, value)
    if value is not None and not isinstance(value, bool | int | float):
        return list(value)  # array.array of numeric arrays
    return value


class NodeParameters(Generic[T]):
    """A node's parameters: declared from a dataclass, checked and applied on every change.

    Args:
        node: the rclpy node.
        params_type: the node's parameters dataclass.
        live: dotted names the node applies while running (the rest are read-only).
        apply: called with the new dataclass before a change is accepted; raising
            ``ConfigError`` or ``ValueError`` refuses it with the message.
        aliases: other names (Hi-ROS's) of fields, ``{alias: field}``: an alias given on the
            command line is that field's default (the field's own value still wins).
        fixed: values that replace the command line's (e.g. a description file's).

    Attributes:
        params: the current dataclass.
        specs: name -> ParameterSpec of every declared field.

    """

    def __init__(
        self,
        node: Any,
        params_type: type[T],
        *,
        live: Collection[str] = (),
        apply: Callable[[T], None] | None = None,
        aliases: dict[str, str] | None = None,
        fixed: dict[str, Any] | None = None,
    ) -> None:
        self._node = node
        self._type = params_type
        self._apply = apply
        self.specs = {spec.name: spec for spec in parameter_specs(params_type, live)}
        unknown = set(live) - set(self.specs)
        if unknown:
            msg = f"live parameters {sorted(unknown)} are no fields of {params_type.__name__}"
            raise ConfigError(msg)
        defaults = self._alias_values(aliases or {})
        self._values = {
            spec.name: self._declare(spec, defaults.get(spec.name, spec.default), fixed or {})
            for spec in self.specs.values()
        }
        self.params: T = self._build(self._values)
        node.add_on_set_parameters_callback(self.on_set)
        self._warn_removed()

    def _warn_removed(self) -> None:
        """Log each given parameter hiros no longer has (rclpy ignores it: never declared)."""
        given = getattr(self._node, "_parameter_overrides", {})
        for name, reason in removed_parameters(given, self._node.get_name()).items():
            self._node.get_logger().warning(
                f"parameter {name} is ignored ({reason}); remove it from the parameter file"
            )

    def _alias_values(self, aliases: dict[str, str]) -> dict[str, Any]:
        """Declare each alias (unset unless given) and return the values given as defaults."""
        values = {}
        for alias, target in aliases.items():
            spec = self.specs[target]
            descriptor = ParameterDescriptor(
                description=f"Hi-ROS's name of {target}: when given, it is {target}'s default.",
                read_only=True,
            )
            kind = Parameter.Type(_parameter_type(spec.hint, spec.default))
            self._node.declare_parameter(alias, kind, descriptor)
            try:
                values[target] = _plain(self._node.get_parameter(alias).value, target)
            except ParameterUninitializedException:
                continue
        return values

    def _declare(self, spec: ParameterSpec, default: Any, fixed: dict[str, Any]) -> Any:
        """Declare one parameter (one the node declared already keeps its value)."""
        name = spec.name
        value = fixed.get(name, default)
        given = getattr(self._node, "_parameter_overrides", {})
        if value == [] and name not in fixed and name in given:
            # rclpy takes an empty list for a byte array: the given list (of strings, ...)
            # would be refused; a typed empty value takes it (rclpy has no public way to ask
            # whether a value was given, nor takes a typed value when none was)
            value = ParameterValue(type=_parameter_type(spec.hint, value))
        try:
            parameter = (
                self._node.get_parameter(name)
                if self._node.has_parameter(name)
                else self._node.declare_parameter(
                    name, value, spec.descriptor(), ignore_override=name in fixed
                )
            )
        except Exception as exc:  # rclpy's type and range errors have no common base
            msg = f"parameter {name}: {exc}"
            raise ConfigError(msg) from exc
        value = _plain(parameter.value, name)
        reason = spec.check(parameter.value)
        if reason:
            raise ConfigError(reason)
        return value

    def _build(self, values: dict[str, Any]) -> T:
        return build_params(self._type, {k: _plain(v, k) for k, v in values.items()})

    def on_set(self, parameters: Iterable[Parameter]) -> SetParametersResult:
        """Check a change of declared parameters against the specs and the dataclass, apply it.

        Names that are no field (a node's own results, such as calib's ``cameras.*``) are
        left to the node.
        """
        changes = {p.name: p.value for p in parameters if p.name in self.specs}
        if not changes:
            return SetParametersResult(successful=True)
        for name, value in changes.items():
            reason = self.specs[name].check(value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        values = {**self._values, **changes}
        try:
            params = self._build(values)
            if self._apply is not None:
                self._apply(params)
        except (ConfigError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self._values, self.params = values, params
        summary = ", ".join(f"{name} = {value!r}" for name, value in changes.items())
        self._node.get_logger().info(f"applied {summary}")
        return SetParametersResult(successful=True)


def declare_params(
    node: Any,
    params_type: type[T],
    *,
    live: Collection[str] = (),
    apply: Callable[[T], None] | None = None,
    aliases: dict[str, str] | None = None,
    fixed: dict[str, Any] | None = None,
) -> NodeParameters[T]:
    """Declare every field of ``params_type`` on ``node`` (see ``NodeParameters``)."""
    return NodeParameters(node, params_type, live=live, apply=apply, aliases=aliases, fixed=fixed)
