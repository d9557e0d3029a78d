"""Each prox against a brute-force minimisation on tiny inputs; the prior table and the proximal average."""
import itertools

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.solve.priors import (PRIORS, LowRank, ProxAverage, Sparsity, SpectralSmoothness, TotalVariation,
                                  build_priors, prox_lowrank, singular_values)
from clsdcam.solve.settings import Settings

BE = NumpyBackend("float64")


def difference_rows(shape, axis, shift=None):
    """Rows of the forward-difference matrix along ``axis``; with ``shift``, only the Haar pairs of that shift."""
    index = np.arange(np.prod(shape)).reshape(shape)
    first = np.moveaxis(index, axis, 0)
    rows = []
    for i in range(first.shape[0] - 1):
        if shift is None or i % 2 == shift:
            for a, b in zip(first[i].ravel(), first[i + 1].ravel()):
                row = np.zeros(index.size)
                row[a], row[b] = -1.0, 1.0
                rows.append(row)
    return np.array(rows).reshape(-1, index.size)


def exact_l1_diff_prox(z, rows, weights, iters=20000):
    """argmin_x ½‖x − z‖² + Σ_r c_r |(Dx)_r| by projected gradient on the dual box |p_r| ≤ c_r."""
    flat = z.ravel()
    p = np.zeros(len(rows))
    step = 1.0 / max(np.linalg.norm(rows, 2) ** 2, 1e-12)
    for _ in range(iters):
        x = flat - rows.T @ p
        p = np.clip(p + step * (rows @ x), -weights, weights)
    return (flat - rows.T @ p).reshape(z.shape)


def test_soft_threshold_is_l1_prox():
    z = np.array([-2.0, -0.3, 0.0, 0.2, 1.5])
    brute = [minimize_scalar(lambda x, zi=zi: 0.5 * (x - zi) ** 2 + 0.5 * abs(x), bounds=(-5, 5), method="bounded",
                             options={"xatol": 1e-10}).x for zi in z]
    np.testing.assert_allclose(BE.soft(z, 0.5), brute, atol=1e-6)


def test_nonneg_is_projection():
    z = np.array([-1.0, 0.0, 2.0])
    np.testing.assert_array_equal(BE.nonneg(z), [0.0, 0.0, 2.0])


@pytest.mark.parametrize("shape,weights", [((1, 1, 9), (0.0, 0.0, 1.0)), ((3, 4, 5), (0.5, 1.0, 2.0))])
def test_haar_tv_is_average_of_exact_shifted_pair_proxes(shape, weights):
    """haar_tv = 1/(2D) Σ_{d,s} prox of 2D·τ·w_d Σ_{pairs of shift s along d} |x_b − x_a|, each prox brute-forced."""
    rng = np.random.default_rng(0)
    z = rng.standard_normal(shape)
    tau = 0.15
    active = [(axis, w) for axis, w in enumerate(weights) if w > 0]
    parts = []
    for (axis, w), shift in itertools.product(active, (0, 1)):
        rows = difference_rows(shape, axis, shift)
        parts.append(exact_l1_diff_prox(z, rows, np.full(len(rows), 2 * len(active) * tau * w)))
    np.testing.assert_allclose(BE.haar_tv(z, tau, weights), np.mean(parts, axis=0), atol=1e-6)


def test_haar_tv_approximates_exact_tv_prox():
    """One parallel-proximal step lowers the TV-prox objective close to its brute-force minimum."""
    rng = np.random.default_rng(1)
    shape, weights, tau = (3, 5, 6), (1.0, 1.0, 1.0), 0.05
    z = rng.standard_normal(shape)
    rows = np.vstack([difference_rows(shape, axis) for axis in range(3)])

    def objective(x):
        return 0.5 * np.sum((x - z) ** 2) + tau * np.sum(np.abs(rows @ x.ravel()))

    exact = exact_l1_diff_prox(z, rows, np.full(len(rows), tau))
    approx = BE.haar_tv(z, tau, weights)
    assert objective(exact) <= objective(approx) < objective(z)
    gap = (objective(approx) - objective(exact)) / (objective(z) - objective(exact))
    assert gap < 0.25


def test_tv_norm_matches_explicit_differences():
    rng = np.random.default_rng(2)
    x = rng.standard_normal((3, 4, 5))
    weights = (0.5, 2.0, 1.5)
    expected = sum(w * np.abs(difference_rows(x.shape, axis) @ x.ravel()).sum() for axis, w in enumerate(weights))
    assert BE.tv_norm(x, weights) == pytest.approx(expected, rel=1e-12)


