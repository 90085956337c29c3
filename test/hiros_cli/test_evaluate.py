"""``hiros evaluate``'s tables keep every word whole in a narrow terminal."""

from __future__ import annotations

import numpy as np
from rich.console import Console
from scipy.spatial.transform import Rotation

from hiros_cli.commands.evaluate import _table

HEADERS = ["stage", "MPJPE cm", "limb CV %", "angle RMSE deg", "IDF1", "ID switches", "fragments"]
ROWS = [["optimizer", "9.13", "1.71", "15.67", "1.000", "0", "0"]]


def _printed(width: int) -> str:
    console = Console(width=width, record=True)
    console.print(_table("stages", HEADERS, ROWS, console.width))
    return console.export_text()


def test_a_table_too_wide_wraps_its_headers_between_words() -> None:
    narrow = _printed(72)
    assert "…" not in narrow
    assert all(word in narrow for word in ("optimizer", "fragments", "switches", "15.67"))
    assert max(len(line) for line in narrow.splitlines()) <= 72


def test_a_table_that_fits_keeps_its_headers_on_one_line() -> None:
    wide = _printed(120)
    assert "angle RMSE deg" in wide
    assert "ID switches" in wide


def _camera(translation, rotation, offset=0.0):
    from hiros_core.calibration import CameraCalibration

    return CameraCalibration(
        frame_id=f"f{translation[0]}", time_offset=offset,
        translation=np.asarray(translation, float), rotation=rotation.as_quat(),
    )  # fmt: skip


def test_a_calibration_file_is_judged_alone_relative_to_its_reference(tmp_path, capsys) -> None:
    """The truth lives in the simulator's world; the estimate in its reference camera's frame,
    with cam1 turned 1°, moved 2 cm and 5 ms late there."""
    from hiros_cli.main import main
    from hiros_core.calibration import Calibration, save_calibration

    base = Rotation.from_euler("z", 30, degrees=True)
    truth = Calibration(reference="cam0", world_frame="world")
    truth.cameras = {
        "cam0": _camera([1.0, 2.0, 1.5], base),
        "cam1": _camera([4.0, 2.0, 1.5], base * Rotation.from_euler("y", 90, degrees=True), 0.3),
    }
    relative = truth.cameras["cam0"].extrinsics.inverse() @ truth.cameras["cam1"].extrinsics
    estimate = Calibration(reference="cam0", world_frame="world")
    estimate.cameras = {
        "cam0": _camera([0.0, 0.0, 0.0], Rotation.identity()),
        "cam1": _camera(
            relative.translation + np.array([0.02, 0.0, 0.0]),
            Rotation.from_euler("x", 1, degrees=True) * relative.rotation,
            0.305,
        ),
    }
    (tmp_path / "truth").mkdir()
    save_calibration(truth, tmp_path / "truth" / "calibration.yaml")
    save_calibration(estimate, tmp_path / "estimate.yaml")
    args = ["evaluate", str(tmp_path / "estimate.yaml"), "--truth", str(tmp_path / "truth")]
    assert main(args) == 0
    row = next(line for line in capsys.readouterr().out.splitlines() if "cam1" in line)
    assert [cell.strip() for cell in row.strip("│ ").split("│")] == [
        "cam1", "5.00", "5.00", "1.000", "2.00",
    ]  # fmt: skip
    assert main([*args, "--report", str(tmp_path / "report")]) == 1
    assert "--report needs a run's output" in capsys.readouterr().err


def test_a_calibration_file_in_a_floor_world_gets_its_up_and_floor_judged(tmp_path, capsys):
    """The estimate's world is tilted 2° about x and its floor 3 cm below the truth's."""
    from hiros_cli.main import main
    from hiros_core.calibration import Calibration, save_calibration
    from hiros_core.geometry import RigidTransform

    truth = Calibration(reference="cam0", world_frame="world")
    truth.cameras = {"cam0": _camera([0.0, 0.0, 1.5], Rotation.identity())}
    tilt = RigidTransform(Rotation.from_euler("x", 2.0, degrees=True), np.zeros(3))
    placed = tilt @ RigidTransform(Rotation.identity(), np.array([0.0, 0.0, 1.53]))
    estimate = Calibration(reference="cam0", world_frame="world")
    estimate.cameras = {"cam0": _camera(placed.translation, placed.rotation)}
    estimate.cameras["cam0"].quality = {"floor_up_from": "feet and torsos", "floor_doubtful": ""}
    (tmp_path / "truth").mkdir()
    save_calibration(truth, tmp_path / "truth" / "calibration.yaml")
    save_calibration(estimate, tmp_path / "estimate.yaml")
    # one person whose pelvis stands above the origin
    positions = np.zeros((1, 2, 32, 3))
    positions[..., 2] = 1.0
    np.savez_compressed(
        tmp_path / "truth" / "truth.npz", times=np.array([0.0, 1.0]), positions=positions,
        person_ids=np.array([1]), clip_names=np.array(["clip"]),
    )  # fmt: skip
    args = ["evaluate", str(tmp_path / "estimate.yaml"), "--truth", str(tmp_path / "truth")]
    assert main(args) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert (
        "world: z 2.00 deg from the truth's up; below the people the true floor is at z = +3.0"
        in out
    )
    assert "does not call its floor doubtful" in out
