import numpy as np

from hiros_core.layouts import AZURE_KINECT, KINECT_V2
from hiros_core.model import Skeleton
from hiros_merger.latest import LatestDetections

T0 = 1_000_000_000


def _skeleton(track: int, t_ns: int, layout=AZURE_KINECT, value: float = 0.0) -> Skeleton:
    positions = np.full((layout.n_joints, 3), value)
    return Skeleton.from_positions(positions, layout, skeleton_id=track, src_time_ns=t_ns)


def test_newest_detection_per_track_and_camera_is_kept():
    store = LatestDetections()
    assert store.put(1, 0, _skeleton(1, T0, value=1.0))
    assert store.put(1, 0, _skeleton(1, T0 + 10, value=2.0))
    assert not store.put(1, 0, _skeleton(1, T0 + 5, value=3.0))
    slots, layout = store.select(T0 + 10, 100, 1000)
    assert layout is AZURE_KINECT
    assert len(slots) == 1
    assert np.all(store.rows[slots[0], :, 1:4] == 2.0)
    assert store.stamps[slots[0]] == T0 + 10
    assert store.tracks[slots[0]] == 1


def test_selection_keeps_first_sight_order_and_forgets_timed_out_detections():
    store = LatestDetections()
    store.put(5, 2, _skeleton(5, T0))
    store.put(3, 1, _skeleton(3, T0))
    store.put(5, 0, _skeleton(5, T0 + 50))
    store.put(3, 2, _skeleton(3, T0 - 500))  # timed out at T0 + 50
    slots, _ = store.select(T0 + 50, 100, 400)
    pairs = [(int(store.tracks[s]), int(store.cameras[s])) for s in slots]
    assert pairs == [(5, 2), (5, 0), (3, 1)]
    assert store.slots == {5: {2: slots[0], 0: slots[1]}, 3: {1: slots[2]}}
    kept = slots[1]
    later, _ = store.select(T0 + 420, 100, 400)  # T0's detections gone, none in the window
    assert later == []
    assert store.slots == {5: {0: kept}}


def test_a_merge_takes_the_first_detection_s_layout_and_rows_widen():
    store = LatestDetections(capacity=2)
    store.put(1, 0, _skeleton(1, T0, KINECT_V2, value=1.0))
    store.put(2, 0, _skeleton(2, T0, AZURE_KINECT, value=2.0))
    store.put(3, 0, _skeleton(3, T0, KINECT_V2, value=3.0))  # beyond the capacity: grows
    assert store.rows.shape[1] == AZURE_KINECT.n_joints
    slots, layout = store.select(T0, 100, 1000)
    assert layout is KINECT_V2
    assert [int(store.tracks[s]) for s in slots] == [1, 3]
    assert np.all(store.rows[slots[0], : KINECT_V2.n_joints, 1:4] == 1.0)
    assert np.all(store.present[slots[1], : KINECT_V2.n_joints])
