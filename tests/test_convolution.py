"""The host's band-chunked, pruned convolution against the primitive-by-primitive one (same operator)."""
import numpy as np
import pytest
import scipy.fft

import clsdcam.backends.host_convolution as host_convolution
from clsdcam.backends.convolution import HostPathConvolution, PrimitiveConvolution
from clsdcam.backends.host_convolution import HostConvolution, band_chunks
from clsdcam.backends.host_fft import irfft2, irfft2_to_window, rfft2_of_window
from clsdcam.backends.numpy import NumpyBackend
from clsdcam.camera.geometry import support_geometry, transfer_function

SENSOR, FIELD_PSF = (21, 34), ((4, 15), (6, 29))


def operators(dtype, filters, chunk_bytes, monkeypatch, skip_unseen=True):
    """(host, primitive) convolutions for one random PSF with a support-sized field."""
    monkeypatch.setattr(host_convolution, "CHUNK_BYTES", chunk_bytes)
    be = NumpyBackend(dtype)
    psf = np.zeros(SENSOR)
    (r0, r1), (c0, c1) = FIELD_PSF
    psf[r0:r1, c0:c1] = np.random.default_rng(0).random((r1 - r0, c1 - c0))
    geometry = support_geometry(psf, be.fast_length)
    transfer = transfer_function(psf, geometry)
    return (HostConvolution(transfer, filters, geometry.field, be.dtype, 2, skip_unseen),
            PrimitiveConvolution(be, transfer, filters, geometry.field), geometry)


@pytest.mark.parametrize("shape", [(8, 10), (9, 15), (6, 7)])
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_the_inverse_in_two_passes_is_pocketffts_irfft2(shape, dtype):
    """host_fft.irfft2 against scipy.fft.irfft2(s=shape) on three half spectra of random fields, even and odd
    lengths: equal within the float rule of their precision (2e-6 + 5e-7·log10 N of the largest value in float32; the
    same 1-D passes, measured bit for bit), the spectrum kept unless ``overwrite`` lets the column pass run on it."""
    field = np.random.default_rng(2).standard_normal((3,) + shape).astype(dtype)
    spectrum = scipy.fft.rfft2(field)
    kept = spectrum.copy()
    expected = scipy.fft.irfft2(kept, s=shape)
    rule = 2e-6 + 5e-7 * np.log10(np.prod(shape)) if dtype == "float32" else 1e-13
    got = irfft2(spectrum, shape)
    assert got.dtype == expected.dtype and got.shape == (3,) + shape
    assert np.max(np.abs(got - expected)) <= rule * np.max(np.abs(expected))
    np.testing.assert_array_equal(spectrum, kept)
    overwritten = irfft2(spectrum, shape, workers=2, overwrite=True)
    assert np.max(np.abs(overwritten - expected)) <= rule * np.max(np.abs(expected))
    assert np.max(np.abs(overwritten - field)) <= 10 * rule * np.max(np.abs(field))


@pytest.mark.parametrize("field, window", [((8, 10), (4, 5)), ((9, 15), (5, 8)), ((6, 7), (6, 7))])
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_the_pruned_transforms_are_the_whole_ones_at_the_window(field, window, dtype):
    """rfft2_of_window is rfft2 of the window zero-padded at the origin, irfft2_to_window the window of irfft2, even
    and odd lengths, a window as large as the field among them: within the float rule of their precision, the spectrum
    kept unless ``overwrite`` lets the column pass run on it."""
    rng = np.random.default_rng(4)
    rule = 2e-6 + 5e-7 * np.log10(np.prod(field)) if dtype == "float32" else 1e-13
    inside = rng.standard_normal((3,) + window).astype(dtype)
    padded = np.zeros((3,) + field, dtype)
    padded[:, :window[0], :window[1]] = inside
    expected = scipy.fft.rfft2(padded)
    got = rfft2_of_window(inside, field, workers=2)
    assert got.dtype == expected.dtype and got.shape == expected.shape
    assert np.max(np.abs(got - expected)) <= rule * np.max(np.abs(expected))
    spectrum = scipy.fft.rfft2(rng.standard_normal((3,) + field)).astype(expected.dtype)
    kept, whole = spectrum.copy(), scipy.fft.irfft2(spectrum, s=field)[:, :window[0], :window[1]]
    back = irfft2_to_window(spectrum, field, window)
    assert back.shape == (3,) + window and np.max(np.abs(back - whole)) <= rule * np.max(np.abs(whole))
    np.testing.assert_array_equal(spectrum, kept)
    back = irfft2_to_window(spectrum, field, window, overwrite=True)
    assert back.shape == (3,) + window and np.max(np.abs(back - whole)) <= rule * np.max(np.abs(whole))


