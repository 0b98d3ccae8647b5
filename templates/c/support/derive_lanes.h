/*
 * Lane mode: the same generated functions evaluated for DERIVE_LANES states at once.
 *
 * Define DERIVE_LANES (2, 4, 8 or 16) and include this header before any generated header (or
 * compile with -DDERIVE_LANES=4 -include derive_lanes.h). DERIVE_REAL then is a GCC/Clang vector
 * of DERIVE_LANES doubles (floats with -DDERIVE_FLOAT): every array a function reads or writes
 * holds one such vector per element, lane k of each being state k ("a vector of lanes per
 * element"). The .c files are unchanged: literals broadcast to every lane, + - * / work lane by
 * lane, and the maths macros become vector functions:
 *   - glibc's libmvec where present (x86-64: AVX2 for 32-byte vectors, AVX-512F for 64-byte):
 *     exp, log, pow (glibc >= 2.22) and tan, asin, acos, atan, tanh, atan2 (>= 2.35), and sin
 *     and cos of float lanes; sin and cos of double lanes there by the inline kernel below.
 *     Neither is correctly rounded (libmvec within 4 ulp by glibc's manual, the kernel within
 *     2), so such a lane differs from the scalar call in the last bits;
 *   - else, or with -DDERIVE_LANES_EXACT, a loop calling <math.h> per lane: bit for bit the
 *     scalar function's results;
 *   - sqrt by the vector instruction (x86 SSE2, AVX), else per lane, and fabs, fmin, fmax and
 *     sign by lane masks: exact either way.
 * Functions that branch on a real (ik_<frame>, manipulability_<frame>) do not compile in lane
 * mode; manifest.json says of every function whether it is lane-wise ("lanes"). Host C only
 * (GCC >= 9 or Clang: vector extensions, __builtin_convertvector); the firmware build never
 * includes this file.
 */
#ifndef DERIVE_LANES_H
#define DERIVE_LANES_H

#ifndef DERIVE_LANES
#error derive_lanes.h: define DERIVE_LANES (the states per call: 2, 4, 8 or 16) before including it
#endif
#if !defined(__GNUC__)
#error derive_lanes.h: lane mode needs GCC or Clang vector extensions
#endif
#ifdef DERIVE_REAL_H
#error derive_lanes.h: include it before derive_real.h and every generated header
#endif

/* derive_real.h first, as the scalar build sees it; its include guard then keeps the generated
   headers from redefining what follows */
#include "derive_real.h"

#ifdef DERIVE_FLOAT
typedef float derive_lane_scalar;
#define DERIVE_LANES_SUFFIX f
#define DERIVE_LANES_BYTES (DERIVE_LANES * 4)
#else
typedef double derive_lane_scalar;
#define DERIVE_LANES_SUFFIX
#define DERIVE_LANES_BYTES (DERIVE_LANES * 8)
#endif
typedef derive_lane_scalar derive_lanes_t __attribute__((vector_size(DERIVE_LANES * sizeof(derive_lane_scalar))));
/* what a lane comparison yields: all ones (true) or zeros per lane */
typedef __typeof__((derive_lanes_t){0} < (derive_lanes_t){0}) derive_lanes_mask;

#undef DERIVE_REAL
#define DERIVE_REAL derive_lanes_t

/* a vector wider than the target's registers (4 doubles without -mavx) is returned in memory: GCC
   warns that the ABI differs from an AVX build's; these helpers are static, so no ABI is crossed */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wpsabi"
#endif

/* x - 0 is x exactly (-0.0 included), broadcast to every lane; folded at compile time */
#undef DERIVE_LIT
#ifdef DERIVE_FLOAT
#define DERIVE_LIT(x) ((x##f) - (derive_lanes_t){0})
#else
#define DERIVE_LIT(x) ((x) - (derive_lanes_t){0})
#endif

/* ---- which vector maths library: DERIVE_LANES_ABI names libmvec's variant, if any ---- */
#if !defined(DERIVE_LANES_EXACT) && defined(__x86_64__) && defined(__GLIBC__) && defined(__GLIBC_PREREQ)
#if __GLIBC_PREREQ(2, 22)
#if DERIVE_LANES_BYTES == 32 && defined(__AVX2__) && !defined(DERIVE_FLOAT)
#define DERIVE_LANES_ABI _ZGVdN4
#elif DERIVE_LANES_BYTES == 32 && defined(__AVX2__)
#define DERIVE_LANES_ABI _ZGVdN8
#elif DERIVE_LANES_BYTES == 64 && defined(__AVX512F__) && !defined(DERIVE_FLOAT)
#define DERIVE_LANES_ABI _ZGVeN8
#elif DERIVE_LANES_BYTES == 64 && defined(__AVX512F__)
#define DERIVE_LANES_ABI _ZGVeN16
#endif
#endif
#if defined(DERIVE_LANES_ABI) && __GLIBC_PREREQ(2, 35)
#define DERIVE_LANES_MVEC_235 1
#endif
#endif

