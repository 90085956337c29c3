from pathlib import Path

import numpy as np
import pytest

from hiros_core.errors import RecordingError
from hiros_sim import default_bvh_files, read_bvh

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"


def _bundled(name: str) -> str:
    return next(f for f in default_bvh_files() if Path(f).name.startswith(name))


@pytest.mark.parametrize(
    ("name", "frames", "joints", "rate"),
    [("131_01", 995, 31, 120.0), ("131_02", 1248, 31, 120.0), ("sbj01_bend1", 839, 23, 60.0)],
)
def test_bundled_clips(name, frames, joints, rate):
    motion = read_bvh(_bundled(name))
    assert motion.n_frames == frames
    real_joints = [n for n in motion.joint_names if not n.endswith("_End")]
    assert len(real_joints) == joints
    assert motion.rate == pytest.approx(rate, rel=1e-3)
    assert motion.positions.shape == (frames, len(motion.joint_names), 3)
    # metres, Y up: the hips of a standing adult are near 0.9-1.0 m
    assert 0.8 < motion.positions[0, 0, 1] < 1.1


@pytest.mark.skipif(not SHARED.is_dir(), reason="needs ../shared/data")
def test_shared_files_match_bundled_copies():
    plain = read_bvh(SHARED / "mocap_cmu" / "131_03.bvh")
    packed = read_bvh(_bundled("131_03"))
    assert plain.n_frames == 1248
    np.testing.assert_array_equal(plain.positions, packed.positions)


def test_forward_kinematics_keeps_bone_lengths():
    motion = read_bvh(_bundled("131_01"))
    parents = motion.parents
    child = np.flatnonzero(parents >= 0)
    lengths = np.linalg.norm(
        motion.positions[:, child] - motion.positions[:, parents[child]], axis=-1
    )
    np.testing.assert_allclose(
        lengths, np.linalg.norm(motion.offsets[child], axis=1)[None] + 0 * lengths, atol=1e-9
    )
    # rotations are proper
    dets = np.linalg.det(motion.rotations[::50])
    np.testing.assert_allclose(dets, 1.0, atol=1e-9)


def test_known_rotation(tmp_path):
    text = (
        "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
        "Zrotation Yrotation Xrotation\n JOINT Arm\n {\n  OFFSET 1 0 0\n  CHANNELS 3 Zrotation "
        "Yrotation Xrotation\n  End Site\n  {\n   OFFSET 0 2 0\n  }\n }\n}\nMOTION\nFrames: 2\n"
        "Frame Time: 0.5\n0 1 0 0 0 0 0 0 0\n0 1 0 90 0 0 0 0 0\n"
    )
    path = tmp_path / "tiny.bvh"
    path.write_text(text)
    motion = read_bvh(path)
    assert motion.joint_names == ("Hips", "Arm", "Arm_End")
    np.testing.assert_allclose(motion.positions[0], [[0, 1, 0], [1, 1, 0], [1, 3, 0]], atol=1e-12)
    # 90 degrees about Z at the root turns +x into +y and +y into -x
    np.testing.assert_allclose(motion.positions[1], [[0, 1, 0], [0, 2, 0], [-2, 2, 0]], atol=1e-12)
    assert motion.rate == 2.0


def test_bad_files_raise_recording_error(tmp_path):
    with pytest.raises(RecordingError, match="cannot read"):
        read_bvh(tmp_path / "missing.bvh")
    bad = tmp_path / "bad.bvh"
    bad.write_text("hello\n")
    with pytest.raises(RecordingError, match="not a BVH"):
        read_bvh(bad)
    short = tmp_path / "short.bvh"
    short.write_text(
        "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\n"
        "MOTION\nFrames: 3\nFrame Time: 0.1\n0 0 0\n"
    )
    with pytest.raises(RecordingError, match="expected 3 frames"):
        read_bvh(short)


def test_position_channels_replace_the_offset(tmp_path):
    """Files that give every joint position channels repeat its offset there (Bandai-Namco's):
    the bone keeps its length, and a root's channels place it whatever its offset."""
    text = (
        "HIERARCHY\nROOT Hips\n{\n OFFSET 5 90 -400\n"
        " CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        " JOINT Spine\n {\n  OFFSET 0 15 0\n"
        "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "  End Site\n  {\n   OFFSET 0 10 0\n  }\n }\n}\n"
        "MOTION\nFrames: 1\nFrame Time: 0.0333333\n0 92 -1 0 0 0 0 15 0 0 0 0\n"
    )
    path = tmp_path / "channels.bvh"
    path.write_text(text)
    motion = read_bvh(path)
    np.testing.assert_allclose(motion.positions[0], [[0, 92, -1], [0, 107, -1], [0, 117, -1]])


@pytest.mark.skipif(not SHARED.is_dir(), reason="needs ../shared/data")
def test_bandai_clip_keeps_its_bone_lengths():
    motion = read_bvh(SHARED / "bandai_motion2" / "dataset-2_wave-both-hands_normal_001.bvh")
    assert motion.rate == pytest.approx(30.0, rel=1e-3)
    pelvis = motion.positions[:, motion.index("Hips")]
    assert 80.0 < np.median(pelvis[:, 1]) < 110.0  # centimetres, Y up
    child = motion.index("LowerLeg_L")
    shank = np.linalg.norm(
        motion.positions[:, motion.index("Foot_L")] - motion.positions[:, child], axis=-1
    )
    np.testing.assert_allclose(
        shank, np.linalg.norm(motion.offsets[motion.index("Foot_L")]), rtol=1e-6
    )
