/* Reductions to per-work-group partial sums, finished on the host in float64.
 * Work item g accumulates the terms i = g·span + j·step (i < n; after span terms when step = 1) in ACC
 * (double with fp64; float with Kahan compensation otherwise): span = 1, step = G (global size) on
 * GPUs (coalesced), span = ⌈n/G⌉, step = 1 on CPUs (one contiguous chunk per item). The group then
 * adds its items by a tree in local memory (local size a power of two); partial has one ACC per group. */

/* Loop over the terms of this work item (see above); declares size_t i. */
#define FOR_TERMS(i) \
    for (size_t i = get_global_id(0) * (size_t)span, last_ = step == 1 ? min((size_t)n, i + (size_t)span) : (size_t)n; \
         i < last_; i += step)

/* s += v, compensated (c carries the lost low-order part) when -DKAHAN. */
inline void acc_add(ACC *s, ACC *c, ACC v)
{
#ifdef KAHAN
    ACC y = v - *c, t = *s + y;
    *c = (t - *s) - y;
    *s = t;
#else
    *s += v;
#endif
}

/* Tree reduction of one value per work item; `op` 0 = sum, 1 = max. Returns the group total. */
inline ACC group_reduce(ACC v, __local ACC *scratch, int op)
{
    int lid = get_local_id(0);
    scratch[lid] = v;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = get_local_size(0) / 2; s > 0; s >>= 1) {
        if (lid < s) scratch[lid] = op ? fmax(scratch[lid], scratch[lid + s]) : scratch[lid] + scratch[lid + s];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    return scratch[0];
}

inline void store_partial(__global ACC *partial, ACC total)
{
    if (get_local_id(0) == 0) partial[get_group_id(0)] = total;
}

/* Output j of a reduction with several: partial holds G values per output, output j at [j·G, (j+1)·G).
 * The barrier lets the next group_reduce reuse the scratch. */
inline void store_partial_of(__global ACC *partial, int j, ACC total)
{
    if (get_local_id(0) == 0) partial[(size_t)j * get_num_groups(0) + get_group_id(0)] = total;
    barrier(CLK_LOCAL_MEM_FENCE);
}

/* vdot: partial sums of Σ_i x_i·y_i (products formed in ACC). x, y: n elements. */
__kernel void vdot(__global ACC *partial, __local ACC *scratch, long n, long span, long step,
                   __global const REAL *x, __global const REAL *y)
{
    ACC s = 0, c = 0;
    FOR_TERMS(i) acc_add(&s, &c, (ACC)x[i] * (ACC)y[i]);
    store_partial(partial, group_reduce(s - c, scratch, 0));
}

/* l1: partial sums of Σ_i |x_i|. x: n elements. */
__kernel void l1(__global ACC *partial, __local ACC *scratch, long n, long span, long step, __global const REAL *x)
{
    ACC s = 0, c = 0;
    FOR_TERMS(i) acc_add(&s, &c, (ACC)fabs(x[i]));
    store_partial(partial, group_reduce(s - c, scratch, 0));
}

/* amax: partial maxima of |x_i| (exact in any precision). x: n elements. */
__kernel void amax(__global ACC *partial, __local ACC *scratch, long n, long span, long step, __global const REAL *x)
{
    ACC m = 0;
    FOR_TERMS(i) m = fmax(m, (ACC)fabs(x[i]));
    store_partial(partial, group_reduce(m, scratch, 1));
}

/* tv_norm: partial sums of Σ_d w_d |x_{i+e_d} − x_i| over the n = K·H·W elements i of x (K,H,W), each with the
 * forward neighbours it has along (λ, y, x) (w_d = 0 skips d): summed, Σ_d w_d ‖∇_d x‖₁. A work item per element,
 * so a GPU's neighbouring items read neighbouring elements (coalesced). */
__kernel void tv_norm(__global ACC *partial, __local ACC *scratch, long n, long span, long step, __global const REAL *x,
                      int K, int H, int W, ACC w0, ACC w1, ACC w2)
{
    ACC s = 0, c = 0;
    size_t plane = (size_t)H * W;
    FOR_TERMS(i) {
        size_t k = i / plane, rest = i - k * plane, y = rest / W, col = rest - y * W;
        REAL v = x[i];
        ACC t = 0;
        if (w2 > 0 && col + 1 < W) t += w2 * (ACC)fabs(x[i + 1] - v);
        if (w1 > 0 && y + 1 < H)   t += w1 * (ACC)fabs(x[i + W] - v);
        if (w0 > 0 && k + 1 < K)   t += w0 * (ACC)fabs(x[i + plane] - v);
        acc_add(&s, &c, t);
    }
    store_partial(partial, group_reduce(s - c, scratch, 0));
}

/* fista_stats: partial sums of (d², x⁺², (y − x⁺)·d) with d = x⁺ − x, the differences in REAL (as NumPy),
 * the products in ACC: FISTA's ‖x⁺ − x‖², ‖x⁺‖² and restart test ⟨y − x⁺, x⁺ − x⟩ in one pass. */
__kernel void fista_stats(__global ACC *partial, __local ACC *scratch, long n, long span, long step,
                          __global const REAL *xnew, __global const REAL *xold, __global const REAL *y)
{
    ACC s0 = 0, c0 = 0, s1 = 0, c1 = 0, s2 = 0, c2 = 0;
    FOR_TERMS(i) {
        REAL a = xnew[i], d = a - xold[i], back = y[i] - a;
        acc_add(&s0, &c0, (ACC)d * (ACC)d);
        acc_add(&s1, &c1, (ACC)a * (ACC)a);
        acc_add(&s2, &c2, (ACC)back * (ACC)d);
    }
    store_partial_of(partial, 0, group_reduce(s0 - c0, scratch, 0));
    store_partial_of(partial, 1, group_reduce(s1 - c1, scratch, 0));
    store_partial_of(partial, 2, group_reduce(s2 - c2, scratch, 0));
}
