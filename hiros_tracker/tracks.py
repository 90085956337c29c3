"""The tracker's state: every track's fields stacked, one array per field (row = track).

A frame predicts and compares every track and updates a few; with the fields stacked, that is
a handful of compiled calls on whole arrays (``kernels``) instead of Python loops over track
objects, whose small numpy calls (stacking, copies, per-track sums) cost the tracker most of
its time. Rows are tracks in creation order, the order matching sees them in (ties in the
assignment resolve alike); removing tracks compacts the rows. Arrays keep spare rows
(``capacity``) so that a new track seldom reallocates: only rows ``[:n]`` are tracks.

Per track (``J`` joints, ``C`` cameras, ``R`` record slots):

- ``positions`` ``(J, 3)``: the smoothed pose at ``time_ns``;
- ``velocities`` ``(J, 3)``: least-squares slopes of the recent detections with one intercept
  per camera (a constant offset between two cameras' calibrations must not read as motion),
  kept as running sums ``sums`` ``(C, J, 9)`` (terms n, t, t², p, t·p; t from ``epoch_ns``)
  over the velocity window; ``velocity`` ``(3,)`` the body's pooled velocity;
- the detections inside the window, a ring of ``R`` slots: ``record_ns``, ``record_camera``,
  ``record_terms`` ``(R, J, 9)`` from ``record_start``, ``record_count`` long (their terms
  leave the sums when they leave the window);
- ``n_cameras``: how many camera codes the sums span (1 + the highest code seen, at least 1);
- ``body_ids`` ``(C,)``/``seen`` ``(C,)``: each camera's last body id for the track;
- counters and stamps (ns): ``hits``, ``confirmed``, ``born_ns``, ``time_ns``, ``last_hit_ns``,
  ``epoch_ns``, ``facing`` (log-odds that its sides are right) and ``facing_ns``, ``doubt``
  (its cameras' evidence against its sides while it walks backwards, ``facing.DOUBT_LIMIT``);
- ``limbs`` ``(J,)``: the mean length of the link ending at each joint over the track's
  detections (0 before a detection shows it), ``limb_count`` ``(J,)`` how many it averages,
  capped at ``LIMB_MEMORY`` (a running mean that still follows a slow change): the body's
  shape, which tells a person returning from another one (``Tracker``'s re-identification);
- ``sides`` ``(3,)``: the held left-right axis its detections' sides are held to (m; 0 before
  the first, and after a relabelling by ``relabel``), ``labels.hold_axes``; per camera, the
  left-right axis of its last detection as labelled, ``camera_sides`` ``(C, 3)`` (0: none),
  at ``camera_sides_ns`` ``(C,)``;
- ``camera_verdicts`` ``(C,)``: the view evidence each camera's last detection gave on the
  track's sides (log-odds, ``facing``), at ``camera_verdicts_ns`` ``(C,)`` (0: none);
- ``votes``/``mirrored``: Python, for the mirror-vote fallback only (camera -> (ns, flips)).
"""

from __future__ import annotations

import numpy as np

from hiros_tracker import kernels
from hiros_tracker.kernel_args import TrackFields

__all__ = ["TrackTable"]

_RECORDS = 32
"""Initial record slots per track (3 cameras x 30 Hz fill ~23 in a 0.25 s window)."""

LIMB_MEMORY = 300
"""Detections a track's limb lengths average at most (10 s of one camera at 30 Hz)."""

_FLOAT_FIELDS = (
    "positions", "velocities", "velocity", "facing", "sums", "limbs", "limb_count", "sides",
    "doubt", "camera_sides", "camera_verdicts",
)  # fmt: skip
_INT_FIELDS = (
    "ids", "born_ns", "time_ns", "last_hit_ns", "epoch_ns", "facing_ns", "hits", "n_cameras",
    "body_ids", "record_ns", "record_camera", "record_start", "record_count", "camera_sides_ns",
    "camera_verdicts_ns",
)  # fmt: skip
_BOOL_FIELDS = ("confirmed", "seen")
_CAMERA_FIELDS = (
    "sums", "body_ids", "seen", "camera_sides", "camera_sides_ns", "camera_verdicts",
    "camera_verdicts_ns",
)  # fmt: skip
_ROW_FIELDS = (*_FLOAT_FIELDS, *_INT_FIELDS, *_BOOL_FIELDS, "record_terms")


