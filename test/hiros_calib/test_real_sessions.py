"""The real KinectMultiTrack sessions (two Kinect v2 on independent clocks, ../shared/data).

Each file holds both cameras' device clocks; the recorder's server clock (the arrival times)
pins the lag to within a second. Two-person sessions recorded 40 minutes apart with the same
two devices must give offsets that differ by a plausible clock drift only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hiros_calib.calibrator import Calibrator, CalibratorParams
from hiros_convert import convert
from hiros_core.recording import read_camera_groups

pytestmark = pytest.mark.slow
DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "kinect_multitrack"


def _session(name: str, folder: Path):
    """Per camera its groups and arrival times: converted as ``hiros convert`` does (the
    server clock becomes the log time), read back as ``hiros calibrate`` does."""
    path = DATA / name
    if not path.exists():
        pytest.skip(f"{path} is not available")
    recording = folder / f"{path.stem}.mcap"
    convert(path, recording, skeleton_groups=True)
    return read_camera_groups(recording)


@pytest.mark.parametrize(
    "name", ["Study_21_Kinect_1_Time_2_09_50_PM.csv", "Study_24_Kinect_1_Time_2_49_46_PM.csv"]
)
def test_two_person_sessions_calibrate(name, tmp_path):
    groups, arrival_ns = _session(name, tmp_path)
    calibrator = Calibrator()
    calibration = calibrator.calibrate(groups, arrival_ns=arrival_ns)
    assert len(calibration.cameras) == 2
    other = next(c for c in calibration.cameras if c != calibration.reference)
    cam = calibration.cameras[other]
    # the recorder had already moved both streams into one frame: a small residual pose
    # (relative to the reference camera; the world is the floor's)
    relative = calibration.cameras[calibration.reference].extrinsics.inverse() @ cam.extrinsics
    assert np.degrees(relative.rotation.magnitude()) < 10.0
    assert np.linalg.norm(relative.translation) < 0.3
    assert cam.quality["residual_m"] < 0.05
    assert cam.quality["time_sharpness"] > 10.0


def test_sessions_40_minutes_apart_agree_up_to_drift(tmp_path):
    offsets = []
    for name in ("Study_21_Kinect_1_Time_2_09_50_PM.csv", "Study_24_Kinect_1_Time_2_49_46_PM.csv"):
        groups, arrival_ns = _session(name, tmp_path)
        params = CalibratorParams(reference="kinect_138_251_207_136")
        calibration = Calibrator(params).calibrate(groups, arrival_ns=arrival_ns)
        offsets.append(calibration.cameras["kinect_138_251_213_82"].time_offset)
    drift = (offsets[1] - offsets[0]) / (40 * 60)
    assert abs(drift) < 100e-6  # crystal clocks: tens of ppm
