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
