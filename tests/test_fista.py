"""The FISTA loop: the t_k sequence, a closed-form problem, the stopping rules."""
import math

import numpy as np

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.fista import fista, next_momentum


def test_momentum_sequence():
    t = [1.0]
    for _ in range(5):
        t.append(next_momentum(t[-1]))
    expected = [1.0, (1 + math.sqrt(5)) / 2]
    expected.append((1 + math.sqrt(1 + 4 * expected[-1] ** 2)) / 2)
    np.testing.assert_allclose(t[:3], expected, rtol=1e-15)
    # t_k ≥ (k + 1)/2, the bound behind the O(1/k²) rate; the authors' 1 + √(1+4t²)/2 violates t² − t ≤ t_prev²
    assert all(tk >= (k + 2) / 2 for k, tk in enumerate(t))
    assert all(abs(t[k] ** 2 - t[k] - t[k - 1] ** 2) < 1e-12 for k in range(1, len(t)))


def quadratic_problem(rng, m=30, n=12, mu=0.3):
    """min ½‖Ax − b‖² + (μ/2)‖x‖², solved by x* = (AᵀA + μI)⁻¹Aᵀb."""
    a = rng.standard_normal((m, n))
    b = rng.standard_normal(m)
    lipschitz = np.linalg.norm(a, 2) ** 2
    exact = np.linalg.solve(a.T @ a + mu * np.eye(n), a.T @ b)

    def gradient_step(y, out):
        residual = a @ y - b
        out[...] = y - a.T @ residual / lipschitz
        return 0.5 * residual @ residual

    def prox(z, out):  # prox of (μ/2L)‖x‖²
        out[...] = z / (1 + mu / lipschitz)

    return gradient_step, prox, exact


def test_fista_quadratic_prior_reaches_closed_form():
    rng = np.random.default_rng(0)
    gradient_step, prox, exact = quadratic_problem(rng)
    result = fista(gradient_step, prox, NumpyBackend("float64"), np.zeros_like(exact), iters=3000)
    np.testing.assert_allclose(result.x, exact, rtol=1e-8, atol=1e-10)
    assert result.stop_reason == "iterations" and result.iterations == 3000


def test_fista_stops_on_tolerance_and_records_history():
    rng = np.random.default_rng(1)
    gradient_step, prox, exact = quadratic_problem(rng)
    result = fista(gradient_step, prox, NumpyBackend("float64"), np.zeros_like(exact), iters=5000, tol=1e-6)
    assert result.stop_reason == "tolerance"
    assert result.iterations < 5000
    assert result.history[-1]["change"] < 1e-6
    assert [r["iteration"] for r in result.history] == list(range(1, result.iterations + 1))
    assert np.linalg.norm(result.x - exact) / np.linalg.norm(exact) < 1e-4


def test_fista_should_stop_callback():
    rng = np.random.default_rng(2)
    gradient_step, prox, exact = quadratic_problem(rng)
    calls = []
    result = fista(gradient_step, prox, NumpyBackend("float64"), np.zeros_like(exact), iters=100,
                   should_stop=lambda: "interrupted" if len(calls.append(1) or calls) >= 7 else None)
    assert result.stop_reason == "interrupted" and result.iterations == 7
