"""The tracker's track lifecycle: confirmation, duplicates, expiry and re-identification.

``TrackLifecycle`` holds the ``Tracker`` methods that decide when a tentative track becomes
a confirmed one (or is a duplicate of one), when tracks expire, and when a newly confirmed
track continues a lost one and re-takes its id (``_reidentify``, by place and body shape).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from hiros_core.accounting import Drops
from hiros_tracker import kernels
from hiros_tracker.correction import CameraCorrection
from hiros_tracker.kernel_args import MatchSettings, TrackPoses
from hiros_tracker.layout_info import _LayoutInfo
from hiros_tracker.tracks import TrackTable

if TYPE_CHECKING:
    from hiros_tracker.tracker import TrackerParams

_NS = 1e-9


class _Lost(NamedTuple):
    """A confirmed track whom every camera lost: what re-identifies the person returning.

    ``positions`` ``(J, 3)`` its pose when last seen (``last_hit_ns``), ``limbs``/``counts``
    ``(J,)`` its link lengths (``TrackTable.limbs``), ``row`` its row while it is still live
    (else -1).
    """

    track_id: int
    last_hit_ns: int
    positions: np.ndarray
    limbs: np.ndarray
    counts: np.ndarray
    row: int = -1


SHAPE_TOLERANCE = 0.1
"""Relative difference of the median link length beyond which two tracks are other people:
wider than the mean of a few noisy detections strays (a few %), narrower than what sets
people apart clearly (a child, another build)."""
MIN_SHAPE_LINKS = 4
"""Links both tracks must have measured for their shapes to be compared at all."""
BLIND_GAP_S = 1.0
"""Seconds without a frame from any camera beyond which nobody was looking: the recording or
every driver paused. Such a gap does not count towards ``reid_timeout``: a person is lost
only while the cameras could have seen them."""


def _centre(positions: np.ndarray, root: int) -> np.ndarray:
    """``(3,)`` a pose's root joint, else the mean of its known joints."""
    if np.isfinite(positions[root]).all():
        return positions[root]
    return np.nanmean(positions, axis=0)


def _same_shape(lost: _Lost, limbs: np.ndarray, counts: np.ndarray) -> bool:
    """Whether a lost track's link lengths and a new track's agree (``SHAPE_TOLERANCE``).

    The median over the links both measured of their length ratio: hands, thumbs and the
    face, noisy or unseen, cannot sway it. Too few links in common say nothing against.
    """
    both = (lost.counts > 0) & (counts > 0) & (lost.limbs > 0) & (limbs > 0)
    if both.sum() < MIN_SHAPE_LINKS:
        return True
    ratio = float(np.median(np.log(limbs[both] / lost.limbs[both])))
    return abs(ratio) <= np.log1p(SHAPE_TOLERANCE)


