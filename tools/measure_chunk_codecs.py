"""CPU and ratio of the chunk compressions, and speed of the CRC-32s, on an MCAP file's chunks.

What chose ``hiros_core.recording.mcap_out.ZSTD_LEVEL`` and ``checksum.crc32`` (zlib-ng's);
the figures are in docs/architecture.md. Each is the best of three passes over every chunk:

    .venv/bin/python tools/measure_chunk_codecs.py out.mcap
"""

from __future__ import annotations

import sys
import time
import zlib
from collections.abc import Callable
from pathlib import Path

import lz4.frame
import zstandard
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from zlib_ng import zlib_ng


def read_chunks(path: Path) -> list[bytes]:
    """The uncompressed records of every chunk of the MCAP file at ``path``."""
    chunks = []
    with path.open("rb") as stream:
        for record in StreamReader(stream, emit_chunks=True).records:
            if not isinstance(record, Chunk):
                continue
            data = record.data
            if record.compression == "zstd":
                data = zstandard.ZstdDecompressor().decompress(
                    data, max_output_size=record.uncompressed_size
                )
            elif record.compression == "lz4":
                data = lz4.frame.decompress(data)
            chunks.append(bytes(data))
    return chunks


def best_cpu(work: Callable[[bytes], object], chunks: list[bytes]) -> tuple[float, list]:
    """The least process CPU time of three passes of ``work`` over ``chunks``, and its results."""
    best, results = float("inf"), []
    for _ in range(3):
        start = time.process_time()
        results = [work(chunk) for chunk in chunks]
        best = min(best, time.process_time() - start)
    return best, results


def main(path: Path) -> None:
    """Print one line per compression and per CRC-32."""
    chunks = read_chunks(path)
    total = sum(map(len, chunks))
    print(f"{path}: {len(chunks)} chunks, {total / 1e6:.0f} MB of records")
    compressions = [(f"zstd {level}", zstandard.ZstdCompressor(level=level).compress)
                    for level in (3, 1, -3)] + [("lz4", lz4.frame.compress)]  # fmt: skip
    for name, compress in compressions:
        seconds, packed = best_cpu(compress, chunks)
        print(f"{name:8s} CPU {seconds:.2f} s, ratio {total / sum(map(len, packed)):.2f}")
    for name, crc32 in (("zlib crc32", zlib.crc32), ("zlib-ng crc32", zlib_ng.crc32)):
        seconds, _ = best_cpu(crc32, chunks)
        print(f"{name:14s} {total / seconds / 1e9:.1f} GB/s")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
