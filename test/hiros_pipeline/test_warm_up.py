"""A run loads every compiled kernel it takes before its clock starts (its warm-up)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

pytest.importorskip("numba")

# In a fresh interpreter: in this one, earlier tests may have loaded what a warm-up missed.
_SCRIPT = """
import sys
from pathlib import Path
from numba.core.registry import CPUDispatcher
from hiros_core.calibration import load_calibration
import hiros_pipeline.offline as offline

def signatures():
    found = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("hiros_"):
            for value in vars(module).values():
                if isinstance(value, CPUDispatcher):
                    key = f"{value.py_func.__module__}.{value.__name__}"
                    found[key] = {str(s) for s in value.signatures}
    return found

warmed = {}
warm_up = offline._warm_up
def watched_warm_up():
    warm_up()
    warmed.update(signatures())  # the stages' and the run's warm-ups are done: the clock starts
offline._warm_up = watched_warm_up
scene = Path(sys.argv[1])
offline.run_recording(
    scene / "recording.mcap", load_calibration(scene / "calibration.yaml"),
    Path(sys.argv[2]), processes=1,
)
for kernel, loaded in sorted(signatures().items()):
    for signature in sorted(loaded - warmed.get(kernel, set())):
        print(f"{kernel} {signature}")
"""


def test_a_run_loads_no_kernel_once_its_clock_runs(
    simulated_scene: Callable[..., Path], tmp_path: Path
) -> None:
    scene = simulated_scene("sim", n_cameras=2, n_people=2, duration=8.0, seed=3)
    result = subprocess.run(
        [sys.executable, "-c", _SCRIPT, str(scene), str(tmp_path / "out.mcap")],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout == "", f"loaded during the run:\n{result.stdout}"
