"""The problem of one space (clsdcam.solve.problem): its gradient step, objective and solution, and the parts it
hands an algorithm's sub-problems."""
import numpy as np
import pytest

from clsdcam.backends import NumpyBackend
from clsdcam.camera.model import ForwardModel
from clsdcam.solve.problem import Problem


@pytest.fixture(scope="module")
def parts():
    rng = np.random.default_rng(1)
    be = NumpyBackend("float64")
    psf, filters = rng.random((6, 7)), rng.random((3, 6, 7))
    model = ForwardModel(be, psf, filters)
    return be, model, filters, rng.random((6, 7))


def test_the_gradient_step_is_y_minus_step_times_the_gradient_and_returns_f(parts):
    be, model, filters, b = parts
    problem = Problem(model, b, None, None, 3)
    y = np.random.default_rng(2).random(model.cube_shape)
    out = np.empty_like(y)
    data = problem.gradient_step(y, out, 0.25)
    r = model.forward(y) - b
    assert data == pytest.approx(0.5 * np.sum(r ** 2), rel=1e-12)
    np.testing.assert_allclose(out, y - 0.25 * model.adjoint(r), rtol=1e-12, atol=1e-12)


def test_the_objective_is_the_data_term_plus_the_penalty_and_the_parts_are_handed_on(parts):
    be, model, filters, b = parts
    shared = {}
    problem = Problem(model, b, None, lambda x: 3.0 * float(np.sum(x)), 3, priors=("a prior",), filters=filters,
                      shared=shared)
    x = np.ones(model.cube_shape)
    assert problem.objective(x) == pytest.approx(problem.data(x) + 3.0 * x.size)
    assert problem.priors == ["a prior"] and problem.filters is filters and problem.shared is shared
    assert problem.subspace is None and problem.to_field(x) is x and problem.solution(x) is x
    assert Problem(model, b, None, None, 3).shared == {}      # a store of its own when none is given
