/* mask_sum: b[y,x] = Σ_k F[k,y,x] · field[k, oy+y, ox+x]   (the spectral filter sum of A).
 * Grid (x, y) over the sensor (H, W), dims 0, 1 rounded up (bounds-checked).
 * Shapes: F (K,H,W), field (K,Hp,Wp), b (H,W). Accumulates in REAL, k ascending. */
__kernel void mask_sum(__global REAL *b, __global const REAL *F, __global const REAL *field,
                       int K, int H, int W, int Hp, int Wp, int oy, int ox)
{
    int x = get_global_id(0), y = get_global_id(1);
    if (x >= W || y >= H) return;
    REAL s = 0;
    for (int k = 0; k < K; ++k)
        s += F[at3(k, y, x, H, W)] * field[at3(k, oy + y, ox + x, Hp, Wp)];
    b[(size_t)y * W + x] = s;
}

/* mask_spread: field[k,Y,X] = F[k,Y-oy,X-ox] · r[Y-oy,X-ox] inside the sensor window, 0 outside
 * (the adjoint of mask_sum, zero padding fused in: one pass over the field).
 * Grid (X, Y, k) over the field (K, Hp, Wp), dims 0, 1 rounded up.
 * Shapes: F (K,H,W), r (H,W), field (K,Hp,Wp). */
__kernel void mask_spread(__global REAL *field, __global const REAL *F, __global const REAL *r,
                          int K, int H, int W, int Hp, int Wp, int oy, int ox)
{
    int X = get_global_id(0), Y = get_global_id(1), k = get_global_id(2);
    if (X >= Wp || Y >= Hp) return;
    int y = Y - oy, x = X - ox;
    int cy = clamp(y, 0, H - 1), cx = clamp(x, 0, W - 1);     /* unconditional loads, then a select (see pad) */
    REAL v = F[at3(k, cy, cx, H, W)] * r[(size_t)cy * W + cx];
    field[at3(k, Y, X, Hp, Wp)] = (y >= 0 && y < H && x >= 0 && x < W) ? v : (REAL)0;
}
