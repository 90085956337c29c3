"""``hiros run`` on bad input: one clear line and no output, or warnings on what was lost."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from mcap.reader import make_reader

from hiros_cli.main import main
from hiros_core.recording import RecordingReader, RecordingWriter
from hiros_sim import SimParams, simulate, write_recording


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("sim")
    write_recording(simulate(SimParams(n_cameras=2, n_people=1, duration=8.0, seed=1)), folder)
    return folder


def _run(sim: Path, recording: Path, out: Path, *extra: str) -> int:
    calibration = str(sim / "calibration.yaml")
    return main(["run", str(recording), "--calibration", calibration, "--out", str(out), *extra])


def test_a_recording_without_camera_topics_is_refused_before_any_output(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    chatter = tmp_path / "chatter.mcap"
    with RecordingWriter(chatter) as writer:
        writer.write("/chatter", "std_msgs/msg/String", b"\x00\x01\x00\x00\x02\x00\x00\x00a\x00", 1)
    out = tmp_path / "out.mcap"
    assert _run(sim, chatter, out) == 1
    err = capsys.readouterr().err
    assert "holds no camera skeletons" in err
    assert "['/chatter']" in err
    assert not out.exists()


def test_what_the_reader_lost_is_printed(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cut = tmp_path / "cut.mcap"
    with (sim / "recording.mcap").open("rb") as stream:
        (chunk, *_) = make_reader(stream).get_summary().chunk_indexes
    end = chunk.chunk_start_offset + chunk.chunk_length
    cut.write_bytes((sim / "recording.mcap").read_bytes()[: end + 5])  # a recorder killed there
    assert _run(sim, cut, tmp_path / "out.mcap", "--processes", "1") == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert "warning: " in printed
    assert "ends early or is damaged" in printed


def test_force_replaces_a_folder_output_but_not_a_folder_of_other_files(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    recording = sim / "recording.mcap"
    assert _run(sim, recording, out, "--processes", "1") == 0
    assert _run(sim, recording, out, "--processes", "1", "--force") == 0
    assert sorted(p.name for p in out.iterdir()) == ["metadata.yaml", "out_0.mcap"]
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert _run(sim, recording, out, "--processes", "1", "--force") == 1
    assert "is not a recording this command made" in capsys.readouterr().err
    assert (out / "out_0.mcap").exists()


@pytest.mark.parametrize("rate", ["nan", "-5", "inf", "fast"])
def test_a_merge_rate_without_a_period_is_a_usage_error(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], rate: str
) -> None:
    with pytest.raises(SystemExit) as exit_:
        _run(sim, sim / "recording.mcap", tmp_path / "out.mcap", "--merge-rate", rate)
    assert exit_.value.code == 2
    assert "is not a rate in Hz" in capsys.readouterr().err


def test_write_picks_the_outputs_and_refuses_unknown_ones(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "filter.mcap"
    assert _run(sim, sim / "recording.mcap", out, "--processes", "1", "--write", "filter") == 0
    assert "merger (not written)" in capsys.readouterr().out
    with RecordingReader(out) as reader:
        assert set(reader.topics) == {"/hiros/calibration", "/tf_static", "/hiros/filter"}
    assert main(["export", str(out), "--out", str(tmp_path / "x"), "--stage", "merger"]) == 1
    assert "holds no /hiros/merger output; it holds filter" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        _run(sim, sim / "recording.mcap", tmp_path / "x.mcap", "--write", "filter,tracks")
    assert exit_.value.code == 2
    assert "give one or more of tracker" in capsys.readouterr().err


def test_the_table_gives_each_persons_time_to_accept_the_limb_lengths(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _run(sim, sim / "recording.mcap", tmp_path / "out.mcap", "--processes", "1") == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert re.search(r"limb lengths: person \d+ │ accepted after \d\.\d s", printed), printed


def _marker_namespaces(out: Path) -> set[str]:
    from hiros_core.codec import decode_marker_array

    with RecordingReader(out) as reader:
        return {
            namespace
            for message in reader.messages({"/hiros/filter/markers"})
            for namespace in decode_marker_array(message.data).namespaces
        }


def test_overlays_go_into_the_output_markers(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plain, drawn = tmp_path / "plain.mcap", tmp_path / "drawn.mcap"
    common = ("--processes", "1", "--write", "filter,markers")
    assert _run(sim, sim / "recording.mcap", plain, *common) == 0
    assert _run(sim, sim / "recording.mcap", drawn, *common,
                "--overlays", "velocity,acceleration,knee_left") == 0  # fmt: skip
    assert not {n for n in _marker_namespaces(plain) if "/" in n}
    assert {"filter/velocity", "filter/acceleration", "filter/angles"} <= _marker_namespaces(drawn)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        _run(sim, sim / "recording.mcap", tmp_path / "x.mcap", "--overlays", "speed")
    assert exit_.value.code == 2
    assert "unknown overlays speed: choose among velocity" in capsys.readouterr().err
