"""The tracker's per-frame association and update: costs, cascade, pairs, hits, labelling.

``FrameMatching`` holds the ``Tracker`` methods that take one released frame's detections
through the compiled kernels: the cost matrix and its cascade (``_match``), each detection's
track (``_pairs``), the tracks' update and facing check (``_hit``) and the output labelling
(``_labelled``). Shapes: ``T`` tracks, ``D`` detections, ``J`` joints, ``K`` mirror parts.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from hiros_core.accounting import Drops
from hiros_core.model import Skeleton
from hiros_tracker import kernels
from hiros_tracker.kernel_args import (
    FacingPriors,
    FacingView,
    FrameRows,
    GateFrame,
    GateSettings,
    GateTracks,
    HitSettings,
    MatchSettings,
    StackedRows,
    TrackPoses,
    UpdateSettings,
)
from hiros_tracker.layout_info import _LayoutInfo, _MirrorParts
from hiros_tracker.tracks import TrackTable

if TYPE_CHECKING:
    from hiros_tracker.tracker import TrackerParams

_NO_CAMERA = np.zeros(3)
"""Placeholder camera position for the facing kernel when the camera's pose is unknown."""


class _Detections(NamedTuple):
    """A frame's detections the tracker can use (``Tracker._valid_detections``).

    ``positions`` ``(D, J, 3)`` (NaN where absent or below ``min_confidence``), ``kept``
    ``(D,)`` how many finite joints each keeps, ``index`` ``(D,)`` their rows in ``rows``
    (markers, presence, links, link presence): the frame's stack when ``stacked``, else
    new arrays of the markers and presence (twice), which labelling must not write to.
    """

    skeletons: list[Skeleton]
    positions: np.ndarray
    kept: np.ndarray
    index: np.ndarray
    rows: StackedRows
    stacked: bool


