/* Helpers of the complex-FFT path (reikna): a real field (K,Hp,Wp) is transformed as
 * P = ceil(K/m) complex fields, m = 1 (one band each) or m = 2 (two bands packed as
 * z = x_a + i·x_b). The half spectrum of band k is (Hp, Wh), Wh = Wp/2 + 1.
 * Complex values are computed on as (re, im) scalars and stored with store_complex (common.cl). */

/* fft_embed: z[p,Y,X] = x[m·p,Y,X] + i·x[m·p+1,Y,X] (second term only when m == 2 and m·p+1 < K).
 * Grid (X, Y, p) over z (P, Hp, Wp), dims 0, 1 rounded up. Shapes: x (K,Hp,Wp) real, z (P,Hp,Wp) complex. */
__kernel void fft_embed(__global REAL2 *z, __global const REAL *x, int K, int m, int Hp, int Wp)
{
    int X = get_global_id(0), Y = get_global_id(1), p = get_global_id(2);
    if (X >= Wp || Y >= Hp) return;
    int a = m * p, b = a + 1;
    REAL re = x[at3(a, Y, X, Hp, Wp)];
    REAL im = (m == 2 && b < K) ? x[at3(b, Y, X, Hp, Wp)] : (REAL)0;
    store_complex(z, at3(p, Y, X, Hp, Wp), re, im);
}

/* fft_half: the half spectrum of band k from its transform Z = FFT(z_p), p = k/m:
 *   m == 1: X_k = Z;  m == 2: X_a = (Z[κ] + conj Z[−κ])/2, X_b = (Z[κ] − conj Z[−κ])/(2i),
 * with −κ = (−k1 mod Hp, −k2 mod Wp). Grid (k2, k1, k) over X (K, Hp, Wh), dims 0, 1 rounded up. */
__kernel void fft_half(__global REAL2 *Xh, __global const REAL2 *z, int K, int m, int Hp, int Wp, int Wh)
{
    int k2 = get_global_id(0), k1 = get_global_id(1), k = get_global_id(2);
    if (k2 >= Wh || k1 >= Hp) return;
    int p = k / m;
    REAL2 Z = z[at3(p, k1, k2, Hp, Wp)];
    REAL re = Z.x, im = Z.y;
    if (m == 2) {
        REAL2 M = z[at3(p, (Hp - k1) % Hp, (Wp - k2) % Wp, Hp, Wp)];      /* conj M = (M.x, −M.y) */
        const REAL halve = 0.5;
        re = (k % 2 == 0) ? (Z.x + M.x) * halve : (Z.y + M.y) * halve;      /* Z + conj M */
        im = (k % 2 == 0) ? (Z.y - M.y) * halve : (M.x - Z.x) * halve;      /* (Z − conj M)/i */
    }
    store_complex(Xh, at3(k, k1, k2, Hp, Wh), re, im);
}

/* The full-spectrum value X[k1,k2] = (*re, *im) of one band from its half spectrum: conj X[−k1, Wp−k2]
 * for k2 ≥ Wh; on the self-conjugate columns (k2 = 0 and k2 = Wp/2) the Hermitian part
 * (X[k1] + conj X[−k1])/2, so that Re ifft2 of the result equals irfft2 for any input. */
inline void hermitian_at(__global const REAL2 *Xh, int band, int k1, int k2, int Hp, int Wp, int Wh, REAL *re, REAL *im)
{
    int n1 = (Hp - k1) % Hp;
    if (k2 >= Wh) {
        REAL2 c = Xh[at3(band, n1, Wp - k2, Hp, Wh)];
        *re = c.x;
        *im = -c.y;
        return;
    }
    REAL2 v = Xh[at3(band, k1, k2, Hp, Wh)];
    *re = v.x;
    *im = v.y;
    if (k2 == 0 || 2 * k2 == Wp) {
        REAL2 c = Xh[at3(band, n1, k2, Hp, Wh)];
        const REAL halve = 0.5;
        *re = (v.x + c.x) * halve;
        *im = (v.y - c.y) * halve;
    }
}

