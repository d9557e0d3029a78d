"""A spectral subspace (clsdcam.solve.subspace): v = B·c and back, its model A·B, its L, its prox in the span."""
import numpy as np
import pytest

from clsdcam.backends import NumpyBackend
from clsdcam.camera.model import ForwardModel
from clsdcam.solve.settings import Settings
from clsdcam.solve.priors import TotalVariation
from clsdcam.solve.subspace import SpectralSubspace


@pytest.fixture(scope="module")
def subspace():
    rng = np.random.default_rng(4)
    be = NumpyBackend("float64")
    filters = rng.random((6, 10, 12))
    model = ForwardModel(be, rng.random((10, 12)), filters)
    basis, _ = np.linalg.qr(rng.random((6, 2)))
    priors = [TotalVariation(be, 1e-3, Settings())]
    return model, SpectralSubspace(model, basis, priors, filters), rng


def test_coefficients_expand_and_project_back_and_the_model_is_a_times_b(subspace):
    model, sub, rng = subspace
    c = rng.random(sub.cube_shape)
    v = sub.expand(c).copy()
    np.testing.assert_allclose(sub.project(v), c, atol=1e-12)
    np.testing.assert_allclose(sub.model.forward(c), model.forward(v), rtol=1e-10, atol=1e-12)


def test_its_lipschitz_constant_bounds_a_b_and_is_at_most_band_spaces(subspace):
    model, sub, rng = subspace
    c = rng.standard_normal(sub.cube_shape)
    gain = np.sum(sub.model.forward(c) ** 2) / np.sum(c ** 2)
    assert gain <= sub.lipschitz * (1 + 1e-6) and sub.lipschitz <= model.lipschitz() * (1 + 1e-6)
    assert sub.power_transforms > 0


def test_its_prox_stays_in_the_span(subspace):
    model, sub, rng = subspace
    c = rng.random(sub.cube_shape)
    out = np.empty_like(c)
    sub.prox(c, 0.5, out)
    assert out.shape == c.shape and np.isfinite(out).all()
    assert sub.penalty(out) <= sub.penalty(c) + 1e-12
