"""The tracker's kernels held equal to their numpy statement (``tracker_reference.py``).

Hypothesis draws the seeds of random tracks and frames on the Azure Kinect layout: people
facing every way (feet and nose pointing forward), detections with noise, NaN joints, sides
swapped part by part or whole, bodies reflected front to back; track tables warmed up by the
kernels themselves (so that their sums, rings and epochs are consistent) and then given random
facing log-odds, doubts, held axes and velocities; one camera or several; empty frames. A
kernel that changes the tracks in place runs on one copy of the state and its reference on
another, and every field is compared.
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path
from typing import NamedTuple

import numpy as np
import tracker_reference as ref
import tracker_reference_association as association_ref
from hypothesis import given, settings
from hypothesis import strategies as st
from numba.core.dispatcher import Dispatcher
from scipy.spatial.transform import Rotation

import hiros_tracker
from hiros_core.layouts import AZURE_KINECT
from hiros_tracker import kernels
from hiros_tracker.correction import _left_product
from hiros_tracker.facing import _facing_evidence
from hiros_tracker.kernel_args import (
    FacingPriors,
    FacingView,
    FrameRows,
    GateFrame,
    GateSettings,
    GateTracks,
    HeldSides,
    Hits,
    HitSettings,
    MatchSettings,
    SideLayout,
    StackedRows,
    TrackFields,
    TrackPoses,
    UpdateSettings,
)
from hiros_tracker.layout_info import _body_frame, _LayoutInfo, _side_arrays
from hiros_tracker.rigid import move_boxes, move_rows
from hiros_tracker.track_update import REBASE_NS
from hiros_tracker.tracker import _joint_weights, _mirror_parts
from hiros_tracker.tracks import TrackTable

LAYOUT = AZURE_KINECT
PARTS = _mirror_parts(LAYOUT)
WEIGHTS = _joint_weights(LAYOUT, 0.8)
HIT_LAYOUT = _LayoutInfo(
    LAYOUT, PARTS, WEIGHTS, _body_frame(LAYOUT), _side_arrays(LAYOUT, PARTS)
).hit_layout
BODY = HIT_LAYOUT.body
N_JOINTS = LAYOUT.n_joints
SEEDS = st.integers(0, 2**32 - 1)
STAMP = 40_000_000_000
"""The frame under test's stamp (ns); warm-up frames come before it."""
WINDOW_NS = 250_000_000
EXAMPLES = settings(max_examples=30, deadline=None, derandomize=True)


def _index(*names: str) -> np.ndarray:
    return np.array([LAYOUT.joint_names.index(name) for name in names])


FEET, HEAD = _index("FootLeft", "FootRight"), _index("Nose")
ANKLES, NECK = _index("AnkleLeft", "AnkleRight"), _index("Head")


def _person(rng: np.random.Generator) -> np.ndarray:
    """A random upright pose ``(J, 3)``, z up, facing a random way, feet and nose forward."""
    pose = np.zeros((N_JOINTS, 3))
    for joint, parent in enumerate(LAYOUT.parents):
        if parent >= 0:
            step = rng.normal(0.0, 0.08, 3)
            name = LAYOUT.joint_names[joint]
            step[1] = 0.15 if "Left" in name else -0.15 if "Right" in name else step[1]
            step[2] = -0.2 if name.startswith(("Hip", "Knee", "Ankle")) else 0.15
            pose[joint] = pose[parent] + step
    pose[FEET] = pose[ANKLES] + [0.15, 0.0, -0.05]
    pose[HEAD] = pose[NECK] + [0.1, 0.0, 0.0]
    yaw = Rotation.from_euler("z", rng.uniform(-np.pi, np.pi))
    return yaw.apply(pose) + np.array([*rng.uniform(-3.0, 3.0, 2), 1.0])


def _seen(rng: np.random.Generator, pose: np.ndarray, missing: float = 0.1) -> np.ndarray:
    """A detection of ``pose``: noisy, with NaN joints, sometimes turned, mislabelled, reflected."""
    seen = pose + rng.normal(0.0, rng.choice([0.02, 0.1]), pose.shape)
    if rng.random() < 0.3:  # the person turned since
        seen = Rotation.from_euler("z", rng.uniform(-2.0, 2.0)).apply(seen - seen[0]) + seen[0]
    draw = rng.random()
    if draw < 0.15:  # the sides swapped
        seen = seen[PARTS.mirror]
    elif draw < 0.3:  # one part swapped
        k = rng.integers(PARTS.count)
        order = np.where(PARTS.part == k, PARTS.mirror, np.arange(N_JOINTS))
        seen = seen[order]
    elif draw < 0.4:  # front/back: reflected through a vertical plane
        seen[:, 0] = 2 * seen[0, 0] - seen[:, 0]
    seen[rng.random(N_JOINTS) < missing] = np.nan
    return seen


