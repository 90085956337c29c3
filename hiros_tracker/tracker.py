"""Tracker: a persistent track id for every camera detection, across cameras and over time.

Data flow of ``Tracker.update`` (one call per camera frame, the node calls exactly this):

1. the camera's group is moved into the world frame and onto the reference clock
   (``CameraCorrection``);
2. it waits in a small buffer for ``max_delay`` seconds so that frames of other cameras arriving
   late can be processed before it (frames are released in reference-time order);
3. each released frame is associated with the tracks: every track is predicted to the frame's
   corrected time with a constant-velocity model, the cost of a (track, detection) pair is the
   mean joint distance (the cheaper of the pose and its left/right mirror, so that a camera's
   front/back flip or side swap does not break the match), gated, and solved with
   ``scipy.optimize.linear_sum_assignment`` — confirmed tracks first, tentative tracks second;
4. unmatched detections start tentative tracks, confirmed after ``min_hits`` hits unless they
   sit on top of a confirmed track (a ghost or duplicate body); tracks without hits expire.

The output is Hi-ROS's: one skeleton per camera detection of a confirmed track, ``id`` = track
id, ``src_frame`` = the camera's frame, ``src_time`` = the corrected stamp, world-frame poses,
mirrored detections relabelled, and each joint's velocity (m/s) filled from the track when the
camera gave none. Shapes: ``T`` tracks, ``D`` detections, ``J`` joints; positions in metres.
"""

from __future__ import annotations

import heapq
import itertools
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_tracker.correction import CameraCorrection

__all__ = ["Tracker", "TrackerParams"]

_NS = 1e-9
_INFEASIBLE = 1e9
"""Cost given to gated-out pairs so that the solver still sees a full matrix."""


@dataclass
class TrackerParams:
    """Tracker parameters (field names = ROS parameter names of the ``tracker`` node).

    Attributes:
        max_delay: seconds a frame waits for late frames of other cameras before it is
            processed; frames older than the last processed one are dropped as ``late``.
        gate_distance: metres; a detection farther than this (mean joint distance) from a
            track's prediction cannot be assigned to it.
        gate_growth: metres per second; the gate widens by this for each second a track went
            unseen, so that a person whose camera dropped out can be picked up again.
        min_hits: hits a tentative track needs to be confirmed (and output).
        tentative_timeout: seconds a tentative track survives without a hit.
        track_timeout: seconds a confirmed track survives without a hit.
        max_prediction: seconds of constant-velocity extrapolation at most; beyond, a track
            waits where it was last predicted.
        position_smoothing: weight (0..1] of a new detection in the track's reference pose.
        velocity_window: seconds of history the per-joint velocity is fitted over.
        velocity_weight: metres of cost per m/s of velocity difference (0: positions only;
            used when detections carry velocities).
        orientation_weight: metres of cost per radian of joint orientation difference
            (0: positions only; used when detections carry orientations).
        mirror_check: compare each detection also with its left/right mirror and keep the
            cheaper labelling (front/back flips, side swaps).
        mirror_margin: metres the mirror must be cheaper by before a detection is relabelled.
        mirror_vote: when most cameras currently disagree with a track's labelling, relabel
            the track (its first detection was the flipped one).
        duplicate_distance: metres; a tentative track closer than this to a confirmed track
            when it would be confirmed is a ghost or duplicate body and is deleted.
        min_joints: joints a detection and a track must share for a cost to exist.
        min_confidence: joints of lower confidence are left out of the cost.

    """

    max_delay: float = 0.05
    gate_distance: float = 0.5
    gate_growth: float = 0.5
    min_hits: int = 8
    tentative_timeout: float = 0.3
    track_timeout: float = 2.0
    max_prediction: float = 0.5
    position_smoothing: float = 0.6
    velocity_window: float = 0.25
    velocity_weight: float = 0.0
    orientation_weight: float = 0.0
    mirror_check: bool = True
    mirror_margin: float = 0.02
    mirror_vote: bool = True
    duplicate_distance: float = 0.25
    min_joints: int = 4
    min_confidence: float = 0.0


