"""The camera simulator: caustic PSF, filter array, scenes, noise, and the forward model against brute force."""
import h5py
import numpy as np
import pytest
from scipy.signal import fftconvolve

from clsdcam import sim
from clsdcam.errors import InputError
from clsdcam.sim import filters as filter_module
from clsdcam.sim import scenes

SMALL = (48, 64)
BANDS8 = sim.band_wavelengths(8)
RANDOM_SCENES = ("leds", "piecewise", "points")
SYNTHETIC_SCENES = ("target",) + RANDOM_SCENES


# ---- wavelengths ------------------------------------------------------------------------

def test_band_wavelengths_are_bin_centres_over_the_range():
    wavelengths = sim.band_wavelengths()
    assert wavelengths.shape == (64,) and wavelengths.dtype == np.float64
    np.testing.assert_allclose(np.diff(wavelengths), 8.0)
    assert wavelengths[0] == pytest.approx(390.0) and wavelengths[-1] == pytest.approx(894.0)
    assert sim.band_wavelengths(1)[0] == pytest.approx(642.0)


def test_band_average_keeps_a_narrow_lines_energy_at_any_band_count():
    """8 bins of 64 nm: a 15 nm line at a bin centre puts ∫line/64 in it; one on an edge splits it in two."""
    energy = 15.0 / 2 * np.sqrt(np.pi / np.log(2))  # ∫ exp(−4 ln2 λ²/w²) dλ
    centred = sim.band_average(sim.gaussian_line(610.0, 15.0), BANDS8)
    on_edge = sim.band_average(sim.gaussian_line(642.0, 15.0), BANDS8)
    assert centred.max() == pytest.approx(energy / 64.0, rel=1e-3)
    assert BANDS8[np.argmax(centred)] == pytest.approx(610.0)
    np.testing.assert_allclose(on_edge[[3, 4]], energy / 128.0, rtol=1e-3)


# ---- the PSF ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def moderate_psfs():
    return {seed: sim.caustic_psf((128, 160), seed=seed) for seed in (0, 1, 2)}


def test_psf_is_nonnegative_unit_norm_float32(moderate_psfs):
    for psf in moderate_psfs.values():
        assert psf.shape == (128, 160) and psf.dtype == np.float32
        assert psf.min() >= 0.0
        assert np.linalg.norm(psf.astype(np.float64)) == pytest.approx(1.0, abs=1e-5)


def test_psf_is_deterministic_per_seed_and_differs_between_seeds(moderate_psfs):
    np.testing.assert_array_equal(sim.caustic_psf((128, 160), seed=1), moderate_psfs[1])
    correlation = np.corrcoef(moderate_psfs[0].ravel(), moderate_psfs[1].ravel())[0, 1]
    assert correlation < 0.5


def test_psf_caustic_fills_the_central_part_of_the_frame(moderate_psfs):
    """96 % of the light lands in the central 60–85 % of each axis, and lines cover much of that."""
    for psf in moderate_psfs.values():
        for axis in (0, 1):
            cumulative = np.cumsum(psf.sum(axis=1 - axis)) / psf.sum()
            first, last = np.searchsorted(cumulative, [0.02, 0.98])
            assert 0.6 <= (last - first) / psf.shape[axis] <= 0.85
        assert (psf > 0.05 * psf.max()).mean() > 0.1  # a network of lines, not a few spots


def test_autocorrelation_halfwidth_of_a_gaussian():
    """A Gaussian of σ has a Gaussian autocorrelation of σ√2, at 70 % when r = σ√2·√(2 ln(1/0.7))."""
    sigma = 2.5
    y, x = np.mgrid[0:64, 0:80]
    psf = np.exp(-((y - 32) ** 2 + (x - 40) ** 2) / (2 * sigma ** 2))
    expected = sigma * np.sqrt(2) * np.sqrt(2 * np.log(1 / 0.7))
    assert sim.autocorrelation_halfwidth(psf) == pytest.approx(expected, rel=0.01)


def test_autocorrelation_halfwidth_is_about_three_pixels(moderate_psfs):
    for psf in moderate_psfs.values():
        assert 2.0 <= sim.autocorrelation_halfwidth(psf) <= 4.5


def test_default_size_psf_halfwidth_is_in_the_papers_range():
    assert 2.0 <= sim.autocorrelation_halfwidth(sim.caustic_psf()) <= 4.0


# ---- filters ----------------------------------------------------------------------------