class FrameMatching:
    """The association and update steps of ``Tracker`` (its base; see ``tracker.py``)."""

    params: TrackerParams
    drops: Drops
    _table: TrackTable | None
    _next_id: int
    _up: np.ndarray

    def _match(  # noqa: PLR0917
        self,
        table: TrackTable,
        positions: np.ndarray,
        det_ids: np.ndarray,
        stamp: int,
        camera: int,
        info: _LayoutInfo,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Assign detections to tracks in a cascade (DeepSORT-like), each level optimally.

        Levels: confirmed tracks seen within ``recent_window``, other confirmed tracks,
        tentative tracks (``kernels.gate_costs``): a track that has just lost its person (who
        left, or whom every camera lost) must not take a detection that a live track explains.

        Returns:
            the solver's pairs, ``(N,)`` track rows and ``(N,)`` detections (those not
            ``(T, D)`` feasible left to ``kernels.frame_pairs``), the feasible pairs and
            ``(T, D, K)`` the mirrored parts of every pair.

        """
        cost, flips, feasible, levels = self._costs(table, positions, det_ids, stamp, camera,
                                                    info)  # fmt: skip
        n_tracks, n_det = cost.shape
        track_levels = levels.tolist()
        if n_tracks and min(track_levels) == max(track_levels):  # one level (usual): one solve
            r, c = linear_sum_assignment(cost)
            return r, c, feasible, flips
        matched = [-1] * n_det
        free = list(range(n_det))
        for level in range(3):
            rows = [t for t, at in enumerate(track_levels) if at == level]
            if not rows or not free:
                continue
            whole = len(rows) == n_tracks and len(free) == n_det
            allowed = feasible if whole else feasible[rows][:, free]
            r, c = linear_sum_assignment(cost if whole else cost[rows][:, free])
            for i, j in zip(r.tolist(), c.tolist(), strict=True):
                if allowed[i, j]:
                    matched[free[j]] = rows[i]
            free = [d for d in free if matched[d] < 0]
        dets = [d for d, row in enumerate(matched) if row >= 0]
        r = np.array([matched[d] for d in dets], dtype=np.int64)
        return r, np.array(dets, dtype=np.int64), feasible, flips

    def _costs(  # noqa: PLR0917
        self,
        table: TrackTable,
        positions: np.ndarray,
        det_ids: np.ndarray,
        stamp: int,
        camera: int,
        info: _LayoutInfo,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every (track, detection) pair's cost, flips, feasibility and the tracks' levels.

        Each pair's cost is independent of the others, so the whole matrix is computed once
        per frame and each cascade level takes its rows.
        """
        params = self.params
        parts = info.parts.arrays
        n = table.n
        tracks = TrackPoses(table.positions[:n], table.velocity[:n], table.time_ns[:n])
        match = MatchSettings(
            params.max_prediction, params.mirror_check, params.min_joints, params.mirror_margin
        )
        gate_tracks = GateTracks(table.last_hit_ns, table.confirmed, table.body_ids, table.seen)
        frame = GateFrame(det_ids, camera, stamp, stamp - round(params.recent_window * 1e9))
        gate = GateSettings(params.body_id_bonus, params.gate_distance, params.gate_growth)
        return kernels.frame_costs(
            tracks, positions, info.weights, parts, match, gate_tracks, frame, gate
        )

    def _pairs(  # noqa: PLR0917
        self,
        table: TrackTable,
        r: np.ndarray,
        c: np.ndarray,
        feasible: np.ndarray,
        flips: np.ndarray,
        found: _Detections,
        stamp: int,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each detection's track: its match, else a new tentative track if it has the joints.

        Returns ``(U,)`` track rows, ``(U,)`` their detections (in detection order, so new
        tracks are made in that order) and ``(U, K)`` the parts to relabel in each.
        """
        rows, dets, pair_flips, new, dropped = kernels.frame_pairs(
            r, c, feasible, flips, found.kept, self.params.min_joints
        )
        if dropped:
            self.drops.detections("too few joints", dropped)
        if new:
            for u in np.flatnonzero(rows < 0).tolist():
                rows[u] = table.add(self._next_id, found.positions[dets[u]], stamp)
                self._next_id += 1
        return rows, dets, pair_flips

    # -------------------------------------------------------------------------------- updates
    def _hit(  # noqa: PLR0917 - one frame's matched pairs, all positional for brevity
        self,
        table: TrackTable,
        found: _Detections,
        det_ids: np.ndarray,
        pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
        info: _LayoutInfo,
        time_ns: int,
        camera: int,
        camera_position: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """Fold one frame's detections into the tracks (``kernels.hit_frame``), confirm them.

        Args:
            table: the tracks.
            found: the frame's detections.
            det_ids: ``(D,)`` the camera's body ids of the detections.
            pairs: ``(U,)`` the rows of the tracks hit (distinct), ``(U,)`` their detections
                and ``(U, K)`` the parts to relabel in each (``_pairs``).
            info: the layout's mirror parts, weights and body frame.
            time_ns: the frame's corrected stamp.
            camera: the frame's camera code.
            camera_position: ``(3,)`` the camera's position in the world, None if unknown.

        Returns:
            ``(U, K)`` the parts to relabel in each detection's output (the detection's own
            flips and its hips, eyes and ears put on its shoulders' side, then the swaps its
            track made: facing check or mirror vote), ``(U,)`` the track ids and whether the
            detections are labelled already (every track confirmed; else ``_labelled`` does).

        """
        params = self.params
        rows = pairs[0]
        facing = params.mirror_check and params.facing_check and info.usable
        voting = params.mirror_check and params.mirror_vote and not facing
        update = UpdateSettings(
            float(params.position_smoothing),
            float(params.max_prediction),
            round(params.velocity_window * 1e9),
            info.weights,
        )
        settings = HitSettings(
            update,
            align=params.mirror_check and params.facing_check,
            weigh=facing,
            label=found.stacked and not voting,
            priors=self._priors,
        )
        frame = FrameRows(found.positions, det_ids, found.index, found.rows)
        flips, full, turned, n_turned, track_ids, labelled = kernels.hit_frame(
            table.hit_fields(),
            frame,
            pairs,
            self._view(camera, time_ns, camera_position),
            info.hit_layout,
            settings,
        )
        if full:
            table.grow_records()
        table.learn_limbs(rows, found.positions[pairs[1]], info.parents)
        if n_turned:
            self._turned(table, rows[turned])
        if labelled or (not voting and table.confirmed[rows].all()):
            return flips, track_ids, labelled
        confirmed, hits = table.confirmed[rows].tolist(), table.hits[rows].tolist()
        for u, row in enumerate(rows.tolist()):
            if not confirmed[u] and hits[u] >= params.min_hits:
                self._confirm(table, row, info, time_ns)
                track_ids[u] = table.ids[row]  # re-identified: an older id
            if voting and table.confirmed[row]:
                flips[u] ^= self._vote(table, row, info.parts, camera, time_ns, flips[u].copy())
        return flips, track_ids, False

    def _view(self, camera: int, time_ns: int, camera_position: np.ndarray | None) -> FacingView:
        """Where ``kernels.turn_facing`` judges a frame's facing from: up, camera, stamp."""
        position = _NO_CAMERA if camera_position is None else camera_position
        return FacingView(self._up, position, camera_position is not None, camera, time_ns)

    @property
    def _priors(self) -> FacingPriors:
        """The facing check's settings, as ``kernels.turn_facing`` takes them."""
        params = self.params
        return FacingPriors(
            params.flip_prior,
            params.flip_prior_back,
            params.walking_speed,
            params.walking_evidence,
            params.facing_memory,
            params.facing_memory_standing,
            params.facing_threshold,
        )

    @staticmethod
    def _turned(table: TrackTable, rows: np.ndarray) -> None:
        """The votes of tracks the facing check relabelled, turned with them."""
        for row in rows.tolist():
            votes = table.votes[row]
            table.votes[row] = {cam: (t, ~vote) for cam, (t, vote) in votes.items()}
            table.mirrored[row] = {cam for cam, (_, vote) in table.votes[row].items() if vote.any()}

    def _vote(  # noqa: PLR0917
        self,
        table: TrackTable,
        row: int,
        parts: _MirrorParts,
        camera: int,
        time_ns: int,
        flips: np.ndarray,
    ) -> np.ndarray:
        """Swap a track's sides of the parts that most cameras seeing it now call mirrored.

        The fallback for layouts without the joints the facing check needs.
        """
        votes, mirrored = table.votes[row], table.mirrored[row]
        votes[camera] = (time_ns, flips)
        if not flips.any():
            mirrored.discard(camera)
            if not mirrored:  # nobody calls the sides mirrored: nothing to count
                return np.zeros_like(flips)
        else:
            mirrored.add(camera)
        recent = time_ns - round(self.params.velocity_window * 1e9)
        recent_votes = [vote for t, vote in votes.values() if t >= recent]
        if len(recent_votes) < 2:
            return np.zeros_like(flips)
        swap = 2 * np.sum(recent_votes, axis=0) > len(recent_votes)
        if swap.any():
            table.relabel(row, parts.permutation(swap))
            table.votes[row] = {cam: (t, vote ^ swap) for cam, (t, vote) in votes.items()}
            table.mirrored[row] = {cam for cam, (_, vote) in table.votes[row].items() if vote.any()}
        return swap

    def _labelled(  # noqa: PLR0917
        self,
        found: _Detections,
        pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
        flips: np.ndarray,
        track_ids: np.ndarray,
        labelled: bool,
        parts: _MirrorParts,
    ) -> list[Skeleton]:
        """The output skeletons of the detections of confirmed tracks: track id, sides fixed.

        The detections are the tracker's own copies (made by the correction), so they are
        changed in place: the parts in ``flips`` ``(U, K)`` relabelled (links too: link ids are
        child joint ids), present joints without a velocity given their track's (track
        ``rows[u]``). ``hit_frame`` did that when ``labelled``; else it takes one compiled call
        with the frame's rows stacked, one per detection without.
        """
        table = self._table
        rows, dets, _ = pairs
        detections = found.skeletons
        if len(dets) < len(detections):
            detections = [detections[det] for det in dets.tolist()]
        if labelled:  # every track confirmed: the usual frame
            for detection, track_id in zip(detections, track_ids.tolist(), strict=True):
                detection.id = track_id
            return detections
        if found.stacked:
            kernels.label_frame(
                found.rows,
                found.index[dets],
                flips,
                parts.arrays,
                table.velocities,
                rows,
                table.confirmed,
            )
        output = []
        confirmed = table.confirmed[rows].tolist()
        for u, (detection, row) in enumerate(zip(detections, rows.tolist(), strict=True)):
            if not confirmed[u]:
                continue
            if not found.stacked:
                kernels.label_rows(
                    detection.markers,
                    detection.marker_present,
                    detection.links,
                    detection.link_present,
                    flips[u],
                    parts.arrays,
                    table.velocities[row],
                )
            detection.id = int(track_ids[u])
            output.append(detection)
        return output
