/* Clip v to [−c, c] (NaN propagates, as np.clip). */
inline REAL clip_to(REAL v, REAL c) { return v < -c ? -c : (v > c ? c : v); }

/* haar_tv: one parallel-proximal Haar step of weighted anisotropic TV (Kamilov 2016),
 *   out_i = x_i + 1/(2D) Σ_d [clip((x_{i+e_d} − x_i)/2, ±c_d) − clip((x_i − x_{i−e_d})/2, ±c_d)]
 * over the D axes d (bit d of `active`; axes λ, y, x) with c_d = 2·D·τ·w_d; a missing neighbour adds 0;
 * `scale` = 1/(2D) (0 when D = 0). Grid (x, y, k) over x (K,H,W), dims 0, 1 rounded up; out must not alias x. */
__kernel void haar_tv(__global REAL *out, __global const REAL *x, int K, int H, int W,
                      int active, REAL c0, REAL c1, REAL c2, REAL scale)
{
    int xx = get_global_id(0), y = get_global_id(1), k = get_global_id(2);
    if (xx >= W || y >= H) return;
    size_t i = at3(k, y, xx, H, W), plane = (size_t)H * W;
    REAL v = x[i], t = 0;
    const REAL halve = 0.5;
    if (active & 1) {
        if (k + 1 < K) t += clip_to((x[i + plane] - v) * halve, c0);
        if (k > 0)     t -= clip_to((v - x[i - plane]) * halve, c0);
    }
    if (active & 2) {
        if (y + 1 < H) t += clip_to((x[i + W] - v) * halve, c1);
        if (y > 0)     t -= clip_to((v - x[i - W]) * halve, c1);
    }
    if (active & 4) {
        if (xx + 1 < W) t += clip_to((x[i + 1] - v) * halve, c2);
        if (xx > 0)     t -= clip_to((v - x[i - 1]) * halve, c2);
    }
    out[i] = t * scale + v;
}

/* tv_term: the TV terms owned by element i = (k, y, x) of x (K,H,W):
 *   Σ_d w_d |x_{i+e_d} − x_i| over the axes (λ, y, x) with a forward neighbour (w_d = 0 skips d).
 * Summed over all i by the tv_norm reduction (reduce.cl) this is Σ_d w_d ‖∇_d x‖₁. */
inline ACC tv_term(__global const REAL *x, size_t i, int K, int H, int W, ACC w0, ACC w1, ACC w2)
{
    size_t plane = (size_t)H * W;
    size_t k = i / plane, r = i - k * plane, y = r / W, xx = r - y * W;
    REAL v = x[i];
    ACC t = 0;
    if (w0 > 0 && k + 1 < K)  t += w0 * (ACC)fabs(x[i + plane] - v);
    if (w1 > 0 && y + 1 < H)  t += w1 * (ACC)fabs(x[i + W] - v);
    if (w2 > 0 && xx + 1 < W) t += w2 * (ACC)fabs(x[i + 1] - v);
    return t;
}
