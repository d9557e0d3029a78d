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
 * tracked band Q of the x-step's relaxed point: Ξ⁺ = (Q − D)/2 into E, and x̂⁺'s band S = D + Ξ⁺. Where the band starts
 * again (restart ≠ 0) Q is ξ⁺'s whole spectrum, and Ξ⁺ its band. 1-D grid over the band's N = K·rows·cols
 * coefficients. */
__kernel void admm_margin_split(__global const REAL2 *X, __global const REAL2 *Q, __global REAL2 *S,
                                __global REAL2 *E, int restart, int N, int rows, int cols, int Hp, int Wq)
{
    int i = get_global_id(0);
    if (i >= N) return;
    size_t at = band_at(i, rows, cols, Hp, Wq);
    REAL2 d = X[at];
    REAL ex, ey;
    if (restart) {
        REAL2 e = Q[at];
        ex = e.x;
        ey = e.y;
    } else {
        REAL2 q = Q[i];
        ex = (q.x - d.x) * (REAL)0.5;
        ey = (q.y - d.y) * (REAL)0.5;
    }
    store_complex(E, i, ex, ey);
    store_complex(S, i, d.x + ex, d.y + ey);
}

/* z = Cd·(Ĥv̂₀ − x̂) along λ at each (r, c) (the orthonormal DCT-II's modes, Cd (K, K)), X v̂₀'s spectrum and S x̂'s
 * band: the masked system's residual before μ₁Ĥ*(I − M), in the modes. 1-D grid over the band's N coefficients. */
__kernel void admm_margin_residual(__global const REAL2 *X, __global const REAL2 *S, __global const REAL2 *Hh,
                                   __global const REAL *Cd, __global REAL2 *z, int K, int rows, int cols, int Hp,
                                   int Wq)
{
    int i = get_global_id(0), plane = rows * cols;
    if (i >= K * plane) return;
    int j = i / plane, rc = band_mod(i, plane);
    REAL2 t = Hh[rc];
    REAL sx = 0, sy = 0;
    for (int k = 0; k < K; ++k) {
        REAL2 v = X[band_at(k * plane + rc, rows, cols, Hp, Wq)], s = S[k * plane + rc];
        REAL m = Cd[j * K + k];
        sx += m * ((t.x * v.x - t.y * v.y) - s.x);
        sy += m * ((t.x * v.y + t.y * v.x) - s.y);
    }
    store_complex(z, i, sx, sy);
}

/* The per-mode passes below run over one mode's plane of n = rows·cols coefficients in local memory, in one work
 * group: item l takes i = l, l + L, … < n, and a barrier separates every pass that reads what another item wrote. */
#define PLANE_EACH(i) for (int i = get_local_id(0); i < n; i += get_local_size(0))

inline void store_local(__local REAL2 *z, int i, REAL re, REAL im) { vstore2((REAL2)(re, im), i, (__local REAL *)z); }

/* out = μ₁Ĥ*(I − M)·(Ĥ if `transfer`)·z on one mode's plane, M = M_y ⊗ M_x the window's mask (margin.py's T): the
 * columns k_x < 0 of z from its Hermitian symmetry (z_{−k} = conj z_k), then (z M_x) along the columns into `across`,
 * then M_y along the rows. T is μ₁conj(Ĥ)'s band and Hh Ĥ's (rows, cols), My (rows, rows), Mx (2·cols − 1, cols)
 * with row c′ for k_x = c′ − (cols − 1); `y` holds Ĥz when `transfer`. */
