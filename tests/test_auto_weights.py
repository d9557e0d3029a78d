"""The automatic-weight hook (clsdcam.solve.auto_weights): due once, at AUTO_AT, only while a weight is pending; it
chooses from the residual's noise and the driver rescores under the new objective; where the scene is not point-like,
``--converge auto`` widens the stop."""
import numpy as np
import pytest

from clsdcam.algorithms.admm import Admm, balance
from clsdcam.algorithms.admm.algorithm import NONNEG, NONNEG_FEW_POINTS, NONNEG_POINT_LIKE, TV
from clsdcam.solve import auto_weights
from clsdcam.solve.auto_weights import (AUTO_AT, FEW_POINTS_PER_PIXEL, FEW_POINTS_STOP, FEWEST_POINTS_PER_PIXEL,
                                        GOOD_LIGHT_BELOW, LIGHTER_FEW_POINTS_STOP, POINTS_IN_GOOD_LIGHT_STOP,
                                        RECOUNT_AT, SPARSE_BELOW, SPARSE_LIGHT_BELOW, SPOTS_FROM, AutoWeights,
                                        auto_tolerance, probe_reading, probed_tolerance, recount_reroutes,
                                        sparse_in_good_light)
from clsdcam.backends.numpy import NumpyBackend
from clsdcam.errors import InputError
from clsdcam.sim import simulate
from clsdcam.solve import settings
from clsdcam.solve.convergence import FIRST_READING
from clsdcam.solve.priors import AutoWeight, TotalVariation, build_priors
from clsdcam.solve.driver import Driver, Rules
from clsdcam.solve.settings import CONVERGE, CONVERGE_WIDE, Settings
from clsdcam.solve.solver import Solver, reconstruct

BACKEND = NumpyBackend("float64")


def hook(tv="auto", point_like_below: float = 0.0, wide_stop: float | None = None) -> AutoWeights:
    return AutoWeights(build_priors(BACKEND, Settings(tv=tv), lambda name: 1.0), point_like_below, wide_stop)


@pytest.mark.parametrize("done, iters, due", [
    (0, 300, AUTO_AT), (AUTO_AT - 1, 1, 1), (AUTO_AT - 1, 5, 1), (20, 10, AUTO_AT - 20),
    (0, AUTO_AT - 1, None), (AUTO_AT, 100, None),
])
def test_due_once_at_auto_at(done, iters, due):
    assert hook().due_in(done, iters) == due


def test_nothing_is_due_without_an_auto_weight():
    assert hook(tv=1e-3).due_in(0, 300) is None


class Residual:
    """A problem whose residual is white noise of σ (0.01) and whose iterate's window is ``cube``, and a driver (and
    its algorithm) that records what it is asked (its stop the driver's own, at CONVERGE)."""

    backend = BACKEND
    rules = Rules(converge=CONVERGE)
    widen_stop, narrow_stop = Driver.widen_stop, Driver.narrow_stop

    def __init__(self, sigma: float = 0.01, cube=None):
        self.residual_buffer = np.random.default_rng(0).normal(0, sigma, (256, 256))
        self.b = np.full((256, 256), 0.1)           # the measurement over its peak: q = mean(b)/max|b| ≈ 0.1
        self.b[0, 0] = 1.0
        self.x, self.iterations, self.rescored, self.notes = None, AUTO_AT, [], []
        self.cube, self.model, self.algorithm, self.told_point_like = cube, self, self, 0
        self.told_few_points, self.rerouted = None, []

    def solution(self, x):
        return self.cube

    def window_on_device(self, field):
        return field

    def residual(self, x):
        return self.residual_buffer

    def objective(self, x):
        return 0.0

    def rescore(self, objective):
        self.rescored.append(objective)

    def note(self, *lines):
        self.notes += lines

    def point_like(self, few_points):
        self.told_point_like += 1
        self.told_few_points = few_points
        return "stand-in: told"

    def lit_spots(self):
        return "stand-in: spots"

    def few_points_to_lighten(self):
        return "stand-in: a few points to lighten"

    def reroute(self, line):
        self.rerouted.append(line)


def test_act_chooses_from_the_noise_and_rescores():
    weights, stand_in = hook(), Residual()
    prior = weights.priors[0]
    weights.act(stand_in, stand_in)
    assert not prior.auto and weights.chosen["noise_estimate"] == pytest.approx(0.01, rel=0.05)
    assert prior.relative == pytest.approx(prior.auto_weight.for_noise(weights.chosen["noise_estimate"]))
    assert stand_in.rescored == [stand_in.objective] and "tv: auto" in stand_in.notes[0]
    assert weights.due_in(0, 300) is None


@pytest.mark.parametrize("noise, point_like, factor", [
    (0.003, False, 1.0),            # not point-like: the rule as it is
    (0.003, True, 0.003 / 0.009),   # point-like in good light: lighter by σ̂/σ0
    (0.02, True, 1.0),              # point-like in low light: as it is
])
def test_a_point_like_scene_in_good_light_takes_a_lighter_weight(noise, point_like, factor):
    rule = AutoWeight(start=3e-4, per_noise=0.06, lowest=1e-9, highest=1.0, point_noise=0.009)
    assert rule.for_noise(noise, point_like) == pytest.approx(0.06 * noise * factor)


