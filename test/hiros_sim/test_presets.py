"""The simulator's robustness conditions: each knob does what it says, each preset runs."""

from dataclasses import fields

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hiros_cli.main import main
from hiros_core.errors import ConfigError
from hiros_core.layouts import AZURE_KINECT
from hiros_core.recording import iter_logged_groups
from hiros_sim import PRESETS, SimParams, load_truth, preset_params, simulate, write_recording
from hiros_sim.shared import BANDAI_FOLDER, shared_data_dir
from hiros_sim.simulate import _people, _truth

IDX = AZURE_KINECT.index
BANDAI = shared_data_dir() / BANDAI_FOLDER
needs_bandai = pytest.mark.skipif(not BANDAI.is_dir(), reason=f"needs {BANDAI}")
QUIET = {"flip_rate": 0.0, "flip_probability": 0.0, "swap_rate": 0.0, "ghost_rate": 0.0}
"""No SDK mistakes: the joint errors are the noise model's alone."""


def _stamps(groups) -> np.ndarray:
    return np.array([g.stamp_ns for g in groups], dtype=np.int64)


def _truth_only(params: SimParams):
    """The people and truth of ``params`` without the cameras (as ``simulate`` makes them)."""
    people = _people(params, np.random.default_rng(np.random.SeedSequence(params.seed).spawn(2)[0]))
    return people, _truth(params, people)


def _joint_errors(result, camera: str) -> np.ndarray:
    """``(N, 32, 3)`` reported minus true joints of person 0 in ``camera``'s frame."""
    cam = result.calibration.camera(camera)
    to_camera = cam.extrinsics.inverse()
    errors = []
    for group, labels in zip(result.camera_groups[camera], result.labels[camera], strict=True):
        for skeleton, person in zip(group.skeletons, labels, strict=True):
            if person == 0:
                t_ref = cam.to_reference_time(group.stamp_ns * 1e-9)
                truth = result.truth.at(np.array([t_ref]))[0, 0]
                errors.append(skeleton.positions - to_camera.apply(truth))
    return np.array(errors)


@pytest.mark.parametrize("name", list(PRESETS))
def test_every_preset_runs_and_sets_only_its_knobs(name):
    if PRESETS[name].needs_shared_data and not BANDAI.is_dir():
        pytest.skip(f"needs {BANDAI}")
    params = preset_params(name, duration=4.0, seed=2)
    default = SimParams(duration=4.0, seed=2)
    changed = {
        f.name for f in fields(SimParams) if getattr(params, f.name) != getattr(default, f.name)
    }
    assert changed == set(PRESETS[name].overrides) - {
        k for k, v in PRESETS[name].overrides.items() if getattr(default, k) == v
    }
    result = simulate(params)
    assert result.truth.positions.shape[0] == params.n_people
    assert all(len(groups) > 0 for groups in result.camera_groups.values())


def test_preset_errors(monkeypatch, tmp_path):
    with pytest.raises(ConfigError, match="unknown simulator preset 'nope'; the presets are"):
        preset_params("nope")
    with pytest.raises(ConfigError, match="no field warp"):
        preset_params("default", warp=9)
    monkeypatch.setenv("HIROS_SHARED_DATA", str(tmp_path))
    with pytest.raises(ConfigError, match=f"in {tmp_path / BANDAI_FOLDER}: set HIROS_SHARED_DATA"):
        preset_params("all")
    with pytest.raises(ConfigError, match="HIROS_SHARED_DATA"):
        simulate(SimParams(motion="bandai", duration=4.0))
    assert preset_params("one-person", seed=4).seed == 4  # the rest needs no shared data
    assert {n for n, p in PRESETS.items() if p.needs_shared_data} == {"repeated-motion", "all"}


def test_log_clock_camera_logs_each_camera_on_its_own_host(tmp_path):
    params = preset_params("host-clocks", duration=6.0, seed=5, n_cameras=3)
    result = simulate(params)
    steps = {}
    for name, groups in result.camera_groups.items():
        delay = (result.receive_ns[name] - _stamps(groups)) * 1e-9
        assert delay.min() >= 0.02
        assert delay.max() <= 0.03 + 6 * params.host_jitter
        assert np.std(delay) < 2 * params.host_jitter  # constant per camera, within jitter
        steps[name] = np.median(delay)
    assert len({round(s, 4) for s in steps.values()}) == 3  # each host its own latency
    # the written recording's log times are those, per camera
    write_recording(result, tmp_path)
    logged = {}
    for camera, group, log_time in iter_logged_groups(tmp_path / "recording.mcap"):
        logged.setdefault(camera, []).append(log_time - group.stamp_ns)
    for name, delays in logged.items():
        assert np.median(delays) * 1e-9 == pytest.approx(steps[name], abs=params.host_jitter)
    # the truth is that of the receiver-clock recording
    receiver = simulate(SimParams(duration=6.0, seed=5, n_cameras=3))
    np.testing.assert_array_equal(result.truth.positions, receiver.truth.positions)
    for name, cam in receiver.calibration.cameras.items():
        assert result.calibration.cameras[name].time_offset == cam.time_offset
        np.testing.assert_array_equal(
            _stamps(result.camera_groups[name]), _stamps(receiver.camera_groups[name])
        )


