"""The paper's analyses as named runs: each writes ``NAME.json`` and ``NAME.png`` into a folder; a summary
table next to the paper's values and ``report.html`` gather them (``clsdcam analyze``).

Sizes (recorded in each JSON): the PSF and condition-number analyses use ``size`` (default the
prototype's 320×448); the reconstructions use ``recon_size`` (default 64×96), ``bands`` (64) and
``iters`` (200), because a full 320×448×64 reconstruction costs seconds per iteration.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from . import analysis, render, sim
from .data import missing_text, shared_data_dir
from .io import atomic_output, load_measurement

SEPARATIONS = (1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 14, 16, 20, 24, 32)
GROUP_SIZES = (2, 4, 9, 16)
REAL_PSFS = {"Spectral DiffuserScope (measured)": "psf/spectraldiffuserscope_psf.npy",
             "DiffuserCam tutorial (measured)": "psf/diffusercam_tutorial_psf_sample.tif"}


# ---- the analyses ------------------------------------------------------------------------------
def run_resolution(args, out: Path) -> dict:
    """The simulated caustic at --size, then each measured PSF present in the shared data folder (dark ring
    subtracted, binned); an absent one is recorded as skipped, with why (:func:`skipped_lines`)."""
    psf = sim.caustic_psf(tuple(args.size), args.seed)
    result = {"simulated caustic": psf_resolution(psf, out / "resolution.png", 1)}
    for label, relative in REAL_PSFS.items():
        path = shared_data_dir() / relative
        if not path.exists():
            result[label] = {"skipped": missing_text(relative)}
            continue
        raw = load_measurement(path)
        measured, factor = analysis.measured_psf(raw)
        result[label] = psf_resolution(measured, out / f"resolution_{path.stem}.png", factor)
        result[label]["native_shape"] = list(raw.shape)
    return {"level": 0.7, "superpixel_px": sim.SUPERPIXEL_PX, "psfs": result}


def psf_resolution(psf: np.ndarray, picture: Path, binning: int) -> dict:
    """r₇₀ of one PSF, its picture, and how the PSF was prepared."""
    record = analysis.autocorrelation_resolution(psf)
    render.save_autocorrelation(picture, sim.autocorrelation(psf), record.pixels)
    return {"pixels": record.pixels, "superpixels": record.superpixels, "shape": list(psf.shape),
            "binning": binning, "picture": picture.name}


def run_condition(args, out: Path) -> dict:
    """κ against separation for every design, 2-D and 3-D, every group size, on --size."""
    shape = tuple(args.size)
    filters = sim.filter_array(shape, sim.band_wavelengths(args.bands), args.seed)
    psfs = {name: build(shape, args.seed) for name, build in sim.DESIGNS.items()}
    separations = tuple(d for d in SEPARATIONS if d * 3 < min(shape) // 2) or (1,)
    study = analysis.condition_study(psfs, filters, separations, GROUP_SIZES, args.trials, args.seed)
    render.save_condition_curves(out / "condition.png", separations, study, analysis.COND_LIMIT, sim.SUPERPIXEL_PX)
    return {"separations_px": list(separations), "limit": analysis.COND_LIMIT, "group_sizes": list(GROUP_SIZES),
            "trials": args.trials, "shape": list(shape), "bands": args.bands, "average": "geometric mean",
            "groups": study}


def run_designs(args, out: Path) -> dict:
    designs = analysis.design_comparison(tuple(args.recon_size), args.bands, args.iters, args.seed)
    render.save_design_pictures(out / "designs.png", designs)
    return {"shape": list(args.recon_size), "bands": args.bands, "iters": args.iters,
            "designs": {name: {"psnr": row["psnr"], "angle": row["angle"]} for name, row in designs.items()}}


def run_spectral(args, out: Path) -> dict:
    result = analysis.spectral_accuracy(tuple(args.recon_size), args.bands, iters=args.iters, seed=args.seed)
    render.save_curves(out / "spectral.png", "recovered peak wavelength of 10 nm lines", "true wavelength (nm)",
                       "found − true (nm)", {"error": (result["true_nm"], result["error_nm"]),
                                             "±5 nm (paper)": ([386, 898, np.nan, 386, 898], [5, 5, np.nan, -5, -5])})
    return result


def run_twopoint(args, out: Path) -> dict:
    result = analysis.two_point_resolution(tuple(args.recon_size), args.bands, iters=args.iters, seed=args.seed)
    curves = {f"{line:g} nm": (result["separations_px"], result[f"{line:g}"]["dip_ratio"])
              for line in analysis.TWO_POINT_WAVELENGTHS}
    render.save_curves(out / "twopoint.png", "two points: dip / weaker peak (resolved below the line)",
                       "separation (px)", "dip ratio", curves, hline=analysis.RAYLEIGH_DIP)
    return result


RUNNERS = {"resolution": run_resolution, "condition": run_condition, "designs": run_designs,
           "spectral": run_spectral, "twopoint": run_twopoint}
ANALYSES = tuple(RUNNERS)


# ---- key figures: (quantity, clsdcam's value, the paper's) per analysis ------------------------------
def superpixel_text(px) -> str:
    return f"{px / sim.SUPERPIXEL_PX:.2f} super-pixel ({px} px)"


def resolution_rows(result: dict) -> list[tuple[str, str, str]]:
    """One row per PSF: r₇₀ in pixels and super-pixels, or why it was skipped (a measured PSF not found)."""
    rows = []
    for label, r in result["psfs"].items():
        if "skipped" in r:
            rows.append((f"autocorrelation resolution, {label}", f"skipped: {r['skipped']}", "—"))
            continue
        binned = f", binned {r['binning']}×" if r["binning"] > 1 else ""
        rows.append((f"autocorrelation resolution, {label}{binned}",
                     f"{r['pixels']:.2f} px = {r['superpixels']:.2f} super-pixel", "~3 px = 0.19 super-pixel"
                     if label == "simulated caustic" else "—"))
    return rows


def condition_rows(result: dict) -> list[tuple[str, str, str]]:
    """One row per design and mode: the largest group's separation at κ = 40, the others in brackets."""
    paper = {"diffuser": "~0.3 super-pixel", "low-NA lens": "~1 super-pixel", "high-NA lens": "—"}
    rows, groups = [], result["groups"]
    for design in sim.DESIGNS:
        for mode in ("2-D", "3-D"):
            at = {n: groups[f"{design}|{mode}|{n}"]["separation_at_limit_px"] for n in result["group_sizes"]}
            others = ", ".join(f"n={n}: {'never' if d is None else d}" for n, d in at.items())
            largest = max(at)
            headline = superpixel_text(at[largest]) if at[largest] is not None else "never"
            rows.append((f"separation at κ = 40, {design}, {mode}, {largest} points",
                         f"{headline} [px: {others}]", paper[design]))
    return rows


