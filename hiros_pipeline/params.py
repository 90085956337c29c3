"""The pipeline's parameters offline, loaded alike by ``hiros run``, the demo and the bench."""

from __future__ import annotations

from pathlib import Path

from hiros_core.errors import ConfigError
from hiros_core.parameters import (
    build_params,
    dataclass_defaults,
    load_config_defaults,
    stage_config_defaults,
)
from hiros_pipeline.pipeline import PipelineParams

__all__ = ["OFFLINE_MERGE_RATE", "load_pipeline_params"]

OFFLINE_MERGE_RATE = 30.0
"""The merger's output rate offline, Hz: one fused output per camera period (live: on each
camera frame)."""

_NODE_ONLY = frozenset({"cameras", "input", "camera_qos", "calibration_file", "calib_node"})
"""Parameters of the pipeline node that an offline run has no use for."""


def load_pipeline_params(
    path: Path | None = None, *, merge_rate: float | None = None
) -> PipelineParams:
    """PipelineParams from config/pipeline.yaml (or ``path``), else the stages' defaults.

    The merger outputs at ``merge_rate`` Hz (None: ``OFFLINE_MERGE_RATE``; 0: on every camera
    frame, as live).

    Raises:
        ConfigError: ``path`` names an unknown parameter, or a value is not of its kind.

    """
    values = dataclass_defaults(PipelineParams)
    values.update({k: v for k, v in stage_config_defaults().items() if k in values})
    file_values = load_config_defaults("pipeline", path)
    unknown = sorted(set(file_values) - set(values) - _NODE_ONLY)
    if path is not None and unknown:
        msg = f"{path}: unknown pipeline parameters {unknown}"
        raise ConfigError(msg)
    values.update({k: v for k, v in file_values.items() if k in values})
    try:
        params = build_params(PipelineParams, values)
    except ConfigError as exc:
        where = path or "the stages' parameter files"
        msg = f"{where}: {exc}"
        raise ConfigError(msg) from exc
    params.merger.output_rate = OFFLINE_MERGE_RATE if merge_rate is None else merge_rate
    return params
