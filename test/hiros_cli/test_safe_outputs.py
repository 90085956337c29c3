"""Issue 21, cases 1-5: no command destroys an input or a user's file, or leaves a cut output."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hiros_cli.main import main
from hiros_core.outputs import STAGING_PREFIX, is_calibration_file, is_hiros_recording
from hiros_sim import SimParams, simulate, write_recording


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("sim")
    write_recording(simulate(SimParams(n_cameras=2, n_people=1, duration=5.0, seed=2)), folder)
    return folder


def _copy(source: Path, target: Path) -> Path:
    target.write_bytes(source.read_bytes())
    return target


def _run(recording: Path, calibration: Path, out: Path, *extra: str) -> int:
    return main(["run", str(recording), "--calibration", str(calibration), "--out", str(out),
                 "--processes", "1", *extra])  # fmt: skip


def test_case1_a_recording_is_never_its_own_output(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recording = _copy(sim / "recording.mcap", tmp_path / "x.mcap")
    before = recording.read_bytes()
    assert _run(recording, sim / "calibration.yaml", recording, "--force") == 1
    assert "is the input" in capsys.readouterr().err
    assert recording.read_bytes() == before
    # through a symbolic link, and a folder holding the input
    link = tmp_path / "link.mcap"
    link.symlink_to(recording)
    assert _run(link, sim / "calibration.yaml", recording, "--force") == 1
    assert _run(recording, sim / "calibration.yaml", tmp_path, "--force") == 1
    assert "folder holding the input" in capsys.readouterr().err
    assert recording.read_bytes() == before


def test_case1_a_recording_folder_is_never_its_own_output(sim: Path, tmp_path: Path) -> None:
    folder = tmp_path / "rec"
    assert main(["convert", str(_csv(tmp_path)), "--out", str(folder)]) == 0
    files = sorted(p.name for p in folder.iterdir())
    assert _run(folder, sim / "calibration.yaml", folder, "--force") == 1
    assert sorted(p.name for p in folder.iterdir()) == files


def _csv(folder: Path) -> Path:
    path = folder / "people.csv"
    rows = ["camera,stamp_ns,body_id,joint,x,y,z"]
    rows += [f"k01,{k * 33_000_000},1,{j},0.{j},1.0,2.0" for k in range(5) for j in range(32)]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_case2_a_calibration_input_is_never_replaced(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration = _copy(sim / "calibration.yaml", tmp_path / "c.yaml")
    before = calibration.read_text()
    assert _run(sim / "recording.mcap", calibration, calibration, "--force") == 1
    assert "is the input" in capsys.readouterr().err
    assert calibration.is_file()
    assert calibration.read_text() == before


def test_force_replaces_only_a_recording_hiros_wrote(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.mcap"
    assert _run(sim / "recording.mcap", sim / "calibration.yaml", out) == 0
    assert is_hiros_recording(out)
    assert _run(sim / "recording.mcap", sim / "calibration.yaml", out) == 1
    assert "--force replaces it" in capsys.readouterr().err
    assert _run(sim / "recording.mcap", sim / "calibration.yaml", out, "--force") == 0
    notes = tmp_path / "notes.mcap"
    notes.write_text("my notes")
    assert _run(sim / "recording.mcap", sim / "calibration.yaml", notes, "--force") == 1
    assert "is not a recording this command made" in capsys.readouterr().err
    assert notes.read_text() == "my notes"
    assert not list(tmp_path.glob(f"{STAGING_PREFIX}*"))


def test_case3_calibrate_never_writes_over_its_recording_or_another_file(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recording = _copy(sim / "recording.mcap", tmp_path / "y.mcap")
    before = recording.read_bytes()
    assert main(["calibrate", str(recording), "--out", str(recording)]) == 1
    assert "is the input" in capsys.readouterr().err
    assert recording.read_bytes() == before
    other = tmp_path / "notes.yaml"
    other.write_text("shopping: [milk]\n")
    assert main(["calibrate", str(recording), "--out", str(other)]) == 1
    assert "not a calibration file" in capsys.readouterr().err
    assert other.read_text() == "shopping: [milk]\n"
    # an earlier calibration file is what calibrate makes: it is replaced
    calibration = _copy(sim / "calibration.yaml", tmp_path / "calib.yaml")
    # (3: written with a camera flagged as doubtful, as a 5 s take of one person may be)
    assert main(["calibrate", str(recording), "--out", str(calibration)]) in {0, 3}
    assert is_calibration_file(calibration)
    assert calibration.read_text() != (sim / "calibration.yaml").read_text()


def test_case4_simulate_refuses_an_existing_simulation_without_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sim"
    args = ["simulate", "--out", str(out), "--cameras", "2", "--people", "1", "--duration", "3"]
    assert main(args) == 0
    truth = (out / "truth.npz").read_bytes()
    assert main([*args, "--seed", "5"]) == 1
    assert "--force replaces it" in capsys.readouterr().err
    assert (out / "truth.npz").read_bytes() == truth
    assert main([*args, "--seed", "5", "--force"]) == 0
    assert (out / "truth.npz").read_bytes() != truth
    (out / "mine.txt").write_text("keep")
    assert main([*args, "--force"]) == 1
    assert "not a simulation folder" in capsys.readouterr().err
    assert (out / "mine.txt").read_text() == "keep"


def test_demo_never_removes_a_folder_it_did_not_make(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "thesis.tex").write_text("years of work")
    assert main(["demo", "--out", str(tmp_path), "--duration", "3"]) == 1
    assert "not a demo folder" in capsys.readouterr().err
    assert (tmp_path / "thesis.tex").read_text() == "years of work"


def test_case5_an_interrupted_run_leaves_nothing_under_its_name(
    sim: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import hiros_pipeline

    def interrupted(recording, calibration, out, *args, **kwargs):
        Path(out).write_bytes(b"\x89MCAP0\r\n half a run")
        raise KeyboardInterrupt

    monkeypatch.setattr(hiros_pipeline, "run_recording", interrupted)
    out = tmp_path / "out.mcap"
    assert _run(sim / "recording.mcap", sim / "calibration.yaml", out) == 130
    assert "interrupted" in capsys.readouterr().err
    assert sorted(tmp_path.iterdir()) == []


# Ctrl-C as a terminal delivers it: a suite started in the background (``make test &``)
# ignores SIGINT, its children inherit that, and Python then keeps ignoring it
_SLOW_RUN = """
import signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)
from pathlib import Path
import hiros_pipeline
def slow(recording, calibration, out, *args, **kwargs):
    Path(out).write_bytes(b"\\x89MCAP0\\r\\n half a run")
    time.sleep(60)
hiros_pipeline.run_recording = slow
from hiros_cli.main import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_case5_a_run_stopped_by_a_signal_leaves_nothing_under_its_name(
    sim: Path, tmp_path: Path, signum: int
) -> None:
    out = tmp_path / "out" / "out.mcap"
    command = [sys.executable, "-c", _SLOW_RUN, "run", str(sim / "recording.mcap"),
               "--calibration", str(sim / "calibration.yaml"), "--out", str(out)]  # fmt: skip
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not list(out.parent.glob(f"{STAGING_PREFIX}*/out.mcap")):
        assert process.poll() is None
        assert time.monotonic() < deadline
        time.sleep(0.05)
    os.kill(process.pid, signum)
    try:
        _, err = process.communicate(timeout=30)
    except subprocess.TimeoutExpired:  # say where it hung
        process.kill()
        _, err = process.communicate()
        pytest.fail(f"the run did not stop within 30 s of signal {signum}; its stderr: {err}")
    assert process.returncode == 128 + signum
    assert "terminated" in err or "interrupted" in err
    assert list(out.parent.iterdir()) == []
