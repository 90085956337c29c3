"""A calibration flagged as doubtful is never used silently by ``hiros run``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hiros_cli.main import main
from hiros_core.calibration import load_calibration, save_calibration
from hiros_eval.calibration import compare_calibration
from hiros_sim import SimParams, simulate, write_recording


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("sim")
    write_recording(simulate(SimParams(n_cameras=2, n_people=1, duration=6.0, seed=3)), folder)
    return folder


def test_run_refuses_a_flagged_camera_unless_told_to_accept_it(
    sim: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration = load_calibration(sim / "calibration.yaml")
    calibration.cameras["k02"].flagged = "the clocks miss the k01-k02 lag by +300 ms"
    flagged = tmp_path / "flagged.yaml"
    save_calibration(calibration, flagged)
    assert load_calibration(flagged).flagged == {"k02": calibration.cameras["k02"].flagged}
    out = tmp_path / "out.mcap"
    args = ["run", str(sim / "recording.mcap"), "--calibration", str(flagged), "--out", str(out)]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "flags k02 as doubtful" in err
    assert "+300 ms" in err
    assert "--accept-flagged" in err
    assert not out.exists()
    assert main([*args, "--accept-flagged"]) == 0
    assert "using flagged cameras" in capsys.readouterr().out
    assert out.exists()


def test_run_with_calibration_auto_stops_on_a_flagged_result(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from hiros_sim.presets import preset_params

    # a noisier SDK and 10 s of one person: the two halves of the recording give poses
    # degrees apart, so the calibration flags the camera as poorly determined
    folder = tmp_path / "noisy"
    scene = simulate(preset_params("noisy-sdk", seed=0, duration=10.0, n_cameras=2, n_people=1))
    write_recording(scene, folder)
    out = tmp_path / "out.mcap"
    args = ["run", str(folder / "recording.mcap"), "--calibration", "auto", "--out", str(out)]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "flags k02 as doubtful" in err
    assert "poorly determined" in err
    assert not out.exists()
    written = load_calibration(out.with_suffix(".calib.yaml"))  # kept, for the user to read
    assert "poorly determined" in written.cameras["k02"].flagged


def test_run_with_calibration_auto_keeps_known_poses_and_times_the_clocks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A recording whose own poses are flagged (as above: seed 1 is flagged alone too) runs
    with the poses of a calibration of the same cameras given as --poses-from; --poses-from
    beside a calibration file is an error."""
    from hiros_sim.presets import preset_params

    folder = tmp_path / "noisy"
    scene = simulate(preset_params("noisy-sdk", seed=1, duration=10.0, n_cameras=2, n_people=1))
    write_recording(scene, folder)
    known = folder / "calibration.yaml"  # the simulator's truth: poses from elsewhere
    out = tmp_path / "out.mcap"
    args = ["run", str(folder / "recording.mcap"), "--out", str(out), "--poses-from", str(known)]
    assert main([*args, "--calibration", "auto"]) == 0
    assert "keeping the camera poses" in capsys.readouterr().out
    written = load_calibration(out.with_suffix(".calib.yaml"))
    truth = load_calibration(known)
    assert written.flagged == {}
    assert written.cameras["k02"].rotation == pytest.approx(truth.cameras["k02"].rotation)
    stamps = {c: np.array([g.stamp for g in gs]) for c, gs in scene.camera_groups.items()}
    assert compare_calibration(written, truth, stamps)["k02"].time_error_ms < 10.0
    assert main([*args, "--calibration", str(known), "--force"]) == 1
    assert "--poses-from goes with --calibration auto" in capsys.readouterr().err
