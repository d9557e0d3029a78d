"""Automatic prior weights as a hook of the phases (:mod:`clsdcam.solve.phases`): weights set to ``auto``
(:mod:`clsdcam.solve.priors`) start at their rule's start and are chosen at iteration ``AUTO_AT`` from the noise
level of that iterate's residual (:func:`clsdcam.solve.noise.residual_noise`, relative to max|b|), in every space
(``--no-skip`` too); the algorithm goes on with its momentum under the new objective, and the driver's observers hear
each choice as a note (the skip report's line). A solve that ends before AUTO_AT keeps the rule's start, and its
report says so.

The same iterate says how point-like the scene is: its sensor window's mean over its peak,

    p = mean(v) / max(v),

is 0.0005–0.0013 on the simulator's narrow-line scenes and 0.0035–0.2 on the others at 128×160×64, for ADMM's
iterate; a lit fraction, it grows on smaller sensors (docs/convergence.md, "A lighter weight for point-like scenes in
good light"). Each algorithm's threshold, ``Algorithm.point_like_below``, is its own: FISTA's early iterate is
blurrier. Below it, a rule with a ``point_noise`` lightens the weight in good light
(:meth:`clsdcam.solve.priors.AutoWeight.for_noise`). A warm start from a cube (``x0``) reads its own iterate there;
a dark iterate counts as p = 1.

Below the threshold, too, the algorithm is told, and whether the scene is one of a few points, fewer than
``FEW_POINTS_PER_PIXEL`` lit voxels a window pixel (below), unless it is one to lighten, told point-like until the
recount (below): ``Algorithm.point_like`` (ADMM lightens its non-negativity penalty, and on a few points widens its
TV thresholds); one to lighten that the recount finds few is told then (``Algorithm.few_points_to_lighten``).
At or above it, the automatic stop may widen its tolerance (``wide_stop``, ``--converge auto``): the scenes the
probe passes reach the model's answer, within the rules of docs/convergence.md, at a distance of 0.1 where the
point-like ones need 0.05 ("The stop widened where the scene is not point-like"). The same iterate's count of lit
voxels is n = sum(v)/max(v) (p times the window's voxels); on a point-like scene where n over the window's H·W
pixels (p·K) is under ``FEW_POINTS_PER_PIXEL``, the tolerance narrows to

    D = ``FEW_POINTS_STOP``·0.05 = 0.01:

so few unknowns are fixed so well by the measurement that a small distance is a large loss of PSNR. With ADMM's
penalties for a few points (:meth:`clsdcam.algorithms.admm.algorithm.Admm.point_like`) the simulator's two-point and
sixteen-source scenes come within 0.2 dB and 0.5° of the answer their own run converges to at tolerances of
0.023–0.05 whatever their count ("Lighter penalties for a few points"), where under the earlier penalties they
needed 0.0011–0.05 and the stop narrowed as 0.05·(n/500)². The wider of that square and 0.01 was tried: it stopped
a fresh sixteen-source scene of 402 lit voxels 1.14 dB short of its answer.

The probe's noise σ̂ and count read a third thing: a scene of a few points in good light (σ̂ under
``GOOD_LIGHT_BELOW`` of max|b|) that is not of the fewest (at least ``FEWEST_POINTS_PER_PIXEL`` lit voxels a window
pixel), the sixteen sources rather than two points, but also the narrow-line spots of half the simulator's lines
scenes in standard light. Such a scene is told point-like until the recount (below); where that finds it a few
points, ADMM takes the few points' penalties, every one halved, and the stop is ``LIGHTER_FEW_POINTS_STOP``·0.05 =
0.02, where it finds lit spots, the point-like scenes' stop in good light (below). Until the recount the stop is
0.02, the narrower of the two: the estimate's first reading comes at the recount's iteration, before the recount acts.
So halved, the sixteen-source scenes need 0.02–0.05, where the two-point
scenes, halved, needed 0.01, and one in low light ended 0.25 dB short at 0.02 ("A wider stop for a few points in good
light"). Told a few points from AUTO_AT instead, the lines scenes read so took 1.8 times the iterations on a fresh
panel, the recount then putting them on the point-like road from a worse start, and the sixteen sources, at the cap
both ways, gained nothing (docs/convergence.md, "A few points in good light told point-like until the recount").

A point-like scene that is not a few points, read in good light (σ̂ under ``GOOD_LIGHT_BELOW``), stops at

    D = ``POINTS_IN_GOOD_LIGHT_STOP``·0.05 = 0.07:

the simulator's narrow-line scenes in standard light, whose answers are the sharpest of every panel, came within the
rules on ADMM's road with at least 0.16 dB and 0.20° to spare there, where 0.1 left 0.02 dB on one of eleven and, on a
fresh scene, stopped 0.08 dB outside (docs/convergence.md, "A wider stop for point-like scenes in good light"). So do
a few points to lighten recounted as lit spots, from the recount on. In low light, and on other few points recounted
as lit spots, the stop stays at 0.05.

A scene counted as a few points is counted again at ``RECOUNT_AT``, the first iteration the stop can fire, whose reading
comes before the recount acts (the attribute ``lit_voxels_recounted``). By then ADMM has gathered each point into a few
voxels: on the few points' road the simulator's sixteen sources count 17–35 and two points 4–21 (120×152 to 144×176),
where the narrow-line spots of its lines scenes, which at AUTO_AT count as few as sixteen sources do, still count 88–367
(128×160); on the point-like road, where a few points to lighten go, the sixteen sources count 18–53 (96×112 to 160×192)
and the lines scenes 106–396 (96×112 and 128×160). From ``SPOTS_FROM`` lit voxels the scene is one of lit spots: one
told a few points takes the algorithm's setting for a point-like scene instead (``Algorithm.lit_spots``; ADMM its
point-like penalties, the TV balanced again), and its stop goes back to the tolerance it narrowed, and one to lighten,
told point-like, widens its stop to 0.07; under it, one told point-like takes the setting for a few points to lighten
(``Algorithm.few_points_to_lighten``) and keeps the stop at 0.02. The estimate forgets its windows where that changed
the iteration. Counted in voxels, not per pixel: gathered, a point lights a few voxels whatever the sensor, where the
spots grow with the field (docs/convergence.md, "A few points counted again").

A scene that is not point-like but sparse in good light, p under ``SPARSE_BELOW`` and σ̂ under ``SPARSE_LIGHT_BELOW``
(the simulator's sparse scenes of a few sources on a dim background, in its standard light), keeps the narrow
tolerance: the measurement fixes its answer so well that the wide one stopped five such scenes of two panels
0.04–0.48 dB short of it, two beyond the rules' 0.2 dB, where the narrow one took the four run again to 0.01–0.25 dB
short, one beyond (docs/convergence.md, "Sparse scenes in good light keep the narrow stop").

On small sensors, where a few points light enough of the frame for p to pass the threshold, the stop widens as
before. Where the probe does not run (no auto weight, or an algorithm without a threshold) the tolerance stays.

A second threshold on the same p, ``Algorithm.widely_lit_above``, marks a widely lit scene, the light of its iterate
spread over the frame (ADMM: p at least 0.065, where forty-one of the simulator's forty-two low-light real cubes
measured read 0.0699–0.147 at 128×160×64, and the highest low-light scene measured to lose at the heavier weight, a
piecewise one, 0.0630; the other real cube, at 0.058, wants the heavier weight but is under the threshold). There a
rule with a ``lit_variance`` V1 makes the weight heavier in low light: it rises as σ̂²/q above V1, q the
measurement's mean over its peak (:func:`measured_mean`, the attribute ``measured_mean_over_peak``;
:meth:`clsdcam.solve.priors.AutoWeight.for_noise`; docs/convergence.md, "A heavier weight for widely lit scenes in
low light", "A lower widely lit threshold" and "The widely lit weight read per unit of mean light"). The threshold
was measured at 128×160×64; at 64×80 p moves both ways and misses one of six real cubes (0.061; the same sections). A
dark iterate (p = 1) counts as widely lit. It is measured only where the algorithm also has a point-like threshold
(the probe's one reading).

Why per pixel: at iteration 30 each point is still spread by the caustic, whose extent grows with the field, so a
scene's n grows with the sensor: sixteen sources count 173–250 at 96×112, 265–448 at 112×144, 302–621 at 128×160
and 551–655 at 160×192, but 0.015–0.030 lit voxels a pixel at every size. A gate of 500 lit voxels, set at the
first two sizes, passed a sixteen-source scene of 621 at 128×160, which then stopped at the cap 3 dB short of its
answer (docs/convergence.md, "A few points counted per pixel")."""
from __future__ import annotations

