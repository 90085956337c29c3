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

    w = conf^CONFIDENCE_POWER            SDK confidence (occluded joints come as LOW)
        × (1 + DEPTH_GAIN · depth)^-2    depth noise grows ~linearly with distance (variance ²)
        × view(cos θ)                     θ: angle between the body's front and the camera
        × flipped                         ``FLIPPED_WEIGHT`` if the detection's feet and nose
                                          point backwards (a front/back flip), which is first
                                          reflected back through its frontal plane
        × occlusion                       another person's torso on the camera's ray
        × staleness                       1 / (1 + (Δt / STALENESS_SCALE)²)

then the robust mean multiplies by a Cauchy weight ``1 / (1 + (r / OUTLIER_SCALE)²)`` of each
joint's distance ``r`` to the current estimate (0 beyond ``OUTLIER_CUTOFF``), starting from the
weighted median, so that one camera's flipped limb or swapped leg does not pull the result.
``r`` is the mean over the joint's limb in that detection: a camera's limb
is weighed whole, so the fused limb is one weighted mean of the cameras' limbs rather than
joints stitched from different cameras (which bent limbs: 1-2 frame joint-angle spikes).

Output: world frame, ``id`` = track id, ``src_time`` = output time, ``src_frame`` = world frame;
positions, orientations, confidences (weighted mean) and velocities (weighted mean) per joint.
Shapes: ``M`` tracks, ``C`` detections per track (padded), ``J`` joints; metres, seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import TypeVar, get_type_hints

import numpy as np

from hiros_core.accounting import Accounted, Drops
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.layouts import AZURE_KINECT, Layout
from hiros_core.model import (
    BOX_WIDTH,
    Skeleton,
    SkeletonGroup,
    SkeletonRows,
    camera_from_frame,
    link_rows,
    stack_rows,
)
from hiros_merger import kernels
from hiros_merger.kernel_args import (
    BodyLayout,
    CameraTable,
    FuseSettings,
    RobustSettings,
    StoredDetections,
    WeightSettings,
)
from hiros_merger.latest import LatestDetections

__all__ = [
    "CONFIDENCE_FLOOR",
    "CONFIDENCE_POWER",
    "DEPTH_GAIN",
    "FLIPPED_WEIGHT",
    "LIMB_CUTOFF",
    "MAX_JUMP",
    "OBLIQUE_GAIN",
    "OCCLUSION_RADIUS",
    "OCCLUSION_WEIGHT",
    "OTHER_FRAME",
    "OUTLIER_CUTOFF",
    "OUTLIER_SCALE",
    "ROBUST_ITERATIONS",
    "STALENESS_SCALE",
    "Merger",
    "MergerParams",
]

T = TypeVar("T")

UP_TOLERANCE = math.radians(15.0)
"""Largest angle between the people's mean vertical and the world's z axis for which the world
is taken to be gravity-aligned (z up, ``Merger.up``)."""
_Z_UP = np.array([0.0, 0.0, 1.0])

OTHER_FRAME = "not in the world frame"
"""Drop reason of the detections of an input group in another frame than the world's."""

