import numpy as np
import optimizer_reference
import pytest

from hiros_core.accounting import Merged
from hiros_core.errors import ConfigError
from hiros_core.kinematics import link_lengths
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_optimizer import (
    Optimizer,
    OptimizerParams,
    PersonCalibration,
    read_person_calibrations,
    write_person_calibrations,
)
from hiros_optimizer import optimizer as optimizer_module
from hiros_optimizer.learning import LIMB_JOINTS

PARENTS = np.asarray(AZURE_KINECT.parents)
FRAMES = 30


@pytest.fixture
def noisy_people(moving_person):
    """Two people, 90 frames: (truths, noisy measurements, lengths)."""
    rng = np.random.default_rng(7)
    truths, measured, lengths = [], [], []
    for seed in (1, 2):
        positions, length = moving_person(90, seed=seed)
        truths.append(positions)
        measured.append(positions + rng.normal(scale=0.01, size=positions.shape))
        lengths.append(length)
    return truths, measured, lengths


@pytest.fixture
def run(group_at):
    """``run(optimizer, people, frames, ids=None, start=0)``: feed frames, return the outputs."""

    def feed(optimizer, people, frames, ids=None, start=0):
        return [
            optimizer.update(group_at(frame, list(people), ids=ids))
            for frame in range(start, start + frames)
        ]

    return feed


def small_optimizer(**kwargs):
    return Optimizer(OptimizerParams(number_of_frames_for_calibration=FRAMES, **kwargs))


def test_learns_lengths_then_holds_them_exactly(noisy_people, run):
    truths, measured, lengths = noisy_people
    optimizer = small_optimizer()
    outputs = run(optimizer, measured, 90)
    assert sorted(optimizer.calibrations) == [0, 1]
    for person in (0, 1):
        calibration = optimizer.calibrations[person]
        constrained = np.isfinite(calibration.lengths)
        assert constrained.sum() >= 0.8 * 31
        # learnt lengths are close to the true ones (1 cm noise per joint)
        assert np.nanmedian(np.abs(calibration.lengths - lengths[person])) < 0.004
        after = np.stack([o.skeletons[person].positions for o in outputs[FRAMES:]])
        held = link_lengths(after, PARENTS)[:, constrained]
        np.testing.assert_allclose(held, np.tile(calibration.lengths[constrained], (len(after), 1)))
        error_out = np.linalg.norm(after - truths[person][FRAMES:], axis=-1).mean()
        error_in = np.linalg.norm(
            measured[person][FRAMES:] - truths[person][FRAMES:], axis=-1
        ).mean()
        assert error_out < error_in


def test_passes_people_through_until_calibrated(noisy_people, run):
    _, measured, _ = noisy_people
    optimizer = small_optimizer()
    first = run(optimizer, measured, FRAMES - 1)
    assert not optimizer.calibrations
    for frame, group in enumerate(first):
        np.testing.assert_array_equal(group.skeletons[0].positions, measured[0][frame])


def test_noisy_start_is_not_accepted(moving_person, run):
    positions, _ = moving_person(FRAMES, seed=3)
    rng = np.random.default_rng(0)
    wild = positions + rng.normal(scale=0.2, size=positions.shape)
    optimizer = small_optimizer(max_calibration_coefficient_of_variation=0.05)
    run(optimizer, [wild], FRAMES)
    assert not optimizer.calibrations


def test_outlier_joint_is_down_weighted(noisy_people, group_at, run):
    truths, measured, _ = noisy_people
    optimizer = small_optimizer()
    run(optimizer, measured, 60)
    frame = 60
    corrupted = [m.copy() for m in measured]
    wrist = AZURE_KINECT.index("WristRight")
    corrupted[0][frame, wrist] += (0.6, 0.0, 0.0)
    out = optimizer.update(group_at(frame, corrupted))
    error = np.linalg.norm(out.skeletons[0].positions[wrist] - truths[0][frame, wrist])
    assert error < 0.2