import math

from .convergence import FIRST_READING
from .noise import residual_noise

AUTO_AT = 30               # auto weights are chosen from the noise of this iteration's residual
# lit voxels (sum/peak) a window pixel below which a point-like scene is one of a few points: ADMM takes its penalties
# for a few points (Algorithm.point_like's few_points) and --converge auto narrows to FEW_POINTS_STOP of itself (a few
# points to lighten: told point-like until RECOUNT_AT, then as its recount reads them, the stop LIGHTER_FEW_POINTS_STOP
# of it until then). The simulator's two-point scenes count 0.004–0.009 a pixel, its sixteen sources 0.015–0.030
# (96×112 to 160×192, 32–48 bands), the narrow-line scenes of a 20-scene 128×160×64 panel 0.019–0.078
# (docs/convergence.md, "A few points counted per pixel")
FEW_POINTS_PER_PIXEL = 0.04
# --converge auto on a scene of a few points, as a share of --converge: the simulator's few-point scenes need 0.023–0.05
# with ADMM's penalties for them; 0.01 keeps twice the margin over the narrowest (docs/convergence.md, "Lighter
# penalties for a few points"). A fresh low-light two-point scene needed 0.018 ("A wider stop for a few points in
# good light")
FEW_POINTS_STOP = 0.2
# and on one in good light, not of the fewest (lighter_few_points): the halved sixteen-source scenes are within at
# 0.02 on 13 of 13 (96×112 to 160×192; four of them on two fresh panels)
LIGHTER_FEW_POINTS_STOP = 0.4
# --converge auto on a point-like scene that is not a few points, in good light (σ̂ under GOOD_LIGHT_BELOW), as a share
# of --converge: 0.07 keeps ADMM's road, replayed, within 0.2 dB and 0.5° of the answer with at least 0.16 dB and 0.20°
# to spare on eleven standard-light lines scenes of four panels, where 0.085 and 0.1 leave 0.05 and 0.02 dB; 6755
# iterations against more than 8475 at 0.05 (docs/convergence.md, "A wider stop for point-like scenes in good light")
POINTS_IN_GOOD_LIGHT_STOP = 1.4
# the noise σ̂ (of max|b|) under which the probe reads good light: 0.0022–0.0044 on the simulator's standard-light
# points and sources (96×112 to 160×192), 0.0057–0.0106 in its low light
GOOD_LIGHT_BELOW = 0.005
# the probe's p under which a scene that is not point-like is sparse: in good light its stop does not widen. The
# simulator's sparse scenes in standard light read 0.0058–0.0204 at 128×160×64 and stopped 0.04–0.48 dB short of their
# answer at the wide tolerance, two of five beyond 0.2 dB; its piecewise scenes read 0.040–0.058, natural 0.021–0.096,
# real 0.090–0.147, and the demo's scene 0.0091 (docs/convergence.md, "Sparse scenes in good light keep the narrow
# stop")
SPARSE_BELOW = 0.03
# the noise σ̂ (of max|b|) under which such a scene is in good light: the simulator's spread scenes read 0.0039–0.0049
# in its standard light and 0.0123–0.0162 in its low light (128×160×64), where its sparse scenes held the answer at the
# wide tolerance; 0.008 is about the geometric middle of the gap, so a light between the two keeps the narrow stop
SPARSE_LIGHT_BELOW = 0.008
# a scene counted as a few points at AUTO_AT is counted again here, the first iteration the stop can fire (the estimate
# forgot its windows at AUTO_AT and reads after FIRST_READING)
RECOUNT_AT = AUTO_AT + FIRST_READING
# lit voxels (sum/peak over the window) at RECOUNT_AT from which such a scene is one of lit spots, its stop back to
# --converge (a few points to lighten: to the point-like scenes' stop in good light): ADMM has gathered the simulator's
# sixteen sources into 17–35 and two points into 4–21 by then (120×152 to 144×176), the narrow-line spots counted as a
# few points at AUTO_AT into 104–367 (128×160), a fresh panel's into 88–314 (docs/convergence.md, "A few points counted
# again"); on the point-like road, where a few points to lighten are told to go until then, the sixteen sources into
# 18–53 and those spots into 106–396 ("A few points in good light told point-like until the recount")
SPOTS_FROM = 64
# lit voxels a window pixel under which a scene of a few points is of the fewest: the simulator's two-point scenes count
# 0.003–0.009, its sixteen sources 0.0136–0.030 at every size measured (96×112 to 160×192)
FEWEST_POINTS_PER_PIXEL = 0.012