# The fusion's settings no setup needs to change (they were parameters of the merger node):
CONFIDENCE_POWER = 2.0
"""Exponent of the SDK confidence in a joint's weight: squared, as a variance weighs."""
CONFIDENCE_FLOOR = 0.05
"""Smallest confidence used in the weight: a joint the SDK gives NONE still counts a little."""
STALENESS_SCALE = 0.05
"""Seconds; a detection of age Δt weighs ``1 / (1 + (Δt / STALENESS_SCALE)²)``: a frame older
than the others (one 30 Hz period and more) counts for less than a fresh one."""
DEPTH_GAIN = 0.33
"""Per metre; a joint's depth weight is ``(1 + DEPTH_GAIN · depth)^-2``: a body-tracking SDK's
noise grows about linearly with the distance, its variance with the square."""
OBLIQUE_GAIN = 1.0
"""The view weight is ``1 / (1 + OBLIQUE_GAIN · |sin θ|)²``, θ the angle between the body's
front and the direction to the camera: a body seen from the side has its limbs along the
camera's noisy depth axis, while the back view is as precise as the front (flips have
``FLIPPED_WEIGHT``); down to 1/4 exactly at the side."""
FLIPPED_WEIGHT = 0.5
"""Weight factor of a detection whose feet and nose point backwards against the body's front:
a front/back flip the tracker relabelled but whose limbs are still reflected through the
frontal plane. It is reflected back through the plane through its pelvis (normal: the front
of the track's detections, across the scene's up, ``Merger.up``), and weighs this much: the
plane is itself an estimate."""
OCCLUSION_RADIUS = 0.2
"""Metres; a joint whose camera ray passes this close to another person's torso, in front of
the joint, is occluded (about a torso's half width)."""
OCCLUSION_WEIGHT = 0.5
"""Weight factor of a joint behind another person's torso (``OCCLUSION_RADIUS``)."""
OUTLIER_SCALE = 0.4
"""Metres; Cauchy scale of the robust mean. The robust mean weighs each camera's limb whole,
by its mean joint distance to the estimate: an SDK's errors are coherent along a limb, and
joints taken from different cameras' versions of one limb bend it (angle spikes) even when
each camera has the angle right."""
ROBUST_ITERATIONS = 3
"""Reweighting iterations of the robust mean, from the weighted median (a numerical choice)."""
OUTLIER_CUTOFF = 0.4
"""Metres; a joint (its limb's mean distance) farther than this from the estimate gets no
weight, as long as another camera's joint is within it: a flipped limb is out, not just less."""
LIMB_CUTOFF = 0.8
"""Metres; a camera's limb (torso, head, each arm, each leg) one of whose joints is this far
from the estimate gets no weight (a single joint's blunder), as long as another camera's is
within it."""
MAX_JUMP = 1.0
"""Seconds; input stamped this much before the newest input so far restarts the merger (its
detections and output clock, counted ``stamps went back``): the earlier input was stamped far
ahead by mistake, or its source restarted (a replayed recording looping). Without it every
later detection would be older than the one kept and dropped, for good. Tracker outputs are
never a second late."""


@dataclass
class MergerParams:
    """Merger parameters (field names = ROS parameter names of the ``merger`` node).

    Attributes:
        window: seconds; a camera's detection older than this at the output time is not fused.
        output_rate: Hz; 0 outputs on each input at its newest stamp.
        max_extrapolation: seconds; each detection is brought to the output time with its
            joint velocities, over this much time at most (0 turns extrapolation off).
        track_timeout: seconds; a track unseen this long is forgotten.

    """

    window: float = 0.1
    output_rate: float = 0.0
    max_extrapolation: float = 0.1
    track_timeout: float = 1.0


@cache
def _body_layout(layout: Layout) -> BodyLayout:
    """What the weights and the limbs need of a layout, as the kernels' arrays.

    Its named body joints (``Layout.body``) and its limbs (:func:`_limbs`); built once per layout.
    """
    joints = layout.body
    left, right = np.array(joints.left), np.array(joints.right)
    torso = np.array(joints.torso)
    head = [joints.head] if joints.head else []
    pointers = np.array([*joints.feet, *head], dtype=np.int64).reshape(-1, 2)
    return BodyLayout(
        root=joints.root,
        neck=joints.neck,
        left=left,
        right=right,
        torso=torso,
        pointers=pointers,
        has_front=joints.neck >= 0 and bool((left >= 0).all() and (right >= 0).all()),
        groups=_limbs(layout, torso),
        link_parents=np.asarray(layout.link_parents, dtype=np.intp),
        link_children=np.asarray(layout.link_children, dtype=np.intp),
    )


def _limbs(layout: Layout, torso: np.ndarray) -> np.ndarray:
    """``(J,)`` limb index of each joint: 0 for the torso, then one per subtree hanging off it.

    A body-tracking SDK fits one model per frame, so its mistakes (a flipped or swapped leg,
    an occluded arm it guessed) and its noise are coherent along a limb: the merger weighs a
    camera's limb as a whole, so that a fused limb is not stitched from different cameras'
    joints (which bends it even when every camera has its angles right).
    """
    parents = layout.parents
    in_torso = set(torso.tolist())
    groups = np.zeros(layout.n_joints, dtype=np.int64)
    starts: dict[int, int] = {}
    for j in range(layout.n_joints):
        if j in in_torso:
            continue
        start = j
        while parents[start] >= 0 and parents[start] not in in_torso:
            start = parents[start]
        groups[j] = starts.setdefault(start, len(starts) + 1)
    return groups


def _read(bundle: type[T], params: MergerParams, **given: object) -> T:
    """``bundle``'s fields from ``params``' of the same names, as the declared types.

    The compiled kernels are built for those types: an ``int`` where a float is declared (a
    YAML ``1``, say) would compile them again for it. Fields in ``given`` are taken as given.
    """
    declared = {name: kind for name, kind in get_type_hints(bundle).items() if name not in given}
    return bundle(**{name: kind(getattr(params, name)) for name, kind in declared.items()}, **given)


