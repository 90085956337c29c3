"""Little-endian CDR (XCDR1) building blocks for the message codec.

Two tools, both pure Python/numpy:

* ``CdrReader`` walks bytes field by field with bounds checks, raising ``CodecError`` on
  truncation, so corrupt input never reads past the buffer or returns garbage.
* ``PlanBuilder`` writes a message once, leaving *slots* where per-message values go. The
  result, a ``Plan``, is a byte template plus, per slot kind, the offsets of every slot. Encoding
  a message of the same shape is then one template copy and one numpy scatter per slot kind;
  decoding is one comparison of the template's constant bytes and one gather per slot kind.
  This is what makes the codec ten times faster than building rclpy message objects.

Alignment is relative to the payload, which starts after the 4-byte encapsulation header.
Fast-CDR leaves padding bytes uninitialised, so plans record padding positions and never
compare them.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from hiros_core.errors import CodecError

ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR_LE, options 0
HEADER_SIZE = len(ENCAPSULATION)
LEAD = 8 - HEADER_SIZE
"""Spare bytes before a message in an aligned buffer: its payload then starts 8-aligned."""
_WORD = np.dtype("<u8")
_UNITS = (8, 4, 2, 1)


def aligned_copy(data: bytes | bytearray | memoryview) -> np.ndarray:
    """The message in a new uint8 buffer laid out for ``Plan.matches_aligned``/``gather_aligned``.

    ``LEAD`` spare bytes, the message, padding to whole 8-byte words (spare and padding bytes
    are left uninitialised: plans never read them). Message byte ``i`` is ``buffer[LEAD + i]``;
    the payload is 8-byte aligned in memory, so every CDR value sits at a multiple of its
    size and numpy gathers whole values (one index per float, not eight per float), on
    aligned memory, and compares whole words.
    """
    raw = np.frombuffer(data, dtype=np.uint8)
    buffer = np.empty(_padded(raw.size), dtype=np.uint8)
    buffer[LEAD : LEAD + raw.size] = raw
    return buffer


def _padded(size: int) -> int:
    return (LEAD + size + 7) // 8 * 8


_U32 = struct.Struct("<I")
_I32 = struct.Struct("<i")
_F64 = struct.Struct("<d")


class CdrReader:
    """Sequential reader over a CDR payload with alignment and bounds checks."""

    __slots__ = ("data", "pos", "what")

    def __init__(self, data: bytes | bytearray | memoryview, what: str) -> None:
        self.data = memoryview(data).cast("B") if not isinstance(data, bytes) else data
        self.what = what
        if len(self.data) < HEADER_SIZE:
            self.fail("shorter than the 4-byte CDR header")
        if self.data[0] != 0 or self.data[1] != 1:
            self.fail(f"unsupported CDR encapsulation {bytes(self.data[:2]).hex()} (need 0001)")
        self.pos = HEADER_SIZE

    def fail(self, reason: str) -> None:
        """Raise CodecError naming the message type and the byte position."""
        msg = f"cannot decode {self.what}: {reason} (at byte {getattr(self, 'pos', 0)})"
        raise CodecError(msg)

    def align(self, size: int) -> None:
        """Skip padding so that the payload offset is a multiple of ``size``."""
        self.pos += (-(self.pos - HEADER_SIZE)) % size

    def take(self, size: int) -> int:
        """Reserve ``size`` bytes and return their start; raises when they run past the end."""
        start = self.pos
        if start + size > len(self.data):
            self.fail(f"truncated: needs {start + size} bytes, has {len(self.data)}")
        self.pos = start + size
        return start

    def u32(self) -> int:
        """An aligned uint32."""
        self.align(4)
        return _U32.unpack_from(self.data, self.take(4))[0]

    def i32(self) -> int:
        """An aligned int32."""
        self.align(4)
        return _I32.unpack_from(self.data, self.take(4))[0]

    def u8(self) -> int:
        """One byte."""
        return self.data[self.take(1)]

    def count(self, item_size: int) -> int:
        """A sequence length, checked against the bytes left (each item >= ``item_size``)."""
        n = self.u32()
        if n * item_size > len(self.data) - self.pos:
            self.fail(
                f"sequence of {n} items cannot fit in the {len(self.data) - self.pos} bytes left"
            )
        return n

    def string(self) -> str:
        """A CDR string: uint32 length including the terminating NUL, bytes, NUL."""
        n = self.u32()
        if n == 0:
            self.fail("string without its terminating NUL")
        start = self.take(n)
        if self.data[start + n - 1] != 0:
            self.fail("string not NUL-terminated")
        try:
            # a C string ends at its first NUL, as rclpy reads it
            return bytes(self.data[start : start + n - 1]).split(b"\x00", 1)[0].decode("utf-8")
        except UnicodeDecodeError:
            self.fail("string is not valid UTF-8")
        raise AssertionError  # unreachable: fail() raises

    def floats(self, count: int, dtype: str = "<f8") -> np.ndarray:
        """``count`` aligned floats as a numpy array (copied)."""
        size = np.dtype(dtype).itemsize
        self.align(size)
        start = self.take(count * size)
        return np.frombuffer(self.data, dtype=dtype, count=count, offset=start).copy()

    def blob(self) -> bytes:
        """A uint8 sequence."""
        n = self.count(1)
        start = self.take(n)
        return bytes(self.data[start : start + n])

    def done(self) -> None:
        """Check that at most trailing alignment padding is left."""
        if len(self.data) - self.pos > 3:
            self.fail(f"{len(self.data) - self.pos} unexpected trailing bytes")


@dataclass(frozen=True, eq=False)
class Plan:
    """Byte template of one message shape and where its per-message values go.

    Attributes:
        template: the message bytes with zeros in every slot and padding.
        slots: slot kind -> ``(k,)`` payload-absolute byte offsets (header included).
        widths: slot kind -> bytes per slot.
        constant: ``(m,)`` offsets of bytes that must match for a message to have this shape.
        meta: what the decoder needs besides the slots (strings, ids, layouts).

    """

    template: np.ndarray
    slots: dict[str, np.ndarray]
    widths: dict[str, int]
    constant: np.ndarray
    meta: object = None
    indices: dict[str, np.ndarray] = field(init=False, repr=False)
    """slot kind -> ``(k, width)`` byte positions of its slots (computed once)."""
    spans: dict[str, tuple[int, int]] = field(init=False, repr=False)
    """slot kind -> its byte range in ``all_indices`` order, for ``gather_all``."""
    all_indices: np.ndarray = field(init=False, repr=False)
    words: np.ndarray = field(init=False, repr=False)
    """The template as 8-byte words of an aligned buffer (``aligned_copy`` layout)."""
    mask: np.ndarray = field(init=False, repr=False)
    """Words with all bits set on the constant bytes, for ``matches_aligned``."""
    units: dict[str, tuple[str, np.ndarray]] = field(init=False, repr=False)
    """slot kind -> ``(k, width / unit)`` element positions in an aligned buffer viewed as
    unsigned ints of the largest size (8, 4, 2 or 1 bytes) dividing the slots' offsets and
    width, for ``gather_aligned``."""

    def __post_init__(self) -> None:
        indices = {
            kind: offsets[:, None] + np.arange(self.widths[kind])
            for kind, offsets in self.slots.items()
            if offsets.size
        }
        spans, start = {}, 0
        for kind, index in indices.items():
            spans[kind] = (start, start + index.size)
            start += index.size
        flat = [index.ravel() for index in indices.values()]
        object.__setattr__(self, "indices", indices)
        object.__setattr__(self, "spans", spans)
        object.__setattr__(
            self, "all_indices", np.concatenate(flat) if flat else np.empty(0, dtype=np.intp)
        )
        words = np.zeros(_padded(self.template.size), dtype=np.uint8)
        words[LEAD : LEAD + self.template.size] = self.template
        mask = np.zeros_like(words)
        mask[self.constant + LEAD] = 0xFF
        object.__setattr__(self, "words", words.view(_WORD))
        object.__setattr__(self, "mask", mask.view(_WORD))
        units = {}
        for kind, offsets in self.slots.items():
            if not offsets.size:
                continue
            width, starts = self.widths[kind], offsets + LEAD
            unit = next(u for u in _UNITS if width % u == 0 and not (starts % u).any())
            units[kind] = (f"<u{unit}", (starts[:, None] + np.arange(0, width, unit)) // unit)
        object.__setattr__(self, "units", units)

    def encode(self, values: dict[str, np.ndarray]) -> bytes:
        """Fill each slot kind with ``values[kind]`` (any dtype, ``k`` rows of ``width`` bytes)."""
        out = self.template.copy()
        for kind, index in self.indices.items():
            out[index] = np.ascontiguousarray(values[kind]).view(np.uint8).reshape(index.shape)
        return out.tobytes()

    def gather_all(self, data: np.ndarray, start: int = 0) -> dict[str, np.ndarray]:
        """Every slot kind's bytes ``(k, width)`` in one gather (a block at ``start``)."""
        raw = data[self.all_indices + start] if start else data[self.all_indices]
        return {
            kind: raw[begin:end].reshape(self.indices[kind].shape)
            for kind, (begin, end) in self.spans.items()
        }

    @property
    def size(self) -> int:
        """Bytes of the message (or block) this plan writes."""
        return self.template.size

    def matches(self, data: np.ndarray) -> bool:
        """True when ``data`` (uint8) has exactly this shape."""
        return data.size == self.template.size and self.matches_at(data, 0)

    def matches_at(self, data: np.ndarray, start: int) -> bool:
        """True when ``data[start:]`` begins with a block of exactly this shape."""
        return start + self.template.size <= data.size and np.array_equal(
            data[start + self.constant], self.template[self.constant]
        )

    def matches_aligned(self, buffer: np.ndarray, size: int) -> bool:
        """True when the ``size``-byte message in ``buffer`` (``aligned_copy``) has this shape."""
        if size != self.template.size:
            return False
        differ = np.bitwise_xor(buffer.view(_WORD), self.words)
        differ &= self.mask
        return not differ.any()

    def gather_aligned(self, buffer: np.ndarray, kind: str, dtype: np.dtype | str) -> np.ndarray:
        """``gather`` from an ``aligned_copy`` buffer: whole values, not bytes, are indexed."""
        found = self.units.get(kind)
        if found is None:
            dtype = np.dtype(dtype)
            return np.zeros((0, self.widths.get(kind, dtype.itemsize)), dtype=np.uint8).view(dtype)
        unit, index = found
        return buffer.view(unit)[index].view(dtype)

    def gather(
        self, data: np.ndarray, kind: str, dtype: np.dtype | str, start: int = 0
    ) -> np.ndarray:
        """The values of one slot kind as ``(k, width / itemsize)`` of ``dtype``."""
        index = self.indices.get(kind)
        if index is None:
            dtype = np.dtype(dtype)
            return np.zeros((0, self.widths.get(kind, dtype.itemsize)), dtype=np.uint8).view(dtype)
        return (data[index + start] if start else data[index]).view(dtype)