class Scene(NamedTuple):
    """A warmed-up track table and the people its tracks follow."""

    table: TrackTable
    people: np.ndarray  # (T, J, 3)
    n_cameras: int


def _scene(rng: np.random.Generator, n_tracks: int, n_cameras: int) -> Scene:
    """Tracks hit by a few frames of the kernels, then given random facing state."""
    table = TrackTable(N_JOINTS, n_cameras, capacity=max(n_tracks, 1) + 1)
    people = np.array([_person(rng) for _ in range(n_tracks)]).reshape(n_tracks, N_JOINTS, 3)
    walk = rng.normal(0.0, 1.0, (n_tracks, 1, 3)) * [1, 1, 0]
    start = STAMP - int(rng.integers(300, 1500)) * 1_000_000
    for t, person in enumerate(people):
        table.add(t + 10, person, start)
    update = UpdateSettings(0.25, 0.5, WINDOW_NS, WEIGHTS)
    stamp = start
    for _ in range(int(rng.integers(0, 12))):
        stamp += int(rng.integers(5, 40)) * 1_000_000
        rows = np.flatnonzero(rng.random(n_tracks) < 0.7)
        moved = people[rows] + walk[rows] * (stamp - start) * 1e-9
        canonical = np.array([_seen(rng, pose) for pose in moved]).reshape(-1, N_JOINTS, 3)
        camera = int(rng.integers(n_cameras))
        hits = Hits(rows, canonical, rng.integers(0, 5, len(rows)), camera, stamp)
        if kernels.fold_hits(table.hit_fields(), hits, update):
            table.grow_records()
    n = table.n
    table.facing[:n] = rng.normal(0.0, 3.0, n)
    table.facing_ns[:n] = STAMP - rng.integers(0, 2_000_000_000, n)
    table.doubt[:n] = rng.choice([0.0, 5.0, 39.5, 45.0], n)
    table.confirmed[:n] = rng.random(n) < 0.7
    table.velocity[:n] = rng.normal(0.0, 0.8, (n, 3)) * rng.choice([0.1, 1.0], (n, 1))
    for r in range(n):
        axis = ref.sides_axis(people[r], BODY.left, BODY.right)
        if rng.random() < 0.8:  # else none held yet
            table.sides[r] = rng.choice([1.0, -1.0, 0.3]) * axis + rng.normal(0.0, 0.05, 3)
        for c in range(n_cameras):
            table.camera_sides[r, c] = rng.choice([0.0, 1.0, -1.0]) * axis
            table.camera_sides_ns[r, c] = STAMP - rng.integers(0, 400_000_000)
            table.camera_verdicts[r, c] = rng.choice([-2.2, -1.1, -0.25, 0.0, 0.25, 2.2])
            table.camera_verdicts_ns[r, c] = STAMP - rng.integers(0, 800_000_000)
    table.positions[:n][rng.random((n, N_JOINTS)) < 0.05] = np.nan  # joints never measured
    return Scene(table, people, n_cameras)


def _frame(
    rng: np.random.Generator, scene: Scene, n_extra: int, missing: float = 0.15
) -> np.ndarray:
    """``(D, J, 3)`` detections of the scene's people (shuffled) and of ``n_extra`` others."""
    poses = [_seen(rng, person, missing) for person in scene.people]
    poses += [_seen(rng, _person(rng)) for _ in range(n_extra)]
    return np.array(poses).reshape(-1, N_JOINTS, 3)[rng.permutation(len(poses))]


def _pairs(rng: np.random.Generator, n_tracks: int, n_det: int) -> tuple[np.ndarray, ...]:
    """Distinct track rows, distinct detections and random flips of each pair."""
    most = min(n_tracks, n_det)
    count = int(rng.integers(0, most + 1)) if rng.random() < 0.3 else most
    rows = rng.permutation(n_tracks)[:count].astype(np.int64)
    dets = rng.permutation(n_det)[:count].astype(np.int64)
    return rows, dets, rng.random((count, PARTS.count)) < 0.2


