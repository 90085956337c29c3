"""A kernel calling another module's kernel recompiles when only the callee's file changed."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import os
import pkgutil
import subprocess
import sys
import textwrap
from pathlib import Path
from types import ModuleType

from numba.core.dispatcher import Dispatcher

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


KERNEL_PACKAGES = (
    "hiros_core", "hiros_tracker", "hiros_merger", "hiros_optimizer", "hiros_filter",
    "hiros_visualizer",
)  # fmt: skip


def _kernel_modules() -> list[ModuleType]:
    """The modules of ``KERNEL_PACKAGES`` that define numba kernels (read first, then imported)."""
    found = []
    for package in KERNEL_PACKAGES:
        for info in pkgutil.walk_packages(importlib.import_module(package).__path__, f"{package}."):
            spec = importlib.util.find_spec(info.name)
            if spec and spec.origin and "@njit" in Path(spec.origin).read_text(encoding="utf-8"):
                found.append(importlib.import_module(info.name))
    return found


def _refreshed(module: ModuleType) -> set[str]:
    """The modules ``module``'s ``refresh_stale_caches`` call compares with (its default alone)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(inspect.getsource(module))):
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "refresh_stale_caches":
            extra = [vars(module)[arg.id].__name__ for arg in node.args[1:]]
            names |= set(extra) or {"hiros_core.compiled"}
    return names


def test_every_kernel_calling_another_modules_kernels_refreshes_on_that_module() -> None:
    # The tracker's hit_frame kept running the old turn_facing after an edit of facing.py
    # alone, until hit.py and facing.py refreshed on the modules they call.
    modules = _kernel_modules()
    assert len(modules) > 10, "the kernel modules were not found"
    for module in modules:
        kernels = [v for v in vars(module).values() if isinstance(v, Dispatcher)]
        own = [k for k in kernels if k.py_func.__module__ == module.__name__]
        callees = {k.py_func.__module__ for k in kernels} - {module.__name__}
        if own and callees:
            missing = callees - _refreshed(module)
            assert not missing, f"{module.__name__} calls kernels of {missing} without refreshing"