class PlanBuilder:
    """Writes a message shape: constants are written, slots are reserved and recorded."""

    def __init__(self, payload_offset: int | None = None) -> None:
        """A whole message (with the CDR header), or a block starting at ``payload_offset``."""
        self.buf = bytearray(ENCAPSULATION if payload_offset is None else b"")
        # payload position of buf[0]: alignment is relative to the payload start
        self.origin = -HEADER_SIZE if payload_offset is None else payload_offset
        self.padding: list[int] = []
        self.slots: dict[str, list[int]] = {}
        self.widths: dict[str, int] = {}

    def align(self, size: int) -> None:
        """Pad to a multiple of ``size`` relative to the payload."""
        pad = (-(self.origin + len(self.buf))) % size
        self.padding.extend(range(len(self.buf), len(self.buf) + pad))
        self.buf += b"\x00" * pad

    def u32(self, value: int) -> None:
        """A constant uint32."""
        self.align(4)
        self.buf += _U32.pack(value)

    def i32(self, value: int) -> None:
        """A constant int32."""
        self.align(4)
        self.buf += _I32.pack(value)

    def u8(self, value: int) -> None:
        """A constant byte."""
        self.buf.append(value)

    def f64(self, value: float) -> None:
        """A constant float64."""
        self.align(8)
        self.buf += _F64.pack(value)

    def string(self, text: str) -> None:
        """A constant CDR string; like rclpy (a C string), it ends at an embedded NUL."""
        try:
            raw = text.encode("utf-8").split(b"\x00", 1)[0]
        except UnicodeEncodeError as exc:
            msg = f"cannot encode string {text!r}: {exc.reason}"
            raise CodecError(msg) from None
        self.u32(len(raw) + 1)
        self.buf += raw + b"\x00"

    def blob(self, raw: bytes) -> None:
        """A constant uint8 sequence."""
        self.u32(len(raw))
        self.buf += raw

    def slot(self, kind: str, width: int, align: int) -> None:
        """Reserve ``width`` bytes aligned to ``align`` for a per-message value of ``kind``."""
        self.align(align)
        self.slots.setdefault(kind, []).append(len(self.buf))
        self.widths[kind] = width
        self.buf += b"\x00" * width

    def build(self, meta: object = None) -> Plan:
        """Freeze into a Plan."""
        template = np.frombuffer(bytes(self.buf), dtype=np.uint8).copy()
        variable = np.zeros(template.size, dtype=bool)
        variable[self.padding] = True
        slots = {k: np.asarray(v, dtype=np.intp) for k, v in self.slots.items()}
        for kind, offsets in slots.items():
            if offsets.size:
                variable[(offsets[:, None] + np.arange(self.widths[kind])).ravel()] = True
        return Plan(template, slots, dict(self.widths), np.flatnonzero(~variable), meta)