inline void pulled(__local const REAL2 *z, __local REAL2 *out, __local REAL2 *y, __local REAL2 *across,
                   __global const REAL2 *T, __global const REAL2 *Hh, __global const REAL2 *My,
                   __global const REAL2 *Mx, int transfer, int rows, int cols)
{
    int n = rows * cols;
    __local const REAL2 *in = z;
    if (transfer) {
        PLANE_EACH(i) {
            REAL2 t = Hh[i], v = z[i];
            store_local(y, i, t.x * v.x - t.y * v.y, t.x * v.y + t.y * v.x);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        in = y;
    }
    PLANE_EACH(i) {
        int r = i / cols, c = band_mod(i, cols);
        REAL sx = 0, sy = 0;
        for (int cc = 0; cc < 2 * cols - 1; ++cc) {
            REAL2 m = Mx[cc * cols + c], w;
            if (cc >= cols - 1) {
                w = in[r * cols + cc - (cols - 1)];
            } else {
                w = in[(rows - 1 - r) * cols + (cols - 1 - cc)];
                w.y = -w.y;
            }
            sx += w.x * m.x - w.y * m.y;
            sy += w.x * m.y + w.y * m.x;
        }
        store_local(across, i, sx, sy);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    PLANE_EACH(i) {
        int r = i / cols, c = band_mod(i, cols);
        REAL sx = 0, sy = 0;
        for (int rr = 0; rr < rows; ++rr) {
            REAL2 m = My[r * rows + rr], a = across[rr * cols + c];
            sx += m.x * a.x - m.y * a.y;
            sy += m.x * a.y + m.y * a.x;
        }
        REAL2 v = in[i], t = T[i];
        REAL dx = v.x - sx, dy = v.y - sy;
        store_local(out, i, t.x * dx - t.y * dy, t.x * dy + t.y * dx);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
}

/* ⟨a, b⟩ of the real fields whose half spectra's planes a and b are: Σ w_c·Re(conj(a)·b), w_c = 1 at c = 0, else 2;
 * the group's total, in ACC. */
inline ACC plane_dot(__local const REAL2 *a, __local const REAL2 *b, __local ACC *scratch, int n, int cols)
{
    ACC s = 0, comp = 0;
    PLANE_EACH(i) {
        REAL2 x = a[i], y = b[i];
        REAL w = band_mod(i, cols) ? (REAL)2 : (REAL)1;
        acc_add(&s, &comp, (ACC)(w * x.x) * (ACC)y.x + (ACC)(w * x.y) * (ACC)y.y);
    }
    ACC total = group_reduce(s - comp, scratch, 0);
    barrier(CLK_LOCAL_MEM_FENCE);               /* every item has read the total before the scratch is used again */
    return total;
}

/* admm_margin_cg: `steps` conjugate gradients on ΠAΠ·δ̂ = r₀ in the modes along λ, one work group a mode j (its
 * own step lengths: A is block diagonal over the modes), preconditioned by P⁻¹: r₀ = μ₁Ĥ*(I − M)·Z (Z the mode's
 * plane of admm_margin_residual's output), A·p = P·p − μ₁Ĥ*(I − M)Ĥ·p (P and P⁻¹ diagonal there); δ̂ into D.
 * L holds the seven plane-sized arrays (r, z, p, A·p, δ̂ and two temporaries), scratch one accumulator an item. */
__kernel void admm_margin_cg(__global const REAL2 *Z, __global REAL2 *D, __global const REAL2 *Hh,
                             __global const REAL2 *T, __global const REAL *P, __global const REAL *Pinv,
                             __global const REAL2 *My, __global const REAL2 *Mx, int steps, int rows, int cols,
                             __local REAL2 *L, __local ACC *scratch)
{
    int n = rows * cols;
    size_t first = (size_t)get_group_id(0) * n;
    __local REAL2 *r = L, *z = L + n, *p = L + 2 * n, *ap = L + 3 * n, *delta = L + 4 * n, *y = L + 5 * n,
                  *across = L + 6 * n;
    PLANE_EACH(i) y[i] = Z[first + i];
    barrier(CLK_LOCAL_MEM_FENCE);
    pulled(y, r, y, across, T, Hh, My, Mx, 0, rows, cols);          /* r₀ */
    PLANE_EACH(i) {
        REAL2 g = r[i];
        REAL m = Pinv[first + i];
        store_local(z, i, g.x * m, g.y * m);
        store_local(p, i, g.x * m, g.y * m);
        store_local(delta, i, 0, 0);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    ACC rz = plane_dot(r, z, scratch, n, cols);
    for (int step = 0; step < steps && rz > 0; ++step) {
        pulled(p, ap, y, across, T, Hh, My, Mx, 1, rows, cols);    /* μ₁Ĥ*(I − M)Ĥ·p */
        PLANE_EACH(i) {                                             /* ap = P·p − μ₁Ĥ*(I − M)Ĥ·p */
            REAL2 v = p[i], u = ap[i];
            REAL m = P[first + i];
            store_local(ap, i, m * v.x - u.x, m * v.y - u.y);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        REAL length = (REAL)(rz / plane_dot(p, ap, scratch, n, cols));
        PLANE_EACH(i) {
            REAL2 d = delta[i], v = p[i];
            store_local(delta, i, d.x + length * v.x, d.y + length * v.y);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        if (step + 1 == steps) break;
        PLANE_EACH(i) {
            REAL2 g = r[i], u = ap[i];
            REAL m = Pinv[first + i], gx = g.x - length * u.x, gy = g.y - length * u.y;
            store_local(r, i, gx, gy);
            store_local(z, i, gx * m, gy * m);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        ACC last = rz;
        rz = plane_dot(r, z, scratch, n, cols);
        REAL ratio = (REAL)(rz / last);
        PLANE_EACH(i) {
            REAL2 g = z[i], v = p[i];
            store_local(p, i, g.x + ratio * v.x, g.y + ratio * v.y);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    PLANE_EACH(i) {
        REAL2 d = delta[i];
        store_complex(D, first + i, d.x, d.y);
    }
}

/* admm_margin_apply: δ̂ = Cdᵀ·D back in the bands, its column k_x = 0 made Hermitian along k_y; then X's band ← v̂ =
 * v̂₀ + δ̂, Rs's band ← Ĥv̂ (Rs the rest's spectrum), and Q ← αĤv̂ + βx̂ + Ξ (S x̂'s band, E Ξ's, β = 1 − α).
 * 1-D grid over the band's N coefficients. */
__kernel void admm_margin_apply(__global REAL2 *X, __global REAL2 *Rs, __global const REAL2 *S,
                                __global const REAL2 *E, __global REAL2 *Q, __global const REAL2 *D,
                                __global const REAL2 *Hh, __global const REAL *Cd, REAL alpha, REAL beta, int K,
                                int rows, int cols, int Hp, int Wq)
{
    int i = get_global_id(0), plane = rows * cols;
    if (i >= K * plane) return;
    int k = i / plane, rc = band_mod(i, plane), r = rc / cols, c = band_mod(rc, cols);
    int mirror = (rows - 1 - r) * cols;           /* (−k_y, 0), read where c = 0 */
    REAL dx = 0, dy = 0, bx = 0, by = 0;
    for (int j = 0; j < K; ++j) {
        REAL m = Cd[j * K + k];
        REAL2 d = D[j * plane + rc];
        dx += m * d.x;
        dy += m * d.y;
        if (c == 0) {
            REAL2 e = D[j * plane + mirror];
            bx += m * e.x;
            by += m * e.y;
        }
    }
    if (c == 0) {
        dx = (dx + bx) * (REAL)0.5;
        dy = (dy - by) * (REAL)0.5;
    }
    size_t at = band_at(i, rows, cols, Hp, Wq);
    REAL2 v = X[at], t = Hh[rc], s = S[i], e = E[i];
    REAL vx = v.x + dx, vy = v.y + dy;
    REAL hx = t.x * vx - t.y * vy, hy = t.x * vy + t.y * vx;
    store_complex(X, at, vx, vy);
    store_complex(Rs, at, hx, hy);
    store_complex(Q, i, alpha * hx + beta * s.x + e.x, alpha * hy + beta * s.y + e.y);
}

#undef PLANE_EACH
