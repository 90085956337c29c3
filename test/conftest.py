"""Shared fixtures: real data paths and a fresh ROS_DOMAIN_ID per ROS test."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import settings

# every property test draws the same examples on every run, so that a CI result is the
# code's, not the draw's (the tracker's kernel references did so already); a test's own
# @settings keep their example counts and inherit this
settings.register_profile("hiros", derandomize=True)
settings.load_profile("hiros")

REPO = Path(__file__).resolve().parent.parent
SHARED_DATA = REPO.parent / "shared" / "data"
_domains = itertools.count(int(os.environ.get("HIROS_TEST_DOMAIN_BASE", "40")) + os.getpid() % 40)


def shared_data(*parts: str) -> Path:
    """A file of ../shared/data; skips the test where the folder is absent (a user's checkout)."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} is not available")
    return path


@pytest.fixture
def ros_env(monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """Environment for ROS 2 child processes: own domain id, localhost-only discovery."""
    domain = str(next(_domains) % 100 + 100)
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return dict(os.environ)


class RosProcesses:
    """ROS 2 node processes of one test: started with the test's environment, always stopped.

    ``stop()`` terminates them (a node's SIGTERM handler shuts it down cleanly) and returns
    everything they printed, so a test can assert that no node raised.
    """

    def __init__(self, env: dict[str, str], cwd: Path | None = None) -> None:
        self.env = env
        self.cwd = cwd  # node processes write files here (the calib node saves at shutdown)
        self.processes: list[subprocess.Popen] = []

    def node(self, module: str, *ros_args: str, function: str = "main") -> subprocess.Popen:
        """Start ``module.function()`` as a node, with ``--ros-args ros_args`` when given."""
        extra = ["--ros-args", *ros_args] if ros_args else []
        code = f"from {module} import {function}; {function}()"
        return self.command([sys.executable, "-c", code, *extra])

    def command(self, command: list[str]) -> subprocess.Popen:
        """Start any command as one of the test's processes."""
        process = subprocess.Popen(
            command,
            env=self.env,
            cwd=self.cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.processes.append(process)
        return process

    def client(self, script: Path, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
        """Run a client script to completion (its output captured)."""
        return subprocess.run(
            [sys.executable, str(script), *args],
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )

    def stop(self) -> str:
        """Terminate every process still running; their combined output."""
        outputs = []
        for process in self.processes:
            if process.poll() is None:
                process.terminate()
            outputs.append(process.communicate(timeout=30)[0] or "")
        self.processes.clear()
        return "".join(outputs)


@pytest.fixture
def ros_processes(ros_env: dict[str, str], tmp_path: Path):
    """A RosProcesses for the test, working in its tmp_path; stopped afterwards."""
    processes = RosProcesses(ros_env, cwd=tmp_path)
    yield processes
    processes.stop()


@pytest.fixture
def ros_context(ros_env: dict[str, str]):
    """rclpy initialised in this process (own domain id) for a node built in the test."""
    rclpy = pytest.importorskip("rclpy")
    pytest.importorskip("hiros_skeleton_msgs.msg")
    rclpy.init()
    yield
    rclpy.shutdown()


class LogLines:
    """Stands in for a node's logger: keeps ``(level, message)`` of every line."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def __getattr__(self, level: str) -> Callable[..., None]:  # info, warning, error, ...
        return lambda message, **_: self.lines.append((level, message))


@pytest.fixture
def log_lines() -> LogLines:
    """A LogLines to put in place of a node's ``get_logger()``."""
    return LogLines()
