"""The calibration file (DESIGN.md): each camera's clock offset and pose in the world frame.

One loader and one writer, used by ``hiros calibrate``, the ``calib`` node and every stage::

    reference: k01
    world_frame: world
    cameras:
      k01:
        frame_id: k01_depth_camera_link
        time_offset: 0.0   # t_reference = t_camera + time_offset + drift * (t_camera - drift_epoch)
        drift: 0.0
        drift_epoch: 0.0
        translation: [0, 0, 0]          # p_world = R p_camera + t
        rotation: [0, 0, 0, 1]          # x, y, z, w
        quality: {}
        flagged: ""     # empty when trusted; otherwise why the result is doubtful
"""

from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hiros_core.errors import CalibrationError
from hiros_core.geometry import RigidTransform
from hiros_core.safe_yaml import load_yaml

__all__ = ["Calibration", "CameraCalibration", "load_calibration", "save_calibration"]

_MAX_CLOCK_SECONDS = 4e9
"""Largest |time_offset| and |drift_epoch| accepted, s (year 2096): beyond it, stamps in int64
nanoseconds overflow once the offset is applied."""
_MAX_DRIFT = 0.1
"""Largest |drift| accepted (a clock 10 % fast or slow; real ones are within 1e-4)."""
_MAX_TRANSLATION_M = 1000.0
"""Largest |translation| component accepted, metres: depth cameras see a few metres, so a
camera a kilometre from the reference is a broken file (1e30 made every detection vanish)."""


@dataclass
class CameraCalibration:
    """One camera's clock and pose relative to the reference."""

    frame_id: str
    time_offset: float = 0.0
    drift: float = 0.0
    drift_epoch: float = 0.0
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    quality: dict[str, Any] = field(default_factory=dict)
    flagged: str = ""
    """Empty when the calibration trusts this camera; otherwise why its result is doubtful.
    A flagged camera is never used silently: stages refuse it unless told to accept it."""

    @property
    def extrinsics(self) -> RigidTransform:
        """Camera frame -> world frame."""
        return RigidTransform.from_quaternion(self.rotation, self.translation)

    def to_reference_time(self, t_camera: float | np.ndarray) -> float | np.ndarray:
        """Camera-clock seconds to reference-clock seconds (DESIGN.md formula)."""
        return t_camera + self.time_offset + self.drift * (t_camera - self.drift_epoch)

    def to_reference_ns(self, t_camera_ns: int) -> int:
        """Camera-clock nanoseconds to reference-clock nanoseconds, exact when drift is 0."""
        offset = self.time_offset + self.drift * (t_camera_ns * 1e-9 - self.drift_epoch)
        return t_camera_ns + round(offset * 1e9)


@dataclass
class Calibration:
    """All cameras of a setup. ``cameras`` is keyed by camera name (topic namespace)."""

    reference: str
    world_frame: str = "world"
    cameras: dict[str, CameraCalibration] = field(default_factory=dict)

    def camera(self, name: str) -> CameraCalibration:
        """One camera's calibration; raises CalibrationError when the camera is unknown."""
        try:
            return self.cameras[name]
        except KeyError:
            msg = f"camera {name!r} is not in the calibration (known: {sorted(self.cameras)})"
            raise CalibrationError(msg) from None

    @property
    def flagged(self) -> dict[str, str]:
        """Per flagged camera, why its result is doubtful (empty when all are trusted)."""
        return {name: cam.flagged for name, cam in self.cameras.items() if cam.flagged}

    def to_dict(self) -> dict[str, Any]:
        """Plain data in the file's layout (lists, floats, strings)."""
        return {
            "reference": self.reference,
            "world_frame": self.world_frame,
            "cameras": {
                name: {
                    "frame_id": cam.frame_id,
                    "time_offset": float(cam.time_offset),
                    "drift": float(cam.drift),
                    "drift_epoch": float(cam.drift_epoch),
                    "translation": [float(v) for v in cam.translation],
                    "rotation": [float(v) for v in cam.rotation],
                    "quality": _plain(cam.quality),
                    "flagged": cam.flagged,
                }
                for name, cam in self.cameras.items()
            },
        }

    @classmethod
    def from_dict(cls, data: Any, source: str = "calibration") -> Calibration:
        """Parse and check the file's layout; errors name the source and the field."""
        if not isinstance(data, dict) or not isinstance(data.get("cameras"), dict):
            msg = f"{source}: expected a mapping with a 'cameras' mapping"
            raise CalibrationError(msg)
        cameras = {
            str(name): _camera_from_dict(entry, f"{source}: camera {name}")
            for name, entry in data["cameras"].items()
        }
        _check_frame_ids(cameras, source)
        reference = str(data.get("reference", next(iter(cameras), "")))
        if cameras and reference not in cameras:
            msg = f"{source}: reference camera {reference!r} is not among the cameras"
            raise CalibrationError(msg)
        return cls(reference, str(data.get("world_frame", "world")), cameras)


