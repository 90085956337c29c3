from pathlib import Path

import numpy as np
import pytest

from hiros_core.layouts import AZURE_KINECT
from hiros_sim import default_bvh_files, read_bvh
from hiros_sim.mapping import BVH_TO_WORLD, map_to_azure
from hiros_sim.people import body_forward, prepare_clip
from hiros_sim.shared import BANDAI_FOLDER, shared_data_dir

IDX = AZURE_KINECT.index
# plausible adult limb lengths (m): generous bounds that a wrong joint would break
LIMBS = {
    ("HipLeft", "KneeLeft"): (0.33, 0.52),
    ("KneeLeft", "AnkleLeft"): (0.32, 0.48),
    ("ShoulderLeft", "ElbowLeft"): (0.2, 0.34),
    ("ElbowLeft", "WristLeft"): (0.17, 0.3),
    ("Pelvis", "Neck"): (0.35, 0.65),
    ("Neck", "Head"): (0.03, 0.15),
    ("HipLeft", "HipRight"): (0.1, 0.25),
    ("ShoulderLeft", "ShoulderRight"): (0.18, 0.45),  # Bandai-Namco's rig: 0.20
    ("WristLeft", "HandTipLeft"): (0.1, 0.25),
}


# Bandai-Namco's clips (shared data, CC BY-NC): centimetres, suffix names, every joint with
# position channels, a rest pose with every bone along its joint's x, a root on the floor.
BANDAI = [
    str(shared_data_dir() / BANDAI_FOLDER / f"dataset-2_{name}_001.bvh")
    for name in ("wave-both-hands_elderly", "walk-turn-left_normal")
]


@pytest.fixture(
    scope="module", params=[*default_bvh_files(), *BANDAI], ids=lambda p: Path(p).name[:24]
)
def mapped(request):
    if not Path(request.param).is_file():
        pytest.skip(f"needs {request.param}")
    return map_to_azure(read_bvh(request.param))


def test_limb_lengths_plausible_and_rigid(mapped):
    for (a, b), (low, high) in LIMBS.items():
        length = np.linalg.norm(mapped[:, IDX(a)] - mapped[:, IDX(b)], axis=-1)
        assert low < np.median(length) < high, (a, b, np.median(length))
    for a, b in (("HipLeft", "KneeLeft"), ("ElbowRight", "WristRight"), ("Head", "Nose")):
        length = np.linalg.norm(mapped[:, IDX(a)] - mapped[:, IDX(b)], axis=-1)
        assert length.std() < 1e-6


def test_sides_symmetric(mapped):
    parents, children = AZURE_KINECT.link_parents, AZURE_KINECT.link_children
    lengths = np.median(np.linalg.norm(mapped[:, children] - mapped[:, parents], axis=-1), axis=0)
    by_child = dict(zip(children.tolist(), lengths, strict=True))
    for child, length in by_child.items():
        twin = int(AZURE_KINECT.mirror[child])
        assert abs(length - by_child[twin]) < 0.03, AZURE_KINECT.joint_names[child]


def test_neck_above_shoulders(mapped):
    shoulders = 0.5 * (mapped[:, IDX("ShoulderLeft")] + mapped[:, IDX("ShoulderRight")])
    up = mapped[:, IDX("Neck")] - mapped[:, IDX("Pelvis")]
    up /= np.linalg.norm(up, axis=-1, keepdims=True)
    rel = np.einsum("tc,tc->t", mapped[:, IDX("Neck")] - shoulders, up)
    assert np.median(rel) > -0.01


def test_world_is_z_up_and_face_in_front(mapped):
    # standing at the start: head above pelvis above ankles
    first = mapped[0]
    assert first[IDX("Head"), 2] > first[IDX("Pelvis"), 2] + 0.4
    assert first[IDX("Pelvis"), 2] > first[IDX("AnkleLeft"), 2] + 0.5
    forward = body_forward(mapped[:20]).mean(axis=0)
    nose = (mapped[:20, IDX("Nose")] - mapped[:20, IDX("Head")]).mean(axis=0)
    assert np.dot(forward, nose) > 0.05  # the nose points where the body faces
    left = mapped[:20, IDX("HipLeft")] - mapped[:20, IDX("HipRight")]
    assert np.dot(np.cross(left.mean(axis=0), [0, 0, 1]), forward) > 0  # forward = left × up
    spine = [IDX(n) for n in ("Pelvis", "SpineNaval", "SpineChest", "Neck")]
    assert np.all(np.diff(first[spine, 2]) > 0.05)  # the spine rises from the pelvis


def test_bvh_to_world_is_a_rotation():
    assert np.allclose(BVH_TO_WORLD @ BVH_TO_WORLD.T, np.eye(3))
    assert np.linalg.det(BVH_TO_WORLD) == pytest.approx(1.0)
    assert np.allclose(BVH_TO_WORLD @ [0, 1, 0], [0, 0, 1])  # BVH up -> world up


def test_prepared_clip_on_the_floor_and_travelling_along_x():
    clip = prepare_clip(read_bvh(default_bvh_files()[0]))
    feet = clip.positions[:, [IDX("FootLeft"), IDX("FootRight")], 2].min(axis=1)
    assert 0.0 < np.percentile(feet, 5) < 0.08
    pelvis = clip.positions[:, IDX("Pelvis")]
    np.testing.assert_allclose(pelvis[0, :2], 0.0, atol=1e-9)
    assert pelvis[-1, 0] == pytest.approx(clip.travel)
    assert abs(pelvis[-1, 1]) < 1e-9
    mirrored = clip.mirrored()
    np.testing.assert_allclose(
        mirrored.positions[:, IDX("HandLeft"), 1], -clip.positions[:, IDX("HandRight"), 1]
    )
