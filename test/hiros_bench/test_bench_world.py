"""hiros bench world: the estimated world's up and floor against the simulator's truth."""

from __future__ import annotations

import io

import pytest
from rich.console import Console

from hiros_bench import world


@pytest.mark.slow
def test_world_bench_prints_up_and_floor_per_condition() -> None:
    console = Console(file=io.StringIO(), width=200)
    lines = world.run(console, seeds=[1], duration=30.0, rows=("default",))
    row = next(line.split() for line in lines if line.startswith("default "))
    runs, up = int(row[1]), row[2].split("/")
    assert runs == 1
    assert float(up[0]) == float(up[1]) < 1.0  # one run: its median is its maximum
    assert abs(float(row[3])) < 5.0
    assert int(row[5]) + int(row[6]) <= 1  # doubtful, silently off
    seed, figures = row[7].rstrip("?!").split(":")  # the run, named by its seed
    assert seed == "1"
    assert figures == f"{float(up[0]):.2f}/{float(row[3]):+.1f}"
