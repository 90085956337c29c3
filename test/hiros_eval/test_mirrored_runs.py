"""How long a person's output stays mirrored: flickers told apart from stretches."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_eval.tracking import mirrored_output, mirrored_share
from hiros_sim import SimParams, simulate

RATE = 30.0


def _output(truth, mirrored_between: list[tuple[float, float]]) -> list[SkeletonGroup]:
    """The truth itself at 30 Hz as one track's output, mirrored (left for right) within spans."""
    times = truth.times[0] + np.arange(0.5, truth.times[-1] - truth.times[0] - 0.5, 1 / RATE)
    groups = []
    for when, true_pose in zip(times, truth.at(times)[0], strict=True):
        since = when - truth.times[0]
        mirrored = any(start <= since < stop for start, stop in mirrored_between)
        pose = true_pose[AZURE_KINECT.mirror] if mirrored else true_pose
        stamp = round(when * 1e9)
        skeleton = Skeleton.from_positions(pose, skeleton_id=1, src_time_ns=stamp, src_frame="w")
        groups.append(SkeletonGroup(stamp, "world", [skeleton]))
    return groups


@pytest.fixture(scope="module")
def truth():
    return simulate(SimParams(n_people=1, duration=6.0, seed=2)).truth


def test_the_longest_mirrored_stretch_is_measured_in_seconds(truth) -> None:
    groups = _output(truth, [(1.0, 1.1), (2.0, 3.5)])
    assert mirrored_output(groups, truth).longest_run_s == pytest.approx(1.5, abs=0.04)
    assert mirrored_share(groups, truth) == pytest.approx(1.6 / 5.0, abs=0.02)


def test_a_person_out_of_view_between_mirrored_frames_is_not_a_long_run(truth) -> None:
    # five mirrored frames, the person out of every view (no output) for 2 s among them: the
    # output reported the person the wrong way round for five frames, not for 2 s
    groups = _output(truth, [(1.0, 4.0)])
    seen = [g for g in groups if not 1.0 + 3 / RATE <= g.stamp_ns * 1e-9 - truth.times[0] < 3.9]
    run = mirrored_output(seen, truth).longest_run_s
    assert run == pytest.approx(6 / RATE, abs=0.5 / RATE)


def test_a_single_mirrored_frame_is_one_frame_long_and_none_is_zero(truth) -> None:
    one = _output(truth, [(2.0, 2.0 + 0.5 / RATE)])
    assert mirrored_output(one, truth).longest_run_s == pytest.approx(1 / RATE, rel=0.05)
    assert mirrored_output(_output(truth, []), truth).longest_run_s == 0.0
    assert math.isnan(mirrored_output([], truth).longest_run_s)