def _fuse_settings(params: MergerParams) -> FuseSettings:
    """The fusion's parameters as the kernels read them."""
    weights = _read(
        WeightSettings,
        params,
        confidence_power=CONFIDENCE_POWER,
        confidence_floor=CONFIDENCE_FLOOR,
        staleness_scale=STALENESS_SCALE,
        depth_gain=DEPTH_GAIN,
        flipped_weight=FLIPPED_WEIGHT,
        oblique_gain=OBLIQUE_GAIN,
        occlusion_radius=OCCLUSION_RADIUS,
        occlusion_weight=OCCLUSION_WEIGHT,
    )
    robust = _read(
        RobustSettings,
        params,
        iterations=ROBUST_ITERATIONS,
        outlier_scale=OUTLIER_SCALE,
        outlier_cutoff=OUTLIER_CUTOFF,
        limb_cutoff=LIMB_CUTOFF,
    )
    return FuseSettings(weights, robust)


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


class Merger(Accounted):
    """Fuses each track's camera detections into one skeleton (see the module docstring).

    Attributes:
        params: the parameters (the fusion's are read once, at a layout's first fusion, and
            again after ``set_params``).
        drops: reason -> count of input left out (detections; a frame is never dropped
            whole: each ``update`` is processed, see ``Accounted``).

    """

    def __init__(
        self, params: MergerParams | None = None, calibration: Calibration | None = None
    ) -> None:
        warm_up()
        self.params = params or MergerParams()
        self.drops = Drops()
        self._latest = LatestDetections()
        self._cameras: dict[str, int] = {}  # camera name -> index into the arrays below
        self._camera_positions = np.empty((0, 3))  # (K, 3), NaN: unknown
        self._frame_names: dict[str, str] = {}  # calibrated frame id -> camera name
        self._frame_cameras: dict[str, int] = {}  # frame id -> camera index, as found
        self._next_tick_ns: int | None = None
        self._last_out_ns: int | None = None
        self._newest_in_ns: int | None = None
        self._world_frame = "world"
        self._world_frame_set = False  # by the calibration, or else the first framed input
        self._constants: dict[str, tuple] = {}  # layout name -> ``_fusion_constants``
        self._verticals = np.zeros(3)  # sum of the fused people's unit root -> neck vectors
        if calibration is not None:
            self.set_calibration(calibration)

    def set_params(self, params: MergerParams) -> None:
        """Fuse with ``params`` from the next update on (the tracks are kept)."""
        self.params = params
        self._constants.clear()  # they hold the parameters (``_fusion_constants``)

    # ----------------------------------------------------------------------------- calibration
    def set_calibration(self, calibration: Calibration) -> None:
        """Camera positions (depth, view and occlusion weights) and the input's world frame.

        Optional: without a calibration, the first input's frame is the world.
        """
        self._world_frame, self._world_frame_set = calibration.world_frame, True
        self._verticals = np.zeros(3)  # (the world may have turned)
        self._camera_positions[:] = np.nan
        self._frame_names = {}
        self._frame_cameras = {}
        for name, camera in calibration.cameras.items():
            self.set_camera(name, camera)

    def set_camera(self, name: str, camera: CameraCalibration) -> None:
        """Replace one camera's pose (a live update from ``calib``)."""
        index = self._camera_index(name)  # (may grow the array)
        self._camera_positions[index] = camera.translation
        if camera.frame_id:
            self._frame_names[camera.frame_id] = name
            self._frame_cameras = {}

    def _camera_index(self, name: str) -> int:
        """The camera's index into the per-camera arrays (a new camera's position unknown)."""
        index = self._cameras.get(name)
        if index is None:
            index = self._cameras[name] = len(self._cameras)
            self._camera_positions = np.vstack([self._camera_positions, np.full(3, np.nan)])
        return index

    def _camera_of(self, frame_id: str) -> int:
        """Index of the camera a detection's ``src_frame`` belongs to."""
        index = self._frame_cameras.get(frame_id)
        if index is None:
            name = self._frame_names.get(frame_id) or camera_from_frame(frame_id)
            index = self._frame_cameras[frame_id] = self._camera_index(name)
        return index

    # ----------------------------------------------------------------------------------- flow
    def update(self, group: SkeletonGroup) -> SkeletonGroup:
        """Take one tracker output; return the fused people (empty when no output is due)."""
        merged = self._merged(group)
        self.processed += 1  # (once it went through: a frame whose merge raised is not)
        return merged

    def _merged(self, group: SkeletonGroup) -> SkeletonGroup:
        if not self._in_world_frame(group):
            self.drops.detections(OTHER_FRAME, len(group.skeletons))
            return SkeletonGroup(group.stamp_ns, self._world_frame, [])
        if group.skeletons and self._went_back(group.stamp_ns):
            self.drops.detections("stamps went back (restarted)")  # the held ones forgotten
            self._latest = LatestDetections()
            self._next_tick_ns = self._last_out_ns = None
        newest = self._store(group.skeletons) if group.skeletons else None
        out_ns = self._output_time(newest, group.stamp_ns)
        if out_ns is None:
            return SkeletonGroup(group.stamp_ns, self._world_frame, [])
        self._last_out_ns = out_ns
        return SkeletonGroup(out_ns, self._world_frame, self.merge(out_ns))

    def _in_world_frame(self, group: SkeletonGroup) -> bool:
        """Whether ``group`` is in the world frame (a frame-less group is taken as it is).

        The tracker's output is; a camera topic wired to the merger by mistake is not, and
        its detections, in a camera's frame, would be fused with the world's.
        """
        if not group.frame_id:
            return True
        if not self._world_frame_set:
            self._world_frame, self._world_frame_set = group.frame_id, True
        return group.frame_id == self._world_frame

    def _went_back(self, stamp_ns: int) -> bool:
        """Whether input stamped ``stamp_ns`` lies ``MAX_JUMP`` before the newest so far."""
        newest = self._newest_in_ns
        back = newest is not None and stamp_ns < newest - round(MAX_JUMP * 1e9)
        if newest is None or back or stamp_ns > newest:
            self._newest_in_ns = stamp_ns
        return back

    def _store(self, skeletons: list[Skeleton]) -> int | None:
        """Keep each usable detection as its track's newest from its camera (else counted).

        Returns the newest stamp kept (None: none). The detections' rows are copied into the
        store in one go from the frame's stack (the tracker's output is one already, so
        ``stack_rows`` copies nothing); a frame mixing joint counts is stored one by one.
        """
        size = len(skeletons[0].markers)
        if any(len(skeleton.markers) != size for skeleton in skeletons):
            stack = None
            has_joints = [bool(skeleton.marker_present.any()) for skeleton in skeletons]
        else:
            stack = stack_rows(skeletons)
            has_joints = stack.marker_present.any(axis=1).tolist()
        latest = self._latest
        taken: dict[int, int] = {}  # slot -> row of the stack (the last one of a slot wins)
        newest = None
        for row, skeleton in enumerate(skeletons):
            if skeleton.id < 0:
                self.drops.detections("no track id")
                continue
            if not has_joints[row]:
                self.drops.detections("no joint")
                continue
            camera = self._camera_of(skeleton.src_frame)
            stamp_ns = skeleton.src_time_ns
            slot = latest.claim(skeleton.id, camera, stamp_ns, skeleton.layout)
            if slot is None:
                self.drops.detections("older than the camera's last detection")
                continue
            if stack is None:
                latest.write([slot], skeleton.markers[None], skeleton.marker_present[None])
            else:
                taken[slot] = row
            if newest is None or stamp_ns > newest:
                newest = stamp_ns
        if len(taken) == len(skeletons):  # every row, in order: the stack as it is
            latest.write(list(taken), stack.markers, stack.marker_present)
        elif taken:
            rows = list(taken.values())
            latest.write(list(taken), stack.markers[rows], stack.marker_present[rows])
        return newest

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
        selected, layout = self._latest.select(out_ns, window_ns, timeout_ns)
        if layout is None:
            return []
        return self._fuse(selected, layout, out_ns)

    def _fuse(self, selected: list[int], layout: Layout, out_ns: int) -> list[Skeleton]:
        """Fuse the detections of each track: robust weighted mean of positions, SO(3) mean.

        The positions, weights, means and output rows are one compiled kernel
        (``kernels.merge``, the module docstring's formulas) reading the ``selected`` slots
        of the stored detections; the orientations' eigen-decomposition stays with numpy.
        """
        latest = self._latest
        stored = StoredDetections(
            latest.rows, latest.present, latest.stamps, latest.tracks, latest.cameras
        )
        cameras = CameraTable(self._camera_positions)
        settings, body = self._fusion_constants(layout)
        selection = np.array(selected, dtype=np.int64)
        frame = kernels.merge(stored, selection, out_ns, cameras, settings, body, self.up)
        rows, present = frame.rows, frame.present
        if body.neck >= 0:
            self._add_verticals(rows[:, body.root, 1:4], rows[:, body.neck, 1:4])
        links, link_present = frame.links, frame.link_present
        if frame.oriented:
            quaternions = self._stored_orientations(frame.table, layout.n_joints)
            rows[..., 4:8] = np.where(
                present[..., None], _quaternion_mean(quaternions, frame.final), np.nan
            )
            links, link_present = link_rows(rows, present, layout)
        boxes = np.full((len(rows), BOX_WIDTH), np.nan)
        return SkeletonRows(rows, present, links, link_present, boxes).skeletons(
            frame.track_ids.tolist(), out_ns, self._world_frame, layout, frame.confidences.tolist()
        )

    @property
    def up(self) -> np.ndarray:
        """``(3,)`` the scene's up: the world's z, or the people's mean vertical (NaN: none yet).

        People stand and walk upright, so the mean of their fused unit root -> neck vectors
        points up whatever frame the world is. Where it lies within ``UP_TOLERANCE`` of the
        world's z axis the world is the gravity-aligned one (REP-103, the calibration levels
        it on the floor and the people) and z is taken: the mean vertical itself leans by the
        SDK's biases of the pelvis and neck (1-4 degrees), which tilt a flip's reflection plane
        (``weights.reflect``). Otherwise (the world is a camera's frame) the mean is taken.
        """
        norm = np.linalg.norm(self._verticals)
        if not norm > 0:
            return np.full(3, np.nan)
        mean = self._verticals / norm
        return _Z_UP if mean[2] >= math.cos(UP_TOLERANCE) else mean

    def _add_verticals(self, roots: np.ndarray, necks: np.ndarray) -> None:
        """Add the fused people's unit root -> neck vectors ``(M, 3)`` to the scene's up."""
        vertical = necks - roots
        norm = np.linalg.norm(vertical, axis=1, keepdims=True)
        finite = np.isfinite(norm[:, 0]) & (norm[:, 0] > 0)
        self._verticals += (vertical[finite] / norm[finite]).sum(axis=0)

    def _fusion_constants(self, layout: Layout) -> tuple[FuseSettings, BodyLayout]:
        """``kernels.merge``'s settings and body bundles for ``layout``, built once per layout.

        The parameters are read on a layout's first fusion (as the optimizer and the filter
        read theirs once), and converted to the types the compiled kernel was built for.
        """
        constants = self._constants.get(layout.name)
        if constants is None:
            settings = _fuse_settings(self.params)
            constants = self._constants[layout.name] = (settings, _body_layout(layout))
        return constants

    def _stored_orientations(self, table: np.ndarray, n_joints: int) -> np.ndarray:
        """``(M, C, J, 4)`` the detections' orientations by ``table`` slot, NaN where absent."""
        latest = self._latest
        valid = (table >= 0)[..., None] & latest.present[table, :n_joints]
        return np.where(valid[..., None], latest.rows[table, :n_joints, 4:8], np.nan)


_WARM = False


def warm_up() -> None:
    """Compile the fusion kernel (or load it from numba's disk cache) once per process.

    The first ``Merger`` of a process calls it, so that a live node pays the cost (a fraction
    of a second from the cache, about 10 s on the very first run after an install or a kernel
    change) before its first frame rather than on it.
    """
    global _WARM  # noqa: PLW0603 - once per process
    if _WARM:
        return
    _WARM = True
    merger = Merger(
        MergerParams(),
        Calibration(
            "warm_up",
            "world",
            {"warm_up": CameraCalibration(frame_id="warm_up", translation=np.zeros(3))},
        ),
    )
    positions = np.linspace(0.0, 1.0, AZURE_KINECT.n_joints * 3).reshape(-1, 3) + np.array(
        [0.0, 0.0, 3.0]
    )
    skeletons = [
        Skeleton.from_positions(
            positions + np.array([track, 0.0, 0.0]),
            AZURE_KINECT,
            skeleton_id=track,
            src_time_ns=1_000_000_000,
            src_frame="warm_up",
        )
        for track in (0, 1)
    ]
    merger.update(SkeletonGroup(1_000_000_000, "world", skeletons))
