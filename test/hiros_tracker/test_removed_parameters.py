"""The tracker's retired parameters: an old file setting them still loads, with a warning."""

from __future__ import annotations

from pathlib import Path

import pytest

from hiros_core.parameters import RemovedParameterWarning, load_config_defaults
from hiros_tracker import TrackerParams

RETIRED = ("velocity_weight", "orientation_weight", "flip_episode", "flip_misread")


def test_an_old_tracker_file_loads_without_the_retired_costs_and_flip_episodes(
    tmp_path: Path,
) -> None:
    path = tmp_path / "tracker.yaml"
    path.write_text(
        "tracker:\n  ros__parameters:\n    gate_distance: 0.6\n"
        + "".join(f"    {name}: 0.0\n" for name in RETIRED)
    )
    with pytest.warns(RemovedParameterWarning) as caught:
        values = load_config_defaults("tracker", path)
    assert values == {"gate_distance": 0.6}
    ignored = sorted(str(w.message).split(": parameter ")[1].split()[0] for w in caught)
    assert ignored == sorted(RETIRED)
    assert not set(RETIRED) & set(vars(TrackerParams()))
