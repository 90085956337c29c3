"""hiros_core.outputs: an output appears whole under its name, or not at all."""

from __future__ import annotations

from pathlib import Path

import pytest

from hiros_core.errors import OutputError
from hiros_core.outputs import STAGING_PREFIX, check_output, staged_output


def test_a_failed_write_leaves_the_earlier_output_and_no_staging(tmp_path: Path) -> None:
    final = tmp_path / "out.txt"
    final.write_text("earlier")

    def half_written() -> None:
        with staged_output(final, replace=True) as staged:
            staged.write_text("half")
            raise RuntimeError

    with pytest.raises(RuntimeError):
        half_written()
    assert final.read_text() == "earlier"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]
    with staged_output(final, replace=True) as staged:
        assert staged.name == "out.txt"
        assert staged.parent.name.startswith(STAGING_PREFIX)
        staged.write_text("new")
    assert final.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]


def test_a_folder_output_replaces_a_folder_and_an_unexpected_one_is_kept(tmp_path: Path) -> None:
    final = tmp_path / "rec"
    final.mkdir()
    (final / "old").write_text("old")
    with staged_output(final, replace=True) as staged:
        staged.mkdir()
        (staged / "new").write_text("new")
    assert sorted(p.name for p in final.iterdir()) == ["new"]
    other = tmp_path / "other"

    def raced() -> None:
        with staged_output(other) as staged:
            staged.write_text("mine")
            other.write_text("someone else's")

    with pytest.raises(OutputError, match="appeared"):
        raced()
    assert other.read_text() == "someone else's"


def test_check_output_names_the_input_and_what_may_be_replaced(tmp_path: Path) -> None:
    source = tmp_path / "data" / "take.mcap"
    source.parent.mkdir()
    source.write_bytes(b"x")
    with pytest.raises(OutputError, match="is the input"):
        check_output(source, inputs=[source], force=True, ours=lambda _: True)
    with pytest.raises(OutputError, match="folder holding the input"):
        check_output(source.parent, inputs=[source], force=True, ours=lambda _: True)
    with pytest.raises(OutputError, match="exists already"):
        check_output(source, ours=lambda _: True, what="recording")
    with pytest.raises(OutputError, match="not a recording this command made"):
        check_output(source, force=True, ours=lambda _: False, what="recording")
    check_output(source, force=True, ours=lambda _: True)
    check_output(tmp_path / "new.mcap", inputs=[source])
