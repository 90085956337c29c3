"""CRC-32 as MCAP stores it (chunks, summary): zlib-ng's where installed, else zlib's.

``hiros run`` checksums every chunk it writes; zlib-ng's crc32 (carry-less multiply) gives
zlib's values several times faster (figures: docs/architecture.md, "Figures out of the
docstrings"). A system install without the ``zlib-ng`` wheel falls back to zlib.
"""

from __future__ import annotations

try:
    from zlib_ng.zlib_ng import crc32
except ImportError:  # pragma: no cover - the fallback gives the same values, slower
    from zlib import crc32

__all__ = ["crc32"]
