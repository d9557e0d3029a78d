/* ADMM's margin correction on the device (clsdcam/algorithms/admm/margin.py has the derivation; margin_kernels.py
 * launches these). The band is the field's lowest frequencies, K × rows × cols coefficients stored (k, r, c)
 * band-major: row r is k_y = r − (rows − 1)/2 (rows odd), column c is k_x = c ≥ 0. In a spectrum (K, Hp, Wq) its
 * coefficient (k, r, c) is at ((k·Hp + (k_y mod Hp))·Wq + c). Complex values are REAL2 (re, im), as everywhere. As in
 * admm.cl, T is μ₁conj(Ĥ) and Hh is Ĥ (here their bands, rows × cols). */

/* a mod b for a ≥ 0, written without %: a / and % pair becomes LLVM's `freeze`, which Oclgrind's uninitialised-value
 * check cannot interpret. */
inline int band_mod(int a, int b) { return a - a / b * b; }

/* The spectrum's index of band coefficient i = (k, r, c). */
inline size_t band_at(int i, int rows, int cols, int Hp, int Wq)
{
    int k = i / (rows * cols), rc = band_mod(i, rows * cols), r = rc / cols, c = band_mod(rc, cols);
    int row = r - (rows - 1) / 2;
    return ((size_t)k * Hp + (size_t)(row < 0 ? row + Hp : row)) * Wq + c;
}

/* admm_margin_split: before the c-step's solve, from the band D of the data split's spectrum X = rfft2(x⁺ − ξ⁺) and the
 * tracked band Q of the x-step's relaxed point: Ξ⁺ = (Q − D)/2 (or Ξ given in E where the band starts again,
 * restart ≠ 0) into E, and x̂⁺'s band S = D + Ξ⁺. 1-D grid over the band's N = K·rows·cols coefficients. */
__kernel void admm_margin_split(__global const REAL2 *X, __global const REAL2 *Q, __global REAL2 *S,
                                __global REAL2 *E, int restart, int N, int rows, int cols, int Hp, int Wq)
{
    int i = get_global_id(0);
    if (i >= N) return;
    REAL2 d = X[band_at(i, rows, cols, Hp, Wq)];
    REAL ex, ey;
    if (restart) {
        REAL2 e = E[i];
        ex = e.x;
        ey = e.y;
    } else {
        REAL2 q = Q[i];
        ex = (q.x - d.x) * (REAL)0.5;
        ey = (q.y - d.y) * (REAL)0.5;
        store_complex(E, i, ex, ey);
    }
    store_complex(S, i, d.x + ex, d.y + ey);
}

/* The loops below run over the band's coefficients in one work group: item l takes i = l, l + L, … < N, and a
 * barrier separates every pass that reads what another item wrote. */
#define MARGIN_EACH(i) for (int i = get_local_id(0); i < N; i += get_local_size(0))
#define MARGIN_SYNC barrier(CLK_GLOBAL_MEM_FENCE | CLK_LOCAL_MEM_FENCE)

/* out = Cd·in along λ at each (r, c) (the orthonormal DCT-II's modes), or Cdᵀ·in with transpose (its inverse). */
inline void modes_along(__global const REAL2 *in, __global REAL2 *out, __global const REAL *Cd, int transpose,
                        int N, int K, int plane)
{
    MARGIN_EACH(i) {
        int j = i / plane, rc = band_mod(i, plane);
        REAL sx = 0, sy = 0;
        for (int k = 0; k < K; ++k) {
            REAL m = transpose ? Cd[k * K + j] : Cd[j * K + k];
            REAL2 z = in[k * plane + rc];
            sx += m * z.x;
            sy += m * z.y;
        }
        store_complex(out, i, sx, sy);
    }
    MARGIN_SYNC;
}

/* out = μ₁Ĥ*(I − M)·z on the band, M = M_y ⊗ M_x the window's mask (margin.py's T): the columns k_x < 0 of z from
 * its Hermitian symmetry (z_{−k} = conj z_k), then (z M_x) along the columns into `across`, then M_y along the rows.
 * T is μ₁conj(Ĥ)'s band (rows, cols), My (rows, rows), Mx (2·cols − 1, cols) with row c′ for k_x = c′ − (cols − 1). */