class _Track:
    """One person's state: a reference pose, per-joint velocities and recent detections.

    ``positions`` ``(J, 3)`` is the smoothed pose at ``time_ns``; ``velocities`` ``(J, 3)`` is
    fitted over ``history`` with one intercept per camera, so that a constant offset between
    two cameras' calibrations does not read as motion.
    """

    __slots__ = (
        "camera_votes",
        "confirmed",
        "hits",
        "id",
        "last_hit_ns",
        "orientations",
        "positions",
        "records",
        "time_ns",
        "velocities",
        "velocity",
    )

    def __init__(
        self, track_id: int, positions: np.ndarray, orientations: np.ndarray, time_ns: int
    ) -> None:
        self.id = track_id
        self.positions = positions.copy()
        self.orientations = orientations.copy()
        self.velocities = np.zeros_like(positions)
        self.velocity = np.zeros(3)
        self.time_ns = time_ns
        self.last_hit_ns = time_ns
        self.hits = 0
        self.confirmed = False
        self.records: deque[tuple[int, int, np.ndarray]] = deque()
        self.camera_votes: dict[int, tuple[int, bool]] = {}

    def predict(self, time_ns: int, max_prediction: float) -> np.ndarray:
        """``(J, 3)`` pose extrapolated to ``time_ns`` with the body's mean velocity."""
        dt = float(np.clip((time_ns - self.time_ns) * _NS, -max_prediction, max_prediction))
        return self.positions + self.velocity * dt

    def mirror(self, mirror: np.ndarray) -> None:
        """Swap the track's left and right labels (pose, velocities, history)."""
        self.positions = self.positions[mirror]
        self.orientations = self.orientations[mirror]
        self.velocities = self.velocities[mirror]
        self.records = deque((t, cam, pos[mirror]) for t, cam, pos in self.records)
        self.camera_votes = {cam: (t, not vote) for cam, (t, vote) in self.camera_votes.items()}


