"""The soak's feed and its like-for-like memory figures (the soak itself is not run here)."""

from dataclasses import dataclass, field

import pytest

from hiros_bench.soak import SAMPLE_SECONDS, SETTLE_SECONDS, feed_passes, memory_growth


@dataclass
class _Group:
    stamp_ns: int
    frame_id: str
    skeletons: list = field(default_factory=list)


def _frames(stamps_ms, delay_ms=60):
    """``(receive ns, camera, group)`` of two cameras at the given stamps, time-ordered."""
    frames = [
        ((t + delay_ms) * 1_000_000, camera, _Group(t * 1_000_000, camera))
        for t in stamps_ms
        for camera in ("a", "b")
    ]
    return sorted(frames, key=lambda f: f[0])


def test_the_feed_played_forward_then_backward_has_no_seam():
    """Each camera's frames keep their spacing across the turns, with no jump back to the
    start: the last frame of a pass opens the next one."""

    frames = _frames(range(0, 1000, 100))
    forward, backward = feed_passes(frames)
    for feed in (forward, backward):
        publish = [p for p, *_ in feed]
        assert publish == sorted(publish)
        assert all(p - s == 60_000_000 for p, s, _, _ in feed)  # the delivery delay is kept
    for camera in ("a", "b"):
        ahead = [g.stamp_ns for _, _, c, g in forward if c == camera]
        back = [g.stamp_ns for _, _, c, g in backward if c == camera]
        assert back == ahead[::-1]  # the same frames, backward
        stamps = [s for _, s, c, _ in forward if c == camera]
        assert stamps == [k * 100_000_000 for k in range(10)]
        stamps = [s for _, s, c, _ in backward if c == camera]
        assert stamps == [k * 100_000_000 for k in range(10)]


def _samples(period_s, memory):
    """Samples every SAMPLE_SECONDS up to 6 periods after settling, ``memory(t)`` per node."""
    end = SETTLE_SECONDS + 6 * period_s
    times = [SAMPLE_SECONDS * k for k in range(1, int(end / SAMPLE_SECONDS) + 1)]
    return [(t, {"calib": memory(t)}, 10) for t in times]


def test_memory_growth_compares_whole_periods_like_for_like():
    """A node whose reading depends on when it falls (mid-estimate or not) grows by nothing
    when its peaks and its lows per period stay put; one whose floor creeps up grows."""

    period = 60.0

    def steady(t):  # a reading mid-estimate or not, whenever it falls; a probe between two
        return (460.0, 470.0, 260.0) if int(t / SAMPLE_SECONDS) % 3 else (260.0, 470.0, 255.0)

    (first, last), peaks, lows = memory_growth(_samples(period, steady), "calib", period)
    assert first == (SETTLE_SECONDS, SETTLE_SECONDS + period)
    assert last == (SETTLE_SECONDS + 5 * period, SETTLE_SECONDS + 6 * period)
    assert peaks == (470.0, 470.0)
    assert lows == (255.0, 255.0)

    def creeping(t):
        return (460.0 + 0.1 * t, 470.0 + 0.1 * t, 260.0 + 0.1 * t)

    _, peaks, lows = memory_growth(_samples(period, creeping), "calib", period)
    assert lows[1] - lows[0] == pytest.approx(0.1 * 5 * period)
    assert peaks[1] - peaks[0] == pytest.approx(0.1 * 5 * period)


def test_memory_growth_needs_two_whole_periods():
    samples = [(t, {"calib": (250.0, 400.0, 240.0)}, 1) for t in range(10, 250, 10)]
    assert memory_growth(samples, "calib", 120.0) is None
