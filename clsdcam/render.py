"""Pictures of a reconstructed cube: false colour, sum projections, spectra, convergence.

A cube is a (K, H, W) array with band wavelengths (K,) in nm (any K ≥ 1, non-uniform or
unsorted spacing, possibly outside the visible range). Colour matching is the CIE 1931 2° observer's, to sRGB
(:mod:`clsdcam.colorimetry`: a shipped table, no colour-science). matplotlib is imported inside the
functions so that ``import clsdcam.render`` stays cheap; figures are drawn on an Agg canvas
of their own (pyplot's global state and backend are left alone, so nothing leaks in batch
runs) and every PNG is written through :func:`clsdcam.io.atomic_output`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import InputError
from .io import atomic_output
from .picks import spectrum_points

PERCENTILE = 99.5          # display white: this percentile of the brightest channel
SINGLE_BAND_WIDTH = 10.0   # nm, nominal width of a lone band (only used for plotting)
RADIANCE = "radiance (calibration units)"    # a cube's values: the calibration's units (docs/conventions.md)
TRUTH_KEYS = (("-", "solid: the cube"), ("--", "dashed: the truth"))   # the legend's key beside a truth
SPECTRUM_COLOURS = ("tab:red", "tab:blue", "tab:green", "tab:orange", "tab:purple", "tab:brown")


# ---- validation ------------------------------------------------------------------------
def _check(cube, wavelengths, truth=None, points=None):
    """(cube float32, wavelengths float64, truth or None, points or None), or InputError."""
    cube = np.asarray(cube)
    if cube.ndim != 3 or min(cube.shape) < 1 or cube.dtype.kind not in "biuf":
        raise InputError(f"cube: expected a real (K, H, W) array with K, H, W ≥ 1, got shape {cube.shape} "
                         f"dtype {cube.dtype}")
    cube = cube.astype(np.float32, copy=False)
    if not np.isfinite(cube).all():
        raise InputError(f"cube: {int((~np.isfinite(cube)).sum())} non-finite values (NaN/Inf)")
    wavelengths = np.asarray(wavelengths, dtype=np.float64).ravel()
    if wavelengths.shape != (cube.shape[0],) or not np.isfinite(wavelengths).all():
        raise InputError(f"wavelengths: expected {cube.shape[0]} finite values (one per band), "
                         f"got {wavelengths.size}")
    if truth is not None:
        truth = np.asarray(truth)
        if truth.shape != cube.shape:
            raise InputError(f"truth: shape {truth.shape} differs from the cube's {cube.shape}")
        truth = truth.astype(np.float32, copy=False)
    if points is not None:
        points = [_check_point(p, cube.shape[1:]) for p in points]
    return cube, wavelengths, truth, points


def _check_point(point, shape):
    """(y, x) as ints inside an image of ``shape`` (H, W), or InputError."""
    try:
        y, x = (int(v) for v in point)
    except (TypeError, ValueError):
        raise InputError(f"points: {point!r} is not a (y, x) pair of integers") from None
    if not (0 <= y < shape[0] and 0 <= x < shape[1]):
        raise InputError(f"points: ({y}, {x}) lies outside the {shape[0]}×{shape[1]} image")
    return y, x


# ---- spectral helpers ------------------------------------------------------------------
def band_edges(wavelengths) -> np.ndarray:
    """Edges (K+1,) of bands around increasing centres λ_k: midpoints (λ_k + λ_{k+1})/2 inside,
    the ends mirrored (λ_0 − (λ_1 − λ_0)/2, λ_{K−1} + (λ_{K−1} − λ_{K−2})/2); a lone band is
    λ_0 ± SINGLE_BAND_WIDTH/2."""
    centres = np.asarray(wavelengths, dtype=np.float64)
    if centres.size == 1:
        return centres[0] + np.array([-0.5, 0.5]) * SINGLE_BAND_WIDTH
    mids = 0.5 * (centres[1:] + centres[:-1])
    return np.concatenate([[2 * centres[0] - mids[0]], mids, [2 * centres[-1] - mids[-1]]])


def band_widths(wavelengths) -> np.ndarray:
    """Δλ_k (K,) in the input order: the width of band k between the edges of the sorted centres,
    Δλ_k = (λ_{k+1} − λ_{k−1})/2 inside and the one-sided spacing at the ends."""
    wavelengths = np.asarray(wavelengths, dtype=np.float64)
    order = np.argsort(wavelengths, kind="stable")
    widths = np.empty_like(wavelengths)
    widths[order] = np.diff(band_edges(wavelengths[order]))
    return widths


def _rgb_weights(wavelengths):
    """Per-band linear-sRGB weights (K, 3), or None when no colour is defined (K == 1 or no band
    inside the CMF range).

    w_k = (x̄, ȳ, z̄)(λ_k) · Δλ_k · A, with the CIE 1931 2° CMFs linearly interpolated at λ_k (zero
    outside their tabulated range) and A the 3×3 XYZ → linear sRGB matrix with the equal-energy
    illuminant E as the source white, so that a spectrally flat scene renders as neutral grey (the
    CAT02 adaptation E → D65 is part of A: :func:`clsdcam.colorimetry.xyz_to_linear_srgb`).
    """
    from .colorimetry import colour_matching_functions, xyz_to_linear_srgb

    if wavelengths.size == 1:
        return None
    table_nm, table = colour_matching_functions()
    cmf = np.stack([np.interp(wavelengths, table_nm, table[:, i], left=0.0, right=0.0) for i in range(3)], axis=1)
    if not cmf.any():
        return None
    return (cmf * band_widths(wavelengths)[:, None]) @ xyz_to_linear_srgb()


def _to_display(rgb):
    """Linear (H, W, 3) → displayable sRGB in [0, 1]: clip negatives, divide by the PERCENTILE-th
    percentile of max(R, G, B) (the maximum if that is 0), clip to 1, apply the sRGB encoding."""
    from .colorimetry import srgb_encode

    rgb = np.clip(rgb, 0.0, None)
    brightest = rgb.max(axis=-1)
    scale = np.percentile(brightest, PERCENTILE)
    scale = scale if scale > 0 else brightest.max()
    if scale > 0:
        rgb = np.clip(rgb / scale, 0.0, 1.0)
    return srgb_encode(rgb)


def false_colour(cube, wavelengths) -> np.ndarray:
    """(H, W, 3) sRGB image in [0, 1] of a (K, H, W) cube.

    XYZ(y, x) = Σ_k cmf(λ_k) Δλ_k v_k(y, x) with the CIE 1931 2° colour matching functions, then
    XYZ → linear sRGB (equal-energy white → D65), both folded into one (K, 3) weight matrix and
    applied in one tensordot; then the display normalisation of :func:`_to_display`. When K == 1
    or no band lies within the CMF range (e.g. all infrared) the image is the grey band sum
    Σ_k v_k, normalised the same way.
    """
    cube, wavelengths, _, _ = _check(cube, wavelengths)
    weights = _rgb_weights(wavelengths)
    if weights is None:
        rgb = np.repeat(cube.sum(axis=0, dtype=np.float64)[..., None], 3, axis=2)
    else:
        rgb = np.tensordot(cube, weights.astype(np.float32), axes=(0, 0))
    return _to_display(rgb)


# ---- figures ---------------------------------------------------------------------------
def new_figure(layout="constrained", **kwargs):
    """A matplotlib Figure on its own Agg canvas (no pyplot state, nothing to close); ``layout="compressed"`` for a
    row of images of fixed aspect, whose titles and labels constrained layout can push off the canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(layout=layout, **kwargs)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path: Path) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically and release its artists."""
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    fig.clear()
    return path


def projections_figure(cube, wavelengths, image):
    """False-colour ``image`` plus the sum projections P_xλ(λ, x) = Σ_y v(λ, y, x) and
    P_yλ(y, λ) = Σ_x v(λ, y, x), drawn on band edges (nm) so non-uniform bands keep their widths.
    Expects increasing wavelengths."""
    k, h, w = cube.shape
    edges = band_edges(wavelengths)
    fig = new_figure(figsize=(15, 4.8))
    ax_img, ax_x, ax_y = fig.subplots(1, 3)
    ax_img.imshow(image, interpolation="nearest")
    ax_img.set(title="false colour (CIE 1931 → sRGB)", xlabel="x (px)", ylabel="y (px)")
    mesh = ax_x.pcolormesh(np.arange(w + 1) - 0.5, edges, cube.sum(axis=1), shading="flat")
    ax_x.set(title="x–λ projection (sum over y)", xlabel="x (px)", ylabel="wavelength (nm)")
    fig.colorbar(mesh, ax=ax_x, label=f"{RADIANCE}, summed over y")
    mesh = ax_y.pcolormesh(edges, np.arange(h + 1) - 0.5, cube.sum(axis=2).T, shading="flat")
    ax_y.set(title="y–λ projection (sum over x)", xlabel="wavelength (nm)", ylabel="y (px)")
    ax_y.invert_yaxis()
    fig.colorbar(mesh, ax=ax_y, label=f"{RADIANCE}, summed over x")
    return fig


def spectra_figure(cube, wavelengths, image, points, truth=None):
    """v(λ, y, x) against λ at each (y, x) in ``points`` (solid), the truth dashed, both in the colour of the light
    there (:func:`_light_colour`), and the points numbered on the false-colour ``image``."""
    from matplotlib.patheffects import withStroke

    outline = [withStroke(linewidth=3, foreground="black")]
    fig = new_figure(figsize=(12, 4.8))
    ax_img, ax_spec = fig.subplots(1, 2, width_ratios=(1, 1.6))
    ax_img.imshow(image, interpolation="nearest")
    ax_img.set(title="points", xlabel="x (px)", ylabel="y (px)")
    weights = _rgb_weights(wavelengths)
    for i, (y, x) in enumerate(points):
        colour = _light_colour((cube if truth is None else truth)[:, y, x], weights)
        ax_img.plot(x, y, "o", mfc="none", mec="white", ms=10, mew=1.5, path_effects=outline)
        ax_img.annotate(str(i + 1), (x, y), xytext=(6, 6), textcoords="offset points", color="white",
                        fontweight="bold", path_effects=outline)
        ax_spec.plot(wavelengths, cube[:, y, x], ".-", color=colour, label=f"{i + 1}: (y={y}, x={x})")
        if truth is not None:
            ax_spec.plot(wavelengths, truth[:, y, x], "--", color=colour)
    ax_spec.set(title="spectra", xlabel="wavelength (nm)", ylabel=RADIANCE)
    ax_spec.grid(alpha=0.3)
    if points:
        legend_beside(ax_spec, truth is not None)
    return fig


def legend_beside(ax, with_truth: bool):
    """The legend of ``ax``'s labelled curves right of its axes, where it hides none of them; ``with_truth``: then
    what the solid and dashed lines are (TRUTH_KEYS, grey)."""
    from matplotlib.lines import Line2D

    keys = TRUTH_KEYS if with_truth else ()
    handles = ax.get_legend_handles_labels()[0] + [Line2D([], [], ls=style, color="0.3", label=text)
                                                   for style, text in keys]
    ax.legend(handles=handles, fontsize="small", loc="upper left", bbox_to_anchor=(1.02, 1), borderaxespad=0)


def _light_colour(spectrum, weights) -> tuple:
    """The colour a spectrum is drawn in: its linear sRGB (``weights`` of :func:`_rgb_weights`) at full brightness
    ×0.85; dark grey when that is nearly neutral (white light), black, or undefined, so that it shows on white."""
    rgb = np.zeros(3) if weights is None else np.clip(np.asarray(spectrum, np.float64) @ weights, 0.0, None)
    if rgb.max() <= 0 or rgb.min() > 0.5 * rgb.max():
        return (0.25, 0.25, 0.25)
    return tuple(0.85 * rgb / rgb.max())


def profiles_figure(image, grey, point, truth=None):
    """A one-band cube (a plain DiffuserCam): the grey ``image`` (H, W) with the row and column through
    ``point`` = (y, x) marked, and the intensity along both (the truth's dashed)."""
    y, x = point
    fig = new_figure(figsize=(12, 4.8))
    ax_img, ax_prof = fig.subplots(1, 2, width_ratios=(1, 1.6))
    ax_img.imshow(grey, cmap="gray", interpolation="nearest")
    ax_img.axhline(y, color="tab:red", lw=1)
    ax_img.axvline(x, color="tab:blue", lw=1)
    ax_img.set(title="image", xlabel="x (px)", ylabel="y (px)")
    for profile, reference, colour, label in ((image[y], None if truth is None else truth[y], "tab:red", f"row y={y}"),
                                              (image[:, x], None if truth is None else truth[:, x], "tab:blue",
                                               f"column x={x}")):
        ax_prof.plot(profile, color=colour, label=label)
        if reference is not None:
            ax_prof.plot(reference, "--", color=colour)
    ax_prof.set(title="line profiles", xlabel="position (px)", ylabel=RADIANCE)
    ax_prof.grid(alpha=0.3)
    legend_beside(ax_prof, truth is not None)
    return fig


def convergence_figure(history):
    """The two curves a solve records, against the iterations done, on a log axis; both are halved squared norms
    in the measurement's units squared (the solver's records times max|b|², so they compare with each other):

    - objective F(x) = ½‖A·x − b‖² + the priors' penalties at the iterate x after step k, evaluated at checkpoints
      only (iteration 1, every ``objective_every`` and the last) and the best so far (a rise is rolled back), dots;
    - data term f(y) = ½‖A·y − b‖² at the point y that step k started from (FISTA's extrapolated point; the start
      for k = 1, so ½‖b‖² from a zero start), a line drawn at k − 1: the iterations done when y was reached.

    Without the shift, step k's data term (taken before the step, at y) would sit beside the objective after
    it, above it at k = 1 by the whole first step. Non-finite and non-positive values are left out."""
    try:
        iterations = np.array([r["iteration"] for r in history], dtype=np.float64)
        series = {key: np.array([r.get(key, np.nan) for r in history], dtype=np.float64)
                  for key in ("objective", "data")}
    except (TypeError, KeyError, ValueError, AttributeError):
        raise InputError("history: expected a list of dicts with numeric 'iteration', 'data' and 'objective'") from None
    fig = new_figure(figsize=(7.5, 4.5))
    ax = fig.subplots()
    curves = (("objective", iterations, "o", "objective F(x) = ½‖A·x − b‖² + priors, at checkpoints"),
              ("data", iterations - 1, "-", "data term ½‖A·y − b‖² at the point the next step starts from"))
    for key, at, style, label in curves:
        keep = np.isfinite(series[key]) & (series[key] > 0)
        if keep.any():
            ax.plot(at[keep], series[key][keep], style, ms=4, label=label)
    if ax.lines:
        ax.set_yscale("log")
        ax.legend(fontsize="small")
    seconds = history[-1].get("seconds", np.nan)
    ax.set(title=f"convergence: {len(history)} iterations in {seconds:.3g} s", xlabel="iterations done",
           ylabel="value (measurement units²)")
    ax.grid(alpha=0.3, which="both")
    return fig


def save_pictures(prefix, cube, wavelengths, history=None, points=None, truth=None) -> list[Path]:
    """Write ``{prefix}_falsecolour.png``, ``_projections.png``, ``_spectra.png`` and, when ``history`` is a
    non-empty list, ``_convergence.png``; return their paths. A one-band cube (a plain DiffuserCam) gets
    ``_image.png`` (grey) and ``_profiles.png`` (row and column through its first point) instead of the colour,
    projection and spectrum pictures.

    ``points`` are (y, x) pixels for the spectra (default: one per distinct lit region of the truth when given,
    else of the cube: :func:`clsdcam.picks.spectrum_points`), numbered on the false-colour image; ``truth`` is a
    cube of the same shape drawn dashed. Bands are sorted by wavelength first. Bad shapes or points raise
    InputError before anything is written.
    """
    cube, wavelengths, truth, points = _check(cube, wavelengths, truth, points)
    order = np.argsort(wavelengths, kind="stable")
    cube, wavelengths = cube[order], wavelengths[order]
    truth = None if truth is None else truth[order]
    image = false_colour(cube, wavelengths)
    points = spectrum_points(cube if truth is None else truth, wavelengths) if points is None else points
    if cube.shape[0] == 1:
        first = "image"
        figures = {"profiles": profiles_figure(cube[0], image[..., 0], points[0] if points else (0, 0),
                                               None if truth is None else truth[0])}
    else:
        first = "falsecolour"
        figures = {"projections": projections_figure(cube, wavelengths, image),
                   "spectra": spectra_figure(cube, wavelengths, image, points, truth)}
    if history:
        figures["convergence"] = convergence_figure(list(history))

    import matplotlib.image

    prefix = Path(prefix)
    prefix.parent.mkdir(parents=True, exist_ok=True)
    paths = [prefix.with_name(f"{prefix.name}_{name}.png") for name in (first, *figures)]
    with atomic_output(paths[0]) as tmp:
        matplotlib.image.imsave(tmp, image, format="png")
    return [paths[0], *(save_figure(fig, path) for fig, path in zip(figures.values(), paths[1:]))]


# ---- analysis pictures (clsdcam analyze) ---------------------------------------------------
def save_curves(path, title: str, xlabel: str, ylabel: str, curves: dict, log_y: bool = False,
                hline: float | None = None) -> Path:
    """Line plot of ``curves`` {label: (x, y)}; optional horizontal reference line."""
    fig = new_figure(figsize=(6, 4))
    ax = fig.subplots()
    for label, (x, y) in curves.items():
        ax.plot(x, y, marker=".", label=label)
    if hline is not None:
        ax.axhline(hline, color="grey", linestyle="--", linewidth=1)
    ax.set(title=title, xlabel=xlabel, ylabel=ylabel, yscale="log" if log_y else "linear")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, Path(path))


