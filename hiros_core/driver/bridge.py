"""``DriverBridge``: one driver topic's MarkerArrays -> SkeletonGroups, drops counted.

Usual messages (every marker an ADD of a known joint, ids in increasing order) take the
compiled kernels of ``hiros_core.driver.kernels``; every other message the numpy path
(``DriverBridge._kept_markers``), which counts what it drops.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hiros_core.accounting import Accounted, Drops
from hiros_core.codec import (
    MarkerArrayData,
    MarkerFields,
    decode_marker_fields,
    encode_marker_array,
)
from hiros_core.driver.markers import ADD, DELETE, DELETEALL, group_to_driver_markers
from hiros_core.driver.params import RESET_AFTER_BACKWARDS, DriverBridgeParams
from hiros_core.errors import CodecError, ConfigError, LayoutError
from hiros_core.layouts import Layout, get_layout
from hiros_core.limits import MAX_BODIES, MAX_MARKERS, marker_counts
from hiros_core.model import (
    STATE_WIDTH,
    Skeleton,
    SkeletonGroup,
    warm_up_group,
)

__all__ = ["DriverBridge", "DriverBridgeParams", "load_bridge_params", "warm_up"]

_ID_SCHEMES = ("body_major", "joint_major")


def load_bridge_params(path: str | Path) -> tuple[DriverBridgeParams, dict[str, Any]]:
    """Read a generic bridge description: the bridge parameters and the rest (topics).

    The file is a mapping whose keys are ``DriverBridgeParams`` fields plus keys for the node
    (``cameras``, ``input_topic``, ``output_topic``, ``input_qos``), either plain or as a ROS
    parameter file (``generic_bridge: ros__parameters: {...}``). A relative ``layout`` file
    path is taken relative to the YAML file. Raises ConfigError naming the file and the bad
    key.
    """
    path = Path(path)
    try:
        spec = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        msg = f"cannot read bridge description {path}: {exc}"
        raise ConfigError(msg) from exc
    if isinstance(spec, dict) and len(spec) == 1:
        # a ROS parameter file: ``<node>: ros__parameters: {...}``
        (section,) = spec.values()
        if isinstance(section, dict) and isinstance(section.get("ros__parameters"), dict):
            spec = section["ros__parameters"]
    if not isinstance(spec, dict):
        msg = f"bridge description {path} must be a mapping of parameters"
        raise ConfigError(msg)
    known = DriverBridgeParams.__dataclass_fields__
    values = {k: v for k, v in spec.items() if k in known}
    layout = values.get("layout")
    if isinstance(layout, str) and layout.endswith((".yaml", ".yml")):
        layout_path = Path(layout)
        if not layout_path.is_absolute():
            values["layout"] = str(path.parent / layout_path)
    try:
        params = DriverBridgeParams(**values)
        DriverBridge(params)  # validates layout, scheme and joint names now, not per message
    except (TypeError, LayoutError, ConfigError) as exc:
        msg = f"bridge description {path}: {exc}"
        raise ConfigError(msg) from exc
    return params, {k: v for k, v in spec.items() if k not in known}


def warm_up() -> None:
    """Load the compiled frame paths (live and recording) before the first frame.

    From numba's disk cache this takes ~20 ms (with numba's import, ~1 s in a process that
    has not loaded it yet); the very first time after an install or a change of the kernel,
    ~2 s of compilation, which a live node should not spend on its first camera message.
    """
    markers = group_to_driver_markers(warm_up_group())
    DriverBridge().update(markers)
    raw = encode_marker_array(markers)  # the batch kernels of recordings
    for buffer in (raw, bytearray(raw)):  # a message's bytes; a reader's (writable) buffer
        DriverBridge().update_batch(buffer, np.array([0]), np.array([len(raw)]))


@cache
def _level(text: str) -> float:
    """Confidence level written in a marker's text, NaN when there is none."""
    try:
        return float(int(text.strip()))
    except ValueError:
        return math.nan


