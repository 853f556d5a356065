/* Small signed big integers of fixed capacity, for the twin's rare exact fallbacks.
 *
 * Magnitude in 64-bit limbs, least significant first, plus a sign. Every operation checks
 * its capacity and sets BIG_OVERFLOW in the context instead of overflowing; the callers'
 * proven bounds (exact.c) stay far below it.
 */
#ifndef BWSD_BIGINT_H
#define BWSD_BIGINT_H

#include <stdint.h>

#define BIG_LIMBS 16 /* 1024 bits */

typedef struct {
    int neg; /* 1 when negative (never for zero) */
    int n;   /* limbs in use; 0 for zero */
    uint64_t d[BIG_LIMBS];
} big;

typedef __int128 i128;
typedef unsigned __int128 u128;

void big_zero(big *r);
void big_from_i64(big *r, int64_t v);
void big_from_i128(big *r, i128 v);
void big_from_parts(big *r, i128 hi, uint64_t lo); /* hi * 2^64 + lo */
int big_from_bytes(big *r, const unsigned char *le, int len, int neg);
int big_sign(const big *a);
int big_cmp(const big *a, const big *b);
int big_add(big *r, const big *a, const big *b);
int big_sub(big *r, const big *a, const big *b);
int big_mul(big *r, const big *a, const big *b);
void big_neg(big *r);
int big_divmod_floor(big *q, big *rem, const big *a, const big *m); /* m > 0 */
int big_to_i64(const big *a, int64_t *out);
int big_to_u128(const big *a, u128 *out);
int big_is_odd(const big *a);
double big_to_double(const big *a);

#endif
