"""Simulator seeds as the benchmarks take them (``--seeds 0-3,7``) and name them."""

from __future__ import annotations

import pytest

from hiros_bench.seeds import parse_seeds, seeds_text
from hiros_core.errors import ConfigError


def test_seeds_are_listed_and_ranged() -> None:
    assert parse_seeds("0-3,7") == (0, 1, 2, 3, 7)
    assert parse_seeds("5") == (5,)
    assert parse_seeds(" 4 , 10-11") == (4, 10, 11)


@pytest.mark.parametrize("text", ["", "a", "3-1", "1,,2", "-2", "0-3,2", "1.5"])
def test_bad_seeds_are_refused_with_the_reason(text: str) -> None:
    with pytest.raises(ConfigError, match="seeds"):
        parse_seeds(text)


def test_seeds_are_named_as_ranges() -> None:
    assert seeds_text((0, 1, 2, 3, 7)) == "0-3,7"
    assert seeds_text((0, 1, 4, 5, 6, 7, 8, 9)) == "0-1,4-9"
    assert seeds_text((3,)) == "3"
    assert seeds_text(parse_seeds("2,0-1")) == "2,0-1"  # the order given is kept