_GAP_STEPS = 64
"""Steps between a driver's stamps kept to find its frame period (the smallest)."""
_GAP_MIN_STEPS = 8
"""Steps seen before gaps are counted."""
_GAP_MAX_S = 5.0
"""A longer step is a pause or a restart, not lost frames."""


class DriverBridge(Accounted):
    """One driver topic's MarkerArrays -> SkeletonGroups in the camera's frame and clock.

    Keep one bridge per camera: it remembers the last stamp to refuse messages that go back
    in time. Bad input is never raised: it is counted in ``drops`` by reason, each reason
    dropping the whole message (a frame: see ``Accounted``) or some of its markers:

    * ``empty_array``: a MarkerArray with no markers, without its arrival time (nothing to
      stamp a group with; frame). The Azure driver publishes one per body frame when nobody
      is in view; given the arrival time (``update(data, arrival_ns)``), the bridge turns it
      into an empty group, "nobody in view" (``nobody_in_view`` counts them);
    * ``nothing_to_add``: a message of DELETE or unknown markers alone (frame);
    * ``stale_deleteall``: DELETEALL markers alone, not newer than the last message (frame);
    * ``undecodable``: bytes the codec rejects, in ``update_batch`` (frame);
    * ``too_many_markers`` / ``too_many_bodies``: past ``hiros_core.limits.MAX_MARKERS``
      markers or ``MAX_BODIES`` bodies in one message (frame, dropped before decoding);
    * ``delete_marker`` / ``deleteall_marker``: DELETE / DELETEALL markers (a message of
      DELETEALL markers alone still gives an empty group: "nobody in view");
    * ``unknown_action``: actions other than ADD, DELETE, DELETEALL;
    * ``unknown_joint``: an id whose joint is outside the layout (or negative);
    * ``nan_position``: a joint position that is NaN or infinite;
    * ``duplicate_marker``: a second marker for the same body and joint (the first is kept);
    * ``mixed_stamps``: markers of one message with different stamps (the first is used);
    * ``stamp_backwards`` / ``repeated_stamp``: a message older than, or as old as, the last
      one (frame); a jump back larger than ``RESET_AFTER_BACKWARDS`` counts
      ``source_restarted`` and is accepted.

    ``processed`` counts the messages that gave a group; ``lost_before_reception`` the frames
    missing from the driver's stamps (never received, so outside the balance; see
    ``diagnostics``).
    """

    def __init__(self, params: DriverBridgeParams | None = None, default_frame: str = "") -> None:
        self.params = params or DriverBridgeParams()
        self.nobody_in_view = 0  # empty arrays turned into empty groups (processed)
        self.lost_before_reception = 0  # frames missing from the stamps' sequence
        self._gap_last: int | None = None  # the last driver stamp (None after an empty array)
        self._gap_steps: deque[int] = deque(maxlen=_GAP_STEPS)
        self._frame = self.params.frame_id or default_frame  # of the last group
        self._transit_ns = 0  # arrival - stamp of the last stamped message
        self.layout: Layout = get_layout(self.params.layout)
        if self.params.id_scheme not in _ID_SCHEMES:
            msg = f"id_scheme must be one of {_ID_SCHEMES}, not {self.params.id_scheme!r}"
            raise ConfigError(msg)
        if self.params.id_stride < 1:
            msg = f"id_stride must be a positive integer, not {self.params.id_stride}"
            raise ConfigError(msg)
        self.drops = Drops()
        self.last_stamp_ns: int | None = None
        self._lookups: dict[str, tuple[Layout, np.ndarray | None]] = {}
        self._shapes: dict[tuple, _IdShape] = {}
        self._lookup("")  # an unknown name in joint_names fails here, not per message

    def _count(self, reason: str, amount: int) -> None:
        """Add to ``drops`` (zero counts leave no entry, so ``drops`` lists what happened)."""
        if amount:
            self.drops[reason] += amount

    def reset(self) -> None:
        """Forget the last stamp (a new recording or a restarted source)."""
        self.last_stamp_ns = None

    def _lookup(self, namespace: str) -> tuple[Layout, np.ndarray | None]:
        """The layout of a namespace and the driver-joint -> marker-id table for it.

        The table is None when driver joint index = marker id (no ``joint_names``).
        """
        found = self._lookups.get(namespace)
        if found is None:
            try:
                layout = get_layout(namespace) if namespace else self.layout
            except LayoutError:
                layout = self.layout
            table = None
            if self.params.joint_names and layout is self.layout:
                table = np.array([layout.index(n) for n in self.params.joint_names])
            found = self._lookups[namespace] = (layout, table)
        return found

    def update_bytes(
        self, data: bytes | bytearray | memoryview, arrival_ns: int | None = None
    ) -> SkeletonGroup | None:
        """``update(decode_marker_array(data), arrival_ns)``, decoding only what it reads.

        Raises:
            CodecError: the bytes are no MarkerArray.

        """
        return self.update(decode_marker_fields(data), arrival_ns)

    def update_batch(
        self, buffer: bytes | memoryview, starts: np.ndarray, ends: np.ndarray
    ) -> list[SkeletonGroup | None]:
        """``update_bytes`` of the messages ``buffer[starts[i]:ends[i]]``, in order, at once.

        For a recording: the batch's usual driver messages (see ``kernels.driver_people``)
        are read by two compiled calls and their people built in one set of arrays; every
        other message takes ``update_bytes``. Same groups and drops
        as ``update_bytes`` message after message, except that bytes the codec rejects give
        None and count ``undecodable`` here instead of raising.
        """
        over = marker_counts(buffer, starts, ends) > MAX_MARKERS
        if over.any():  # dropped before the compiled reading allocates for them
            out: list[SkeletonGroup | None] = [None] * len(starts)
            kept = np.flatnonzero(~over)
            made = self.update_batch(buffer, starts[kept], ends[kept]) if len(kept) else []
            for m, group in zip(kept.tolist(), made, strict=True):
                out[m] = group
            self.drops.frame("too_many_markers", int(over.sum()))
            return out
        from hiros_core.driver.batch import BatchPeople

        people = BatchPeople(self.params, self._lookup, buffer, starts, ends)
        out: list[SkeletonGroup | None] = []
        for m, (start, end) in enumerate(zip(starts.tolist(), ends.tolist(), strict=True)):
            if not people.made[m]:
                out.append(self._update_counted(buffer[start:end]))
            elif not self._accept_stamp(stamp := people.stamps[m]):
                out.append(None)
            else:
                if people.mixed[m]:
                    self.drops["mixed_stamps"] += 1
                frame = self.params.frame_id or people.frame(m)
                skeletons = people.skeletons(m, stamp, frame)
                out.append(self._bounded(SkeletonGroup(stamp, frame, skeletons)))
        return out

    def _update_counted(self, data: bytes) -> SkeletonGroup | None:
        """``update_bytes``, counting ``undecodable`` instead of raising."""
        try:
            return self.update_bytes(data)
        except CodecError as exc:  # OverLimitError: too_many_markers
            self.drops.frame(getattr(exc, "reason", "undecodable"))
            return None

    def update(
        self, data: MarkerArrayData | MarkerFields, arrival_ns: int | None = None
    ) -> SkeletonGroup | None:
        """Convert one MarkerArray; None when the whole message is dropped (see ``drops``).

        ``arrival_ns``, when the message arrived (the receiver's clock), lets an empty array
        become an empty group (see ``empty_array``).
        """
        if arrival_ns is not None and len(data.actions) == 0:
            return self._nobody_in_view(arrival_ns)
        group = self._convert(data)
        if group is None:
            return None
        if arrival_ns is not None:
            self._transit_ns = arrival_ns - group.stamp_ns
        self._frame = group.frame_id
        return self._bounded(group)

    def _nobody_in_view(self, arrival_ns: int) -> SkeletonGroup:
        """An empty group for an empty array, stamped on the camera's clock.

        The array has no stamp: it is stamped at its arrival less the transit of the last
        stamped message (none before the first: the receiver's clock is taken for the
        camera's), and never before the last stamp (a group's stamps only go forward).
        """
        stamp = arrival_ns - self._transit_ns
        if self.last_stamp_ns is not None:
            stamp = max(stamp, self.last_stamp_ns + 1)
        self.last_stamp_ns = stamp
        self._gap_last = None  # the driver's stamps are unknown across empty arrays
        self.nobody_in_view += 1
        self.processed += 1
        return SkeletonGroup(stamp, self._frame, [])

    def _bounded(self, group: SkeletonGroup) -> SkeletonGroup | None:
        """``group``, counted processed; None (``too_many_bodies``) past ``MAX_BODIES``."""
        if len(group.skeletons) > MAX_BODIES:
            self.drops.frame("too_many_bodies")
            return None
        self.processed += 1
        return group

    def _convert(self, data: MarkerArrayData | MarkerFields) -> SkeletonGroup | None:
        actions = np.asarray(data.actions)
        if len(actions) == 0:
            self.drops.frame("empty_array")
            return None
        add = actions == ADD
        if add.all():  # the driver's usual message: every marker a joint to add
            rows = None
        else:
            deleteall = actions == DELETEALL
            self._count("delete_marker", int((actions == DELETE).sum()))
            self._count("deleteall_marker", int(deleteall.sum()))
            self._count("unknown_action", int((~add & ~deleteall & (actions != DELETE)).sum()))
            rows = np.flatnonzero(add if add.any() else deleteall)
            if len(rows) == 0:
                self.drops.frame("nothing_to_add")
                return None
        first = 0 if rows is None else int(rows[0])
        stamp = int(data.stamps_ns[first])
        frame = self.params.frame_id or data.frame_ids[first]
        if rows is not None and not add.any():
            # Clearing markers are often unstamped: they say "nobody in view" only when they
            # carry a new stamp, and never restart the clock.
            if self.last_stamp_ns is not None and stamp <= self.last_stamp_ns:
                self.drops.frame("stale_deleteall")
                return None
            self.last_stamp_ns = stamp
            return SkeletonGroup(stamp, frame, [])
        if not self._accept_stamp(stamp):
            return None
        stamps = data.stamps_ns if rows is None else data.stamps_ns[rows]
        if (stamps != stamp).any():
            self.drops["mixed_stamps"] += 1
        return SkeletonGroup(stamp, frame, self._skeletons(data, rows, stamp, frame))

    def _accept_stamp(self, stamp: int) -> bool:
        last = self.last_stamp_ns
        if last is not None and stamp <= last:
            if last - stamp > RESET_AFTER_BACKWARDS * 1e9:
                self.drops["source_restarted"] += 1
            else:
                self.drops.frame("repeated_stamp" if stamp == last else "stamp_backwards")
                return False
        self.last_stamp_ns = stamp
        self._count_gap(stamp)
        return True

    def _count_gap(self, stamp: int) -> None:
        """Count the frames missing between this stamp and the last stamped one.

        A driver stamps its frames at a steady period (the device clock), so a gap of
        several periods means frames lost before this bridge received them (best-effort QoS
        under load, a dropped connection): ``lost_before_reception`` counts them. They are no
        part of the frame balance (they were never received). The period is the smallest
        step among the last ``_GAP_STEPS`` (it needs ``_GAP_MIN_STEPS`` first); steps back and
        steps over ``_GAP_MAX_S`` (a restart, a pause) are not counted.
        """
        last, self._gap_last = self._gap_last, stamp
        if last is None or not 0 < stamp - last <= _GAP_MAX_S * 1e9:
            return
        step = stamp - last
        if len(self._gap_steps) >= _GAP_MIN_STEPS:
            period = min(self._gap_steps)
            if step > 1.5 * period:
                self.lost_before_reception += round(step / period) - 1
        self._gap_steps.append(step)

    def diagnostics(self) -> dict[str, str]:
        """``lost_before_reception``: frames missing from the driver's stamps (when any)."""
        if not self.lost_before_reception:
            return {}
        return {"lost_before_reception": str(self.lost_before_reception)}

    def _skeletons(
        self, data: MarkerArrayData | MarkerFields, rows: np.ndarray | None, stamp: int, frame: str
    ) -> list[Skeleton]:
        """Skeletons of the ADD markers ``rows`` (None: all), one per body id in increasing order.

        Every body of the message in one pass (a fixed number of numpy calls per message); the
        usual message (ids increasing, no duplicates, whole bodies) skips the sorting and
        scattering the general case needs.
        """
        if rows is None:
            made = self._compiled_rows(data)
            if made is not None:
                layout, arranged, markers, present = made
                return Skeleton.many_from_rows(
                    markers, present, layout, skeleton_ids=arranged.skeleton_ids,
                    src_time_ns=stamp, src_frame=frame,
                )  # fmt: skip
        layout, body, joint, block, arranged = self._kept_markers(data, rows)
        if len(body) == 0:
            return []
        if arranged is None:
            arranged = _Arrangement.of(body, joint, layout.n_joints)
        n_people, n_joints = len(arranged.skeleton_ids), layout.n_joints
        markers = np.full((n_people, n_joints, STATE_WIDTH), np.nan)
        if arranged.flat is None:
            # Strictly increasing keys, at most J joints per body: every body is whole, in order.
            markers[..., :8] = block.reshape(n_people, n_joints, 8)
            present = np.ones((n_people, n_joints), dtype=bool)
        else:
            markers.reshape(-1, STATE_WIDTH)[arranged.flat, :8] = block
            present = np.zeros((n_people, n_joints), dtype=bool)
            present.reshape(-1)[arranged.flat] = True
        return Skeleton.many_from_rows(
            markers,
            present,
            layout,
            skeleton_ids=arranged.skeleton_ids,
            src_time_ns=stamp,
            src_frame=frame,
        )

    def _compiled_rows(
        self, data: MarkerArrayData | MarkerFields
    ) -> tuple[Layout, _Arrangement, np.ndarray, np.ndarray] | None:
        """The usual message's people in one compiled call, or None (take the general path).

        Same rows as ``_kept_markers`` + ``_skeletons`` give (``hiros_core.driver.kernels``,
        imported at the first call: see ``hiros_core.compiled`` for the rule).
        """
        from hiros_core.driver import kernels

        ids = np.asarray(data.ids)
        shape = self._id_shape(data.namespaces[0], ids)
        arranged = shape.arranged
        if arranged is None:
            return None
        markers, present, ok = kernels.driver_rows(
            np.ascontiguousarray(data.poses, dtype=float)[:, :7],
            np.fromiter(map(_level, data.texts), float, len(ids)),
            arranged.rows,
            len(arranged.skeleton_ids),
            shape.layout.n_joints,
            float(self.params.position_scale),
            float(self.params.confidence_levels),
        )
        return (shape.layout, arranged, markers, present) if ok else None

    def _id_shape(self, namespace: str, ids: np.ndarray) -> _IdShape:
        """What a message's namespace and marker ids fix (cached: drivers repeat them)."""
        key = (namespace, ids.dtype.str, ids.tobytes())
        found = self._shapes.get(key)
        if found is None:
            if len(self._shapes) >= _ID_SHAPE_CAPACITY:
                self._shapes.clear()
            found = self._shapes[key] = self._new_id_shape(namespace, ids)
        return found

    def _new_id_shape(self, namespace: str, raw_ids: np.ndarray) -> _IdShape:
        layout, table = self._lookup(namespace)
        ids = np.asarray(raw_ids, dtype=np.int64)
        major, minor = np.divmod(ids, self.params.id_stride)
        body, driver_joint = (
            (major, minor) if self.params.id_scheme == "body_major" else (minor, major)
        )
        if table is None:
            known = (ids >= 0) & (driver_joint < layout.n_joints)
            joint = driver_joint
        else:
            known = (ids >= 0) & (driver_joint < len(table))
            joint = np.where(known, table[np.minimum(driver_joint, len(table) - 1)], -1)
            known &= joint >= 0
        key = body * layout.n_joints + joint
        usual = bool(known.all()) and bool((key[1:] > key[:-1]).all()) and len(ids) > 0
        arranged = _Arrangement.of(body, joint, layout.n_joints) if usual else None
        return _IdShape(layout, body, joint, known, arranged)

    def _kept_markers(
        self, data: MarkerArrayData | MarkerFields, rows: np.ndarray | None
    ) -> tuple[Layout, np.ndarray, np.ndarray, np.ndarray, _Arrangement | None]:
        """The markers that make joints, in (body, joint) order, drops counted.

        Returns the layout, body ids ``(n,)``, marker ids ``(n,)``, rows ``(n, 8)`` of
        [confidence, position, orientation] (NaN orientation where the driver gave none) and,
        for the usual message (every marker kept, in order), how they make people.
        """
        ids = np.asarray(data.ids)
        poses = np.asarray(data.poses, dtype=float)
        texts = data.texts
        if rows is not None:
            ids, poses = ids[rows], poses[rows]
            texts = [texts[i] for i in rows.tolist()]
        shape = self._id_shape(data.namespaces[0 if rows is None else rows[0]], ids)
        layout, body, joint = shape.layout, shape.body, shape.joint
        block = np.empty((len(ids), 8))
        block[:, 1:8] = poses[:, :7]
        if self.params.position_scale != 1.0:
            block[:, 1:4] *= self.params.position_scale
        finite = np.isfinite(block[:, 1:4]).all(axis=1)
        arranged = shape.arranged
        if arranged is None or not finite.all():
            arranged = None
            known = shape.known
            usable = known & finite
            if not usable.all():
                self._count("unknown_joint", int((~known).sum()))
                self._count("nan_position", int((known & ~finite).sum()))
                keep = np.flatnonzero(usable)
                body, joint, block = body[keep], joint[keep], block[keep]
                texts = [texts[i] for i in keep.tolist()]
            key = body * layout.n_joints + joint
            if not (key[1:] > key[:-1]).all():
                _, first = np.unique(key, return_index=True)
                self._count("duplicate_marker", len(key) - len(first))
                body, joint, block = body[first], joint[first], block[first]
                texts = [texts[i] for i in first.tolist()]
        block[:, 0] = np.fromiter(map(_level, texts), float, len(texts))
        block[:, 0] /= self.params.confidence_levels
        unknown = ~(np.einsum("ij,ij->i", block[:, 4:8], block[:, 4:8]) > 0)
        block[unknown, 4:8] = np.nan  # zero or NaN quaternion: no orientation
        return layout, body, joint, block, arranged


