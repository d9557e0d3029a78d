"""The solve: the Solver (one calibration), one Reconstruction per measurement, its units and Result, the
settings and priors, the problem in each space, the phases, the driver, its checkpoints and its observers
(tracker), and the skips and state. The algorithms are in :mod:`clsdcam.algorithms`."""
