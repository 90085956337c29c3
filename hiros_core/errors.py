"""Error types of hiros: callers catch these, not ``Exception``.

Each is raised with one sentence a user can act on (which file, which field, what is wrong).
"""

from __future__ import annotations


class HirosError(Exception):
    """Base class of every error hiros raises on purpose."""


class LayoutError(HirosError):
    """A skeleton layout is unknown or its YAML description is inconsistent."""


class CodecError(HirosError):
    """Bytes cannot be decoded as the expected message (truncated, corrupt, wrong type)."""


class RecordingError(HirosError):
    """A recording cannot be read or written (missing, truncated, unknown topic type)."""


class CalibrationError(HirosError):
    """A calibration file is invalid, or the data cannot determine a calibration."""


class ConfigError(HirosError):
    """A parameter file or parameter value is invalid."""


class OutputError(HirosError):
    """An output path would destroy an input or a file the command did not make."""
