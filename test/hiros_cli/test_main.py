"""hiros's entry point: errors the user can fix end in one line and exit code 1, no traceback."""

from __future__ import annotations

import numpy as np
import pytest

from hiros_cli.main import main
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_core.recording import RecordingWriter
from hiros_pipeline.offline import _calibration_message


@pytest.fixture(name="run_output")
def _run_output(tmp_path):
    """The smallest `hiros run` output: the calibration used and one filter output."""
    path = tmp_path / "out.mcap"
    calibration = Calibration("k01", cameras={"k01": CameraCalibration("k01_depth_camera_link")})
    person = Skeleton.from_positions(np.zeros((32, 3)), skeleton_id=1, src_time_ns=10**9)
    with RecordingWriter(path) as writer:
        writer.write("/hiros/calibration", "std_msgs/msg/String",
                     _calibration_message(calibration), 0)  # fmt: skip
        writer.write_group("/hiros/filter", SkeletonGroup(10**9, "world", [person]))
    return path


def test_an_output_folder_that_cannot_be_made_is_one_line(tmp_path, run_output, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert main(["export", str(run_output), "--out", str(blocker)]) == 1
    err = capsys.readouterr().err
    assert err == f"hiros export: error: {blocker}: File exists\n"
