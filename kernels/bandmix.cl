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
 * Work item (p, r) computes output bands k = r·ROWS … r·ROWS + ROWS − 1 (those < K) of pixel p. A work-group is
 * TILE pixels × the row blocks of its dim 1 (all ⌈K/ROWS⌉ of them where the group size allows): it copies x's
 * TILE columns into local memory, CHUNK bands at a time, once for all its rows, so that each x[j, p] is read from
 * global memory once per group along dim 1 (not once per row block) and neighbouring work items read neighbouring
 * pixels (coalesced on GPUs, vector loads on CPUs); M's entries are the same for every work item of a row block.
 * Grid (p, r) over (⌈P/TILE⌉·TILE, row blocks rounded up to the group), groups (TILE, G); work items past P or K
 * compute but store nothing. Shapes: x (J,P), out (K,P), M (K,J); out must not alias x. */
#define BANDMIX_ROWS 8
#define BANDMIX_TILE 32
#define BANDMIX_CHUNK 32
__kernel void bandmix(__global REAL *out, __global const REAL *x, __global const REAL *M, int K, int J, long P)
{
    __local REAL tile[BANDMIX_CHUNK * BANDMIX_TILE];
    size_t lp = get_local_id(0), p0 = get_group_id(0) * BANDMIX_TILE, p = p0 + lp;
    size_t me = get_local_id(1) * BANDMIX_TILE + lp, items = get_local_size(1) * BANDMIX_TILE;
    int k0 = get_global_id(1) * BANDMIX_ROWS;
    REAL s[BANDMIX_ROWS];
    for (int r = 0; r < BANDMIX_ROWS; ++r) s[r] = 0;
    for (int j0 = 0; j0 < J; j0 += BANDMIX_CHUNK) {
        size_t chunk = min(BANDMIX_CHUNK, J - j0);
        barrier(CLK_LOCAL_MEM_FENCE);                       /* every work item is done with the last chunk */
        for (size_t e = me; e < chunk * BANDMIX_TILE; e += items) {
            size_t q = p0 + e % BANDMIX_TILE;
            tile[e] = q < (size_t)P ? x[(size_t)(j0 + e / BANDMIX_TILE) * P + q] : 0;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        for (size_t j = 0; j < chunk; ++j) {
            REAL v = tile[j * BANDMIX_TILE + lp];
            for (int r = 0; r < BANDMIX_ROWS; ++r) s[r] += M[min(k0 + r, K - 1) * J + j0 + (int)j] * v;  /* rows ≥ K: not stored */
        }
    }
    if (p < (size_t)P)
        for (int r = 0; r < BANDMIX_ROWS && k0 + r < K; ++r) out[(size_t)(k0 + r) * P + p] = s[r];
}