_ID_SHAPE_CAPACITY = 64


@dataclass(frozen=True)
class _Arrangement:
    """How kept markers (in increasing (body, joint) order) make people.

    ``skeleton_ids`` the body ids in order; ``flat`` each marker's row in the flattened
    ``(P * J)`` people x joints, or None when every body is whole (rows in order).
    """

    skeleton_ids: list[int]
    flat: np.ndarray | None
    rows: np.ndarray  # ``flat``, or every row in order when every body is whole

    @classmethod
    def of(cls, body: np.ndarray, joint: np.ndarray, n_joints: int) -> _Arrangement:
        # ``body`` is in increasing order (sorted keys): people start where it changes.
        change = np.empty(len(body), dtype=bool)
        change[0] = True
        np.not_equal(body[1:], body[:-1], out=change[1:])
        starts = np.flatnonzero(change)
        flat = None
        if len(body) != len(starts) * n_joints:
            flat = (np.cumsum(change) - 1) * n_joints + joint
        rows = np.arange(len(body), dtype=np.intp) if flat is None else flat.astype(np.intp)
        return cls(body[starts].tolist(), flat, rows)


@dataclass(frozen=True)
class _IdShape:
    """What the marker ids of a message fix (drivers repeat them from frame to frame).

    Layout, body and joint per marker, which markers are known joints, and (every marker
    known and in increasing order) how they make people.
    """

    layout: Layout
    body: np.ndarray
    joint: np.ndarray
    known: np.ndarray
    arranged: _Arrangement | None
