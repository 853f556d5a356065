/* Exact predicates and correctly rounded constructions: see exact.h. */
#include "exact.h"

#include <float.h>
#include <math.h>

#if !defined(FLT_EVAL_METHOD) || FLT_EVAL_METHOD != 0
#error "the twin kernel needs double arithmetic evaluated in double (SSE2 on x86)"
#endif

#define EPS 1.1102230246251565e-16 /* 2^-53 */

int exact_only = 0;

static inline double fabs_(double x) { return x < 0 ? -x : x; }

static inline void cross_i128(const int64_t *a, const int64_t *b, i128 *n) {
    n[0] = (i128)a[1] * b[2] - (i128)a[2] * b[1];
    n[1] = (i128)a[2] * b[0] - (i128)a[0] * b[2];
    n[2] = (i128)a[0] * b[1] - (i128)a[1] * b[0];
}

/* c . n exactly for |c_i| < 2^53, |n_i| < 2^108: returned as hi * 2^64 + lo, lo unsigned. */
static inline void dot_parts(const int64_t *c, const i128 *n, i128 *hi, uint64_t *lo) {
    i128 h = 0, l = 0;
    for (int i = 0; i < 3; i++) {
        i128 nh = n[i] >> 64; /* arithmetic: floor */
        uint64_t nl = (uint64_t)n[i];
        h += (i128)c[i] * nh;
        l += (i128)c[i] * (i128)nl;
    }
    h += l >> 64;
    *hi = h;
    *lo = (uint64_t)l;
}

static inline int parts_sign(i128 hi, uint64_t lo) { return hi > 0 ? 1 : (hi < 0 ? -1 : lo > 0); }

static inline void diff3(const int64_t *p, const int64_t *o, int64_t *out) {
    out[0] = p[0] - o[0];
    out[1] = p[1] - o[1];
    out[2] = p[2] - o[2];
}

/* det[p1 - p0, p2 - p0, p3 - p0] as u . (a x b): a, b, u the differences */
static void orient_setup(const int64_t *p0, const int64_t *p1, const int64_t *p2, const int64_t *p3,
                         Cross *x, int64_t *u) {
    int64_t a[3], b[3];
    diff3(p1, p0, a);
    diff3(p2, p0, b);
    diff3(p3, p0, u);
    cross_init(x, a, b);
}

void orient_sgn(const int64_t *p0, const int64_t *p1, const int64_t *p2, const int64_t *p3,
                Sgn *out) {
    Cross x;
    int64_t u[3];
    orient_setup(p0, p1, p2, p3, &x, u);
    cross_side(&x, u, out);
}

int orient_big(const int64_t *p0, const int64_t *p1, const int64_t *p2, const int64_t *p3,
               big *out) {
    Cross x;
    int64_t u[3];
    orient_setup(p0, p1, p2, p3, &x, u);
    return cross_big(&x, u, out);
}

void plane_init(Plane *pl, const int64_t *b, const int64_t *a1, const int64_t *a2) {
    int64_t ia[3], ic[3];
    diff3(a1, b, ia);
    diff3(a2, b, ic);
    for (int k = 0; k < 3; k++) pl->b[k] = b[k];
    cross_init(&pl->x, ia, ic);
    cross_exact(&pl->x);
    const i128 *n = pl->x.N;
    pl->flat = n[0] == 0 && n[1] == 0 && n[2] == 0;
}

int dot_sign(const int64_t *u, const i128 *n) {
    i128 hi;
    uint64_t lo;
    dot_parts(u, n, &hi, &lo);
    return parts_sign(hi, lo);
}

void cross_exact(Cross *x) {
    cross_i128(x->a, x->c, x->N);
    x->exact_ready = 1;
}

int cross_big(Cross *x, const int64_t *u, big *out) {
    i128 hi;
    uint64_t lo;
    if (!x->exact_ready) cross_exact(x);
    dot_parts(u, x->N, &hi, &lo);
    big_from_parts(out, hi, lo);
    return 0;
}

int plane_big(Plane *pl, const int64_t *x, big *out) {
    int64_t u[3];
    diff3(x, pl->b, u);
    return cross_big(&pl->x, u, out);
}

/* Round a float value known to lie within err of the exact one; 0 when it cannot decide. */
static int round_float(double v, double err, int64_t *out) {
    if (exact_only) return 0;
    double r = rint(v);
    if (!(fabs_(v - r) + err < 0.5)) return 0;      /* also refuses NaN */
    if (!(fabs_(r) < 4503599627370496.0)) return 0; /* 2^52: let the exact path report it */
    *out = (int64_t)r;
    return 1;
}

