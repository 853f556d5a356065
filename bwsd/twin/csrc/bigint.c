/* Small signed big integers: see bigint.h. Returns 0 on success, -1 on capacity overflow. */
#include "bigint.h"

#include <string.h>

static void trim(big *r) {
    while (r->n > 0 && r->d[r->n - 1] == 0) r->n--;
    if (r->n == 0) r->neg = 0;
}

void big_zero(big *r) {
    r->neg = 0;
    r->n = 0;
}

static void from_u128(big *r, u128 m, int neg) {
    r->d[0] = (uint64_t)m;
    r->d[1] = (uint64_t)(m >> 64);
    r->n = 2;
    r->neg = neg;
    trim(r);
}

void big_from_i64(big *r, int64_t v) {
    u128 m = v < 0 ? (u128)(-(i128)v) : (u128)v;
    from_u128(r, m, v < 0);
}

void big_from_i128(big *r, i128 v) {
    /* |v| < 2^127 everywhere this is used, so the negation cannot overflow */
    u128 m = v < 0 ? (u128)(-v) : (u128)v;
    from_u128(r, m, v < 0);
}

void big_from_parts(big *r, i128 hi, uint64_t lo) {
    big h, l;
    big_from_i128(&h, hi);
    /* h * 2^64: shift the limbs up by one */
    if (h.n) {
        for (int i = h.n; i > 0; i--) h.d[i] = h.d[i - 1];
        h.d[0] = 0;
        h.n++;
    }
    l.neg = 0;
    l.d[0] = lo;
    l.n = lo ? 1 : 0;
    big_add(r, &h, &l);
}

int big_from_bytes(big *r, const unsigned char *le, int len, int neg) {
    big_zero(r);
    if (len > 8 * BIG_LIMBS) return -1;
    memset(r->d, 0, sizeof r->d);
    for (int i = 0; i < len; i++) r->d[i / 8] |= (uint64_t)le[i] << (8 * (i % 8));
    r->n = (len + 7) / 8;
    r->neg = neg;
    trim(r);
    return 0;
}

int big_sign(const big *a) { return a->n == 0 ? 0 : (a->neg ? -1 : 1); }

static int mag_cmp(const big *a, const big *b) {
    if (a->n != b->n) return a->n < b->n ? -1 : 1;
    for (int i = a->n - 1; i >= 0; i--)
        if (a->d[i] != b->d[i]) return a->d[i] < b->d[i] ? -1 : 1;
    return 0;
}

int big_cmp(const big *a, const big *b) {
    int sa = big_sign(a), sb = big_sign(b);
    if (sa != sb) return sa < sb ? -1 : 1;
    int m = mag_cmp(a, b);
    return sa < 0 ? -m : m;
}

/* |r| = |a| + |b| */
static int mag_add(big *r, const big *a, const big *b) {
    int n = a->n > b->n ? a->n : b->n;
    uint64_t carry = 0;
    big out;
    for (int i = 0; i < n; i++) {
        u128 s = (u128)(i < a->n ? a->d[i] : 0) + (i < b->n ? b->d[i] : 0) + carry;
        out.d[i] = (uint64_t)s;
        carry = (uint64_t)(s >> 64);
    }
    if (carry) {
        if (n == BIG_LIMBS) return -1;
        out.d[n++] = carry;
    }
    out.n = n;
    memcpy(r->d, out.d, sizeof(uint64_t) * (size_t)n);
    r->n = n;
    return 0;
}

/* |r| = |a| - |b|, |a| >= |b| */
static void mag_sub(big *r, const big *a, const big *b) {
    uint64_t borrow = 0;
    int n = a->n;
    for (int i = 0; i < n; i++) {
        uint64_t bi = i < b->n ? b->d[i] : 0;
        u128 s = (u128)a->d[i] - bi - borrow;
        r->d[i] = (uint64_t)s;
        borrow = (uint64_t)(s >> 64) ? 1 : 0;
    }
    r->n = n;
}

static int signed_add(big *r, const big *a, const big *b, int b_neg) {
    int a_neg = a->neg;
    if (a_neg == b_neg) {
        if (mag_add(r, a, b)) return -1;
        r->neg = a_neg;
    } else if (mag_cmp(a, b) >= 0) {
        mag_sub(r, a, b);
        r->neg = a_neg;
    } else {
        big tmp = *b;
        mag_sub(r, &tmp, a);
        r->neg = b_neg;
    }
    trim(r);
    return 0;
}

