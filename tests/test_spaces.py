"""The spaces a solve's iterates live in (clsdcam.solve.spaces): band space is the full problem, a subspace is A·B with
its own Lipschitz constant (remembered for the same basis), and the subspace's check takes one exact full step."""
import numpy as np
import pytest

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.camera import model as model_module
from clsdcam.camera.model import ForwardModel
from clsdcam.solve.priors import build_priors
from clsdcam.solve.settings import Settings
from clsdcam.sim import simulate
from clsdcam.solve.spaces import LastLipschitz, Spaces

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


def passes(model, monkeypatch) -> list:
    """The forward passes ``model``'s power iterations make, counted into the returned list (one entry each)."""
    counted, forward = [], model.forward
    monkeypatch.setattr(model, "forward", lambda *a, **k: counted.append(1) or forward(*a, **k))
    return counted


def test_a_start_near_the_dominant_vector_with_a_faint_flat_part_converges_in_fewer_passes(spaces, monkeypatch):
    """From band space's eigenvector projected onto the basis, the power iteration at the refresh's tolerance takes
    fewer passes with REFRESH_FLAT of the flat cube than with all of it, and those fewer than from the flat cube
    alone; each ends within that tolerance of a 200-pass estimate (a lower bound)."""
    basis = orthonormal(3, seed=7)
    model = spaces.subspace(basis).subspace.model
    exact = model.lipschitz(iters=200, tol=0.0)
    start = spaces._unit(BACKEND.bandmix(spaces.model.power_vector, basis.T))
    counted, found = passes(model, monkeypatch), {}
    for name, power in {"faint": dict(start=start, flat=model_module.REFRESH_FLAT), "even": dict(start=start),
                        "cold": {}}.items():
        counted.clear()
        found[name] = (model.lipschitz(tol=model_module.REFRESH_TOL, **power), len(counted))
    assert found["faint"][1] < found["even"][1] < found["cold"][1]
    assert all(exact * (1 - model_module.REFRESH_TOL) <= value <= exact for value, _ in found.values())


def test_a_first_subspace_starts_from_band_spaces_vector_and_only_a_refresh_from_the_old_one(spaces, monkeypatch):
    """A new subspace's power iteration starts from band space's eigenvector projected (the flat cube at full weight,
    the usual tolerance); moving to a basis of the same rank starts from the old eigenvector with a faint flat part,
    the refresh's tolerance and the old L to compare with; a wider basis starts as a new subspace does."""
    calls, lipschitz = [], ForwardModel.lipschitz
    monkeypatch.setattr(ForwardModel, "lipschitz", lambda self, **k: calls.append(k) or lipschitz(self, **k))
    first = spaces.subspace(orthonormal(3, seed=9))
    spaces.onto(first, orthonormal(3, seed=10))
    spaces.onto(first, orthonormal(4, seed=11))
    assert [sorted(k) for k in calls] == [["start"], ["expected", "flat", "start", "tol"], ["start"]]
    assert all(k["start"] is not None for k in calls) and calls[1]["flat"] == model_module.REFRESH_FLAT
    assert calls[1]["expected"] == first.subspace.lipschitz


def test_a_refresh_whose_lipschitz_constant_has_not_moved_takes_one_pass(spaces, monkeypatch):
    """A basis turned by 1e-5 from the last: its L equals the old one to the refresh's tolerance, so one power pass
    confirms it (the estimate stays within that tolerance of a 200-pass one)."""
    basis = orthonormal(3, seed=12)
    first = spaces.subspace(basis)
    turned = np.linalg.qr(basis + 1e-5 * np.random.default_rng(13).standard_normal(basis.shape))[0]
    counted, forward = [], ForwardModel.forward
    monkeypatch.setattr(ForwardModel, "forward", lambda self, *a, **k: counted.append(1) or forward(self, *a, **k))
    moved, _ = spaces.onto(first, turned)
    monkeypatch.undo()
    exact = moved.subspace.model.lipschitz(iters=200, tol=0.0)
    assert len(counted) == 1 and exact * (1 - model_module.REFRESH_TOL) <= moved.subspace.lipschitz <= exact


def test_a_refresh_that_starts_at_its_dominant_vector_takes_one_pass_though_its_lipschitz_constant_moved(
        spaces, monkeypatch):
    """A refresh whose old L is 5 % off but whose start is already the new basis's dominant vector (a long run's):
    the next pass's predicted change, 4(‖AᵀAv‖/‖v‖ − λ), stops it after one pass, within the refresh's tolerance of a
    200-pass estimate. A start far from it (random, orthogonal to it, with the same faint flat part) does not stop
    there."""
    model = spaces.subspace(orthonormal(3, seed=14)).subspace.model
    exact = model.lipschitz(iters=200, tol=0.0)
    dominant = model.power_vector
    counted = passes(model, monkeypatch)
    found = model.lipschitz(start=dominant, flat=model_module.REFRESH_FLAT, tol=model_module.REFRESH_TOL,
                            expected=0.95 * exact)
    assert len(counted) == 1 and exact * (1 - model_module.REFRESH_TOL) <= found <= exact * (1 + 1e-9)
    far = np.random.default_rng(15).standard_normal(dominant.shape)
    far -= BACKEND.vdot(far, dominant) / BACKEND.vdot(dominant, dominant) * dominant
    counted.clear()
    model.lipschitz(start=spaces._unit(far), flat=model_module.REFRESH_FLAT, tol=model_module.REFRESH_TOL,
                    expected=0.95 * exact)
    assert len(counted) > 1


def test_fista_moves_to_a_basis_of_the_same_rank_in_its_own_arrays(spaces):
    """Onto a basis of the same rank the mapping keeps the shape, and FISTA writes the mapped iterates into its own
    four arrays (no new cubes), with the values of mapping each into a new one; onto a wider basis it takes new ones."""
    from clsdcam.algorithms.fista import Fista
    from clsdcam.solve.driver import Rules

    basis = orthonormal(3, seed=14)
    first = spaces.subspace(basis)
    rng = np.random.default_rng(15)
    fista = Fista(BACKEND, np.zeros(first.subspace.cube_shape), 0.1, Rules())
    fista.x, fista.x_prev, fista.y = (rng.standard_normal(first.subspace.cube_shape) for _ in range(3))
    before = [fista.x, fista.x_prev, fista.y, fista.z]
    _, mapping = spaces.onto(first, orthonormal(3, seed=16))
    expected = [mapping(a) for a in before[:3]]
    fista.move(mapping)
    assert mapping.keeps_shape and {id(a) for a in before} == {id(a) for a in (fista.x, fista.x_prev, fista.y, fista.z)}
    assert all(np.array_equal(got, want) for got, want in zip((fista.x, fista.x_prev, fista.y), expected))
    _, wider = spaces.onto(first, orthonormal(4, seed=17))
    fista.move(wider)
    assert not wider.keeps_shape and fista.x.shape[0] == 4 and all(id(a) not in {id(b) for b in before}
                                                                    for a in (fista.x, fista.x_prev, fista.y))
