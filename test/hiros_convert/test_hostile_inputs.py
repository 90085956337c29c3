"""Issue 21 cases 12 and 15: hostile converter inputs give a counted result or one clear error."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest

from hiros_cli.main import main
from hiros_convert import read_streams
from hiros_core.errors import RecordingError

_JOINTS = 32


def _body(body_id: object) -> dict:
    return {
        "body_id": body_id,
        "joint_positions": [[0.0, 0.0, 2000.0]] * _JOINTS,
        "joint_orientations": [[1.0, 0.0, 0.0, 0.0]] * _JOINTS,
    }


def _k4abt(path: Path, frames: list[tuple[str, str]]) -> Path:
    """A k4abt file whose frames have the raw JSON ``timestamp_usec`` and ``body_id`` given."""
    template = json.dumps({"timestamp_usec": "STAMP", "num_bodies": 1, "bodies": [_body("ID")]})
    text = ", ".join(
        template.replace('"STAMP"', stamp).replace('"ID"', body_id) for stamp, body_id in frames
    )
    path.write_text(f'{{"frames": [{text}]}}')
    return path


@pytest.mark.parametrize(
    ("stamp", "body_id", "reason"),
    [("1e400", "1", "bad_frame"), ("1e30", "1", "bad_frame"), ("-5", "1", "bad_frame"),
     ("33000", "1e30", "bad_body"), ("33000", "1e400", "bad_body")],
)  # fmt: skip
def test_case12_absurd_k4abt_numbers_are_counted_not_raised(
    tmp_path: Path, stamp: str, body_id: str, reason: str
) -> None:
    path = _k4abt(tmp_path / "take.json", [("0", "1"), (stamp, body_id), ("66000", "1")])
    drops: Counter[str] = Counter()
    streams = read_streams(path, "k4abt-json", drops=drops)
    assert len(streams["k01"].groups) == 2
    assert drops[reason] == 1


def test_case12_deeply_nested_json_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "deep.json"
    path.write_text("[" * 200_000 + "]" * 200_000)
    with pytest.raises(RecordingError, match="nests too deep"):
        read_streams(path, "k4abt-json")
    assert main(["convert", str(path), "--out", str(tmp_path / "out.mcap")]) == 1
    err = capsys.readouterr().err
    assert "nests too deep" in err
    assert not (tmp_path / "out.mcap").exists()


@pytest.mark.parametrize("fmt", ["csv", "multitrack-csv"])
def test_case15_camera_names_that_become_one_topic_are_refused(
    tmp_path: Path, fmt: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "cams.csv"
    if fmt == "csv":
        rows = [f"{cam},{k * 33_000_000},1,Pelvis,0,0,2" for k in range(100)
                for cam in ("cam-A", "cam_A")]  # fmt: skip
        path.write_text("camera,stamp_ns,body_id,joint,x,y,z\n" + "\n".join(rows) + "\n")
    else:
        header = "Kinect_Id,Person_Id,Skeleton_Time,SpineBase_X,SpineBase_Y,SpineBase_Z"
        rows = [f"{cam},1,{k * 330_000},0,0,2" for k in range(100) for cam in ("cam-A", "cam_A")]
        path.write_text(header + "\n" + "\n".join(rows) + "\n")
    with pytest.raises(RecordingError, match="'cam-A' and 'cam_A' both become"):
        read_streams(path, fmt)
    assert main(["convert", str(path), "--out", str(tmp_path / "out.mcap")]) == 1
    assert "both become the topic namespace 'cam_A'" in capsys.readouterr().err
    assert not (tmp_path / "out.mcap").exists()


def test_a_csv_past_the_size_limit_is_refused_before_reading(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from hiros_convert import _table

    path = tmp_path / "big.csv"
    rows = [f"k01,{k},1,Pelvis,0,0,2" for k in range(1000)]
    path.write_text("camera,stamp_ns,body_id,joint,x,y,z\n" + "\n".join(rows) + "\n")
    monkeypatch.setattr(_table, "MAX_CSV_BYTES", 10_000)
    with pytest.raises(RecordingError, match="larger than 10000 bytes"):
        read_streams(path, "csv")
