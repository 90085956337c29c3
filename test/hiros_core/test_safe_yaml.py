"""Issue 21 cases 7, 11, 13, 14: YAML inputs are read within limits, with one clear error."""

from __future__ import annotations

import resource
from pathlib import Path

import pytest

from hiros_cli.main import main
from hiros_core.calibration import load_calibration
from hiros_core.errors import CalibrationError, ConfigError, RecordingError
from hiros_core.parameters import load_config_defaults
from hiros_core.recording import RecordingReader
from hiros_core.safe_yaml import MAX_DEPTH, MAX_NODES, parse_yaml

_CAMERA = """reference: k01
cameras:
  k01:
    frame_id: k01_depth_camera_link
    translation: [0, 0, 0]
    rotation: [0, 0, 0, 1]
    quality: {quality}
"""


def _bomb(levels: int = 10, width: int = 10) -> str:
    """``levels`` anchors, each a list of ``width`` aliases of the one before."""
    lines = [f"a0: &a0 [{', '.join(['x'] * width)}]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, levels)]
    return "{" + ", ".join(lines) + "}"


def _max_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def test_case7_an_alias_bomb_in_a_calibration_is_refused_without_expanding_it(
    tmp_path: Path,
) -> None:
    path = tmp_path / "bomb.yaml"
    path.write_text(_CAMERA.format(quality=_bomb()))
    before = _max_rss_mb()
    with pytest.raises(CalibrationError, match=f"expand to more than {MAX_NODES}"):
        load_calibration(path)
    assert _max_rss_mb() - before < 100


def test_case7_a_large_yaml_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    path = tmp_path / "big.yaml"
    path.write_text(_CAMERA.format(quality="{notes: '" + "x" * (2 << 20) + "'}"))
    with pytest.raises(CalibrationError, match="larger than"):
        load_calibration(path)


@pytest.mark.parametrize(
    "nesting", ["[" * 100_000 + "]" * 100_000, "{a: " * 5000 + "1" + "}" * 5000]
)
def test_case11_deep_nesting_is_an_error_not_a_recursion_error(
    tmp_path: Path, nesting: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "deep.yaml"
    path.write_text(_CAMERA.format(quality=nesting))
    with pytest.raises(CalibrationError, match=f"deeper than {MAX_DEPTH}"):
        load_calibration(path)
    params = tmp_path / "params.yaml"
    params.write_text(f"pipeline:\n  ros__parameters:\n    tracker: {nesting}\n")
    with pytest.raises(ConfigError, match="deeper than"):
        load_config_defaults("pipeline", params)
    assert main(["evaluate", str(path), "--truth", str(tmp_path)]) == 1
    assert "deeper than" in capsys.readouterr().err


def test_a_recursive_alias_and_an_ordinary_alias(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="recursive"):
        parse_yaml("a: &a [1, *a]", source="x", error=ConfigError)
    assert parse_yaml("a: &v 2\nb: *v\n", source="x", error=ConfigError) == {"a": 2, "b": 2}


def test_case13_a_binary_metadata_yaml_is_a_clear_error(tmp_path: Path) -> None:
    folder = tmp_path / "rec"
    folder.mkdir()
    (folder / "metadata.yaml").write_bytes(bytes(range(256)) * 4)
    with pytest.raises(RecordingError, match="cannot read rosbag2 metadata"):
        RecordingReader(folder)
    (folder / "metadata.yaml").write_text(_bomb())
    with pytest.raises(RecordingError, match="expand to more than"):
        RecordingReader(folder)


@pytest.mark.parametrize(
    ("value", "message"),
    [(".nan", "not a finite number"), ("-0.5", "negative"), (".inf", "not a finite number")],
)
def test_case14_nan_or_negative_parameters_are_refused_naming_file_and_field(
    tmp_path: Path, value: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(f"pipeline:\n  ros__parameters:\n    tracker:\n      max_delay: {value}\n")
    code = main(["run", str(tmp_path / "none.mcap"), "--calibration", str(params),
                 "--out", str(tmp_path / "out.mcap"), "--params", str(params)])  # fmt: skip
    assert code == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "params.yaml: parameter tracker.max_delay: " in err
    assert message in err


def test_case14_load_pipeline_params(tmp_path: Path) -> None:
    from hiros_pipeline import load_pipeline_params

    params = tmp_path / "params.yaml"
    params.write_text("pipeline:\n  ros__parameters:\n    tracker:\n      max_delay: .nan\n")
    with pytest.raises(ConfigError, match=r"params.yaml: parameter tracker.max_delay: nan"):
        load_pipeline_params(params)
    params.write_text("pipeline:\n  ros__parameters:\n    filter:\n      cutoff_frequency: 4\n")
    assert load_pipeline_params(params).filter.cutoff_frequency == 4.0
