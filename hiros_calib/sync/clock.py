"""What the time-offset estimation finds: a camera pair's lag and a camera's clock.

Sign convention: a pair's lag ``tau = t_a - t_b`` for the same event, so the signature of
camera b shifted by ``tau`` matches camera a; with the DESIGN.md clock model
``t_ref = t_cam + time_offset + drift (t_cam - drift_epoch)`` this means
``time_offset_b - time_offset_a = tau`` when there is no drift.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["CameraClock", "PairOffset", "Settle", "fisher_significance", "fisher_z", "refused_pair"]


@dataclass
class PairOffset:
    """The clock lag of camera b relative to camera a, or why there is none.

    Attributes:
        camera_a, camera_b: the two cameras.
        status: ``"ok"`` or ``"refused"``.
        reason: why it was refused (empty when ok).
        offset: ``tau = t_a - t_b`` (s) for the same event, over the whole overlap.
        windows: ``(W, 4)`` per window: centre time on b's clock, tau, weight, correlation.
        quality: peak correlation, sharpness, ambiguity, body pairs used/considered, ...
        lags: ``(L,)`` lags (s) of the pooled correlation curve (for plots).
        correlation: ``(L,)`` pooled correlation at those lags.
        body_pairs: ``(track_a, track_b)`` indices of the body pairs in the consensus.
        candidates: ``(K, 2)`` lags (s) the motion supports and their pooled correlation,
            best first; the first is ``offset``'s lobe. Other rows are lags one repetition
            away, or side lobes, for the poses to rule out.
        rivals: ``(R, 2)`` lags (s) other clear body pairs support about as strongly as
            the consensus, outside the pooled curve's candidates, and their pooled
            correlation: the poses check that none fits as well as the chosen lag.

    """

    camera_a: str
    camera_b: str
    status: str = "refused"
    reason: str = ""
    offset: float = math.nan
    windows: np.ndarray = field(default_factory=lambda: np.empty((0, 4)))
    quality: dict[str, Any] = field(default_factory=dict)
    lags: np.ndarray = field(default_factory=lambda: np.empty(0))
    correlation: np.ndarray = field(default_factory=lambda: np.empty(0))
    body_pairs: list[tuple[int, int]] = field(default_factory=list)
    candidates: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    rivals: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))

    @property
    def ok(self) -> bool:
        """True when the offset was determined."""
        return self.status == "ok"


@dataclass
class CameraClock:
    """One camera's clock relative to the reference (DESIGN.md model), or why it is unknown."""

    camera: str
    status: str = "refused"
    reason: str = ""
    time_offset: float = math.nan
    drift: float = 0.0
    drift_epoch: float = 0.0
    quality: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when the clock is determined."""
        return self.status == "ok"

    def to_reference(self, t_camera: np.ndarray | float) -> np.ndarray | float:
        """Camera-clock seconds to reference seconds."""
        return t_camera + self.time_offset + self.drift * (t_camera - self.drift_epoch)

    def from_reference(self, t_reference: np.ndarray | float) -> np.ndarray | float:
        """Reference seconds to camera-clock seconds (inverse of :meth:`to_reference`)."""
        return (t_reference - self.time_offset + self.drift * self.drift_epoch) / (1 + self.drift)


Settle = Callable[[PairOffset, Callable[[float], PairOffset]], PairOffset]
"""A check of one pair's lag before the global solve: ``settle(pair, repin) -> pair``."""


def fisher_z(correlation: Any, limit: float = 0.999) -> Any:
    """Fisher's z (``arctanh``) of a correlation clipped to ``±limit``, per element.

    The clip keeps a perfect correlation finite; a lower ``limit`` caps how much any one
    near-perfect measurement can count.
    """
    return np.arctanh(np.clip(correlation, -limit, limit))


def fisher_significance(correlation: Any, overlap: Any) -> Any:
    """Fisher z of a correlation times the square root of its overlap (s), per element.

    A high correlation over a few seconds of overlap is more often chance than a slightly
    lower one over the whole recording; this weighs the two alike.
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        return fisher_z(correlation) * np.sqrt(overlap)


def refused_pair(a: str, b: str, reason: str, **quality: Any) -> PairOffset:
    """A pair refused for ``reason``, with the figures that show it in its quality."""
    return PairOffset(a, b, status="refused", reason=reason, quality=quality)
