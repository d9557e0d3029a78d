"""Accuracy figures against a truth, by hand."""
import numpy as np
from scipy.ndimage import uniform_filter

from clsdcam.metrics import accuracy, peak_ratio, psnr, spectral_angle


def sources(shape=(3, 8, 8)) -> np.ndarray:
    """Two bright point sources (peaks 4 and 3) and a dim one (1) on a dark ground."""
    truth = np.zeros(shape)
    truth[1, 2, 2], truth[0, 5, 5], truth[2, 6, 1] = 4.0, 3.0, 1.0
    return truth


def test_peak_ratio_is_the_mean_recovered_share_of_the_brightest_points():
    """Brightest points: peak ≥ half the largest (4 and 3, not 1); each keeps its share of its own peak."""
    truth = sources()
    cube = 0.5 * truth
    cube[1, 2, 2] = 1.0                               # a quarter of the first source's peak
    assert peak_ratio(cube, truth) == (1.0 / 4.0 + 1.5 / 3.0) / 2
    assert peak_ratio(truth, truth) == 1.0 and np.isnan(peak_ratio(truth, np.zeros_like(truth)))


def test_a_point_spread_over_its_neighbours_has_a_high_psnr_and_a_low_peak_ratio():
    """A sparse scene's blind spot: each source spread evenly over its 3 × 3 neighbourhood."""
    truth = sources((3, 64, 64))
    spread = uniform_filter(truth, size=(1, 3, 3), mode="constant")
    assert psnr(spread, truth) > 30 and abs(peak_ratio(spread, truth) - 1 / 9) < 1e-12


def test_accuracy_gathers_the_three_figures_and_a_failed_frame_has_none():
    truth, cube = sources(), 0.9 * sources()
    assert accuracy(cube, truth) == {"psnr": psnr(cube, truth), "spectral_angle": spectral_angle(cube, truth),
                                     "peak_ratio": peak_ratio(cube, truth)}
    assert all(np.isnan(v) for v in accuracy(np.full_like(truth, np.nan), truth).values())
