"""The spaces a solve's iterates live in (clsdcam.spaces): band space is the full problem, a subspace is A·B with
its own Lipschitz constant (remembered for the same basis), and the subspace's check takes one exact full step."""
import numpy as np
import pytest

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.model import ForwardModel
from clsdcam.priors import build_priors
from clsdcam.settings import Settings
from clsdcam.sim import simulate
from clsdcam.spaces import LastLipschitz, Spaces

BACKEND = NumpyBackend("float64")


@pytest.fixture(scope="module")
def spaces():
    sim = simulate(scene="leds", shape=(32, 48), n_bands=8, seed=0)
    cal = sim.calibration
    model = ForwardModel(BACKEND, cal.psf, cal.filters)
    b = BACKEND.to_device(sim.measurement / np.abs(sim.measurement).max())
    priors = build_priors(BACKEND, Settings(tv=1e-3), lambda name: 1.0)
    return Spaces(model, b, priors, cal.filters, model.lipschitz(), LastLipschitz())


def orthonormal(rank: int, seed: int = 0) -> np.ndarray:
    return np.linalg.qr(np.random.default_rng(seed).standard_normal((8, rank)))[0]


def test_band_space_is_the_full_problem(spaces):
    band = spaces.band
    assert band is spaces.band and band.subspace is None and band.rank == 8
    x = np.random.default_rng(1).random(spaces.model.cube_shape)
    r = spaces.model.forward(x) - spaces.b
    assert band.data(x) == pytest.approx(0.5 * np.sum(r * r), rel=1e-12)


def test_a_subspace_is_a_times_its_basis_and_remembers_its_lipschitz_constant(spaces):
    basis = orthonormal(3)
    sub = spaces.subspace(basis)
    c = np.random.default_rng(2).random(sub.subspace.cube_shape)
    assert sub.rank == 3 and sub.data(c) == pytest.approx(spaces.band.data(sub.to_field(c)), rel=1e-10)
    assert sub.subspace.lipschitz <= spaces.lipschitz * (1 + 1e-6)
    again = spaces.subspace(basis)
    assert again.subspace.lipschitz == sub.subspace.lipschitz and not hasattr(again.subspace.model, "power_vector")
    other = spaces.subspace(orthonormal(3, seed=5))
    assert hasattr(other.subspace.model, "power_vector")          # another basis: a power iteration of its own


def test_the_check_takes_one_exact_full_proximal_gradient_step(spaces):
    sub = spaces.subspace(orthonormal(4))
    c = np.random.default_rng(3).random(sub.subspace.cube_shape)
    step = 0.5 / spaces.lipschitz
    gain, before, stepped = spaces.full_step(sub, c, step)
    v = sub.to_field(c).copy()
    z = BACKEND.empty(v.shape)
    spaces.band.gradient_step(v, z, step)
    expected = spaces.band.prox(z, step, BACKEND.empty(v.shape))
    np.testing.assert_allclose(before, spaces.window(v), rtol=1e-12)
    np.testing.assert_allclose(stepped, spaces.window(expected), rtol=1e-10, atol=1e-14)
    data = spaces.band.data(v)
    assert gain == pytest.approx((data - spaces.band.data(expected)) / data, rel=1e-9)
    assert spaces.full_step_transforms(sub) == 4 * 4 // 2 + 4 * 8
    unjudged = spaces.full_step(sub, c, step, judged=False)
    assert unjudged[:2] == (None, None)
    np.testing.assert_array_equal(unjudged[2], stepped)          # the same step, without A·x⁺ and v's window
    assert spaces.full_step_transforms(sub, judged=False) == 4 * 4 // 2 + 4 * 8 // 2