def _view(rng: np.random.Generator, scene: Scene, up_known: bool, has_camera: bool) -> FacingView:
    up = np.array([*rng.normal(0.0, 0.05, 2), 1.0, 1.0]) if up_known else np.zeros(4)
    if up_known:
        up[:3] /= np.linalg.norm(up[:3])
    position = rng.uniform(-4.0, 4.0, 3) if has_camera else np.zeros(3)
    return FacingView(up, position, has_camera, int(rng.integers(scene.n_cameras)), STAMP)


def _priors(rng: np.random.Generator) -> FacingPriors:
    return FacingPriors(
        flip_prior=float(rng.choice([0.1, 0.3])),
        flip_prior_back=0.7,
        walking_speed=0.4,
        walking_evidence=0.0 if rng.random() < 0.2 else 1.0,
        facing_memory=3.0,
        facing_memory_standing=float(rng.choice([3.0, 30.0])),
        facing_threshold=float(rng.choice([1.0, 3.0])),
    )


def _held(tracks: TrackFields, rows: np.ndarray, view: FacingView, sided: bool) -> HeldSides:
    left, right = (BODY.left, BODY.right) if sided else (np.empty(0, np.int64),) * 2
    return HeldSides(
        tracks=tracks.positions,
        axes=tracks.sides,
        velocity=tracks.velocity,
        track_rows=rows,
        left=left,
        right=right,
        camera_axes=tracks.camera_sides,
        camera_ns=tracks.camera_sides_ns,
        camera=view.camera,
        stamp_ns=view.stamp_ns,
        facing=tracks.facing,
    )


def _assert_same(got: tuple | np.ndarray, want: tuple | np.ndarray) -> None:
    """Equal arrays (floats to rounding), field by field for named tuples."""
    if isinstance(got, tuple):
        names = getattr(got, "_fields", range(len(got)))
        for name, a, b in zip(names, got, want, strict=True):
            try:
                _assert_same(a, b)
            except AssertionError as error:
                raise AssertionError(f"{name}: {error}") from None
        return
    got, want = np.asarray(got), np.asarray(want)
    assert got.shape == want.shape
    if got.dtype.kind == "f":
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9)
    else:
        np.testing.assert_array_equal(got, want)


# ------------------------------------------------------------------------------ association
@EXAMPLES
@given(seed=SEEDS, min_confidence=st.sampled_from([0.0, 0.5]))
def test_masked_positions(seed: int, min_confidence: float) -> None:
    rng = np.random.default_rng(seed)
    n_det = int(rng.integers(0, 4))
    markers = rng.normal(0.0, 1.0, (n_det, N_JOINTS, 20))
    markers[..., 0] = rng.choice([0.0, 1 / 3, 2 / 3, 1.0, np.nan], (n_det, N_JOINTS))
    markers[rng.random((n_det, N_JOINTS)) < 0.3, 1 + rng.integers(3)] = np.nan
    markers[rng.random(n_det) < 0.3, :, 2] = np.nan  # a detection with no finite joint
    present = rng.random((n_det, N_JOINTS)) < 0.8
    got = kernels.masked_positions(markers, present, min_confidence)
    _assert_same(got, association_ref.reference_masked_positions(markers, present, min_confidence))


@EXAMPLES
@given(seed=SEEDS, use_parts=st.booleans())
def test_match_costs(seed: int, use_parts: bool) -> None:
    rng = np.random.default_rng(seed)
    people = np.array([_person(rng) for _ in range(rng.integers(0, 4))]).reshape(-1, N_JOINTS, 3)
    tracks = TrackPoses(
        np.array([_seen(rng, person) for person in people]).reshape(people.shape),
        rng.normal(0.0, 1.0, (len(people), 3)),
        rng.integers(0, 400_000_000, len(people)),
    )
    detections = np.array([_seen(rng, p, 0.3) for p in people[rng.permutation(len(people))]])
    detections = detections.reshape(-1, N_JOINTS, 3)
    if len(people):  # a track seen mirrored: its parts must come out flipped
        detections[0] = tracks.positions[0][PARTS.mirror] + rng.normal(0.0, 0.01, (N_JOINTS, 3))
    match = MatchSettings(0.2, use_parts, int(rng.integers(1, 20)), float(rng.random() * 0.1))
    stamp = 300_000_000
    got = kernels.match_costs(tracks, detections, stamp, WEIGHTS, PARTS.arrays, match)
    want = association_ref.reference_match_costs(
        tracks, detections, stamp, WEIGHTS, PARTS.arrays, match
    )
    _assert_same(got, want)


