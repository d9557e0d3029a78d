"""ADMM for the filter-array camera, in band space: one folder holds the algorithm and its sub-problems.

* :mod:`.algorithm`: :class:`Admm`, what the driver runs, and its penalties;
* :mod:`.terms`: the penalties, the state's arrays, the calibration's terms and the steps' common base;
* :mod:`.balance`: the TV split's penalty balanced along each axis, once, from the iterate's differences;
* :mod:`.host_steps`: the steps on NumPy arrays (row blocks on the host's threads);
* :mod:`.margin`: the c-step's correction for the field's margin, a few conjugate-gradient steps on the lowest
  frequencies towards the c-step with the data split's unobserved part eliminated (on both backends, worked on the
  host);
* :mod:`.jit_steps`: the same with the splits, the TV adjoint and the solve along λ compiled by Numba, one loop a pass
  (the ``jit`` extra; :func:`~.algorithm.host_steps` picks it where Numba is installed);
* :mod:`.kernel_steps`: the steps as ``kernels/admm.cl`` on a backend with programs (OpenCL), chosen by
  :func:`band_steps` from the backend's optional :class:`~clsdcam.backends.base.Programs`, never by its name.

The problem, on the field (K, Hp, Wp) in the solver's units:

    min_{v ≥ 0} ½‖b − S·F·H v‖² + τ Σ_d w_d ‖D_d v‖₁ (+ τ₁‖v‖₁)

with H the PSF's circular convolution (its output frame has the sensor window at the origin), F the filters
(per sensor pixel p, the K values f_p: (F x)_p = f_pᵀ x_p), S the window, and D_d the forward differences along
the cube's axes d = λ, y, x (circular on the field's y and x; along λ the last difference is 0). Three splits,
each with its scaled dual: x = H·v (data), u_d = D_d·v (TV), w = v (non-negativity, and L1). One iteration:

* **c-step**, the only transforms: v = argmin μ₁/2‖Hv − x + ξ‖² + μ₂/2 Σ_d‖D_d v − u_d + η_d‖² + μ₃/2‖v − w + ρ‖²,

      (μ₁HᵀH + μ₂ΣD_dᵀD_d + μ₃I) v = μ₁Hᵀ(x − ξ) + μ₂ΣD_dᵀ(u_d − η_d) + μ₃(w − ρ)

  HᵀH and the spatial D_yᵀD_y, D_xᵀD_x are diagonal in the 2-D Fourier basis (|Ĥ|², 2 − 2cos(2πk/N)), the same
  for every band; D_λᵀD_λ, the path graph's Laplacian along the bands, is tridiagonal (1, 2, …, 2, 1; −1 beside).
  So the system is one K×K tridiagonal system per Fourier coefficient ω:

      (a_ω·I + μ₂,λ·D_λᵀD_λ) v̂_ω = μ₁conj(Ĥ_ω)·rfft2(x − ξ)_ω + rfft2(Σ_d μ₂,dD_dᵀ(u_d − η_d) + μ₃(w − ρ))_ω,
      a_ω = μ₁|Ĥ_ω|² + μ₂,y|d̂_y|² + μ₂,x|d̂_x|² + μ₃ > 0,

  strictly diagonally dominant, solved by Thomas's sweeps on pivots computed once per penalties
  (:func:`~.terms.band_pivots`; the kernels form theirs on the device): each coefficient read and written twice,
  where a DCT along λ (which diagonalises D_λᵀD_λ) would mix all K bands twice. Then v = irfft2(v̂) and
  Hv = irfft2(Ĥ·v̂): 2K forward and 2K inverse transforms, as one FISTA gradient.
* **x-step**, per pixel (Sherman–Morrison): with q = Hv + ξ, argmin ½(b_p − f_pᵀx_p)² + μ₁/2‖x_p − q_p‖² is
  x_p = q_p + f_p·(b_p − f_pᵀq_p)/(μ₁ + ‖f_p‖²) on the sensor window, x_p = q_p outside it.
* **u-step**: u_d = soft(D_d v + η_d, τw_d/μ₂), the exact prox of the anisotropic TV (not the Haar average FISTA
  uses: the two minimisers differ, so compare them against the truth, not the objective).
* **w-step**: w = max(v + ρ − τ₁/μ₃, 0) (no L1 term: τ₁ = 0).

Each split's dual follows its step: with q = K·v + dual, z = prox(q), dual⁺ = q − z, so what the next c-step needs
of the split, z − dual⁺ = 2z − q, is formed in the same pass, and neither u nor x is kept:

* data: ξ⁺ = −f_p·(b_p − f_pᵀq_p)/(μ₁ + ‖f_p‖²) on the window and 0 outside it (kept on the window only), and
  x − ξ⁺ = q + 2(x − q) is written over Hv (the host keeps x − ξ as its spectrum and steps it there, its x-step on
  the window alone: :mod:`.host_steps`);
* TV: η_d⁺ = clip(q, ±τw_d/μ₂) (the soft threshold's remainder) and s_d = u_d − η_d⁺ = q − 2η_d⁺;
* non-negativity: ρ⁺ = q − w and μ₃(w − ρ⁺), the start of the next right-hand side, to which one more pass adds
  μ₂ΣD_dᵀs_d.

The duals are scaled (ξ = λ/μ₁); the penalties are relative to the problem's own scales
(:func:`~clsdcam.algorithms.admm.algorithm.penalties_for`); docs/admm.md has the measurements.
"""
from __future__ import annotations

from .algorithm import Admm, band_steps, penalties_for

__all__ = ["Admm", "band_steps", "penalties_for"]