def test_gap_and_reappearance_do_not_explode(noisy_people, group_at, run):
    truths, measured, _ = noisy_people
    optimizer = small_optimizer(track_timeout=0.5)
    run(optimizer, measured, 45)
    # person 0 disappears for 1 s, then comes back far away with joints missing
    later = [m.copy() for m in measured]
    later[0][75:] += (2.0, 0.0, 0.0)
    later[0][75:, 5:9] = np.nan
    outputs = [optimizer.update(group_at(f, [later[1]], ids=[1])) for f in range(45, 75)]
    outputs += run(optimizer, later, 15, start=75)
    back = np.stack([o.skeletons[0].positions for o in outputs[30:]])
    present = np.isfinite(later[0][75:])
    assert np.isnan(back[~present]).all()
    shifted = truths[0][75:] + np.array([2.0, 0.0, 0.0])
    assert np.linalg.norm(back - shifted, axis=-1)[present.all(axis=-1)].max() < 0.1


def test_yaml_round_trip(tmp_path, noisy_people, group_at, run):
    _, measured, _ = noisy_people
    optimizer = small_optimizer()
    run(optimizer, measured, FRAMES)
    path = tmp_path / "people.yaml"
    write_person_calibrations(path, optimizer.export_calibrations())
    other = small_optimizer()
    assert other.load_calibrations(read_person_calibrations(path)) == [0, 1]
    for person in (0, 1):
        np.testing.assert_allclose(
            other.calibrations[person].lengths, optimizer.calibrations[person].lengths, atol=1e-6
        )
    # a known person is optimised from the first frame of the next session
    first = other.update(group_at(0, measured))
    constrained = np.isfinite(other.calibrations[0].lengths)
    held = link_lengths(first.skeletons[0].positions, PARENTS)[constrained]
    np.testing.assert_allclose(held, other.calibrations[0].lengths[constrained])


@pytest.mark.parametrize(
    "data",
    [
        {"people": {"x": {"layout": "azure_kinect", "links": {}}}},
        {"people": {0: {"layout": "azure_kinect", "links": {"Nope-Link": 0.3}}}},
        {"people": {0: {"layout": "azure_kinect", "links": {"Pelvis-SpineNaval": -1}}}},
        {"tracks": []},
    ],
)
def test_bad_calibration_data_raises_config_error(data):
    with pytest.raises(ConfigError):
        Optimizer().load_calibrations(data)


def test_unreadable_file_raises_config_error(tmp_path):
    (tmp_path / "bad.yaml").write_text("people: [unclosed")
    with pytest.raises(ConfigError):
        read_person_calibrations(tmp_path / "bad.yaml")
    with pytest.raises(ConfigError):
        read_person_calibrations(tmp_path / "missing.yaml")


def test_change_id_moves_the_calibration(noisy_people, group_at, run):
    _, measured, _ = noisy_people
    optimizer = small_optimizer()
    run(optimizer, measured, FRAMES, ids=[5, 6])
    lengths = optimizer.calibrations[5].lengths.copy()
    assert not optimizer.change_id(42, 0)  # unknown track
    assert not optimizer.change_id(5, 6)  # 6 is another live track
    assert optimizer.change_id(5, 0)
    assert 5 not in optimizer.calibrations
    np.testing.assert_array_equal(optimizer.calibrations[0].lengths, lengths)
    out = optimizer.update(group_at(FRAMES, measured, ids=[5, 6]))
    assert list(out.ids) == [0, 6]
    constrained = np.isfinite(lengths)
    held = link_lengths(out.skeletons[0].positions, PARENTS)[constrained]
    np.testing.assert_allclose(held, lengths[constrained])


def test_change_id_keeps_a_known_persons_calibration(noisy_people, group_at, run):
    _, measured, _ = noisy_people
    known = PersonCalibration(AZURE_KINECT, np.full(32, 0.25), np.full(32, np.nan))
    known.lengths[0] = np.nan
    optimizer = small_optimizer()
    optimizer.load_calibrations({"people": {0: known.to_dict()}})
    run(optimizer, [measured[1]], 3, ids=[9])
    assert optimizer.change_id(9, 0)
    out = optimizer.update(group_at(3, [measured[1]], ids=[9]))
    assert list(out.ids) == [0]
    np.testing.assert_allclose(link_lengths(out.skeletons[0].positions, PARENTS)[1:], 0.25)


def test_calibrate_restarts_learning(noisy_people, run):
    _, measured, _ = noisy_people
    optimizer = small_optimizer()
    run(optimizer, measured, FRAMES)
    assert optimizer.calibrate([0])
    assert 0 not in optimizer.calibrations
    assert 1 in optimizer.calibrations
    assert not optimizer.calibrate([77])
    run(optimizer, measured, FRAMES, start=FRAMES)
    assert 0 in optimizer.calibrations


