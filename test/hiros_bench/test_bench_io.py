"""The io benchmark runs and prints one row per job (figures are not checked: no timing tests)."""

import pytest

from hiros_bench.io import run


class _Console:
    def __init__(self):
        self.lines = []

    def print(self, line, **_):
        self.lines.append(line)


@pytest.mark.slow
def test_io_bench_quick_prints_every_job():
    pytest.importorskip("hiros_skeleton_msgs.msg")
    console = _Console()
    lines = run(console, quick=True)
    assert lines == console.lines
    assert len(lines) == 6
    assert lines[1].startswith("bridge 2x32")
    assert "convert" in lines[-1]
