"""Parameters dataclasses and ROS parameter files, without ROS (used by nodes and offline).

A node's parameters are its dataclass's defaults, then whatever its command line gives
(``--ros-args -p name:=value`` or ``--params-file``, applied by rclpy): no node reads a file
unasked (``hiros_ros.params``). The files of config/ hold every node's parameters with those
defaults (a test keeps them so); ``hiros run`` reads them (``stage_config_defaults``) and the
file given with ``--params``. A file is in ROS's format, ``<node>: ros__parameters: {...}`` or
``/**: ros__parameters: {...}``. Nested dataclasses become dotted names (``gating.max_distance``).
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import typing
import warnings
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TypeVar

from hiros_core.errors import ConfigError
from hiros_core.safe_yaml import load_yaml

T = TypeVar("T")

__all__ = [
    "REMOVED_PARAMETERS",
    "RemovedParameterWarning",
    "build_params",
    "config_path",
    "dataclass_defaults",
    "load_config_defaults",
    "removed_parameters",
    "stage_config_defaults",
]

_CALIB_CONSTANTS = (
    "grid_step",
    "refine_step",
    "min_prior_significance",
    "prior_contradiction",
    "min_motion",
    "min_sharpness",
    "min_repeated_peak",
    "candidate_ratio",
    "max_candidates",
    "best_fraction",
    "consensus_tolerance",
    "loop_overrule_strength",
    "min_lag_margin",
    "inlier_sigmas",
    "frame_outlier_ratio",
    "ransac_checks",
    "joint_offset_rounds",
    "offset_shrinkage",
    "association_frames",
    "min_drift_span",
    "min_overlap",
    "max_drift",
    "max_signature_mismatch",
    "min_common_time",
    "inlier_threshold",
    "min_track_frames",
    "replace_after",
    "replace_margin",
    "max_interpolation_gap",
    "max_correspondences",
    "min_correspondences",
    "seed",
    "agree_time",
    "agree_rotation",
    "agree_translation",
    "check_length",
    "moved_ratio",
    "restart_after_backwards",
    "step_period",
)
"""Parameters of the ``calib`` node that became constants of hiros_calib (the same name in
capitals): the method's statistical and numerical choices, which no recording should need
changed."""

_MERGER_REMOVED = {
    **dict.fromkeys(
        ("fuse_directions", "direction_iterations", "direction_eps", "direction_torso"),
        "the merger no longer rebuilds limbs along the cameras' link directions (it raised the "
        "joint-angle error)",
    ),
    **dict.fromkeys(
        ("view_weight_min", "view_power"),
        "the merger weighs a camera behind a person as one in front; oblique_gain weighs side "
        "views",
    ),
    **dict.fromkeys(
        ("agreement_scale", "agreement_smoothing"),
        "the merger has no camera agreement weight (it fed back on itself)",
    ),
    "extrapolate": "the merger always extrapolates; max_extrapolation 0 turns it off",
    "limb_residuals": "the merger always weighs a camera's limb whole",
    **{
        name: f"hiros_merger fixes it as the constant {constant}"
        for name, constant in (
            ("confidence_power", "CONFIDENCE_POWER"),
            ("confidence_floor", "CONFIDENCE_FLOOR"),
            ("staleness_scale", "STALENESS_SCALE"),
            ("occlusion_weight", "OCCLUSION_WEIGHT"),
            ("iterations", "ROBUST_ITERATIONS"),
            ("outlier_cutoff", "OUTLIER_CUTOFF"),
            ("limb_cutoff", "LIMB_CUTOFF"),
            ("max_jump", "MAX_JUMP"),
            ("depth_gain", "DEPTH_GAIN"),
            ("oblique_gain", "OBLIQUE_GAIN"),
            ("flipped_weight", "FLIPPED_WEIGHT"),
            ("occlusion_radius", "OCCLUSION_RADIUS"),
            ("outlier_scale", "OUTLIER_SCALE"),
        )
    },
}

_COMPILED = "the optimizer and the filter always run their compiled kernels"

_BRIDGE_REMOVED = {
    "reset_after_backwards": "the bridges fix it as the constant RESET_AFTER_BACKWARDS "
    "(hiros_core.driver)",
}

REMOVED_PARAMETERS: dict[str, dict[str, str]] = {
    "calib": {
        **{
            name: f"hiros_calib fixes it as the constant {name.upper()}"
            for name in _CALIB_CONSTANTS
        },
        "loss_scale": "the calibration's robust loss flattens at the data's own robust scale",
        **dict.fromkeys(
            ("ransac_iterations", "frames_per_minute", "max_frames"),
            "hiros_calib fixes the frames and RANSAC samples a pose draws on (FULL_SAMPLING)",
        ),
        "loss": "hiros_calib fixes its robust loss as the constant LOSS (soft_l1)",
        "mirror_invariant": "the calibration's signature is always immune to left/right swaps",
        "frame_weights": "the calibration always weighs each frame by its residual spread",
    },
    "merger": _MERGER_REMOVED,
    "optimizer": {
        "compiled": _COMPILED,
        "sweeps": "hiros_optimizer fixes it as the constant SWEEPS",
        "refinements": "hiros_optimizer fixes it as the constant REFINEMENTS",
        **{
            name: f"hiros_optimizer fixes it as the constant {name.upper()}"
            for name in (
                "min_link_presence",
                "outlier_threshold",
                "outlier_distance",
                "prior_weight",
                "confidence_floor",
            )
        },
    },
    "filter": {
        "compiled": _COMPILED,
        "rate_tolerance": "hiros_filter fixes it as the constant RATE_TOLERANCE",
        **{
            name: f"hiros_filter fixes it as the constant {name.upper()}"
            for name in ("max_noise_scale", "max_gap", "track_timeout", "butterworth_order")
        },
        "sample_frequency": "the filter always estimates the sampling rate from the stamps",
    },
    "visualizer": {
        "label_height": "hiros_visualizer fixes it as the constant LABEL_HEIGHT (markers.py)",
        "arrow_time": "hiros_visualizer fixes it as the constant ARROW_TIME (overlays.py)",
    },
    "tracker": {
        **dict.fromkeys(
            ("velocity_weight", "orientation_weight"),
            "the tracker compares a detection with a track by joint positions only (the "
            "velocity and orientation costs were off by default and earned nothing)",
        ),
        **dict.fromkeys(
            ("flip_episode", "flip_misread"),
            "the tracker weighs each detection's facing evidence on its own (SDK flip "
            "episodes were off by default: on, they made hiros bench tracking worse)",
        ),
    },
    "azure_bridge": _BRIDGE_REMOVED,
    "generic_bridge": _BRIDGE_REMOVED,
}
"""Parameters hiros had and dropped, by node (its name): a file that still sets one loads,
with a ``RemovedParameterWarning``, so that older parameter files keep working.

