"""A detection's sides are held to its track's (``kernels.canonical_poses``)."""

import numpy as np
import pytest

from hiros_core.layouts import AZURE_KINECT
from hiros_tracker import kernels
from hiros_tracker.kernel_args import FacingView, HeldSides, SideLayout
from hiros_tracker.labels import CLEAR_AXIS, SIDE_MEMORY, WALK_MEMORY, WALK_SPEED
from hiros_tracker.tracker import _body_frame, _mirror_parts, _side_arrays

_NO_CAMERA = (np.zeros((1, 1, 3)), np.zeros((1, 1), dtype=np.int64), 0, 0)
"""``HeldSides``' camera fields of a track no camera has given an axis yet."""


def _standing() -> np.ndarray:
    """``(J, 3)`` a person facing +x (left = +y), joints placed by name."""
    pose = np.zeros((AZURE_KINECT.n_joints, 3))
    for joint, name in enumerate(AZURE_KINECT.joint_names):
        side = 0.18 if "Left" in name else -0.18 if "Right" in name else 0.0
        height = 1.4 if any(part in name for part in ("Shoulder", "Clavicle", "Elbow")) else 0.9
        pose[joint] = (0.05 * (joint % 3), side, height)
    return pose


def _canonical(  # noqa: PLR0917 - the detection, its track and what the track holds
    detection: np.ndarray,
    track: np.ndarray,
    matched: np.ndarray | None = None,
    axis: np.ndarray | None = None,
    camera_axis: np.ndarray | None = None,
    camera_age: float = 0.0,
) -> np.ndarray:
    """The flips ``canonical_poses`` gives a detection whose parts matched ``matched``.

    ``matched`` ``(K,)``: the parts the association took mirrored (default: none); ``axis``
    ``(3,)`` the track's held left-right axis (default: none yet, the pose's);
    ``camera_axis`` ``(3,)`` that of the camera's last detection of the track, ``camera_age``
    s before this one (default: none).
    """
    parts = _mirror_parts(AZURE_KINECT)
    sides = SideLayout(*_side_arrays(AZURE_KINECT, parts))
    frame = _body_frame(AZURE_KINECT)
    if matched is None:
        matched = np.zeros(parts.count, dtype=bool)
    axes = np.zeros((1, 3)) if axis is None else axis[None].astype(float)
    camera = _NO_CAMERA
    if camera_axis is not None:
        stamp = round(camera_age * 1e9)
        camera = (camera_axis[None, None].astype(float), np.zeros((1, 1), dtype=np.int64), 0, stamp)
    held = HeldSides(
        track[None],
        axes,
        np.zeros((1, 3)),
        np.array([0]),
        frame.left,
        frame.right,
        *camera,
        np.zeros(1),
    )
    _, flips = kernels.canonical_poses(
        detection[None],
        np.array([0]),
        matched[None],
        parts.arrays,
        True,
        sides,
        held,
    )
    return flips[0]


def _turned(pose: np.ndarray, degrees: float) -> np.ndarray:
    angle = np.radians(degrees)
    rotation = np.array(
        [[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0, 0, 1]]
    )
    return pose @ rotation.T


@pytest.mark.parametrize("degrees", [150.0, 180.0, 210.0])
def test_a_detection_whose_left_points_to_the_tracks_right_is_relabelled_whole(degrees):
    # The per-part match kept its labels (a flip's swinging hands and feet can do that):
    # its left-right axis (shoulders and hips) then says the whole body is mirrored.
    track = _standing()
    flips = _canonical(_turned(track, degrees), track)
    assert flips.all()


@pytest.mark.parametrize("degrees", [0.0, 60.0, 100.0])
def test_a_detection_within_a_turn_of_its_track_keeps_its_labels(degrees):
    track = _standing()
    assert not _canonical(_turned(track, degrees), track).any()


def test_the_arms_follow_a_clearly_reversed_torso_whatever_the_part_match() -> None:
    # A noisy flipped detection: its shoulders and hips together point to the track's right
    # (cos -0.99), but the association took its legs mirrored and its arms as given, and
    # neither the hips against the shoulders (cos -0.2) nor the relabelled torso (cos -0.4)
    # is clearly reversed: the arms kept the camera's mirrored labels and pulled the track
    # (noisy-sdk, 18.75 s). The arms' labels now follow the raw torso's.
    names = {name: j for j, name in enumerate(AZURE_KINECT.joint_names)}
    track = _standing()
    detection = track.copy()
    for joint, half in (("Shoulder", [0.1, -0.15, 0.0]), ("Hip", [-0.125, -0.05, 0.0])):
        left, right = names[f"{joint}Left"], names[f"{joint}Right"]
        middle = (track[left] + track[right]) / 2
        detection[left], detection[right] = middle + half, middle - np.array(half)
    parts = _mirror_parts(AZURE_KINECT)
    arms, legs = parts.part[names["ShoulderLeft"]], parts.part[names["HipLeft"]]
    matched = np.zeros(parts.count, dtype=bool)
    matched[legs] = True
    flips = _canonical(detection, track, matched)
    assert flips[arms]


