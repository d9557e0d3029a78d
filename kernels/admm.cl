/* ADMM's passes over the field (clsdcam/algorithms/admm/ derives them; its kernel_steps.py launches them).
 * Cubes are (K, Hp, Wp) C-contiguous; the sensor window (H, W) sits at the field's origin; ξ and the filters f are
 * (K, H, W); b and the x-step's r = 1/(μ₁ + ‖f‖²) (terms.x_step_reciprocal) are (H, W). The split arrays η and s
 * hold one cube per active TV axis, in axis order (λ, y, x). Differences along λ stop at the last band; along y and x
 * they are circular. */

/* admm_x_step, a reduction (reduce.cl) over the n = Hp·Wp field pixels: with q_k = α·hv_k + (1 − α)·x_k (+ ξ_k on
 * the window) at pixel p, on the sensor window
 *   ξ_k ← −g_k·(b − Σ_j f_j·q_j),   x_k ← q_k − ξ_k,   hv_k ← x_k − ξ_k   (= x − ξ⁺, the next c-step's data term)
 * with the gain g_k = f_k·r (r: `reciprocal`) rounded to REAL (as the host's terms.PenaltyTerms.gain)
 * and outside it x_k ← q_k, hv_k ← q_k (no data there, no dual); partial sums of ½(Σ_k f_k·hv_k − b)², the data
 * term at v (before the step). Sums over k in ACC. */
__kernel void admm_x_step(__global ACC *partial, __local ACC *scratch, long n, long span, long step,
                          __global REAL *hv, __global REAL *x, __global REAL *xi, __global const REAL *f,
                          __global const REAL *reciprocal, __global const REAL *b, int K, int H, int W, int Wp,
                          REAL alpha)
{
    ACC s = 0, c = 0;
    size_t window = (size_t)H * W;
    FOR_TERMS(at) {
        size_t y = at / Wp, col = at % Wp, p = y * W + col;
        if (y >= H || col >= W) {
            for (int k = 0; k < K; ++k) {
                size_t i = k * n + at;
                REAL q = alpha * hv[i] + ((REAL)1 - alpha) * x[i];
                x[i] = q;
                hv[i] = q;
            }
            continue;
        }
        ACC fitted = 0, stepped = 0;
        for (int k = 0; k < K; ++k) {
            size_t i = k * n + at;
            REAL fk = f[k * window + p], h = hv[i];
            fitted += (ACC)fk * (ACC)h;
            stepped += (ACC)fk * (ACC)(alpha * h + ((REAL)1 - alpha) * x[i] + xi[k * window + p]);
        }
        REAL misfit = b[p] - (REAL)stepped, rp = reciprocal[p];
        for (int k = 0; k < K; ++k) {
            size_t i = k * n + at;
            REAL gain = f[k * window + p] * rp;
            REAL q = alpha * hv[i] + ((REAL)1 - alpha) * x[i] + xi[k * window + p], e = -gain * misfit;
            xi[k * window + p] = e;
            q -= e;
            x[i] = q;
            hv[i] = q - e;
        }
        ACC r = fitted - (ACC)b[p];
        acc_add(&s, &c, (ACC)0.5 * r * r);
    }
    store_partial(partial, group_reduce(s - c, scratch, 0));
}

/* admm_w_step, a reduction over the n = K·Hp·Wp elements: with q = α·v + (1 − α)·w + ρ,
 *   w⁺ = max(q − shift, 0),   ρ ← q − w⁺,   rest ← μ₃(w⁺ − ρ)   (the next right-hand side's start);
 * partial sums of ‖w⁺ − w‖² (output 0) and ‖w⁺‖² (output 1). NaN propagates, as np.maximum. */
