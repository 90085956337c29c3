"""Camera-independent pose signatures (after Eichler et al., Sensors 2022, "PoseID").

The distances between every two joints of a body do not depend on where the camera stands, so
two cameras watching the same person see the same distance curves, shifted by their clock
offset. For K joints that is K(K−1)/2 channels per frame. Two changes to Eichler's PoseID:

- **Mirror invariance.** A body-tracking SDK that sees a person from behind swaps left and
  right labels, which permutes the channels (d(i, j) becomes d(m(i), m(j))) for the frames where
  it happens. Replacing each such pair of channels by their minimum and maximum gives a
  signature that is the same with or without the swap, frame by frame.
- **Reliability weights.** Each channel carries the product of its two joints' weights, so
  joints the SDK is unsure of (or did not see) contribute little or nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from hiros_calib.tracks import BodyTrack
from hiros_core.layouts import Layout

__all__ = ["DEFAULT_JOINTS", "PoseSignature", "pose_signature", "select_joints"]

DEFAULT_JOINTS: tuple[str, ...] = (
    # Azure Kinect names
    "Pelvis", "SpineNaval", "SpineChest", "Neck", "Head",
    "ShoulderLeft", "ElbowLeft", "WristLeft", "ShoulderRight", "ElbowRight", "WristRight",
    "HipLeft", "KneeLeft", "AnkleLeft", "HipRight", "KneeRight", "AnkleRight",
    # Kinect v2 names of the same body parts
    "SpineBase", "SpineMid", "SpineShoulder",
)  # fmt: skip
"""Body joints that trackers place reliably; hands, feet and face points jitter more."""


def select_joints(layout: Layout, names: tuple[str, ...] | list[str]) -> np.ndarray:
    """Indices of the named joints that the layout has, closed under the left/right mirror.

    Names the layout lacks are skipped (one list serves several layouts); an empty list
    means every joint.
    """
    wanted = set(names)
    if not wanted:
        return np.arange(layout.n_joints)
    chosen = {i for i, name in enumerate(layout.joint_names) if name in wanted}
    chosen |= {int(layout.mirror[i]) for i in chosen}
    return np.array(sorted(chosen), dtype=np.int64)


_SQUARE_SCALE = 0.5
"""Metres dividing the squared left/right difference channels back to a distance scale."""


@dataclass(frozen=True)
class _Channels:
    """Index tables turning ``(T, K, K)`` distances into signature channels."""

    first: tuple[np.ndarray, np.ndarray]  # joint index pairs of each channel's first distance
    second: tuple[np.ndarray, np.ndarray]  # and of its mirror image
    take_max: np.ndarray  # (C,) True: channel is max(first, second); False: min
    pairs: tuple[np.ndarray, np.ndarray]  # (D,) the distinct joint pairs whose distances count
    first_pair: np.ndarray  # (C,) index into ``pairs`` of each channel's first distance
    second_pair: np.ndarray  # (C,) and of its mirror image


@cache
def _channels(layout: Layout, joints: tuple[int, ...], mirror_invariant: bool) -> _Channels:
    joints_arr = np.array(joints)
    local = {j: k for k, j in enumerate(joints)}
    mirror = np.array([local[int(layout.mirror[j])] for j in joints_arr])
    i, j = np.triu_indices(len(joints), k=1)
    if not mirror_invariant:
        pair = (joints_arr[i], joints_arr[j])
        return _with_pairs(pair, pair, np.zeros(len(i), dtype=bool))
    mi, mj = np.minimum(mirror[i], mirror[j]), np.maximum(mirror[i], mirror[j])
    # each unordered orbit {c, mirror(c)} gives two channels (min and max) or one when c is
    # its own mirror image; the pair (i, j) <= (mi, mj) in lexicographic order keeps one copy
    code, mcode = i * len(joints) + j, mi * len(joints) + mj
    self_mirror = code == mcode
    lead = code < mcode
    first_i = np.concatenate([i[self_mirror], i[lead], i[lead]])
    first_j = np.concatenate([j[self_mirror], j[lead], j[lead]])
    second_i = np.concatenate([i[self_mirror], mi[lead], mi[lead]])
    second_j = np.concatenate([j[self_mirror], mj[lead], mj[lead]])
    take_max = np.concatenate(
        [np.zeros(self_mirror.sum(), bool), np.zeros(lead.sum(), bool), np.ones(lead.sum(), bool)]
    )
    return _with_pairs(
        (joints_arr[first_i], joints_arr[first_j]),
        (joints_arr[second_i], joints_arr[second_j]),
        take_max,
    )


def _with_pairs(
    first: tuple[np.ndarray, np.ndarray],
    second: tuple[np.ndarray, np.ndarray],
    take_max: np.ndarray,
) -> _Channels:
    """The tables plus the distinct joint pairs, so each distance is computed once per frame."""
    codes = np.concatenate([first[0] * 4096 + first[1], second[0] * 4096 + second[1]])
    unique, inverse = np.unique(codes, return_inverse=True)
    n = len(first[0])
    return _Channels(
        first, second, take_max, (unique // 4096, unique % 4096), inverse[:n], inverse[n:]
    )


@dataclass
class PoseSignature:
    """A track's signature: camera-clock times and ``(T, C)`` channels with weights.

    Attributes:
        track: the body track it was computed from.
        values: ``(T, C)`` distances in metres, NaN where a joint is missing.
        weights: ``(T, C)`` reliability 0..1 of each value (0 where NaN).

    """

    track: BodyTrack
    values: np.ndarray
    weights: np.ndarray

    @property
    def times(self) -> np.ndarray:
        """``(T,)`` camera-clock seconds."""
        return self.track.times

    def motion(self, smooth: float = 0.5) -> float:
        """How much the body moves (m).

        The 90th percentile over channels of the std of the signature after a
        ``smooth``-second moving average, which removes most sensor noise (a still
        person's joints jitter by about a centimetre, a moving one's by decimetres).
        """
        values = np.where(self.weights > 0, self.values, np.nan)
        if len(values) < 3:
            return 0.0
        period = float(np.median(np.diff(self.times)))
        width = max(1, round(smooth / max(period, 1e-6)))
        filled = np.where(np.isfinite(values), values, 0.0)
        counts = np.isfinite(values).astype(float)
        sums = _moving_sum(filled, width)
        norm = _moving_sum(counts, width)
        with np.errstate(invalid="ignore", divide="ignore"):
            smoothed = np.where(norm > width / 2, sums / norm, np.nan)
        finite = np.isfinite(smoothed).sum(axis=0) > 1
        spread = np.nanstd(smoothed[:, finite], axis=0)
        spread = spread[np.isfinite(spread)]
        return float(np.percentile(spread, 90)) if spread.size else 0.0


def _moving_sum(values: np.ndarray, width: int) -> np.ndarray:
    """Sums of ``width`` consecutive rows (``valid`` mode), all columns at once."""
    total = np.cumsum(np.vstack([np.zeros((1, values.shape[1])), values]), axis=0)
    return total[width:] - total[:-width]


def pose_signature(
    track: BodyTrack, joints: np.ndarray, *, mirror_invariant: bool = True
) -> PoseSignature:
    """The inter-joint distance signature of a track over the given joints."""
    tables = _channels(track.layout, tuple(int(j) for j in joints), mirror_invariant)
    pos, w = track.positions, track.weights
    # each distinct joint pair's distance and weight once, then gathered into the channels
    delta = pos[:, tables.pairs[0]] - pos[:, tables.pairs[1]]
    distance = np.sqrt(np.einsum("tdk,tdk->td", delta, delta))
    pair_weight = w[:, tables.pairs[0]] * w[:, tables.pairs[1]]
    d1, d2 = distance[:, tables.first_pair], distance[:, tables.second_pair]
    values = np.where(tables.take_max, (d1 - d2) ** 2 / _SQUARE_SCALE, 0.5 * (d1 + d2))
    weights = np.minimum(pair_weight[:, tables.first_pair], pair_weight[:, tables.second_pair])
    weights = np.where(np.isfinite(values), weights, 0.0)
    return PoseSignature(track, values, weights)