def probe_reading(attrs: dict, point_like_below: float) -> tuple[bool, bool, bool]:
    """(point-like, a few points, a few points to lighten) from the probe's attributes ``mean_over_peak`` (p),
    ``lit_per_pixel`` (n/(H·W)) and ``noise_estimate`` (σ̂) of a solve or its result: p below the algorithm's
    threshold; then n/(H·W) below FEW_POINTS_PER_PIXEL; then :func:`lighter_few_points`. All False where the probe
    did not measure."""
    p = attrs.get("mean_over_peak")
    point_like = p is not None and p < point_like_below
    few_points = point_like and attrs["lit_per_pixel"] < FEW_POINTS_PER_PIXEL
    return point_like, few_points, few_points and lighter_few_points(attrs["noise_estimate"], attrs["lit_per_pixel"])


def recount_reading(attrs: dict) -> bool:
    """Whether the recount (``lit_voxels_recounted`` of a solve or its result, at RECOUNT_AT on a scene read as a few
    points) found lit spots, SPOTS_FROM lit voxels or more. False where it did not count."""
    return attrs.get("lit_voxels_recounted", 0.0) >= SPOTS_FROM


def recount_reroutes(attrs: dict, point_like_below: float) -> bool:
    """Whether the recount of a solve or its result changed its road (:meth:`AutoWeights.recount`): lit spots found
    on a few points told so, or a few points found on a few points to lighten, told point-like until then. False
    where it did not count."""
    _, few_points, lighter = probe_reading(attrs, point_like_below)
    return few_points and "lit_voxels_recounted" in attrs and recount_reading(attrs) != lighter