def _gate_input(rng: np.random.Generator) -> tuple[np.ndarray, GateTracks, GateFrame]:
    n_tracks, n_det, n_cameras = rng.integers(0, 6), rng.integers(0, 6), int(rng.integers(1, 4))
    cost = rng.random((n_tracks, n_det)) * 2.0
    cost[rng.random(cost.shape) < 0.2] = np.inf
    cost[rng.random(cost.shape) < 0.1] = np.nan
    tracks = GateTracks(
        rng.integers(0, 2_000_000_000, n_tracks + 2),  # the table's rows past n are not read
        rng.random(n_tracks + 2) < 0.6,
        rng.integers(-1, 4, (n_tracks + 2, n_cameras)),
        rng.random((n_tracks + 2, n_cameras)) < 0.7,
    )
    frame = GateFrame(
        rng.integers(-1, 4, n_det), int(rng.integers(n_cameras)), 2 * 10**9, 15 * 10**8
    )
    return cost, tracks, frame


@EXAMPLES
@given(seed=SEEDS, bonus=st.sampled_from([0.0, 0.3]))
def test_gate_costs(seed: int, bonus: float) -> None:
    rng = np.random.default_rng(seed)
    cost, tracks, frame = _gate_input(rng)
    gate = GateSettings(bonus, 0.8, 2.0)
    want = association_ref.reference_gate_costs(cost, tracks, frame, gate)
    feasible, levels = kernels.gate_costs(cost, tracks, frame, gate)  # finishes cost in place
    _assert_same((cost, feasible, levels), want)


@EXAMPLES
@given(seed=SEEDS)
def test_frame_costs(seed: int) -> None:
    """``match_costs`` then ``gate_costs`` at the frame's stamp."""
    rng = np.random.default_rng(seed)
    _, gate_tracks, frame = _gate_input(rng)
    n_tracks, n_det = len(gate_tracks.confirmed) - 2, len(frame.det_ids)
    tracks = TrackPoses(
        np.array([_person(rng) for _ in range(n_tracks)]).reshape(-1, N_JOINTS, 3),
        rng.normal(0.0, 1.0, (n_tracks, 3)),
        rng.integers(1_500_000_000, 2_000_000_000, n_tracks),
    )
    detections = np.array([_person(rng) for _ in range(n_det)]).reshape(-1, N_JOINTS, 3)
    match, gate = MatchSettings(0.2, True, 5, 0.05), GateSettings(0.3, 3.0, 2.0)
    got = kernels.frame_costs(
        tracks, detections, WEIGHTS, PARTS.arrays, match, gate_tracks, frame, gate
    )
    want = association_ref.reference_frame_costs(
        tracks, detections, WEIGHTS, PARTS.arrays, match, gate_tracks, frame, gate
    )
    _assert_same(got, want)


@EXAMPLES
@given(seed=SEEDS)
def test_frame_pairs(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_tracks, n_det = int(rng.integers(0, 5)), int(rng.integers(0, 5))
    count = min(n_tracks, n_det)
    r = rng.permutation(n_tracks)[:count].astype(np.int64)
    c = rng.permutation(n_det)[:count].astype(np.int64)
    feasible = rng.random((n_tracks, n_det)) < 0.6
    flips = rng.random((n_tracks, n_det, PARTS.count)) < 0.3
    kept = rng.integers(0, N_JOINTS, n_det)
    got = kernels.frame_pairs(r, c, feasible, flips, kept, 10)
    _assert_same(got, association_ref.reference_frame_pairs(r, c, feasible, flips, kept, 10))


@EXAMPLES
@given(seed=SEEDS)
def test_live_tracks(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 6))
    last_hit_ns = rng.integers(0, 3_000_000_000, n + 2)
    confirmed = rng.random(n + 2) < 0.5
    got = kernels.live_tracks(last_hit_ns, confirmed, n, 3_000_000_000, 1.0, 0.3)
    _assert_same(got, ref.reference_live_tracks(last_hit_ns, confirmed, n, 3_000_000_000, 1.0, 0.3))


