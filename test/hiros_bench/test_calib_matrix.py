"""The calibration robustness matrix: rows per condition, and no silently wrong result."""

from __future__ import annotations

import io

import pytest
from rich.console import Console

from hiros_bench import calib_matrix


@pytest.mark.slow
def test_matrix_rows_report_outcomes_and_nothing_silently_wrong() -> None:
    console = Console(file=io.StringIO(), width=200)
    rows = ("host-clocks", "two-cameras-45", "exercise+walk")
    lines = calib_matrix.run(console, seeds=[1], duration=25.0, rows=rows)
    table = {
        line.split()[0]: line.split() for line in lines if line.split()[:1] in ([r] for r in rows)
    }
    assert set(table) == set(rows)
    for name, cells in table.items():
        runs, undecidable = int(cells[1]), int(cells[3])
        refused, flagged, silent = int(cells[5]), int(cells[6]), int(cells[7])
        assert runs == 1, name
        assert silent == 0, name
        assert undecidable <= refused
        assert refused + flagged <= runs
    assert any(line.startswith("KinectMultiTrack") or "KinectMultiTrack" in line for line in lines)