def test_lowrank_prox_is_singular_value_thresholding():
    rng = np.random.default_rng(3)
    z = rng.standard_normal((6, 4, 5))
    unfolded = z.reshape(6, -1).T  # pixels × bands
    u, s, vt = np.linalg.svd(unfolded, full_matrices=False)
    threshold = 0.8 * s[2]
    expected = (u * np.maximum(s - threshold, 0)) @ vt
    result = prox_lowrank(BE, z, threshold)
    np.testing.assert_allclose(result.reshape(6, -1).T, expected, atol=1e-10)
    np.testing.assert_allclose(singular_values(BE, z)[::-1], s, rtol=1e-8)


def test_lowrank_prox_against_brute_force_nuclear_objective():
    """SVT minimises ½‖X − Z‖² + t‖X‖_*: random perturbations never do better."""
    rng = np.random.default_rng(4)
    z = rng.standard_normal((3, 2, 3))
    t = 1.0

    def objective(x):
        return 0.5 * np.sum((x - z) ** 2) + t * np.linalg.norm(x.reshape(3, -1).T, "nuc")

    best = prox_lowrank(BE, z, t)
    trials = [objective(best + 1e-2 * rng.standard_normal(z.shape)) for _ in range(300)]
    assert objective(best) <= min(trials)


def test_combined_prox_averages_terms_then_projects():
    rng = np.random.default_rng(5)
    z = rng.standard_normal((4, 5, 6))
    settings = Settings(tv_weights=(1.0, 2.0, 0.5))
    priors = [TotalVariation(BE, 0.2, settings), LowRank(BE, 0.3, settings), Sparsity(BE, 0.1, settings)]
    step = 0.5
    out = np.empty_like(z)
    ProxAverage(BE, priors, z.shape).prox(z, step, out)
    expected = np.maximum(0, (BE.haar_tv(z, step * 0.2, (0.5, 2.0, 1.0)) + prox_lowrank(BE, z, step * 0.3)
                              + BE.soft(z, step * 0.1)) / 3)
    np.testing.assert_allclose(out, expected, atol=1e-12)


def test_zero_weight_terms_are_dropped():
    assert build_priors(BE, Settings(tv=0.0), lambda name: 1.0) == []
    assert build_priors(BE, Settings(tv=1.0, tv_weights=(0.0, 0.0, 0.0)), lambda name: 1.0) == []
    z = np.array([[[-1.0, 2.0]]])
    out = np.empty_like(z)
    ProxAverage(BE, [], z.shape).prox(z, 1.0, out)
    np.testing.assert_array_equal(out, [[[0.0, 2.0]]])


def test_weights_are_relative_to_each_priors_reference():
    """Each active prior's absolute weight is its relative weight times the reference it names (asked only
    for the references an active prior needs)."""
    asked = []

    def references(name):
        asked.append(name)
        return {"atb_max": 10.0, "atb_sigma1": 100.0, "lipschitz": 1000.0}[name]

    priors = build_priors(BE, Settings(tv=0.1, lowrank=0.2, l1=0.0, spectral=0.3), references)
    assert [(p.name, p.weight) for p in priors] == [("tv", 1.0), ("lowrank", 20.0), ("spectral", 300.0)]
    assert sorted(asked) == ["atb_max", "atb_sigma1", "lipschitz"]


def test_every_prior_row_is_a_setting_and_a_flag():
    from clsdcam.cli.options import build_parser

    parser = build_parser()
    for row in PRIORS:
        assert getattr(Settings(), row.name) == row.default
        args = parser.parse_args(["reconstruct", "m.npy", "--calibration", "c.h5", "-o", "o.h5", row.flag, "0.25"])
        assert getattr(args, row.name) == 0.25


def test_spectral_smoothness_prox_minimises_its_objective():
    """prox of ½·t·Σ_p ‖D v_p‖² (second differences along λ) against scipy's minimiser, and its value."""
    from scipy.optimize import minimize

    rng = np.random.default_rng(6)
    z = rng.standard_normal((5, 2, 3))
    step, weight = 0.7, 0.4
    prior = SpectralSmoothness(BE, weight, Settings())
    d = np.diff(np.eye(5), n=2, axis=0)                        # (K−2) × K second differences

    def penalty(x):
        return 0.5 * weight * np.sum((d @ x.reshape(5, -1)) ** 2)

    brute = minimize(lambda x: 0.5 * np.sum((x - z.ravel()) ** 2) + step * penalty(x), z.ravel(), method="BFGS",
                     options={"gtol": 1e-12}).x.reshape(z.shape)
    np.testing.assert_allclose(prior.prox(z, step, np.empty_like(z)), brute, atol=1e-6)
    assert prior.value(z) == pytest.approx(penalty(z.ravel()), rel=1e-12)
    assert SpectralSmoothness(BE, 1.0, Settings()).value(np.ones((5, 2, 3)) * np.arange(5)[:, None, None]) == \
        pytest.approx(0.0, abs=1e-12)                         # straight spectra cost nothing