# --------------------------------------------------------------------------------- labels
SIDES = SideLayout(*_side_arrays(LAYOUT, PARTS))
NO_SHOULDERS = SIDES._replace(shoulders=np.empty(0, np.int64))
NO_PAIRS = SIDES._replace(
    pairs=np.empty((0, 2), np.int64),
    pair_parts=np.empty(0, np.int64),
    below=np.empty((0, 2), np.int64),
    below_parts=np.empty(0, np.int64),
)


def _check_canonical_poses(
    seed: int, align: bool, sides: SideLayout, sided: bool, off_table: bool
) -> None:
    """``canonical_poses`` on a random frame; ``off_table``: a camera code past the fields."""
    rng = np.random.default_rng(seed)
    scene = _scene(rng, int(rng.integers(1, 4)), int(rng.integers(1, 3)))
    positions = _frame(rng, scene, int(rng.integers(0, 2)), missing=0.03)
    rows, dets, flips = _pairs(rng, scene.table.n, len(positions))
    view = _view(rng, scene, True, False)
    if off_table:
        view = view._replace(camera=scene.n_cameras)
    held = _held(scene.table.hit_fields(), rows, view, sided)
    args = (positions, dets, flips, PARTS.arrays, align, sides, held)
    _assert_same(kernels.canonical_poses(*args), ref.reference_canonical_poses(*args))


@settings(max_examples=120, deadline=None, derandomize=True)
@given(seed=SEEDS, off_table=st.booleans())
def test_canonical_poses(seed: int, off_table: bool) -> None:
    """Aligned against the tracks' held axes, their poses' or their cameras' last."""
    _check_canonical_poses(seed, True, SIDES, True, off_table)


@EXAMPLES
@given(
    seed=SEEDS,
    align=st.booleans(),
    sides=st.sampled_from([SIDES, NO_SHOULDERS, NO_PAIRS]),
    sided=st.booleans(),
)
def test_canonical_poses_part_by_part(
    seed: int, align: bool, sides: SideLayout, sided: bool
) -> None:
    """Without aligning, or on layouts without shoulders, side pairs or body sides."""
    _check_canonical_poses(seed, align, sides, sided, False)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(seed=SEEDS, up_known=st.booleans(), off_table=st.booleans())
def test_hold_axes(seed: int, up_known: bool, off_table: bool) -> None:
    """Also for a camera code past the per-camera fields (its last axis neither read nor kept)."""
    rng = np.random.default_rng(seed)
    scene = _scene(rng, int(rng.integers(1, 4)), int(rng.integers(1, 3)))
    positions = _frame(rng, scene, 0, missing=0.03)
    rows, dets, _ = _pairs(rng, scene.table.n, len(positions))
    view = _view(rng, scene, up_known, False)
    if off_table:
        view = view._replace(camera=scene.n_cameras)
    fields = scene.table.hit_fields()
    mine = ref.copy_fields(fields)
    canonical = positions[dets]
    kernels.hold_axes(_held(fields, rows, view, True), canonical, fields.last_hit_ns, view)
    ref.reference_hold_axes(_held(mine, rows, view, True), canonical, mine.last_hit_ns, view)
    _assert_same(fields, mine)


@EXAMPLES
@given(seed=SEEDS)
def test_relabel(seed: int) -> None:
    rng = np.random.default_rng(seed)
    scene = _scene(rng, int(rng.integers(1, 4)), 2)
    fields = scene.table.hit_fields()
    mine = ref.copy_fields(fields)
    row = int(rng.integers(scene.table.n))
    permutation = rng.permutation(N_JOINTS)
    kernels.relabel(fields, row, permutation)
    ref.reference_relabel(mine, row, permutation)
    _assert_same(fields, mine)


def _stacked(rng: np.random.Generator, n: int) -> StackedRows:
    markers = rng.normal(0.0, 1.0, (n, N_JOINTS, 20))
    markers[rng.random((n, N_JOINTS)) < 0.3, 8 + rng.integers(3)] = np.nan
    links = rng.normal(0.0, 1.0, (n, N_JOINTS, 20))
    present, link_present = rng.random((2, n, N_JOINTS)) < 0.8
    return StackedRows(markers, present, links, link_present)


def _copy(stacked: StackedRows) -> StackedRows:
    return StackedRows(*(field.copy() for field in stacked))


