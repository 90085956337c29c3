"""CDR field conversions both codecs share: stamps, strings, checked integers, row stacks."""

from __future__ import annotations

import numpy as np

from hiros_core.errors import CodecError

NS = 1_000_000_000
TIME_DTYPE = np.dtype([("sec", "<i4"), ("nanosec", "<u4")])


def split_ns(stamps_ns: np.ndarray, what: str) -> np.ndarray:
    """Integer nanoseconds to (sec, nanosec) records; refuses stamps outside int32 seconds."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    sec, nanosec = np.divmod(stamps, NS)
    if sec.size and (sec.min() < -(2**31) or sec.max() >= 2**31):
        msg = f"{what}: a stamp is outside the int32 seconds range of builtin_interfaces/Time"
        raise CodecError(msg)
    out = np.empty(stamps.shape, dtype=TIME_DTYPE)
    out["sec"], out["nanosec"] = sec, nanosec
    return out


def c_string(text: str) -> str:
    """What a string becomes in CDR: rclpy ends it at the first NUL."""
    return text.split("\x00", 1)[0]


def join_ns(times: np.ndarray) -> np.ndarray:
    """Integer nanoseconds of (sec, nanosec) records."""
    return times["sec"].astype(np.int64) * NS + times["nanosec"].astype(np.int64)


def checked_ints(values: list[int], dtype: str, what: str) -> np.ndarray:
    """``values`` as ``dtype``; CodecError naming ``what`` when one is out of its range."""
    info = np.iinfo(dtype)
    if values and (min(values) < info.min or max(values) > info.max):
        msg = f"{what}: value out of range for {np.dtype(dtype).name}"
        raise CodecError(msg)
    return np.asarray(values, dtype=dtype)


def stacked_rows(arrays: list[np.ndarray], width: int) -> np.ndarray:
    """The arrays' rows stacked, ``(0, width)`` when there are none."""
    return np.concatenate(arrays) if arrays else np.empty((0, width))
