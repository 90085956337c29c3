from dataclasses import replace

import numpy as np
import pytest

from hiros_core.errors import RecordingError
from hiros_core.layouts import AZURE_KINECT
from hiros_eval.body import limb_length_cv
from hiros_sim import SimParams
from hiros_sim.fit import (
    DEFAULT_CSV,
    fit_noise,
    read_kinect_csv,
    simulated_errors,
    skeleton_errors,
    take_scene,
)

THUMBS = np.array([10, 17])
FEET = [AZURE_KINECT.index("FootLeft"), AZURE_KINECT.index("FootRight")]


@pytest.mark.slow
def test_noise_fit_is_finite_and_plausible():
    fit = fit_noise()
    a = fit.alignment
    assert abs(a.shift) < 1.0  # the two files start within a second of each other
    assert 0.02 < a.rms < 0.1  # Azure Kinect vs inertial mocap: centimetres
    assert 0.1 < np.mean(a.flipped) < 0.6  # the take has front/back flips
    assert 0.0 < fit.noise_base < 0.05
    assert np.isfinite(fit.noise_per_metre)
    assert abs(fit.noise_per_metre) < 0.03
    assert np.all((fit.noise_std > 0.003) & (fit.noise_std < 0.08))
    assert 0.5 < fit.depth_axis_gain < 3.0
    assert 0.03 < fit.correlation_time < 2.0
    assert fit.frame_interval == pytest.approx(1 / 30, rel=0.02)
    assert 0.0 <= fit.drop_rate < 0.05
    names = [name for name, _ in fit.figures()]
    assert "noise_base (x, y)" in names
    # the SDK's skeleton is one rigid model per frame: limbs vary with one body scale
    skeleton = fit.skeleton
    assert skeleton.body_limb_cv == pytest.approx(0.035, abs=0.005)
    assert skeleton.scale_cv == pytest.approx(skeleton.body_limb_cv, rel=0.05)
    assert np.nanmedian(skeleton.unscaled_limb_cv) < 0.001
    assert np.all((skeleton.parent_correlation > 0.4) & (skeleton.parent_correlation < 0.9))
    assert 0.1 < skeleton.scale_correlation_time < 0.4
    # the resting foot is the SDK's quietest joint vertically: 1.24 cm against the pelvis's 2.3
    foot, pelvis = skeleton.vertical_scatter
    assert 0.008 < foot < 0.016
    assert foot < 0.7 * pelvis


def test_kinect_csv_reader():
    stamps, positions = read_kinect_csv(DEFAULT_CSV)
    assert positions.shape == (357, 32, 3)
    assert np.isnan(positions[:, 0, 0]).sum() == 2  # two frames without a body
    assert 1.6e9 < stamps[0] < 1.7e9  # Unix seconds
    depth = positions[:, 0, 2]
    assert 2.5 < np.nanmedian(depth) < 4.0  # metres in front of the camera


