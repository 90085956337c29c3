"""Parameter files given by hand: the wrong file is refused, not silently ignored."""

from __future__ import annotations

from pathlib import Path

import pytest

from hiros_core.errors import ConfigError
from hiros_core.parameters import RemovedParameterWarning, config_path, load_config_defaults


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"\x89MCAP0\r\n\xd9\xff", "cannot read parameter file"),
        (b"reference: k01\ncameras: {k01: {}}\n", "no ROS 2 parameter file for pipeline"),
        (b"- 1\n- 2\n", "no ROS 2 parameter file for pipeline"),
        (b"pipeline:\n  ros__parameters: 5\n", "must be a mapping"),
    ],
)
def test_a_wrong_parameter_file_is_refused(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "params.yaml"
    path.write_bytes(content)
    with pytest.raises(ConfigError, match=message):
        load_config_defaults("pipeline", path)


def test_a_parameter_file_for_all_nodes_is_read(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    path.write_text("/**:\n  ros__parameters:\n    merger: {output_rate: 10.0}\n")
    assert load_config_defaults("pipeline", path) == {"merger.output_rate": 10.0}
    shipped = config_path("pipeline")
    assert shipped is not None
    assert load_config_defaults("pipeline", shipped) == load_config_defaults("pipeline")


def test_an_old_file_setting_a_removed_parameter_loads_with_a_warning(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    path.write_text(
        "pipeline:\n  ros__parameters:\n    filter: {compiled: true, max_gap: 0.4}\n"
        "    optimizer: {compiled: false}\n"
    )
    with pytest.warns(RemovedParameterWarning) as caught:
        values = load_config_defaults("pipeline", path)
    assert values == {"filter.max_gap": 0.4}
    assert sorted(str(w.message).split(": parameter ")[1].split()[0] for w in caught) == [
        "filter.compiled",
        "optimizer.compiled",
    ]
