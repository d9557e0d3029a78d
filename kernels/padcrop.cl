/* pad: out[b,Y,X] = x[b, Y-oy, X-ox] inside the window, 0 outside.
 * Grid (X, Y, b) over the output (B, Hp, Wp), dims 0, 1 rounded up.
 * Shapes: x (B,h,w), out (B,Hp,Wp); B is the product of the leading axes (1 for 2-D). */
__kernel void pad(__global REAL *out, __global const REAL *x,
                  int h, int w, int Hp, int Wp, int oy, int ox)
{
    int X = get_global_id(0), Y = get_global_id(1), b = get_global_id(2);
    if (X >= Wp || Y >= Hp) return;
    int y = Y - oy, xx = X - ox;
    /* an unconditional load of the nearest window element, then a select: vector loads on CPUs, no divergence */
    REAL v = x[at3(b, clamp(y, 0, h - 1), clamp(xx, 0, w - 1), h, w)];
    out[at3(b, Y, X, Hp, Wp)] = (y >= 0 && y < h && xx >= 0 && xx < w) ? v : (REAL)0;
}

/* crop: out[b,y,x] = x[b, oy+y, ox+x], the (h, w) window at (oy, ox).
 * Grid (x, y, b) over the output (B, h, w), dims 0, 1 rounded up.
 * Shapes: x (B,Hp,Wp), out (B,h,w). */
__kernel void crop(__global REAL *out, __global const REAL *x,
                   int h, int w, int Hp, int Wp, int oy, int ox)
{
    int xx = get_global_id(0), y = get_global_id(1), b = get_global_id(2);
    if (xx >= w || y >= h) return;
    out[at3(b, y, xx, h, w)] = x[at3(b, oy + y, ox + xx, Hp, Wp)];
}
