import numpy as np
import pytest

from hiros_core.errors import RecordingError
from hiros_sim.fit import DEFAULT_CSV, fit_noise, read_kinect_csv


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
