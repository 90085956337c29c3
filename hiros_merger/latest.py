"""The merger's memory: each track's newest detection per camera, kept as stacked arrays.

The merger fuses the same few detections again at every output (each camera's newest of each
track). Copying a detection's rows once, on arrival, into preallocated ``(S, J, 20)`` arrays
lets the fusion kernel read them by slot index: no stacking of skeletons at every output.
"""

from __future__ import annotations

import numpy as np

from hiros_core.layouts import Layout
from hiros_core.model import STATE_WIDTH, Skeleton

__all__ = ["LatestDetections"]


class LatestDetections:
    """Newest detection of each (track, camera) in slot ``s`` of stacked arrays.

    Attributes:
        rows: ``(S, J, 20)`` marker rows of each slot (``J`` the most joints seen; a slot of
            a smaller layout uses its first rows).
        present: ``(S, J)`` marker presence of each slot.
        stamps: ``(S,)`` ``src_time_ns`` of each slot's detection.
        tracks: ``(S,)`` track id of each slot.
        cameras: ``(S,)`` camera index of each slot.
        slots: track id -> camera index -> slot, both in order of first sight (the order
            the fusion sums over a track's cameras, kept for equal results).

    """

    def __init__(self, capacity: int = 16) -> None:
        self.rows = np.full((capacity, 0, STATE_WIDTH), np.nan)
        self.present = np.zeros((capacity, 0), dtype=bool)
        self.stamps = np.zeros(capacity, dtype=np.int64)
        self.tracks = np.zeros(capacity, dtype=np.int64)
        self.cameras = np.zeros(capacity, dtype=np.int64)
        self.slots: dict[int, dict[int, int]] = {}
        self._stamps: list[int] = [0] * capacity  # ``stamps`` as Python ints, for selecting
        self._layouts: list[Layout | None] = [None] * capacity
        self._free = list(range(capacity - 1, -1, -1))
        self._layout: Layout | None = None  # the last layout claimed
        self._mixed = False  # whether layouts of different joint counts were ever claimed

    def put(self, track: int, camera: int, skeleton: Skeleton) -> bool:
        """Keep ``skeleton`` as the track's newest from ``camera``; False if it is older."""
        slot = self.claim(track, camera, skeleton.src_time_ns, skeleton.layout)
        if slot is None:
            return False
        self.write([slot], skeleton.markers[None], skeleton.marker_present[None])
        return True

    def claim(self, track: int, camera: int, stamp_ns: int, layout: Layout) -> int | None:
        """The slot of the track's newest detection from ``camera``, now stamped ``stamp_ns``.

        None (and nothing changed) when the slot holds a newer detection. The caller copies
        the detection's rows in with :meth:`write`: a frame's detections are claimed one by
        one, then copied in one go.
        """
        per_camera = self.slots.setdefault(track, {})
        slot = per_camera.get(camera)
        if slot is None:
            slot = per_camera[camera] = self._allocate()
            self.tracks[slot] = track
            self.cameras[slot] = camera
        elif self._stamps[slot] > stamp_ns:
            return None
        self.stamps[slot] = self._stamps[slot] = stamp_ns
        self._layouts[slot] = layout
        if layout is not self._layout:
            if self._layout is not None and layout.n_joints != self._layout.n_joints:
                self._mixed = True
            self._layout = layout
        return slot

    def write(self, slots: list[int], markers: np.ndarray, present: np.ndarray) -> None:
        """Copy ``markers`` ``(n, J, 20)`` and ``present`` ``(n, J)`` into ``slots`` (distinct).

        Rows of a smaller layout fill a slot's first rows; a larger one widens every slot.
        """
        n_joints = markers.shape[1]
        if n_joints == self.rows.shape[1]:  # (one layout: the usual case)
            self.rows[slots] = markers
            self.present[slots] = present
            return
        if n_joints > self.rows.shape[1]:
            self._widen(n_joints)
        self.rows[slots, :n_joints] = markers
        self.present[slots, :n_joints] = present

    def select(
        self, out_ns: int, window_ns: int, timeout_ns: int
    ) -> tuple[list[int], Layout | None]:
        """Slots of the detections within ``window_ns`` of ``out_ns``, and their layout.

        Forgets detections older than ``timeout_ns`` (and tracks left without any). The slots
        come track by track, cameras in order of first sight; only those with the first one's
        joint count (a merge fuses one layout). No slot: an empty list and None.
        """
        selected: list[int] = []
        stamps = self._stamps
        for track in list(self.slots):
            per_camera = self.slots[track]
            for camera, slot in list(per_camera.items()):
                age = out_ns - stamps[slot]
                if age > timeout_ns:
                    del per_camera[camera]
                    self._free.append(slot)
                elif abs(age) <= window_ns:
                    selected.append(slot)
            if not per_camera:
                del self.slots[track]
        if not selected:
            return selected, None
        layouts = self._layouts
        first = layouts[selected[0]]
        if not self._mixed:
            return selected, first
        return [s for s in selected if _same_size(layouts[s], first)], first

    def _allocate(self) -> int:
        if not self._free:
            self._grow()
        return self._free.pop()

    def _grow(self) -> None:
        """Double the number of slots (the new ones free)."""
        old = len(self.stamps)
        self.rows = np.concatenate([self.rows, np.full_like(self.rows, np.nan)])
        self.present = np.concatenate([self.present, np.zeros_like(self.present)])
        self.stamps = np.concatenate([self.stamps, np.zeros_like(self.stamps)])
        self.tracks = np.concatenate([self.tracks, np.zeros_like(self.tracks)])
        self.cameras = np.concatenate([self.cameras, np.zeros_like(self.cameras)])
        self._stamps += [0] * old
        self._layouts += [None] * old
        self._free = list(range(2 * old - 1, old - 1, -1))

    def _widen(self, n_joints: int) -> None:
        """Room for ``n_joints`` rows per slot (a layout with more joints than seen so far)."""
        rows = np.full((len(self.rows), n_joints, STATE_WIDTH), np.nan)
        present = np.zeros((len(self.rows), n_joints), dtype=bool)
        rows[:, : self.rows.shape[1]] = self.rows
        present[:, : self.present.shape[1]] = self.present
        self.rows, self.present = rows, present


def _same_size(layout: Layout | None, other: Layout | None) -> bool:
    return layout is other or (
        layout is not None and other is not None and layout.n_joints == other.n_joints
    )
