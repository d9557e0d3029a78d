/* soft: out_i = sign(x_i) · max(|x_i| − t, 0)   (soft threshold, the prox of t‖·‖₁).
 * 1-D grid over n elements (rounded up, bounds-checked); any shape, out may alias x. */
__kernel void soft(__global REAL *out, __global const REAL *x, REAL t, long n)
{
    size_t i = get_global_id(0);
    if (i >= n) return;
    REAL v = x[i], a = fabs(v) - t;
    a = a > 0 ? a : (REAL)0;
    out[i] = v > 0 ? a : (v < 0 ? -a : (REAL)0);
}

/* nonneg: out_i = max(x_i, 0) (NaN propagates, as np.maximum).
 * 1-D grid over n elements (rounded up, bounds-checked); any shape, out may alias x. */
__kernel void nonneg(__global REAL *out, __global const REAL *x, long n)
{
    size_t i = get_global_id(0);
    if (i >= n) return;
    REAL v = x[i];
    out[i] = v < 0 ? (REAL)0 : v;
}
