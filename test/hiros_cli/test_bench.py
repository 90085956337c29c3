"""``hiros bench``'s simulator settings for the calib suite."""

from __future__ import annotations

import pytest

from hiros_cli.commands.bench import _sim_overrides
from hiros_core.errors import ConfigError


def test_settings_take_their_fields_types() -> None:
    got = _sim_overrides(["oblique_gain=0", "n_people=2", "enter_leave=off", "drift_ppm=1e2"])
    assert got == {"oblique_gain": 0.0, "n_people": 2, "enter_leave": False, "drift_ppm": 100.0}
    assert isinstance(got["oblique_gain"], float)
    assert isinstance(got["n_people"], int)


@pytest.mark.parametrize("pair", ["nonsense=1", "oblique_gain", "oblique_gain=x", "setup=ring"])
def test_bad_settings_are_refused_with_the_reason(pair: str) -> None:
    with pytest.raises(ConfigError, match="--sim"):
        _sim_overrides([pair])


def test_a_suite_that_fails_its_own_verdict_makes_bench_exit_1(monkeypatch, capsys) -> None:
    import argparse

    from hiros_bench import SuiteFailedError, soak
    from hiros_cli.commands import bench

    def failing(console, quick: bool = False, minutes: float | None = None) -> list[str]:
        raise SuiteFailedError("the soak failed (exit status 1)")

    monkeypatch.setattr(soak, "run", failing)
    args = argparse.Namespace(
        suites=["soak"], sim=[], quick=True, minutes=0.1, matrix=False, seeds=None
    )
    assert bench.run(args) == 1
    assert "the soak failed" in capsys.readouterr().out


def test_seeds_reach_the_suites_that_take_them(monkeypatch) -> None:
    import argparse

    from hiros_bench import robust
    from hiros_cli.commands import bench

    taken = []
    monkeypatch.setattr(robust, "run", lambda console, quick=False, seeds=(0,): taken.append(seeds))
    args = argparse.Namespace(suites=["robust"], sim=[], quick=True, seeds="0-1,4", matrix=False)
    assert bench.run(args) == 0
    assert taken == [(0, 1, 4)]
    args.seeds = "4-1"
    with pytest.raises(ConfigError, match="runs backwards"):
        bench.run(args)  # before any suite runs
    assert len(taken) == 1
