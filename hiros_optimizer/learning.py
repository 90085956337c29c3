"""Learning a person's limb lengths link by link, and what a person's learning has reached.

A link's length is *learnt* once it is measured in at least ``MIN_LINK_PRESENCE`` of the last
``N`` frames and its robust coefficient of variation (``1.4826 MAD / median``) over them is
below ``max_calibration_coefficient_of_variation`` (Hi-ROS's acceptance rule, per link and with
robust statistics so that a few bad frames do not spoil it). Each link locks on its own: a noisy
hand or an unseen thumb keeps only itself free, never a thigh. A limb link not learnt while its
mirror on the other side is takes that one's length for now (*borrowed*), until its own is
learnt. A person is *accepted* once the links of their limbs (upper arms, forearms, thighs,
shanks: what joint angles are made of) are learnt or borrowed; how long that took from the
person's first frame is their acceptance time, and a person not accepted within
``acceptance_timeout`` is reported with the reason of each limb link still free. Once a person
is accepted, every link measured often enough is locked too, steady or not: a steady body
vouches for the measurement, and a noisy link's median over the window is still a good length
(its standard error shrinks with the window; constraining it steadies the joint angles next to
it). Links seen too rarely stay free.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from hiros_core.layouts import Layout

__all__ = ["LIMB_JOINTS", "PersonProgress", "WindowStatistics", "limb_links", "window_statistics"]

_MAD_TO_SD = 1.4826  # MAD of a normal distribution times this is its standard deviation

LIMB_JOINTS = (
    "ElbowLeft",
    "WristLeft",
    "ElbowRight",
    "WristRight",
    "KneeLeft",
    "AnkleLeft",
    "KneeRight",
    "AnkleRight",
)
"""Child joints of the limb links a person's acceptance waits for (upper arm, forearm, thigh,
shank on each side; Azure Kinect and Kinect v2 names)."""


@lru_cache(maxsize=8)
def limb_links(layout: Layout) -> np.ndarray:
    """Link ids (child joints) of ``layout``'s limbs; every link where it names none of them."""
    names = {name: i for i, name in enumerate(layout.joint_names)}
    found = [names[n] for n in LIMB_JOINTS if n in names and layout.parents[names[n]] >= 0]
    return np.array(found, dtype=np.intp) if found else layout.link_children.astype(np.intp)


class WindowStatistics(NamedTuple):
    """Per-link statistics of learning windows, each ``(R, J)`` by link id.

    Attributes:
        presence: share of the window's frames the link was measured in.
        median: median length (m), NaN where never measured.
        variation: robust coefficient of variation, NaN where the link is not seen enough.
        learnt: whether the link's length is learnt (see the module docstring).
        lengths: the median lengths, unbiased (m), of the links seen often enough (NaN
            elsewhere); only the ``learnt`` ones lock before the person is accepted.

    """

    presence: np.ndarray
    median: np.ndarray
    variation: np.ndarray
    learnt: np.ndarray
    lengths: np.ndarray


def window_statistics(
    windows: np.ndarray, min_presence: float, max_variation: float
) -> WindowStatistics:
    """Statistics of ``(R, J, N)`` windows of measured link lengths (NaN: not measured)."""
    size = windows.shape[2]
    count = size - np.isnan(windows).sum(axis=2)  # (R, J) frames each link was measured in
    presence = count / size
    seen = presence >= min_presence
    median = _nanmedian_last(windows, count)
    with np.errstate(invalid="ignore", divide="ignore"):
        mad = _nanmedian_last(np.abs(windows - median[..., None]), count)
        variation = np.where(seen, _MAD_TO_SD * mad / median, np.nan)
        learnt = seen & (median > 0) & (variation < max_variation)
    # Noise perpendicular to a link lengthens it on average: |d + n|^2 = L^2 + 3 s^2 with
    # s the per-axis noise of d, of which the radial part shows as the spread s of the
    # lengths; the two perpendicular axes add 2 s^2, which is removed here.
    spread = variation * median
    unbiased = np.sqrt(np.maximum(median**2 - 2 * spread**2, 0.25 * median**2))
    return WindowStatistics(
        presence, median, variation, learnt, np.where(seen & (median > 0), unbiased, np.nan)
    )


