"""The randomised panel's scene kinds (clsdcam.sim.kinds): valid cubes, new scenes per seed, what each kind is for."""
import numpy as np
import pytest

from clsdcam.errors import InputError
from clsdcam.sim import band_wavelengths, simulate
from clsdcam.sim.kinds import KINDS, make_kind, real_cubes, spectra
from clsdcam.sim.scenes import border_px, shared_data_dir
from clsdcam.solve.subspace import Spectra, lit_shapes

SHAPE, WAVELENGTHS = (48, 64), band_wavelengths(32)
NEEDS_DATA = pytest.mark.skipif(not real_cubes(shared_data_dir()), reason="no real cube in ../shared/data")


def kinds():
    return [pytest.param(kind, marks=NEEDS_DATA) if kind == "real" else kind for kind in KINDS]


@pytest.mark.parametrize("kind", kinds())
def test_every_kind_is_a_valid_scene_that_changes_with_its_seed(kind):
    cube = make_kind(kind, SHAPE, WAVELENGTHS, seed=3)
    by, bx = border_px(SHAPE)
    assert cube.shape == (32,) + SHAPE and cube.dtype == np.float32 and cube.min() >= 0 and cube.max() == 1
    assert not cube[:, :by].any() and not cube[:, -by:].any() and not cube[:, :, :bx].any() and not cube[:, :, -bx:].any()
    np.testing.assert_array_equal(cube, make_kind(kind, SHAPE, WAVELENGTHS, seed=3))
    assert not np.array_equal(cube, make_kind(kind, SHAPE, WAVELENGTHS, seed=4))


def test_piecewise_scenes_hold_many_overlapping_spectra():
    """What the fixed panel lacked: many directions hold the lit spectra (measured 10–13 at a 1e-3 tail; the LED
    grid: 3)."""
    ranks = [Spectra.of_shapes(lit_shapes(make_kind("piecewise", SHAPE, band_wavelengths(64), seed))).rank_for(1e-3)
             for seed in range(4)]
    assert min(ranks) >= 8, ranks


def test_narrow_spectra_are_narrow_and_broad_ones_broad():
    rng = np.random.default_rng(0)
    narrow, broad = spectra(rng, band_wavelengths(64), 20, (4.0, 16.0)), spectra(rng, band_wavelengths(64), 20)
    assert np.median((narrow > 0.5).sum(axis=1)) <= 3 < np.median((broad > 0.5).sum(axis=1))


def test_a_kind_scene_is_imaged_by_the_simulator():
    cube = make_kind("sparse", SHAPE, WAVELENGTHS, seed=1)
    sim = simulate(scene="sparse", shape=SHAPE, n_bands=32, seed=1, cube=cube)
    np.testing.assert_array_equal(sim.truth, cube)
    assert sim.measurement.shape == SHAPE and sim.measurement.max() > 0


def test_an_unknown_kind_is_refused():
    with pytest.raises(InputError, match="expected one of"):
        make_kind("galaxy", SHAPE, WAVELENGTHS, seed=0)


def test_a_sensor_too_small_for_a_kind_or_a_cube_of_the_wrong_shape_is_refused():
    with pytest.raises(InputError, match="too small"):
        make_kind("natural", (6, 12), WAVELENGTHS, seed=0)
    with pytest.raises(InputError, match="expected"):
        simulate(scene="sparse", shape=SHAPE, n_bands=16, seed=0, cube=make_kind("sparse", SHAPE, WAVELENGTHS, 0))
