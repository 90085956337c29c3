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
        "pipeline:\n  ros__parameters:\n    filter: {compiled: true, cutoff_frequency: 4.0}\n"
        "    optimizer: {compiled: false}\n    tracker: {compiled: true}\n"
    )
    with pytest.warns(RemovedParameterWarning) as caught:
        values = load_config_defaults("pipeline", path)
    # by node: the tracker never had it (the pipeline refuses it as unknown)
    assert values == {"filter.cutoff_frequency": 4.0, "tracker.compiled": True}
    assert sorted(str(w.message).split(": parameter ")[1].split()[0] for w in caught) == [
        "filter.compiled",
        "optimizer.compiled",
    ]


def test_an_old_calib_file_loads_without_the_parameters_that_became_constants(
    tmp_path: Path,
) -> None:
    """The calib node's statistical settings (grid_step ... loss) became constants, loss_scale
    went, and a setting that stays (prior_window) still loads."""
    path = tmp_path / "calib.yaml"
    path.write_text(
        "calib:\n  ros__parameters:\n    max_offset: 2.0\n    grid_step: 0.01\n"
        "    min_lag_margin: 1.15\n    step_period: 0.2\n    loss_scale: 0.0\n    loss: soft_l1\n"
        "    prior_window: 0.5\n"
    )
    with pytest.warns(RemovedParameterWarning) as caught:
        values = load_config_defaults("calib", path)
    assert values == {"max_offset": 2.0, "prior_window": 0.5}
    messages = sorted(str(w.message) for w in caught)
    assert len(messages) == 5
    assert any("constant GRID_STEP" in m for m in messages)
    assert any("parameter loss_scale is ignored" in m for m in messages)
    assert any("constant LOSS" in m for m in messages)


def test_an_old_pipeline_file_loads_without_the_stages_removed_parameters(tmp_path: Path) -> None:
    """The merger's direction fusion, back-view and agreement weights and its limb switch went;
    the filter's, optimizer's and bridges' numerical settings became constants."""
    path = tmp_path / "pipeline.yaml"
    path.write_text(
        "pipeline:\n  ros__parameters:\n"
        "    merger: {fuse_directions: false, view_weight_min: 1.0, agreement_scale: 0.0,"
        " limb_residuals: true, window: 0.2}\n"
        "    optimizer: {sweeps: 1, refinements: 2}\n    filter: {rate_tolerance: 0.15}\n"
    )
    with pytest.warns(RemovedParameterWarning) as caught:
        values = load_config_defaults("pipeline", path)
    assert values == {"merger.window": 0.2}
    messages = sorted(str(w.message).split(": parameter ")[1] for w in caught)
    assert [m.split()[0] for m in messages] == [
        "filter.rate_tolerance",
        "merger.agreement_scale",
        "merger.fuse_directions",
        "merger.limb_residuals",
        "merger.view_weight_min",
        "optimizer.refinements",
        "optimizer.sweeps",
    ]
    assert "constant RATE_TOLERANCE" in messages[0]


def test_a_name_one_node_retired_stays_another_node_s_parameter(tmp_path: Path) -> None:
    """max_jump became a constant of the merger only, track_timeout of the filter only: the
    tracker and the optimizer keep their own, from the same file."""
    path = tmp_path / "pipeline.yaml"
    path.write_text(
        "pipeline:\n  ros__parameters:\n"
        "    merger: {max_jump: 2.0}\n    filter: {track_timeout: 3.0}\n"
        "    tracker: {max_jump: 2.0}\n    optimizer: {track_timeout: 2.0}\n"
    )
    with pytest.warns(RemovedParameterWarning) as caught:
        values = load_config_defaults("pipeline", path)
    assert values == {"tracker.max_jump": 2.0, "optimizer.track_timeout": 2.0}
    messages = sorted(str(w.message).split(": parameter ")[1] for w in caught)
    assert [m.split()[0] for m in messages] == ["filter.track_timeout", "merger.max_jump"]
    assert "constant MAX_JUMP" in messages[1]


@pytest.mark.parametrize(
    ("node", "values", "constant"),
    [
        ("optimizer", {"prior_weight": 0.05, "confidence_floor": 0.2}, "PRIOR_WEIGHT"),
        ("filter", {"butterworth_order": 4, "sample_frequency": 30.0}, "BUTTERWORTH_ORDER"),
        ("merger", {"depth_gain": 0.0, "oblique_gain": 0.0, "outlier_scale": 1.0}, "DEPTH_GAIN"),
        ("merger", {"flipped_weight": 1.0, "occlusion_radius": 0.0}, "OCCLUSION_RADIUS"),
        ("calib", {"min_overlap": 5.0}, "MIN_OVERLAP"),
    ],
)
def test_a_node_file_setting_its_retired_weights_loads_with_a_warning_each(
    tmp_path: Path, node: str, values: dict[str, float], constant: str
) -> None:
    """Each node's own file (not only the pipeline's) still loads with what it retired, and
    keeps a setting that stays (the merger's and calib's window)."""
    path = tmp_path / f"{node}.yaml"
    settings = "".join(f"    {name}: {value}\n" for name, value in values.items())
    kept = {"optimizer": "track_timeout", "filter": "cutoff_frequency"}.get(node, "window")
    path.write_text(f"{node}:\n  ros__parameters:\n{settings}    {kept}: 2.0\n")
    with pytest.warns(RemovedParameterWarning) as caught:
        loaded = load_config_defaults(node, path)
    assert loaded == {kept: 2.0}
    messages = [str(w.message) for w in caught]
    assert len(messages) == len(values)
    assert any(f"constant {constant}" in m for m in messages)