@pytest.mark.parametrize("noise, lit_mean, factor", [
    (0.003, 0.2, 1.0),                           # widely lit in good light (σ̂²/q under V1): the rule as it is
    (0.0135, 0.2, 0.0135 ** 2 / (0.2 * 4e-4)),   # widely lit in low light: heavier by σ̂²/(q·V1)
    (0.0135, 0.4, 0.0135 ** 2 / (0.4 * 4e-4)),   # the same noise spread over more light: less so
    (0.0135, None, 1.0),                         # not widely lit: as it is
    (0.0135, 0.0, 1.0),                          # no mean light read (a dark-subtracted frame's q ≤ 0): as it is
])
def test_a_widely_lit_scene_in_low_light_takes_a_heavier_weight(noise, lit_mean, factor):
    rule = AutoWeight(start=3e-4, per_noise=0.06, lowest=1e-9, highest=1.0, point_noise=0.009, lit_variance=4e-4)
    assert rule.for_noise(noise, lit_mean=lit_mean) == pytest.approx(0.06 * noise * factor)
    assert rule._replace(lit_variance=None).for_noise(noise, lit_mean=lit_mean) == pytest.approx(0.06 * noise)


def test_the_heavier_weight_keeps_the_ceiling_and_a_point_like_reading_comes_first():
    rule = TotalVariation.auto_weight
    assert rule.for_noise(0.02, lit_mean=0.2) == rule.highest < 0.06 * 0.02 * 0.02 ** 2 / (0.2 * rule.lit_variance)
    assert rule.for_noise(0.003, True, 0.01) == pytest.approx(rule.for_noise(0.003, True))
    assert rule.for_noise(0.003, True) < rule.for_noise(0.003)


def test_the_lighter_weight_keeps_the_floor_and_needs_a_point_noise():
    rule = AutoWeight(start=3e-4, per_noise=0.06, lowest=1e-4, highest=1.0, point_noise=0.009)
    assert rule.for_noise(0.003, True) == pytest.approx(1e-4)           # 0.06·0.003/3 = 6e-5, below the floor
    assert rule._replace(point_noise=None).for_noise(0.003, True) == pytest.approx(0.06 * 0.003)


def one_lit_pixel() -> np.ndarray:
    cube = np.zeros((4, 32, 32))
    cube[1, 10, 10] = 2.0
    return cube


@pytest.mark.parametrize("cube, mean_over_peak, point_like", [
    (one_lit_pixel(), 1 / (4 * 32 * 32), True),
    (np.full((4, 32, 32), 0.5), 1.0, False),
    (np.zeros((4, 32, 32)), 1.0, False),            # no light: not point-like (and no division by 0)
])
def test_act_reads_how_point_like_the_iterate_is(cube, mean_over_peak, point_like):
    weights, stand_in = hook(point_like_below=0.0025), Residual(sigma=0.003, cube=cube)
    prior = weights.priors[0]
    weights.act(stand_in, stand_in)
    noise = weights.chosen["noise_estimate"]
    assert weights.chosen["mean_over_peak"] == pytest.approx(mean_over_peak)
    assert prior.relative == pytest.approx(prior.auto_weight.for_noise(noise, point_like))
    if point_like:
        assert prior.relative < prior.auto_weight.for_noise(noise)
    assert ("a point-like scene" in stand_in.notes[0]) == point_like
    assert stand_in.told_point_like == point_like          # the algorithm is told, once


def faint_field(level: float) -> np.ndarray:
    """A field of ``level`` with one voxel at 1: p = (level·(N − 1) + 1)/N."""
    cube = np.full((4, 32, 32), level)
    cube[2, 16, 16] = 1.0
    return cube


def lit_fraction(cube: np.ndarray) -> float:
    return float(cube.mean(dtype=float)) / float(cube.max())


@pytest.mark.parametrize("cube, widely_lit_above, lit", [
    (np.full((4, 32, 32), 0.5), 0.063, True),                    # p = 1
    (np.full((4, 32, 32), 0.5), float("inf"), False),            # an algorithm without the threshold
    (faint_field(0.05), 0.063, False),                           # p ≈ 0.05: between the two thresholds
    (faint_field(0.05), lit_fraction(faint_field(0.05)), True),  # at the threshold
])
def test_act_raises_the_weight_of_a_widely_lit_scene_in_low_light(cube, widely_lit_above, lit):
    weights = AutoWeights(build_priors(BACKEND, Settings(tv="auto"), lambda name: 1.0), 0.0025, None, widely_lit_above)
    stand_in = Residual(sigma=0.01, cube=cube)        # σ̂²/q above the rule's V1
    weights.act(stand_in, stand_in)
    prior, noise, q = weights.priors[0], weights.chosen["noise_estimate"], weights.chosen["measured_mean_over_peak"]
    assert q == pytest.approx(stand_in.b.mean() / stand_in.b.max()) and noise ** 2 / q > prior.auto_weight.lit_variance
    assert prior.relative == pytest.approx(prior.auto_weight.for_noise(noise, lit_mean=q if lit else None))
    assert (prior.relative > 1.5 * prior.auto_weight.for_noise(noise)) == lit
    assert ("a widely lit scene" in stand_in.notes[0]) == lit and not stand_in.told_point_like