class BlockPlans:
    """Plans of message blocks (one skeleton, say), by shape and by alignment phase.

    A block's bytes depend on where it starts modulo 8, so plans are kept per phase; decoding
    tries the most recently used plans of the block's phase before parsing field by field.
    """

    def __init__(self, capacity: int = 512, candidates: int = 24) -> None:
        self.capacity = capacity
        self.candidates = candidates
        self.by_key: dict[object, Plan] = {}
        self.by_phase: dict[int, list[Plan]] = {}

    def get(self, key: object) -> Plan | None:
        """The plan of a known block shape (the key includes the phase), if cached."""
        return self.by_key.get(key)

    def put(self, key: object, plan: Plan, phase: int) -> Plan:
        """Remember a plan."""
        if len(self.by_key) >= self.capacity:
            self.by_key.clear()
            self.by_phase.clear()
        self.by_key[key] = plan
        recent = self.by_phase.setdefault(phase, [])
        recent.insert(0, plan)
        del recent[self.candidates :]
        return plan

    def find_at(self, data: np.ndarray, start: int, phase: int) -> Plan | None:
        """A plan whose block matches ``data`` at ``start``; moved to the front when found."""
        recent = self.by_phase.get(phase, [])
        for index, plan in enumerate(recent):
            if plan.matches_at(data, start):
                if index:
                    recent.insert(0, recent.pop(index))
                return plan
        return None


