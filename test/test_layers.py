"""The packages' layer contracts (``.importlinter``, checked by ``lint-imports`` in ``make test``).

``make test`` runs the contracts on the tree; these tests hold the contracts themselves to
what docs/architecture.md says: every package is in a layer, and an upward import, a lazy
one included, an import between two stages, or a ROS import in ``hiros_core`` breaks them.
"""

from __future__ import annotations

import configparser
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / ".importlinter"
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")


def contracts() -> configparser.ConfigParser:
    """The repository's import-linter configuration."""
    config = configparser.ConfigParser()
    config.read(CONFIG)
    return config


def layer_packages(config: configparser.ConfigParser) -> list[str]:
    """Every package named in the layers contract, from the top layer down."""
    layers = config["importlinter:contract:layers"]["layers"].split()
    return [name for name in layers if name not in (":", "|")]


def test_every_package_is_in_a_layer() -> None:
    packages = {p.parent.name for p in REPO.glob("hiros_*/__init__.py")}
    config = contracts()
    assert set(config["importlinter"]["root_packages"].split()) == packages
    assert sorted(layer_packages(config)) == sorted(packages)


def lint(root: Path, files: dict[str, str]) -> subprocess.CompletedProcess[str]:
    """``lint-imports`` with the repository's contracts over empty packages plus ``files``."""
    for package in layer_packages(contracts()):
        (root / package).mkdir()
        (root / package / "__init__.py").write_text("")
    for name, text in files.items():
        (root / name).write_text(f"def f() -> None:\n    {text}\n")
    config = root / ".importlinter"
    config.write_text(CONFIG.read_text())
    return subprocess.run(
        [str(LINT_IMPORTS), "--no-cache", "--config", str(config)],
        cwd=root,
        capture_output=True,
        text=True,
        check=False,
    )


def broken_imports(report: str) -> set[str]:
    """``module -> imported`` for each import a ``lint-imports`` report names as breaking."""
    plain = re.sub(r"\x1b\[[0-9;]*m", "", report)
    return set(re.findall(r"^-\s+(\S+ -> \S+) \(l\.\d+\)$", plain, flags=re.MULTILINE))


def test_imports_down_and_within_a_layer_keep_the_contracts(tmp_path: Path) -> None:
    done = lint(
        tmp_path,
        {
            "hiros_cli/a.py": "from hiros_bench import b",
            "hiros_filter/c.py": "from hiros_core import f",
            "hiros_pipeline/g.py": "from hiros_visualizer import h",
            "hiros_ros/e.py": "import rclpy.node",
            "hiros_core/f.py": "import numpy",
        },
    )
    assert done.returncode == 0, done.stdout


def test_an_upward_or_ros_import_breaks_the_contracts(tmp_path: Path) -> None:
    done = lint(
        tmp_path,
        {
            "hiros_core/a.py": "from hiros_cli import main",
            "hiros_core/b.py": "import rclpy.node",
            "hiros_data/c.py": "from std_msgs.msg import Header",
            "hiros_bench/d.py": "from hiros_cli import main",
            "hiros_tracker/e.py": "import hiros_pipeline",
            "hiros_merger/f.py": "from hiros_tracker import e",
            "hiros_filter/g.py": "from hiros_optimizer import h",
            "hiros_optimizer/h.py": "import numpy",
        },
    )
    assert done.returncode == 1, done.stdout
    assert broken_imports(done.stdout) == {
        "hiros_core.a -> hiros_cli",
        "hiros_core.b -> rclpy",
        "hiros_data.c -> std_msgs",
        "hiros_bench.d -> hiros_cli",
        "hiros_tracker.e -> hiros_pipeline",
        "hiros_merger.f -> hiros_tracker.e",
        "hiros_filter.g -> hiros_optimizer.h",
    }