class TrackLifecycle:
    """The lifecycle steps of ``Tracker`` (its base; see ``tracker.py``)."""

    params: TrackerParams
    drops: Drops
    correction: CameraCorrection
    _table: TrackTable | None
    _doomed: list[int]
    _lost: list[_Lost]
    _blind: list[tuple[int, int]]  # (from, to) ns: gaps with no frame from any camera
    _last_frame_ns: int | None

    def _confirm(self, table: TrackTable, row: int, info: _LayoutInfo, time_ns: int) -> None:
        """Confirm a tentative track seen enough, unless it duplicates a confirmed one.

        A duplicate is a tentative track within ``duplicate_distance`` of a confirmed track,
        or near one (``2 * gate_distance``) and given, by every camera that saw both, the body
        id that camera gives the confirmed track: a camera's poor view of a person it already
        follows (its SDK says so), which a crowded, noisy moment pushed beyond the gate. A
        duplicate is removed at the end of the frame (``_remove_doomed``): rows stay put while
        the frame's pairs refer to them. A confirmed track may re-take the id of a lost one
        (``_reidentify``).
        """
        params = self.params
        cameras = min(params.min_cameras, max(len(self.correction.cameras), 1))
        old_enough = (time_ns - int(table.born_ns[row])) * _NS >= params.single_camera_confirm
        if int(table.seen[row].sum()) < cameras and not old_enough:
            return
        confirmed = np.flatnonzero(table.confirmed[: table.n])
        if len(confirmed):
            distance = self._distances(table, confirmed, row, info, time_ns)
            same_body = self._same_body_ids(table, confirmed, row)
            if (distance < params.duplicate_distance).any() or (
                same_body & (distance < 2.0 * params.gate_distance)
            ).any():
                self._doomed.append(row)
                self.drops.detections("duplicate of a confirmed track")
                return
        table.confirmed[row] = True
        self._reidentify(table, row, info)

    def _distances(
        self, table: TrackTable, rows: np.ndarray, row: int, info: _LayoutInfo, time_ns: int
    ) -> np.ndarray:
        """``(len(rows),)`` cost distance (m) of track ``row`` to tracks ``rows`` predicted."""
        params = self.params
        tracks = TrackPoses(table.positions[rows], table.velocity[rows], table.time_ns[rows])
        plain = MatchSettings(params.max_prediction, False, params.min_joints, 0.0)
        distance, _ = kernels.match_costs(
            tracks, table.positions[row][None], time_ns, info.weights, info.parts.arrays, plain
        )
        return distance[:, 0]

    @staticmethod
    def _same_body_ids(table: TrackTable, rows: np.ndarray, row: int) -> np.ndarray:
        """``(len(rows),)`` whether the cameras saw track ``row`` as each of ``rows``.

        True where at least one camera saw both tracks and every such camera gave both the
        same body id.
        """
        both = table.seen[rows] & table.seen[row]
        same = table.body_ids[rows] == table.body_ids[row]
        return both.any(axis=1) & ~(both & ~same).any(axis=1)

    def _reidentify(self, table: TrackTable, row: int, info: _LayoutInfo) -> None:
        """Give a newly confirmed track the id of the lost track it continues, if any.

        A person whom every camera lost (out of the shared view, hidden, or a turn the
        motion model missed) comes back as a new track. It re-takes the id of a lost track
        when that track was last seen within ``reid_timeout`` before the new one was born
        (never seen beside it; gaps in which no camera sent a frame not counted,
        ``_recently_lost``), within ``reid_distance`` of where the new one is (root joint)
        and with the same body shape (``_same_shape``); of several, the nearest. A lost track
        is a confirmed one still live but unseen since the new one was born (it is removed)
        or one that expired (``_expire`` keeps it in ``_lost``).
        """
        params = self.params
        if params.reid_timeout <= 0:
            return
        born = int(table.born_ns[row])
        here = _centre(table.positions[row], info.frame.root)
        live = [
            _Lost(int(table.ids[k]), int(table.last_hit_ns[k]), table.positions[k].copy(),
                  table.limbs[k].copy(), table.limb_count[k].copy(), k)
            for k in np.flatnonzero(table.confirmed[: table.n]).tolist()
            if k != row and table.last_hit_ns[k] < born and k not in self._doomed
        ]  # fmt: skip
        best, nearest = None, params.reid_distance
        for lost in [*live, *self._lost]:
            if not (lost.last_hit_ns < born and self._recently_lost(lost.last_hit_ns, born)):
                continue
            distance = float(np.linalg.norm(_centre(lost.positions, info.frame.root) - here))
            if distance <= nearest and _same_shape(lost, table.limbs[row], table.limb_count[row]):
                best, nearest = lost, distance
        if best is None:
            return
        table.ids[row] = best.track_id
        if best.row >= 0:
            self._doomed.append(best.row)
        else:
            self._lost.remove(best)

    def _remove_doomed(self) -> None:
        """Remove the duplicate tracks ``_confirm`` found and the tracks re-identified."""
        if self._doomed and self._table is not None:
            keep = np.ones(self._table.n, dtype=bool)
            keep[self._doomed] = False
            self._table.keep(keep)
            self._doomed.clear()

    def _expire(self, now_ns: int) -> None:
        """Remove the tracks not hit within their timeout; keep confirmed ones as lost."""
        table, params = self._table, self.params
        self._note_frame(now_ns)
        self._lost = [lost for lost in self._lost if self._recently_lost(lost.last_hit_ns, now_ns)]
        if table is None or not table.n:
            return
        count, keep = kernels.live_tracks(
            table.last_hit_ns,
            table.confirmed,
            table.n,
            now_ns,
            params.track_timeout,
            params.tentative_timeout,
        )
        if count < table.n:
            if params.reid_timeout > 0:
                gone = np.flatnonzero(~keep & table.confirmed[: table.n]).tolist()
                self._lost.extend(
                    _Lost(int(table.ids[k]), int(table.last_hit_ns[k]), table.positions[k].copy(),
                          table.limbs[k].copy(), table.limb_count[k].copy())
                    for k in gone
                )  # fmt: skip
            table.keep(keep)

    def _note_frame(self, now_ns: int) -> None:
        """Keep a gap before this frame with no frame from any camera (``BLIND_GAP_S``).

        Gaps that end before every lost track was last seen are forgotten.
        """
        last = self._last_frame_ns
        if last is not None and (now_ns - last) * _NS > BLIND_GAP_S:
            self._blind.append((last, now_ns))
        self._last_frame_ns = now_ns if last is None else max(last, now_ns)
        if not self._blind:  # the usual case: nothing to forget, every frame
            return
        oldest = min((lost.last_hit_ns for lost in self._lost), default=None)
        table = self._table
        if table is not None and table.n:
            live = int(table.last_hit_ns[: table.n].min())
            oldest = live if oldest is None else min(oldest, live)
        self._blind = [gap for gap in self._blind if oldest is not None and gap[1] > oldest]

    def _recently_lost(self, last_hit_ns: int, now_ns: int) -> bool:
        """Whether a track last seen at ``last_hit_ns`` is still within ``reid_timeout``.

        Counted up to ``now_ns``, less the gaps in which no camera sent a frame (``_blind``).
        """
        blind = sum(
            max(0, min(end, now_ns) - max(start, last_hit_ns)) for start, end in self._blind
        )
        return (now_ns - last_hit_ns - blind) * _NS <= self.params.reid_timeout
