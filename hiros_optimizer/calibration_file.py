"""Person calibrations on disk: the YAML file that lets a known person keep their lengths.

The algorithm (:class:`hiros_optimizer.Optimizer`) only exchanges plain dicts; this module is
the one place that reads and writes them as YAML::

    people:
      0:
        layout: azure_kinect
        n_frames: 60
        links:
          Pelvis-SpineNaval: {length: 0.1912, cv: 0.011}
          ...
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from hiros_core.errors import ConfigError

__all__ = ["read_person_calibrations", "write_person_calibrations"]


def write_person_calibrations(path: str | Path, data: dict[str, Any]) -> None:
    """Write :meth:`Optimizer.export_calibrations` output to ``path`` (parents created)."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(yaml.safe_dump(data, sort_keys=False))
    except OSError as exc:
        msg = f"cannot write person calibrations to {path}: {exc.strerror}"
        raise ConfigError(msg) from exc


def read_person_calibrations(path: str | Path) -> dict[str, Any]:
    """Read a file written by :func:`write_person_calibrations`, for ``load_calibrations``."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        msg = f"cannot read person calibrations from {path}: {exc.strerror}"
        raise ConfigError(msg) from exc
    except yaml.YAMLError as exc:
        msg = f"person calibration file {path} is not valid YAML: {exc}"
        raise ConfigError(msg) from exc
    if not isinstance(data, dict):
        msg = f"person calibration file {path} must be a mapping with 'people'"
        raise ConfigError(msg)
    return data