int big_add(big *r, const big *a, const big *b) {
    big bb = *b;
    return signed_add(r, a, &bb, b->neg);
}

int big_sub(big *r, const big *a, const big *b) {
    big bb = *b;
    return signed_add(r, a, &bb, bb.n ? !b->neg : 0);
}

int big_mul(big *r, const big *a, const big *b) {
    if (a->n == 0 || b->n == 0) {
        big_zero(r);
        return 0;
    }
    int n = a->n + b->n;
    if (n > BIG_LIMBS + 1) return -1;
    uint64_t out[2 * BIG_LIMBS + 1];
    memset(out, 0, sizeof(uint64_t) * (size_t)n);
    for (int i = 0; i < a->n; i++) {
        uint64_t carry = 0;
        for (int j = 0; j < b->n; j++) {
            u128 p = (u128)a->d[i] * b->d[j] + out[i + j] + carry;
            out[i + j] = (uint64_t)p;
            carry = (uint64_t)(p >> 64);
        }
        out[i + b->n] = carry;
    }
    while (n > 0 && out[n - 1] == 0) n--;
    if (n > BIG_LIMBS) return -1;
    memcpy(r->d, out, sizeof(uint64_t) * (size_t)n);
    r->n = n;
    r->neg = a->neg != b->neg;
    trim(r);
    return 0;
}

void big_neg(big *r) {
    if (r->n) r->neg = !r->neg;
}

static int bit_length(const big *a) {
    if (a->n == 0) return 0;
    uint64_t top = a->d[a->n - 1];
    int bits = 0;
    while (top) {
        bits++;
        top >>= 1;
    }
    return 64 * (a->n - 1) + bits;
}

/* Floor division by a positive m: q = floor(a / m), rem = a - q m in [0, m). */
int big_divmod_floor(big *q, big *rem, const big *a, const big *m) {
    if (big_sign(m) <= 0) return -1;
    big r, quo;
    big_zero(&r);
    big_zero(&quo);
    memset(quo.d, 0, sizeof quo.d);
    int bits = bit_length(a);
    for (int i = bits - 1; i >= 0; i--) {
        /* r = 2 r + bit i of |a| */
        uint64_t carry = (a->d[i / 64] >> (i % 64)) & 1;
        for (int k = 0; k < r.n; k++) {
            uint64_t next = r.d[k] >> 63;
            r.d[k] = (r.d[k] << 1) | carry;
            carry = next;
        }
        if (carry) {
            if (r.n == BIG_LIMBS) return -1;
            r.d[r.n++] = carry;
        }
        if (mag_cmp(&r, m) >= 0) {
            mag_sub(&r, &r, m);
            trim(&r);
            quo.d[i / 64] |= (uint64_t)1 << (i % 64);
        }
    }
    quo.n = (bits + 63) / 64;
    quo.neg = 0;
    trim(&quo);
    r.neg = 0;
    trim(&r);
    if (a->neg && r.n) {
        /* floor: -(|a| div m) - 1, remainder m - r */
        big one;
        big_from_i64(&one, 1);
        if (mag_add(&quo, &quo, &one)) return -1;
        quo.neg = 1;
        big mm = *m;
        mag_sub(&r, &mm, &r);
        trim(&r);
    } else if (a->neg) {
        quo.neg = quo.n ? 1 : 0;
    }
    *q = quo;
    *rem = r;
    return 0;
}

int big_to_i64(const big *a, int64_t *out) {
    if (a->n > 1 || (a->n == 1 && a->d[0] > (uint64_t)INT64_MAX)) return -1;
    int64_t v = a->n ? (int64_t)a->d[0] : 0;
    *out = a->neg ? -v : v;
    return 0;
}

int big_to_u128(const big *a, u128 *out) {
    if (a->neg || a->n > 2) return -1;
    *out = (a->n > 0 ? (u128)a->d[0] : 0) | (a->n > 1 ? (u128)a->d[1] << 64 : 0);
    return 0;
}

int big_is_odd(const big *a) { return a->n > 0 && (a->d[0] & 1); }

double big_to_double(const big *a) {
    double v = 0.0;
    for (int i = a->n - 1; i >= 0; i--) v = v * 18446744073709551616.0 + (double)a->d[i];
    return a->neg ? -v : v;
}