def test_an_algorithm_without_a_threshold_is_never_point_like():
    weights, stand_in = hook(), Residual(sigma=0.003, cube=one_lit_pixel())
    weights.act(stand_in, stand_in)
    assert "mean_over_peak" not in weights.chosen and not stand_in.told_point_like
    assert weights.priors[0].relative == pytest.approx(weights.priors[0].auto_weight.for_noise(0.003), rel=0.05)


def test_a_solve_reads_the_window_of_its_iterate_and_lightens_a_point_scene(monkeypatch):
    """Through the solver: ADMM's 30-iteration cube (the sensor window it returns) is what ``mean_over_peak`` reads,
    three lit voxels in good light count as point-like and take the lighter weight, and ADMM its point-like
    non-negativity penalty for a few points (so few lit voxels a pixel are the fewest, never told point-like first),
    and the balance after the probe its wider thresholds, the solve's notes saying so; FISTA reads nothing."""
    cube = np.zeros((8, 48, 64), np.float32)
    for band, y, x in ((1, 20, 20), (4, 30, 40), (6, 15, 45)):
        cube[band, y, x] = 1.0
    sim = simulate("points", (48, 64), 8, seed=0, cube=cube)
    admm = reconstruct(sim.measurement, sim.calibration, iters=AUTO_AT, algorithm="admm")
    noise, rule = admm.attrs["noise_estimate"], TotalVariation.auto_weight
    assert admm.attrs["mean_over_peak"] == pytest.approx(admm.cube.mean(dtype=float) / admm.cube.max(), rel=1e-5)
    assert admm.attrs["mean_over_peak"] < Admm.point_like_below == 0.0025 and noise < rule.point_noise
    assert admm.attrs["tv_chosen"] == pytest.approx(rule.for_noise(noise, True))
    assert rule.for_noise(noise, True) < 0.5 * rule.for_noise(noise)
    penalties = admm.state.carry[0].penalties          # μ₂ and μ₃ share their scale (penalties_for)
    assert penalties.nonneg / penalties.tv == pytest.approx(NONNEG_FEW_POINTS / TV, rel=1e-12)   # a few points
    said = f"admm: μ₃ × {NONNEG_FEW_POINTS / NONNEG:g}, wider TV thresholds (a scene of a few points)"
    assert noise < GOOD_LIGHT_BELOW and admm.attrs["lit_per_pixel"] < FEWEST_POINTS_PER_PIXEL     # the fewest points
    assert said in admm.attrs["skips"]
    told, real = [], balance.balance
    monkeypatch.setattr(balance, "balance", lambda *a: told.append(a[3]) or real(*a))
    reconstruct(sim.measurement, sim.calibration, iters=AUTO_AT + 1, algorithm="admm")
    assert admm.attrs["lit_per_pixel"] < FEW_POINTS_PER_PIXEL and told == ["few_points"]
    fista = reconstruct(sim.measurement, sim.calibration, iters=AUTO_AT, algorithm="fista")
    assert "mean_over_peak" not in fista.attrs
    assert fista.attrs["tv_chosen"] == pytest.approx(rule.for_noise(fista.attrs["noise_estimate"]))


def test_a_solve_weighs_a_widely_lit_scene_in_low_light_more():
    """Through the solver: a cube lit everywhere, in low light, reads as widely lit at ADMM's probe and takes the
    heavier weight, its note saying so; FISTA reads nothing and keeps the noise rule."""
    spectrum = np.linspace(0.5, 1.0, 8, dtype=np.float32)[:, None, None]
    sim = simulate("lit", (48, 64), 8, seed=0, cube=spectrum * np.ones((8, 48, 64), np.float32),
                   noise_var=1e-4, photons=2e3)
    admm = reconstruct(sim.measurement, sim.calibration, iters=AUTO_AT, algorithm="admm")
    noise, rule = admm.attrs["noise_estimate"], TotalVariation.auto_weight
    q = admm.attrs["measured_mean_over_peak"]
    assert q == pytest.approx(sim.measurement.mean(dtype=float) / sim.measurement.max(), rel=1e-5)
    assert admm.attrs["mean_over_peak"] >= Admm.widely_lit_above == 0.065 and noise ** 2 / q > rule.lit_variance
    assert admm.attrs["tv_chosen"] == pytest.approx(rule.for_noise(noise, lit_mean=q))
    assert rule.for_noise(noise, lit_mean=q) > 1.5 * rule.for_noise(noise)
    assert "a widely lit scene" in admm.attrs["skips"]
    fista = reconstruct(sim.measurement, sim.calibration, iters=AUTO_AT, algorithm="fista")
    assert fista.attrs["tv_chosen"] == pytest.approx(rule.for_noise(fista.attrs["noise_estimate"]))
    assert "a widely lit scene" not in fista.attrs["skips"]