def tell_point_like(algorithm, few_points: bool, lighter: bool) -> str | None:
    """What the probe tells the algorithm of a point-like scene (``Algorithm.point_like``): whether it is one of
    ``few_points``, unless it is one to make ``lighter``, told point-like until the recount. The algorithm's line."""
    return algorithm.point_like(few_points and not lighter)


def tell_recount(algorithm, lighter: bool) -> str | None:
    """What a recount that changed the road (:func:`recount_reroutes`) tells the algorithm: a few points found on one
    to make ``lighter`` (``Algorithm.few_points_to_lighten``), else lit spots found on a few points
    (``Algorithm.lit_spots``). The algorithm's line."""
    return algorithm.few_points_to_lighten() if lighter else algorithm.lit_spots()


def widely_lit(attrs: dict, widely_lit_above: float) -> bool:
    """Whether the probe's p (``mean_over_peak``) is at least the algorithm's ``widely_lit_above``: a scene whose light
    spreads over the frame, where the weight rises in low light (``AutoWeight.for_noise``). False where the probe did
    not measure."""
    p = attrs.get("mean_over_peak")
    return p is not None and p >= widely_lit_above


def in_good_light(noise: float) -> bool:
    """Whether the probe's noise σ̂ (of max|b|) reads good light for a point-like scene: under GOOD_LIGHT_BELOW."""
    return noise < GOOD_LIGHT_BELOW