def test_bad_skeletons_are_counted_not_fatal(noisy_people):
    _, measured, _ = noisy_people
    optimizer = small_optimizer()
    broken = Skeleton.from_positions(measured[0][0], skeleton_id=3)
    broken.positions[2] = np.inf
    anonymous = Skeleton.from_positions(measured[1][0], skeleton_id=-1)
    twin = Skeleton.from_positions(measured[1][0], skeleton_id=4)
    group = SkeletonGroup(0, "world", [broken, anonymous, twin, twin.copy()])
    out = optimizer.update(group)
    assert list(out.ids) == [-1, 4]
    assert sum(optimizer.drops.values()) == 3


def test_params_are_checked():
    with pytest.raises(ConfigError):
        OptimizerParams(number_of_frames_for_calibration=1)
    with pytest.raises(ConfigError):
        OptimizerParams(acceptance_timeout=0.0)


def test_compiled_frames_equal_the_numpy_frames(noisy_people, group_at, monkeypatch):
    """Learning, fitting (with an outlier, a gap past the timeout and a new id) through the
    frame kernels of ``hiros_optimizer.compiled`` and through their numpy statement
    (``optimizer_reference.ReferenceMemory``): the same outputs (the fits agree to rounding)."""
    _, measured, _ = noisy_people
    people = [p.copy() for p in measured]
    people[0][40, 5] += 0.4  # an outlier joint once calibrated
    stages = [small_optimizer(), small_optimizer()]
    outputs = [[], []]
    frames = [*range(45), *range(80, 90)]  # 35 frames missing: over the 1 s track timeout
    for frame in frames:
        ids = [0, 1] if frame < 80 else [0, 2]
        group = group_at(frame, people, ids=ids)
        for stage, out in zip(stages, outputs, strict=True):
            copy = SkeletonGroup(
                group.stamp_ns, group.frame_id, [s.copy() for s in group.skeletons]
            )
            with monkeypatch.context() as patch:
                if stage is stages[0]:  # its memory, made at its first frame, is numpy's
                    patch.setattr(optimizer_module, "Memory", optimizer_reference.ReferenceMemory)
                out.append(stage.update(copy).skeletons)
    assert isinstance(next(iter(stages[0]._memories.values())), optimizer_reference.ReferenceMemory)
    assert sorted(stages[0].calibrations) == sorted(stages[1].calibrations) == [0, 1]
    for reference, compiled in zip(*outputs, strict=True):
        for a, b in zip(reference, compiled, strict=True):
            assert a.id == b.id
            np.testing.assert_array_equal(a.marker_present, b.marker_present)
            np.testing.assert_allclose(b.markers, a.markers, atol=1e-9, equal_nan=True)
            np.testing.assert_allclose(b.links, a.links, atol=1e-9, equal_nan=True)


def _unknown_layout_bytes(n_markers: int, stamp_ns: int) -> bytes:
    """A one-person group whose marker names fit no built-in layout (a decoded layout)."""
    from hiros_skeleton_msgs.msg import Marker
    from hiros_skeleton_msgs.msg import Skeleton as SkeletonMsg
    from hiros_skeleton_msgs.msg import SkeletonGroup as GroupMsg
    from rclpy.serialization import serialize_message

    skeleton = SkeletonMsg(id=1, max_markers=n_markers)
    skeleton.src_time.sec, skeleton.src_time.nanosec = divmod(stamp_ns, 10**9)
    skeleton.markers = [Marker(id=i, name="x") for i in range(n_markers)]
    for i, marker in enumerate(skeleton.markers):
        marker.center.pose.position.z = 3.0 + 0.1 * i
        marker.center.pose.orientation.w = 1.0
    group = GroupMsg(skeletons=[skeleton])
    group.header.stamp.sec, group.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    return serialize_message(group)


def test_a_track_whose_decoded_layout_changes_size_is_learnt_again():
    """A track seen with 3 then 32 unknown markers: two decoded layouts. They used to share
    the name "decoded", hence one track memory, and the compiled learning wrote past its
    arrays (the live optimizer node died of a segfault)."""
    pytest.importorskip("hiros_skeleton_msgs.msg")
    from hiros_core.codec import decode_group

    stage = small_optimizer()
    for frame, n_markers in enumerate([3] * 5 + [32] * 5):
        out = stage.update(decode_group(_unknown_layout_bytes(n_markers, (frame + 1) * 10**8)))
        assert [len(s.markers) for s in out.skeletons] == [n_markers]