#define DERIVE_LANES_CAT_(a, b, c, d) a##b##c##d
#define DERIVE_LANES_CAT(a, b, c, d) DERIVE_LANES_CAT_(a, b, c, d)
/* libmvec's name of f (sin: _ZGVdN4v_sin), and of the scalar <math.h> function (sin, sinf) */
#define DERIVE_LANES_V(f) DERIVE_LANES_CAT(DERIVE_LANES_ABI, v_, f, DERIVE_LANES_SUFFIX)
#define DERIVE_LANES_VV(f) DERIVE_LANES_CAT(DERIVE_LANES_ABI, vv_, f, DERIVE_LANES_SUFFIX)
#define DERIVE_LANES_S(f) DERIVE_LANES_CAT(f, DERIVE_LANES_SUFFIX, , )

/* a lane-wise function name(x) calling the scalar f per lane (exact, slower) */
#define DERIVE_LANES_LOOP1(name, f)                                                        \
    static inline derive_lanes_t name(derive_lanes_t x)                                    \
    {                                                                                      \
        derive_lanes_t r;                                                                  \
        int k;                                                                             \
        for (k = 0; k < DERIVE_LANES; ++k) r[k] = DERIVE_LANES_S(f)(x[k]);                 \
        return r;                                                                          \
    }
#define DERIVE_LANES_LOOP2(name, f)                                                        \
    static inline derive_lanes_t name(derive_lanes_t x, derive_lanes_t y)                  \
    {                                                                                      \
        derive_lanes_t r;                                                                  \
        int k;                                                                             \
        for (k = 0; k < DERIVE_LANES; ++k) r[k] = DERIVE_LANES_S(f)(x[k], y[k]);           \
        return r;                                                                          \
    }
/* name(x) = libmvec's f: declared here (the vector ABI passes and returns in one register) */
#define DERIVE_LANES_MVEC1(name, f)                                                        \
    derive_lanes_t DERIVE_LANES_V(f)(derive_lanes_t);                                      \
    static inline derive_lanes_t name(derive_lanes_t x) { return DERIVE_LANES_V(f)(x); }
#define DERIVE_LANES_MVEC2(name, f)                                                        \
    derive_lanes_t DERIVE_LANES_VV(f)(derive_lanes_t, derive_lanes_t);                     \
    static inline derive_lanes_t name(derive_lanes_t x, derive_lanes_t y) { return DERIVE_LANES_VV(f)(x, y); }

/* with libmvec's double lanes, sin and cos are derive's own inline kernel (below): libmvec's are
   calls, which spill every live vector, and cannot share one argument's work between its sin and
   cos as the scalar build's sincos does */
#if defined(DERIVE_LANES_ABI) && !defined(DERIVE_FLOAT)
#define DERIVE_LANES_TRIG_KERNEL 1
#endif

#ifdef DERIVE_LANES_ABI
#ifndef DERIVE_LANES_TRIG_KERNEL
DERIVE_LANES_MVEC1(derive_lanes_sin, sin)
DERIVE_LANES_MVEC1(derive_lanes_cos, cos)
#endif
DERIVE_LANES_MVEC1(derive_lanes_exp, exp)
DERIVE_LANES_MVEC1(derive_lanes_log, log)
DERIVE_LANES_MVEC2(derive_lanes_pow, pow)
#else
DERIVE_LANES_LOOP1(derive_lanes_sin, sin)
DERIVE_LANES_LOOP1(derive_lanes_cos, cos)
DERIVE_LANES_LOOP1(derive_lanes_exp, exp)
DERIVE_LANES_LOOP1(derive_lanes_log, log)
DERIVE_LANES_LOOP2(derive_lanes_pow, pow)
#endif
#ifdef DERIVE_LANES_MVEC_235
DERIVE_LANES_MVEC1(derive_lanes_tan, tan)
DERIVE_LANES_MVEC1(derive_lanes_asin, asin)
DERIVE_LANES_MVEC1(derive_lanes_acos, acos)
DERIVE_LANES_MVEC1(derive_lanes_atan, atan)
DERIVE_LANES_MVEC1(derive_lanes_tanh, tanh)
DERIVE_LANES_MVEC2(derive_lanes_atan2, atan2)
#else
DERIVE_LANES_LOOP1(derive_lanes_tan, tan)
DERIVE_LANES_LOOP1(derive_lanes_asin, asin)
DERIVE_LANES_LOOP1(derive_lanes_acos, acos)
DERIVE_LANES_LOOP1(derive_lanes_atan, atan)
DERIVE_LANES_LOOP1(derive_lanes_tanh, tanh)
DERIVE_LANES_LOOP2(derive_lanes_atan2, atan2)
#endif

