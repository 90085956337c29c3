"""The people of a batch of driver messages, read straight from a recording's chunk.

``DriverBridge.update_batch`` hands a batch (an MCAP chunk's messages) to ``BatchPeople``,
which reads its usual messages with two compiled calls (``kernels.driver_messages`` and
``kernels.driver_people``) into one set of rows.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hiros_core.driver import kernels
from hiros_core.driver.params import DriverBridgeParams
from hiros_core.layouts import Layout
from hiros_core.model import BOX_WIDTH, Skeleton, SkeletonRows, link_rows

__all__ = ["BatchPeople"]


class BatchPeople:
    """The people of a batch's usual driver messages (``DriverBridge.update_batch``).

    Read by ``kernels.driver_messages`` and ``kernels.driver_people``; per message ``made``
    (its people are here), ``stamps`` and ``mixed`` (markers with other stamps). Each
    skeleton's arrays are views of distinct rows of the batch's arrays, as
    ``Skeleton.many_from_rows`` gives for one message.
    """

    def __init__(
        self,
        params: DriverBridgeParams,
        lookup: Callable[[str], tuple[Layout, np.ndarray | None]],
        buffer: bytes,
        starts: np.ndarray,
        ends: np.ndarray,
    ) -> None:
        """Read the batch; ``lookup`` is the bridge's namespace -> (layout, joint table)."""
        raw = np.frombuffer(buffer, dtype=np.uint8)
        parsed = kernels.driver_messages(raw, starts, ends, float(params.position_scale))
        first, usual, mixed, _, stamps, spans = parsed[:6]
        self.buffer, self.spans, self.first = buffer, spans, first[:-1].tolist()
        self.texts: dict[bytes, str] = {}
        found = np.flatnonzero(usual)
        namespace = spans[first[found[0]], 2:] if len(found) else np.zeros(2, dtype=np.int64)
        self.layout, table = lookup(self._text(*namespace.tolist()))
        made, people, bodies, markers, present = kernels.driver_people(
            raw, parsed, namespace, self.layout.n_joints, params.id_stride,
            params.id_scheme == "joint_major",
            np.empty(0, dtype=np.int64) if table is None else table.astype(np.int64),
            float(params.position_scale), float(params.confidence_levels),
        )  # fmt: skip
        links, link_present = link_rows(markers, present, self.layout)
        boxes = np.full((len(markers), BOX_WIDTH), np.nan)
        self.made, self.mixed = made.tolist(), mixed.tolist()
        # a message without markers starts at the end of the stamps: pad one (it is unusual
        # and goes through update_bytes; its stamp here is never used)
        self.stamps = np.append(stamps, 0)[first[:-1]].tolist()
        self.people, self.bodies = people.tolist(), bodies.tolist()
        self.rows = SkeletonRows(markers, present, links, link_present, boxes)

    def _text(self, first: int, stop: int) -> str:
        """The ASCII text at ``buffer[first:stop]``, decoded once per distinct text."""
        raw = bytes(self.buffer[first:stop])  # the buffer may be a (reused) bytearray's view
        text = self.texts.get(raw)
        if text is None:
            text = self.texts[raw] = raw.decode("ascii")
        return text

    def frame(self, m: int) -> str:
        """Frame id of message ``m``'s first marker."""
        span = self.spans[self.first[m]]
        return self._text(int(span[0]), int(span[1]))

    def skeletons(self, m: int, stamp: int, frame: str) -> list[Skeleton]:
        """The skeletons of message ``m`` (one with ``made[m]``), ``many_from_rows``' way.

        They are the rows of the message's own ``SkeletonRows`` (a slice of the batch's), so
        ``stack_rows`` of them, in the tracker and the encoder, copies nothing.
        """
        first, stop = self.people[m], self.people[m + 1]
        rows = SkeletonRows(*(field[first:stop] for field in self.rows))
        return rows.skeletons(self.bodies[first:stop], stamp, frame, self.layout)
