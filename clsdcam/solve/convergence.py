"""How far the iterate still is from its limit, from the iterations' own steps (no truth, no extra arrays): the
stopping rule of ``--iters auto``.

With c_i = ‖x_{i+1} − x_i‖/‖x_{i+1}‖ (every record's ``change``), the steps of window j (W iterations) sum to

    S_j = Σ_{i in window j} c_i  ≥  ‖x_end(j) − x_start(j)‖/‖x‖.

A sequence that converges linearly, ‖x_i − x*‖ ≈ C·ρ^i, has windows that shrink by q = ρ^W each, so the road left
is the geometric tail

    d_j = S_j · q/(1 − q),      q = max(S_j/S_{j−1}, S_{j−1}/S_{j−2}, S_{j−2}/S_{j−3})   (the slowest of three)

an estimate of ‖x − x*‖/‖x*‖ (the triangle inequality makes S_j an over-estimate of the window's net move when the
momentum zig-zags: the estimate errs towards more iterations). While the windows do not shrink (q ≥ 1: a new
weight, FISTA's momentum building up again after a restart) the tail is unknown (∞) and the solve goes on; the
slowest of three ratios keeps one window cut short by a restart from passing for convergence.

Two guards, both measured on reference runs and fresh panels (docs/convergence.md, "The first readings and the
zig-zag"):

- **Trust.** The first TRUSTED − 1 finite tails after a (re)start are not reported (∞): they rest on the windows
  just after a new weight, whose ratios still carry its transient. One natural scene read 0.095 at its second window
  and stopped 0.32 dB short of its answer.
- **Zig-zag.** Where ADMM's steps alternate, one window's sum against the next can sit above 1 for thousands of
  iterations although the run has settled. Once the tail was trusted, FALLBACK_AFTER unknown tails in a row
  report the tail of windows twice as long instead, until a finite tail returns: the last 2(RATIOS + 1) window sums
  added in pairs, so the long windows, too, end with the window just closed.

The solve stops at the end of the first window whose reported distance is below the tolerance.
"""
from __future__ import annotations

import math

WINDOW = 25         # iterations a window sums
RATIOS = 3          # window-to-window ratios the rate is judged by (the slowest)
TRUSTED = 3         # the finite tails after a (re)start up to and including the first one reported
FALLBACK_AFTER = 2  # unknown tails in a row before the long windows' tail is reported
FIRST_READING = WINDOW * (RATIOS + TRUSTED)   # iterations after a (re)start before a steady decay is read


def geometric_tail(sums: list[float]) -> float:
    """d = S_j·q/(1 − q) of the last RATIOS + 1 window sums, q their slowest ratio; ∞ while there are fewer, or
    while q ≥ 1."""
    last = sums[-RATIOS - 1:]
    if len(last) <= RATIOS or not all(math.isfinite(s) for s in last):
        return math.inf
    if last[-1] == 0.0:
        return 0.0
    q = max(after / before if before > 0 else math.inf for before, after in zip(last, last[1:]))
    return last[-1] * q / (1.0 - q) if q < 1.0 else math.inf


def paired_tail(sums: list[float]) -> float:
    """The geometric tail of windows twice as long, all ending with the last window: the last 2(RATIOS + 1) sums
    added in pairs (∞ while there are fewer)."""
    last = sums[-2 * (RATIOS + 1):]
    if len(last) < 2 * (RATIOS + 1):
        return math.inf
    return geometric_tail([first + second for first, second in zip(last[::2], last[1::2])])


class WindowTail:
    """The window sums S_j and their tail d_j (the module docstring's formula)."""

    def __init__(self, window: int):
        self.window = window
        self.sums: list[float] = []     # S_j of the closed windows
        self.open = 0.0                 # the steps of the window being summed
        self.count = 0
        self.tail = math.inf            # the last closed window's d_j

    def add(self, change: float) -> bool:
        """Count one iteration's relative step; True when it closed a window (``tail`` is new)."""
        self.open += change
        self.count += 1
        if self.count < self.window:
            return False
        self.sums.append(self.open)
        self.open, self.count = 0.0, 0
        self.tail = geometric_tail(self.sums)
        return True


class DistanceEstimate:
    """The running estimate of the relative distance to the limit, ``distance``: the W-window tail once TRUSTED
    finite ones were read, the paired 2W-window tail after FALLBACK_AFTER unknown ones in a row after that (module
    docstring)."""

    def __init__(self, window: int = WINDOW):
        self.window = window
        self.restart()

    def add(self, change: float) -> bool:
        """Count one iteration's relative step; True when it closed a window (``distance`` is new)."""
        if not self.short.add(change):
            return False
        if math.isfinite(self.short.tail):
            self.finite, self.unknown = self.finite + 1, 0
            self.distance = self.short.tail if self.finite >= TRUSTED else math.inf
        else:
            self.unknown += 1
            settled = self.finite >= TRUSTED and self.unknown >= FALLBACK_AFTER
            self.distance = paired_tail(self.short.sums) if settled else math.inf
        return True

    def restart(self) -> None:
        """Forget the windows (the objective changed: the steps before belong to another limit)."""
        self.short = WindowTail(self.window)
        self.finite = self.unknown = 0                 # finite tails read; unknown ones in a row
        self.distance = math.inf