def test_log_clock_receiver_logs_on_the_reference_clock():
    result = simulate(SimParams(duration=6.0, seed=5, n_cameras=3))
    offsets = []
    for name, groups in result.camera_groups.items():
        cam = result.calibration.camera(name)
        arrival = cam.to_reference_time(_stamps(groups) * 1e-9) + result.params.latency
        np.testing.assert_allclose(result.receive_ns[name] * 1e-9, arrival, atol=1e-6)
        offsets.append(np.median(result.receive_ns[name] - _stamps(groups)) * 1e-9)
    assert np.ptp(offsets) > 0.1  # log minus stamp follows the camera's clock offset


def test_noisy_sdk_errs_more_most_on_hands_feet_and_face():
    base = {"duration": 40.0, "seed": 1, "n_people": 1, "n_cameras": 1, **QUIET}
    default = _joint_errors(simulate(SimParams(**base)), "k01")
    noisy = _joint_errors(simulate(preset_params("noisy-sdk", **base)), "k01")
    rms = {
        k: np.sqrt(np.nanmean(np.sum(e**2, axis=-1), axis=0))
        for k, e in (("d", default), ("n", noisy))
    }
    assert np.median(rms["n"] / rms["d"]) > 1.5
    hands = [IDX(n) for n in ("HandLeft", "HandTipRight", "FootLeft", "Nose")]
    body = [IDX(n) for n in ("SpineChest", "Neck", "ShoulderLeft")]
    assert (
        rms["n"][hands].mean() / rms["n"][body].mean()
        > 1.3 * rms["d"][hands].mean() / rms["d"][body].mean()
    )


def test_drifting_bias_changes_over_seconds():
    """Joint noise off: a fixed bias gives each joint a steady error, a drifting one does not."""
    bias_only = {"noise_base": 0.0, "noise_per_metre": 0.0, "body_scale_cv": 0.0}
    base = {"duration": 40.0, "seed": 1, "n_people": 1, "n_cameras": 1, **QUIET, **bias_only}

    def drift(bias_drift_time: float) -> float:
        """Median spread of each joint's 5-second mean error over the recording, metres."""
        errors = _joint_errors(simulate(SimParams(bias_drift_time=bias_drift_time, **base)), "k01")
        means = np.stack([np.nanmean(w, axis=0) for w in np.array_split(errors, 8)])
        return float(np.median(np.nanstd(means, axis=0)))

    assert drift(3.0) > 2.0 * drift(0.0)
    assert preset_params("noisy-sdk").bias_drift_time == 3.0


def test_15hz_and_5_percent_drops():
    result = simulate(preset_params("15hz", duration=10.0, seed=2))
    for groups in result.camera_groups.values():
        assert np.median(np.diff(_stamps(groups))) * 1e-9 == pytest.approx(1 / 15, rel=0.01)
    result = simulate(preset_params("drops-5", duration=40.0, seed=2))
    published = missing = 0
    for groups in result.camera_groups.values():
        gaps = np.round(np.diff(_stamps(groups)) * 1e-9 * result.params.rate)
        missing += int(np.sum(gaps - 1))
        published += len(groups)
    assert missing / (missing + published) == pytest.approx(0.05, abs=0.012)


@pytest.mark.parametrize("seed", range(6))
def test_two_cameras_45_geometry(seed):
    calibration = simulate(preset_params("two-cameras-45", duration=4.0, seed=seed)).calibration
    first, second = calibration.cameras["k01"], calibration.cameras["k02"]
    relative = Rotation.from_quat(first.rotation).inv() * Rotation.from_quat(second.rotation)
    assert 40.0 <= np.degrees(relative.magnitude()) <= 50.0
    assert 1.3 <= np.linalg.norm(first.translation - second.translation) <= 1.5
    # both face the scene: the room centre is in front of each
    for cam in (first, second):
        forward = Rotation.from_quat(cam.rotation).as_matrix()[:, 2]
        assert forward @ (np.array([0.0, 0.0, 1.0]) - cam.translation) > 0.0