class PlanCache:
    """A bounded cache of plans, keyed by shape for encoding and by size for decoding."""

    def __init__(self, capacity: int = 256) -> None:
        self.capacity = capacity
        self.by_key: dict[object, Plan] = {}
        self.by_size: dict[int, list[Plan]] = {}

    def get(self, key: object) -> Plan | None:
        """The plan of a known shape, if cached."""
        return self.by_key.get(key)

    def put(self, key: object, plan: Plan) -> Plan:
        """Remember a plan (the oldest goes when full)."""
        if len(self.by_key) >= self.capacity:
            self.by_key.pop(next(iter(self.by_key)))
            self.by_size.clear()
        self.by_key[key] = plan
        candidates = self.by_size.setdefault(plan.template.size, [])
        if not any(candidate is plan for candidate in candidates):
            candidates.insert(0, plan)
            del candidates[8:]
        return plan

    def find(self, data: np.ndarray) -> Plan | None:
        """A cached plan whose constant bytes match ``data``, if any."""
        for plan in self.by_size.get(data.size, ()):
            if plan.matches(data):
                return plan
        return None

    def find_aligned(self, buffer: np.ndarray, size: int) -> Plan | None:
        """``find`` for a ``size``-byte message in an ``aligned_copy`` buffer."""
        for plan in self.by_size.get(size, ()):
            if plan.matches_aligned(buffer, size):
                return plan
        return None