def lighter_few_points(noise: float, lit_per_pixel: float) -> bool:
    """A scene of a few points read in good light (:func:`in_good_light`) and not of the fewest (at least
    FEWEST_POINTS_PER_PIXEL lit voxels a pixel): told point-like until the recount; where that finds them few, ADMM
    halves its penalties there, and the stop is wider than on other few points."""
    return in_good_light(noise) and lit_per_pixel >= FEWEST_POINTS_PER_PIXEL


def sparse_in_good_light(attrs: dict) -> bool:
    """Whether the probe read a sparse scene in good light: p (``mean_over_peak``) under SPARSE_BELOW and σ̂
    (``noise_estimate``) under SPARSE_LIGHT_BELOW. False where the probe did not measure."""
    p = attrs.get("mean_over_peak")
    return p is not None and p < SPARSE_BELOW and attrs["noise_estimate"] < SPARSE_LIGHT_BELOW


def auto_tolerance(converge: float, wide: float, point_like: bool, few_points: bool, lighter: bool = False,
                   sparse: bool = False, good_light: bool = False) -> float:
    """``--converge auto``'s tolerance from the probe's reading (:func:`probe_reading`, :func:`sparse_in_good_light`,
    the module docstring): ``wide`` on a scene that is not point-like, unless ``sparse`` in good light
    (``converge``); on a point-like one, FEW_POINTS_STOP·``converge`` on a scene of a few points
    (LIGHTER_FEW_POINTS_STOP· on one to lighten), else POINTS_IN_GOOD_LIGHT_STOP·``converge`` in ``good_light`` and
    ``converge`` in low light."""
    if not point_like:
        return converge if sparse else wide
    if few_points:
        return converge * (LIGHTER_FEW_POINTS_STOP if lighter else FEW_POINTS_STOP)
    return converge * POINTS_IN_GOOD_LIGHT_STOP if good_light else converge


def probed_tolerance(attrs: dict, point_like_below: float, converge: float, wide: float,
                     recounted: bool = False) -> float:
    """``--converge auto``'s tolerance (:func:`auto_tolerance`) from the probe's attributes of a solve or its result
    (:func:`probe_reading`, :func:`sparse_in_good_light`, ``noise_estimate``), ``converge`` untuned; where
    ``recounted`` (after RECOUNT_AT), lit spots found on a few points stop as a point-like scene that is not a few
    points, in good light on those to lighten (where the wider stop was judged), at ``converge`` on the others. Until
    the recount a few points to lighten take the narrower of their two stops, LIGHTER_FEW_POINTS_STOP·``converge``:
    the stop's first reading comes at the recount's iteration, before it acts. Where the probe did not measure, the
    stop stays at ``converge``."""
    if "mean_over_peak" not in attrs:
        return converge
    point_like, few_points, lighter = probe_reading(attrs, point_like_below)
    spots = recounted and recount_reading(attrs)
    good_light = lighter if spots else in_good_light(attrs["noise_estimate"])
    return auto_tolerance(converge, wide, point_like, few_points and not spots, lighter, sparse_in_good_light(attrs),
                          good_light)


def measured_mean(problem) -> float:
    """q = mean(b)/max|b| of the problem's measurement (it holds b/max|b|): the light's spread over the sensor, which
    sets how much of σ̂ (of the peak) is shot noise (:meth:`clsdcam.solve.priors.AutoWeight.for_noise`)."""
    return float(problem.backend.to_host(problem.b).mean(dtype=float))


