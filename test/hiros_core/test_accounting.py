"""Drops and Merged: the frame / detection kinds survive counting, merging and pickling."""

from __future__ import annotations

import pickle
from collections import Counter

from hiros_core.accounting import Accounted, Drops, Merged


def _drops() -> Drops:
    drops = Drops()
    drops.frame("late frame")
    drops.frame("late frame", 2)
    drops.detections("no joint", 4)
    drops["helper reason"] += 1  # a helper handed the counter: a detection reason
    return drops


def test_kinds_are_kept_apart_and_the_counter_reads_as_before() -> None:
    drops = _drops()
    assert drops == {"late frame": 3, "no joint": 4, "helper reason": 1}
    assert drops.frame_total == 3
    assert drops.of_frames() == Counter({"late frame": 3})
    assert drops.of_detections() == Counter({"no joint": 4, "helper reason": 1})
    assert drops.is_frame("late frame")
    assert not drops.is_frame("no joint")


def test_copies_pickles_and_merges_keep_the_kinds() -> None:
    drops = _drops()
    for copy in (drops.copy(), pickle.loads(pickle.dumps(drops))):
        assert copy == drops
        assert copy.frame_reasons == {"late frame"}
        assert copy.frame_total == 3
    merged = Drops()
    merged.add(drops, "tracker: ")
    merged.add(Counter({"truncated": 2, "zero": 0}), "reader: ", frames=True)
    assert merged.of_frames() == Counter({"tracker: late frame": 3, "reader: truncated": 2})
    assert merged.of_detections() == Counter({"tracker: no joint": 4, "tracker: helper reason": 1})
    assert merged.frame_total == 5
    assert "reader: zero" not in merged


class _Stage(Accounted):
    def __init__(self, processed: int, held: int, drops: Drops) -> None:
        self.processed, self.held, self.drops = processed, held, drops


def test_merged_counts_the_frames_of_the_counting_stages_and_every_drop() -> None:
    first = _Stage(7, 0, _drops())  # a bridge: its 7 processed frames went on to ``last``
    last = _Stage(5, 1, Drops({"duplicate frame": 1}, ["duplicate frame"]))
    merged = Merged([("bridge: ", first), ("", last)], [last])
    assert (merged.processed, merged.held) == (5, 1)
    assert merged.drops.frame_total == 4
    assert merged.accounted == 5 + 1 + 4 == first.accounted + last.accounted - first.processed
