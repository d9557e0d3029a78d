/* haar_tv: one parallel-proximal Haar step of weighted anisotropic TV (Kamilov 2016),
 *   out_i = x_i + 1/(2D) Σ_d [clip((x_{i+e_d} − x_i)/2, ±c_d) − clip((x_i − x_{i−e_d})/2, ±c_d)]
 * over the D axes d (bit d of `active`; axes λ, y, x) with c_d = 2·D·τ·w_d; a missing neighbour adds 0;
 * `scale` = 1/(2D) (0 when D = 0); `nonneg` ≠ 0 stores max(out, 0) (the prox's projection, fused).
 * Grid (x, y, k) over x (K,H,W), dims 0, 1 rounded up; out must not alias x. */
__kernel void haar_tv(__global REAL *out, __global const REAL *x, int K, int H, int W,
                      int active, REAL c0, REAL c1, REAL c2, REAL scale, int nonneg)
{
    int xx = get_global_id(0), y = get_global_id(1), k = get_global_id(2);
    if (xx >= W || y >= H) return;
    size_t i = at3(k, y, xx, H, W), plane = (size_t)H * W;
    /* Branch-free: a missing neighbour is replaced by the element itself, so its difference is 0 and
     * clip(0) adds nothing; selects let PoCL vectorise across work items. */
    REAL v = x[i], t = 0;
    const REAL halve = 0.5;
    if (active & 1) {
        REAL next = x[k + 1 < K ? i + plane : i], prev = x[k > 0 ? i - plane : i];
        t += clip_to((next - v) * halve, c0) - clip_to((v - prev) * halve, c0);
    }
    if (active & 2) {
        REAL next = x[y + 1 < H ? i + W : i], prev = x[y > 0 ? i - W : i];
        t += clip_to((next - v) * halve, c1) - clip_to((v - prev) * halve, c1);
    }
    if (active & 4) {
        REAL next = x[xx + 1 < W ? i + 1 : i], prev = x[xx > 0 ? i - 1 : i];
        t += clip_to((next - v) * halve, c2) - clip_to((v - prev) * halve, c2);
    }
    REAL result = t * scale + v;
    out[i] = nonneg && result < 0 ? (REAL)0 : result;
}

/* difference_term: |d|, or d² with `squared` (the difference in REAL, its magnitude or square in ACC). */
inline ACC difference_term(REAL d, int squared) { return squared ? (ACC)d * (ACC)d : (ACC)fabs(d); }

/* sum_of_differences: Σ_{i<n} difference_term(b[i] − a[i]) in ACC, four independent partial sums (a reduction the
 * compiler may not reorder by itself, so this is what lets it use vector lanes). tv_row's |·|, and the squares of
 * ADMM's balance (admm.cl). */
inline ACC sum_of_differences(__global const REAL *a, __global const REAL *b, int n, int squared)
{
    ACC s0 = 0, s1 = 0, s2 = 0, s3 = 0;
    int i = 0;
    for (; i + 4 <= n; i += 4) {
        s0 += difference_term(b[i] - a[i], squared);
        s1 += difference_term(b[i + 1] - a[i + 1], squared);
        s2 += difference_term(b[i + 2] - a[i + 2], squared);
        s3 += difference_term(b[i + 3] - a[i + 3], squared);
    }
    for (; i < n; ++i) s0 += difference_term(b[i] - a[i], squared);
    return (s0 + s1) + (s2 + s3);
}

/* tv_row: the TV terms owned by row (k, y) of x (K,H,W):
 *   Σ_x Σ_d w_d |x_{i+e_d} − x_i| over the axes (λ, y, x) with a forward neighbour (w_d = 0 skips d).
 * Summed over all K·H rows by the tv_norm reduction (reduce.cl) this is Σ_d w_d ‖∇_d x‖₁; one division
 * per row. */
inline ACC tv_row(__global const REAL *x, size_t row, int K, int H, int W, ACC w0, ACC w1, ACC w2)
{
    size_t k = row / H, y = row - k * H, plane = (size_t)H * W;
    __global const REAL *r = x + row * W;
    ACC t = 0;
    if (w2 > 0)              t += w2 * sum_of_differences(r, r + 1, W - 1, 0);
    if (w1 > 0 && y + 1 < H) t += w1 * sum_of_differences(r, r + W, W, 0);
    if (w0 > 0 && k + 1 < K) t += w0 * sum_of_differences(r, r + plane, W, 0);
    return t;
}

