"""Compile hiros's numba kernels once, at setup, by running the pipeline over a tiny recording.

The per-frame kernels (tracker, merger, optimizer, filter, codec helpers) are compiled on first
use and cached on disk next to their sources (numba ``cache=True``). Compiling them all takes
tens of seconds on a small machine, which would otherwise land on a user's first ``hiros demo``
or live node. ``make setup`` runs this after installing, so that cost is paid with the install.
A second run loads everything from the cache in about a second.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path


def main() -> int:
    """Simulate four seconds of two cameras and two people, and run the whole pipeline on it."""
    from hiros_core.calibration import load_calibration
    from hiros_pipeline import run_recording
    from hiros_sim import SimParams, simulate, write_recording

    start = time.monotonic()
    with tempfile.TemporaryDirectory() as folder:
        sim = Path(folder) / "sim"
        write_recording(simulate(SimParams(n_cameras=2, n_people=2, duration=4.0, seed=0)), sim)
        calibration = load_calibration(sim / "calibration.yaml")
        run_recording(sim / "recording.mcap", calibration, Path(folder) / "out.mcap")
    print(f"hiros kernels compiled or loaded from the cache in {time.monotonic() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