def _legs_reported(hips_apart: float, below: str) -> np.ndarray:
    """A standing track's detection whose hips are ``hips_apart`` m apart, ``below`` the
    hips as labelled ("right"), swapped ("swapped": crossed, or the whole leg mislabelled)
    or not seen ("unseen")."""
    index = AZURE_KINECT.index
    detection = _standing()
    left, right = index("HipLeft"), index("HipRight")
    middle = (detection[left] + detection[right]) / 2
    half = np.array([0.0, hips_apart / 2, 0.0])
    detection[left] = middle + half
    detection[right] = middle - half
    for joint in ("Knee", "Ankle", "Foot"):
        left, right = index(f"{joint}Left"), index(f"{joint}Right")
        if below == "swapped":
            detection[[left, right]] = detection[[right, left]]
        elif below == "unseen":
            detection[[left, right]] = np.nan
    return detection


@pytest.mark.parametrize(
    ("hips_apart", "below", "flipped"),
    [
        (-0.04, "right", False),  # an SDK's hips 4 cm apart, pointing the wrong way: noise
        (-0.04, "unseen", True),  # the hips alone, as before: nothing says otherwise
        (-0.36, "swapped", True),  # the whole leg labelled the other side's
        (0.36, "swapped", False),  # a turning step: knees and feet cross, the hips do not
    ],
)
def test_the_legs_are_held_to_the_shoulders_by_the_hips_unless_the_leg_says_otherwise(
    hips_apart: float, below: str, flipped: bool
) -> None:
    track = _standing()
    legs = _mirror_parts(AZURE_KINECT).part[AZURE_KINECT.joint_names.index("HipLeft")]
    flips = _canonical(_legs_reported(hips_apart, below), track)
    assert flips[legs] == flipped
    assert flips.sum() == flipped  # no other part moves


def test_detections_are_held_to_the_tracks_held_axis_not_to_its_dragged_pose() -> None:
    # Noisy detections taken with their labels dragged the track's pose 100 deg round; its
    # held axis still says left is +y. A detection facing the other way (170 deg) is held
    # to that: relabelled whole, though it lies only 70 deg from the dragged pose.
    track = _standing()
    dragged = _turned(track, 100.0)
    detection = _turned(track, 170.0)
    assert not _canonical(detection, dragged).any()  # held to the pose: kept as labelled
    flips = _canonical(detection, dragged, axis=np.array([0.0, 1.0, 0.0]))
    assert flips.all()


def test_a_detection_that_goes_on_turning_with_its_camera_keeps_its_labels() -> None:
    # A fast turn at the end of a walk: the track's held axis (left = +y) lags the body by
    # 125 deg, so the detection alone counts as reversed; the camera's previous detection,
    # 1/30 s before, had already turned 110 deg. It keeps its labels.
    track = _standing()
    detection = _turned(track, 125.0)
    held = np.array([0.0, 1.0, 0.0])
    assert _canonical(detection, track, axis=held).all()  # the held axis alone: relabelled
    last = _axis(_turned(track, 110.0))
    assert not _canonical(detection, track, axis=held, camera_axis=last, camera_age=1 / 30).any()
    stale = _canonical(detection, track, axis=held, camera_axis=last, camera_age=0.5)
    assert stale.all()  # the camera's axis of half a second before tells nothing


@pytest.mark.parametrize(("length", "kept"), [(0.5, True), (0.05, False)])
def test_a_side_views_short_axis_does_not_steer_its_cameras_next_detection(length, kept):
    # The camera's last detection, labelled 115 deg off the held axis (left = +y): a clear
    # one (0.5 m) had turned with the body, and the next, 130 deg off, keeps its labels; a
    # side view's 5 cm axis says nothing, and the next detection is held to the track.
    track = _standing()
    detection = _turned(track, 130.0)
    last = _axis(_turned(track, 115.0))
    last *= length / np.linalg.norm(last)
    flips = _canonical(detection, track, axis=np.array([0.0, 1.0, 0.0]), camera_axis=last)
    assert (not flips.any()) == kept
    assert flips.all() != kept


