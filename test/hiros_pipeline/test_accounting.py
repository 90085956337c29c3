"""Every camera frame is accounted for by the stages themselves, at every step.

``processed + frames dropped + held`` must equal the frames given, whatever they hold: NaN
detections, a repeated frame, one sent too late, two swapped ones, an uncalibrated camera, an
empty one; what the stages leave out of processed frames is counted apart.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from hiros_core.calibration import load_calibration
from hiros_core.codec import MarkerArrayData
from hiros_core.driver import DELETE, DELETEALL, DriverBridge, group_to_driver_markers
from hiros_core.recording import iter_groups
from hiros_pipeline import Pipeline


@pytest.fixture(scope="module")
def scene(simulated_scene: Callable[..., Path]) -> Path:
    return simulated_scene(
        "accounting", n_cameras=2, n_people=2, duration=4.0, seed=8,
        enter_leave=False,
    )  # fmt: skip


def _bad_stream(groups: list) -> list:
    """The scene's frames with bad ones put in (see the module docstring)."""
    nan = groups[10].copy()
    for skeleton in nan.skeletons:
        skeleton.positions[:] = np.nan
    stranger = groups[11].copy()
    stranger.frame_id = "k99_depth_camera_link"
    empty = groups[12].copy()
    empty.skeletons = []
    late = groups[0].copy()
    late.stamp_ns += 1  # not a repeat of frame 0, but older than what was processed
    stream = [*groups[:10], nan, stranger, empty, groups[9], *groups[13:40], late]
    stream += [groups[41], groups[40], *groups[42:]]  # two swapped: held, then processed
    return stream


def test_the_pipeline_accounts_for_every_camera_frame_at_every_step(scene: Path) -> None:
    pipeline = Pipeline(calibration=load_calibration(scene / "calibration.yaml"))
    stream = _bad_stream([g for _, g in iter_groups(scene / "recording.mcap")])
    held_at_some_point = False
    for given, group in enumerate(stream, start=1):
        pipeline.update(group)
        assert pipeline.accounted == pipeline.tracker.accounted == given
        held_at_some_point |= pipeline.held > 0
    pipeline.flush()
    assert held_at_some_point
    assert pipeline.held == 0
    assert pipeline.processed + pipeline.drops.frame_total == len(stream)
    assert pipeline.drops.of_frames() == {
        "tracker: duplicate frame": 1,
        "tracker: late frame": 1,
        "tracker: uncalibrated camera": 1,
    }
    left_out = pipeline.drops.of_detections()
    assert left_out["tracker: no finite joint"] == len(stream[10].skeletons)
    assert not set(left_out) & set(pipeline.drops.frame_reasons)


def _markers(count: int, stamp: int, actions: int | None = None) -> MarkerArrayData:
    data = MarkerArrayData.new(count, frame_id="k01_depth_camera_link", stamp_ns=stamp)
    data.ids[:] = np.arange(100, 100 + count)
    data.poses[:, :3] = [0.1, 0.2, 2.0]
    if actions is not None:
        data.actions[:] = actions
    return data


def test_the_bridge_accounts_for_every_message(scene: Path) -> None:
    group = next(g for _, g in iter_groups(scene / "recording.mcap"))
    good = group_to_driver_markers(group)
    stamp = group.stamp_ns
    nan = _markers(3, stamp + 2)
    nan.poses[1, 0] = np.nan
    messages = [
        good,
        good,  # repeated stamp
        MarkerArrayData.new(0),  # empty
        nan,  # one joint left out, the message kept
        _markers(2, stamp + 3, DELETE),  # nothing to add
        _markers(1, stamp + 1, DELETEALL),  # a clearing message older than the last
        _markers(1, stamp + 4, DELETEALL),  # "nobody in view": processed
    ]
    bridge = DriverBridge()
    for given, message in enumerate(messages, start=1):
        bridge.update(message)
        assert bridge.accounted == given
    assert bridge.processed == 3
    assert bridge.drops.of_frames() == {
        "repeated_stamp": 1,
        "empty_array": 1,
        "nothing_to_add": 1,
        "stale_deleteall": 1,
    }
    assert bridge.drops.of_detections() == {
        "nan_position": 1,
        "delete_marker": 2,
        "deleteall_marker": 2,
    }