@pytest.mark.parametrize("chunk_bytes", [1, 3 << 10, 1 << 30])   # one band per chunk, a few, all at once
@pytest.mark.parametrize("dtype,tolerance", [("float32", 2e-6), ("float64", 1e-12)])
def test_host_matches_primitives(chunk_bytes, dtype, tolerance, monkeypatch):
    rng = np.random.default_rng(1)
    filters = rng.random((7,) + SENSOR)
    host, primitive, geometry = operators(dtype, filters, chunk_bytes, monkeypatch)
    v = rng.standard_normal((7,) + geometry.field).astype(dtype)
    r = rng.standard_normal(SENSOR).astype(dtype)
    y = rng.standard_normal(v.shape).astype(dtype)

    def close(got, ref):
        assert np.max(np.abs(got - ref)) <= tolerance * np.max(np.abs(ref))

    close(host.forward(v, np.empty(SENSOR, dtype)), primitive.forward(v, np.empty(SENSOR, dtype)))
    close(host.adjoint(r, np.empty_like(v)), primitive.adjoint(r, np.empty_like(v)))
    close(host.adjoint(r, np.empty_like(v), y, 0.3), primitive.adjoint(r, np.empty_like(v), y, 0.3))
    aliased = y.copy()
    close(host.adjoint(r, aliased, aliased, 0.3), primitive.adjoint(r, np.empty_like(v), y, 0.3))  # out is y


def test_unseen_bands_are_skipped_exactly(monkeypatch):
    """A band no filter sees: no transforms for it, the same b, Aᵀr = 0 there, the gradient step leaves y."""
    rng = np.random.default_rng(2)
    filters = rng.random((5,) + SENSOR)
    filters[[1, 4]] = 0.0
    host, primitive, geometry = operators("float64", filters, 1, monkeypatch)
    full, _, _ = operators("float64", filters, 1, monkeypatch, skip_unseen=False)
    assert host.chunks == [(0, 1), (2, 3), (3, 4)] and host.transforms() == 12 and full.transforms() == 20
    v, y = rng.standard_normal((2, 5) + geometry.field)
    r = rng.standard_normal(SENSOR)
    np.testing.assert_allclose(host.forward(v, np.empty(SENSOR)), primitive.forward(v, np.empty(SENSOR)), rtol=1e-12)
    adjoint = host.adjoint(r, np.full_like(v, np.nan))
    assert np.all(adjoint[[1, 4]] == 0)
    np.testing.assert_allclose(adjoint, primitive.adjoint(r, np.empty_like(v)), atol=1e-12)
    stepped = host.adjoint(r, np.full_like(v, np.nan), y, 0.5)
    np.testing.assert_array_equal(stepped[[1, 4]], y[[1, 4]])


def test_band_chunks_cut_runs_of_seen_bands():
    seen = np.array([1, 1, 1, 0, 1, 1, 0, 0, 1], bool)
    assert band_chunks(seen, 2) == [(0, 2), (2, 3), (4, 6), (8, 9)]
    assert band_chunks(seen, 10) == [(0, 3), (4, 6), (8, 9)]
    assert band_chunks(np.zeros(3, bool), 4) == []


def test_with_filters_shares_the_transfer_and_changes_the_bands(monkeypatch):
    rng = np.random.default_rng(3)
    host, _, geometry = operators("float64", rng.random((4,) + SENSOR), 1 << 20, monkeypatch)
    other = host.with_filters(rng.random((2,) + SENSOR))
    assert other.n_bands == 2 and other.transfer is host.transfer
    assert other.adjoint(rng.random(SENSOR), np.empty((2,) + geometry.field)).shape == (2,) + geometry.field


def test_the_numpy_backend_returns_the_host_pipeline(monkeypatch):
    """``backend.convolution`` on NumPy (the host path): the chunked pipeline on the arrays themselves, unseen bands
    skipped unless asked not to."""
    rng = np.random.default_rng(4)
    filters = rng.random((3,) + SENSOR)
    filters[1] = 0.0
    host, _, geometry = operators("float64", filters, 1 << 20, monkeypatch)
    be = NumpyBackend("float64")
    made = be.convolution(host.transfer, filters, geometry.field)
    assert isinstance(made, HostPathConvolution) and made.transforms() == 8
    assert be.convolution(host.transfer, filters, geometry.field, skip_unseen=False).transforms() == 12
    v = rng.standard_normal((3,) + geometry.field)
    np.testing.assert_array_equal(made.forward(v, np.empty(SENSOR)), host.forward(v, np.empty(SENSOR)))
