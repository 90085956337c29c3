"""The facing check's flip-episode filter (``facing._episode_evidence``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hiros_tracker.facing import _episode_evidence, _independent_evidence

FRONT, BACK = 0.1, 0.7  # flip priors of a front and a back view


def _run(flags: list[bool], prior_right: float, prior_wrong: float, dt: float = 1 / 30) -> list:
    state = np.zeros(2)
    values = []
    for k, flipped in enumerate(flags):
        elapsed = -1.0 if k == 0 else dt
        values.append(_episode_evidence(state, flipped, prior_right, prior_wrong, 1.5, 0.0,
                                        elapsed))  # fmt: skip
    return values


@pytest.mark.parametrize("flipped", [True, False])
def test_a_first_detection_weighs_like_an_independent_one(flipped: bool) -> None:
    first = _run([flipped], FRONT, BACK)[0]
    assert first == pytest.approx(_independent_evidence(flipped, FRONT, BACK))


def test_a_flip_episode_counts_about_once_not_once_per_frame() -> None:
    episode = _run([True] * 60, FRONT, FRONT)  # 2 s of one camera seeing the front flipped
    single = _independent_evidence(True, FRONT, FRONT)
    assert sum(episode) < 0  # still evidence that the track is reversed ...
    assert sum(episode) > 3 * single  # ... but nowhere near 60 independent votes
    assert 60 * single < 20 * sum(episode)


def test_a_long_unflipped_run_supports_the_track_and_the_filter_relaxes_to_the_prior() -> None:
    assert all(v > 0 for v in _run([False] * 30, FRONT, FRONT))
    state = np.array([0.9, 0.9])
    _episode_evidence(state, False, FRONT, FRONT, 1.5, 0.05, 100.0)  # long gap: the prior
    expected = FRONT * 0.05 / (FRONT * 0.05 + (1 - FRONT) * 0.95)
    assert state[0] == pytest.approx(expected)
    assert math.isfinite(state[1])
