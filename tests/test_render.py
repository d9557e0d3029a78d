"""clsdcam.render: false-colour hues, grey fallbacks, the PNG files and input checks."""
import numpy as np
import pytest

from clsdcam.errors import InputError
from clsdcam.render import band_widths, false_colour, save_pictures

VISIBLE = np.arange(400.0, 701.0, 10.0)     # 31 uniform bands


def line_cube(wavelengths, peak_nm, shape=(4, 5)):
    """A cube that is 1 in the band nearest ``peak_nm`` and 0 elsewhere."""
    cube = np.zeros((len(wavelengths), *shape), np.float32)
    cube[np.argmin(np.abs(np.asarray(wavelengths) - peak_nm))] = 1.0
    return cube


@pytest.mark.parametrize("peak_nm, channel", [(450, 2), (540, 1), (650, 0)])
def test_single_band_hue(peak_nm, channel):
    rgb = false_colour(line_cube(VISIBLE, peak_nm), VISIBLE)
    assert rgb.shape == (4, 5, 3)
    assert np.argmax(rgb[2, 3]) == channel
    assert rgb[2, 3, channel] > 1.5 * np.delete(rgb[2, 3], channel).max()


def test_flat_spectrum_is_grey():
    rgb = false_colour(np.ones((len(VISIBLE), 3, 3), np.float32), VISIBLE)[1, 1]
    assert rgb.max() > 0.9
    assert rgb.min() > 0.85 * rgb.max()


def test_flat_spectrum_on_non_uniform_wide_grid_is_grey():
    wl = np.sort(np.concatenate([np.linspace(386, 898, 40), [505.0, 507.0, 509.0]]))  # uneven spacing
    rgb = false_colour(np.ones((wl.size, 2, 2), np.float32), wl)[0, 0]
    assert rgb.min() > 0.85 * rgb.max()


def test_false_colour_is_in_unit_range_and_normalised():
    rng = np.random.default_rng(0)
    rgb = false_colour(rng.random((16, 20, 30), dtype=np.float32) * 50, np.linspace(400, 700, 16))
    assert rgb.min() >= 0 and rgb.max() <= 1
    assert np.quantile(rgb.max(axis=-1), 0.9) > 0.5   # scaled to the display, not left tiny


def assert_grey_band_sum(rgb, cube):
    assert np.allclose(rgb[..., 0], rgb[..., 1]) and np.allclose(rgb[..., 1], rgb[..., 2])
    total = cube.sum(axis=0)
    assert np.argmax(rgb[..., 0]) == np.argmax(total) and np.argmin(rgb[..., 0]) == np.argmin(total)


def test_single_band_is_grey():
    cube = np.random.default_rng(1).random((1, 6, 7), dtype=np.float32)
    assert_grey_band_sum(false_colour(cube, [550.0]), cube)


def test_infrared_bands_give_grey_band_sum():
    cube = np.random.default_rng(2).random((5, 6, 7), dtype=np.float32)
    assert_grey_band_sum(false_colour(cube, [850.0, 860, 870, 880, 898]), cube)


def test_zero_cube_is_black():
    assert not false_colour(np.zeros((3, 2, 2), np.float32), [450.0, 550, 650]).any()


def test_band_widths_non_uniform_and_unsorted():
    assert np.allclose(band_widths([400.0, 410, 430]), [10, 15, 20])
    assert np.allclose(band_widths([430.0, 400, 410]), [20, 10, 15])
    assert band_widths([500.0]).shape == (1,)


def test_unsorted_wavelengths_give_the_same_colour():
    order = np.random.default_rng(3).permutation(VISIBLE.size)
    cube = np.random.default_rng(4).random((VISIBLE.size, 4, 4), dtype=np.float32)
    assert np.allclose(false_colour(cube[order], VISIBLE[order]), false_colour(cube, VISIBLE), atol=1e-6)


def read_png(path):
    import matplotlib.image

    assert path.stat().st_size > 0
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return matplotlib.image.imread(path)


def small_cube(seed=5, shape=(8, 12, 16)):
    return np.random.default_rng(seed).random(shape, dtype=np.float32)


HISTORY = [{"iteration": i, "data": 10.0 / (i + 1), "objective": 12.0 / (i + 1) if i % 5 == 0 else float("nan"),
            "seconds": 0.01 * i} for i in range(20)]


def test_save_pictures_with_history_and_truth(tmp_path):
    cube = small_cube()
    paths = save_pictures(tmp_path / "new" / "run", cube, np.linspace(386, 898, 8), history=HISTORY,
                          truth=small_cube(6))
    names = ["run_falsecolour.png", "run_projections.png", "run_spectra.png", "run_convergence.png"]
    assert [p.name for p in paths] == names
    assert sorted(p.name for p in (tmp_path / "new").iterdir()) == sorted(names)   # no temporary files
    for path in paths:
        assert read_png(path).ndim == 3
    assert read_png(paths[0]).shape[:2] == cube.shape[1:]


def test_save_pictures_without_history(tmp_path):
    wl = [400.0, 420, 470, 560, 700, 710]     # non-uniform
    paths = save_pictures(tmp_path / "a", small_cube(shape=(6, 9, 9)), wl, history=[], points=[(0, 0), (8, 8)])
    assert [p.name for p in paths] == ["a_falsecolour.png", "a_projections.png", "a_spectra.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [p.name for p in paths]
    for path in paths:
        read_png(path)


def test_save_pictures_single_band(tmp_path):
    """A plain DiffuserCam (K = 1) gets a grey image, its line profiles and the convergence plot, not a fake
    wavelength axis and a one-dot "spectrum"."""
    cube = small_cube(shape=(1, 5, 6))
    paths = save_pictures(tmp_path / "one", cube, [532.0], history=HISTORY[:1], truth=cube * 0.9)
    assert [p.name for p in paths] == ["one_image.png", "one_profiles.png", "one_convergence.png"]
    grey = read_png(paths[0])
    assert np.allclose(grey[..., 0], grey[..., 1]) and np.allclose(grey[..., 1], grey[..., 2])


@pytest.mark.parametrize("kwargs, message", [
    (dict(cube=np.zeros((4, 5), np.float32)), "cube"),
    (dict(wavelengths=np.arange(3.0)), "wavelengths"),
    (dict(truth=np.zeros((4, 5, 5), np.float32)), "truth"),
    (dict(points=[(2, 6)]), "points"),
    (dict(points=[(-1, 0)]), "points"),
    (dict(points=[(1,)]), "points"),
    (dict(history=[{"data": 1.0}]), "history"),
])
def test_bad_inputs_raise_input_error_and_write_nothing(tmp_path, kwargs, message):
    args = {"cube": np.ones((4, 5, 6), np.float32), "wavelengths": np.linspace(450, 650, 4), **kwargs}
    with pytest.raises(InputError, match=message):
        save_pictures(tmp_path / "bad", **args)
    assert not any(tmp_path.iterdir())


def test_false_colour_rejects_bad_shapes():
    with pytest.raises(InputError):
        false_colour(np.ones((3, 4, 4), np.float32), [500.0, 600.0])
    with pytest.raises(InputError):
        false_colour(np.ones((4, 4), np.float32), [500.0])