SHORT_JOINTS = [
    AZURE_KINECT.index(name)
    for name in (
        "HandLeft", "HandTipLeft", "ThumbLeft", "HandRight", "HandTipRight", "ThumbRight",
        "Nose", "EyeLeft", "EarLeft", "EyeRight", "EarRight",
    )
]  # fmt: skip
LIMBS = [AZURE_KINECT.index(name) for name in LIMB_JOINTS]


def test_noisy_short_links_do_not_keep_a_person_from_acceptance(noisy_people, run):
    """A third of the links far too noisy to be steady (hands, thumbs, face): the old
    all-or-nothing rule (80 % of the links steady) never accepted such a person. The limbs
    lock at the first full window, and with them every link seen often enough."""
    _, measured, true_lengths = noisy_people
    rng = np.random.default_rng(3)
    shaky = measured[0].copy()
    scale = 0.5 * true_lengths[0][SHORT_JOINTS, None]  # (per axis: a CV far above 0.2)
    shaky[:, SHORT_JOINTS] += scale * rng.standard_normal((len(shaky), len(SHORT_JOINTS), 3))
    optimizer = small_optimizer()
    outputs = run(optimizer, [shaky], 90)
    progress = optimizer.people()[0]
    assert (progress.variation[SHORT_JOINTS] > 0.2).all()
    assert (progress.variation > 0.2).sum() > 0.2 * (AZURE_KINECT.n_joints - 1)
    assert progress.acceptance_time == pytest.approx((FRAMES - 1) / 30)
    assert optimizer.report()[0] == "accepted after 1.0 s"
    lengths = optimizer.calibrations[0].lengths
    assert np.isfinite(lengths[1:]).all()
    after = np.stack([o.skeletons[0].positions for o in outputs[FRAMES:]])
    np.testing.assert_allclose(link_lengths(after, PARENTS)[:, 1:], np.tile(lengths[1:], (60, 1)))


def shaken(positions, joints, scale, seed):
    """``positions`` with ``joints`` jittered by ``scale`` m per axis: links far from steady."""
    rng = np.random.default_rng(seed)
    shaky = positions.copy()
    shaky[:, joints] += scale * rng.standard_normal((len(shaky), len(joints), 3))
    return shaky


def test_limbs_unsteady_on_both_sides_stay_free_while_the_other_links_lock(noisy_people, run):
    _, measured, true_lengths = noisy_people
    knees = [AZURE_KINECT.index("KneeLeft"), AZURE_KINECT.index("KneeRight")]
    legs = [*knees, AZURE_KINECT.index("AnkleLeft"), AZURE_KINECT.index("AnkleRight")]
    shaky = shaken(measured[0], knees, 0.5 * true_lengths[0][legs].max(), seed=4)
    optimizer = small_optimizer()
    run(optimizer, [shaky], 45)
    lengths = optimizer.calibrations[0].lengths
    assert np.isnan(lengths[legs]).all()
    assert np.isfinite(np.delete(lengths, [0, *legs])).all()
    assert optimizer.people()[0].accepted_ns is None
    report = optimizer.report()[0]
    assert report.startswith("not accepted after 1.5 s: HipLeft-KneeLeft unsteady (CV ")
    assert "KneeRight-AnkleRight unsteady" in report


def test_an_unsteady_limb_takes_the_other_sides_length_until_its_own_is_learnt(moving_person, run):
    """The left knee jitters for 1.5 s: the left thigh and shank borrow the right ones'
    lengths (the fixture's sides differ, as a real person's may), the person is accepted at
    the first full window, and once the knee is steady the left links take their own."""
    positions, true_lengths = moving_person(180, seed=1)
    knee, ankle = AZURE_KINECT.index("KneeLeft"), AZURE_KINECT.index("AnkleLeft")
    right = [AZURE_KINECT.index("KneeRight"), AZURE_KINECT.index("AnkleRight")]
    shaky = shaken(positions, [knee], 0.5 * true_lengths[[knee, ankle]].max(), seed=4)
    shaky[45:] = positions[45:]
    optimizer = small_optimizer()
    run(optimizer, [shaky], 45)
    calibration = optimizer.calibrations[0]
    np.testing.assert_allclose(calibration.lengths[[knee, ankle]], calibration.lengths[right])
    assert calibration.borrowed[[knee, ankle]].all()
    assert calibration.borrowed.sum() == 2
    assert optimizer.people()[0].acceptance_time == pytest.approx((FRAMES - 1) / 30)
    assert optimizer.report()[0] == (
        "accepted after 1.0 s (the other side's length for now: HipLeft-KneeLeft, "
        "KneeLeft-AnkleLeft)"
    )
    assert PersonCalibration.from_dict(calibration.to_dict()).borrowed[[knee, ankle]].all()
    run(optimizer, [shaky], 135, start=45)
    calibration = optimizer.calibrations[0]
    own = true_lengths[[knee, ankle]]
    assert (np.abs(own / true_lengths[right] - 1) > 0.05).all()  # the sides differ
    np.testing.assert_allclose(calibration.lengths[[knee, ankle]], own, rtol=0.02)
    assert not calibration.borrowed.any()
    assert optimizer.report()[0] == "accepted after 1.0 s"