/* sqrt is correctly rounded by IEEE 754, so the vector instruction equals the scalar call (the
   compiler's builtins: <immintrin.h> would cost each translation unit a third of a second) */
#if (defined(__x86_64__) || defined(__i386__)) && \
    ((DERIVE_LANES_BYTES == 16 && defined(__SSE2__)) || (DERIVE_LANES_BYTES == 32 && defined(__AVX__)))
typedef double derive_lanes_v2d __attribute__((vector_size(16)));
typedef float derive_lanes_v4f __attribute__((vector_size(16)));
typedef double derive_lanes_v4d __attribute__((vector_size(32)));
typedef float derive_lanes_v8f __attribute__((vector_size(32)));
static inline derive_lanes_t derive_lanes_sqrt(derive_lanes_t x)
{
#if DERIVE_LANES_BYTES == 16 && defined(DERIVE_FLOAT)
    return (derive_lanes_t)__builtin_ia32_sqrtps((derive_lanes_v4f)x);
#elif DERIVE_LANES_BYTES == 16
    return (derive_lanes_t)__builtin_ia32_sqrtpd((derive_lanes_v2d)x);
#elif defined(DERIVE_FLOAT)
    return (derive_lanes_t)__builtin_ia32_sqrtps256((derive_lanes_v8f)x);
#else
    return (derive_lanes_t)__builtin_ia32_sqrtpd256((derive_lanes_v4d)x);
#endif
}
#else
DERIVE_LANES_LOOP1(derive_lanes_sqrt, sqrt)
#endif

/* |x|: the sign bit cleared (the bits of -0.0 are the sign bit alone) */
static inline derive_lanes_t derive_lanes_fabs(derive_lanes_t x)
{
    return (derive_lanes_t)((derive_lanes_mask)x & ~(derive_lanes_mask)DERIVE_LIT(-0.0));
}

/* the lanes of a where m is all ones, of b elsewhere */
static inline derive_lanes_t derive_lanes_select(derive_lanes_mask m, derive_lanes_t a, derive_lanes_t b)
{
    return (derive_lanes_t)(((derive_lanes_mask)a & m) | ((derive_lanes_mask)b & ~m));
}

/* fmin/fmax: a NaN argument yields the other one, as C99's */
static inline derive_lanes_t derive_lanes_fmin(derive_lanes_t a, derive_lanes_t b)
{
    return derive_lanes_select((a < b) | (b != b), a, b);
}

static inline derive_lanes_t derive_lanes_fmax(derive_lanes_t a, derive_lanes_t b)
{
    return derive_lanes_select((a > b) | (b != b), a, b);
}

#ifdef DERIVE_LANES_TRIG_KERNEL
/*
 * sin and cos of double lanes, inline, so that the compiler merges the work of sin(a) and cos(a)
 * (the same reduction and polynomials) and keeps every other vector in registers:
 *   k = x * 2/pi rounded to an integer (adding and subtracting 1.5 * 2^52; k mod 4 is then in the
 *   low bits of the sum), r = x - k * pi/2 with pi/2 split in three (P1 and P2 of 32 significant
 *   bits, so k * P1 and k * P2 are exact for |k| < 2^20), |r| <= pi/4;
 *   sin r = r + r z S(z) and cos r = 1 - z/2 + z^2 C(z), z = r^2, S and C of degree 5 (fitted
 *   for relative error on [0, (pi/4)^2]: under 1 ulp before rounding);
 *   by k mod 4 (k + 1 for cos): sin r, cos r, -sin r, -cos r; sin r takes the sign of r (sin(-0) = -0).
 * Lanes with |x| > 1e5 or infinite take <math.h>'s sin and cos (a cold call); NaN stays NaN.
 * Within 2 ulp of <math.h> (derive bench lanes measures it), as libmvec (4 ulp) is.
 */
static __attribute__((noinline, cold)) derive_lanes_t derive_lanes_trig_wide(derive_lanes_t x, derive_lanes_t v,
                                                                             derive_lanes_mask wide, int shift)
{
    int k;
    for (k = 0; k < DERIVE_LANES; ++k)
        if (wide[k])
            v[k] = shift ? cos(x[k]) : sin(x[k]);
    return v;
}