__kernel void admm_w_step(__global ACC *partial, __local ACC *scratch, long n, long span, long step,
                          __global const REAL *v, __global REAL *rho, __global REAL *w, __global REAL *rest,
                          REAL shift, REAL mu, REAL alpha)
{
    ACC s0 = 0, c0 = 0, s1 = 0, c1 = 0;
    FOR_TERMS(i) {
        REAL q = alpha * v[i] + ((REAL)1 - alpha) * w[i] + rho[i], z = q - shift;
        z = z < 0 ? (REAL)0 : z;
        REAL d = w[i] - z;
        acc_add(&s0, &c0, (ACC)d * (ACC)d);
        acc_add(&s1, &c1, (ACC)z * (ACC)z);
        w[i] = z;
        q -= z;
        rho[i] = q;
        rest[i] = mu * (z - q);
    }
    store_partial_of(partial, 0, group_reduce(s0 - c0, scratch, 0));
    store_partial_of(partial, 1, group_reduce(s1 - c1, scratch, 0));
}

/* (D_axis v) at (k, y, x): the next element along the axis minus this one (0 at the last band). */
inline REAL forward_difference(__global const REAL *v, int axis, int k, int y, int x, int K, int Hp, int Wp)
{
    REAL here = v[at3(k, y, x, Hp, Wp)];
    if (axis == 0) return k + 1 < K ? v[at3(k + 1, y, x, Hp, Wp)] - here : (REAL)0;
    if (axis == 1) return v[at3(k, y + 1 == Hp ? 0 : y + 1, x, Hp, Wp)] - here;
    return v[at3(k, y, x + 1 == Wp ? 0 : x + 1, Hp, Wp)] - here;
}

/* admm_u_step: for each active axis d (bit d of mask) with its threshold t_d = τw_d/μ₂ and
 * q = α·D_d v + (1 − α)·u_d + η_d, where u_d = s_d + η_d,
 *   η_d ← clip(q, ±t_d),   s_d ← q − 2η_d   (= u_d − η_d⁺, soft(q, t_d) being q − clip(q, ±t_d)).
 * Grid (x, y, k) over (Wp, Hp, K), x and y rounded up (bounds-checked). */
__kernel void admm_u_step(__global REAL *eta, __global REAL *s, __global const REAL *v, int K, int Hp, int Wp,
                          int mask, REAL t0, REAL t1, REAL t2, REAL alpha)
{
    int x = get_global_id(0), y = get_global_id(1), k = get_global_id(2);
    if (x >= Wp || y >= Hp) return;
    size_t cube = (size_t)K * Hp * Wp, at = at3(k, y, x, Hp, Wp);
    REAL limits[3] = {t0, t1, t2};
    for (int axis = 0; axis < 3; ++axis) {
        if (!((mask >> axis) & 1)) continue;
        REAL q = alpha * forward_difference(v, axis, k, y, x, K, Hp, Wp) + ((REAL)1 - alpha) * s[at]
                 + ((REAL)2 - alpha) * eta[at], e = clip_to(q, limits[axis]);
        eta[at] = e;
        s[at] = (q - e) - e;
        at += cube;
    }
}

/* admm_tv_adjoint: rest += Σ_d μ₂,d·D_dᵀ s_d over the active axes (bit d of mask; μ₂,d = mu_d, the axis's TV
 * penalty), with (D_dᵀu)_i = u_{i−1} − u_i (along λ u_{−1} = 0 and u_{K−1} unused; circular along y and x), each
 * axis's two terms added in NumPy's order. Grid (x, y, k) over (Wp, Hp, K), x and y rounded up (bounds-checked). */
__kernel void admm_tv_adjoint(__global REAL *rest, __global const REAL *s, int K, int Hp, int Wp, int mask,
                              REAL mu0, REAL mu1, REAL mu2)
{
    int x = get_global_id(0), y = get_global_id(1), k = get_global_id(2);
    if (x >= Wp || y >= Hp) return;
    size_t cube = (size_t)K * Hp * Wp, i = at3(k, y, x, Hp, Wp);
    __global const REAL *u = s;
    REAL r = rest[i], penalties[3] = {mu0, mu1, mu2};
    for (int axis = 0; axis < 3; ++axis) {
        if (!((mask >> axis) & 1)) continue;
        REAL mu = penalties[axis];
        if (axis == 0) {
            if (k + 1 < K) r -= mu * u[i];
            if (k > 0) r += mu * u[at3(k - 1, y, x, Hp, Wp)];
        } else {
            size_t before = axis == 1 ? at3(k, y == 0 ? Hp - 1 : y - 1, x, Hp, Wp)
                                      : at3(k, y, x == 0 ? Wp - 1 : x - 1, Hp, Wp);
            r -= mu * u[i];
            r += mu * u[before];
        }
        u += cube;
    }
    rest[i] = r;
}

