"""One colcon workspace holds Hi-ROS's packages and hiros's, as the README says: our message
package left out (COLCON_IGNORE), Hi-ROS's hiros_skeleton_msgs (same messages, no services)
and hiros_skeleton_optimizer (its services) built beside the hiros package; our optimizer node
then answers at /hiros/change_id with Hi-ROS's type.

Hi-ROS's packages are stood in for by interface packages made here from ours: the messages
without the services, and the two services under Hi-ROS's package name.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
REPO = Path(__file__).resolve().parents[2]
MESSAGES = REPO / "hiros_skeleton_msgs"

CLIENT = """
import sys, time, rclpy
from hiros_skeleton_optimizer.srv import ChangeId
rclpy.init()
node = rclpy.create_node("hiros_workspace_client")
client = node.create_client(ChangeId, "/hiros/change_id")
end = time.monotonic() + 120
while not client.service_is_ready() and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
future = client.call_async(ChangeId.Request(from_id=3, to_id=0))
rclpy.spin_until_future_complete(node, future, timeout_sec=20)
print("answer", future.result().ok if future.done() else "none")
print("type", dict(node.get_service_names_and_types())["/hiros/change_id"][0])
"""


def _interface_package(target: Path, name: str, files: list[str], depends: list[str]) -> None:
    """An ament_cmake interface package ``name`` of ``files`` (copied from ours)."""
    for file in files:
        (target / file).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(MESSAGES / file, target / file)
    listed = " ".join(f'"{file}"' for file in files)
    (target / "CMakeLists.txt").write_text(
        f"cmake_minimum_required(VERSION 3.8)\nproject({name})\n"
        "find_package(ament_cmake REQUIRED)\nfind_package(rosidl_default_generators REQUIRED)\n"
        + "".join(f"find_package({d} REQUIRED)\n" for d in depends)
        + f"rosidl_generate_interfaces(${{PROJECT_NAME}} {listed}"
        + f" DEPENDENCIES {' '.join(depends)})\n"
        "ament_export_dependencies(rosidl_default_runtime)\nament_package()\n"
    )
    manifest = (MESSAGES / "package.xml").read_text().replace("hiros_skeleton_msgs", name)
    (target / "package.xml").write_text(manifest)


def test_hiros_and_hiros_s_packages_in_one_workspace(tmp_path: Path, ros_env) -> None:
    colcon = Path(sys.prefix) / "bin" / "colcon"
    if not colcon.exists():
        pytest.skip("colcon is not installed")
    src = tmp_path / "src"
    shutil.copytree(REPO, src / "hiros", ignore=shutil.ignore_patterns(
        ".venv", ".git", "build", "install", "log", "__pycache__", "test"))  # fmt: skip
    (src / "hiros" / "hiros_skeleton_msgs" / "COLCON_IGNORE").touch()
    messages = sorted(str(p.relative_to(MESSAGES)) for p in (MESSAGES / "msg").glob("*.msg"))
    _interface_package(src / "hiros_skeleton_msgs", "hiros_skeleton_msgs", messages,
                       ["builtin_interfaces", "std_msgs", "geometry_msgs"])  # fmt: skip
    services = ["srv/Calibrate.srv", "srv/ChangeId.srv"]
    _interface_package(src / "hiros_skeleton_optimizer", "hiros_skeleton_optimizer", services, [])
    env = dict(ros_env, AMENT_PREFIX_PATH=sys.prefix, CMAKE_PREFIX_PATH=sys.prefix)
    env["PATH"] = f"{Path(sys.prefix) / 'bin'}{os.pathsep}{env['PATH']}"
    env["_ROS_WHEELS_BOOTSTRAP_COMPLETE"] = "1"
    build = subprocess.run(
        [str(colcon), "build", "--base-paths", "src",
         "--cmake-args", f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1200, check=False,
    )  # fmt: skip
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    install = tmp_path / "install"
    assert sorted(p.name for p in install.iterdir() if p.is_dir()) == [
        "hiros", "hiros_skeleton_msgs", "hiros_skeleton_optimizer"
    ]  # fmt: skip
    assert not list((install / "hiros_skeleton_msgs").rglob("_change_id.py"))  # Hi-ROS's: no srv
    setup = shlex.quote(str(install / "setup.bash"))
    node = subprocess.Popen(
        ["bash", "-c", f"source {setup} && exec {install}/hiros/lib/hiros/optimizer "
         "--ros-args -r __node:=skeleton_optimizer -r __ns:=/hiros"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    try:
        client = subprocess.run(
            ["bash", "-c", f"source {setup} && exec {shlex.quote(sys.executable)} -c "
             f"{shlex.quote(CLIENT)}"],
            env=env, capture_output=True, text=True, timeout=240, check=False,
        )  # fmt: skip
    finally:
        node.terminate()
        output = node.communicate(timeout=30)[0]
    assert client.stdout.splitlines() == [
        "answer False", "type hiros_skeleton_optimizer/srv/ChangeId"
    ], client.stderr + output  # fmt: skip
    assert "Traceback" not in output