By node, because nodes share names (``window``, ``max_jump``, ``track_timeout``,
``confidence_floor``, ...): one node's retired ``max_jump`` is another's parameter."""


class RemovedParameterWarning(FutureWarning):
    """A parameter file sets a parameter hiros no longer has; it is ignored.

    A ``FutureWarning``: Python shows it to whoever runs the command, whose file it is (a
    ``DeprecationWarning`` is hidden outside ``__main__``).
    """


def removed_parameters(names: Iterable[str], node: str) -> dict[str, str]:
    """The dotted ``names`` given to ``node`` that are ``REMOVED_PARAMETERS``, with why.

    ``stage.name``, where ``stage`` is a node (the pipeline's parameters of its stages), is
    ``stage``'s ``name``; any other name is the node's own.
    """
    removed = {}
    for name in names:
        section, _, rest = name.partition(".")
        owner, leaf = (section, rest) if rest and section in REMOVED_PARAMETERS else (node, name)
        reason = REMOVED_PARAMETERS.get(owner, {}).get(leaf)
        if reason is not None:
            removed[name] = reason
    return removed


def config_path(node_name: str) -> Path | None:
    """Where ``<node_name>.yaml`` lives: ``HIROS_CONFIG_DIR``, the installed share, the repo."""
    candidates = []
    if os.environ.get("HIROS_CONFIG_DIR"):
        candidates.append(Path(os.environ["HIROS_CONFIG_DIR"]))
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidates.append(Path(prefix) / "share" / "hiros" / "config")
    candidates.append(Path(sys.prefix) / "share" / "hiros" / "config")
    candidates.append(Path(__file__).resolve().parent.parent / "config")
    for directory in candidates:
        path = directory / f"{node_name}.yaml"
        if path.is_file():
            return path
    return None


def load_config_defaults(node_name: str, path: Path | None = None) -> dict[str, Any]:
    """Flat ``{dotted.name: value}`` of a node's parameter file (empty when there is none).

    A parameter hiros no longer has (``REMOVED_PARAMETERS``) is left out with a
    ``RemovedParameterWarning``.

    Raises:
        ConfigError: the file cannot be read; or ``path`` was given and holds no section
            for the node (another kind of YAML file, passed by mistake, would else be
            silently ignored).

    """
    given = path is not None
    path = path or config_path(node_name)
    if path is None:
        return {}
    document = load_yaml(path, what="parameter file", error=ConfigError) or {}
    keys = ("/**", node_name, f"/{node_name}")
    sections = [document.get(k) for k in keys] if isinstance(document, dict) else []
    if given and not any(isinstance(s, dict) and "ros__parameters" in s for s in sections):
        msg = (
            f"{path} is no ROS 2 parameter file for {node_name}: no '{node_name}: ros__parameters:'"
        )
        raise ConfigError(msg)
    values: dict[str, Any] = {}
    for section in sections:
        parameters = section.get("ros__parameters") if isinstance(section, dict) else None
        if parameters is not None and not isinstance(parameters, dict):
            msg = f"{path}: ros__parameters of {node_name} must be a mapping, not {parameters!r}"
            raise ConfigError(msg)
        values.update(_flatten(parameters or {}))
    for name, reason in removed_parameters(values, node_name).items():
        del values[name]
        warnings.warn(
            f"{path}: parameter {name} is ignored ({reason}); remove it from the file",
            RemovedParameterWarning,
            stacklevel=2,
        )
    return values


def _flatten(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{name}."))
        else:
            flat[name] = value
    return flat


def dataclass_defaults(params_type: type, prefix: str = "") -> dict[str, Any]:
    """Flat ``{dotted.name: default}`` of a (possibly nested) parameters dataclass."""
    out: dict[str, Any] = {}
    hints = typing.get_type_hints(params_type)
    for f in dataclasses.fields(params_type):
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(hints[f.name]):
            out.update(dataclass_defaults(hints[f.name], f"{name}."))
        elif f.default is not dataclasses.MISSING:
            out[name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[name] = f.default_factory()
        else:
            msg = f"parameter {name} of {params_type.__name__} has no default"
            raise ConfigError(msg)
    return out


def build_params(params_type: type[T], values: dict[str, Any], prefix: str = "") -> T:
    """Instantiate a (nested) parameters dataclass from flat dotted values."""
    hints = typing.get_type_hints(params_type)
    kwargs = {}
    for f in dataclasses.fields(params_type):
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(hints[f.name]):
            kwargs[f.name] = build_params(hints[f.name], values, f"{name}.")
        elif name in values:
            kwargs[f.name] = _coerce(values[name], hints[f.name], name)
            _check_number(kwargs[f.name], name)
    try:
        return params_type(**kwargs)
    except (TypeError, ValueError) as exc:  # the dataclass's own checks
        msg = f"{params_type.__name__}: {exc}"
        raise ConfigError(msg) from exc


def _check_number(value: Any, name: str) -> None:
    """A number parameter must be finite and not negative.

    Every stage's durations, distances, rates, weights and counts are 0 or more (none uses a
    negative sentinel: the filter's sampling rate, once one, is always estimated). A NaN would
    pass every ``<`` test as False and silently switch a check off.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return
    if not math.isfinite(value):
        msg = f"parameter {name}: {value!r} is not a finite number"
        raise ConfigError(msg)
    if value < 0:
        msg = f"parameter {name}: {value!r} is negative (it must be 0 or more)"
        raise ConfigError(msg)


def _coerce(value: Any, hint: Any, name: str) -> Any:
    origin = typing.get_origin(hint)
    try:
        if hint is float:
            return float(value)
        if hint is int:
            return int(value)
        if hint is bool:
            return bool(value)
        if hint is str:
            return str(value)
        if origin in (list, tuple):
            (item,) = typing.get_args(hint)[:1] or (str,)
            items = [_coerce(v, item, name) for v in (value or [])]
            return tuple(items) if origin is tuple else items
    except (TypeError, ValueError) as exc:
        msg = f"parameter {name}: cannot use {value!r} as {hint}"
        raise ConfigError(msg) from exc
    return value


def stage_config_defaults(
    stages: tuple[str, ...] = ("tracker", "merger", "optimizer", "filter"),
) -> dict[str, Any]:
    """Each stage node's YAML values under the stage's name (``tracker.max_delay``, ...).

    The composed pipeline and ``hiros run`` read the stage nodes' own files, so a parameter is
    tuned in one place whichever way the stages run; ``pipeline.yaml`` may override them.
    """
    return {f"{stage}.{k}": v for stage in stages for k, v in load_config_defaults(stage).items()}
