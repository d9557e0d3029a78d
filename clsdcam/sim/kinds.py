"""Random scenes by kind, for judging the solver on scenes nobody tuned it on (``tools/bench_panel.py``).

Each kind draws a new scene from a seed: its layout and its spectra. Spectra are smooth and random,

    s(λ) = Σ_j a_j · exp(−4 ln2 (λ − c_j)² / w_j²),  1–3 terms, a ~ U(0.2, 1), c ~ U(range), w ~ U(30, 150)

nm (:func:`random_spectrum`), band-averaged; narrow lines (the ``lines`` and ``sparse`` kinds) take w ~ U(4, 16) nm.

- ``piecewise``: a few large regions and many small ones (rectangles and ellipses painted over one another),
  each with its own spectrum and brightness: many distinct, overlapping spectra with sharp edges.
- ``natural``: a photograph's structure (edges, texture, shading) from scikit-image's bundled colour images
  (random image, crop and flip), with 4–12 spectra softly mixed: each pixel's abundances fall off with its colour's
  distance from each spectrum's colour, times the photograph's luminance.
- ``sparse``: 5–40 small sources (a pixel or a disc of radius ≤ 2), narrow or broad, on a dim broad background
  whose brightness varies smoothly (1–10 % of the peak).
- ``lines``: spots on a jittered grid, each with one of 3–8 narrow lines.
- ``real``: a real cube (``../shared/data``: Samson, Jasper Ridge to 900 nm, CarbonBee's leaf), a random crop,
  flip and transposition, interpolated to the bands (clamped at its range's ends).

Every scene is zero in the 5 % border (as :mod:`clsdcam.sim.scenes`) and scaled to peak 1.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.ndimage as ndi

from ..errors import InputError
from ..extras import require
from .scenes import (compose, disc_masks, envi_wavelengths, in_window, inner_shape, inner_window, read_samson,
                     resample_spectra, shared_data_dir)
from .spectra import band_average, gaussian_line

BROAD_FWHM, NARROW_FWHM = (30.0, 150.0), (4.0, 16.0)      # nm
PHOTOS = ("astronaut", "chelsea", "coffee", "rocket", "hubble_deep_field", "immunohistochemistry", "retina")
JASPER_TOP_NM = 900.0
MIN_INNER_PX = 8                       # a kind's scene needs this much room inside the zero border
LEAF_RANGE_NM = (400.0, 1000.0)        # CarbonBee's leaf: 80 bands, not in the file (its tool's defaults)


def random_spectrum(rng: np.random.Generator, wavelengths, fwhm=BROAD_FWHM) -> np.ndarray:
    """A band-averaged sum of 1–3 Gaussians of random height, centre (over the bands' range) and width (``fwhm``)."""
    n = int(rng.integers(1, 4))
    lo, hi = float(np.min(wavelengths)), float(np.max(wavelengths))
    terms = [(rng.uniform(0.2, 1.0), rng.uniform(lo, hi), rng.uniform(*fwhm)) for _ in range(n)]
    return band_average(lambda lam: sum(a * gaussian_line(c, w)(lam) for a, c, w in terms), wavelengths)


def spectra(rng, wavelengths, n: int, fwhm=BROAD_FWHM) -> np.ndarray:
    """(n, K) random spectra, each scaled to peak 1."""
    out = np.stack([random_spectrum(rng, wavelengths, fwhm) for _ in range(n)])
    return out / out.max(axis=1, keepdims=True)


def shape_mask(box, rng: np.random.Generator, size) -> np.ndarray:
    """A random axis-aligned rectangle or ellipse of height and width U(size) × the box's: (h, w) bool."""
    h, w = box
    dy, dx = (max(1.0, rng.uniform(*size) * n) for n in box)
    cy, cx = rng.uniform(0, h), rng.uniform(0, w)
    y, x = np.mgrid[0:h, 0:w]
    if rng.random() < 0.5:
        return (np.abs(y - cy) <= dy / 2) & (np.abs(x - cx) <= dx / 2)
    return ((y - cy) / (dy / 2)) ** 2 + ((x - cx) / (dx / 2)) ** 2 <= 1.0


def piecewise_kind(shape, wavelengths, rng) -> np.ndarray:
    """2–5 large regions (25–70 % of each side) then 8–30 small ones (3–15 %), each painted over the last."""
    box = inner_shape(shape)
    sizes = [(0.25, 0.7)] * int(rng.integers(2, 6)) + [(0.03, 0.15)] * int(rng.integers(8, 31))
    label = np.full(box, -1)
    for index, size in enumerate(sizes):
        label[shape_mask(box, rng, size)] = index
    masks = (label[None] == np.arange(len(sizes))[:, None, None]) * rng.uniform(0.3, 1.0, (len(sizes), 1, 1))
    return compose(in_window(shape, masks), spectra(rng, wavelengths, len(sizes)))


def photo(box, rng: np.random.Generator) -> np.ndarray:
    """A random crop (the box's aspect, ≥ half the photograph's side), flip and zoom of a bundled photograph:
    (h, w, 3) in [0, 1]. InputError when scikit-image (the video extra) is not installed."""
    require("the natural scene kind")
    import skimage.data

    image = getattr(skimage.data, PHOTOS[rng.integers(len(PHOTOS))])()[..., :3].astype(np.float64) / 255.0
    side = rng.uniform(0.5, 1.0)
    ch = max(1, int(min(image.shape[0], image.shape[1] * box[0] / box[1]) * side))
    cw = max(1, min(image.shape[1], int(ch * box[1] / box[0])))
    top, left = rng.integers(0, image.shape[0] - ch + 1), rng.integers(0, image.shape[1] - cw + 1)
    crop = image[top:top + ch, left:left + cw]
    crop = crop[:, ::-1] if rng.random() < 0.5 else crop
    return np.clip(ndi.zoom(crop, (box[0] / ch, box[1] / cw, 1), order=1), 0, 1)


def natural_kind(shape, wavelengths, rng) -> np.ndarray:
    """4–12 spectra mixed by colour over a photograph, shaded by its luminance (see the module docstring)."""
    box = inner_shape(shape)
    rgb = photo(box, rng)
    n = int(rng.integers(4, 13))
    colours = rgb.reshape(-1, 3)[rng.integers(0, box[0] * box[1], n)]
    width = rng.uniform(0.05, 0.2)
    distance2 = np.sum((rgb[None] - colours[:, None, None]) ** 2, axis=-1)
    abundance = np.exp(-(distance2 - distance2.min(axis=0)) / (2 * width ** 2))
    shading = rgb @ np.array([0.2126, 0.7152, 0.0722])
    return compose(in_window(shape, abundance / abundance.sum(axis=0) * shading), spectra(rng, wavelengths, n))


def sparse_kind(shape, wavelengths, rng) -> np.ndarray:
    """5–40 sources (narrow or broad spectra, brightness U(0.3, 1)) on a dim, smoothly varying broad background."""
    box = inner_shape(shape)
    n = int(rng.integers(5, 41))
    centres = np.stack([rng.integers(0, box[0], n), rng.integers(0, box[1], n)], axis=1)
    discs = disc_masks(box, centres, rng.choice([0.0, 1.0, 1.5, 2.0], n)) * rng.uniform(0.3, 1.0, (n, 1, 1))
    narrow = rng.random(n) < 0.5
    source_spectra = np.where(narrow[:, None], spectra(rng, wavelengths, n, NARROW_FWHM), spectra(rng, wavelengths, n))
    field = ndi.gaussian_filter(rng.random(box), sigma=max(box) / 8)
    field = (field - field.min()) / (np.ptp(field) or 1.0)
    background = rng.uniform(0.02, 0.1) * (0.5 + 0.5 * field)
    return compose(in_window(shape, np.concatenate([discs, background[None]])),
                   np.concatenate([source_spectra, spectra(rng, wavelengths, 1)]))


def lines_kind(shape, wavelengths, rng) -> np.ndarray:
    """Spots (radius 1–2.5 px) on a jittered 3–6 × 4–8 grid, each with one of 3–8 narrow lines."""
    box = inner_shape(shape)
    rows, cols = int(rng.integers(3, 7)), int(rng.integers(4, 9))
    ys = (np.arange(rows) + 0.5) * box[0] / rows + rng.uniform(-0.2, 0.2, rows) * box[0] / rows
    xs = (np.arange(cols) + 0.5) * box[1] / cols + rng.uniform(-0.2, 0.2, cols) * box[1] / cols
    centres = np.stack(np.meshgrid(ys, xs, indexing="ij"), -1).reshape(-1, 2)
    masks = disc_masks(box, centres, rng.uniform(1.0, 2.5, len(centres))) * rng.uniform(0.3, 1.0, (len(centres), 1, 1))
    lines = spectra(rng, wavelengths, int(rng.integers(3, 9)), NARROW_FWHM)
    return compose(in_window(shape, masks), lines[rng.integers(0, len(lines), len(centres))])


def real_cubes(data: Path) -> dict:
    """Name -> a loader of (cube (h, w, bands) float64, wavelengths (bands,) nm), for the cubes present."""
    found = {}
    if (data / "cubes/samson/samson_1.img").exists():
        found["samson"] = lambda: read_samson(data / "cubes/samson/samson_1.img")
    if (data / "cubes/jasper_ridge/jasperRidge2_R198.img").exists():
        found["jasper"] = lambda: read_jasper(data / "cubes/jasper_ridge/jasperRidge2_R198.img")
    if (data / "cubes/carbonbee_leaf/leaf0.tiff").exists():
        found["leaf"] = lambda: read_leaf(data / "cubes/carbonbee_leaf/leaf0.tiff")
    return found


def read_jasper(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Jasper Ridge (ENVI BIL int16, 100 × 100 × 198), its bands sorted by wavelength and cut at 900 nm."""
    cube = np.fromfile(path, dtype="<i2").reshape(100, 198, 100).transpose(0, 2, 1).astype(np.float64)
    nm = envi_wavelengths(path.with_suffix(".hdr"))
    order = np.argsort(nm)
    keep = order[nm[order] <= JASPER_TOP_NM]
    return cube[..., keep], nm[keep]


def read_leaf(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """CarbonBee's leaf (TIFF, bands first, 80 × 60 × 60 uint8) over LEAF_RANGE_NM, evenly spaced."""
    import tifffile

    cube = tifffile.imread(path).astype(np.float64).transpose(1, 2, 0)
    return cube, np.linspace(*LEAF_RANGE_NM, cube.shape[-1])


def real_kind(shape, wavelengths, rng) -> np.ndarray:
    """A random crop (≥ 60 % of each side, the box's aspect), flip and transposition of a random real cube."""
    cubes = real_cubes(shared_data_dir())
    if not cubes:
        raise InputError("kind 'real' needs a real cube in ../shared/data/cubes (or $CLSDCAM_DATA); none present")
    raw, nm = cubes[sorted(cubes)[rng.integers(len(cubes))]]()
    raw = raw.transpose(1, 0, 2) if rng.random() < 0.5 else raw
    box = inner_shape(shape)
    side = rng.uniform(0.6, 1.0)
    ch = max(1, int(min(raw.shape[0], raw.shape[1] * box[0] / box[1]) * side))
    cw = max(1, min(raw.shape[1], int(ch * box[1] / box[0])))
    top, left = rng.integers(0, raw.shape[0] - ch + 1), rng.integers(0, raw.shape[1] - cw + 1)
    crop = np.maximum(raw[top:top + ch, left:left + cw], 0.0)
    crop = crop[::-1] if rng.random() < 0.5 else crop
    bands = resample_spectra(crop, nm, wavelengths).transpose(2, 0, 1)
    cube = np.zeros((len(wavelengths),) + tuple(shape))
    cube[(slice(None),) + inner_window(shape)] = ndi.zoom(bands, (1, box[0] / ch, box[1] / cw), order=1)
    return np.maximum(cube, 0.0)


KINDS = {"piecewise": piecewise_kind, "natural": natural_kind, "sparse": sparse_kind, "lines": lines_kind,
         "real": real_kind}


def make_kind(kind: str, shape, wavelengths, seed: int) -> np.ndarray:
    """A random scene of ``kind`` (K, H, W) float32 ≥ 0, zero in the border, peak 1, drawn from ``seed``."""
    if kind not in KINDS:
        raise InputError(f"kind {kind!r}: expected one of {', '.join(KINDS)}")
    if min(inner_shape(shape)) < MIN_INNER_PX:
        raise InputError(f"kind {kind!r}: the sensor {tuple(shape)} is too small (at least {MIN_INNER_PX} px inside "
                         "the border each way)")
    cube = KINDS[kind](tuple(shape), np.asarray(wavelengths, np.float64), np.random.default_rng(seed))
    if not cube.max() > 0:
        raise InputError(f"kind {kind!r}: the sensor {tuple(shape)} is too small to hold it")
    return (cube / cube.max()).astype(np.float32)
