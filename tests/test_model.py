"""The forward operator: adjoint identity, linearity, geometry conventions, Lipschitz constant."""
import numpy as np
import pytest
from scipy.signal import fftconvolve

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.camera.model import ForwardModel, window_offset


def random_model(rng, sensor=(21, 34), bands=5, field=None, dtype="float32"):
    psf = rng.random(sensor)
    filters = rng.random((bands,) + sensor)
    return ForwardModel(NumpyBackend(dtype), psf, filters, field_shape=field)


@pytest.mark.parametrize("field", [None, (45, 70), (41, 67)])
def test_adjoint_identity_float32_odd_nonsquare(field):
    rng = np.random.default_rng(1)
    model = random_model(rng, field=field)
    x = rng.standard_normal(model.cube_shape).astype(np.float32)
    y = rng.standard_normal(model.sensor_shape).astype(np.float32)
    ax = model.forward(x).astype(np.float64)
    aty = model.adjoint(y).astype(np.float64)
    gap = abs(np.vdot(ax, y) - np.vdot(x.astype(np.float64), aty))
    assert gap <= 1e-5 * np.linalg.norm(ax) * np.linalg.norm(y)


def test_linearity():
    rng = np.random.default_rng(2)
    model = random_model(rng, dtype="float64")
    x1, x2 = (rng.standard_normal(model.cube_shape) for _ in range(2))
    combined = model.forward(2.5 * x1 - 0.5 * x2).copy()
    np.testing.assert_allclose(combined, 2.5 * model.forward(x1) - 0.5 * model.forward(x2), rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("sensor", [(16, 24), (15, 23)])
def test_delta_psf_at_centre_is_identity_on_window(sensor):
    """A delta PSF at (H//2, W//2) with an all-ones one-band mask is the identity on the sensor window."""
    rng = np.random.default_rng(3)
    psf = np.zeros(sensor)
    psf[sensor[0] // 2, sensor[1] // 2] = 1.0
    model = ForwardModel(NumpyBackend("float64"), psf, np.ones((1,) + sensor))
    cube = rng.random((1,) + sensor)
    np.testing.assert_allclose(model.forward(model.embed(cube)), cube[0], atol=1e-12)
    np.testing.assert_allclose(model.window(model.embed(cube)), cube, atol=0)


def test_forward_equals_linear_convolution_of_the_field():
    """b = Σ_k F_k ⊙ crop(h ∗ v_k) with a full linear convolution, PSF origin at its centre."""
    rng = np.random.default_rng(4)
    sensor, bands = (12, 17), 3
    psf, filters = rng.random(sensor), rng.random((bands,) + sensor)
    model = ForwardModel(NumpyBackend("float64"), psf, filters)
    field = rng.random(model.cube_shape)
    oy, ox = model.offset
    cy, cx = sensor[0] // 2, sensor[1] // 2
    expected = sum(filters[k] * fftconvolve(field[k], psf, mode="full")[oy + cy:oy + cy + sensor[0], ox + cx:ox + cx + sensor[1]]
                   for k in range(bands))
    np.testing.assert_allclose(model.forward(field), expected, rtol=1e-10, atol=1e-10)


def test_window_offset_centres_window():
    assert window_offset((320, 448), (640, 896)) == (160, 224)
    assert window_offset((15, 23), (30, 46)) == (8, 12)


def test_lipschitz_matches_dense_operator_norm():
    rng = np.random.default_rng(5)
    model = random_model(rng, sensor=(6, 7), bands=2, dtype="float64")
    n = int(np.prod(model.cube_shape))
    dense = np.stack([model.forward(e.reshape(model.cube_shape)).ravel().copy() for e in np.eye(n)], axis=1)
    exact = np.linalg.norm(dense, 2) ** 2
    estimate = model.lipschitz(iters=100)
    assert exact <= estimate <= 1.03 * exact
