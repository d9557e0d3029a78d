"""The algorithms the driver can run, by name (``Settings.algorithm``, ``--algorithm``); what one is:
:mod:`clsdcam.algorithms.base`. A new algorithm is one module here and one line below."""
from __future__ import annotations

from .admm import Admm
from .fista import Fista

ALGORITHMS = {
    "fista": Fista,
    "admm": Admm,
}
