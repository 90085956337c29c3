"""``hiros bench robust``: one condition's row, measured on a short simulation."""

from __future__ import annotations

import io

import numpy as np
import pytest

from hiros_bench.robust import HEADER, Row, mean_row, measure


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


def _row(seed: int, **changes: object) -> Row:
    figures: dict[str, object] = {
        "condition": "noisy-sdk",
        "mpjpe": dict.fromkeys(("tracker", "merger", "optimizer", "filter"), 0.1 + 0.01 * seed),
        "best_camera": 0.2,
        "switches": seed,
        "limb_cv": 0.002,
        "accepted": 2,
        "people": 2,
        "acceptance": 2.0 + seed,
        "angle_change": -0.3,
        "mirrored": 0.01 * seed,
        "fps": 4000.0,
    }
    return Row(**{**figures, **changes})  # type: ignore[arg-type]


def test_a_conditions_rows_over_seeds_average_their_figures_and_sum_their_counts() -> None:
    rows = [_row(0, mirror_run=0.5), _row(2, flagged=("k02",), mirror_run=2.0)]
    rows.append(_row(4, limb_cv=float("nan")))
    mean = mean_row(rows)
    assert mean.mpjpe["filter"] == pytest.approx(0.12)
    assert mean.mirrored == pytest.approx(0.02)
    assert mean.limb_cv == pytest.approx(0.002)  # a seed without accepted people adds nothing
    assert (mean.switches, mean.accepted, mean.people) == (6, 6, 6)
    assert mean.acceptance == 6.0  # the longest
    assert mean.mirror_run == 2.0  # the longest; a seed without the figure adds nothing
    assert mean.flagged == ("k02",)
    assert mean.ratio == pytest.approx(0.12 / 0.2)


def test_several_seeds_print_the_mean_then_each_seed(monkeypatch) -> None:
    from rich.console import Console

    from hiros_bench import robust
    from hiros_core.errors import CalibrationError

    def fake(condition: str, seed: int = 0, duration: float = 60.0, *, auto: bool = False) -> Row:
        if auto and seed == 1:
            raise CalibrationError("no body pair correlates clearly")
        return _row(seed, condition=condition, flagged=("k03",) if auto else ())

    monkeypatch.setattr(robust, "measure", fake)
    monkeypatch.setattr(robust, "CONDITIONS", ("noisy-sdk",))
    lines = robust.run(Console(file=io.StringIO()), quick=True, seeds=(0, 1, 2))
    true, auto = lines.index(robust.HEADER), len(lines) - 1 - lines[::-1].index(robust.HEADER)
    assert "seeds 0-2; each condition's mean, then each seed" in lines[true - 1]
    assert lines[true + 1].startswith("noisy-sdk ")
    assert [line.split()[:2] for line in lines[true + 2 : true + 5]] == [
        ["seed", "0"], ["seed", "1"], ["seed", "2"],
    ]  # fmt: skip
    assert lines[auto + 1].endswith("calibration flagged on 2 of 2 seeds; 1 seed(s) left out")
    assert "left out: no body pair correlates clearly" in lines[auto + 3]