def fwhm_of_main_lobe(grid: np.ndarray, curve: np.ndarray) -> float:
    """Width of the contiguous region above half the maximum around the argmax, edges interpolated."""
    half = curve.max() / 2
    peak = int(np.argmax(curve))
    left = peak - np.flatnonzero(curve[peak::-1] < half)[0]
    right = peak + np.flatnonzero(curve[peak:] < half)[0]
    left_edge = np.interp(half, [curve[left], curve[left + 1]], [grid[left], grid[left + 1]])
    right_edge = np.interp(half, [curve[right], curve[right - 1]], [grid[right], grid[right - 1]])
    return right_edge - left_edge


def test_filter_fwhm_grows_from_6_nm_blue_to_23_nm_nir():
    grid = np.arange(340.0, 950.0, 0.05)
    transmissions = filter_module.filter_transmissions(grid)
    fwhm = np.array([fwhm_of_main_lobe(grid, t) for t in transmissions])
    assert fwhm[0] == pytest.approx(6.0, abs=0.5)
    assert fwhm[-1] == pytest.approx(23.0, abs=1.0)
    assert np.all((fwhm > 5.5) & (fwhm < 24.0))
    assert np.corrcoef(fwhm, sim.band_wavelengths(64))[0, 1] > 0.99


def test_filter_peaks_and_side_lobes():
    grid = np.arange(370.0, 900.0, 1.0)
    transmissions = filter_module.filter_transmissions(grid)
    peaks = transmissions.max(axis=1)
    assert np.all((peaks > 0.55) & (peaks <= 1.0))
    # each peak on the grid point nearest its band centre: within half the 1 nm grid step
    np.testing.assert_allclose(grid[np.argmax(transmissions, axis=1)], sim.band_wavelengths(64), atol=0.5)
    relative = transmissions / peaks[:, None]
    nir_blue_lobe = relative[-8:, (grid >= 450) & (grid <= 650)]
    blue_nir_leak = relative[:8, (grid >= 840) & (grid <= 880)]
    assert 0.005 < np.median(nir_blue_lobe) < 0.06 and nir_blue_lobe.max() < 0.1
    assert 0.005 < np.median(blue_nir_leak) < 0.06 and blue_nir_leak.max() < 0.1


def test_filter_side_lobes_resemble_the_measured_sfa(shared_data):
    """Relative side-lobe medians within a factor 2 of the digitized Spectral DiffuserScope SFA."""
    measured = np.load(shared_data("spectra/spectraldiffuserscope/sfa64_transmission_digitized.npz"))
    grid = measured["wavelength_nm"].astype(np.float64)

    def side_lobes(transmissions, peak_nm):
        relative = transmissions / transmissions.max(axis=1, keepdims=True)
        return (np.median(relative[peak_nm >= 750][:, (grid >= 450) & (grid <= 650)]),
                np.median(relative[peak_nm <= 480][:, (grid >= 840) & (grid <= 880)]))

    ours = side_lobes(filter_module.filter_transmissions(grid), sim.band_wavelengths(64))
    theirs = side_lobes(measured["transmission"], measured["peak_nm"])
    for mine, real in zip(ours, theirs):
        assert real / 2 < mine < real * 2


def test_filter_array_shape_range_and_determinism():
    filters = sim.filter_array(SMALL, BANDS8, seed=3)
    assert filters.shape == (8,) + SMALL and filters.dtype == np.float32
    assert filters.min() >= 0.0 and filters.max() <= 1.0 and filters.max() > 0.5
    np.testing.assert_array_equal(filters, sim.filter_array(SMALL, BANDS8, seed=3))
    assert not np.array_equal(filters, sim.filter_array(SMALL, BANDS8, seed=4))


def test_aligned_tile_repeats_every_16_pixels_exactly():
    filters = sim.filter_array(SMALL, sim.band_wavelengths(), misalignment=(0.0, 0.0), rotation_deg=0.0)
    np.testing.assert_array_equal(filters[:, 16:, :], filters[:, :-16, :])
    np.testing.assert_array_equal(filters[:, :, 16:], filters[:, :, :-16])
    assert not np.array_equal(filters[:, 8:, :], filters[:, :-8, :])
    np.testing.assert_array_equal(filters[:, 0::2, 0::2], filters[:, 1::2, 1::2])  # 2×2 squares