inline void pulled(__global const REAL2 *z, __global REAL2 *out, __global REAL2 *across, __global const REAL2 *T,
                   __global const REAL2 *My, __global const REAL2 *Mx, int N, int rows, int cols)
{
    MARGIN_EACH(i) {
        int kr = i / cols, c = band_mod(i, cols), r = band_mod(kr, rows), flipped = (kr - r) + (rows - 1 - r);
        REAL sx = 0, sy = 0;
        for (int cc = 0; cc < 2 * cols - 1; ++cc) {
            REAL2 m = Mx[cc * cols + c], w;
            if (cc >= cols - 1) {
                w = z[kr * cols + cc - (cols - 1)];
            } else {
                w = z[flipped * cols + (cols - 1 - cc)];
                w.y = -w.y;
            }
            sx += w.x * m.x - w.y * m.y;
            sy += w.x * m.y + w.y * m.x;
        }
        store_complex(across, i, sx, sy);
    }
    MARGIN_SYNC;
    MARGIN_EACH(i) {
        int kr = i / cols, c = band_mod(i, cols), r = band_mod(kr, rows), first = (kr - r) * cols;
        REAL sx = 0, sy = 0;
        for (int rr = 0; rr < rows; ++rr) {
            REAL2 m = My[r * rows + rr], a = across[first + rr * cols + c];
            sx += m.x * a.x - m.y * a.y;
            sy += m.x * a.y + m.y * a.x;
        }
        REAL2 v = z[i], t = T[band_mod(i, rows * cols)];
        REAL dx = v.x - sx, dy = v.y - sy;
        store_complex(out, i, t.x * dx - t.y * dy, t.x * dy + t.y * dx);
    }
    MARGIN_SYNC;
}

/* ⟨a, b⟩ of the real fields whose half spectra's bands a and b are: Σ w_c·Re(conj(a)·b), w_c = 1 at c = 0, else 2. */
inline ACC band_dot(__global const REAL2 *a, __global const REAL2 *b, __local ACC *scratch, int N, int cols)
{
    ACC s = 0, comp = 0;
    MARGIN_EACH(i) {
        REAL2 x = a[i], y = b[i];
        REAL w = band_mod(i, cols) ? (REAL)2 : (REAL)1;
        acc_add(&s, &comp, (ACC)(w * x.x) * (ACC)y.x + (ACC)(w * x.y) * (ACC)y.y);
    }
    ACC total = group_reduce(s - comp, scratch, 0);
    barrier(CLK_LOCAL_MEM_FENCE);               /* every item has read the total before the scratch is used again */
    return total;
}

/* admm_margin_correct: after the c-step's solve, the correction δ̂ of v̂₀'s band (X's) and what follows from it, in
 * one work group (global size = local size):
 *   r₀ = μ₁Ĥ*(I − M)(Ĥv̂₀ − x̂) in the modes along λ (S = x̂'s band), then `steps` conjugate gradients on
 *   ΠAΠ·δ̂ = r₀ preconditioned by P⁻¹ (A·p = P·p − μ₁Ĥ*(I − M)Ĥ·p, P and P⁻¹ diagonal there), δ̂ back in the bands
 *   with its column k_x = 0 made Hermitian along k_y; then X's band ← v̂ = v̂₀ + δ̂, Rs's band ← Ĥv̂ (Rs the rest's
 *   spectrum), and Q ← αĤv̂ + βx̂ + Ξ (E = Ξ's band, β = 1 − α).
 * W holds seven band-sized scratch arrays (X's band is read again at the end: nothing writes it before); Cd is the
 * DCT-II (K, K); scratch one accumulator a work item. */