def _fit_velocities(
    times: np.ndarray, cameras: np.ndarray, positions: np.ndarray
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Least-squares joint velocities with one intercept per camera (fixed effects).

    Args:
        times: ``(N,)`` seconds.
        cameras: ``(N,)`` camera codes.
        positions: ``(N, J, 3)`` with NaN for missing joints.

    Returns:
        ``(J, 3)`` per-joint velocities (0 where not determined), ``(3,)`` pooled body velocity,
        and whether any camera gave two or more samples.

    """
    codes, group = np.unique(cameras, return_inverse=True)
    valid = np.isfinite(positions).all(axis=2)  # (N, J)
    weight = valid.astype(float)
    filled = np.where(valid[..., None], positions, 0.0)
    onehot = np.zeros((len(times), len(codes)))
    onehot[np.arange(len(times)), group] = 1.0
    count = onehot.T @ weight  # (C, J)
    safe = np.maximum(count, 1.0)
    mean_t = (onehot.T @ (weight * times[:, None])) / safe  # (C, J)
    mean_p = np.einsum("nc,nj,njk->cjk", onehot, weight, filled) / safe[..., None]
    dt = (times[:, None] - mean_t[group]) * weight  # (N, J)
    dp = (filled - mean_p[group]) * weight[..., None]  # (N, J, 3)
    sxx = (dt * dt).sum(axis=0)  # (J,)
    sxy = np.einsum("nj,njk->jk", dt, dp)  # (J, 3)
    determined = sxx > 1e-6
    velocities = np.zeros_like(sxy)
    velocities[determined] = sxy[determined] / sxx[determined, None]
    total = sxx.sum()
    body = sxy.sum(axis=0) / total if total > 1e-6 else np.zeros(3)
    return velocities, body, bool(determined.any())


def _pair_costs(predicted: np.ndarray, detections: np.ndarray, min_joints: int) -> np.ndarray:
    """``(T, D)`` mean joint distance between predicted tracks and detections.

    Args:
        predicted: ``(T, J, 3)``.
        detections: ``(D, J, 3)``, NaN for joints left out.
        min_joints: pairs sharing fewer joints cost ``inf``.

    """
    distance = np.linalg.norm(predicted[:, None] - detections[None], axis=3)  # (T, D, J)
    shared = np.isfinite(distance)
    count = shared.sum(axis=2)
    total = np.where(shared, distance, 0.0).sum(axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        cost = total / count
    cost[count < min_joints] = np.inf
    return cost


def _angle_costs(tracks: np.ndarray, detections: np.ndarray) -> np.ndarray:
    """``(T, D)`` mean rotation angle (rad) between track and detection joint quaternions."""
    dot = np.abs(np.einsum("tjk,djk->tdj", tracks, detections))
    angle = 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))
    shared = np.isfinite(angle)
    return np.where(shared, angle, 0.0).sum(axis=2) / np.maximum(shared.sum(axis=2), 1)


class Tracker:
    """Gives every camera detection a persistent track id (see the module docstring).

    Attributes:
        params: the parameters it was built with.
        drops: reason -> count of input left out (uncalibrated camera, late frame, ...).
        correction: the calibration being applied (``set_calibration`` replaces it).

    """

    def __init__(
        self, params: TrackerParams | None = None, calibration: Calibration | None = None
    ) -> None:
        self.params = params or TrackerParams()
        self.drops: Counter[str] = Counter()
        self.correction = CameraCorrection(calibration, self.drops)
        self._tracks: list[_Track] = []
        self._next_id = 0
        self._buffer: list[tuple[int, int, str, SkeletonGroup]] = []
        self._sequence = itertools.count()
        self._camera_codes: dict[str, int] = {}
        self._newest_ns: int | None = None
        self._released_ns: int | None = None

    # ----------------------------------------------------------------------------- calibration
    def set_calibration(self, calibration: Calibration) -> None:
        """Use a new calibration from the next frame on (tracks are kept)."""
        self.correction.set_calibration(calibration)

    def set_camera(self, name: str, camera: CameraCalibration) -> None:
        """Replace one camera's calibration from the next frame on."""
        self.correction.set_camera(name, camera)

    @property
    def uncalibrated(self) -> set[str]:
        """Cameras whose frames were dropped for want of a calibration."""
        return self.correction.uncalibrated

    # ---------------------------------------------------------------------------------- state
    @property
    def track_ids(self) -> list[int]:
        """Ids of the confirmed tracks."""
        return [track.id for track in self._tracks if track.confirmed]

    @property
    def pending(self) -> int:
        """Frames waiting in the out-of-order buffer."""
        return len(self._buffer)

    # ----------------------------------------------------------------------------------- flow
    def update(self, group: SkeletonGroup) -> SkeletonGroup:
        """Take one camera frame; return the detections released by it, with track ids.

        The returned group holds every detection of confirmed tracks from the frames released
        by this call (zero or more frames, in reference-time order): world frame, header stamp
        = the last released frame's corrected stamp.
        """
        corrected = self.correction.apply(group)
        if corrected is None:
            return self._output([])
        if self._released_ns is not None and corrected.stamp_ns < self._released_ns:
            self.drops["late frame"] += 1
            return self._output([])
        camera = self.correction.camera_name(group) or group.camera
        heapq.heappush(self._buffer, (corrected.stamp_ns, next(self._sequence), camera, corrected))
        if self._newest_ns is None or corrected.stamp_ns > self._newest_ns:
            self._newest_ns = corrected.stamp_ns
        horizon = self._newest_ns - round(self.params.max_delay * 1e9)
        return self._release(horizon)

    def flush(self) -> SkeletonGroup:
        """Process every buffered frame now (end of a recording)."""
        return self._release(None)

    def _release(self, horizon_ns: int | None) -> SkeletonGroup:
        skeletons: list[Skeleton] = []
        while self._buffer and (horizon_ns is None or self._buffer[0][0] <= horizon_ns):
            stamp_ns, _, camera, frame = heapq.heappop(self._buffer)
            self._released_ns = stamp_ns
            skeletons.extend(self._process(frame, camera))
        return self._output(skeletons)

    def _output(self, skeletons: list[Skeleton]) -> SkeletonGroup:
        stamp = self._released_ns if self._released_ns is not None else 0
        return SkeletonGroup(stamp, self.correction.world_frame, skeletons)

    # ---------------------------------------------------------------------------- association
    def _process(self, frame: SkeletonGroup, camera: str) -> list[Skeleton]:
        """Associate one world-frame camera frame with the tracks; return confirmed outputs."""
        code = self._camera_codes.setdefault(camera, len(self._camera_codes))
        detections = self._valid_detections(frame.skeletons)
        self._expire(frame.stamp_ns)
        if not detections:
            return []
        params = self.params
        layout = detections[0].layout
        times = np.array([d.src_time_ns for d in detections], dtype=np.int64)
        positions = np.stack([d.positions for d in detections])  # (D, J, 3)
        present = np.stack([d.marker_present for d in detections])
        usable = present & np.isfinite(positions).all(axis=2)
        if params.min_confidence > 0:
            confidences = np.stack([d.confidences for d in detections])
            usable &= ~(confidences < params.min_confidence)
        cost_positions = np.where(usable[..., None], positions, np.nan)

        assigned: dict[int, tuple[_Track, bool]] = {}
        free = list(range(len(detections)))
        for confirmed in (True, False):
            tracks = [t for t in self._tracks if t.confirmed == confirmed]
            if tracks and free:
                matches = self._match(
                    tracks,
                    detections,
                    cost_positions,
                    free,
                    stamp=int(times[0]),
                    mirror=layout.mirror,
                )
                for det, track, mirrored in matches:
                    assigned[det] = (track, mirrored)
                free = [d for d in free if d not in assigned]

        outputs: list[Skeleton] = []
        for det, detection in enumerate(detections):
            canonical = positions[det]
            if det in assigned:
                track, mirrored = assigned[det]
            else:
                if usable[det].sum() < params.min_joints:
                    self.drops["too few joints"] += 1
                    continue
                track = self._new_track(canonical, detection.orientations, int(times[det]))
                mirrored = False
            if mirrored:
                canonical = canonical[layout.mirror]
            relabel = self._hit(
                track, canonical, detection, time_ns=int(times[det]), camera=code, mirrored=mirrored
            )
            if track.confirmed:
                outputs.append(self._labelled(detection, track, mirrored != relabel))
        return outputs

    def _valid_detections(self, skeletons: list[Skeleton]) -> list[Skeleton]:
        """Skeletons with enough finite joints and the layout of the first one."""
        valid: list[Skeleton] = []
        for skeleton in skeletons:
            if valid and skeleton.layout.n_joints != valid[0].layout.n_joints:
                self.drops["layout differs within a frame"] += 1
            elif not (skeleton.marker_present & np.isfinite(skeleton.positions).all(1)).any():
                self.drops["no finite joint"] += 1
            else:
                valid.append(skeleton)
        if valid and self._tracks and valid[0].layout.n_joints != len(self._tracks[0].positions):
            self.drops["layout differs from the tracks"] += len(valid)
            return []
        return valid

    def _match(
        self,
        tracks: list[_Track],
        detections: list[Skeleton],
        positions: np.ndarray,
        free: list[int],
        *,
        stamp: int,
        mirror: np.ndarray,
    ) -> list[tuple[int, _Track, bool]]:
        """Optimal assignment of ``free`` detections to ``tracks``: (detection, track, mirrored)."""
        params = self.params
        predicted = np.stack([t.predict(stamp, params.max_prediction) for t in tracks])
        candidates = positions[free]
        cost = _pair_costs(predicted, candidates, params.min_joints)
        mirrored = np.zeros(cost.shape, dtype=bool)
        if params.mirror_check:
            cost_mirrored = _pair_costs(predicted, candidates[:, mirror], params.min_joints)
            mirrored = cost_mirrored + params.mirror_margin < cost
            cost = np.where(mirrored, cost_mirrored, cost)
        if params.velocity_weight > 0:
            cost = cost + params.velocity_weight * self._velocity_costs(
                tracks, detections, free, mirror, mirrored
            )
        if params.orientation_weight > 0:
            track_q = np.stack([t.orientations for t in tracks])
            det_q = np.stack([detections[d].orientations for d in free])
            angle = np.where(
                mirrored, _angle_costs(track_q, det_q[:, mirror]), _angle_costs(track_q, det_q)
            )
            cost = cost + params.orientation_weight * angle
        unseen = np.array([(stamp - t.last_hit_ns) * _NS for t in tracks])
        gate = params.gate_distance + params.gate_growth * np.clip(unseen, 0.0, None)
        feasible = np.isfinite(cost) & (cost <= gate[:, None])
        if not feasible.any():
            return []
        rows, cols = linear_sum_assignment(np.where(feasible, cost, _INFEASIBLE))
        return [
            (free[c], tracks[r], bool(mirrored[r, c]))
            for r, c in zip(rows, cols, strict=True)
            if feasible[r, c]
        ]

    def _velocity_costs(
        self,
        tracks: list[_Track],
        detections: list[Skeleton],
        free: list[int],
        mirror: np.ndarray,
        mirrored: np.ndarray,
    ) -> np.ndarray:
        """``(T, D)`` mean joint velocity difference (m/s); 0 where detections carry none."""
        track_v = np.stack([t.velocities for t in tracks])
        det_v = np.stack([detections[d].velocities for d in free])
        direct = _pair_costs(track_v, det_v, 1)
        swapped = _pair_costs(track_v, det_v[:, mirror], 1)
        cost = np.where(mirrored, swapped, direct)
        return np.where(np.isfinite(cost), cost, 0.0)

    # -------------------------------------------------------------------------------- updates
    def _new_track(self, positions: np.ndarray, orientations: np.ndarray, time_ns: int) -> _Track:
        track = _Track(self._next_id, positions, orientations, time_ns)
        self._next_id += 1
        self._tracks.append(track)
        return track

    def _hit(
        self,
        track: _Track,
        canonical: np.ndarray,
        detection: Skeleton,
        *,
        time_ns: int,
        camera: int,
        mirrored: bool,
    ) -> bool:
        """Fold one detection (already in the track's labelling) into the track.

        Returns True when the track itself was relabelled (mirror vote), so the caller flips
        the output labelling of this detection too.
        """
        params = self.params
        predicted_time = max(time_ns, track.time_ns)
        predicted = track.predict(predicted_time, params.max_prediction)
        measured = np.isfinite(canonical).all(axis=1)
        alpha = params.position_smoothing if track.hits else 1.0
        track.positions = np.where(
            measured[:, None], predicted + alpha * (canonical - predicted), predicted
        )
        unknown = ~np.isfinite(track.positions).all(axis=1)
        track.positions[unknown] = canonical[unknown]
        track.time_ns = predicted_time
        track.last_hit_ns = max(track.last_hit_ns, time_ns)
        track.hits += 1
        orientations = detection.orientations
        if np.isfinite(orientations).any():
            track.orientations = (
                orientations[detection.layout.mirror] if mirrored else orientations.copy()
            )

        horizon = time_ns - round(params.velocity_window * 1e9)
        track.records.append((time_ns, camera, canonical))
        while track.records and track.records[0][0] < horizon:
            track.records.popleft()
        if len(track.records) >= 2:
            t0 = track.records[0][0]
            times = np.array([(r[0] - t0) * _NS for r in track.records])
            cams = np.array([r[1] for r in track.records])
            stacked = np.stack([r[2] for r in track.records])
            velocities, body, determined = _fit_velocities(times, cams, stacked)
            if determined:
                track.velocities = velocities
                track.velocity = body

        if not track.confirmed and track.hits >= params.min_hits:
            self._confirm(track, time_ns)
        relabel = False
        if params.mirror_check and params.mirror_vote and track.confirmed:
            relabel = self._vote(track, camera, time_ns, mirrored, detection.layout.mirror)
        return relabel

    def _vote(
        self, track: _Track, camera: int, time_ns: int, mirrored: bool, mirror: np.ndarray
    ) -> bool:
        """Relabel a track when most cameras seeing it now call its labelling mirrored."""
        track.camera_votes[camera] = (time_ns, mirrored)
        recent = time_ns - round(self.params.velocity_window * 1e9)
        votes = [vote for t, vote in track.camera_votes.values() if t >= recent]
        if len(votes) >= 2 and 2 * sum(votes) > len(votes):
            track.mirror(mirror)
            return True
        return False

    def _confirm(self, track: _Track, time_ns: int) -> None:
        """Confirm a tentative track unless it duplicates a confirmed one (ghost body)."""
        confirmed = [t for t in self._tracks if t.confirmed]
        if confirmed:
            predicted = np.stack(
                [t.predict(time_ns, self.params.max_prediction) for t in confirmed]
            )
            distance = _pair_costs(predicted, track.positions[None], self.params.min_joints)
            if (distance < self.params.duplicate_distance).any():
                self._tracks.remove(track)
                self.drops["duplicate of a confirmed track"] += 1
                return
        track.confirmed = True

    def _expire(self, now_ns: int) -> None:
        params = self.params
        kept = []
        for track in self._tracks:
            unseen = (now_ns - track.last_hit_ns) * _NS
            timeout = params.track_timeout if track.confirmed else params.tentative_timeout
            if unseen <= timeout:
                kept.append(track)
        self._tracks = kept

    def _labelled(self, detection: Skeleton, track: _Track, mirrored: bool) -> Skeleton:
        """The output skeleton of one detection: track id, labels fixed, velocities filled."""
        out = detection  # already a copy owned by the tracker (made by the correction)
        if mirrored:
            mirror = detection.layout.mirror
            out.markers = out.markers[mirror]
            out.marker_present = out.marker_present[mirror]
            out.links = out.links[mirror]
            out.link_present = out.link_present[mirror]
        out.id = track.id
        missing = out.marker_present & ~np.isfinite(out.velocities).all(axis=1)
        out.velocities[missing] = track.velocities[missing]
        return out
