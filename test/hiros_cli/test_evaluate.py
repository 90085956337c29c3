"""``hiros evaluate``'s tables keep every word whole in a narrow terminal."""

from __future__ import annotations

from rich.console import Console

from hiros_cli.commands.evaluate import _table

HEADERS = ["stage", "MPJPE cm", "limb CV %", "angle RMSE deg", "IDF1", "ID switches", "fragments"]
ROWS = [["optimizer", "9.13", "1.71", "15.67", "1.000", "0", "0"]]


def _printed(width: int) -> str:
    console = Console(width=width, record=True)
    console.print(_table("stages", HEADERS, ROWS, console.width))
    return console.export_text()


def test_a_table_too_wide_wraps_its_headers_between_words() -> None:
    narrow = _printed(72)
    assert "…" not in narrow
    assert all(word in narrow for word in ("optimizer", "fragments", "switches", "15.67"))
    assert max(len(line) for line in narrow.splitlines()) <= 72


def test_a_table_that_fits_keeps_its_headers_on_one_line() -> None:
    wide = _printed(120)
    assert "angle RMSE deg" in wide
    assert "ID switches" in wide