def test_kinect_csv_errors(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,foo\n1,2\n")
    with pytest.raises(RecordingError, match="cannot read Kinect CSV"):
        read_kinect_csv(bad)


@pytest.fixture(scope="module")
def real_limb_cv():
    """``(32,)`` limb-length CV of the real Azure Kinect stream (by link id; NaN root)."""
    _, positions = read_kinect_csv(DEFAULT_CSV)
    return limb_length_cv(positions[np.isfinite(positions[:, 0, 0])])


def test_real_sdk_limbs_vary_together(real_limb_cv):
    """The figure the noise model reproduces: one whole-body scale, thumbs apart."""
    body = np.delete(real_limb_cv[1:], THUMBS - 1)
    assert np.all((body > 0.03) & (body < 0.04))
    assert np.ptp(body) < 0.002  # the same CV on every limb
    assert np.all(real_limb_cv[THUMBS] > 0.05)


def test_simulated_limb_cv_matches_the_real_sdk(real_limb_cv):
    """Noise on, occlusion off (hidden joints as noisy as seen ones), SDK mistakes off."""
    params = SimParams(n_cameras=2, n_people=2, duration=20.0, seed=1, occluded_gain=1.0)
    sim = simulated_errors(params)
    ratio = sim.limb_cv[1:] / real_limb_cv[1:]
    assert np.all((ratio > 1 / 1.5) & (ratio < 1.5)), np.round(ratio, 2)
    assert sim.scale_cv == pytest.approx(0.035, rel=0.3)
    assert np.nanmedian(sim.unscaled_limb_cv) < 0.01  # limbs keep their ratios, as the SDK's
    # per-joint errors: the fitted size (sigma about 12 mm + 4 mm/m x depth, x 1.2 along z,
    # from the front, more from the side) and correlated with the parent's like the take's
    assert np.all((sim.noise_std > 0.015) & (sim.noise_std < 0.06))
    assert np.all((sim.parent_correlation > 0.4) & (sim.parent_correlation < 0.85))


def test_independent_residual_breaks_the_limb_ratios():
    params = SimParams(n_cameras=1, n_people=1, duration=10.0, noise_residual=0.01)
    assert np.nanmedian(simulated_errors(params).unscaled_limb_cv) > 0.02
    rigid = simulated_errors(SimParams(n_cameras=1, n_people=1, duration=10.0))
    # planted legs bent to their feet too (hiros_sim.noise.plant_legs)
    assert np.nanmedian(rigid.unscaled_limb_cv) < 0.005


def test_skeleton_errors_of_a_rigid_scaled_stream():
    rng = np.random.default_rng(0)
    pose = rng.normal(0.0, 0.3, (32, 3))  # fixed limb lengths, moving about
    reference = pose + np.cumsum(rng.normal(0.0, 0.01, (300, 1, 3)), axis=0)
    pelvis = reference[:, :1]
    scale = 1.0 + 0.05 * rng.standard_normal(300)
    shift = rng.normal(0.0, 0.05, (300, 1, 3))  # the whole body moves together
    observed = pelvis + scale[:, None, None] * (reference - pelvis) + shift
    follows = np.ones(300, bool)
    errors = skeleton_errors([(observed, reference, follows)], 1 / 30)
    assert errors.scale_cv == pytest.approx(0.05, rel=0.15)
    np.testing.assert_allclose(errors.unscaled_limb_cv[1:], 0.0, atol=1e-3)
    assert errors.scale_correlation_time < 1 / 30  # white scale noise
    assert np.all(errors.parent_correlation > 0.5)
    # independent joint noise: no correlation, and limbs vary apart from any scale
    independent = reference + rng.normal(0.0, 0.05, reference.shape)
    errors = skeleton_errors([(independent, reference, follows)], 1 / 30)
    assert np.all(np.abs(errors.parent_correlation) < 0.1)
    assert np.nanmedian(errors.unscaled_limb_cv) > 0.05


def test_vertical_scatter_of_resting_feet_and_pelvis():
    """Robust SD along the given vertical: the feet only where the reference foot rests."""
    rng = np.random.default_rng(5)
    frames = 600
    reference = np.tile(rng.normal(0.0, 0.3, (1, 32, 3)), (frames, 1, 1))
    walking = np.arange(frames) >= 300  # the feet move at 0.6 m/s over the second half
    for foot in FEET:
        reference[:, foot, 0] += np.where(walking, 0.02 * np.arange(frames), 0.0)
    up = np.array([0.0, -1.0, 0.0])  # a camera's y axis points down
    observed = reference + rng.normal(0.0, 0.001, reference.shape)
    observed[:, FEET, 1] += np.where(walking, 0.1, 0.01)[:, None] * rng.standard_normal((frames, 2))
    observed[:, 0, 1] += 0.03 * rng.standard_normal(frames)
    errors = skeleton_errors([(observed, reference, np.ones(frames, bool))], 1 / 30, [up])
    foot, pelvis = errors.vertical_scatter
    assert foot == pytest.approx(0.01, rel=0.15)  # the noisy walking frames are left out
    assert pelvis == pytest.approx(0.03, rel=0.15)
    # without a vertical the figure is not measured
    assert np.isnan(
        skeleton_errors([(observed, reference, np.ones(frames, bool))], 1 / 30).vertical_scatter
    ).all()


def test_simulated_planted_feet_are_quiet_like_the_real_take():
    """On the take's scene the simulated resting foot scatters vertically as the real one does
    (1.24 cm, ``test_noise_fit_is_finite_and_plausible``): well below the pelvis."""
    take = take_scene(duration=30.0, seed=2)
    foot, pelvis = simulated_errors(take, facing_only=True).vertical_scatter
    assert 0.009 < foot < 0.017
    assert foot < 0.5 * pelvis
    # the planted foot's evidence as noisy as the rest of the body: the foot is not quiet
    noisy_foot, _ = simulated_errors(
        replace(take, planted_gain=1.0), facing_only=True
    ).vertical_scatter
    assert noisy_foot > 0.025