@pytest.mark.parametrize("noise, per_pixel, lighter", [
    (0.99 * GOOD_LIGHT_BELOW, FEWEST_POINTS_PER_PIXEL, True),
    (1.01 * GOOD_LIGHT_BELOW, FEWEST_POINTS_PER_PIXEL, False),          # low light
    (0.99 * GOOD_LIGHT_BELOW, 0.99 * FEWEST_POINTS_PER_PIXEL, False),   # the fewest points
])
def test_a_few_points_are_lightened_in_good_light_unless_they_are_the_fewest(noise, per_pixel, lighter):
    """The probe's third reading, at its two gates, and the stop a scene of a few points ends at:
    CONVERGE·LIGHTER_FEW_POINTS_STOP where it holds (from the recount), CONVERGE·FEW_POINTS_STOP where not; a scene
    that is not a few points is never lightened."""
    attrs = {"mean_over_peak": 0.0001, "lit_per_pixel": per_pixel, "noise_estimate": noise}
    assert probe_reading(attrs, 0.0025) == (True, True, lighter)
    assert probe_reading({**attrs, "lit_per_pixel": FEW_POINTS_PER_PIXEL}, 0.0025) == (True, False, False)
    share = LIGHTER_FEW_POINTS_STOP if lighter else FEW_POINTS_STOP
    assert auto_tolerance(CONVERGE, CONVERGE_WIDE, True, True, lighter) == pytest.approx(CONVERGE * share, rel=1e-12)


def lit_voxels(n: int, shape=(4, 128, 128)) -> np.ndarray:
    cube = np.zeros(shape)
    cube.reshape(-1)[::97][:n] = 1.0
    return cube


MANY = (32, 128, 128)     # 0.04 lit voxels a pixel: 655.36 of these, point-like (p = 655/524288 < 0.0025)


@pytest.mark.parametrize("cube, tolerance, said, few_points", [
    (lit_voxels(656, MANY), CONVERGE * POINTS_IN_GOOD_LIGHT_STOP, "a point-like scene in good light: noise 0.003 < "
     "0.005", False),                                   # point-like, not a few points, in good light
    (lit_voxels(655, MANY), CONVERGE * LIGHTER_FEW_POINTS_STOP, "a point-like scene of few lit voxels: 655, 0.03998 "
     "a pixel < 0.04; in good light, noise 0.003 < 0.005, not of the fewest, ≥ 0.012: until the recount at 180",
     False),                # a few points to lighten: told point-like until the recount, the narrower stop till then
    (lit_voxels(93, (32, 48, 48)), CONVERGE * POINTS_IN_GOOD_LIGHT_STOP, "a point-like scene in good light",
     False),                                                  # under 500 lit voxels, over 0.04 a pixel: not a few
    (lit_voxels(120), CONVERGE * FEW_POINTS_STOP, "a point-like scene of few lit voxels: 120, 0.007324 a pixel < 0.04",
     True),
    (one_lit_pixel(), CONVERGE * FEW_POINTS_STOP, "few lit voxels: 1, 0.0009766 a pixel < 0.04", True),
    (np.full((4, 32, 32), 0.5), CONVERGE_WIDE, "not a point-like scene", None),
    (np.zeros((4, 32, 32)), CONVERGE_WIDE, "not a point-like scene", None),   # a dark iterate counts as p = 1
])
def test_the_stop_widens_on_a_spread_scene_and_narrows_on_a_few_points(cube, tolerance, said, few_points):
    """--converge auto from the probe's mean/peak p and lit voxels n = sum/peak: CONVERGE_WIDE at or above the
    point-like threshold, CONVERGE·POINTS_IN_GOOD_LIGHT_STOP below it (the probe's σ̂ = 0.003 is good light; low light:
    the next test), CONVERGE·FEW_POINTS_STOP below FEW_POINTS_PER_PIXEL lit voxels a window pixel (n/(H·W)),
    CONVERGE·LIGHTER_FEW_POINTS_STOP where the scene is one to lighten (in the probe's good light, σ̂ = 0.003, and not
    of the fewest, FEWEST_POINTS_PER_PIXEL lit voxels a pixel or more), told point-like until the recount; a note says
    so where it moved. The algorithm hears whether a point-like scene is one of a few points (None: not told); what it
    says back is noted."""
    weights, stand_in = hook(point_like_below=0.0025, wide_stop=CONVERGE_WIDE), Residual(sigma=0.003, cube=cube)
    weights.act(stand_in, stand_in)
    assert stand_in.told_few_points is few_points
    assert weights.chosen["noise_estimate"] == pytest.approx(0.003, 0.05)
    assert ("stand-in: told" in stand_in.notes) == (few_points is not None)      # what the algorithm said, noted
    assert stand_in.rules.converge == pytest.approx(tolerance, rel=1e-12)
    assert probed_tolerance(weights.chosen, 0.0025, CONVERGE, CONVERGE_WIDE) == stand_in.rules.converge   # the tools'
    assert weights.chosen["lit_voxels"] == pytest.approx(cube.sum() / cube.max() if cube.any() else cube.size)
    pixels = cube.shape[1] * cube.shape[2]
    assert weights.chosen["lit_per_pixel"] == pytest.approx(weights.chosen["lit_voxels"] / pixels)
    stops = [line for line in stand_in.notes if line.startswith("stop: --converge auto, ")]
    assert [said in line for line in stops] == ([] if said is None else [True])
    assert said is None or stops[0].startswith(f"stop: --converge auto, {tolerance:.2g} (")


