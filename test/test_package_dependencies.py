"""package.xml declares, by rosdep key, every third-party module the package imports, so that
``rosdep install`` then ``colcon build`` give nodes that start (they failed on ``import numba``).

The keys are rosdistro's where it has one for Ubuntu Noble, else defined in rosdep/hiros.yaml
(rosdistro checked at commit 000730d: python.yaml has no rich, mcap, rosbags, lz4, zstandard
or zlib-ng key, and its python3-numba names only Ubuntu bionic and focal).
"""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parent.parent

KEYS = {
    "rclpy": "rclpy",
    "ament_index_python": "ament_index_python",
    "builtin_interfaces": "builtin_interfaces",
    "std_msgs": "std_msgs",
    "std_srvs": "std_srvs",
    "geometry_msgs": "geometry_msgs",
    "visualization_msgs": "visualization_msgs",
    "diagnostic_msgs": "diagnostic_msgs",
    "tf2_msgs": "tf2_msgs",
    "rosgraph_msgs": "rosgraph_msgs",
    "rcl_interfaces": "rcl_interfaces",
    "hiros_skeleton_msgs": "hiros_skeleton_msgs",
    "launch": "launch",
    "launch_ros": "launch_ros",
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib",
    "numba": "python3-numba-pip",
    "rich": "python3-rich-pip",
    "mcap": "python3-mcap-pip",
    "rosbags": "python3-rosbags-pip",
    "zlib_ng": "python3-zlib-ng-pip",
    "lz4": "python3-lz4",
    "zstandard": "python3-zstandard",
    "norfair": "python3-norfair-pip",
    "OneEuroFilter": "python3-oneeurofilter-pip",
}
"""Top-level module -> the rosdep key that installs it."""

OPTIONAL = {"hiros_skeleton_optimizer"}
"""Imported when installed, never needed: Hi-ROS's service types (hiros_optimizer.node)."""

ROSDISTRO_KEYS = {"python3-numpy", "python3-scipy", "python3-yaml", "python3-matplotlib"}
"""Python keys of rosdistro's python.yaml that resolve on Ubuntu Noble (checked at 000730d)."""


def third_party_imports() -> dict[str, set[str]]:
    """Top-level module -> the files of the package (and its launch files) importing it."""
    ours = {path.parent.name for path in REPO.glob("hiros_*/__init__.py")}
    files = [*REPO.glob("hiros_*/**/*.py"), *REPO.glob("launch/*.py")]
    found: dict[str, set[str]] = {}
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.partition(".")[0]
                if top not in sys.stdlib_module_names and top not in ours:
                    found.setdefault(top, set()).add(str(path.relative_to(REPO)))
    return found


def declared() -> dict[str, set[str]]:
    """package.xml's dependencies by tag."""
    root = ET.parse(REPO / "package.xml").getroot()
    tags: dict[str, set[str]] = {}
    for element in root:
        if element.tag.endswith("depend"):
            tags.setdefault(element.tag, set()).add(element.text.strip())
    return tags


def test_every_third_party_import_is_a_declared_dependency() -> None:
    imports = {k: v for k, v in third_party_imports().items() if k not in OPTIONAL}
    unknown = {module: sorted(files) for module, files in imports.items() if module not in KEYS}
    assert not unknown, f"imports without a rosdep key in KEYS: {unknown}"
    run_time = declared()["exec_depend"]
    missing = {KEYS[module] for module in imports} - run_time
    assert not missing, f"package.xml lacks {sorted(missing)}"
    stale = run_time - set(KEYS.values())
    assert not stale, f"package.xml declares what nothing imports: {sorted(stale)}"


def test_every_python_key_resolves_from_rosdistro_or_our_rosdep_file() -> None:
    ours = yaml.safe_load((REPO / "rosdep" / "hiros.yaml").read_text())
    python_keys = {key for key in declared()["exec_depend"] if key.startswith("python3-")}
    assert python_keys <= ROSDISTRO_KEYS | set(ours)
    for key in set(ours):
        for system in ("debian", "ubuntu"):
            rule = ours[key][system]
            assert rule, (key, system)
            assert isinstance(rule, list) or rule["pip"]["packages"], (key, system)
    assert not set(ours) & ROSDISTRO_KEYS  # never a second definition of rosdistro's
