"""hiros demo end to end on a shortened sample: every output written, the summary's figures sane."""

from __future__ import annotations

import re

import pytest

from hiros_cli.main import main
from hiros_core.calibration import load_calibration
from hiros_core.recording import RecordingReader


@pytest.mark.slow
def test_demo_writes_its_outputs_and_a_sane_summary(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--duration", "20"]) == 0
    printed = capsys.readouterr().out

    calibration = load_calibration(out / "calib.yaml")
    assert sorted(calibration.cameras) == ["k01", "k02", "k03"]
    with RecordingReader(out / "out.mcap") as reader:
        topics = set(reader.topics)
    assert {"/hiros/tracker", "/hiros/merger", "/hiros/optimizer", "/hiros/filter"} <= topics
    report = (out / "report" / "report.html").read_text()
    assert "<img" in report

    assert "3 cameras, 3 people, 20 s" in printed  # the length asked for, in the title
    assert "dropped with a reason" in printed
    frames_in, dropped = map(int, re.search(r"reason\D*(\d+) / (\d+)", printed).groups())
    assert frames_in > 0
    assert dropped == 0
    ratio = float(re.search(r"filter / best single camera\D*([\d.]+)", printed).group(1))
    assert ratio < 1.0  # three cameras fused beat the best one alone
    gain = float(re.search(r"filter vs tracker\D*?([-+][\d.]+) %", printed).group(1))
    assert gain < 0.0  # the chain lowers the joint-angle error