/* admm_rescale_tv_duals: the TV split's scaled duals for new penalties, the unscaled μ₂,d·η_d kept: over the
 * active axes' slabs of η and s (one slab per active axis, in axis order), with r_d = μ₂,d(old)/μ₂,d(new),
 *   s_d ← s_d + (1 − r_d)·η_d,   η_d ← r_d·η_d   (u_d = s_d + η_d unchanged).
 * Grid over the cube's n elements. */
__kernel void admm_rescale_tv_duals(__global REAL *eta, __global REAL *s, long n, int mask, REAL r0, REAL r1,
                                    REAL r2)
{
    size_t i = get_global_id(0);
    if (i >= (size_t)n) return;
    REAL ratios[3] = {r0, r1, r2};
    for (int axis = 0; axis < 3; ++axis) {
        if (!((mask >> axis) & 1)) continue;
        REAL r = ratios[axis], e = eta[i];
        s[i] += ((REAL)1 - r) * e;
        eta[i] = r * e;
        i += (size_t)n;
    }
}

/* admm_band_solve: the c-step's solve at each Fourier coefficient i of the plane (one work item each). With the
 * right-hand side r_k = X_k·T_i + R_k (T = μ₁conj(Ĥ)), the tridiagonal system (a_i·I + e·D_λᵀD_λ)v = r along the
 * K bands by Thomas's sweeps on the pivots m (terms.band_pivots; e = μ₂,λ, 0 without TV along λ):
 *   forward g_k = (r_k + e·g_{k−1})·m_k,   back v_k = g_k + (e·m_k)·v_{k+1};
 * then X_k ← v_k and R_k ← Ĥ_i·v_k. X, R, m are (K, plane), T and Ĥ (plane). Each band's coefficients are
 * consecutive work items (coalesced). 1-D grid over the plane (rounded up, bounds-checked). */
__kernel void admm_band_solve(__global REAL2 *X, __global REAL2 *R, __global const REAL2 *T,
                              __global const REAL2 *Hh, __global const REAL *m, REAL e, int K, long plane)
{
    size_t i = get_global_id(0);
    if (i >= (size_t)plane) return;
    REAL2 t = T[i], h = Hh[i];
    REAL gx = 0, gy = 0;
    for (int k = 0; k < K; ++k) {
        size_t at = k * plane + i;
        REAL2 a = X[at], r = R[at];
        REAL pivot = m[at];
        gx = (a.x * t.x - a.y * t.y + r.x + e * gx) * pivot;
        gy = (a.x * t.y + a.y * t.x + r.y + e * gy) * pivot;
        store_complex(X, at, gx, gy);
    }
    store_complex(R, (K - 1) * plane + i, gx * h.x - gy * h.y, gx * h.y + gy * h.x);
    for (int k = K - 2; k >= 0; --k) {
        size_t at = k * plane + i;
        REAL2 g = X[at];
        REAL factor = m[at] * e;
        gx = g.x + gx * factor;
        gy = g.y + gy * factor;
        store_complex(X, at, gx, gy);
        store_complex(R, at, gx * h.x - gy * h.y, gx * h.y + gy * h.x);
    }
}

/* The type of admm_band_pivots' recursion: ACC where it is double (no -DKAHAN: the device has fp64), else REAL; the
 * kernel is launched only where it is double (a device without fp64 takes the host's pivots, kernel_steps.py). */
#ifdef KAHAN
#define PIVOT REAL
#else
#define PIVOT ACC
#endif