@EXAMPLES
@given(seed=SEEDS)
def test_label_rows(seed: int) -> None:
    rng = np.random.default_rng(seed)
    stacked = _stacked(rng, 1)
    mine = _copy(stacked)
    flips = rng.random(PARTS.count) < 0.5
    velocities = rng.normal(0.0, 1.0, (N_JOINTS, 3))
    kernels.label_rows(*(field[0] for field in stacked), flips, PARTS.arrays, velocities)
    ref.reference_label_rows(*(field[0] for field in mine), flips, PARTS.arrays, velocities)
    _assert_same(stacked, mine)


@EXAMPLES
@given(seed=SEEDS)
def test_label_frame(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 4))
    stacked = _stacked(rng, n)
    mine = _copy(stacked)
    index, rows = rng.permutation(n).astype(np.int64), rng.permutation(n).astype(np.int64)
    flips = rng.random((n, PARTS.count)) < 0.5
    velocities = rng.normal(0.0, 1.0, (n, N_JOINTS, 3))
    confirmed = rng.random(n) < 0.6
    kernels.label_frame(stacked, index, flips, PARTS.arrays, velocities, rows, confirmed)
    ref.reference_label_frame(mine, index, flips, PARTS.arrays, velocities, rows, confirmed)
    _assert_same(stacked, mine)


# --------------------------------------------------------------------------------- facing
@settings(max_examples=80, deadline=None, derandomize=True)
@given(seed=SEEDS, up_known=st.booleans(), has_camera=st.booleans())
def test_turn_facing(seed: int, up_known: bool, has_camera: bool) -> None:
    """From an unknown up or a known one, with the camera's position or without."""
    rng = np.random.default_rng(seed)
    scene = _scene(rng, int(rng.integers(0, 4)), int(rng.integers(1, 3)))
    positions = _frame(rng, scene, 0)
    rows, dets, _ = _pairs(rng, scene.table.n, len(positions))
    view = _view(rng, scene, up_known, has_camera)
    my_view = view._replace(up=view.up.copy())
    priors = _priors(rng)
    fields = scene.table.hit_fields()
    mine = ref.copy_fields(fields)
    turned = kernels.turn_facing(fields, rows, positions[dets], view, BODY, priors)
    want = ref.reference_turn_facing(mine, rows, positions[dets], my_view, BODY, priors)
    _assert_same((turned, view.up, fields), (want, my_view.up, mine))


def test_a_detection_without_its_forward_pointers_gives_no_facing_evidence() -> None:
    """No foot or nose seen: the detection cannot look flipped or not, so it adds nothing
    (it used to read as 'not flipped' and add full evidence that the sides were right)."""
    rng = np.random.default_rng(7)
    scene = _scene(rng, 1, 1)
    scene.table.positions[0] = scene.people[0]  # the track's own front is known
    positions = _frame(rng, scene, 0, missing=0.0)
    pointed = np.unique(BODY.pointers)
    blind = positions.copy()
    blind[:, pointed[pointed != BODY.root]] = np.nan
    rows = np.zeros(1, dtype=np.int64)
    up = np.array([0.0, 0.0, 1.0])
    # flip prior 0.1: with 0.3, a camera behind one hypothesis weighs 0.7 against 0.7 (no evidence)
    still = _priors(rng)._replace(walking_evidence=0.0, flip_prior=0.1)
    for has_camera in (False, True):
        view = _view(rng, scene, True, has_camera)
        fields = scene.table.hit_fields()
        seen, _ = _facing_evidence(fields, rows, positions, up, view, BODY, still)
        unseen, _ = _facing_evidence(fields, rows, blind, up, view, BODY, still)
        assert seen[0] != 0.0
        assert unseen[0] == 0.0
        want, _ = ref.facing_evidence(ref.copy_fields(fields), rows, blind, up, view, BODY, still)
        assert want[0] == 0.0