def test_a_camera_whose_labels_went_wrong_is_held_to_the_track() -> None:
    # The camera's previous detection went into the track with its sides reversed (170 deg
    # off the held axis); its next one, as reversed, is relabelled all the same.
    track = _standing()
    detection = _turned(track, 175.0)
    last = _axis(_turned(track, 170.0))
    flips = _canonical(detection, track, axis=np.array([0.0, 1.0, 0.0]), camera_axis=last)
    assert flips.all()


def test_a_cameras_last_axis_is_kept_and_turned_with_its_track() -> None:
    track = _standing()
    held = _held(track)
    kernels.hold_axes(held, track[None], np.zeros(1, dtype=np.int64), _view(7))
    assert held.camera_axes[0, 0] == pytest.approx(_axis(track))
    assert held.camera_ns[0, 0] == 7


def _held(
    track: np.ndarray, velocity: tuple[float, float, float] = (0.0, 0.0, 0.0), facing: float = 0.0
) -> HeldSides:
    """One track at ``track`` with no held axis yet, moving at ``velocity`` (m/s), with
    ``facing`` log-odds that its sides are right."""
    frame = _body_frame(AZURE_KINECT)
    velocities = np.array([velocity], dtype=float)
    return HeldSides(
        track[None],
        np.zeros((1, 3)),
        velocities,
        np.array([0]),
        frame.left,
        frame.right,
        np.zeros((1, 2, 3)),
        np.zeros((1, 2), dtype=np.int64),
        0,
        0,
        np.array([facing]),
    )


def _view(stamp_ns: int, camera: int = 0) -> FacingView:
    """A camera's view at ``stamp_ns`` in a z-up world (its position does not matter here)."""
    return FacingView(np.array([0.0, 0.0, 1.0, 1.0]), np.zeros(3), True, camera, stamp_ns)


def _axis(pose: np.ndarray) -> np.ndarray:
    frame = _body_frame(AZURE_KINECT)
    return pose[frame.left].sum(axis=0) - pose[frame.right].sum(axis=0)


def test_the_held_axis_follows_detections_over_its_memory() -> None:
    track = _standing()
    held = _held(track)
    first = np.zeros(1, dtype=np.int64)
    kernels.hold_axes(held, track[None], first, _view(0))  # a first detection: taken whole
    assert held.axes[0] == pytest.approx(_axis(track))
    turned = _turned(track, 60.0)
    kernels.hold_axes(held, turned[None], first, _view(round(SIDE_MEMORY * 1e9 / 2)))
    # half a memory's time, weighed by the cosine with the camera's last detection (0.5)
    keep = np.exp(-0.5 * np.cos(np.radians(60.0)))
    assert held.axes[0] == pytest.approx(keep * _axis(track) + (1 - keep) * _axis(turned))


def test_a_detection_that_jumped_across_its_cameras_stream_leaves_the_held_axis() -> None:
    # A noisy detection whose torso lies 95 deg off its camera's last one, 0.1 s before: not
    # clearly reversed, so kept as labelled, but it says nothing of the track's sides.
    track = _standing()
    held = _held(track)
    first = np.zeros(1, dtype=np.int64)
    kernels.hold_axes(held, track[None], first, _view(0))
    across = _turned(track, 95.0)
    kernels.hold_axes(held, across[None], first, _view(round(0.1e9)))
    assert held.axes[0] == pytest.approx(_axis(track))
    assert held.camera_axes[0, 0] == pytest.approx(_axis(across))  # its camera's last, still


def test_a_hit_without_a_torso_leaves_the_axis_its_time() -> None:
    # Camera 1 sees the track between camera 0's two detections, but not its hips: its hit
    # adds nothing to the held axis and must not use up the time camera 0's next detection
    # (turned 60 deg, a turn going on) is weighed by.
    track = _standing()
    held = _held(track)
    kernels.hold_axes(held, track[None], np.zeros(1, dtype=np.int64), _view(1))
    hipless = track.copy()
    hipless[AZURE_KINECT.joint_names.index("HipLeft")] = np.nan
    kernels.hold_axes(held, hipless[None], np.array([1]), _view(round(0.05e9), camera=1))
    turned = _turned(track, 60.0)
    kernels.hold_axes(held, turned[None], np.array([round(0.05e9)]), _view(round(0.1e9) + 1))
    keep = np.exp(-0.5 * np.cos(np.radians(60.0)))  # 0.1 s of the memory's 0.2, cos 0.5
    assert held.axes[0] == pytest.approx(keep * _axis(track) + (1 - keep) * _axis(turned))


