"""Scene cubes v (K, H, W) on the sensor window: resolution charts, LEDs, narrow spectral lines, Voronoi
cells, two points, narrow-band point sources, and a real airborne cube (Samson).

A synthetic scene is R spatial masks with one spectrum each,

    v_k(y, x) = Σ_r mask_r(y, x) · s_r(k),

drawn inside an inner window (the scene is zero within 5 % of each side); analytic spectra are
band averages (:func:`clsdcam.sim.spectra.band_average`). The real cube is linearly
interpolated to the band wavelengths. Every scene is scaled to peak 1; random choices are seeded.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Callable

import numpy as np
import scipy.ndimage as ndi
from scipy.interpolate import interp1d

from ..data import missing_text, shared_data_dir
from ..errors import InputError
from .sensor import DEFAULT_SHAPE
from .spectra import band_average, band_wavelengths, blackbody, gaussian_line

BORDER_FRACTION = 0.05             # scenes are zero within this fraction of each side
LINE_FWHM = 15.0                   # nm, narrow-band illumination in "target" and "points"
LED_FWHM = 20.0                    # nm
RGB_LINES = {"red": 630.0, "green": 530.0, "blue": 460.0}
SAMSON = "cubes/samson/samson_1.img"
SAMSON_SHAPE = (156, 95, 95)       # ENVI BSQ: bands, lines, samples
NARROW_FWHM = 8.0                  # nm, the "lines" scene: one 8 nm band wide
# the "lines" scene: lines next to the calibrated range's ends and on bin boundaries of the 64 bands
# (386 + 8j nm), and one faint line (peak FAINT of the others')
EDGE_LINES = (391.0, 498.0, 594.0, 706.0, 893.0)
FAINT_LINE, FAINT = 650.0, 0.1
SOURCE_FWHM = 10.0                 # nm, the "sources" scene (the paper's point-source analysis)
N_SOURCES = 16


def border_px(shape) -> tuple[int, int]:
    """The zero border of a scene: max(1, round(5 % of each side))."""
    return tuple(max(1, round(BORDER_FRACTION * n)) for n in shape)


def inner_window(shape) -> tuple[slice, slice]:
    """The part of the sensor window inside the zero border."""
    by, bx = border_px(shape)
    return slice(by, shape[0] - by), slice(bx, shape[1] - bx)


def compose(masks: np.ndarray, spectra: np.ndarray) -> np.ndarray:
    """v_k(y, x) = Σ_r mask_r(y, x) · s_r(k): (R, H, W) spatial maps × (R, K) spectra -> (K, H, W)."""
    return np.einsum("rhw,rk->khw", masks, spectra)


def in_window(shape, inner_masks: np.ndarray) -> np.ndarray:
    """Masks drawn on the inner window (R, h, w), placed in zero frames (R, H, W)."""
    full = np.zeros((inner_masks.shape[0],) + tuple(shape))
    full[(slice(None),) + inner_window(shape)] = inner_masks
    return full


def inner_shape(shape) -> tuple[int, int]:
    """(h, w) of the inner window."""
    return tuple(s.stop - s.start for s in inner_window(shape))


def bar_triple(width: int) -> np.ndarray:
    """Three vertical bars of ``width`` px, ``width`` apart, 5·width tall: a (5w, 5w) 0/1 element."""
    element = np.zeros((5 * width, 5 * width))
    for start in (0, 2 * width, 4 * width):
        element[:, start:start + width] = 1.0
    return element


def bar_widths(box) -> list[int]:
    """The bar widths (1, 2, 3, 4, 6, 8, …, smallest first) whose rows fit in ``box``: 6·Σw ≤ h, 11·w ≤ w_box."""
    widths, height = [], 0
    for width in (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64):
        if 6 * (height + width) > box[0] or 11 * width > box[1]:
            break
        widths.append(width)
        height += width
    return widths


def resolution_chart(box) -> np.ndarray:
    """A USAF-like chart in ``box``: rows of a vertical and a horizontal bar triple, widest at the top, centred."""
    widths = bar_widths(box)[::-1]
    chart = np.zeros(box)
    top = (box[0] - 6 * sum(widths) + min(widths, default=0)) // 2
    left = (box[1] - 11 * max(widths, default=0)) // 2
    for width in widths:
        element = bar_triple(width)
        chart[top:top + 5 * width, left:left + 5 * width] = element
        chart[top:top + 5 * width, left + 6 * width:left + 11 * width] = element.T
        top += 6 * width
    return chart


def quadrant_masks(box) -> np.ndarray:
    """Four resolution charts, one per quadrant of ``box`` (1-px gap between): (4, h, w), order TL, TR, BL, BR."""
    h, w = box
    quadrant = ((h - 1) // 2, (w - 1) // 2)
    masks = np.zeros((4,) + tuple(box))
    chart = resolution_chart(quadrant)
    for i, (oy, ox) in enumerate([(0, 0), (0, w - quadrant[1]), (h - quadrant[0], 0), (h - quadrant[0], w - quadrant[1])]):
        masks[i, oy:oy + quadrant[0], ox:ox + quadrant[1]] = chart
    return masks


def target_scene(shape, wavelengths, _rng: np.random.Generator) -> np.ndarray:
    """Resolution charts in four quadrants lit by red, green, blue (15 nm lines) and white (5000 K) light (not random)."""
    lights = [gaussian_line(RGB_LINES[name], LINE_FWHM) for name in ("red", "green", "blue")] + [blackbody(5000.0)]
    spectra = np.stack([band_average(light, wavelengths) for light in lights])
    return compose(in_window(shape, quadrant_masks(inner_shape(shape))), spectra)


def disc_masks(box, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """One 0/1 disc per (centre, radius): pixels whose centre is within the radius, (R, h, w)."""
    y, x = np.mgrid[0:box[0], 0:box[1]]
    distance2 = (y[None] - centres[:, 0, None, None]) ** 2 + (x[None] - centres[:, 1, None, None]) ** 2
    return (distance2 <= radii[:, None, None] ** 2).astype(np.float64)


def grid_centres(box, grid) -> np.ndarray:
    """(rows·cols, 2) centres of a ``grid`` = (rows, cols) spread evenly over ``box``, its margins included."""
    rows = np.linspace(0, box[0] - 1, grid[0] + 2)[1:-1]
    cols = np.linspace(0, box[1] - 1, grid[1] + 2)[1:-1]
    return np.round(np.stack(np.meshgrid(rows, cols, indexing="ij"), axis=-1).reshape(-1, 2))


def spots(box, rng: np.random.Generator, grid) -> np.ndarray:
    """Disc spots on a ``grid`` (radius U(1, 2) px, brightness U(0.5, 1)): (R, h, w)."""
    centres = grid_centres(box, grid)
    return disc_masks(box, centres, rng.uniform(1.0, 2.0, len(centres))) * rng.uniform(0.5, 1.0, (len(centres), 1, 1))


def led_scene(shape, wavelengths, rng: np.random.Generator, grid=(4, 6)) -> np.ndarray:
    """A ``grid`` of LED spots (radius U(1, 2) px, brightness U(0.5, 1)) with three spectra: 460, 530, 630 nm lines."""
    masks = spots(inner_shape(shape), rng, grid)
    colours = np.stack([band_average(gaussian_line(RGB_LINES[name], LED_FWHM), wavelengths) for name in ("blue", "green", "red")])
    assignment = rng.permutation(np.arange(len(masks)) % 3)
    return compose(in_window(shape, masks), colours[assignment])


def lines_scene(shape, wavelengths, rng: np.random.Generator, grid=(4, 6)) -> np.ndarray:
    """LED spots (as in ``leds``) with six narrow lines (FWHM 8 nm, one band at 64 bands): next to both ends of
    the calibrated range and on bin boundaries (EDGE_LINES), and one faint line (FAINT_LINE at FAINT of the others'
    peak); each spectrum on a quarter of the spots or fewer."""
    masks = spots(inner_shape(shape), rng, grid)
    lines = [band_average(gaussian_line(centre, NARROW_FWHM), wavelengths) for centre in EDGE_LINES]
    lines.append(FAINT * band_average(gaussian_line(FAINT_LINE, NARROW_FWHM), wavelengths))
    assignment = rng.permutation(np.arange(len(masks)) % len(lines))
    return compose(in_window(shape, masks), np.stack(lines)[assignment])


def smooth_random_spectrum(rng: np.random.Generator) -> Callable[[np.ndarray], np.ndarray]:
    """s(λ) = Σ_j a_j · line(c_j, w_j) over 2–3 broad Gaussians: a ~ U(0.2, 1), c ~ U(400, 880), w ~ U(60, 200) nm."""
    n = rng.integers(2, 4)
    amplitudes, centres, widths = rng.uniform(0.2, 1.0, n), rng.uniform(400.0, 880.0, n), rng.uniform(60.0, 200.0, n)
    return lambda lam: sum(a * gaussian_line(c, w)(lam) for a, c, w in zip(amplitudes, centres, widths))


def piecewise_scene(shape, wavelengths, rng: np.random.Generator, n_cells: int = 12) -> np.ndarray:
    """Voronoi cells around ``n_cells`` uniform random sites, each with its own smooth random spectrum."""
    box = inner_shape(shape)
    sites = rng.uniform((0, 0), box, size=(n_cells, 2))
    y, x = np.mgrid[0:box[0], 0:box[1]]
    nearest = np.argmin((y[None] - sites[:, 0, None, None]) ** 2 + (x[None] - sites[:, 1, None, None]) ** 2, axis=0)
    masks = (nearest[None] == np.arange(n_cells)[:, None, None]).astype(np.float64)
    spectra = np.stack([band_average(smooth_random_spectrum(rng), wavelengths) for _ in range(n_cells)])
    return compose(in_window(shape, masks), spectra)


def points_scene(shape, wavelengths, rng: np.random.Generator, separation: int = 4) -> np.ndarray:
    """Two single-pixel sources ``separation`` px apart in x near the centre (seeded jitter), one 530 nm line."""
    box = inner_shape(shape)
    jitter = rng.integers(-(np.array(box) // 8), np.array(box) // 8 + 1)
    y = int(np.clip(box[0] // 2 + jitter[0], 0, box[0] - 1))
    x0 = int(np.clip(box[1] // 2 - separation // 2 + jitter[1], 0, max(box[1] - 1 - separation, 0)))
    mask = np.zeros((1,) + box)
    mask[0, y, [x0, min(x0 + separation, box[1] - 1)]] = 1.0
    return compose(in_window(shape, mask), band_average(gaussian_line(RGB_LINES["green"], LINE_FWHM), wavelengths)[None])


def source_positions(shape, n: int = N_SOURCES) -> list[tuple[int, int]]:
    """n pixels on a ⌈√n⌉-wide grid spread over the central two thirds of the frame."""
    side = int(np.ceil(np.sqrt(n)))
    ys, xs = (np.round(np.linspace(s / 6, 5 * s / 6, side)).astype(int) for s in shape)
    return [(int(ys[i // side]), int(xs[i % side])) for i in range(n)]


def source_lines(wavelengths, n: int = N_SOURCES) -> np.ndarray:
    """The n sources' line centres (nm): evenly from the first to the last band centre."""
    return np.linspace(wavelengths[0], wavelengths[-1], n)