/* fft_full: z[p,k1,k2] = X_a[k1,k2] + i·X_b[k1,k2] (full Hermitian spectra of bands a = m·p,
 * b = a + 1 when m == 2 and b < K), so that IFFT(z) = x_a + i·x_b.
 * Grid (k2, k1, p) over z (P, Hp, Wp), dims 0, 1 rounded up. Shapes: X (K,Hp,Wh), z (P,Hp,Wp). */
__kernel void fft_full(__global REAL2 *z, __global const REAL2 *Xh, int K, int m, int Hp, int Wp, int Wh)
{
    int k2 = get_global_id(0), k1 = get_global_id(1), p = get_global_id(2);
    if (k2 >= Wp || k1 >= Hp) return;
    int a = m * p, b = a + 1;
    REAL ar, ai, br = 0, bi = 0;
    hermitian_at(Xh, a, k1, k2, Hp, Wp, Wh, &ar, &ai);
    if (m == 2 && b < K) hermitian_at(Xh, b, k1, k2, Hp, Wp, Wh, &br, &bi);
    store_complex(z, at3(p, k1, k2, Hp, Wp), ar - bi, ai + br);
}

/* fft_hermitian: Y[k,k1,k2] = X[k,k1,k2], on the self-conjugate columns (k2 = 0 and k2 = Wp/2) the Hermitian part
 * (X[k1] + conj X[−k1])/2: the half spectrum whose C2R transform is irfft2(X) for any X (VkFFT's C2R reads
 * the columns as they are, and may overwrite its input: Y is its input). Grid (k2, k1, k) over Y (K, Hp, Wh),
 * dims 0, 1 rounded up. Shapes: X, Y (K, Hp, Wh); Y must not alias X. */
__kernel void fft_hermitian(__global REAL2 *Y, __global const REAL2 *Xh, int Hp, int Wp, int Wh)
{
    int k2 = get_global_id(0), k1 = get_global_id(1), k = get_global_id(2);
    if (k2 >= Wh || k1 >= Hp) return;
    REAL re, im;
    hermitian_at(Xh, k, k1, k2, Hp, Wp, Wh, &re, &im);
    store_complex(Y, at3(k, k1, k2, Hp, Wh), re, im);
}

/* fft_real: x[m·p] = Re z[p], x[m·p+1] = Im z[p] (when m == 2 and m·p+1 < K).
 * Grid (X, Y, p) over z (P, Hp, Wp), dims 0, 1 rounded up. Shapes: z (P,Hp,Wp), x (K,Hp,Wp). */
__kernel void fft_real(__global REAL *x, __global const REAL2 *z, int K, int m, int Hp, int Wp)
{
    int X = get_global_id(0), Y = get_global_id(1), p = get_global_id(2);
    if (X >= Wp || Y >= Hp) return;
    int a = m * p, b = a + 1;
    REAL2 v = z[at3(p, Y, X, Hp, Wp)];
    x[at3(a, Y, X, Hp, Wp)] = v.x;
    if (m == 2 && b < K) x[at3(b, Y, X, Hp, Wp)] = v.y;
}

/* cmul: out[k,i] = X[k,i] · Ĥ[i]  (conj != 0: X[k,i] · conj Ĥ[i]), Ĥ broadcast over bands.
 * Grid (i, k): i over one spectrum plane (Hp·Wh, rounded up), k over the K bands.
 * Shapes: X, out (K, Hp, Wh) complex (out may alias X); Ĥ (Hp, Wh) complex. */
__kernel void cmul(__global REAL2 *out, __global const REAL2 *X, __global const REAL2 *Hh,
                   int plane, int conj)
{
    int i = get_global_id(0);
    size_t k = get_global_id(1);
    if (i >= plane) return;
    REAL2 a = X[k * plane + i], h = Hh[i];
    REAL hy = conj ? -h.y : h.y;
    store_complex(out, k * plane + i, a.x * h.x - a.y * hy, a.x * hy + a.y * h.x);
}
