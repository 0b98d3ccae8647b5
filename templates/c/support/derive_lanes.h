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
 *     sin, cos, exp, log, pow (glibc >= 2.22) and tan, asin, acos, atan, tanh, atan2 (>= 2.35).
 *     libmvec is not correctly rounded (within 4 ulp by glibc's manual), so such a lane differs
 *     from the scalar call in the last bits;
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

#ifdef DERIVE_LANES_ABI
DERIVE_LANES_MVEC1(derive_lanes_sin, sin)
DERIVE_LANES_MVEC1(derive_lanes_cos, cos)
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
