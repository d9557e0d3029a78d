"""Field geometry: the PSF's measured support, the support-sized field, and the convention that A is a
linear convolution with the PSF's centre pixel as origin on every field (docs/conventions.md)."""
import numpy as np
import pytest
from scipy.signal import fftconvolve

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.errors import InputError
from clsdcam.camera.geometry import centred_geometry, psf_support, support_geometry, transfer_function
from clsdcam.camera.model import ForwardModel

BE = NumpyBackend("float64")


def boxed_psf(sensor, rows, cols, seed=0):
    """A random PSF that is non-zero exactly on rows × cols (absolute indices)."""
    psf = np.zeros(sensor)
    psf[rows[0]:rows[1] + 1, cols[0]:cols[1] + 1] = np.random.default_rng(seed).random(
        (rows[1] - rows[0] + 1, cols[1] - cols[0] + 1)) + 0.1
    return psf


def test_support_of_a_boxed_psf_is_its_box_relative_to_the_centre():
    psf = boxed_psf((20, 30), (3, 12), (20, 27))
    assert psf_support(psf, tail=0.0) == ((3 - 10, 12 - 10), (20 - 15, 27 - 15))


def test_support_trims_a_faint_tail_but_keeps_a_heavy_one():
    psf = boxed_psf((20, 30), (8, 11), (13, 17))
    psf[0, 0] = 1e-9 * psf.sum()                    # far, faint: outside the support
    assert psf_support(psf) == ((8 - 10, 11 - 10), (13 - 15, 17 - 15))
    psf[0, 0] = 0.1 * psf.sum()                     # far, heavy: the support reaches it
    assert psf_support(psf)[0][0] == -10 and psf_support(psf)[1][0] == -15


def test_all_zero_psf_is_an_input_error():
    with pytest.raises(InputError, match="all zero"):
        psf_support(np.zeros((4, 5)))


@pytest.mark.parametrize("rows,cols", [((3, 12), (20, 27)), ((11, 16), (16, 25)), ((0, 19), (0, 29)), ((2, 4), (3, 5))])
def test_support_field_holds_every_scene_point_that_reaches_the_sensor(rows, cols):
    """oy ≥ max(s_hi, 0) and Hp − oy − H ≥ max(−s_lo, 0) on both axes; lengths are the engine's fast ones."""
    sensor = (20, 30)
    geometry = support_geometry(boxed_psf(sensor, rows, cols), BE.fast_length, tail=0.0)
    for n, field, offset, (lo, hi) in zip(sensor, geometry.field, geometry.offset, geometry.support):
        assert offset >= max(hi, 0) and field - offset - n >= max(-lo, 0)
        assert field == BE.fast_length(field)


@pytest.mark.parametrize("rows,cols", [((3, 12), (20, 27)), ((11, 16), (16, 25)), ((2, 4), (3, 5)), ((0, 19), (0, 29))])
def test_forward_on_the_support_field_is_the_linear_convolution(rows, cols):
    """b = Σ_k F_k ⊙ [v_k ∗ h]_window with the PSF centre as origin, off-centre supports included."""
    sensor, bands = (20, 30), 3
    rng = np.random.default_rng(1)
    psf, filters = boxed_psf(sensor, rows, cols), rng.random((bands,) + sensor)
    geometry = support_geometry(psf, BE.fast_length, tail=0.0)
    model = ForwardModel(BE, psf, filters, geometry=geometry)
    field = rng.random(model.cube_shape)
    (oy, ox), (cy, cx) = geometry.offset, (sensor[0] // 2, sensor[1] // 2)
    expected = sum(filters[k] * fftconvolve(field[k], psf)[oy + cy:oy + cy + sensor[0], ox + cx:ox + cx + sensor[1]]
                   for k in range(bands))
    np.testing.assert_allclose(model.forward(field), expected, rtol=1e-10, atol=1e-10)


def test_support_field_and_paper_field_see_the_same_scene_through_the_window():
    """A scene inside the sensor window gives the same measurement on both fields."""
    sensor = (24, 32)
    rng = np.random.default_rng(2)
    psf, filters = boxed_psf(sensor, (6, 15), (10, 21)), rng.random((2,) + sensor)
    paper = ForwardModel(BE, psf, filters)
    small = ForwardModel(BE, psf, filters, geometry=support_geometry(psf, BE.fast_length, tail=0.0))
    assert small.field_shape[0] < paper.field_shape[0] and small.field_shape[1] < paper.field_shape[1]
    window = rng.random((2,) + sensor)
    np.testing.assert_allclose(small.forward(small.embed(window)), paper.forward(paper.embed(window)), rtol=1e-10)


@pytest.mark.parametrize("sensor", [(16, 24), (15, 23)])
def test_delta_psf_at_centre_is_the_identity_on_a_support_sized_field(sensor):
    psf = np.zeros(sensor)
    psf[sensor[0] // 2, sensor[1] // 2] = 1.0
    geometry = support_geometry(psf, BE.fast_length)
    assert geometry.support == ((0, 0), (0, 0)) and geometry.field == tuple(BE.fast_length(n) for n in sensor)
    model = ForwardModel(BE, psf, np.ones((1,) + sensor), geometry=geometry)
    cube = np.random.default_rng(3).random((1,) + sensor)
    np.testing.assert_allclose(model.forward(model.embed(cube)), cube[0], atol=1e-12)


def test_paper_geometry_is_the_centred_2h_by_2w_field():
    geometry = centred_geometry((320, 448))
    assert geometry.field == (640, 896) and geometry.offset == (160, 224)
    assert geometry.support == ((-160, 159), (-224, 223))


def test_transfer_function_puts_the_window_at_the_fft_origin():
    """The kernel's (s − offset) mod field holds h_c(s): a delta at the PSF centre is a shift by −offset."""
    sensor = (8, 10)
    psf = np.zeros(sensor)
    psf[4, 5] = 1.0
    geometry = centred_geometry(sensor)
    kernel = np.fft.irfft2(transfer_function(psf, geometry), s=geometry.field)
    expected = np.zeros(geometry.field)
    expected[-geometry.offset[0] % geometry.field[0], -geometry.offset[1] % geometry.field[1]] = 1.0
    np.testing.assert_allclose(kernel, expected, atol=1e-12)
