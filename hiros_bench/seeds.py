"""Simulator seeds as a user writes them (``0-3,7``) and as a table names them.

One seed of a simulated condition is one draw of people, motion and SDK noise; a change to
the stages or the calibration moves single seeds by whole points (docs/stages-robustness.md),
so the benchmarks take a set of seeds and say which they ran.
"""

from __future__ import annotations

from collections.abc import Sequence

from hiros_core.errors import ConfigError

__all__ = ["parse_seeds", "seeds_text"]


def parse_seeds(text: str) -> tuple[int, ...]:
    """``"0-3,7"`` -> ``(0, 1, 2, 3, 7)``: comma-separated seeds and inclusive ranges.

    Raises:
        ConfigError: an empty list, a part that is not a non-negative whole number or a
            range ``FIRST-LAST`` with ``FIRST <= LAST``, or a seed given twice.

    """
    seeds: list[int] = []
    for part in text.split(","):
        first, dash, last = part.strip().partition("-")
        if not (first.isdigit() and (last.isdigit() if dash else True)):
            msg = f"seeds {text!r}: expected e.g. 0-3,7 (whole numbers from 0, ranges inclusive)"
            raise ConfigError(msg)
        start, stop = int(first), int(last) if dash else int(first)
        if stop < start:
            msg = f"seeds {text!r}: the range {part.strip()} runs backwards"
            raise ConfigError(msg)
        seeds += range(start, stop + 1)
    if len(set(seeds)) != len(seeds):
        msg = f"seeds {text!r}: a seed is given twice"
        raise ConfigError(msg)
    return tuple(seeds)


def seeds_text(seeds: Sequence[int]) -> str:
    """``(0, 1, 2, 3, 7)`` -> ``"0-3,7"``: consecutive seeds as ranges, in the given order."""
    runs: list[list[int]] = []
    for seed in seeds:
        if runs and seed == runs[-1][1] + 1:
            runs[-1][1] = seed
        else:
            runs.append([seed, seed])
    return ",".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)