class TrackTable:
    """All tracks' state (see the module docstring); ``n`` tracks in rows ``[:n]``."""

    def __init__(self, n_joints: int, n_cameras: int = 1, capacity: int = 8) -> None:
        self.n = 0
        self.n_joints = n_joints
        self._fields: TrackFields | None = None
        self.votes: list[dict[int, tuple[int, np.ndarray]]] = []
        self.mirrored: list[set[int]] = []
        joints, cameras, records = n_joints, max(n_cameras, 1), _RECORDS
        shapes = {
            "positions": (joints, 3), "velocities": (joints, 3),
            "velocity": (3,), "sums": (cameras, joints, 9), "body_ids": (cameras,),
            "seen": (cameras,), "record_ns": (records,), "record_camera": (records,),
            "record_terms": (records, joints, 9), "limbs": (joints,),
            "limb_count": (joints,), "sides": (3,), "camera_sides": (cameras, 3),
            "camera_sides_ns": (cameras,), "camera_verdicts": (cameras,),
            "camera_verdicts_ns": (cameras,),
        }  # fmt: skip
        for name in _ROW_FIELDS:
            dtype = float if name in _FLOAT_FIELDS or name == "record_terms" else np.int64
            dtype = bool if name in _BOOL_FIELDS else dtype
            self._set(name, np.zeros((capacity, *shapes.get(name, ())), dtype=dtype))

    positions: np.ndarray
    velocities: np.ndarray
    velocity: np.ndarray
    facing: np.ndarray
    sums: np.ndarray
    ids: np.ndarray
    born_ns: np.ndarray
    time_ns: np.ndarray
    last_hit_ns: np.ndarray
    epoch_ns: np.ndarray
    facing_ns: np.ndarray
    hits: np.ndarray
    n_cameras: np.ndarray
    body_ids: np.ndarray
    record_ns: np.ndarray
    record_camera: np.ndarray
    record_start: np.ndarray
    record_count: np.ndarray
    confirmed: np.ndarray
    seen: np.ndarray
    record_terms: np.ndarray
    limbs: np.ndarray
    limb_count: np.ndarray
    sides: np.ndarray
    doubt: np.ndarray
    camera_sides: np.ndarray
    camera_sides_ns: np.ndarray
    camera_verdicts: np.ndarray
    camera_verdicts_ns: np.ndarray

    @property
    def capacity(self) -> int:
        """Rows allocated."""
        return len(self.ids)

    @property
    def camera_capacity(self) -> int:
        """Camera codes the per-camera fields hold."""
        return self.sums.shape[1]

    def add(self, track_id: int, positions: np.ndarray, time_ns: int) -> int:
        """Start a tentative track at a detection's pose; return its row."""
        if self.n == self.capacity:
            self._grow_rows()
        row = self.n
        self.n += 1
        for name in _ROW_FIELDS:
            getattr(self, name)[row] = 0
        self.ids[row] = track_id
        self.positions[row] = positions
        self.born_ns[row] = self.time_ns[row] = self.last_hit_ns[row] = time_ns
        self.epoch_ns[row] = self.facing_ns[row] = time_ns
        self.n_cameras[row] = 1
        self.votes.append({})
        self.mirrored.append(set())
        return row

    def keep(self, mask: np.ndarray) -> None:
        """Remove the tracks not in ``mask`` ``(n,)``, keeping the others' order."""
        kept = int(mask.sum())
        for name in _ROW_FIELDS:
            field = getattr(self, name)
            field[:kept] = field[: self.n][mask]
        self.votes = [v for v, k in zip(self.votes, mask.tolist(), strict=True) if k]
        self.mirrored = [m for m, k in zip(self.mirrored, mask.tolist(), strict=True) if k]
        self.n = kept

    def ensure_cameras(self, n_cameras: int) -> None:
        """Widen the per-camera fields to hold camera codes ``< n_cameras``."""
        if n_cameras > self.camera_capacity:
            for name in _CAMERA_FIELDS:
                self._widen(name, 1, n_cameras)

    def grow_records(self) -> None:
        """Double the record slots (a track's ring is full), unrolling every ring to start at 0."""
        slots = self.record_ns.shape[1]
        order = (self.record_start[:, None] + np.arange(slots)) % slots
        for name in ("record_ns", "record_camera", "record_terms"):
            field = getattr(self, name)
            index = order.reshape(order.shape + (1,) * (field.ndim - 2))
            self._set(name, np.take_along_axis(field, index, 1))
            self._widen(name, 1, 2 * slots)
        self.record_start[:] = 0

    def hit_fields(self) -> TrackFields:
        """The fields the frame kernels read and change in place (``kernels.hit_frame``).

        Kept until a field is replaced by a larger array (``_set``), so that a frame does not
        gather 24 fields anew.
        """
        if self._fields is None:
            self._fields = TrackFields(
                **{name: getattr(self, name) for name in TrackFields._fields}
            )
        return self._fields

    def _set(self, name: str, field: np.ndarray) -> None:
        """Replace field ``name`` by a new array (the kernels' bundle is made anew)."""
        setattr(self, name, field)
        self._fields = None

    def learn_limbs(self, rows: np.ndarray, positions: np.ndarray, parents: np.ndarray) -> None:
        """Fold detections' link lengths into their tracks' running means.

        Args:
            rows: ``(U,)`` distinct track rows.
            positions: ``(U, J, 3)`` their detections (NaN where absent), in any labelling:
                the left and right links of a body are alike, and a mirrored detection only
                exchanges them.
            parents: ``(J,)`` each joint's parent, ``-1`` at the root.

        """
        has_parent = parents >= 0
        lengths = np.full(positions.shape[:2], np.nan)
        lengths[:, has_parent] = np.linalg.norm(
            positions[:, has_parent] - positions[:, parents[has_parent]], axis=-1
        )
        seen = np.isfinite(lengths)
        count = np.minimum(self.limb_count[rows] + seen, LIMB_MEMORY)
        step = np.where(seen, (lengths - self.limbs[rows]) / np.maximum(count, 1), 0.0)
        self.limbs[rows] += step
        self.limb_count[rows] = count

    def relabel(self, row: int, permutation: np.ndarray) -> None:
        """Reorder a track's joints (swap the sides of some parts); votes are the caller's.

        Its held left-right axes (the track's and each camera's) and its cameras' verdicts on
        its sides are forgotten (the pose's axis is used until detections give them anew).
        """
        kernels.relabel(self.hit_fields(), row, permutation)
        self.sides[row] = 0.0
        self.camera_sides[row] = 0.0
        self.camera_verdicts_ns[row] = 0

    def _grow_rows(self) -> None:
        for name in _ROW_FIELDS:
            self._widen(name, 0, 2 * self.capacity)

    def _widen(self, name: str, axis: int, size: int) -> None:
        """Zero-pad field ``name`` along ``axis`` to ``size``."""
        field = getattr(self, name)
        shape = list(field.shape)
        shape[axis] = size
        grown = np.zeros(shape, dtype=field.dtype)
        grown[tuple(slice(0, n) for n in field.shape)] = field
        self._set(name, grown)
