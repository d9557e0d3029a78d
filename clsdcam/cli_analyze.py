"""``clsdcam analyze WHAT OUTDIR``: the paper's analyses, each writing JSON and a PNG into OUTDIR;
``all`` also writes ``report.html`` and prints the summary table next to the paper's values."""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from . import analysis, render, sim
from .io import atomic_output

SEPARATIONS = tuple(range(1, 25))
REAL_PSFS = {"Spectral DiffuserScope (measured)": "psf/spectraldiffuserscope_psf.npy",
             "DiffuserCam tutorial (measured)": "psf/diffusercam_tutorial_psf_sample.tif"}


def add_parser(subparsers, size_type):
    p = subparsers.add_parser("analyze", help="the paper's resolution analyses (JSON + PNG per analysis)")
    p.add_argument("what", choices=("resolution", "condition", "designs", "spectral", "twopoint", "all"))
    p.add_argument("outdir")
    p.add_argument("--size", type=size_type, default=sim.DEFAULT_SHAPE, metavar="HxW",
                   help="sensor size for PSF and condition-number analyses (default 320x448)")
    p.add_argument("--recon-size", type=size_type, default=(64, 96), metavar="HxW",
                   help="sensor size of the reconstruction analyses (default 64x96)")
    p.add_argument("--bands", type=int, default=64, help="bands of the reconstruction analyses (default 64)")
    p.add_argument("--iters", type=int, default=200, help="iterations of each reconstruction (default 200)")
    p.add_argument("--seed", type=int, default=0)


def run(args) -> int:
    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    names = ANALYSES if args.what == "all" else (args.what,)
    results = {}
    for name in names:
        start = time.perf_counter()
        results[name] = RUNNERS[name](args, out)
        _write_json(out / f"{name}.json", results[name])
        print(f"{name}: {out / (name + '.json')}, {out / (name + '.png')} ({time.perf_counter() - start:.0f} s)")
    if args.what == "all":
        table = summary_table(results)
        print(table)
        _write_report(out, table)
    return 0


# ---- the analyses ----------------------------------------------------------------------------
def run_resolution(args, out: Path) -> dict:
    psf = sim.caustic_psf(tuple(args.size), args.seed)
    result = {"simulated caustic": _resolution(psf)}
    for label, relative in REAL_PSFS.items():
        path = sim.shared_data_dir() / relative
        if path.exists():
            result[label] = _resolution(_load_psf(path))
    render.save_autocorrelation(out / "resolution.png", sim.autocorrelation(psf), result["simulated caustic"]["pixels"])
    return result


def _resolution(psf) -> dict:
    record = analysis.autocorrelation_resolution(psf)
    return {"pixels": record.pixels, "superpixels": record.superpixels, "shape": list(psf.shape)}


def _load_psf(path: Path) -> np.ndarray:
    """A measured PSF, background (median) removed; the tutorial's 1200×1600 frame as it is."""
    if path.suffix == ".npy":
        psf = np.load(path).astype(np.float64)
    else:
        import tifffile

        psf = tifffile.imread(path).astype(np.float64)
    return np.maximum(psf - np.median(psf), 0)


def run_condition(args, out: Path) -> dict:
    shape = tuple(args.size)
    filters = sim.filter_array(shape, sim.band_wavelengths(), args.seed)
    result, curves = {}, {}
    for design, build in sim.DESIGNS.items():
        psf = build(shape, args.seed)
        for spectral in (False, True):
            label = f"{design}, {'3-D' if spectral else '2-D'}"
            cond = analysis.condition_sweep(psf, filters, SEPARATIONS, spectral=spectral, seed=args.seed)
            below = analysis.separation_below(SEPARATIONS, cond)
            result[label] = {"separations_px": list(SEPARATIONS), "condition": [_finite(c) for c in cond],
                             "separation_at_40_px": below,
                             "separation_at_40_superpixels": None if below is None else below / sim.SUPERPIXEL_PX}
            curves[label] = (SEPARATIONS, np.minimum(cond, 1e12))
    render.save_curves(out / "condition.png", "local condition number, 4 points", "separation (px)",
                       "median cond(A_S)", curves, log_y=True, hline=analysis.COND_LIMIT)
    return result


