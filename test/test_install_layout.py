"""The installed layout `ros2 run hiros <node>` relies on, and a colcon build of both packages."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

NODES = [
    "azure_bridge",
    "calib",
    "tracker",
    "merger",
    "optimizer",
    "filter",
    "pipeline",
    "visualizer",
]


def test_ament_index_finds_every_node_executable(monkeypatch: pytest.MonkeyPatch) -> None:
    """As `ros2 run` does: package prefix from the ament index, then lib/<package>/<executable>."""
    packages = pytest.importorskip("ament_index_python.packages")
    if not os.environ.get("AMENT_PREFIX_PATH"):
        monkeypatch.setenv("AMENT_PREFIX_PATH", sys.prefix)
    prefix = Path(packages.get_package_prefix("hiros"))
    for node in NODES:
        executable = prefix / "lib" / "hiros" / node
        assert executable.exists(), executable
        assert os.access(executable, os.X_OK)
    assert (Path(packages.get_package_share_directory("hiros")) / "package.xml").is_file()
    assert packages.get_package_prefix("hiros_skeleton_msgs")


@pytest.mark.slow
def test_colcon_builds_both_packages_in_a_workspace(tmp_path: Path) -> None:
    """A system-ROS user's path: repo in src/, `colcon build`, executables in install/hiros/lib."""
    colcon = Path(sys.prefix) / "bin" / "colcon"
    if not colcon.exists():
        pytest.skip("colcon is not installed")
    source = tmp_path / "src" / "hiros"
    shutil.copytree(
        REPO,
        source,
        ignore=shutil.ignore_patterns(".venv", ".git", "build", "install", "log", "__pycache__"),
    )
    env = dict(os.environ, AMENT_PREFIX_PATH=sys.prefix, CMAKE_PREFIX_PATH=sys.prefix)
    env["PATH"] = f"{Path(sys.prefix) / 'bin'}{os.pathsep}{env['PATH']}"
    env["_ROS_WHEELS_BOOTSTRAP_COMPLETE"] = "1"
    result = subprocess.run(
        # The repo root is itself the `hiros` package, so colcon is shown the nested one too.
        [str(colcon), "build", "--base-paths", "src/hiros", "src/hiros/hiros_skeleton_msgs",
         "--cmake-args", f"-DPython3_EXECUTABLE={sys.executable}",
         "-DBUILD_TESTING=OFF"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    install = tmp_path / "install"
    assert (install / "hiros" / "lib" / "hiros" / "tracker").exists()
    assert (
        install / "hiros" / "share" / "ament_index" / "resource_index" / "packages" / "hiros"
    ).exists()
    generated = list((install / "hiros_skeleton_msgs").rglob("_skeleton_group.py"))
    assert generated, "SkeletonGroup Python bindings were not generated"
    assert not (install / "tf2_msgs").exists(), "third_party/ must be ignored by colcon"