@pytest.mark.parametrize("sigma, wider", [(0.8 * GOOD_LIGHT_BELOW, True), (1.25 * GOOD_LIGHT_BELOW, False)])
def test_a_point_like_scene_in_good_light_stops_wider_and_in_low_light_keeps_the_stop(sigma, wider):
    """A point-like scene that is not a few points takes CONVERGE·POINTS_IN_GOOD_LIGHT_STOP where the probe's σ̂ is
    under GOOD_LIGHT_BELOW, said in a note, and keeps CONVERGE, unsaid, at or above it; a few points are narrowed
    whatever the light."""
    weights, stand_in = hook(point_like_below=0.0025, wide_stop=CONVERGE_WIDE), Residual(sigma, lit_voxels(656, MANY))
    weights.act(stand_in, stand_in)
    noise = weights.chosen["noise_estimate"]
    assert (noise < GOOD_LIGHT_BELOW) is wider and stand_in.told_few_points is False
    assert stand_in.rules.converge == pytest.approx(CONVERGE * (POINTS_IN_GOOD_LIGHT_STOP if wider else 1), rel=1e-12)
    stops = [line for line in stand_in.notes if line.startswith("stop: --converge auto, ")]
    assert stops == ([f"stop: --converge auto, {CONVERGE * POINTS_IN_GOOD_LIGHT_STOP:g} (a point-like scene in good "
                      f"light: noise {noise:.2g} < {GOOD_LIGHT_BELOW:g})"] if wider else [])
    for lighter in (False, True):
        share = LIGHTER_FEW_POINTS_STOP if lighter else FEW_POINTS_STOP
        assert auto_tolerance(CONVERGE, CONVERGE_WIDE, True, True, lighter, good_light=True) == CONVERGE * share


@pytest.mark.parametrize("every, sigma, narrow", [
    (50, 0.003, True),                      # p = 0.02 < SPARSE_BELOW, σ̂ in good light: the stop stays narrow
    (50, 0.007, True),                      # σ̂ over the points' GOOD_LIGHT_BELOW, under SPARSE_LIGHT_BELOW
    (50, 0.01, False),                      # the same scene in low light: widened
    (33, 0.003, False),                     # p = 0.0303 ≥ SPARSE_BELOW: not sparse, widened
])
def test_a_sparse_scene_in_good_light_keeps_the_narrow_stop(every, sigma, narrow):
    """A scene that is not point-like (p ≥ 0.0025) but sparse (p under SPARSE_BELOW) in good light (σ̂ under
    SPARSE_LIGHT_BELOW) keeps CONVERGE, said in a note; in low light, or at SPARSE_BELOW and above, the stop widens.
    Neither is point-like, so the algorithm is told nothing."""
    cube = np.zeros((4, 32, 32))
    cube.reshape(-1)[::every] = 1.0
    weights, stand_in = hook(point_like_below=0.0025, wide_stop=CONVERGE_WIDE), Residual(sigma=sigma, cube=cube)
    weights.act(stand_in, stand_in)
    p, noise = weights.chosen["mean_over_peak"], weights.chosen["noise_estimate"]
    assert p == pytest.approx(1 / every, rel=0.05) and noise == pytest.approx(sigma, rel=0.05)
    assert sparse_in_good_light(weights.chosen) is narrow and stand_in.told_point_like == 0
    assert stand_in.rules.converge == (CONVERGE if narrow else CONVERGE_WIDE)
    stops = [line for line in stand_in.notes if line.startswith("stop: --converge auto, ")]
    said = (f"{CONVERGE:g} (a sparse scene in good light: mean/peak {p:.2g} < {SPARSE_BELOW:g}, noise {noise:.2g} < "
            f"{SPARSE_LIGHT_BELOW:g})" if narrow else f"{CONVERGE_WIDE:g} (not a point-like scene")
    assert len(stops) == 1 and said in stops[0]


def test_no_sparse_reading_without_the_probe():
    assert not sparse_in_good_light({"noise_estimate": 0.001})
    assert auto_tolerance(CONVERGE, CONVERGE_WIDE, False, False, sparse=True) == CONVERGE
    assert auto_tolerance(CONVERGE, CONVERGE_WIDE, True, False, sparse=True) == CONVERGE