# --------------------------------------------------------------------------- track update
@settings(max_examples=15, deadline=None, derandomize=True)
@given(seed=SEEDS, n_cameras=st.integers(1, 3), rebase=st.booleans())
def test_fold_hits_step_by_step(seed: int, n_cameras: int, rebase: bool) -> None:
    """Frames of a few moving tracks, each fold compared from the kernel's state before it.

    With ``rebase``, the tracks' time origin starts nearly ``REBASE_NS`` back, so that it moves
    with detections in the window; the rings fill and grow.
    """
    rng = np.random.default_rng(seed)
    scene = _scene(rng, int(rng.integers(1, 4)), n_cameras)
    table, n = scene.table, scene.table.n
    if rebase:
        table.epoch_ns[:n] -= REBASE_NS - 200_000_000
    walk = rng.normal(0.0, 1.0, (n, 1, 3))
    offsets = rng.normal(0.0, 0.05, (n_cameras, 1, 3))  # each camera's own calibration error
    update = UpdateSettings(float(rng.choice([0.25, 1.0])), 0.5, WINDOW_NS, WEIGHTS)
    stamp = STAMP
    for _ in range(40):
        stamp += int(rng.integers(2, 25)) * 1_000_000
        camera = int(rng.integers(n_cameras))
        rows = rng.permutation(n)[: rng.integers(0, n + 1)].astype(np.int64)
        moved = scene.people[rows] + walk[rows] * (stamp - STAMP) * 1e-9 + offsets[camera]
        canonical = np.array([_seen(rng, pose) for pose in moved]).reshape(-1, N_JOINTS, 3)
        hits = Hits(rows, canonical, rng.integers(0, 5, len(rows)), camera, stamp)
        fields = table.hit_fields()
        mine = ref.copy_fields(fields)
        full = kernels.fold_hits(fields, hits, update)
        assert full == ref.reference_fold_hits(mine, hits, update)
        _assert_same(fields, mine)
        if full:
            table.grow_records()


@settings(max_examples=15, deadline=None, derandomize=True)
@given(seed=SEEDS)
def test_fold_hits_fits_the_velocities_of_the_window(seed: int) -> None:
    """Detections of one moving track from three cameras (offset from each other) folded in.

    The fit is checked against the detections the test keeps itself, not the kernel's ring.
    """
    rng = np.random.default_rng(seed)
    velocity = rng.normal(0.0, 1.0, 3)
    offsets = rng.normal(0.0, 0.05, (3, 1, 3))
    base = _person(rng)
    update = UpdateSettings(0.5, 0.2, WINDOW_NS, WEIGHTS)
    count = int(rng.integers(6, 20))
    stamps = np.cumsum(rng.integers(5_000_000, 30_000_000, count)) + 1_000_000_000
    cameras = rng.integers(0, 3, count)
    poses = base + velocity * ((stamps - stamps[0]) * 1e-9)[:, None, None] + offsets[cameras]
    poses += rng.normal(0.0, 0.01, poses.shape)
    poses[rng.random(poses.shape[:2]) < 0.1] = np.nan
    table = TrackTable(N_JOINTS, 3)
    row = table.add(0, base, int(stamps[0]))
    for stamp, camera, pose in zip(stamps.tolist(), cameras.tolist(), poses, strict=True):
        hits = Hits(np.array([row]), pose[None], np.array([7]), camera, stamp)
        if kernels.fold_hits(table.hit_fields(), hits, update):
            table.grow_records()
    inside = stamps >= stamps[-1] - WINDOW_NS
    slopes, sxx, body = ref.window_velocities(
        stamps[inside], cameras[inside], poses[inside], WEIGHTS
    )
    clear = (sxx > 1e-4) | (sxx < 1e-6)  # clear of the 1e-5 cut either way
    np.testing.assert_allclose(table.velocities[row][clear], slopes[clear], atol=1e-6)
    if clear.all() and (sxx > 1e-4).any():  # the same joints pooled
        np.testing.assert_allclose(table.velocity[row], body, atol=1e-6)


# ------------------------------------------------------------------------------------ hit
@EXAMPLES
@given(
    seed=SEEDS,
    align=st.booleans(),
    weigh=st.booleans(),
    label=st.booleans(),
    has_camera=st.booleans(),
)
def test_hit_frame(seed: int, align: bool, weigh: bool, label: bool, has_camera: bool) -> None:
    """One frame through every step, its output rows labelled when its tracks are confirmed."""
    rng = np.random.default_rng(seed)
    scene = _scene(rng, int(rng.integers(0, 4)), int(rng.integers(1, 3)))
    if rng.random() < 0.5:
        scene.table.confirmed[:] = True
    positions = _frame(rng, scene, int(rng.integers(0, 2)))
    n_det = len(positions)
    pairs = _pairs(rng, scene.table.n, n_det)
    stacked = _stacked(rng, n_det)
    frame = FrameRows(positions, rng.integers(0, 5, n_det), rng.permutation(n_det), stacked)
    my_frame = frame._replace(stacked=_copy(stacked))
    view = _view(rng, scene, rng.random() < 0.8, has_camera)
    my_view = view._replace(up=view.up.copy())
    update = UpdateSettings(0.25, 0.5, WINDOW_NS, WEIGHTS)
    hit = HitSettings(update, align, weigh, label, _priors(rng))
    fields = scene.table.hit_fields()
    mine = ref.copy_fields(fields)
    my_pairs = tuple(part.copy() for part in pairs)
    got = kernels.hit_frame(fields, frame, pairs, view, HIT_LAYOUT, hit)
    want = ref.reference_hit_frame(mine, my_frame, my_pairs, my_view, HIT_LAYOUT, hit)
    _assert_same(
        (*got, fields, frame.stacked, view.up), (*want, mine, my_frame.stacked, my_view.up)
    )