def test_crossing_4_people_pass_within_half_a_metre():
    _, truth = _truth_only(preset_params("crossing-4", duration=30.0, seed=0))
    pelvis = truth.positions[:, :, IDX("Pelvis"), :2]
    closest = [
        np.min(np.linalg.norm(pelvis[a] - pelvis[b], axis=-1))
        for a in range(4)
        for b in range(a + 1, 4)
    ]
    assert sum(c < 0.5 for c in closest) >= 3  # neighbours in lanes pass each other closely
    assert min(closest) > 0.25  # and do not walk through each other


def test_one_person():
    result = simulate(preset_params("one-person", duration=4.0))
    assert result.truth.positions.shape[0] == 1
    assert max(len(g.skeletons) for gs in result.camera_groups.values() for g in gs) <= 2  # ghosts


@needs_bandai
def test_repeated_motion_is_periodic_with_variation():
    params = preset_params("repeated-motion", n_people=1, duration=40.0, seed=0)
    people, truth = _truth_only(params)
    clip = people[0].clip
    assert clip.name.startswith("dataset-2_wave-both-hands")
    wrist = truth.positions[0, :, IDX("WristRight"), 2]
    wrist = wrist - wrist.mean()
    correlation = np.correlate(wrist, wrist, "full")[wrist.size - 1 :] / np.dot(wrist, wrist)
    lags = np.arange(correlation.size) / truth.rate
    search = (lags > 0.5 * clip.duration) & (lags < 1.5 * clip.duration)
    peak = lags[search][np.argmax(correlation[search])]
    assert peak == pytest.approx(clip.duration, rel=0.1)
    assert correlation[search].max() > 0.4
    # each repetition differs: the same phase of two repetitions is not the same pose
    exact = _truth_only(
        preset_params("repeated-motion", n_people=1, duration=40.0, loop_variation=0.0)
    )[1]
    assert np.nanmax(np.abs(truth.positions - exact.positions)) > 0.05
    # the person's limbs keep their length through the variation and the seams
    parents = np.asarray(AZURE_KINECT.parents[1:])

    def limbs(positions: np.ndarray) -> np.ndarray:
        return np.linalg.norm(positions[:, 1:] - positions[:, parents], axis=-1).mean(axis=0)

    np.testing.assert_allclose(limbs(truth.positions[0]), limbs(clip.positions), rtol=0.01)


@needs_bandai
def test_repeated_motion_blends_the_seams():
    """No jump where a clip's end meets its start: no joint moves faster than in the clip."""

    def fastest(blend: float) -> float:
        people, truth = _truth_only(
            preset_params("repeated-motion", n_people=1, duration=30.0, seed=3, loop_blend=blend)
        )
        clip = people[0].clip
        assert clip.name.endswith("exhausted_001")  # its end pose is 25 cm from its start
        own = np.linalg.norm(np.diff(clip.positions, axis=0), axis=-1).max() * clip.rate
        return np.linalg.norm(np.diff(truth.positions[0], axis=0), axis=-1).max() * truth.rate / own

    assert fastest(0.5) < 1.25  # the speed variation allows 10 %
    assert fastest(0.0) > 1.5  # cut without a blend


@needs_bandai
def test_all_combines_the_conditions(tmp_path):
    assert (
        main(
            [
                "simulate",
                "--preset",
                "all",
                "--duration",
                "6",
                "--seed",
                "1",
                "--out",
                str(tmp_path / "sim"),
            ]
        )
        == 0
    )
    truth = load_truth(tmp_path / "sim")
    assert truth.positions.shape[0] == 1
    assert truth.clip_names[0].startswith("dataset-2_")
    params = preset_params("all")
    assert (params.rate, params.drop_rate, params.log_clock, params.setup) == (
        15.0,
        0.05,
        "camera",
        "pair",
    )
    assert params.bias_drift_time > 0.0


def test_command_line_preset_under_the_options_given():
    import argparse

    from hiros_cli.commands.simulate import _params, add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert all(name in parser.format_help() for name in PRESETS)
    params = _params(parser.parse_args(["--out", "x", "--preset", "drops-5"]))
    assert (params.drop_rate, params.n_cameras, params.rate) == (0.05, 3, 30.0)
    args = ["--out", "x", "--preset", "drops-5", "--rate", "5", "--set", "drop_rate=0.1"]
    params = _params(parser.parse_args(args))
    assert (params.drop_rate, params.rate) == (0.1, 5.0)
    with pytest.raises(ConfigError, match="--sample or --preset"):
        _params(parser.parse_args(["--out", "x", "--preset", "15hz", "--sample"]))
    with pytest.raises(SystemExit):
        parser.parse_args(["--out", "x", "--preset", "warp-9"])