def test_coverage_is_a_partition_blended_only_when_misaligned():
    layout = filter_module.filter_layout(0)
    aligned = filter_module.filter_coverage(SMALL, layout, 2.0, (0.0, 0.0), 0.0)
    shifted = filter_module.filter_coverage(SMALL, layout, 2.0, (0.3, 0.45), 0.2)
    for coverage in (aligned, shifted):
        np.testing.assert_allclose(coverage.sum(axis=0), 1.0)
    assert set(np.unique(aligned)) == {0.0, 1.0}
    blended = shifted.max(axis=0) < 1.0
    assert 0.6 < blended.mean() < 0.9  # boundaries cross ~half the rows and ~half the columns


def test_each_pixel_responds_most_at_its_filters_centre():
    layout = filter_module.filter_layout(5)
    wavelengths = sim.band_wavelengths()
    filters = sim.filter_array(SMALL, wavelengths, seed=5, misalignment=(0.0, 0.0), rotation_deg=0.0)
    y, x = np.mgrid[0:SMALL[0], 0:SMALL[1]]
    own_centre = wavelengths[layout[(y // 2) % 8, (x // 2) % 8]]
    np.testing.assert_array_equal(wavelengths[np.argmax(filters, axis=0)], own_centre)


def test_misaligned_pixels_respond_most_at_their_dominant_filters_centre():
    layout = filter_module.filter_layout(0)
    wavelengths = sim.band_wavelengths()
    coverage = filter_module.filter_coverage(SMALL, layout, 2.0, (0.3, 0.45), 0.2)
    filters = sim.filter_array(SMALL, wavelengths)
    dominant = coverage.max(axis=0) > 0.6
    best_band = np.argmax(filters, axis=0)
    assert np.mean(best_band[dominant] == np.argmax(coverage, axis=0)[dominant]) > 0.95


def test_single_band_filter_array():
    filters = sim.filter_array(SMALL, sim.band_wavelengths(1))
    assert filters.shape == (1,) + SMALL
    assert np.all(np.isfinite(filters)) and filters.min() >= 0.0 and filters.max() > 0.5


# ---- scenes -----------------------------------------------------------------------------

def assert_valid_scene(cube, bands=8, shape=SMALL):
    assert cube.shape == (bands,) + shape and cube.dtype == np.float32
    assert cube.min() >= 0.0 and cube.max() == pytest.approx(1.0)
    by, bx = scenes.border_px(shape)
    assert by >= 0.04 * shape[0] and bx >= 0.04 * shape[1]
    inside = np.zeros(shape, bool)
    inside[by:shape[0] - by, bx:shape[1] - bx] = True
    assert np.all(cube[:, ~inside] == 0.0)


@pytest.mark.parametrize("name", SYNTHETIC_SCENES)
def test_scene_shape_range_border_and_determinism(name):
    cube = sim.make_scene(name, SMALL, BANDS8, seed=2)
    assert_valid_scene(cube)
    np.testing.assert_array_equal(cube, sim.make_scene(name, SMALL, BANDS8, seed=2))


@pytest.mark.parametrize("name", RANDOM_SCENES)
def test_random_scenes_change_with_the_seed(name):
    assert not np.array_equal(sim.make_scene(name, SMALL, BANDS8, seed=0), sim.make_scene(name, SMALL, BANDS8, seed=1))


def test_default_scene_is_the_target_with_64_bands():
    cube = sim.make_scene(shape=SMALL)
    np.testing.assert_array_equal(cube, sim.make_scene("target", SMALL, sim.band_wavelengths()))
    assert cube.shape == (64,) + SMALL


def test_target_quadrants_are_red_green_blue_and_white():
    wavelengths = sim.band_wavelengths()
    cube = sim.make_scene("target", (96, 128), wavelengths)
    halves = ((slice(0, 48), slice(0, 64)), (slice(0, 48), slice(64, 128)),
              (slice(48, 96), slice(0, 64)), (slice(48, 96), slice(64, 128)))
    spectra = [cube[(slice(None),) + quadrant].sum(axis=(1, 2)) for quadrant in halves]
    for spectrum, line in zip(spectra[:3], (630.0, 530.0, 460.0)):
        assert abs(wavelengths[np.argmax(spectrum)] - line) <= 8.0
        assert spectrum[np.abs(wavelengths - line) > 40].max() < 1e-3 * spectrum.max()
    white = spectra[3] / spectra[3].max()
    assert white.min() > 0.3
    charts = [bounding_box(np.any(cube[(slice(None),) + quadrant] > 0, axis=0)) for quadrant in halves]
    assert all(np.array_equal(chart, charts[0]) for chart in charts)  # the same chart in each


def bounding_box(mask: np.ndarray) -> np.ndarray:
    """The smallest sub-array holding every True of ``mask``."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    return mask[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]


def test_target_chart_has_several_bar_widths():
    assert scenes.bar_widths((142, 200)) == [1, 2, 3, 4, 6]
    chart = scenes.resolution_chart((60, 80))
    columns_with_bars = chart.max(axis=0)
    assert chart.max() == 1.0 and columns_with_bars.sum() < 80


def test_leds_have_exactly_three_spectra():
    cube = sim.make_scene("leds", SMALL, BANDS8, seed=4)
    pixels = cube.reshape(8, -1).T.astype(np.float64)
    singular = np.linalg.svd(pixels[pixels.max(axis=1) > 0], compute_uv=False)
    assert singular[2] > 1e-3 * singular[0]
    assert singular[3] < 1e-6 * singular[0]


def test_leds_are_small_spots():
    cube = sim.make_scene("leds", SMALL, BANDS8)
    lit = cube.max(axis=0) > 0
    assert 24 * 5 <= lit.sum() <= 24 * 13  # 24 discs of radius 1..2 px: 5 to 13 pixels each


def test_piecewise_regions_have_constant_spectra():
    cube = sim.make_scene("piecewise", SMALL, BANDS8, seed=6)
    inner = cube[(slice(None),) + scenes.inner_window(SMALL)].reshape(8, -1).T
    distinct = np.unique(inner, axis=0)
    assert 8 <= len(distinct) <= 12
    assert np.linalg.matrix_rank(distinct.astype(np.float64), tol=1e-4) == 8


def test_points_are_two_pixels_four_apart_with_one_spectrum():
    cube = sim.make_scene("points", SMALL, BANDS8, seed=7)
    ys, xs = np.nonzero(cube.max(axis=0))
    assert len(ys) == 2 and ys[0] == ys[1] and abs(xs[1] - xs[0]) == 4
    np.testing.assert_array_equal(cube[:, ys[0], xs[0]], cube[:, ys[1], xs[1]])
    assert BANDS8[np.argmax(cube[:, ys[0], xs[0]])] == pytest.approx(546.0)


def test_unknown_scene_names_the_choices():
    with pytest.raises(InputError, match="target.*leds.*piecewise.*points.*realcube"):
        sim.make_scene("moon", SMALL, BANDS8)


def test_scene_too_small_for_its_chart_is_an_input_error():
    with pytest.raises(InputError, match="too small"):
        sim.make_scene("target", (10, 12), BANDS8)


def test_realcube_from_samson(shared_data):
    shared_data(scenes.SAMSON)
    wavelengths = np.array([390.0, 395.0, 550.0, 650.0, 850.0])
    cube = sim.make_scene("realcube", SMALL, wavelengths)
    assert_valid_scene(cube, bands=5)
    np.testing.assert_array_equal(cube[0], cube[1])  # below 400.9 nm both clamp to the first band
    inner = cube[(slice(None),) + scenes.inner_window(SMALL)]
    assert (inner.max(axis=0) > 0).mean() > 0.99


def test_realcube_missing_data_is_an_input_error(monkeypatch, tmp_path):
    monkeypatch.setenv("CLSDCAM_DATA", str(tmp_path))
    with pytest.raises(InputError, match="realcube.*not present"):
        sim.make_scene("realcube", SMALL, BANDS8)


# ---- noise ------------------------------------------------------------------------------

def test_noise_off_returns_the_input():
    b = np.random.default_rng(0).random((20, 30))
    np.testing.assert_array_equal(sim.add_noise(b, np.random.default_rng(1), gaussian_var=0.0, photons=None), b)
    np.testing.assert_array_equal(sim.add_noise(np.zeros((4, 4)), np.random.default_rng(1), 1e-2, 100.0), 0.0)


def test_gaussian_noise_variance_is_relative_to_the_peak_squared():
    b = np.full((300, 300), 2.0)
    noisy = sim.add_noise(b, np.random.default_rng(2), gaussian_var=1e-4)
    assert np.std(noisy - b) == pytest.approx(0.01 * 2.0, rel=0.02)
    assert np.mean(noisy - b) == pytest.approx(0.0, abs=5e-4)


def test_shot_noise_counts_photons_at_the_peak():
    b = np.full((300, 300), 3.0)
    b[0, 0] = 4.0  # peak: 4.0 ↦ 1000 photons, so 3.0 ↦ 750
    counts = sim.add_noise(b, np.random.default_rng(3), photons=1000.0) / 4.0 * 1000.0
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
    assert np.mean(counts) == pytest.approx(750.0, rel=0.002)
    assert np.var(counts) == pytest.approx(750.0, rel=0.03)


# ---- the whole camera -------------------------------------------------------------------

def brute_force_measurement(psf, filters, cube):
    """Σ_k F_k ⊙ crop(h ∗ v_k): full linear convolution, PSF origin at (H//2, W//2), sensor (y, x) -> (y, x)."""
    h, w = psf.shape
    cy, cx = h // 2, w // 2
    return sum(f * fftconvolve(v.astype(np.float64), psf.astype(np.float64), mode="full")[cy:cy + h, cx:cx + w]
               for f, v in zip(filters.astype(np.float64), cube))


@pytest.mark.parametrize("shape", [(14, 19), (16, 20)])
def test_noiseless_measurement_equals_brute_force_convolution(shape):
    rng = np.random.default_rng(8)
    psf = rng.random(shape).astype(np.float32)
    filters = rng.random((5,) + shape).astype(np.float32)
    result = sim.simulate("piecewise", psf=psf, filters=filters, seed=8, noise_var=0.0, photons=None)
    expected = brute_force_measurement(psf, filters, result.truth)
    np.testing.assert_allclose(result.measurement, expected, rtol=0, atol=1e-5 * expected.max())


def test_simulated_camera_equals_brute_force_convolution():
    result = sim.simulate("leds", shape=SMALL, n_bands=8, seed=9, noise_var=0.0, photons=None)
    cal = result.calibration
    expected = brute_force_measurement(cal.psf, cal.filters, result.truth)
    np.testing.assert_allclose(result.measurement, expected, rtol=0, atol=1e-5 * expected.max())


def test_point_seen_through_a_delta_psf_lands_on_its_own_pixel():
    psf = np.zeros(SMALL, np.float32)
    psf[SMALL[0] // 2, SMALL[1] // 2] = 1.0
    result = sim.simulate("points", psf=psf, filters=np.ones((1,) + SMALL, np.float32), seed=1, noise_var=0.0, photons=None)
    np.testing.assert_allclose(result.measurement, result.truth[0], atol=1e-6)


def test_simulate_shapes_and_noise():
    result = sim.simulate("piecewise", shape=SMALL, n_bands=8, seed=10)
    clean = sim.simulate("piecewise", shape=SMALL, n_bands=8, seed=10, noise_var=0.0, photons=None)
    cal = result.calibration
    assert result.measurement.shape == SMALL and result.measurement.dtype == np.float32
    assert result.truth.shape == (8,) + SMALL and cal.filters.shape == (8,) + SMALL and cal.psf.shape == SMALL
    np.testing.assert_allclose(cal.wavelengths, BANDS8)
    assert result.scene == "piecewise" and result.seed == 10
    assert result.measurement.min() >= 0.0
    relative_error = np.linalg.norm(result.measurement - clean.measurement) / np.linalg.norm(clean.measurement)
    assert 1e-3 < relative_error < 0.05
    np.testing.assert_array_equal(result.measurement, sim.simulate("piecewise", shape=SMALL, n_bands=8, seed=10).measurement)


def test_simulate_rejects_conflicting_geometry():
    psf = np.ones(SMALL, np.float32)
    with pytest.raises(InputError, match="shape"):
        sim.simulate(shape=(32, 32), psf=psf)
    with pytest.raises(InputError, match="n_bands"):
        sim.simulate(n_bands=4, psf=psf, filters=np.ones((8,) + SMALL, np.float32))


def test_write_simulation(tmp_path):
    result = sim.simulate("points", shape=SMALL, n_bands=8, seed=11)
    paths = sim.write_simulation(tmp_path / "out", result)
    assert set(paths) == {"calibration", "measurement", "truth"}
    assert all(path.exists() for path in paths.values())
    np.testing.assert_array_equal(np.load(paths["measurement"]), result.measurement)
    with h5py.File(paths["truth"], "r") as f:
        np.testing.assert_array_equal(f["cube"][...], result.truth)
        np.testing.assert_allclose(f["wavelength"][...], BANDS8)
    with h5py.File(paths["calibration"], "r") as f:
        np.testing.assert_array_equal(f["psf"][...], result.calibration.psf)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["calibration.h5", "measurement.npy", "truth.h5"]
