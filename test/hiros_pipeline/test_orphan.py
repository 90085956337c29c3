"""The reading child of ``hiros run`` ends when its parent is killed outright."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

# The parent kills itself (SIGKILL: no clean-up of any kind) at its first frame, when the
# child has started, and leaves the child's pid behind.
_SCRIPT = """
import multiprocessing, os, signal, sys
from pathlib import Path
from hiros_core.calibration import load_calibration
from hiros_pipeline.offline import run_recording

scene, out, pid_file = (Path(a) for a in sys.argv[1:])

def die(_frames):
    Path(pid_file).write_text(str(multiprocessing.active_children()[0].pid))
    os.kill(os.getpid(), signal.SIGKILL)

run_recording(scene / "recording.mcap", load_calibration(scene / "calibration.yaml"), out,
              progress=die, processes=2)
"""


def _running(pid: int) -> bool:
    """Whether ``pid`` is alive (a zombie, ended but not reaped, counts as ended)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in {"Z", "X"}


def test_a_parent_killed_outright_leaves_no_child_waiting(
    simulated_scene: Callable[..., Path], tmp_path: Path
) -> None:
    # ~10 MB of tracked batches: more than the pipes hold, so the child must write on
    scene = simulated_scene("sim", n_cameras=2, n_people=2, duration=8.0, seed=3)
    pid_file = tmp_path / "child.pid"
    # output not captured: a child left waiting would hold the capture open
    subprocess.run(
        [sys.executable, "-c", _SCRIPT, str(scene), str(tmp_path / "o.mcap"), str(pid_file)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=300, check=False,
    )  # fmt: skip
    child = int(pid_file.read_text())
    deadline = time.monotonic() + 30.0
    while _running(child) and time.monotonic() < deadline:
        time.sleep(0.1)
    alive = _running(child)
    if alive:
        subprocess.run(["kill", "-9", str(child)], check=False)
    assert not alive, "the reading child still waits on a pipe nobody reads"