@pytest.mark.parametrize("wide_stop", [CONVERGE_WIDE, None])
@pytest.mark.parametrize("lit", [SPOTS_FROM, SPOTS_FROM - 1])
def test_a_few_points_counted_again_as_lit_spots_tell_the_algorithm_and_take_back_the_stop(lit, wide_stop):
    """A scene read as a few points at AUTO_AT (120 lit voxels, low light) is counted again at RECOUNT_AT, and only
    then: SPOTS_FROM lit voxels or more are lit spots, said in a note, the algorithm told (``lit_spots``, its line
    rerouting the driver), and a stop --converge auto narrowed (``wide_stop`` set) back to the tolerance it had;
    fewer change nothing but a note. Without --converge auto the stop never moves, but the algorithm is told all the
    same. The count is kept either way, and nothing more is due."""
    weights, stand_in = hook(point_like_below=0.0025, wide_stop=wide_stop), Residual(cube=lit_voxels(120))
    weights.act(stand_in, stand_in)
    narrowed = CONVERGE * FEW_POINTS_STOP if wide_stop else CONVERGE
    assert stand_in.rules.converge == pytest.approx(narrowed, rel=1e-12)
    assert weights.due_in(AUTO_AT, RECOUNT_AT - AUTO_AT) == RECOUNT_AT - AUTO_AT
    assert weights.due_in(AUTO_AT, RECOUNT_AT - AUTO_AT - 1) is None and weights.due_in(RECOUNT_AT, 100) is None
    stand_in.cube, stand_in.iterations = lit_voxels(lit), RECOUNT_AT
    weights.act(stand_in, stand_in)
    assert weights.chosen["lit_voxels_recounted"] == pytest.approx(lit, rel=1e-12)
    assert weights.chosen["lit_voxels"] == pytest.approx(120, rel=1e-12)        # the first count is kept
    spots = lit >= SPOTS_FROM
    assert stand_in.rules.converge == pytest.approx(CONVERGE if spots else narrowed, rel=1e-12)
    replayed = probed_tolerance(weights.chosen, 0.0025, CONVERGE, wide_stop, True) if wide_stop else CONVERGE
    assert replayed == stand_in.rules.converge                                                         # the tools'
    assert stand_in.rerouted == (["stand-in: spots"] if spots else [])      # what the algorithm said
    said = [line for line in stand_in.notes if line.startswith("recount:") or "(lit spots)" in line]
    recounted = f"recount: lit spots, not a few points ({lit} lit voxels at iteration {RECOUNT_AT} ≥ {SPOTS_FROM})"
    stop = f"stop: --converge auto, {CONVERGE:g} (lit spots)"
    few = f"recount: a few points ({lit} lit voxels at iteration {RECOUNT_AT} < {SPOTS_FROM})"
    assert said == ([recounted] + ([stop] if wide_stop else []) if spots else [few])
    assert weights.due_in(0, 10_000) is None


@pytest.mark.parametrize("wide_stop", [CONVERGE_WIDE, None])
@pytest.mark.parametrize("lit", [SPOTS_FROM, SPOTS_FROM - 1])
def test_a_few_points_to_lighten_counted_again_tell_the_algorithm_or_widen_the_stop(lit, wide_stop):
    """A scene read as a few points to lighten at AUTO_AT (655 lit voxels, 0.04 a pixel, in good light), told
    point-like, its stop --converge auto (``wide_stop`` set) at CONVERGE·LIGHTER_FEW_POINTS_STOP, is counted again at
    RECOUNT_AT, said in a note: under SPOTS_FROM lit voxels it is a few points, the algorithm told
    (``few_points_to_lighten``, its line rerouting the driver), the stop kept; at SPOTS_FROM or more it is lit spots,
    the algorithm keeps its road and the stop widens to CONVERGE·POINTS_IN_GOOD_LIGHT_STOP, said in a note. Until the
    recount the stop is the narrower of the two: the estimate's first reading, at RECOUNT_AT, comes before the
    recount acts. Without --converge auto the stop never moves, but the algorithm is told all the same."""
    weights, stand_in = hook(point_like_below=0.0025, wide_stop=wide_stop), Residual(0.003, lit_voxels(655, MANY))
    weights.act(stand_in, stand_in)
    assert stand_in.told_few_points is False and weights.due_in(AUTO_AT, RECOUNT_AT - AUTO_AT) == RECOUNT_AT - AUTO_AT
    narrowed = CONVERGE * LIGHTER_FEW_POINTS_STOP if wide_stop else CONVERGE
    assert stand_in.rules.converge == pytest.approx(narrowed, rel=1e-12)
    stand_in.cube, stand_in.iterations = lit_voxels(lit, MANY), RECOUNT_AT
    weights.act(stand_in, stand_in)
    assert weights.chosen["lit_voxels_recounted"] == pytest.approx(lit, rel=1e-12)
    few = lit < SPOTS_FROM
    widened = CONVERGE * POINTS_IN_GOOD_LIGHT_STOP if wide_stop else CONVERGE
    assert stand_in.rules.converge == pytest.approx(narrowed if few else widened, rel=1e-12)
    replayed = probed_tolerance(weights.chosen, 0.0025, CONVERGE, wide_stop, True) if wide_stop else CONVERGE
    assert replayed == stand_in.rules.converge                                                         # the tools'
    assert stand_in.rerouted == (["stand-in: a few points to lighten"] if few else [])
    said = [line for line in stand_in.notes if line.startswith("recount:") or "(lit spots)" in line]
    recounted = (f"recount: a few points ({lit} lit voxels at iteration {RECOUNT_AT} < {SPOTS_FROM})" if few else
                 f"recount: lit spots, not a few points ({lit} lit voxels at iteration {RECOUNT_AT} ≥ {SPOTS_FROM})")
    stop = f"stop: --converge auto, {widened:g} (lit spots)"
    assert said == [recounted] + ([stop] if wide_stop and not few else [])
    assert weights.due_in(0, 10_000) is None


