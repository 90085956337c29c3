"""A kernel calling another module's kernel recompiles when only the callee's file changed."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

CALLEE = """
from numba import njit

@njit(cache=True)
def value():
    return {value}
"""

CALLER = """
from numba import njit

from hiros_core.compiled import refresh_stale_caches
import callee_module
from callee_module import value

@njit(cache=True)
def doubled():
    return 2 * value()

{refresh}
"""


def _run(folder: Path) -> str:
    """``doubled()`` in a fresh interpreter (the disk cache is all that carries over)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), *sys.path])}
    env.pop("NUMBA_CACHE_DIR", None)
    code = "import caller_module; print(caller_module.doubled())"
    done = subprocess.run([sys.executable, "-c", code], env=env, cwd=folder,
                          capture_output=True, text=True, check=True)  # fmt: skip
    return done.stdout.strip()


def _write_callee(folder: Path, value: int, stamp: float) -> None:
    path = folder / "callee_module.py"
    path.write_text(textwrap.dedent(CALLEE.format(value=value)))
    os.utime(path, (stamp, stamp))


def _case(folder: Path, refresh: str) -> tuple[str, str]:
    """``doubled()`` before and after the callee changed (the caller's file untouched)."""
    _write_callee(folder, 1, 1_000_000.0)
    (folder / "caller_module.py").write_text(CALLER.format(refresh=refresh))
    before = _run(folder)
    _write_callee(folder, 5, 2_000_000_000.0)  # newer than any cache index written today
    return before, _run(folder)


def test_a_caller_sees_its_changed_callee(tmp_path: Path) -> None:
    assert _case(tmp_path, "refresh_stale_caches(globals(), callee_module)") == ("2", "10")


def test_without_the_refresh_numba_keeps_the_stale_callee(tmp_path: Path) -> None:
    # what the refresh is for: numba alone loads the caller's machine code with the old callee
    assert _case(tmp_path, "") == ("2", "2")
