/* scale: out_i = a · x_i.  1-D grid over n elements (rounded up); out may alias x. */
__kernel void scale(__global REAL *out, __global const REAL *x, REAL a, long n)
{
    size_t i = get_global_id(0);
    if (i < n) out[i] = a * x[i];
}

/* axpy: out_i = a · x_i + y_i.  1-D grid over n elements (rounded up); out may alias x or y
 * (each element is read before it is written, by the same work item). */
__kernel void axpy(__global REAL *out, REAL a, __global const REAL *x, __global const REAL *y, long n)
{
    size_t i = get_global_id(0);
    if (i < n) out[i] = a * x[i] + y[i];
}

/* extrapolate: out_i = x⁺_i + β (x⁺_i − x_i)   (FISTA momentum step).
 * 1-D grid over n elements (rounded up); out may alias x (x_old) or x⁺. */
__kernel void extrapolate(__global REAL *out, __global const REAL *xnew, __global const REAL *xold,
                          REAL beta, long n)
{
    size_t i = get_global_id(0);
    if (i >= n) return;
    REAL v = xnew[i];
    out[i] = (v - xold[i]) * beta + v;
}