@pytest.mark.parametrize("recounted, lit, good_light, share", [
    (False, SPOTS_FROM, True, LIGHTER_FEW_POINTS_STOP),             # to lighten, until the recount: the narrower
    (True, SPOTS_FROM - 1, True, LIGHTER_FEW_POINTS_STOP),          # recounted a few points
    (True, SPOTS_FROM, True, POINTS_IN_GOOD_LIGHT_STOP),            # recounted lit spots: point-like in good light
    (False, SPOTS_FROM, False, FEW_POINTS_STOP),                    # a few points in low light
    (True, SPOTS_FROM, False, 1.0),                                 # recounted lit spots: the untuned stop
])
def test_probed_tolerance_reads_the_probe_and_the_recount(recounted, lit, good_light, share):
    """The tolerance the tools replay, from a solve's attributes, before (``recounted`` False) and after the recount:
    the shares the hook sets (the tests above also compare it with the hook's own); without the probe, the stop
    untuned."""
    attrs = {"mean_over_peak": 0.001, "noise_estimate": 0.003 if good_light else 0.01, "lit_per_pixel": 0.02,
             "lit_voxels_recounted": lit}
    tolerance = probed_tolerance(attrs, 0.0025, CONVERGE, CONVERGE_WIDE, recounted)
    assert tolerance == pytest.approx(CONVERGE * share, rel=1e-12)
    unprobed = {"noise_estimate": 0.003}
    assert probed_tolerance(unprobed, 0.0025, CONVERGE, CONVERGE_WIDE, recounted) == CONVERGE      # no probe


@pytest.mark.parametrize("point_like, lighter, spots, rerouted", [
    (True, False, True, True), (True, False, False, False),     # a few points: lit spots reroute
    (True, True, False, True), (True, True, True, False),       # a few points to lighten: a few points reroute
    (False, False, True, False),                                # not point-like: never counted
])
def test_recount_reroutes_where_the_recount_changed_the_road(point_like, lighter, spots, rerouted):
    attrs = {"mean_over_peak": 0.001 if point_like else 0.1, "noise_estimate": 0.003 if lighter else 0.01,
             "lit_per_pixel": 0.02, "lit_voxels_recounted": SPOTS_FROM if spots else SPOTS_FROM - 1}
    assert recount_reroutes(attrs, 0.0025) is rerouted
    assert recount_reroutes({key: attrs[key] for key in list(attrs)[:3]}, 0.0025) is False      # not counted


@pytest.mark.parametrize("cube", [np.full((4, 32, 32), 0.5), lit_voxels(656, MANY)])
def test_no_recount_on_a_spread_scene_or_on_many_points(cube):
    """A spread scene, or a point-like one of more than a few points, is never counted again."""
    weights, stand_in = hook(point_like_below=0.0025, wide_stop=CONVERGE_WIDE), Residual(sigma=0.003, cube=cube)
    weights.act(stand_in, stand_in)
    assert weights.due_in(AUTO_AT, 10_000) is None and "lit_voxels_recounted" not in weights.chosen


@pytest.mark.parametrize("point_like_below, wide_stop", [(0.0, CONVERGE_WIDE), (0.0025, None)])
def test_the_stop_stays_without_a_probe_or_without_auto(point_like_below, wide_stop):
    """An algorithm without a threshold reads nothing, so the stop stays; so it does with a --converge of the user's."""
    weights, stand_in = hook(point_like_below=point_like_below, wide_stop=wide_stop), Residual(cube=np.ones((4, 8, 8)))
    weights.act(stand_in, stand_in)
    assert stand_in.rules.converge == CONVERGE and len(stand_in.notes) == 1


@pytest.mark.parametrize("settings, start, wide", [
    ({}, CONVERGE, CONVERGE_WIDE),
    ({"converge": 0.07}, 0.07, None),
    ({"iters": 50}, 0.0, None),
    ({"iters": 50, "converge": 0.07}, 0.0, None),
])
def test_converge_auto_starts_at_converge_and_may_widen_only_with_iters_auto(settings, start, wide):
    s = Settings(**settings)
    assert (s.stop_distance, s.wide_stop) == (start, wide)


@pytest.mark.parametrize("converge", ["often", 0.0, -0.1, float("nan"), float("inf")])
def test_a_converge_that_is_neither_auto_nor_positive_is_refused(converge):
    with pytest.raises(InputError, match="--converge"):
        Settings(converge=converge)


