"""The phases of one solve (clsdcam.solve.phases): the driver run through the spaces for the solve's budget, hooks
acting between iterations when due, and Ctrl-C ending the run with a reason."""
import numpy as np

from clsdcam.algorithms.fista import Fista
from clsdcam.sim import simulate
from clsdcam.solve.driver import Driver, Observer, Rules
from clsdcam.solve.phases import Phases
from clsdcam.solve.priors import build_priors
from clsdcam.solve.settings import Settings
from clsdcam.solve.solver import Solver
from clsdcam.solve.spaces import LastLipschitz, Spaces
from clsdcam.solve.tracker import Progress, Ranks
from clsdcam.solve.units import Units


class Hook:
    """Acts once, at iteration ``at``; records when."""

    def __init__(self, at):
        self.at, self.acted = at, []

    def due_in(self, done, iters):
        return self.at - done if not self.acted and done < self.at <= done + iters else None

    def act(self, problem, driver):
        self.acted.append(driver.iterations)


def phases_for(settings, hooks=(), progress=None):
    sim = simulate(scene="leds", shape=(32, 48), n_bands=8, seed=5)
    solver = Solver(sim.calibration, settings=settings)
    be, model = solver.backend, solver.model
    b = be.to_device(sim.measurement / np.abs(sim.measurement).max())
    priors = build_priors(be, settings, lambda name: 1.0)
    spaces = Spaces(model, b, priors, sim.calibration.filters, solver.lipschitz, LastLipschitz())
    observers = [Ranks()] + ([Progress(Units(1.0), progress)] if progress else [])
    driver = Driver(Fista(be, model.embed(np.zeros((8, 32, 48))), 1.0 / solver.lipschitz, Rules()), Rules(),
                    spaces.band.objective, observers)
    return Phases(driver, spaces, settings, settings.iters, hooks)


def test_band_space_runs_the_budget_and_a_hook_acts_when_due():
    hook = Hook(7)
    phases = phases_for(Settings(iters=12), (hook,))
    assert phases.run(warm_started=False) == "iterations"
    assert phases.driver.iterations == 12 and hook.acted == [7] and phases.basis() is None


class Heard(Observer):
    """The notes and the work between iterations the driver's observers hear."""

    def __init__(self):
        self.notes, self.work = [], []

    def on_note(self, line):
        self.notes.append(line)

    def on_work(self, transforms):
        self.work.append(transforms)


def test_a_fixed_rank_enters_its_subspace_after_the_warm_up_and_says_so_through_the_driver():
    """The entry is a note; its power iteration and each check's full step are work the observers hear."""
    phases, heard = phases_for(Settings(iters=40, rank=3)), Heard()
    phases.driver.observe(heard)
    phases.run(warm_started=False)
    assert phases.basis().shape == (8, 3) and phases.problem.rank == 3
    assert heard.notes[0].startswith("subspace: 3 spectral basis vectors") and len(heard.work) >= 3
    assert all(transforms > 0 for transforms in heard.work)


def test_ctrl_c_ends_the_run_with_its_reason(default_sigint):
    def interrupt(record):
        if record["iteration"] == 4:
            raise KeyboardInterrupt

    phases = phases_for(Settings(iters=12), progress=interrupt)
    assert phases.run(warm_started=False) == "interrupted" and phases.driver.iterations == 4