def spectral_rows(result: dict) -> list[tuple[str, str, str]]:
    return [("peak-wavelength error, median / worst", f"{result['median_abs_error_nm']:.1f} / "
             f"{result['worst_abs_error_nm']:.1f} nm ({len(result['true_nm'])} sources)", "within 5 nm")]


def twopoint_rows(result: dict) -> list[tuple[str, str, str]]:
    """One row per wavelength: the smallest separation resolved (and every larger one)."""
    rows = []
    for line in analysis.TWO_POINT_WAVELENGTHS:
        d = result[f"{line:g}"]["resolved_px"]
        rows.append((f"two-point resolution at {line:g} nm (Rayleigh)",
                     f"not within {result['separations_px'][-1]} px" if d is None else f"{d} px", "—"))
    return rows


def design_rows(result: dict) -> list[tuple[str, str, str]]:
    return [(f"target reconstruction, {name}", f"{r['psnr']:.2f} dB PSNR, {r['angle']:.1f}° mean spectral angle",
             "—") for name, r in result["designs"].items()]


ROWS = {"resolution": resolution_rows, "condition": condition_rows, "spectral": spectral_rows,
        "twopoint": twopoint_rows, "designs": design_rows}     # in the summary table's order


def figure_lines(name: str, result: dict) -> list[str]:
    """The analysis' key figures as printed lines: ``  quantity: value`` and the paper's value when it gives one."""
    return [f"  {quantity}: {value}" + (f" (paper: {paper})" if paper != "—" else "")
            for quantity, value, paper in ROWS[name](result)]


def summary_table(results: dict) -> str:
    """Markdown: each figure next to the paper's."""
    rows = [row for name, rows_of in ROWS.items() for row in rows_of(results[name])]
    return "\n".join(["| quantity | clsdcam | paper |", "|---|---|---|"] + [f"| {a} | {b} | {c} |" for a, b, c in rows])


def write_report(out: Path, table: str, results: dict) -> Path:
    """report.html: the table, the sizes used, and every picture, on one page."""
    body = "".join("<tr>" + "".join(f"<td>{cell.strip()}</td>" for cell in line.strip("|").split("|")) + "</tr>"
                   for line in table.splitlines()[2:])
    pictures = [r["picture"] for r in results["resolution"]["psfs"].values() if "picture" in r]
    pictures += [f"{name}.png" for name in ANALYSES[1:]]
    images = "".join(f'<figure><img src="{name}" style="max-width:100%"><figcaption>{name}</figcaption></figure>'
                     for name in pictures)
    sizes = {name: {k: results[name].get(k) for k in ("shape", "bands", "iters", "trials") if k in results[name]}
             for name in ANALYSES[1:]}
    html = ("<html><head><meta charset='utf-8'><title>clsdcam analysis</title></head><body>"
            "<h1>clsdcam analysis</h1><table border=1 cellpadding=4><tr><th>quantity</th><th>clsdcam</th>"
            f"<th>paper</th></tr>{body}</table><p>sizes: {json.dumps(sizes)}</p>{images}</body></html>")
    with atomic_output(out / "report.html") as tmp:
        tmp.write_text(html, encoding="utf-8")
    return out / "report.html"


def write_json(path: Path, data) -> Path:
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(jsonable(data), indent=1, allow_nan=False))
    return path


def jsonable(value):
    """Plain JSON: containers recursed, NumPy scalars to Python, inf/NaN to None."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [jsonable(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value.item() if isinstance(value, np.generic) else value