def test_a_solve_widens_its_stop_on_a_spread_scene_and_narrows_it_on_a_few_points(monkeypatch):
    """Through the solver, --iters auto: a piecewise scene stops at CONVERGE_WIDE and says so in its attributes, and
    keeps ADMM's non-negativity penalty; three points (point-like, a few lit voxels) narrow the stop to
    CONVERGE·FEW_POINTS_STOP, with their count n in the attributes, and run to the cap (here 400) with the estimate
    still above it; a tolerance the user gives is kept; a warm start from the first solve's state, whose weights it
    carries, reads no probe and keeps CONVERGE."""
    points = np.zeros((8, 48, 64), np.float32)
    for band, y, x in ((1, 20, 20), (4, 30, 40), (6, 15, 45)):
        points[band, y, x] = 1.0
    spread = simulate("piecewise", (48, 64), 8, seed=0)
    point = simulate("points", (48, 64), 8, seed=0, cube=points)
    wide = reconstruct(spread.measurement, spread.calibration)
    assert wide.attrs["mean_over_peak"] >= Admm.point_like_below and wide.attrs["stop_tolerance"] == CONVERGE_WIDE
    assert wide.state.carry[0].penalties.nonneg / wide.state.carry[0].penalties.tv == pytest.approx(NONNEG / TV)
    assert wide.stop_reason == "converged" and wide.attrs["distance_estimate"] < CONVERGE_WIDE
    with monkeypatch.context() as patch:
        patch.setattr(settings, "AUTO_CAP", 400)
        narrow = reconstruct(point.measurement, point.calibration)
    assert narrow.attrs["mean_over_peak"] < Admm.point_like_below and narrow.attrs["lit_voxels"] >= 3
    assert narrow.attrs["lit_per_pixel"] == pytest.approx(narrow.attrs["lit_voxels"] / (48 * 64), rel=1e-12)
    assert narrow.attrs["lit_per_pixel"] < FEW_POINTS_PER_PIXEL
    assert narrow.attrs["stop_tolerance"] == pytest.approx(CONVERGE * FEW_POINTS_STOP, rel=1e-12)
    assert (narrow.stop_reason, narrow.iterations) == ("iterations", 400)
    assert narrow.attrs["distance_estimate"] > narrow.attrs["stop_tolerance"]
    kept = reconstruct(spread.measurement, spread.calibration, converge=0.07)
    assert kept.attrs["stop_tolerance"] == 0.07 and kept.iterations > wide.iterations
    warm = Solver(spread.calibration).solve(spread.measurement, state=wide.state)       # weights carried: no probe
    assert "mean_over_peak" not in warm.attrs and warm.attrs["stop_tolerance"] == CONVERGE


def test_a_solve_counts_a_few_points_again_at_recount_at(monkeypatch):
    """Through the solver, --iters auto: three points narrow the stop at AUTO_AT and are counted again at RECOUNT_AT,
    gathered to about three lit voxels by then (kept in the attributes), under SPOTS_FROM: the penalties stay. With
    SPOTS_FROM at 1 the same count reads lit spots: ADMM takes a point-like scene's penalties there (μ₃ at
    NONNEG_POINT_LIKE of μ₂'s scale, the TV balanced again with the spread scenes' C), the estimate starts afresh
    (no stop before RECOUNT_AT + FIRST_READING), and the stop goes back to CONVERGE and fires (under a cap of 800)."""
    points = np.zeros((8, 48, 64), np.float32)
    for band, y, x in ((1, 20, 20), (4, 30, 40), (6, 15, 45)):
        points[band, y, x] = 1.0
    sim = simulate("points", (48, 64), 8, seed=0, cube=points)
    monkeypatch.setattr(settings, "AUTO_CAP", 400)
    told, real = [], balance.balance
    monkeypatch.setattr(balance, "balance", lambda split, state, backend, scene="spread":
                        told.append(scene) or real(split, state, backend, scene))
    few = reconstruct(sim.measurement, sim.calibration)
    assert told == ["few_points"] and "lit spots" not in few.attrs["skips"]
    assert few.attrs["lit_voxels_recounted"] == pytest.approx(3, abs=0.5) and SPOTS_FROM > 3     # gathered
    assert few.attrs["stop_tolerance"] == pytest.approx(CONVERGE * FEW_POINTS_STOP, rel=1e-12)
    monkeypatch.setattr(auto_weights, "SPOTS_FROM", 1)
    monkeypatch.setattr(settings, "AUTO_CAP", 800)
    spots = reconstruct(sim.measurement, sim.calibration)
    assert spots.attrs["lit_voxels_recounted"] == pytest.approx(few.attrs["lit_voxels_recounted"], rel=1e-6)
    assert told == ["few_points", "few_points", "spread"]   # the few points' balance at BALANCE_AT, then the spread C
    penalties = spots.state.carry[0].penalties
    assert penalties.nonneg / penalties.tv == pytest.approx(NONNEG_POINT_LIKE / TV, rel=1e-12)
    assert f"at iteration {RECOUNT_AT} ≥ 1)" in spots.attrs["skips"] and "TV balanced again" in spots.attrs["skips"]
    assert spots.attrs["stop_tolerance"] == CONVERGE and spots.stop_reason == "converged"
    assert RECOUNT_AT + FIRST_READING <= spots.iterations < 800
