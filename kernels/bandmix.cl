/* gram: partial[g,i,j] = Σ_p x[i,p]·x[j,p] over the pixels p of work-group g's work items, for j ≥ i (products and
 * sums in ACC, Kahan without fp64); the host adds the groups in float64 and mirrors j < i: G = X Xᵀ.
 * Grid (t, i, j) over (T, K, K), T = G·L with groups (L, 1, 1): work item t sums pixels t, t + T, t + 2T, …, so
 * neighbouring work items read neighbouring pixels (coalesced on GPUs, vector loads on CPUs); the group adds its
 * items in local memory (group_reduce, reduce.cl). A group has one (i, j): groups with j < i return whole.
 * Shapes: x (K, P) (a cube (K,H,W) with P = H·W), partial (G, K, K). */
__kernel void gram(__global ACC *partial, __local ACC *scratch, __global const REAL *x, int K, long P)
{
    size_t i = get_global_id(1), j = get_global_id(2);
    if (j < i) return;
    __global const REAL *a = x + i * P, *b = x + j * P;
    ACC s = 0, c = 0;
    for (size_t p = get_global_id(0); p < (size_t)P; p += get_global_size(0)) acc_add(&s, &c, (ACC)a[p] * (ACC)b[p]);
    ACC total = group_reduce(s - c, scratch, 0);
    if (get_local_id(0) == 0) partial[(get_group_id(0) * K + i) * K + j] = total;
}

/* bandmix: out[k,p] = Σ_j M[k,j]·x[j,p], a K×J matrix applied along the band axis (j ascending, in REAL):
 * a square mix (low-rank prox), or a spectral basis's expansion (K×r) or projection (r×K).
 * Work item (p, r) computes output bands k = r·ROWS … r·ROWS + ROWS − 1 (those < K) of pixel p: each x[j, p] is
 * read once for ROWS outputs, and neighbouring work items read neighbouring pixels (coalesced on GPUs, vector
 * loads on CPUs); M's entries are the same for every work item of a row of the grid.
 * Grid (p, r) over (⌈K/ROWS⌉, P), dim 0 rounded up. Shapes: x (J,P), out (K,P), M (K,J); out must not alias x. */
#define BANDMIX_ROWS 8
__kernel void bandmix(__global REAL *out, __global const REAL *x, __global const REAL *M, int K, int J, long P)
{
    size_t p = get_global_id(0);
    int k0 = get_global_id(1) * BANDMIX_ROWS;
    if (p >= (size_t)P) return;
    REAL s[BANDMIX_ROWS];
    for (int r = 0; r < BANDMIX_ROWS; ++r) s[r] = 0;
    for (int j = 0; j < J; ++j) {
        REAL v = x[(size_t)j * P + p];
        for (int r = 0; r < BANDMIX_ROWS; ++r) s[r] += M[min(k0 + r, K - 1) * J + j] * v;   /* rows ≥ K: not stored */
    }
    for (int r = 0; r < BANDMIX_ROWS && k0 + r < K; ++r) out[(size_t)(k0 + r) * P + p] = s[r];
}