def save_autocorrelation(path, corr: np.ndarray, halfwidth_px: float) -> Path:
    """The central part of the PSF autocorrelation with its 70 % contour."""
    reach = int(max(4, 4 * halfwidth_px))
    cy, cx = corr.shape[0] // 2, corr.shape[1] // 2
    crop = corr[cy - reach:cy + reach + 1, cx - reach:cx + reach + 1]
    fig = new_figure(figsize=(4.5, 4))
    ax = fig.subplots()
    extent = (-reach - 0.5, reach + 0.5, reach + 0.5, -reach - 0.5)
    ax.imshow(crop, extent=extent, cmap="magma")
    ax.contour(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1), crop, levels=[0.7], colors="cyan")
    ax.set(title=f"PSF autocorrelation; 70 % half-width {halfwidth_px:.2f} px", xlabel="Δx (px)", ylabel="Δy (px)")
    return save_figure(fig, Path(path))


def save_design_pictures(path, designs: dict) -> Path:
    """Per design: false colour and the y–λ sum projection, side by side."""
    fig = new_figure(figsize=(4.2 * len(designs), 6.5))
    axes = fig.subplots(2, len(designs), squeeze=False)
    for column, (name, row) in enumerate(designs.items()):
        cube, wavelengths = row["cube"], row["wavelengths"]
        axes[0, column].imshow(false_colour(cube, wavelengths), interpolation="nearest")
        axes[0, column].set(title=f"{name}: {row['psnr']:.1f} dB, {row['angle']:.1f}°")
        edges = band_edges(wavelengths)
        axes[1, column].pcolormesh(edges, np.arange(cube.shape[1] + 1) - 0.5, cube.sum(axis=2).T, shading="flat")
        axes[1, column].set(xlabel="wavelength (nm)", ylabel="y (px)")
        axes[1, column].invert_yaxis()
    return save_figure(fig, Path(path))


