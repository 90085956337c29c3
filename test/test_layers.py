"""The packages' layers (docs/architecture.md): no package imports one of a higher layer.

core <- ros <- stages <- tools over the stages <- benchmarks <- command line. Every import
counts, at module level or inside a function (a lazy import is still a dependency), and
``TYPE_CHECKING`` ones too.
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

LAYERS = (
    ("hiros_core", "hiros_data"),
    ("hiros_ros",),
    (
        "hiros_tracker", "hiros_merger", "hiros_optimizer", "hiros_filter", "hiros_calib",
        "hiros_azure_bridge",
    ),
    ("hiros_pipeline", "hiros_sim", "hiros_eval", "hiros_convert", "hiros_visualizer"),
    ("hiros_bench",),
    ("hiros_cli",),  # ``hiros bench`` runs the benchmarks
)  # fmt: skip
"""From the bottom up; a package may import its own layer's and the ones below."""

LAYER = {package: level for level, packages in enumerate(LAYERS) for package in packages}
ROS = ("rclpy", "rosidl_runtime_py", "launch", "launch_ros", "ament_index_python")
"""What only ``hiros_ros`` and the layers above may import: ``hiros_core`` is ROS-free."""


def imported(path: Path) -> set[str]:
    """Top-level names of every module ``path`` imports (absolute imports only)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def upward_imports(root: Path) -> list[str]:
    """``file: package`` for each import of a package of a higher layer under ``root``."""
    found = []
    for package, level in LAYER.items():
        for path in sorted((root / package).rglob("*.py")):
            above = {n for n in imported(path) if LAYER.get(n, -1) > level}
            if package == "hiros_core":
                above |= imported(path) & set(ROS)
            found += [f"{path.relative_to(root)}: {name}" for name in sorted(above)]
    return found


def test_every_package_is_in_a_layer() -> None:
    packages = {p.parent.name for p in REPO.glob("hiros_*/__init__.py")}
    assert packages == set(LAYER)


def test_no_package_imports_a_higher_layer() -> None:
    assert upward_imports(REPO) == []


def test_an_upward_import_is_found(tmp_path: Path) -> None:
    files = {
        "hiros_core/a.py": "from hiros_cli.commands import run",
        "hiros_core/b.py": "import rclpy.node",
        "hiros_ros/c.py": "import rclpy",
        "hiros_cli/d.py": "from hiros_bench import calib",
        "hiros_bench/e.py": "from hiros_cli import main",
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text(f"def f():\n    {text}\n")
    assert upward_imports(tmp_path) == [
        "hiros_core/a.py: hiros_cli",
        "hiros_core/b.py: rclpy",
        "hiros_bench/e.py: hiros_cli",
    ]

