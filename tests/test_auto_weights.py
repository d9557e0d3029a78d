"""The automatic-weight hook (clsdcam.solve.auto_weights): due once, at AUTO_AT, only while a weight is pending; it
chooses from the residual's noise and the driver rescores under the new objective."""
import numpy as np
import pytest

from clsdcam.solve.auto_weights import AUTO_AT, AutoWeights
from clsdcam.backends.numpy import NumpyBackend
from clsdcam.solve.priors import build_priors
from clsdcam.solve.settings import Settings

BACKEND = NumpyBackend("float64")


def hook(tv="auto") -> AutoWeights:
    return AutoWeights(build_priors(BACKEND, Settings(tv=tv), lambda name: 1.0))


@pytest.mark.parametrize("done, iters, due", [
    (0, 300, AUTO_AT), (AUTO_AT - 1, 1, 1), (AUTO_AT - 1, 5, 1), (20, 10, AUTO_AT - 20),
    (0, AUTO_AT - 1, None), (AUTO_AT, 100, None),
])
def test_due_once_at_auto_at(done, iters, due):
    assert hook().due_in(done, iters) == due


def test_nothing_is_due_without_an_auto_weight():
    assert hook(tv=1e-3).due_in(0, 300) is None


class Residual:
    """A problem whose residual is white noise of σ = 0.01, and a driver that records what it is asked."""

    backend = BACKEND

    def __init__(self):
        self.residual_buffer = np.random.default_rng(0).normal(0, 0.01, (256, 256))
        self.x, self.iterations, self.rescored, self.notes = None, AUTO_AT, [], []

    def residual(self, x):
        return self.residual_buffer

    def objective(self, x):
        return 0.0

    def rescore(self, objective):
        self.rescored.append(objective)

    def note(self, *lines):
        self.notes += lines


def test_act_chooses_from_the_noise_and_rescores():
    weights, stand_in = hook(), Residual()
    prior = weights.priors[0]
    weights.act(stand_in, stand_in)
    assert not prior.auto and weights.chosen["noise_estimate"] == pytest.approx(0.01, rel=0.05)
    assert prior.relative == pytest.approx(prior.auto_weight.for_noise(weights.chosen["noise_estimate"]))
    assert stand_in.rescored == [stand_in.objective] and "tv: auto" in stand_in.notes[0]
    assert weights.due_in(0, 300) is None