static inline __attribute__((always_inline)) derive_lanes_t derive_lanes_trig(derive_lanes_t x, int shift)
{
    const derive_lanes_t round = DERIVE_LIT(6755399441055744.0); /* 1.5 * 2^52 */
    derive_lanes_t sum = x * DERIVE_LIT(0.6366197723675814) + round;
    derive_lanes_mask quadrant = (derive_lanes_mask)sum + shift;
    derive_lanes_t k = sum - round;
    derive_lanes_t r = ((x - k * DERIVE_LIT(1.5707963267341256)) - k * DERIVE_LIT(6.077100506303966e-11))
                       - k * DERIVE_LIT(2.0222662487959506e-21);
    derive_lanes_t z = r * r;
    derive_lanes_t s = DERIVE_LIT(1.5895943103357368e-10);
    derive_lanes_t c = DERIVE_LIT(-1.1358093609276402e-11);
    s = DERIVE_LIT(-2.505074222357712e-08) + z * s;
    s = DERIVE_LIT(2.755731358095979e-06) + z * s;
    s = DERIVE_LIT(-0.00019841269829452244) + z * s;
    s = DERIVE_LIT(0.008333333333321907) + z * s;
    s = DERIVE_LIT(-0.1666666666666663) + z * s;
    s = r + r * z * s;
    c = DERIVE_LIT(2.0875691483269687e-09) + z * c;
    c = DERIVE_LIT(-2.755731410296429e-07) + z * c;
    c = DERIVE_LIT(2.480158728855358e-05) + z * c;
    c = DERIVE_LIT(-0.0013888888888872505) + z * c;
    c = DERIVE_LIT(0.04166666666666659) + z * c;
    c = DERIVE_LIT(1.0) - DERIVE_LIT(0.5) * z + z * z * c;
    derive_lanes_mask sign = (derive_lanes_mask)DERIVE_LIT(-0.0);
    derive_lanes_t v;
    s = (derive_lanes_t)(((derive_lanes_mask)s & ~sign) | ((derive_lanes_mask)r & sign)); /* sin(-0) = -0 */
    v = derive_lanes_select((quadrant & 1) != 0, c, s);
    derive_lanes_mask wide = derive_lanes_fabs(x) > DERIVE_LIT(1.0e5); /* infinities too, not NaN */
    __typeof__(wide[0]) any = wide[0];
    int j;
    v = (derive_lanes_t)((derive_lanes_mask)v ^ (((quadrant & 2) != 0) & sign));
    for (j = 1; j < DERIVE_LANES; ++j)
        any |= wide[j];
    if (__builtin_expect(any != 0, 0))
        v = derive_lanes_trig_wide(x, v, wide, shift);
    return v;
}

static inline __attribute__((always_inline)) derive_lanes_t derive_lanes_sin(derive_lanes_t x) { return derive_lanes_trig(x, 0); }
static inline __attribute__((always_inline)) derive_lanes_t derive_lanes_cos(derive_lanes_t x) { return derive_lanes_trig(x, 1); }
#endif

/* sign(x): -1, 0 or 1 as the scalar DERIVE_SIGN ((x > 0) - (x < 0)); a true lane compares as -1 */
static inline derive_lanes_t derive_lanes_sign(derive_lanes_t x)
{
    return __builtin_convertvector(x < 0, derive_lanes_t) - __builtin_convertvector(x > 0, derive_lanes_t);
}

#undef DERIVE_SIN
#undef DERIVE_COS
#undef DERIVE_TAN
#undef DERIVE_SQRT
#undef DERIVE_EXP
#undef DERIVE_LOG
#undef DERIVE_FABS
#undef DERIVE_ASIN
#undef DERIVE_ACOS
#undef DERIVE_ATAN
#undef DERIVE_TANH
#undef DERIVE_POW
#undef DERIVE_ATAN2
#undef DERIVE_FMIN
#undef DERIVE_FMAX
#undef DERIVE_SIGN
#define DERIVE_SIN derive_lanes_sin
#define DERIVE_COS derive_lanes_cos
#define DERIVE_TAN derive_lanes_tan
#define DERIVE_SQRT derive_lanes_sqrt
#define DERIVE_EXP derive_lanes_exp
#define DERIVE_LOG derive_lanes_log
#define DERIVE_FABS derive_lanes_fabs
#define DERIVE_ASIN derive_lanes_asin
#define DERIVE_ACOS derive_lanes_acos
#define DERIVE_ATAN derive_lanes_atan
#define DERIVE_TANH derive_lanes_tanh
#define DERIVE_POW derive_lanes_pow
#define DERIVE_ATAN2 derive_lanes_atan2
#define DERIVE_FMIN derive_lanes_fmin
#define DERIVE_FMAX derive_lanes_fmax
#define DERIVE_SIGN derive_lanes_sign

/* what this build uses, for programs that report it: 1 when libmvec computes the elementary functions */
#ifdef DERIVE_LANES_ABI
#define DERIVE_LANES_LIBMVEC 1
#else
#define DERIVE_LANES_LIBMVEC 0
#endif

#endif /* DERIVE_LANES_H */