/* admm_band_pivots: Thomas's reciprocal pivots of the c-step's systems (a_i·I + e·D_λᵀD_λ)v = r along the K bands,
 * at each Fourier coefficient i of the plane (one work item each; terms.band_pivots, whose float64 arithmetic this
 * follows in PIVOT):
 *   m_0 = 1/(a_i + e·deg_0),   m_k = 1/(a_i + e·deg_k − e²·m_{k−1}),   deg_k = [k > 0] + [k < K − 1]
 * (D_λᵀD_λ's diagonal, 1, 2, …, 2, 1; 0 for one band), written in REAL into m (K, plane), admm_band_solve's pivots;
 * a (plane) in PIVOT. 1-D grid over the plane (rounded up, bounds-checked). */
__kernel void admm_band_pivots(__global REAL *m, __global const PIVOT *a, PIVOT e, int K, long plane)
{
    size_t i = get_global_id(0);
    if (i >= (size_t)plane) return;
    PIVOT diagonal = a[i], coupled = e * e, pivot = 0;
    for (int k = 0; k < K; ++k) {
        PIVOT degree = (PIVOT)((k > 0) + (k + 1 < K));
        pivot = (PIVOT)1 / (diagonal + e * degree - coupled * pivot);
        m[k * plane + i] = (REAL)pivot;
    }
}

/* sum_of_squared_differences: Σ_{i<n} (b[i] − a[i])², the difference in REAL, its square in ACC, in four independent
 * partial sums (a reduction the compiler may not reorder by itself, so this is what lets it use vector lanes). */
inline ACC sum_of_squared_differences(__global const REAL *a, __global const REAL *b, int n)
{
    ACC s0 = 0, s1 = 0, s2 = 0, s3 = 0;
    int i = 0;
    for (; i + 4 <= n; i += 4) {
        REAL d0 = b[i] - a[i], d1 = b[i + 1] - a[i + 1], d2 = b[i + 2] - a[i + 2], d3 = b[i + 3] - a[i + 3];
        s0 += (ACC)d0 * (ACC)d0;
        s1 += (ACC)d1 * (ACC)d1;
        s2 += (ACC)d2 * (ACC)d2;
        s3 += (ACC)d3 * (ACC)d3;
    }
    for (; i < n; ++i) {
        REAL d = b[i] - a[i];
        s0 += (ACC)d * (ACC)d;
    }
    return (s0 + s1) + (s2 + s3);
}

/* admm_difference_squares, a reduction over the n = K·Hp rows of w (K, Hp, Wp): partial sums of (D_d w)² for each
 * axis d (output d; 0 for an axis not in mask, bit d), the differences in REAL as the u-step takes them (0 at the
 * last band, circular along y and x: forward_difference's), their squares in ACC (sum_of_squared_differences), a
 * row's summed along it and the rows' compensated (-DKAHAN). One division per row; the inner loops run along the
 * rows. */
__kernel void admm_difference_squares(__global ACC *partial, __local ACC *scratch, long n, long span, long step,
                                      __global const REAL *w, int K, int Hp, int Wp, int mask)
{
    ACC s0 = 0, c0 = 0, s1 = 0, c1 = 0, s2 = 0, c2 = 0;
    size_t plane = (size_t)Hp * Wp;
    FOR_TERMS(row) {
        size_t k = row / Hp, y = row - k * Hp;
        __global const REAL *r = w + row * Wp;
        if ((mask & 1) && k + 1 < (size_t)K) acc_add(&s0, &c0, sum_of_squared_differences(r, r + plane, Wp));
        if (mask & 2) acc_add(&s1, &c1, sum_of_squared_differences(r, y + 1 < (size_t)Hp ? r + Wp : r - y * Wp, Wp));
        if (mask & 4) {
            REAL last = r[0] - r[Wp - 1];
            acc_add(&s2, &c2, sum_of_squared_differences(r, r + 1, Wp - 1) + (ACC)last * (ACC)last);
        }
    }
    store_partial_of(partial, 0, group_reduce(s0 - c0, scratch, 0));
    store_partial_of(partial, 1, group_reduce(s1 - c1, scratch, 0));
    store_partial_of(partial, 2, group_reduce(s2 - c2, scratch, 0));
}