def test_a_detection_after_its_cameras_gap_counts_whole() -> None:
    # Its camera last saw the track half a second before: the body may have turned since.
    track = _standing()
    held = _held(track)
    first = np.zeros(1, dtype=np.int64)
    kernels.hold_axes(held, track[None], first, _view(0))
    across = _turned(track, 95.0)
    stamp = round(0.5e9)
    kernels.hold_axes(held, across[None], first, _view(stamp))
    keep = np.exp(-0.5 / SIDE_MEMORY)
    assert held.axes[0] == pytest.approx(keep * _axis(track) + (1 - keep) * _axis(across))


@pytest.mark.parametrize("speed", [0.0, 0.5 * WALK_SPEED])
def test_a_standing_or_stepping_track_keeps_the_axis_its_detections_give(speed: float) -> None:
    track = _standing()  # left is +y, facing +x
    held = _held(track, (-speed, 0.0, 0.0))  # stepping back
    first = np.zeros(1, dtype=np.int64)
    kernels.hold_axes(held, track[None], first, _view(0))
    kernels.hold_axes(held, track[None], first, _view(round(WALK_MEMORY * 1e9)))
    assert held.axes[0] == pytest.approx(_axis(track))


def test_a_walking_tracks_axis_turns_to_face_where_it_walks() -> None:
    # The held axis says left is -y (the track's sides mirrored, its detections held to
    # that), but the body walks along +x: a body facing +x has its left at +y. Over
    # WALK_MEMORY the walk pulls the axis 1 - 1/e of the way there, keeping its length,
    # before the detection folds in.
    track = _standing()
    mirrored = _turned(track, 180.0)
    held = _held(track, (1.5 * WALK_SPEED, 0.0, 0.0))
    first = np.zeros(1, dtype=np.int64)
    kernels.hold_axes(held, mirrored[None], first, _view(0))
    length = np.linalg.norm(_axis(mirrored))
    stamp = round(WALK_MEMORY * 1e9)
    kernels.hold_axes(held, mirrored[None], first, _view(stamp))
    walked = np.exp(-1.0) * _axis(mirrored) + (1 - np.exp(-1.0)) * np.array([0.0, length, 0.0])
    keep = np.exp(-WALK_MEMORY / SIDE_MEMORY)
    expected = keep * walked + (1 - keep) * _axis(mirrored)
    assert held.axes[0] == pytest.approx(expected)


@pytest.mark.parametrize(("facing", "pulled"), [(10.0, False), (0.0, True)])
def test_a_track_sure_of_its_sides_is_not_turned_by_a_step_back(facing, pulled) -> None:
    # The person faces +x and steps back fast (-x): a track whose cameras have told it its
    # sides keeps them; one in doubt is turned to face its walk, as a mirrored one must be.
    track = _standing()
    held = _held(track, (-1.5 * WALK_SPEED, 0.0, 0.0), facing=facing)
    first = np.zeros(1, dtype=np.int64)
    kernels.hold_axes(held, track[None], first, _view(0))
    kernels.hold_axes(held, track[None], first, _view(round(WALK_MEMORY * 1e9)))
    assert (held.axes[0] != pytest.approx(_axis(track))) == pulled


def test_a_side_views_short_axis_hardly_turns_the_held_one() -> None:
    # A camera at the person's side sees the axis along its depth and reports it a few
    # centimetres long, pointing anywhere: it counts by (length / CLEAR_AXIS)^2.
    track = _standing()
    held = _held(track)
    first = np.zeros(1, dtype=np.int64)
    kernels.hold_axes(held, track[None], first, _view(0))
    side = track.copy()
    side[:, 1] *= 0.1  # the shoulders and hips 4 cm from the midline...
    side = _turned(side, -90.0)  # ...and the axis pointing along +x
    short = _axis(side)
    length = np.linalg.norm(short)
    assert 0.05 < length < 0.1
    stamp = round(SIDE_MEMORY * 1e9 / 2)
    kernels.hold_axes(held, side[None], first, _view(stamp, camera=1))
    keep = np.exp(-0.5 * (length / CLEAR_AXIS) ** 2)
    assert held.axes[0] == pytest.approx(keep * _axis(track) + (1 - keep) * short)

    def turn(axis: np.ndarray) -> float:
        cosine = axis @ _axis(track) / np.linalg.norm(axis) / np.linalg.norm(_axis(track))
        return np.degrees(np.arccos(min(cosine, 1.0)))

    whole = np.exp(-0.5) * _axis(track) + (1 - np.exp(-0.5)) * short
    assert 0.0 < turn(held.axes[0]) < 0.5
    assert turn(whole) > 3.0  # taken whole; and a run of them turns it far more
