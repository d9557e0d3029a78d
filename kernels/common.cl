/* Types shared by every kernel family (prepended to each build).
 * REAL is float or double (-DREAL=...), REAL2 its complex pair (re, im).
 * ACC accumulates reductions: double when the device has fp64 (-DHAVE_FP64),
 * else float with Kahan compensation (-DKAHAN). FP contraction is off so that
 * a*x + y rounds exactly as NumPy does (two roundings, no fused multiply-add). */
#ifdef HAVE_FP64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#endif
#pragma OPENCL FP_CONTRACT OFF

#ifndef REAL
#define REAL float
#endif
#ifndef REAL2
#define REAL2 float2
#endif
#ifndef ACC
#define ACC REAL
#endif

/* Flat index of (row, col) in a row-major plane stack: ((b*H + y)*W + x). */
inline size_t at3(size_t b, size_t y, size_t x, size_t H, size_t W) { return (b * H + y) * W + x; }
/* z[i] = re + i·im, stored as two REALs: a REAL2 built from scalars and stored whole is reported as an
 * uninitialised write by Oclgrind (jrprice/Oclgrind#126, and building one from another's lanes crashes it);
 * vstore2 is the same 2·REAL store on every device. Complex values are read whole (REAL2) and computed
 * on as (re, im) scalars. */
inline void store_complex(__global REAL2 *z, size_t i, REAL re, REAL im) { vstore2((REAL2)(re, im), i, (__global REAL *)z); }
/* Clip v to [−c, c] (NaN propagates, as np.clip). */
inline REAL clip_to(REAL v, REAL c) { return v < -c ? -c : (v > c ? c : v); }