def window_reading(problem, x) -> tuple[float, int, int]:
    """(p, voxels, bands) of the iterate ``x``'s sensor window: its mean over its peak (1 where it is dark), its
    voxels and its bands. The window of a solution is non-negative, so its sum and peak are the backend's ℓ₁ norm and
    max|·| (on a device, two reductions: the window is not downloaded)."""
    be, window = problem.backend, problem.model.window_on_device(problem.solution(x))
    voxels, peak = math.prod(window.shape), be.amax(window)
    return (be.l1_norm(window) / voxels / peak if peak > 0 else 1.0), voxels, window.shape[0]


class AutoWeights:
    """The auto-weighted priors of one solve, chosen once at AUTO_AT, and a few points counted again at
    RECOUNT_AT."""

    def __init__(self, priors: list, point_like_below: float = 0.0, wide_stop: float | None = None,
                 widely_lit_above: float = math.inf):
        self.priors = priors
        self.point_like_below = point_like_below      # the algorithm's threshold on p (0: never point-like)
        self.widely_lit_above = widely_lit_above      # and the one at or above which it is widely lit (∞: never)
        self.wide_stop = wide_stop                    # the stop's tolerance where p passes (None: it stays)
        self.chosen: dict = {}          # what was chosen, for the result's attributes
        self._recount_due = False       # a few points read at AUTO_AT, not yet counted again
        self._untuned: float | None = None   # the stop's tolerance before the probe tuned it (None: not tuned)

    def due_in(self, done: int, iters: int) -> int | None:
        """Iterations from ``done`` until the hook acts (at AUTO_AT while a weight is pending, at RECOUNT_AT while a
        recount is due), when that is within the next ``iters``; else None."""
        if any(prior.auto for prior in self.priors):
            at = AUTO_AT
        elif self._recount_due:
            at = RECOUNT_AT
        else:
            return None
        return at - done if done < at <= done + iters else None

    def act(self, problem, driver) -> None:
        """The weights chosen (:meth:`choose`) while one is pending, else the recount (:meth:`recount`)."""
        if any(prior.auto for prior in self.priors):
            self.choose(problem, driver)
        else:
            self.recount(problem, driver)

    def choose(self, problem, driver) -> None:
        """Choose from the noise σ̂ of the residual at the driver's iterate, noted to its observers; the driver
        rescores under the new F."""
        noise = self.chosen["noise_estimate"] = residual_noise(problem.backend.to_host(problem.residual(driver.x)))
        self._measure_likeness(problem, driver.x)
        point_like, few_points, lighter = probe_reading(self.chosen, self.point_like_below)
        lit = widely_lit(self.chosen, self.widely_lit_above)
        q = self.chosen["measured_mean_over_peak"] = measured_mean(problem)
        for prior in (prior for prior in self.priors if prior.auto):
            prior.set_relative(prior.auto_weight.for_noise(noise, point_like, q if lit else None))
            prior.auto = False
            scene = "; a point-like scene" if point_like else "; a widely lit scene" if lit else ""
            driver.note(f"{prior.name}: auto, {prior.relative:.3g} (noise σ ≈ {noise:.3g} of max|b|, from the "
                        f"residual at iteration {driver.iterations}{scene})")
        driver.rescore(problem.objective)
        if point_like:
            driver.note(tell_point_like(driver.algorithm, few_points, lighter))
        self._recount_due = few_points
        if self.wide_stop and "mean_over_peak" in self.chosen:
            self._tune_stop(driver, point_like, few_points, lighter)

    def _tune_stop(self, driver, point_like: bool, few_points: bool, lighter: bool) -> None:
        """``--converge auto`` from the probe's reading (:func:`probed_tolerance`, the module docstring): widened on a
        scene that is not point-like unless it is sparse in good light, less on a point-like one in good light,
        narrowed on a scene of a few points (a few points to lighten until the recount); said in a note."""
        p, n, per_pixel = (self.chosen[name] for name in ("mean_over_peak", "lit_voxels", "lit_per_pixel"))
        noise = self.chosen["noise_estimate"]
        self._untuned = driver.rules.converge
        tolerance = probed_tolerance(self.chosen, self.point_like_below, self._untuned, self.wide_stop)
        if not point_like and sparse_in_good_light(self.chosen):
            driver.note(f"stop: --converge auto, {driver.rules.converge:g} (a sparse scene in good light: mean/peak "
                        f"{p:.2g} < {SPARSE_BELOW:g}, noise {noise:.2g} < {SPARSE_LIGHT_BELOW:g})")
        elif not point_like:
            driver.widen_stop(tolerance)
            driver.note(f"stop: --converge auto, {driver.rules.converge:g} (not a point-like scene: mean/peak "
                        f"{p:.2g} ≥ {self.point_like_below:g})")
        elif few_points:
            driver.narrow_stop(tolerance)
            lighten = (f"; in good light, noise {noise:.2g} < {GOOD_LIGHT_BELOW:g}, not of the fewest, ≥ "
                       f"{FEWEST_POINTS_PER_PIXEL:g}: until the recount at {RECOUNT_AT}") if lighter else ""
            driver.note(f"stop: --converge auto, {driver.rules.converge:.2g} (a point-like scene of few lit voxels: "
                        f"{n:.3g}, {per_pixel:.4g} a pixel < {FEW_POINTS_PER_PIXEL:g}{lighten})")
        elif in_good_light(noise):
            driver.widen_stop(tolerance)
            driver.note(f"stop: --converge auto, {driver.rules.converge:g} (a point-like scene in good light: noise "
                        f"{noise:.2g} < {GOOD_LIGHT_BELOW:g})")

    def recount(self, problem, driver) -> None:
        """At RECOUNT_AT on a scene the probe read as a few points: its lit voxels n counted again (the attribute
        ``lit_voxels_recounted``; the module docstring), said in a note. Where that changed its road
        (:func:`recount_reroutes`) the algorithm is told: ``Algorithm.few_points_to_lighten`` on a few points to
        lighten found few, ``Algorithm.lit_spots`` on other few points found to be lit spots (the estimate forgets its
        windows where that changed the iteration). A stop the probe tuned takes the recounted tolerance
        (:func:`probed_tolerance`): wider where lit spots were found."""
        self._recount_due = False
        p, voxels, _ = window_reading(problem, driver.x)
        n = self.chosen["lit_voxels_recounted"] = p * voxels
        spots = recount_reading(self.chosen)
        driver.note(f"recount: lit spots, not a few points ({n:.0f} lit voxels at iteration {driver.iterations} ≥ "
                    f"{SPOTS_FROM})" if spots else
                    f"recount: a few points ({n:.0f} lit voxels at iteration {driver.iterations} < {SPOTS_FROM})")
        if recount_reroutes(self.chosen, self.point_like_below):
            driver.reroute(tell_recount(driver.algorithm, probe_reading(self.chosen, self.point_like_below)[2]))
        if self._untuned is not None and spots:
            driver.widen_stop(probed_tolerance(self.chosen, self.point_like_below, self._untuned, self.wide_stop,
                                               recounted=True))
            driver.note(f"stop: --converge auto, {driver.rules.converge:g} (lit spots)")

    def _measure_likeness(self, problem, x) -> None:
        """The iterate's window's p = mean/max, kept as the attribute ``mean_over_peak``, n = p times the window's
        voxels as ``lit_voxels`` and n over its pixels as ``lit_per_pixel`` (:func:`probe_reading` reads them); not
        measured where the algorithm's threshold is 0."""
        if not self.point_like_below:
            return
        p, voxels, bands = window_reading(problem, x)
        self.chosen["mean_over_peak"] = p
        self.chosen["lit_voxels"] = p * voxels
        self.chosen["lit_per_pixel"] = p * bands      # n/(H·W) = p·K

    def unchosen(self, driver) -> None:
        """Say, for each weight still pending after the driver's solve (fewer than AUTO_AT iterations), that the
        solve used its rule's start."""
        for prior in (prior for prior in self.priors if prior.auto):
            driver.note(f"{prior.name}: auto needs {AUTO_AT} iterations to read the noise; this "
                        f"{driver.iterations}-iteration solve used the rule's start {prior.relative:.3g}")
