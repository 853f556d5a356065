/* Exact predicates and correctly rounded constructions on the 2^-32 mm grid.
 *
 * Coordinates are integers q (q * 2^-32 mm) with |q| < 2^52, so every coordinate and every
 * difference of two is a float64 exactly. Each predicate is a float evaluation with a proven
 * error bound; where the bound cannot decide, the value is recomputed exactly in integers.
 * Each construction is rounded to the grid (nearest, ties to even) from a float value with
 * a proven error bound, or from the exact rational value where that value lies too close
 * to a midpoint between grid points.
 */
#ifndef BWSD_EXACT_H
#define BWSD_EXACT_H

#include <stdint.h>

#include <math.h>

#include "bigint.h"

#define GRID_LIMIT ((int64_t)1 << 52) /* 2^20 mm: coordinates must stay strictly below */

/* Error codes shared by the kernel (0 is success). */
enum {
    E_OK = 0,
    E_LIMIT = 1, /* a coordinate at or beyond 2^20 mm */
    E_ARITH = 2, /* an exact fallback ran out of its capacity (a bug) */
    E_NOMEM = 3,
    E_CONTACTS = 4, /* too many contacts in one sweep */
    E_MOVE_OUT = 5,
    E_MOVE_BUSY = 6,
    E_LINE = 7,      /* a line index outside the matrix */
    E_MOVE_SPAN = 8, /* a case would leave the segment it is moved on */
    E_JAM = 9,       /* a contact node within one diameter of the guide plane, or above it */
};

/* A signed value as the filter saw it: float value, its error bound, the exact sign, and
 * whether the float value decided that sign (|v| > e). */
typedef struct {
    double v, e;
    int s;
    int filtered;
} Sgn;

/* The cross product a x c of two exact vectors, to take u . (a x c) = det[u, a, c] for many
 * u: float minors with their permanents, the exact product when first needed. Every
 * orientation of the kernel is one such determinant. */
typedef struct {
    int64_t a[3], c[3];
    double m[6];
    i128 N[3];
    int exact_ready;
} Cross;

/* The plane of a sweep triangle (b, a1, a2): sides are u . ((a1 - b) x (a2 - b)), u = x - b. */
typedef struct {
    int64_t b[3];
    Cross x;
    int flat; /* the exact normal is zero: every point lies on it */
} Plane;

/* The yarn diameter in grid units: num / den exactly, f as a float. */
typedef struct {
    double f;
    big num, den;
    int zero;
} Diam;

/* Test hook: when set, every filter defers to the exact computation (results are the same). */
extern int exact_only;

void orient_sgn(const int64_t *p0, const int64_t *p1, const int64_t *p2, const int64_t *p3,
                Sgn *out);
int orient_big(const int64_t *p0, const int64_t *p1, const int64_t *p2, const int64_t *p3,
               big *out);
void plane_init(Plane *pl, const int64_t *b, const int64_t *a1, const int64_t *a2);
int plane_big(Plane *pl, const int64_t *x, big *out);

/* round(p + A / (A + B) * (q - p)) per coordinate, A = |a|, B = |b| (a, b nonzero, or
 * one of them zero); exact values are recomputed by the callbacks only when needed. */
typedef int (*ExactPair)(const void *ctx, big *a, big *b);
int lerp_round(const int64_t *p, const int64_t *q, const Sgn *a, const Sgn *b, ExactPair exact,
               const void *ctx, int64_t *out);
/* X = round(y - d n / |n|), n = m with its component along u removed. */
int rest_round(const int64_t *y, const int64_t *m, const int64_t *u, const Diam *d, int64_t *out);
/* Whether gap <= d exactly (gap in grid units, |gap| < 2^53; d the diameter). */
int within_diameter(int64_t gap, const Diam *d, int *out);
/* Compare the ratios |a1| / (|a1| + |b1|) and |a2| / (|a2| + |b2|) exactly: -1, 0, 1. */
int ratio_cmp_exact(const big *a1, const big *b1, const big *a2, const big *b2, int *out);
int round_ratio(const big *num, const big *den, int64_t *out);

/* Shewchuk's bound for the float form of the 3x3 determinant used here is (7 + 56 eps) eps
 * times the permanent (differences rounded); ours are exact, so the bound holds with room. */
#define ERRBOUND 8.0e-16

int dot_sign(const int64_t *u, const i128 *n);       /* the exact sign of u . n */
void cross_exact(Cross *x);                          /* the exact a x c */
int cross_big(Cross *x, const int64_t *u, big *out); /* the exact u . (a x c) */

static inline void cross_init(Cross *x, const int64_t *a, const int64_t *c) {
    double af[3] = {(double)a[0], (double)a[1], (double)a[2]};
    double cf[3] = {(double)c[0], (double)c[1], (double)c[2]};
    for (int k = 0; k < 3; k++) {
        x->a[k] = a[k];
        x->c[k] = c[k];
    }
    x->m[0] = af[1] * cf[2];
    x->m[1] = af[2] * cf[1];
    x->m[2] = af[2] * cf[0];
    x->m[3] = af[0] * cf[2];
    x->m[4] = af[0] * cf[1];
    x->m[5] = af[1] * cf[0];
    x->exact_ready = 0;
}

/* u . (a x c): the minors of a and c dotted with u, summed left to right; the sign from the
 * float value where it exceeds the bound, else exactly. */
static inline void cross_side(Cross *x, const int64_t *u, Sgn *out) {
    const double *m = x->m;
    double u0 = (double)u[0], u1 = (double)u[1], u2 = (double)u[2];
    double det = u0 * (m[0] - m[1]) + u1 * (m[2] - m[3]) + u2 * (m[4] - m[5]);
    double perm = fabs(u0) * (fabs(m[0]) + fabs(m[1])) + fabs(u1) * (fabs(m[2]) + fabs(m[3]));
    perm = perm + fabs(u2) * (fabs(m[4]) + fabs(m[5]));
    out->v = det;
    out->e = ERRBOUND * perm;
    if (!exact_only && (det > out->e || -det > out->e)) {
        out->s = det > 0 ? 1 : -1;
        out->filtered = 1;
        return;
    }
    if (!x->exact_ready) cross_exact(x);
    out->s = dot_sign(u, x->N);
    out->filtered = 0;
}

/* The side of x: the sign of det[a1 - b, a2 - b, x - b]. */
static inline void plane_side(Plane *pl, const int64_t *x, Sgn *out) {
    int64_t u[3] = {x[0] - pl->b[0], x[1] - pl->b[1], x[2] - pl->b[2]};
    cross_side(&pl->x, u, out);
}

#endif
