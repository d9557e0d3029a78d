/* Clip v to [−c, c] (NaN propagates, as np.clip). */
inline REAL clip_to(REAL v, REAL c) { return v < -c ? -c : (v > c ? c : v); }

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
    REAL result = t * scale + v;
    out[i] = nonneg && result < 0 ? (REAL)0 : result;
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

/* subspace_tv: c⁺ = Bᵀ·max(0, haar_tv(B·c)) for a cube in a spectral subspace: c (R,H,W) coefficients,
 * B (K,R) row-major with orthonormal columns (R ≤ SUBSPACE_MAX). One work item per pixel: it loads its
 * own and its four neighbours' coefficients, then walks the bands k, expanding v_k = Σ_j B[k,j]·c_j at
 * the pixel (a rolling window over k − 1, k, k + 1) and at the neighbours, applies the haar_tv step
 * (as haar_tv above, with max(·, 0)) and accumulates the projection c⁺_j += B[k,j]·out_k.
 * Grid (x, y, 1) over (H, W), rounded up; out must not alias c. */
#define SUBSPACE_MAX 32
inline REAL expand_at(__global const REAL *B, int k, int R, const REAL *coeffs)
{
    REAL v = 0;
    for (int j = 0; j < R; ++j) v += B[k * R + j] * coeffs[j];
    return v;
}

__kernel void subspace_tv(__global REAL *out, __global const REAL *c, __global const REAL *B, int K, int R,
                          int H, int W, int active, REAL c0, REAL c1, REAL c2, REAL scale)
{
    int xx = get_global_id(0), y = get_global_id(1);
    if (xx >= W || y >= H) return;
    size_t plane = (size_t)H * W, i = (size_t)y * W + xx;
    REAL own[SUBSPACE_MAX], up[SUBSPACE_MAX], down[SUBSPACE_MAX], left[SUBSPACE_MAX], right[SUBSPACE_MAX];
    REAL acc[SUBSPACE_MAX];
    int has_up = y > 0, has_down = y + 1 < H, has_left = xx > 0, has_right = xx + 1 < W;
    for (int j = 0; j < R; ++j) {
        size_t at = j * plane + i;
        own[j] = c[at];
        up[j] = has_up ? c[at - W] : 0;
        down[j] = has_down ? c[at + W] : 0;
        left[j] = has_left ? c[at - 1] : 0;
        right[j] = has_right ? c[at + 1] : 0;
        acc[j] = 0;
    }
    const REAL halve = 0.5;
    REAL previous = 0, v = expand_at(B, 0, R, own);
    for (int k = 0; k < K; ++k) {
        REAL next = k + 1 < K ? expand_at(B, k + 1, R, own) : 0, t = 0;
        if (active & 1) {
            if (k + 1 < K) t += clip_to((next - v) * halve, c0);
            if (k > 0)     t -= clip_to((v - previous) * halve, c0);
        }
        if (active & 2) {
            if (has_down) t += clip_to((expand_at(B, k, R, down) - v) * halve, c1);
            if (has_up)   t -= clip_to((v - expand_at(B, k, R, up)) * halve, c1);
        }
        if (active & 4) {
            if (has_right) t += clip_to((expand_at(B, k, R, right) - v) * halve, c2);
            if (has_left)  t -= clip_to((v - expand_at(B, k, R, left)) * halve, c2);
        }
        REAL result = t * scale + v;
        result = result < 0 ? (REAL)0 : result;
        for (int j = 0; j < R; ++j) acc[j] += B[k * R + j] * result;
        previous = v;
        v = next;
    }
    for (int j = 0; j < R; ++j) out[j * plane + i] = acc[j];
}
