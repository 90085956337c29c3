"""Merger: one skeleton per person, fused from what every camera saw of that track.

Data flow of ``Merger.update`` (one call per tracker output; the node calls exactly this):

1. each tracker skeleton (one camera detection, ``id`` = track id, world frame, reference-clock
   ``src_time``) replaces the previous one of the same track and camera;
2. at the output time (each input's newest stamp, or the ticks of ``output_rate``) every track
   with detections younger than ``window`` is fused: each detection is first brought to the
   output time with its joints' velocities (the tracker fills them), then joints are averaged
   with reliability weights and an iteratively reweighted robust mean;
3. joint orientations are averaged on SO(3) with the same weights (the weighted quaternion mean
   of Markley et al., "Averaging quaternions", J. Guidance 30(4), 2007 — what
   ``scipy.spatial.transform.Rotation.mean`` computes, here for all joints at once).

Reliability of joint ``j`` of the detection of camera ``c`` (after Colombel et al., 2021, who
weight each camera by confidence, distance and view; the product form is ours)::

    w = conf^confidence_power            SDK confidence (occluded joints come as LOW)
        × (1 + depth_gain · depth)^-2    depth noise grows ~linearly with distance (variance ²)
        × view(cos θ)                     θ: angle between the body's front and the camera
        × flipped                         ``flipped_weight`` if the detection's feet and nose
                                          point backwards (a front/back flip)
        × occlusion                       another person's torso on the camera's ray
        × agreement(c)                    1 / (1 + (e_c / agreement_scale)²), e_c the camera's
                                          recent mean distance to the fused skeletons
        × staleness                       1 / (1 + (Δt / staleness_scale)²)

then the robust mean multiplies by a Cauchy weight ``1 / (1 + (r / outlier_scale)²)`` of each
joint's distance ``r`` to the current estimate (0 beyond ``outlier_cutoff``), starting from the
weighted median, so that one camera's flipped limb or swapped leg does not pull the result.

Output: world frame, ``id`` = track id, ``src_time`` = output time, ``src_frame`` = world frame;
positions, orientations, confidences (weighted mean) and velocities (weighted mean) per joint.
Shapes: ``M`` tracks, ``C`` detections per track (padded), ``J`` joints; metres, seconds.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.layouts import Layout
from hiros_core.model import STATE_WIDTH, Skeleton, SkeletonGroup, camera_from_frame

__all__ = ["Merger", "MergerParams"]

_NS = 1e-9


@dataclass
class MergerParams:
    """Merger parameters (field names = ROS parameter names of the ``merger`` node).

    Attributes:
        window: seconds; a camera's detection older than this at the output time is not fused.
        output_rate: Hz; 0 outputs on each input at its newest stamp.
        extrapolate: bring each detection to the output time with its joint velocities.
        max_extrapolation: seconds of extrapolation at most.
        confidence_power: exponent of the SDK confidence in the weight.
        confidence_floor: smallest confidence used (a NONE joint still counts a little).
        depth_gain: per metre; the depth weight is ``(1 + depth_gain · depth)^-2``.
        view_weight_min: weight of a camera behind the person; facing it gives 1, the weight is
            ``max(view_weight_min, ((1 + cos θ) / 2)^view_power)``.
        view_power: exponent of the view weight.
        flipped_weight: weight factor of a detection whose feet and nose point backwards
            against the body's front (a front/back flip the tracker relabelled but whose limbs
            are still reflected).
        occlusion_radius: metres; a joint whose camera ray passes this close to another
            person's torso, in front of the joint, is occluded (0 turns the check off).
        occlusion_weight: weight factor of an occluded joint.
        agreement_scale: metres; scale of the camera agreement weight.
        agreement_smoothing: weight (0..1] of each new residual in a camera's running agreement.
        staleness_scale: seconds; scale of the weight of older detections.
        outlier_scale: metres; Cauchy scale of the robust mean.
        outlier_cutoff: metres; a joint farther than this from the estimate gets no weight (as
            long as another camera's joint is within it): a flipped limb is out, not just less.
        iterations: reweighting iterations of the robust mean.
        track_timeout: seconds; a track unseen this long is forgotten.

    """

    window: float = 0.1
    output_rate: float = 0.0
    extrapolate: bool = True
    max_extrapolation: float = 0.1
    confidence_power: float = 2.0
    confidence_floor: float = 0.05
    depth_gain: float = 0.33
    view_weight_min: float = 0.3
    view_power: float = 1.0
    flipped_weight: float = 0.1
    occlusion_radius: float = 0.2
    occlusion_weight: float = 0.5
    agreement_scale: float = 0.1
    agreement_smoothing: float = 0.02
    staleness_scale: float = 0.05
    outlier_scale: float = 0.25
    outlier_cutoff: float = 0.4
    iterations: int = 3
    track_timeout: float = 1.0


@dataclass(frozen=True)
class _BodyAxes:
    """Joints that give a body's facing direction and torso, or -1 where a layout lacks them."""

    root: int
    neck: int
    left: np.ndarray  # (2,) hip and shoulder on the left
    right: np.ndarray  # (2,)
    torso: np.ndarray  # joints standing for the torso in occlusion tests
    pointers: np.ndarray  # (k, 2) joint pairs pointing forward: ankle -> foot, head -> nose

    @classmethod
    def of(cls, layout: Layout) -> _BodyAxes:
        """Find the joints by name (Azure Kinect and Kinect v2 names)."""
        names = {name: i for i, name in enumerate(layout.joint_names)}
        root = layout.parents.index(-1)
        neck = names.get("Neck", -1)
        left = np.array([names.get("HipLeft", -1), names.get("ShoulderLeft", -1)])
        right = np.array([names.get("HipRight", -1), names.get("ShoulderRight", -1)])
        torso_names = ("SpineNaval", "SpineMid", "SpineChest", "SpineShoulder", "Neck")
        torso = np.array([root] + [names[n] for n in torso_names if n in names])
        pairs = (("AnkleLeft", "FootLeft"), ("AnkleRight", "FootRight"), ("Head", "Nose"))
        pointers = np.array(
            [(names[a], names[b]) for a, b in pairs if a in names and b in names], dtype=np.int64
        ).reshape(-1, 2)
        return cls(root, neck, left, right, torso, pointers)

    def front(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit up (root -> neck) and front (cross(left, up)) of poses ``(..., J, 3)``."""
        up = _unit(positions[..., self.neck, :] - positions[..., self.root, :])
        # mean of left minus mean of right, as numpy's means compute them
        left_mean = np.add.reduce(positions[..., self.left, :], axis=-2) / len(self.left)
        right_mean = np.add.reduce(positions[..., self.right, :], axis=-2) / len(self.right)
        left = left_mean - right_mean
        return up, _unit(_cross(left, up))

    def forward(self, positions: np.ndarray, up: np.ndarray) -> np.ndarray:
        """Unit anatomical forward (feet and nose, ⟂ up) of poses ``(..., J, 3)``.

        It does not depend on the left/right labels, so it tells a front/back flipped
        detection (forward against the body's front) from a correct one.
        """
        steps = positions[..., self.pointers[:, 1], :] - positions[..., self.pointers[:, 0], :]
        up = up[..., None, :]
        steps = _unit(steps - np.add.reduce(steps * up, axis=-1)[..., None] * up)
        return _unit(np.add.reduce(np.where(np.isfinite(steps), steps, 0.0), axis=-2))

    @property
    def has_front(self) -> bool:
        """Whether the layout names what the facing direction needs."""
        return self.neck >= 0 and (self.left >= 0).all() and (self.right >= 0).all()


@dataclass
class _Batch:
    """The detections being fused, padded to ``(M, C, ...)``: M tracks, C cameras at most.

    ``known`` ``(M, C)``: detections whose camera position is known; ``confidences``
    ``(M, C, J)``: SDK confidences, 1 where unknown (both computed once by ``_stack``).
    """

    markers: np.ndarray  # (M, C, J, 20) rows as received, NaN padding
    positions: np.ndarray  # (M, C, J, 3) brought to the output time
    ages: np.ndarray  # (M, C) seconds from detection to output time
    cameras: np.ndarray  # (M, C, 3) camera positions, NaN when unknown
    camera_names: list[list[str]]  # (M, C), "" for padding
    known: np.ndarray = field(init=False)
    confidences: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.known = np.isfinite(self.cameras).all(axis=-1)
        confidences = self.markers[..., 0]
        self.confidences = np.where(np.isfinite(confidences), confidences, 1.0)


_AXES: dict[str, _BodyAxes] = {}
_UNKNOWN_CAMERA = (np.nan, np.nan, np.nan)


def _axes(layout: Layout) -> _BodyAxes:
    axes = _AXES.get(layout.name)
    if axes is None:
        axes = _AXES[layout.name] = _BodyAxes.of(layout)
    return axes


def _unit(vectors: np.ndarray) -> np.ndarray:
    """Vectors ``(..., 3)`` scaled to unit length; zero or NaN ones become NaN."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return vectors / _norm(vectors)[..., None]


def _norm(vectors: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(vectors, axis=-1)``: the same arithmetic without its wrapper."""
    return np.sqrt(np.add.reduce(vectors * vectors, axis=-1))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of ``(..., 3)`` vectors, written out (numpy's wrapper costs more)."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted median along axis 1 of ``values`` ``(M, C, J, 3)`` with ``weights`` ``(M, C, J)``.

    Per coordinate: the smallest value whose cumulative weight reaches half the total; NaN
    values carry no weight. Entries with all weights 0 give NaN.
    """
    weights = np.where(np.isfinite(values), weights[..., None], 0.0)
    order = np.argsort(np.where(weights > 0, values, np.inf), axis=1)
    # Gathers along axis 1 as flat indices (take_along_axis' wrapper costs more than them).
    n_tracks, n_cameras = values.shape[:2]
    inner = values[0, 0].size
    base = (np.arange(n_tracks) * (n_cameras * inner))[:, None, None, None] + np.arange(
        inner
    ).reshape(values.shape[2:])
    flat = base + order * inner
    sorted_values = values.reshape(-1)[flat]
    cumulative = np.cumsum(weights.reshape(-1)[flat], axis=1)
    total = cumulative[:, -1:]
    first = np.argmax(cumulative >= 0.5 * total, axis=1)[:, None]
    median = np.take_along_axis(sorted_values, first, axis=1)[:, 0]
    return np.where(total[:, 0] > 0, median, np.nan)


def _weighted_mean(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted mean along axis 1 of ``(M, C, J, k)`` with ``(M, C, J)``; NaN where no weight."""
    finite = np.isfinite(values).all(axis=-1)
    weights = np.where(finite, weights, 0.0)
    total = weights.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (np.where(finite[..., None], values, 0.0) * weights[..., None]).sum(axis=1)
        return mean / total[..., None]


def _distance(positions: np.ndarray, fused: np.ndarray) -> np.ndarray:
    """``(M, C, J)`` distance of each detection's joints to the fused ``(M, J, 3)``.

    ``np.linalg.norm(positions - fused[:, None], axis=-1)`` without its wrapper.
    """
    difference = positions - fused[:, None]
    return np.sqrt(np.add.reduce(difference * difference, axis=-1))


def _mean_of_filled(filled: np.ndarray, finite: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """:func:`_weighted_mean` of values already zero-filled where not ``finite``."""
    weights = np.where(finite, weights, 0.0)
    total = weights.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (filled * weights[..., None]).sum(axis=1) / total[..., None]


def _quaternion_mean(quaternions: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted mean rotation along axis 1 of ``(M, C, J, 4)`` (x, y, z, w), batched Markley.

    The mean is the eigenvector of the largest eigenvalue of ``Σ w q qᵀ`` (sign-free, so q and
    -q count alike); NaN where no orientation has weight.
    """
    finite = np.isfinite(quaternions).all(axis=-1)
    weights = np.where(finite, weights, 0.0)
    q = np.where(finite[..., None], quaternions, 0.0)
    q = q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)
    scatter = np.einsum("mcj,mcja,mcjb->mjab", weights, q, q)
    _, vectors = np.linalg.eigh(scatter)
    mean = vectors[..., -1]
    mean = np.where(mean[..., 3:4] < 0, -mean, mean)
    return np.where((weights.sum(axis=1) > 0)[..., None], mean, np.nan)


class Merger:
    """Fuses each track's camera detections into one skeleton (see the module docstring).

    Attributes:
        params: the parameters it was built with.
        drops: reason -> count of input left out.
        agreement: camera name -> running mean distance (m) of its detections to the fused
            skeletons.

    """

    def __init__(
        self, params: MergerParams | None = None, calibration: Calibration | None = None
    ) -> None:
        self.params = params or MergerParams()
        self.drops: Counter[str] = Counter()
        self.agreement: dict[str, float] = {}
        self._camera_positions: dict[str, np.ndarray] = {}
        self._frame_names: dict[str, str] = {}
        self._latest: dict[int, dict[str, Skeleton]] = {}
        self._next_tick_ns: int | None = None
        self._last_out_ns: int | None = None
        self._world_frame = "world"
        if calibration is not None:
            self.set_calibration(calibration)

    # ----------------------------------------------------------------------------- calibration
    def set_calibration(self, calibration: Calibration) -> None:
        """Camera positions for the depth, view and occlusion weights (optional)."""
        self._camera_positions = {}
        self._frame_names = {}
        for name, camera in calibration.cameras.items():
            self.set_camera(name, camera)

    def set_camera(self, name: str, camera: CameraCalibration) -> None:
        """Replace one camera's pose (a live update from ``calib``)."""
        self._camera_positions[name] = np.asarray(camera.translation, dtype=float)
        if camera.frame_id:
            self._frame_names[camera.frame_id] = name

    def _camera_name(self, frame_id: str) -> str:
        return self._frame_names.get(frame_id) or camera_from_frame(frame_id)

    # ----------------------------------------------------------------------------------- flow
    def update(self, group: SkeletonGroup) -> SkeletonGroup:
        """Take one tracker output; return the fused people (empty when no output is due)."""
        if group.frame_id:
            self._world_frame = group.frame_id
        newest = None
        for skeleton in group.skeletons:
            if skeleton.id < 0:
                self.drops["no track id"] += 1
                continue
            if not skeleton.marker_present.any():
                self.drops["no joint"] += 1
                continue
            camera = self._camera_name(skeleton.src_frame)
            per_camera = self._latest.setdefault(skeleton.id, {})
            previous = per_camera.get(camera)
            if previous is not None and previous.src_time_ns > skeleton.src_time_ns:
                self.drops["older than the camera's last detection"] += 1
                continue
            per_camera[camera] = skeleton
            newest = max(newest or skeleton.src_time_ns, skeleton.src_time_ns)
        out_ns = self._output_time(newest, group.stamp_ns)
        if out_ns is None:
            return SkeletonGroup(group.stamp_ns, self._world_frame, [])
        self._last_out_ns = out_ns
        return SkeletonGroup(out_ns, self._world_frame, self.merge(out_ns))

    def _output_time(self, newest_ns: int | None, stamp_ns: int) -> int | None:
        """When to output: the newest input stamp, a passed tick, or None (nothing new)."""
        rate = self.params.output_rate
        if rate <= 0:
            if newest_ns is None or (
                self._last_out_ns is not None and newest_ns <= self._last_out_ns
            ):
                return None
            return newest_ns
        newest_ns = stamp_ns if newest_ns is None else max(newest_ns, stamp_ns)
        period = round(1e9 / rate)
        if self._next_tick_ns is None:
            self._next_tick_ns = newest_ns - newest_ns % period
        if newest_ns < self._next_tick_ns:
            return None
        tick = self._next_tick_ns + (newest_ns - self._next_tick_ns) // period * period
        self._next_tick_ns = tick + period
        return tick

    # --------------------------------------------------------------------------------- fusion
    def merge(self, out_ns: int) -> list[Skeleton]:
        """Fuse every track seen within ``window`` of ``out_ns``; one skeleton per track."""
        params = self.params
        window_ns = round(params.window * 1e9)
        timeout_ns = round(params.track_timeout * 1e9)
        entries: list[tuple[int, str, Skeleton]] = []
        for track_id in list(self._latest):
            per_camera = self._latest[track_id]
            for camera in list(per_camera):
                age = out_ns - per_camera[camera].src_time_ns
                if age > timeout_ns:
                    del per_camera[camera]
                elif abs(age) <= window_ns:
                    entries.append((track_id, camera, per_camera[camera]))
            if not per_camera:
                del self._latest[track_id]
        if not entries:
            return []
        layout = entries[0][2].layout
        entries = [e for e in entries if e[2].layout.n_joints == layout.n_joints]
        track_ids = sorted({track_id for track_id, _, _ in entries})
        return self._fuse(entries, track_ids, layout, out_ns)

    def _fuse(
        self,
        entries: list[tuple[int, str, Skeleton]],
        track_ids: list[int],
        layout: Layout,
        out_ns: int,
    ) -> list[Skeleton]:
        """Fuse the detections of each track: robust weighted mean of positions, SO(3) mean."""
        params = self.params
        batch = self._stack(entries, track_ids, out_ns)
        weight = self._prior_weights(batch)
        positions = batch.positions
        fused = _weighted_median(positions, weight)
        axes = _axes(layout)
        if axes.has_front:
            up, front = axes.front(fused)
            if len(axes.pointers):
                forward = axes.forward(positions, up[:, None])
                flipped = np.einsum("mck,mk->mc", forward, front) < 0
                weight = weight * np.where(flipped, params.flipped_weight, 1.0)[..., None]
            if batch.known.any():
                weight = (
                    weight
                    * self._view_weights(fused, front, batch.cameras, batch.known, axes)[..., None]
                )
        if params.occlusion_radius > 0 and len(track_ids) > 1 and batch.known.any():
            weight = weight * self._occlusion(fused, positions, batch.cameras, batch.known, axes)
        # The positions do not change between iterations: their mask and zero-filled copy once.
        finite = np.isfinite(positions).all(axis=-1)
        filled = np.where(finite[..., None], positions, 0.0)
        for _ in range(params.iterations):
            residual = _distance(positions, fused)
            fused = _mean_of_filled(filled, finite, self._robust(weight, residual))
        residual = _distance(positions, fused)
        final = self._robust(weight, residual)
        self._update_agreement(residual, batch.camera_names)

        markers = batch.markers
        confidence = _weighted_mean(
            np.where(final > 0, batch.confidences, np.nan)[..., None], final
        )[..., 0]
        velocity = _weighted_mean(markers[..., 8:11], final)
        orientations = markers[..., 4:8]
        orientation = (
            _quaternion_mean(orientations, final)
            if np.isfinite(orientations).all(axis=-1).any()
            else None
        )
        # Every track's output rows at once; a joint is present where its fused position is.
        present = np.isfinite(fused).all(axis=-1)  # (M, J)
        rows = np.full((*present.shape, STATE_WIDTH), np.nan)
        keep = present[..., None]
        rows[..., 0] = np.where(present, confidence, np.nan)
        rows[..., 1:4] = np.where(keep, fused, np.nan)
        rows[..., 8:11] = np.where(keep, velocity, np.nan)
        if orientation is not None:
            rows[..., 4:8] = np.where(keep, orientation, np.nan)
        out = Skeleton.many_from_rows(
            rows,
            present,
            layout,
            skeleton_ids=track_ids,
            src_time_ns=out_ns,
            src_frame=self._world_frame,
        )
        whole = present.all(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            means = np.nanmean(rows[..., 0], axis=1) if whole.any() else whole
        for m, skeleton in enumerate(out):
            if whole[m]:
                skeleton.confidence = float(means[m])
            elif present[m].any():
                skeleton.confidence = float(np.nanmean(rows[m, present[m], 0]))
        return out

    def _robust(self, weight: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """Cauchy reweighting, and nothing beyond ``outlier_cutoff`` unless nothing is left."""
        params = self.params
        robust = weight / (1.0 + (residual / params.outlier_scale) ** 2)
        robust = np.where(np.isfinite(residual), robust, 0.0)
        inside = np.where(residual <= params.outlier_cutoff, robust, 0.0)
        return np.where((inside.sum(axis=1) > 0)[:, None], inside, robust)

    def _stack(
        self, entries: list[tuple[int, str, Skeleton]], track_ids: list[int], out_ns: int
    ) -> _Batch:
        """Pad the detections into ``(M, C, ...)`` arrays, brought to the output time."""
        params = self.params
        rows = {track_id: m for m, track_id in enumerate(track_ids)}
        counts = dict.fromkeys(track_ids, 0)
        slot_list: list[int] = []
        for track_id, _, _ in entries:
            slot_list.append(counts[track_id])
            counts[track_id] += 1
        row_list = [rows[track_id] for track_id, _, _ in entries]
        rows_of, slots = np.array(row_list), np.array(slot_list)
        shape = (len(track_ids), max(counts.values()))
        markers = np.full((*shape, entries[0][2].layout.n_joints, 20), np.nan)
        received = np.array([s.markers for _, _, s in entries])
        present = np.array([s.marker_present for _, _, s in entries])
        markers[rows_of, slots] = np.where(present[..., None], received, np.nan)
        ages = np.zeros(shape)
        ages[rows_of, slots] = [(out_ns - s.src_time_ns) * _NS for _, _, s in entries]
        positions = markers[..., 1:4]
        if params.extrapolate:
            dt = np.clip(ages, -params.max_extrapolation, params.max_extrapolation)
            velocities = markers[..., 8:11]
            positions = (
                positions + np.where(np.isfinite(velocities), velocities, 0.0) * dt[..., None, None]
            )
        cameras = np.full((*shape, 3), np.nan)
        cameras[rows_of, slots] = [
            self._camera_positions.get(camera, _UNKNOWN_CAMERA) for _, camera, _ in entries
        ]
        names = [[""] * shape[1] for _ in range(shape[0])]
        for (_, camera, _), m, c in zip(entries, row_list, slot_list, strict=True):
            names[m][c] = camera
        return _Batch(markers, positions, ages, cameras, names)

    def _prior_weights(self, batch: _Batch) -> np.ndarray:
        """``(M, C, J)`` weights known before fusing: confidence, staleness, agreement, depth."""
        params = self.params
        weight = np.maximum(batch.confidences, params.confidence_floor) ** params.confidence_power
        weight = np.where(np.isfinite(batch.positions).all(axis=-1), weight, 0.0)
        weight = weight / (1.0 + (batch.ages / params.staleness_scale) ** 2)[..., None]
        scale = params.agreement_scale
        factors = {
            name: 1.0 / (1.0 + (error / scale) ** 2) for name, error in self.agreement.items()
        }
        agreement = np.array(
            [[factors.get(name, 1.0) for name in names] for names in batch.camera_names]
        )
        weight = weight * agreement[..., None]
        depth = _norm(batch.positions - batch.cameras[:, :, None])
        depth_weight = (1.0 + params.depth_gain * depth) ** -2
        return np.where(batch.known[..., None], weight * depth_weight, weight)

    def _view_weights(
        self,
        fused: np.ndarray,
        front: np.ndarray,
        cameras: np.ndarray,
        known: np.ndarray,
        axes: _BodyAxes,
    ) -> np.ndarray:
        """``(M, C)`` weight of each camera's view: 1 from the front, down to the back."""
        params = self.params
        to_camera = cameras - fused[:, None, axes.root]
        to_camera /= _norm(to_camera)[..., None]
        cosine = np.einsum("mk,mck->mc", front, to_camera)
        view = np.maximum(params.view_weight_min, ((1.0 + cosine) / 2.0) ** params.view_power)
        return np.where(known & np.isfinite(view), view, 1.0)

    def _occlusion(
        self,
        fused: np.ndarray,
        positions: np.ndarray,
        cameras: np.ndarray,
        known: np.ndarray,
        axes: _BodyAxes,
    ) -> np.ndarray:
        """``(M, C, J)`` factor for joints whose camera ray passes another person's torso.

        A torso point ``q`` of another track blocks the ray from camera ``o`` to joint ``p``
        when it lies within ``occlusion_radius`` of the ray and between ``o`` and ``p``.
        """
        params = self.params
        n_tracks = len(fused)
        points = fused[:, axes.torso].reshape(-1, 3)  # (Q, 3), Q = M × torso joints
        owner = np.repeat(np.arange(n_tracks), len(axes.torso))
        ray = positions - cameras[:, :, None]  # (M, C, J, 3)
        length = _norm(ray)
        direction = ray / length[..., None]
        rel = points[None, None] - cameras[:, :, None]  # (M, C, Q, 3)
        along = np.einsum("mcjk,mcqk->mcjq", direction, rel)  # (M, C, J, Q)
        radius = params.occlusion_radius
        with np.errstate(invalid="ignore"):
            # Squared distance of each torso point to each ray, |rel|² - along², decides
            # "within the radius" except within 1e-9 m² of it, where the distance is computed
            # as the point minus its projection (the exact form) for those pairs only.
            across_sq = np.add.reduce(rel * rel, axis=-1)[:, :, None, :] - along * along
            close = across_sq < radius * radius
            unsure = np.abs(across_sq - radius * radius) < 1e-9
            if unsure.any():
                m, c, j, q = np.nonzero(unsure)
                closest = along[m, c, j, q][:, None] * direction[m, c, j]
                close[m, c, j, q] = _norm(rel[m, c, q] - closest) < radius
            blocking = (
                close
                & (along > 0)
                & (along < length[..., None] - radius)
                & (owner != np.arange(n_tracks)[:, None, None, None])
            )
        occluded = blocking.any(axis=-1) & known[..., None]
        return np.where(occluded, params.occlusion_weight, 1.0)

    def _update_agreement(self, residual: np.ndarray, camera_names: list[list[str]]) -> None:
        """Fold each camera's mean joint distance to the fused skeletons into its agreement."""
        alpha = self.params.agreement_smoothing
        per_camera: dict[str, list[float]] = {}
        finite = np.isfinite(residual)
        mean = np.where(finite, np.minimum(residual, 0.5), 0.0).sum(-1) / np.maximum(
            finite.sum(-1), 1
        )
        seen = finite.any(axis=-1).tolist()
        for names, row, seen_row in zip(camera_names, mean.tolist(), seen, strict=True):
            for name, value, any_seen in zip(names, row, seen_row, strict=True):
                if name and any_seen:
                    per_camera.setdefault(name, []).append(value)
        for name, errors in per_camera.items():
            value = float(np.mean(errors)) if len(errors) > 1 else errors[0]
            previous = self.agreement.get(name)
            self.agreement[name] = (
                value if previous is None else previous + alpha * (value - previous)
            )
