"""The safeguards around any algorithm (clsdcam.solve.checkpoints): the best iterate, rollback on a rise for a
monotone algorithm only, back-off on blow-up, and the best iterate restored."""
import math

import numpy as np

from clsdcam.algorithms.base import Algorithm
from clsdcam.backends import NumpyBackend
from clsdcam.solve.checkpoints import BLOWUP, Checkpoints


class Walker(Algorithm):
    """x is set from outside; reset records where it was sent."""

    def __init__(self, x, monotone=True):
        super().__init__(NumpyBackend("float64"), x, 1.0, None)
        self.x, self.monotone, self.resets = np.array(x, float), monotone, []

    def reset(self, point):
        self.x = np.array(point)
        self.resets.append(float(point[0]))


def square(x):
    return float(np.sum(x ** 2))


def test_a_rise_rolls_a_monotone_algorithm_back_to_its_best_iterate():
    walker = Walker([2.0])
    checks = Checkpoints(walker, square, np.float64)
    walker.x[:] = 1.0
    assert checks.check() == {"objective": 1.0}
    walker.x[:] = 3.0
    assert checks.check() == {"rollback": True, "objective": 1.0} and walker.resets == [1.0]


def test_a_rise_is_kept_for_an_algorithm_that_is_not_monotone_and_ctrl_c_restores_the_best():
    walker = Walker([1.0], monotone=False)
    checks = Checkpoints(walker, square, np.float64)
    walker.x[:] = 3.0
    assert checks.check() == {"objective": 9.0} and walker.resets == []
    checks.restore()
    assert walker.x[0] == 1.0


def test_a_blown_up_data_term_halves_the_step_from_the_best_iterate():
    walker = Walker([1.0])
    checks = Checkpoints(walker, square, np.float64)
    record = checks.guard({"data": 2 * BLOWUP, "change": 0.1})
    assert record["backoff"] and walker.step == 0.5 and walker.resets == [1.0]
    assert checks.guard({"data": math.nan, "change": 0.1})["step"] == 0.25


def test_without_an_objective_there_are_no_checkpoints():
    checks = Checkpoints(Walker([1.0]), None, np.float64)
    assert not checks.active and checks.best_objective == math.inf