@dataclass
class PersonProgress:
    """How far one track's limb lengths are learnt.

    Attributes:
        first_ns: stamp of the track's first frame.
        last_ns: stamp of its latest frame.
        accepted_ns: stamp at which its limb links were all learnt (None: not yet).
        overdue: the track went ``acceptance_timeout`` without acceptance (reported once).
        free: ``(J,)`` links not learnt yet, by link id (None: no full window yet).
        presence: ``(J,)`` share of the last full window each link was measured in.
        variation: ``(J,)`` robust CV of each link over that window.
        borrowed: ``(J,)`` limb links whose length is the other side's for now.

    """

    first_ns: int
    last_ns: int = 0
    accepted_ns: int | None = None
    overdue: bool = False
    free: np.ndarray | None = None
    presence: np.ndarray | None = None
    variation: np.ndarray | None = None
    borrowed: np.ndarray | None = None

    @property
    def acceptance_time(self) -> float | None:
        """Seconds from the first frame to acceptance (None: not accepted)."""
        if self.accepted_ns is None:
            return None
        return (self.accepted_ns - self.first_ns) * 1e-9

    @property
    def seen_for(self) -> float:
        """Seconds from the first frame to the latest."""
        return (max(self.last_ns, self.first_ns) - self.first_ns) * 1e-9

    def observe(
        self,
        statistics: WindowStatistics,
        row: int,
        free: np.ndarray,
        borrowed: np.ndarray | None = None,
    ) -> None:
        """Keep window ``row``'s figures, the ``(J,)`` links still ``free`` and ``borrowed``."""
        self.free = free
        self.borrowed = borrowed
        self.presence = statistics.presence[row]
        self.variation = statistics.variation[row]

    def free_links(self, layout: Layout, max_variation: float) -> dict[str, str]:
        """Link name -> why its length is not learnt (empty before the first full window)."""
        if self.free is None or self.presence is None or self.variation is None:
            return {}
        reasons = {}
        for link in np.flatnonzero(self.free):  # (a report: a few links, not a hot path)
            variation = self.variation[link]
            if np.isfinite(variation) and variation >= max_variation:
                why = f"unsteady (CV {variation * 100:.0f} %)"
            else:
                why = f"seen in {self.presence[link] * 100:.0f} % of frames"
            reasons[layout.link_names[link]] = why
        return reasons

    def summary(self, layout: Layout, max_variation: float) -> str:
        """One sentence: the acceptance time, or which limb links keep the person from it.

        Free links off the limbs are listed after it: they follow the measurement.
        """
        limbs = {layout.link_names[link] for link in limb_links(layout)}
        free = self.free_links(layout, max_variation)
        others = sorted(name for name in free if name not in limbs)
        if self.accepted_ns is not None:
            text = f"accepted after {self.acceptance_time:.1f} s"
        elif self.free is None:
            text = f"not accepted after {self.seen_for:.1f} s: too few frames yet"
        else:
            blocking = "; ".join(f"{n} {why}" for n, why in sorted(free.items()) if n in limbs)
            text = f"not accepted after {self.seen_for:.1f} s: {blocking}"
        if others:
            text += f" (free: {', '.join(others)})"
        if self.borrowed is not None and self.borrowed.any():
            names = ", ".join(sorted(layout.link_names[i] for i in np.flatnonzero(self.borrowed)))
            text += f" (the other side's length for now: {names})"
        return text


def _nanmedian_last(values: np.ndarray, count: np.ndarray) -> np.ndarray:
    """``np.nanmedian(values, axis=-1)`` of ``(R, J, N)`` with ``count`` non-NaN values each.

    One sort (NaN sorts last) and two gathers give the same numbers as numpy's (mean of the two
    middle values for an even count, NaN where nothing was measured) at a fraction of the
    cost: numpy's small-array path goes through masked arrays, which made the calibration
    check the stage's most expensive step.
    """
    size = values.shape[-1]
    ordered = np.sort(values, axis=-1).reshape(-1)
    base = np.arange(count.size).reshape(count.shape) * size
    low = ordered[base + np.maximum(count - 1, 0) // 2]
    high = ordered[base + count // 2]
    return np.where(count > 0, (low + high) / 2, np.nan)
