from collections import Counter

import numpy as np
import optimizer_reference
from hypothesis import given, settings
from hypothesis import strategies as st

from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonRows, stack_rows
from hiros_core.stacking import _unusable_rows, output_skeletons, stack_frame

J = AZURE_KINECT.n_joints


def _people(n: int = 3) -> list[Skeleton]:
    positions = np.arange(n * J * 3, dtype=float).reshape(n, J, 3)
    return Skeleton.many_from_positions(
        positions, AZURE_KINECT, skeleton_ids=range(n), src_time_ns=5, src_frame="world"
    )


def test_stack_frame_copies_the_rows_a_stage_writes_and_keeps_the_input_stack():
    people = _people()
    drops: Counter[str] = Counter()
    places = stack_frame(people, drops)
    stack = places[0][0]
    assert [row for _, row in places] == [0, 1, 2]
    assert stack.source.markers is stack_rows(people).markers  # no copy of the input
    stack.markers[:] = 0.0
    stack.present[:] = False
    assert np.isfinite(people[0].positions).all()
    assert people[0].marker_present.all()
    links, link_present = stack.input_links([2, 0])
    assert np.array_equal(link_present, np.array([people[2].link_present, people[0].link_present]))
    links[:] = 0.0
    assert not (people[2].links == 0.0).any()


def test_output_skeletons_are_views_of_the_rows_when_frames_agree_else_built_one_by_one():
    people = _people()
    rows = stack_rows(people)
    copies = SkeletonRows(*(field.copy() for field in rows))
    made = output_skeletons(people, [7, 8, 9], copies)
    assert [s.id for s in made] == [7, 8, 9]
    assert stack_rows(made).markers is copies.markers
    assert all(a.src_time_ns == b.src_time_ns and a.src_frame == b.src_frame
               for a, b in zip(made, people, strict=True))  # fmt: skip
    people[1].src_frame = "elsewhere"
    mixed = output_skeletons(people, [7, 8, 9], copies)
    assert [s.src_frame for s in mixed] == ["world", "elsewhere", "world"]
    assert np.shares_memory(mixed[1].markers, copies.markers)


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), people=st.integers(0, 5))
def test_unusable_rows_equal_the_numpy_statement(seed, people):
    """Non-finite values in and out of the position columns, of present and absent joints."""
    rng = np.random.default_rng(seed)
    markers = rng.normal(size=(people, J, 20))
    markers[rng.random(markers.shape) < 0.02] = rng.choice([np.nan, np.inf, -np.inf])
    present = rng.random((people, J)) < 0.7
    want = optimizer_reference.unusable_rows(markers, present)
    assert np.array_equal(_unusable_rows(markers, present), want)
