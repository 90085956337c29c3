"""The shipped RViz config and Foxglove layout show what hiros publishes and writes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import yaml

from hiros_core.calibration import Calibration
from hiros_pipeline.offline import DRAWN_STAGES, STAGES

CONFIG = Path(__file__).resolve().parents[2] / "config"
# what `hiros run` writes, and what the live nodes publish beside it
TOPICS = (
    {f"/hiros/{stage}" for stage in STAGES}
    | {f"/hiros/{stage}/markers" for stage in DRAWN_STAGES}
    | {"/hiros/calibration", "/tf", "/tf_static", "/diagnostics"}
)
WORLD = Calibration("k01").world_frame


def test_rviz_config_shows_the_filter_markers_in_the_world_frame() -> None:
    config = yaml.safe_load((CONFIG / "rviz" / "hiros.rviz").read_text())
    manager = config["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == WORLD
    displays = {d["Class"]: d for d in manager["Displays"]}
    assert "rviz_default_plugins/TF" in displays
    markers = [d for d in manager["Displays"] if d["Class"] == "rviz_default_plugins/MarkerArray"]
    assert {d["Topic"]["Value"] for d in markers} <= TOPICS
    shown = [d["Topic"]["Value"] for d in markers if d["Enabled"]]
    assert shown == ["/hiros/filter/markers"]
    assert all(d["Topic"]["Reliability Policy"] == "Reliable" for d in markers)


def test_foxglove_layout_names_only_our_topics() -> None:
    layout = json.loads((CONFIG / "foxglove" / "hiros_layout.json").read_text())
    panels = layout["configById"]
    placed = set(re.findall(r"[\w]+![\w]+", json.dumps(layout["layout"])))
    assert placed == set(panels)
    three_d = panels["3D!hiros"]
    assert three_d["followTf"] == WORLD
    assert three_d["topics"]["/hiros/filter/markers"]["visible"]
    paths = [p["value"] for p in panels["Plot!hirosjoints"]["paths"]]
    paths.append(panels["RawMessages!hiroscalib"]["topicPath"])
    named = set(three_d["topics"]) | {re.match(r"(/[\w/]+)", p).group(1) for p in paths}
    assert named <= TOPICS