def source_cube(shape, wavelengths, n: int = N_SOURCES) -> np.ndarray:
    """n single-pixel sources (:func:`source_positions`), each a SOURCE_FWHM nm line at its own wavelength
    (:func:`source_lines`), band-averaged: (K, H, W) float64."""
    cube = np.zeros((len(wavelengths),) + tuple(shape))
    for (y, x), centre in zip(source_positions(shape, n), source_lines(wavelengths, n)):
        cube[:, y, x] = band_average(gaussian_line(centre, SOURCE_FWHM), wavelengths)
    return cube


def sources_scene(shape, wavelengths, _rng: np.random.Generator) -> np.ndarray:
    """The paper's point-source analysis: N_SOURCES narrow-band point sources in one frame (not random)."""
    return source_cube(shape, wavelengths)


def envi_wavelengths(header: Path) -> np.ndarray:
    """The ``wavelength = { … }`` list of an ENVI header (nm)."""
    match = re.search(r"wavelength\s*=\s*\{([^}]*)\}", header.read_text())
    return np.array([float(v) for v in match.group(1).split(",")])


def read_samson(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The Samson cube as (lines, samples, bands) float64 and its wavelengths (nm) from the ENVI header."""
    cube = np.fromfile(path, dtype="<i2").reshape(SAMSON_SHAPE).transpose(1, 2, 0).astype(np.float64)
    return cube, envi_wavelengths(path.with_name(path.name + ".hdr"))


def resample_spectra(cube: np.ndarray, source_nm: np.ndarray, wavelengths) -> np.ndarray:
    """Linear interpolation along the last axis, clamped: bands outside the source range take its end values."""
    query = np.clip(np.asarray(wavelengths, dtype=np.float64), source_nm[0], source_nm[-1])
    return interp1d(source_nm, cube, axis=-1)(query)


def central_crop(image: np.ndarray, aspect: float) -> np.ndarray:
    """The largest central crop of an (h, w, …) array with width/height = ``aspect``."""
    h, w = image.shape[:2]
    ch, cw = min(h, round(w / aspect)), min(w, round(h * aspect))
    top, left = (h - ch) // 2, (w - cw) // 2
    return image[top:top + ch, left:left + cw]


def realcube_scene(shape, wavelengths, _rng: np.random.Generator) -> np.ndarray:
    """The Samson airborne cube (400.9–899.1 nm): clamped-interpolated to the bands, centrally cropped to the
    window's aspect and zoomed (bilinear) onto the inner window; negative raw values clipped to 0 (not random)."""
    path = shared_data_dir() / SAMSON
    if not path.exists():
        raise InputError(f"scene 'realcube': {missing_text(SAMSON)}")
    raw, source_nm = read_samson(path)
    box = inner_shape(shape)
    cropped = central_crop(raw, box[1] / box[0])
    spectral = resample_spectra(cropped, source_nm, wavelengths).transpose(2, 0, 1)
    zoomed = ndi.zoom(spectral, (1.0, box[0] / spectral.shape[1], box[1] / spectral.shape[2]), order=1)
    cube = np.zeros((len(wavelengths),) + tuple(shape))
    cube[(slice(None),) + inner_window(shape)] = np.maximum(zoomed, 0.0)
    return cube


SCENE_BUILDERS = {
    "target": target_scene,
    "leds": led_scene,
    "lines": lines_scene,
    "piecewise": piecewise_scene,
    "points": points_scene,
    "sources": sources_scene,
    "realcube": realcube_scene,
}
SCENES = tuple(SCENE_BUILDERS)


def make_scene(name: str = "target", shape=DEFAULT_SHAPE, wavelengths=None, seed: int = 0) -> np.ndarray:
    """A scene cube (K, H, W) float32 ≥ 0 on the sensor window, zero in the border, peak 1.

    ``wavelengths`` defaults to :func:`band_wavelengths` (64 bands). See SCENES for the names.
    """
    if name not in SCENE_BUILDERS:
        raise InputError(f"--scene {name!r}: expected one of {', '.join(SCENES)}")
    wavelengths = band_wavelengths() if wavelengths is None else np.asarray(wavelengths, dtype=np.float64)
    cube = SCENE_BUILDERS[name](tuple(shape), wavelengths, np.random.default_rng(seed))
    if not cube.max() > 0:
        raise InputError(f"--scene {name!r}: the sensor {tuple(shape)} is too small to hold it")
    return (cube / cube.max()).astype(np.float32)