int round_ratio(const big *num, const big *den, int64_t *out) {
    big n = *num, m = *den, q, r, twice;
    if (big_sign(&m) == 0) return E_ARITH;
    if (big_sign(&m) < 0) {
        big_neg(&n);
        big_neg(&m);
    }
    if (big_divmod_floor(&q, &r, &n, &m) || big_add(&twice, &r, &r)) return E_ARITH;
    int c = big_cmp(&twice, &m);
    if (c > 0 || (c == 0 && big_is_odd(&q))) {
        big one;
        big_from_i64(&one, 1);
        if (big_add(&q, &q, &one)) return E_ARITH;
    }
    int64_t v;
    if (big_to_i64(&q, &v)) return E_LIMIT;
    if (v >= GRID_LIMIT || v <= -GRID_LIMIT) return E_LIMIT;
    *out = v;
    return E_OK;
}

static void big_abs(big *x) { x->neg = 0; }

int lerp_round(const int64_t *p, const int64_t *q, const Sgn *a, const Sgn *b, ExactPair exact,
               const void *ctx, int64_t *out) {
    if (a->s == 0) {
        for (int k = 0; k < 3; k++) out[k] = p[k];
        return E_OK;
    }
    if (b->s == 0) {
        for (int k = 0; k < 3; k++) out[k] = q[k];
        return E_OK;
    }
    double s = 0, es = 1;
    int usable = a->filtered && b->filtered;
    if (usable) {
        double av = fabs_(a->v), bv = fabs_(b->v);
        s = av / (av + bv);
        double lo = (av - a->e) / ((av - a->e) + (bv + b->e));
        double hi = (av + a->e) / ((av + a->e) + (bv - b->e));
        es = 2.0 * (fmax(hi - s, s - lo) + 4 * EPS);
    }
    int done[3] = {0, 0, 0};
    for (int k = 0; k < 3; k++) {
        int64_t dk = q[k] - p[k];
        if (dk == 0) {
            out[k] = p[k];
            done[k] = 1;
        } else if (usable) {
            double delta = (double)dk, prod = s * delta, v = (double)p[k] + prod;
            double err = 2.0 * (es * fabs_(delta) + 4 * EPS * (fabs_(prod) + fabs_(v)));
            done[k] = round_float(v, err, &out[k]);
        }
    }
    if (done[0] && done[1] && done[2]) return E_OK;
    big A, B, sum, num, t1, t2, pk, qk;
    if (exact(ctx, &A, &B)) return E_ARITH;
    big_abs(&A);
    big_abs(&B);
    if (big_add(&sum, &A, &B)) return E_ARITH;
    for (int k = 0; k < 3; k++) {
        if (done[k]) continue;
        big_from_i64(&pk, p[k]);
        big_from_i64(&qk, q[k]);
        if (big_mul(&t1, &pk, &B) || big_mul(&t2, &qk, &A) || big_add(&num, &t1, &t2))
            return E_ARITH;
        int err = round_ratio(&num, &sum, &out[k]);
        if (err) return err;
    }
    return E_OK;
}

static u128 isqrt_u128(u128 n) {
    u128 x = (u128)sqrt((double)n);
    while (x > 0 && x * x > n) x--;
    while ((x + 1) * (x + 1) <= n) x++;
    return x;
}

/* Exact X_k = round(y_k - D nv_k / sqrt(S)), D = num / den, S = |nv|^2 (see exact.h). */
static int rest_exact(int64_t yk, const big *nvk, const big *S, const Diam *d, int64_t *out) {
    int sigma = big_sign(nvk);
    if (sigma == 0) {
        *out = yk;
        return E_OK;
    }
    big A, A2, B, den2, two, q, r, jb, j2, check;
    big_from_i64(&two, 2);
    A = *nvk;
    big_abs(&A);
    if (big_mul(&A, &A, &d->num) || big_mul(&A, &A, &two) || big_mul(&A2, &A, &A)) return E_ARITH;
    if (big_mul(&den2, &d->den, &d->den) || big_mul(&B, &den2, S)) return E_ARITH;
    if (big_divmod_floor(&q, &r, &A2, &B)) return E_ARITH;
    u128 qq;
    if (big_to_u128(&q, &qq) || (qq >> 120)) return E_ARITH;
    u128 j = isqrt_u128(qq);
    big_zero(&jb);
    jb.d[0] = (uint64_t)j;
    jb.d[1] = (uint64_t)(j >> 64);
    jb.n = jb.d[1] ? 2 : (jb.d[0] ? 1 : 0);
    if (big_mul(&j2, &jb, &jb) || big_mul(&check, &j2, &B)) return E_ARITH;
    int whole = big_cmp(&check, &A2) == 0; /* |2W| is exactly the integer j */
    if (j > (u128)1 << 100) return E_ARITH;
    int64_t jj = (int64_t)j;
    /* 2Z = 2 y - 2W, 2W = sigma * (j + frac) */
    int64_t f2 = sigma > 0 ? 2 * yk - jj - (whole ? 0 : 1) : 2 * yk + jj;
    int64_t k = f2 >> 1; /* floor */
    int64_t x;
    if ((f2 & 1) == 0)
        x = k;
    else if (!whole)
        x = k + 1;
    else
        x = (k & 1) == 0 ? k : k + 1; /* a tie: to even */
    if (x >= GRID_LIMIT || x <= -GRID_LIMIT) return E_LIMIT;
    *out = x;
    return E_OK;
}