# ---------------------------------------------------------------------------------- rigid
def _transform(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``R``, ``t``, the kernels' ``(4, 4)`` left product of the turn, and the turn itself."""
    turn = Rotation.random(random_state=rng)
    quaternion = turn.as_quat()  # x, y, z, w
    return turn.as_matrix(), rng.normal(0.0, 2.0, 3), _left_product(quaternion), quaternion


def _rows(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Marker/link rows with NaN in some fields and some zero quaternions."""
    rows = rng.normal(0.0, 1.0, shape)
    rows[rng.random(shape[:-1]) < 0.2, 1 + rng.integers(19)] = np.nan
    rows[rng.random(shape[:-1]) < 0.1, 4:8] = 0.0
    return rows


@EXAMPLES
@given(seed=SEEDS)
def test_move_rows_and_boxes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    rotation, translation, product, turn = _transform(rng)
    rows = _rows(rng, (int(rng.integers(0, 6)), 20))
    boxes = _rows(rng, (int(rng.integers(0, 3)), 22))
    want_rows, want_boxes = rows.copy(), boxes.copy()
    move_rows(rows, rotation, translation, product)
    move_boxes(boxes, rotation, translation, product)
    ref.reference_move_rows(want_rows, rotation, translation, turn)
    ref.reference_move_boxes(want_boxes, rotation, translation, turn)
    _assert_same((rows, boxes), (want_rows, want_boxes))


@EXAMPLES
@given(seed=SEEDS)
def test_move_frame_and_moved_frame(seed: int) -> None:
    """``moved_frame`` leaves its input and returns the moved copies; ``move_frame`` moves."""
    rng = np.random.default_rng(seed)
    rotation, translation, product, turn = _transform(rng)
    n_det = int(rng.integers(0, 3))
    markers, links = _rows(rng, (n_det, N_JOINTS, 20)), _rows(rng, (n_det, N_JOINTS, 20))
    present, link_present = rng.random((2, n_det, N_JOINTS)) < 0.8
    boxes = _rows(rng, (n_det, 22))
    frame = (markers, present, links, link_present, boxes)
    before = tuple(field.copy() for field in frame)
    moved = kernels.moved_frame(*frame, rotation, translation, product)
    _assert_same(frame, before)
    want = ref.reference_moved_frame(*frame, rotation, translation, turn)
    _assert_same(moved, want)
    kernels.move_frame(markers, links, boxes, rotation, translation, product)
    _assert_same(frame, want)


def _public_kernels() -> list[str]:
    """The compiled functions every ``hiros_tracker`` module defines, but the private helpers."""
    names = []
    for info in pkgutil.iter_modules(hiros_tracker.__path__):
        name = f"hiros_tracker.{info.name}"
        if "@njit" not in Path(importlib.util.find_spec(name).origin).read_text():
            continue  # (the node imports rclpy)
        module = importlib.import_module(name)
        names += [
            kernel
            for kernel, value in vars(module).items()
            if isinstance(value, Dispatcher) and value.__module__ == name
        ]
    return sorted(kernel for kernel in names if not kernel.startswith("_"))


def test_every_kernel_has_a_reference() -> None:
    """Each public kernel of the package is stated in the reference modules (by its name).

    The private helpers are stated there under names of their own, held through their callers.
    """
    kernels_found = _public_kernels()
    assert {"fold_hits", "hit_frame", "move_rows", "turn_facing"} <= set(kernels_found)
    missing = [
        name
        for name in kernels_found
        if not any(callable(getattr(m, f"reference_{name}", None)) for m in (ref, association_ref))
    ]
    assert not missing
    assert association_ref.INFEASIBLE == kernels.INFEASIBLE