def run_designs(args, out: Path) -> dict:
    designs = analysis.design_comparison(tuple(args.recon_size), args.bands, iters=args.iters, seed=args.seed)
    render.save_design_pictures(out / "designs.png", designs)
    return {name: {"psnr": row["psnr"], "angle": row["angle"]} for name, row in designs.items()}


def run_spectral(args, out: Path) -> dict:
    result = analysis.spectral_accuracy(tuple(args.recon_size), args.bands, iters=args.iters, seed=args.seed)
    render.save_curves(out / "spectral.png", "recovered peak wavelength", "true wavelength (nm)", "error (nm)",
                       {"|found − true|": (result["true_nm"], result["error_nm"])}, hline=5.0)
    return result


def run_twopoint(args, out: Path) -> dict:
    half = (args.recon_size[0] // 2, args.recon_size[1] // 2)  # two points need only a small field
    result = analysis.two_point_resolution(half, args.bands, iters=args.iters, seed=args.seed)
    labels = list(result)
    render.save_curves(out / "twopoint.png", "two-point resolution (Rayleigh)", "wavelength (nm)",
                       "smallest resolved separation (px)",
                       {"resolved at": ([float(k) for k in labels], [np.nan if result[k] is None else result[k]
                                                                      for k in labels])})
    return result


ANALYSES = ("resolution", "condition", "designs", "spectral", "twopoint")
RUNNERS = {"resolution": run_resolution, "condition": run_condition, "designs": run_designs,
           "spectral": run_spectral, "twopoint": run_twopoint}


# ---- summary --------------------------------------------------------------------------------
def summary_table(results: dict) -> str:
    """Markdown: each figure next to the paper's."""
    res = results["resolution"]["simulated caustic"]
    rows = [("autocorrelation resolution, simulated PSF", f"{res['pixels']:.2f} px = {res['superpixels']:.2f} super-pixel",
             "~3 px = 0.19 super-pixel")]
    rows += [(f"autocorrelation resolution, {label}", f"{r['pixels']:.2f} px of its sensor", "—")
             for label, r in results["resolution"].items() if label != "simulated caustic"]
    for label, r in results["condition"].items():
        at = r["separation_at_40_superpixels"]
        rows.append((f"separation at cond 40, {label}", "never ≤ 24 px" if at is None else f"{at:.2f} super-pixel",
                     "diffuser ~0.3, low-NA lens ~1 super-pixel"))
    spectral = results["spectral"]
    rows.append(("peak wavelength error, median / worst",
                 f"{spectral['median_error_nm']:.1f} / {spectral['worst_error_nm']:.1f} nm", "within 5 nm"))
    for line, d in results["twopoint"].items():
        rows.append((f"two-point resolution at {line} nm", "not within 8 px" if d is None else f"{d} px", "—"))
    for name, r in results["designs"].items():
        rows.append((f"target reconstruction, {name}", f"{r['psnr']:.2f} dB, {r['angle']:.1f}°", "—"))
    lines = ["| quantity | clsdcam | paper |", "|---|---|---|"] + [f"| {a} | {b} | {c} |" for a, b, c in rows]
    return "\n".join(lines)


def _write_report(out: Path, table: str):
    body = "".join(f"<tr>{''.join(f'<td>{cell.strip()}</td>' for cell in line.strip('|').split('|'))}</tr>"
                   for line in table.splitlines()[2:])
    images = "".join(f'<h2>{name}</h2><img src="{name}.png" style="max-width:100%">' for name in ANALYSES)
    html = (f"<html><head><meta charset='utf-8'><title>clsdcam analysis</title></head><body>"
            f"<h1>clsdcam analysis</h1><table border=1 cellpadding=4><tr><th>quantity</th><th>clsdcam</th>"
            f"<th>paper</th></tr>{body}</table>{images}</body></html>")
    with atomic_output(out / "report.html") as tmp:
        tmp.write_text(html, encoding="utf-8")


def _write_json(path: Path, data):
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1, default=_finite))


def _finite(value):
    """JSON-safe number: inf/NaN become None."""
    value = float(value)
    return value if math.isfinite(value) else None