int rest_round(const int64_t *y, const int64_t *m, const int64_t *u, const Diam *d, int64_t *out) {
    for (int k = 0; k < 3; k++) out[k] = y[k];
    if (d->zero) return E_OK;
    i128 c[3];
    cross_i128(m, u, c);
    if (c[0] == 0 && c[1] == 0 && c[2] == 0) return E_OK; /* the move runs along the segment */
    /* n is parallel to nv = u x (m x u), |nv| = |u| |m x u| */
    double uf[3] = {(double)u[0], (double)u[1], (double)u[2]};
    double cf[3] = {(double)c[0], (double)c[1], (double)c[2]};
    double nu = sqrt(uf[0] * uf[0] + uf[1] * uf[1] + uf[2] * uf[2]);
    double nc = sqrt(cf[0] * cf[0] + cf[1] * cf[1] + cf[2] * cf[2]);
    double norm = nu * nc;
    int done[3];
    for (int k = 0; k < 3; k++) {
        int i = (k + 1) % 3, j = (k + 2) % 3;
        double p1 = uf[i] * cf[j], p2 = uf[j] * cf[i], nv = p1 - p2;
        double e_nv = 3 * EPS * (fabs_(p1) + fabs_(p2)) + EPS * fabs_(nv);
        double w = d->f * (nv / norm);
        double err_w = d->f * (e_nv / norm) * (1 + 32 * EPS) + 12 * EPS * d->f + 3 * EPS * fabs_(w);
        double v = (double)y[k] - w;
        double err = 2.0 * (err_w + EPS * fabs_(v));
        done[k] =
            nv == 0 && c[i] == 0 && c[j] == 0 ? (out[k] = y[k], 1) : round_float(v, err, &out[k]);
    }
    if (done[0] && done[1] && done[2]) return E_OK;
    big ub[3], cb[3], uu, cc, S, t1, t2, nvk;
    for (int k = 0; k < 3; k++) {
        big_from_i64(&ub[k], u[k]);
        big_from_i128(&cb[k], c[k]);
    }
    big_zero(&uu);
    big_zero(&cc);
    for (int k = 0; k < 3; k++) {
        if (big_mul(&t1, &ub[k], &ub[k]) || big_add(&uu, &uu, &t1)) return E_ARITH;
        if (big_mul(&t2, &cb[k], &cb[k]) || big_add(&cc, &cc, &t2)) return E_ARITH;
    }
    if (big_mul(&S, &uu, &cc)) return E_ARITH;
    for (int k = 0; k < 3; k++) {
        if (done[k]) continue;
        int i = (k + 1) % 3, j = (k + 2) % 3;
        if (big_mul(&t1, &ub[i], &cb[j]) || big_mul(&t2, &ub[j], &cb[i]) || big_sub(&nvk, &t1, &t2))
            return E_ARITH;
        int err = rest_exact(y[k], &nvk, &S, d, &out[k]);
        if (err) return err;
    }
    return E_OK;
}

int ratio_cmp_exact(const big *a1, const big *b1, const big *a2, const big *b2, int *out) {
    big A1 = *a1, B1 = *b1, A2 = *a2, B2 = *b2, s1, s2, l, r;
    big_abs(&A1);
    big_abs(&B1);
    big_abs(&A2);
    big_abs(&B2);
    if (big_add(&s1, &A1, &B1) || big_add(&s2, &A2, &B2)) return E_ARITH;
    if (big_mul(&l, &A1, &s2) || big_mul(&r, &A2, &s1)) return E_ARITH;
    *out = big_cmp(&l, &r);
    return E_OK;
}

int within_diameter(int64_t gap, const Diam *d, int *out) {
    if (d->zero) return *out = gap <= 0, E_OK;
    double g = (double)gap; /* exact: |gap| < 2^53 */
    if (!exact_only && g > d->f * (1 + 4 * EPS)) return *out = 0, E_OK;
    if (!exact_only && g < d->f * (1 - 4 * EPS)) return *out = 1, E_OK;
    big gb, lhs; /* gap <= num / den  <=>  gap * den <= num (den > 0) */
    big_from_i64(&gb, gap);
    if (big_mul(&lhs, &gb, &d->den)) return E_ARITH;
    *out = big_cmp(&lhs, &d->num) <= 0;
    return E_OK;
}