def test_hands_never_seen_still_give_constrained_legs(noisy_people, run):
    _, measured, _ = noisy_people
    handless = measured[0].copy()
    handless[:, SHORT_JOINTS[:6]] = np.nan
    optimizer = small_optimizer()
    run(optimizer, [handless], 60)
    lengths = optimizer.calibrations[0].lengths
    assert np.isfinite(lengths[LIMBS]).all()
    assert np.isnan(lengths[SHORT_JOINTS[:6]]).all()
    assert optimizer.people()[0].accepted_ns is not None
    free = optimizer.people()[0].free_links(AZURE_KINECT, 0.2)
    assert free["WristLeft-HandLeft"] == "seen in 0 % of frames"


def test_a_person_who_never_qualifies_is_reported(noisy_people, run):
    """Neither arm ever seen: the legs lock, the person is reported once past the timeout."""
    _, measured, _ = noisy_people
    armless = measured[0].copy()
    elbows = [AZURE_KINECT.index("ElbowLeft"), AZURE_KINECT.index("ElbowRight")]
    armless[:, elbows[0] : elbows[0] + 5] = np.nan  # elbow to thumb, left
    armless[:, elbows[1] : elbows[1] + 5] = np.nan  # and right
    optimizer = small_optimizer(acceptance_timeout=1.5)
    overdue = []
    for frame in range(60):
        run(optimizer, [armless], 1, start=frame)
        overdue += [(frame, track) for track in optimizer.new_overdue]
    assert overdue == [(46, 0)]  # 1.53 s after the first frame
    progress = optimizer.people()[0]
    assert progress.accepted_ns is None
    assert np.isfinite(optimizer.calibrations[0].lengths[LIMBS[4:]]).all()
    report = optimizer.report()[0]
    assert report == (
        "not accepted after 2.0 s: ElbowLeft-WristLeft seen in 0 % of frames; "
        "ElbowRight-WristRight seen in 0 % of frames; "
        "ShoulderLeft-ElbowLeft seen in 0 % of frames; "
        "ShoulderRight-ElbowRight seen in 0 % of frames "
        "(free: HandLeft-HandTipLeft, HandRight-HandTipRight, WristLeft-HandLeft, "
        "WristLeft-ThumbLeft, WristRight-HandRight, WristRight-ThumbRight)"
    )
    assert optimizer.diagnostics() == {"person.0": report}


def test_diagnostics_give_the_acceptance_under_the_stage_name(noisy_people, run):
    _, measured, _ = noisy_people
    optimizer = small_optimizer()
    run(optimizer, measured[:1], FRAMES)
    merged = Merged([("optimizer: ", optimizer)], [optimizer])
    assert merged.diagnostics() == {"optimizer: person.0": "accepted after 1.0 s"}


def test_services_refuse_meaningless_arguments(noisy_people, run):
    """Issue 21 case 20: ``~/calibrate []`` and ``~/change_id(0, 0)`` returned success."""
    _, measured, _ = noisy_people
    optimizer = small_optimizer()
    run(optimizer, measured, FRAMES)
    calibrations = dict(optimizer.calibrations)
    assert sorted(calibrations) == [0, 1]
    assert not optimizer.calibrate([])
    assert not optimizer.change_id(0, 0)
    assert not optimizer.change_id(0, -1)
    assert optimizer.calibrations == calibrations  # nothing changed
    assert optimizer.change_id(0, 7)
    assert optimizer.calibrate([7])