def _check_frame_ids(cameras: dict[str, CameraCalibration], source: str) -> None:
    """Refuse two cameras with one ``frame_id``: their detections would be merged as one's."""
    owners: dict[str, str] = {}
    for name, cam in cameras.items():
        if cam.frame_id and cam.frame_id in owners:
            msg = (
                f"{source}: cameras {owners[cam.frame_id]} and {name} have the same frame_id "
                f"{cam.frame_id!r}; each camera needs its own"
            )
            raise CalibrationError(msg)
        owners.setdefault(cam.frame_id, name)


def _camera_from_dict(entry: Any, where: str) -> CameraCalibration:
    if not isinstance(entry, dict):
        msg = f"{where}: expected a mapping"
        raise CalibrationError(msg)
    try:
        translation = np.asarray(entry.get("translation", [0.0, 0.0, 0.0]), dtype=float)
        rotation = np.asarray(entry.get("rotation", [0.0, 0.0, 0.0, 1.0]), dtype=float)
        scalars = {k: float(entry.get(k, 0.0)) for k in ("time_offset", "drift", "drift_epoch")}
    except (TypeError, ValueError) as exc:
        msg = f"{where}: {exc}"
        raise CalibrationError(msg) from exc
    if translation.shape != (3,) or rotation.shape != (4,):
        msg = f"{where}: translation needs 3 numbers and rotation 4 (x, y, z, w)"
        raise CalibrationError(msg)
    norm = float(np.linalg.norm(rotation))
    if not math.isfinite(norm) or abs(norm - 1.0) > 1e-3:
        msg = f"{where}: rotation {rotation.tolist()} is not a unit quaternion"
        raise CalibrationError(msg)
    _check_ranges(translation, scalars, where)
    quality = entry.get("quality") or {}
    if not isinstance(quality, dict):
        msg = f"{where}: quality must be a mapping, not {quality!r}"
        raise CalibrationError(msg)
    return CameraCalibration(
        frame_id=str(entry.get("frame_id", "")),
        translation=translation,
        rotation=rotation / norm,
        quality=dict(quality),
        flagged=str(entry.get("flagged") or ""),
        **scalars,
    )


def _check_ranges(translation: np.ndarray, scalars: dict[str, float], where: str) -> None:
    """Reject values every stage would turn into NaN poses or overflowing stamps."""
    if not (np.abs(translation) < _MAX_TRANSLATION_M).all():  # also NaN and inf
        msg = (
            f"{where}: translation {translation.tolist()} is out of range (finite, each "
            f"|value| < {_MAX_TRANSLATION_M:g} m)"
        )
        raise CalibrationError(msg)
    limits = {"time_offset": _MAX_CLOCK_SECONDS, "drift_epoch": _MAX_CLOCK_SECONDS}
    for key, value in scalars.items():
        limit = limits.get(key, _MAX_DRIFT)
        if not abs(value) < limit:  # also NaN
            msg = f"{where}: {key} {value} is out of range (|{key}| < {limit:g})"
            raise CalibrationError(msg)


def _plain(value: Any) -> Any:
    """Numpy scalars and arrays to YAML-safe Python values."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def load_calibration(path: str | Path) -> Calibration:
    """Read a calibration file; raises CalibrationError naming the file on any problem.

    The YAML is read within ``hiros_core.safe_yaml``'s limits (size, nesting, aliases).
    """
    path = Path(path)
    data = load_yaml(path, what="calibration file", error=CalibrationError)
    return Calibration.from_dict(data, str(path))


def save_calibration(calibration: Calibration, path: str | Path) -> None:
    """Write a calibration file (parent folders are created), whole or not at all.

    It is written beside the target under a hidden name and renamed over it, so that the
    ``calib`` node saving while a stage reads, or a full disk, never leaves half a file.

    Raises:
        CalibrationError: the file cannot be written (a folder there, no permission).

    """
    path = Path(path)
    text = yaml.safe_dump(calibration.to_dict(), sort_keys=False)
    partial = path.with_name(f".{path.name}.partial-{os.getpid()}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial.write_text(text)
        partial.replace(path)  # the file is whole or not there: a reader never sees half
    except OSError as exc:
        msg = f"cannot write calibration file {path}: {exc}"
        raise CalibrationError(msg) from exc
    finally:
        with contextlib.suppress(OSError):  # renamed, or its folder cannot hold it
            partial.unlink(missing_ok=True)
