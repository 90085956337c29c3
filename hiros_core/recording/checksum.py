"""CRC-32 as MCAP stores it (chunks, summary): zlib-ng's where installed, else zlib's.

``hiros run`` checksums every chunk it writes (207 MB for the 20 s benchmark recording):
zlib's crc32 runs at ~1.8 GB/s here, zlib-ng's (carry-less multiply) at ~8 GB/s, the same
values. A system install without the ``zlib-ng`` wheel falls back to zlib.
"""

from __future__ import annotations

try:
    from zlib_ng.zlib_ng import crc32
except ImportError:  # pragma: no cover - the fallback gives the same values, slower
    from zlib import crc32

__all__ = ["crc32"]
