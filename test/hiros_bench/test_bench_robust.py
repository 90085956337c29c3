"""``hiros bench robust``: one condition's row, measured on a short simulation."""

from __future__ import annotations

import numpy as np

from hiros_bench.robust import HEADER, measure


def test_a_condition_row_judges_every_stage_against_the_truth() -> None:
    row = measure("one-person", duration=8.0)
    assert set(row.mpjpe) == {"tracker", "merger", "optimizer", "filter"}
    assert row.mpjpe["filter"] < row.mpjpe["tracker"]
    assert 0 < row.ratio < 1
    assert row.switches == 0
    assert row.accepted == row.people == 1
    assert 1.5 < row.acceptance < 4.0  # a 60-frame window at 30 Hz, from the first frame
    assert row.limb_cv < 0.01  # the limb lengths are locked after acceptance
    assert 0 <= row.mirrored < 0.1
    assert np.isfinite(row.angle_change)
    assert len(row.line().split()) == len(HEADER.split())
