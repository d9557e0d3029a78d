"""The paper's analyses on tiny problems against brute force (explicit A, numpy.linalg.cond)."""
import json

import numpy as np
import pytest

from clsdcam import analysis, sim
from clsdcam.backends.numpy import NumpyBackend
from clsdcam.cli import main
from clsdcam.model import ForwardModel

SHAPE = (9, 12)
RNG = np.random.default_rng(0)


def dense_columns(psf, filters, voxels):
    """Columns of A by applying the forward model to unit voxels on the sensor window (brute force)."""
    model = ForwardModel(NumpyBackend("float64"), psf, filters)
    out = []
    for k, y, x in voxels:
        cube = np.zeros(filters.shape)
        cube[k, y, x] = 1.0
        out.append(model.forward(model.embed(cube)).ravel())
    return np.stack(out, axis=1)


def test_autocorrelation_resolution_of_a_gaussian_psf():
    """A Gaussian of σ has a Gaussian autocorrelation of σ√2: half-width at 70 % = 2σ·√ln(1/0.7)."""
    y, x = np.mgrid[:96, :96]
    sigma = 2.5
    psf = np.exp(-((y - 48) ** 2 + (x - 48) ** 2) / (2 * sigma ** 2))
    result = analysis.autocorrelation_resolution(psf)
    assert result.pixels == pytest.approx(2 * sigma * np.sqrt(np.log(1 / 0.7)), rel=0.02)
    assert result.superpixels == pytest.approx(result.pixels / 16)


def test_columns_equal_the_forward_model_applied_to_unit_voxels():
    psf, filters = RNG.random(SHAPE), RNG.random((3,) + SHAPE)
    voxels = [(0, 0, 0), (1, 4, 6), (2, 8, 11), (1, 2, 9)]
    np.testing.assert_allclose(analysis.columns(psf, filters, voxels), dense_columns(psf, filters, voxels),
                               rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("spectral", [False, True])
def test_group_condition_matches_numpy_cond_of_the_explicit_submatrix(spectral):
    psf, filters = RNG.random(SHAPE), RNG.random((3,) + SHAPE)
    bands = (1, 2) if spectral else (1,)
    voxels = [(k, y, x) for k in bands for y, x in analysis.grid_points(4, 3, (2, 3))]
    expected = np.linalg.cond(dense_columns(psf, filters, voxels))
    assert analysis.group_condition(psf, filters, 4, 3, 1, (2, 3), spectral) == pytest.approx(expected, rel=1e-8)


def test_lens_comparators_light_one_filter_pixel_or_one_superpixel():
    high, low = sim.lens_psf((64, 80), 2), sim.lens_psf((64, 80), 16)
    assert np.count_nonzero(high) == 4 and np.count_nonzero(low) == 256
    ys, xs = np.nonzero(high)
    assert set(ys) == {32, 33} and set(xs) == {40, 41}
    assert np.linalg.norm(high) == pytest.approx(1) and np.linalg.norm(low) == pytest.approx(1)
    assert set(sim.DESIGNS) == {"diffuser", "low-NA lens", "high-NA lens"}


def test_separation_below_needs_every_larger_separation_below_the_limit():
    assert analysis.separation_below([1, 2, 3, 4], [100, 30, 50, 20]) == 4
    assert analysis.separation_below([1, 2, 3], [10, 20, 30]) == 1
    assert analysis.separation_below([1, 2], [100, np.inf]) is None


def test_diffuser_is_better_conditioned_than_a_low_na_lens():
    shape = (64, 80)
    filters = sim.filter_array(shape, sim.band_wavelengths(16), 0)
    seps = (1, 2, 3)
    diffuser = analysis.condition_sweep(sim.caustic_psf(shape, 0), filters, seps, trials=5)
    lens = analysis.condition_sweep(sim.lens_psf(shape, 16), filters, seps, trials=5)
    assert np.all(diffuser < lens)


def test_analyze_all_through_the_command_line(tmp_path, capsys):
    out = tmp_path / "an"
    assert main(["analyze", "all", str(out), "--size", "48x64", "--recon-size", "24x32", "--bands", "8",
                 "--iters", "10"]) == 0
    table = capsys.readouterr().out
    assert "| autocorrelation resolution, simulated PSF |" in table and "within 5 nm" in table
    for name in analysis_names():
        assert (out / f"{name}.png").stat().st_size > 0
        json.loads((out / f"{name}.json").read_text())
    assert "<table" in (out / "report.html").read_text()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def analysis_names():
    from clsdcam.cli_analyze import ANALYSES

    return ANALYSES