def save_condition_curves(path, separations, study: dict, limit: float, superpixel_px: int) -> Path:
    """Local condition number against separation: one panel per mode (2-D, 3-D), one colour per
    design, darker and thicker for larger groups; log κ up to 10⁶ (numerically singular groups,
    κ ≈ 10¹⁶, fall off the top), the ``limit`` dashed, a super-pixel axis on top."""
    modes = sorted({row["mode"] for row in study.values()})
    designs = list(dict.fromkeys(row["design"] for row in study.values()))
    sizes = sorted({row["points"] for row in study.values()})
    fig = new_figure(figsize=(6 * len(modes), 4.5))
    for ax, mode in zip(fig.subplots(1, len(modes), squeeze=False)[0], modes):
        for row in (r for r in study.values() if r["mode"] == mode):
            weight = (sizes.index(row["points"]) + 1) / len(sizes)
            ax.plot(separations, row["condition"], marker=".", lw=0.6 + 1.4 * weight, alpha=0.35 + 0.65 * weight,
                    color=SPECTRUM_COLOURS[designs.index(row["design"]) % len(SPECTRUM_COLOURS)],
                    label=f"{row['design']}, n={row['points']}")
        ax.axhline(limit, color="grey", linestyle="--", linewidth=1)
        ax.set(title=f"{mode}: κ(A_S) of n points, geometric mean", xlabel="separation (px)",
               ylabel="condition number", yscale="log", ylim=(0.8, 1e6))
        top = ax.secondary_xaxis("top", functions=(lambda d: d / superpixel_px, lambda s: s * superpixel_px))
        top.set_xlabel("separation (super-pixels)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6, ncols=len(designs))
    return save_figure(fig, Path(path))
