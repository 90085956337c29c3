"""The calib benchmark's table: every setup with its pose baseline (figures are not judged)."""

import math
import re
from contextlib import nullcontext

import pytest

from hiros_bench.calib import SETUPS, run


class _Console:
    def __init__(self):
        self.lines = []

    def print(self, line, **_):
        self.lines.append(line)

    def status(self, _text):
        return nullcontext()


@pytest.mark.slow
def test_calib_bench_prints_each_setup_beside_its_baselines_floor_and_live_check():
    console = _Console()
    lines = run(console, seeds=[1], duration=30.0)
    assert lines == console.lines
    rows = [line for line in lines if line.split(" ")[0] in SETUPS]
    baselines = [line for line in lines if "pose baseline" in line]
    floors = [line for line in lines if "given the true rotation" in line]
    assert len(rows) == len(baselines) == len(floors) == len(SETUPS)
    knocks = [line for line in lines if line.startswith("live ")]
    assert [line.split(" at ")[0].split("turned ")[1] for line in knocks] == [
        "5° and slid 10 cm",
        "2° and slid 5 cm",
    ]
    for live in knocks:
        assert "1 runs" in live
        assert "0 missed" in live
        assert "0 false alarms" in live
    for line in floors:
        median, p95 = (float(x) for x in re.findall(r"\d+\.\d+", line))
        assert 0.0 <= median <= p95 < 10.0
    for line in baselines:
        figures = [float(x) for x in re.findall(r"-?\d+\.\d+|nan", line)]
        assert "0 unsolved" in line
        assert all(math.isfinite(x) and x >= 0 for x in figures)