__kernel void admm_margin_correct(__global REAL2 *X, __global REAL2 *Rs, __global const REAL2 *S,
                                  __global const REAL2 *E, __global REAL2 *Q, __global const REAL2 *Hh,
                                  __global const REAL2 *T, __global const REAL *P, __global const REAL *Pinv,
                                  __global const REAL2 *My, __global const REAL2 *Mx, __global const REAL *Cd,
                                  __global REAL2 *W, REAL alpha, REAL beta, int steps, int K, int rows, int cols,
                                  int Hp, int Wq, __local ACC *scratch)
{
    int plane = rows * cols, N = K * plane;
    __global REAL2 *y = W, *across = W + N, *r = W + 2 * N, *z = W + 3 * N, *p = W + 4 * N, *ap = W + 5 * N,
                   *delta = W + 6 * N;
    MARGIN_EACH(i) {                              /* y = Ĥv̂₀ − x̂ */
        REAL2 v = X[band_at(i, rows, cols, Hp, Wq)], t = Hh[band_mod(i, plane)], s = S[i];
        store_complex(y, i, (t.x * v.x - t.y * v.y) - s.x, (t.x * v.y + t.y * v.x) - s.y);
    }
    MARGIN_SYNC;
    modes_along(y, z, Cd, 0, N, K, plane);
    pulled(z, r, across, T, My, Mx, N, rows, cols);        /* r₀ */
    MARGIN_EACH(i) {
        REAL2 g = r[i];
        REAL m = Pinv[i];
        store_complex(z, i, g.x * m, g.y * m);
        store_complex(p, i, g.x * m, g.y * m);
        store_complex(delta, i, 0, 0);
    }
    MARGIN_SYNC;
    ACC rz = band_dot(r, z, scratch, N, cols);
    for (int step = 0; step < steps && rz > 0; ++step) {
        MARGIN_EACH(i) {                          /* y = Ĥp */
            REAL2 t = Hh[band_mod(i, plane)], v = p[i];
            store_complex(y, i, t.x * v.x - t.y * v.y, t.x * v.y + t.y * v.x);
        }
        MARGIN_SYNC;
        pulled(y, ap, across, T, My, Mx, N, rows, cols);
        MARGIN_EACH(i) {                          /* ap = P·p − μ₁Ĥ*(I − M)Ĥ·p */
            REAL2 v = p[i], u = ap[i];
            REAL m = P[i];
            store_complex(ap, i, m * v.x - u.x, m * v.y - u.y);
        }
        MARGIN_SYNC;
        REAL length = (REAL)(rz / band_dot(p, ap, scratch, N, cols));
        MARGIN_EACH(i) {
            REAL2 d = delta[i], v = p[i];
            store_complex(delta, i, d.x + length * v.x, d.y + length * v.y);
        }
        MARGIN_SYNC;
        if (step + 1 == steps) break;
        MARGIN_EACH(i) {
            REAL2 g = r[i], u = ap[i];
            REAL m = Pinv[i], gx = g.x - length * u.x, gy = g.y - length * u.y;
            store_complex(r, i, gx, gy);
            store_complex(z, i, gx * m, gy * m);
        }
        MARGIN_SYNC;
        ACC last = rz;
        rz = band_dot(r, z, scratch, N, cols);
        REAL ratio = (REAL)(rz / last);
        MARGIN_EACH(i) {
            REAL2 g = z[i], v = p[i];
            store_complex(p, i, g.x + ratio * v.x, g.y + ratio * v.y);
        }
        MARGIN_SYNC;
    }
    modes_along(delta, y, Cd, 1, N, K, plane);             /* δ̂ in the bands */
    MARGIN_EACH(i) {                              /* column k_x = 0 made Hermitian along k_y, into across */
        if (band_mod(i, cols) == 0) {
            int kr = i / cols, r0 = band_mod(kr, rows);
            REAL2 a = y[i], b = y[(kr - r0 + rows - 1 - r0) * cols];
            store_complex(across, i, (a.x + b.x) * (REAL)0.5, (a.y - b.y) * (REAL)0.5);
        }
    }
    MARGIN_SYNC;
    MARGIN_EACH(i) {
        size_t at = band_at(i, rows, cols, Hp, Wq);
        REAL2 d = band_mod(i, cols) ? y[i] : across[i], v = X[at], t = Hh[band_mod(i, plane)];
        REAL2 s = S[i], e = E[i];
        REAL vx = v.x + d.x, vy = v.y + d.y;
        REAL hx = t.x * vx - t.y * vy, hy = t.x * vy + t.y * vx;
        store_complex(X, at, vx, vy);
        store_complex(Rs, at, hx, hy);
        store_complex(Q, i, alpha * hx + beta * s.x + e.x, alpha * hy + beta * s.y + e.y);
    }
}

#undef MARGIN_EACH
#undef MARGIN_SYNC
