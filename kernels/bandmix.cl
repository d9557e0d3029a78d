/* gram: partial[g,i,j] = Σ_{p ∈ chunk g} x[i,p]·x[j,p] for j ≥ i (products and sum in ACC, Kahan
 * without fp64); the host adds the chunks in float64 and mirrors j < i: G = X Xᵀ.
 * Grid (j, i, g) over (G, K, K); chunk g covers pixels [g·chunk, min(P, (g+1)·chunk)).
 * Shapes: x (K, P) (a cube (K,H,W) with P = H·W), partial (G, K, K). */
__kernel void gram(__global ACC *partial, __global const REAL *x, int K, long P, long chunk)
{
    int j = get_global_id(0), i = get_global_id(1), g = get_global_id(2);
    if (j < i) return;
    size_t start = (size_t)g * chunk, stop = min((size_t)P, start + chunk);
    __global const REAL *a = x + (size_t)i * P, *b = x + (size_t)j * P;
    ACC s = 0, c = 0;
    for (size_t p = start; p < stop; ++p) acc_add(&s, &c, (ACC)a[p] * (ACC)b[p]);
    partial[at3(g, i, j, K, K)] = s - c;
}

/* bandmix: out[k,p] = Σ_j M[k,j]·x[j,p], a K×J matrix applied along the band axis (j ascending, in REAL):
 * a square mix (low-rank prox), or a spectral basis's expansion (K×r) or projection (r×K).
 * Work item (t, k) computes the BANDMIX_TILE pixels p = t·TILE … of band k (a private tile, so
 * each x[j, tile] row is read once per item and the inner loop vectorises).
 * Grid (t, k) over (K, ⌈P/TILE⌉), dim 0 rounded up. Shapes: x (J,P), out (K,P), M (K,J); out must not alias x. */
#define BANDMIX_TILE 16
__kernel void bandmix(__global REAL *out, __global const REAL *x, __global const REAL *M, int J, long P)
{
    size_t p0 = get_global_id(0) * BANDMIX_TILE, k = get_global_id(1);
    if (p0 >= P) return;
    REAL s[BANDMIX_TILE];
    for (int t = 0; t < BANDMIX_TILE; ++t) s[t] = 0;
    if (p0 + BANDMIX_TILE <= P) {
        for (int j = 0; j < J; ++j) {
            REAL m = M[k * J + j];
            __global const REAL *row = x + (size_t)j * P + p0;
            for (int t = 0; t < BANDMIX_TILE; ++t) s[t] += m * row[t];
        }
        for (int t = 0; t < BANDMIX_TILE; ++t) out[k * P + p0 + t] = s[t];
        return;
    }
    for (size_t p = p0; p < P; ++p) {          /* the last, partial tile */
        REAL v = 0;
        for (int j = 0; j < J; ++j) v += M[k * J + j] * x[(size_t)j * P + p];
        out[k * P + p] = v;
    }
}

