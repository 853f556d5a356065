/* The relaxation's steps (docs/relax.md, "The method, and why"): a loop over nodes and pairs
 * in the fixed order of the arrays given, so the same input gives the same bytes. Built with
 * the package (setup.py), with the twin kernel's flags (-ffp-contract=off among them); the
 * interpreter lock is released while it runs.
 *
 * One step, from positions x0:
 *   1. caps: each node may move at most CAP times the least distance from its segments to
 *      the listed segments of other yarns, and no more than its room (what is left of the
 *      pair list's reach);
 *   2. pull (alpha > 0): Gauss-Seidel over the nodes in order, each free node moved by alpha
 *      of the way to the minimiser of its two segments' majorised tension x length (the
 *      point (T1 a / l1 + T2 b / l2) / (T1 / l1 + T2 / l2) on its free components);
 *   3. push: `passes` Gauss-Seidel sweeps over the pairs in order, each overlapping pair
 *      pushed apart to `target` (d and a skin) along its closest points' direction, the
 *      correction shared by the four ends with weights of the closest points and inverse
 *      masses 1 / stiffness;
 *   every node's displacement from x0 is kept within its cap after each change.
 * A step is kept when the tension-weighted length did not rise and the worst overlap stayed
 * within the limit; else alpha halves and the step is tried again from x0. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define CAP 0.45
#define GROW 1.25 /* alpha grows by this after a kept step */
#define MIN_ALPHA (1.0 / 1048576.0)

typedef struct {
    double *pos;            /* (nodes, 3), updated in place with every kept step */
    const int64_t *a, *b;   /* segment ends */
    const int64_t *pi, *pj; /* listed pairs of segments */
    const double *tension, *free;
    double *room;     /* per node, updated with every kept step */
    double *energies; /* the energy after each kept step */
    Py_ssize_t nodes, segs, pairs, max_steps;
    double d, target, limit, stall, relist;
    int passes, pull;
} Run;

typedef struct {
    double *x, *cap, *stiff, *inv;
} Work;

static double dot3(const double *u, const double *v) {
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
}

static double clamp01(double x) { return x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x); }

/* Closest points of segments p0-p1 and q0-q1: parameters s, t; returns the distance and
 * the unit direction from the second to the first in n (zero when they meet). */
static double closest(const double *p0, const double *p1, const double *q0, const double *q1,
                      double *s_out, double *t_out, double *n) {
    double u[3], v[3], w[3], g[3];
    for (int k = 0; k < 3; k++) {
        u[k] = p1[k] - p0[k];
        v[k] = q1[k] - q0[k];
        w[k] = p0[k] - q0[k];
    }
    double a = dot3(u, u), b = dot3(u, v), c = dot3(v, v), e = dot3(u, w), f = dot3(v, w);
    double den = a * c - b * b, s = 0.0, t;
    if (den > 1e-12 * a * c) s = clamp01((b * f - c * e) / den);
    t = c > 1e-300 ? (b * s + f) / c : 0.0;
    if (t < 0.0) {
        t = 0.0;
        s = a > 1e-300 ? clamp01(-e / a) : 0.0;
    } else if (t > 1.0) {
        t = 1.0;
        s = a > 1e-300 ? clamp01((b - e) / a) : 0.0;
    }
    for (int k = 0; k < 3; k++) g[k] = (p0[k] + s * u[k]) - (q0[k] + t * v[k]);
    double dist = sqrt(dot3(g, g));
    for (int k = 0; k < 3; k++) n[k] = dist > 1e-300 ? g[k] / dist : 0.0;
    *s_out = s;
    *t_out = t;
    return dist;
}

static double pair_at(const Run *r, const double *x, Py_ssize_t p, double *s, double *t, double *n,
                      int64_t *e) {
    e[0] = r->a[r->pi[p]];
    e[1] = r->b[r->pi[p]];
    e[2] = r->a[r->pj[p]];
    e[3] = r->b[r->pj[p]];
    return closest(x + 3 * e[0], x + 3 * e[1], x + 3 * e[2], x + 3 * e[3], s, t, n);
}

static double seg_len(const double *x, int64_t a, int64_t b) {
    double s[3] = {x[3 * b] - x[3 * a], x[3 * b + 1] - x[3 * a + 1], x[3 * b + 2] - x[3 * a + 2]};
    return sqrt(dot3(s, s));
}

static void caps(const Run *r, Work *w) {
    double s, t, n[3];
    int64_t e[4];
    memcpy(w->cap, r->room, (size_t)r->nodes * sizeof(double));
    for (Py_ssize_t p = 0; p < r->pairs; p++) {
        double limit = CAP * pair_at(r, r->pos, p, &s, &t, n, e);
        for (int k = 0; k < 4; k++)
            if (limit < w->cap[e[k]]) w->cap[e[k]] = limit;
    }
}

/* Node i's stiffness T1 / l1 + T2 / l2 at x0: its inverse is the node's inverse mass. */
static void stiffness(const Run *r, Work *w) {
    memset(w->stiff, 0, (size_t)r->nodes * sizeof(double));
    for (Py_ssize_t q = 0; q < r->segs; q++) {
        double len = seg_len(r->pos, r->a[q], r->b[q]);
        double k = r->tension[q] / (len > 1e-12 ? len : 1e-12);
        w->stiff[r->a[q]] += k;
        w->stiff[r->b[q]] += k;
    }
    for (Py_ssize_t i = 0; i < r->nodes; i++)
        w->inv[i] = w->stiff[i] > 0.0 ? 1.0 / w->stiff[i] : 0.0;
}

/* Keep node i within its cap of x0. */
static void keep(const Run *r, Work *w, int64_t i) {
    double m[3];
    for (int k = 0; k < 3; k++) m[k] = w->x[3 * i + k] - r->pos[3 * i + k];
    double len = sqrt(dot3(m, m));
    if (len > w->cap[i])
        for (int k = 0; k < 3; k++) w->x[3 * i + k] = r->pos[3 * i + k] + m[k] * (w->cap[i] / len);
}

/* Gauss-Seidel over the nodes; prev[i] and next[i] are node i's segments (-1: none). */
static void pull(const Run *r, Work *w, const int64_t *prev, const int64_t *next, double alpha) {
    for (Py_ssize_t i = 0; i < r->nodes; i++) {
        double num[3] = {0.0, 0.0, 0.0}, den = 0.0;
        const double *xi = w->x + 3 * i;
        if (prev[i] >= 0) {
            int64_t q = prev[i], o = r->a[q];
            double len = seg_len(w->x, o, i), k = r->tension[q] / (len > 1e-12 ? len : 1e-12);
            for (int c = 0; c < 3; c++) num[c] += k * w->x[3 * o + c];
            den += k;
        }
        if (next[i] >= 0) {
            int64_t q = next[i], o = r->b[q];
            double len = seg_len(w->x, i, o), k = r->tension[q] / (len > 1e-12 ? len : 1e-12);
            for (int c = 0; c < 3; c++) num[c] += k * w->x[3 * o + c];
            den += k;
        }
        if (den <= 0.0) continue;
        for (int c = 0; c < 3; c++) {
            double target = num[c] / den;
            w->x[3 * i + c] = xi[c] + alpha * (target - xi[c]) * r->free[3 * i + c];
        }
        keep(r, w, i);
    }
}

/* One Gauss-Seidel sweep over the pairs; returns the worst overlap met. */
static double push(const Run *r, Work *w) {
    double s, t, n[3], worst = 0.0;
    int64_t e[4];
    for (Py_ssize_t p = 0; p < r->pairs; p++) {
        double dist = pair_at(r, w->x, p, &s, &t, n, e);
        if (!(dist < r->d)) continue; /* only overlaps are pushed, to the skin beyond d */
        if (r->d - dist > worst) worst = r->d - dist;
        double wt[4] = {1.0 - s, s, -(1.0 - t), -t};
        for (int c = 0; c < 3; c++) {
            double denom = 0.0;
            for (int k = 0; k < 4; k++)
                denom += wt[k] * wt[k] * w->inv[e[k]] * r->free[3 * e[k] + c];
            if (denom <= 0.0) continue;
            double lam = (r->target - dist) * n[c] / denom;
            for (int k = 0; k < 4; k++)
                w->x[3 * e[k] + c] += wt[k] * w->inv[e[k]] * r->free[3 * e[k] + c] * lam;
        }
        for (int k = 0; k < 4; k++) keep(r, w, e[k]);
    }
    return worst;
}

static void measure(const Run *r, const double *x, double *energy, double *worst) {
    double s, t, n[3], e_sum = 0.0, w_max = 0.0;
    int64_t e[4];
    for (Py_ssize_t q = 0; q < r->segs; q++) e_sum += r->tension[q] * seg_len(x, r->a[q], r->b[q]);
    for (Py_ssize_t p = 0; p < r->pairs; p++) {
        double over = r->d - pair_at(r, x, p, &s, &t, n, e);
        if (over > w_max) w_max = over;
    }
    *energy = e_sum;
    *worst = w_max;
}

static void try_step(const Run *r, Work *w, const int64_t *prev, const int64_t *next,
                     double alpha) {
    memcpy(w->x, r->pos, (size_t)r->nodes * 3 * sizeof(double));
    if (alpha > 0.0) pull(r, w, prev, next, alpha);
    for (int k = 0; k < r->passes; k++)
        if (push(r, w) == 0.0) break;
}

static void take(Run *r, Work *w) {
    for (Py_ssize_t i = 0; i < r->nodes; i++) {
        double m[3];
        for (int k = 0; k < 3; k++) m[k] = w->x[3 * i + k] - r->pos[3 * i + k];
        r->room[i] -= sqrt(dot3(m, m));
    }
    memcpy(r->pos, w->x, (size_t)r->nodes * 3 * sizeof(double));
}

static double least(const double *v, Py_ssize_t n) {
    double m = INFINITY;
    for (Py_ssize_t i = 0; i < n; i++)
        if (v[i] < m) m = v[i];
    return m;
}

/* Status: 0 stalled (converged), 1 out of steps, 2 relist needed, 3 no step was kept. */
typedef struct {
    Py_ssize_t steps, rejected;
    double energy, worst, alpha;
    int status;
} Outcome;

static void run(Run *r, Work *w, const int64_t *prev, const int64_t *next, Outcome *o) {
    double e0, w0, e1, w1;
    measure(r, r->pos, &e0, &w0);
    o->status = 1;
    while (o->steps < r->max_steps) {
        if (least(r->room, r->nodes) < r->relist) {
            o->status = 2;
            break;
        }
        stiffness(r, w);
        caps(r, w);
        double limit = w0 > r->limit ? w0 : r->limit;
        for (;;) {
            try_step(r, w, prev, next, r->pull ? o->alpha : 0.0);
            measure(r, w->x, &e1, &w1);
            if (!r->pull || (e1 <= e0 && w1 <= limit) || o->alpha <= MIN_ALPHA) break;
            o->alpha *= 0.5;
            o->rejected++;
        }
        if (r->pull && (e1 > e0 || w1 > limit)) {
            o->status = 3;
            break;
        }
        take(r, w);
        r->energies[o->steps++] = e1;
        double drop = e0 - e1;
        e0 = e1;
        w0 = w1;
        if (r->pull) {
            o->alpha = o->alpha * GROW < 1.0 ? o->alpha * GROW : 1.0;
            if (drop <= r->stall * e1) {
                o->status = 0;
                break;
            }
        } else if (w1 <= r->limit) {
            o->status = 0;
            break;
        }
    }
    o->energy = e0;
    o->worst = w0;
}

static int check(Py_buffer *buf, Py_ssize_t items, size_t size, const char *what) {
    if (buf->len != items * (Py_ssize_t)size) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd items of %zu bytes", what, items, size);
        return -1;
    }
    return 0;
}

static int neighbours(const Run *r, int64_t *prev, int64_t *next) {
    for (Py_ssize_t i = 0; i < r->nodes; i++) {
        prev[i] = -1;
        next[i] = -1;
    }
    for (Py_ssize_t q = 0; q < r->segs; q++) {
        if (r->a[q] < 0 || r->a[q] >= r->nodes || r->b[q] < 0 || r->b[q] >= r->nodes) return -1;
        next[r->a[q]] = q;
        prev[r->b[q]] = q;
    }
    for (Py_ssize_t p = 0; p < r->pairs; p++)
        if (r->pi[p] < 0 || r->pi[p] >= r->segs || r->pj[p] < 0 || r->pj[p] >= r->segs) return -1;
    return 0;
}

static int execute(Run *r, Outcome *o) {
    size_t n = (size_t)r->nodes;
    Work w = {malloc(3 * n * sizeof(double) + 1), malloc(n * sizeof(double) + 1),
              malloc(n * sizeof(double) + 1), malloc(n * sizeof(double) + 1)};
    int64_t *prev = malloc(n * sizeof(int64_t) + 1), *next = malloc(n * sizeof(int64_t) + 1);
    int rc = -1;
    if (w.x && w.cap && w.stiff && w.inv && prev && next) {
        rc = neighbours(r, prev, next) ? -2 : 0;
        if (rc == 0) run(r, &w, prev, next, o);
    }
    free(w.x);
    free(w.cap);
    free(w.stiff);
    free(w.inv);
    free(prev);
    free(next);
    return rc;
}

static PyObject *py_steps(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer pos, a, b, tension, freeb, pi, pj, room, energies;
    Run r;
    Outcome o = {0, 0, 0.0, 0.0, 1.0, 1};
    int rc = -1;
    if (!PyArg_ParseTuple(args, "w*y*y*y*y*y*y*w*w*dddddipd", &pos, &a, &b, &tension, &freeb, &pi,
                          &pj, &room, &energies, &r.d, &r.target, &r.limit, &r.stall, &r.relist,
                          &r.passes, &r.pull, &o.alpha))
        return NULL;
    r.pos = pos.buf;
    r.a = a.buf;
    r.b = b.buf;
    r.pi = pi.buf;
    r.pj = pj.buf;
    r.tension = tension.buf;
    r.free = freeb.buf;
    r.room = room.buf;
    r.energies = energies.buf;
    r.nodes = pos.len / 24;
    r.segs = a.len / 8;
    r.pairs = pi.len / 8;
    r.max_steps = energies.len / 8;
    if (check(&pos, r.nodes * 3, 8, "pos") == 0 && check(&b, r.segs, 8, "b") == 0 &&
        check(&tension, r.segs, 8, "tension") == 0 && check(&freeb, r.nodes * 3, 8, "free") == 0 &&
        check(&pj, r.pairs, 8, "pj") == 0 && check(&room, r.nodes, 8, "room") == 0) {
        Py_BEGIN_ALLOW_THREADS
            rc = execute(&r, &o);
        Py_END_ALLOW_THREADS
        if (rc == -1)
            PyErr_NoMemory();
        else if (rc == -2)
            PyErr_SetString(PyExc_ValueError, "an index is out of range");
    }
    PyBuffer_Release(&pos);
    PyBuffer_Release(&a);
    PyBuffer_Release(&b);
    PyBuffer_Release(&tension);
    PyBuffer_Release(&freeb);
    PyBuffer_Release(&pi);
    PyBuffer_Release(&pj);
    PyBuffer_Release(&room);
    PyBuffer_Release(&energies);
    if (rc != 0) return NULL;
    return Py_BuildValue("nnddid", o.steps, o.rejected, o.energy, o.worst, o.status, o.alpha);
}

static PyMethodDef methods[] = {
    {"steps", py_steps, METH_VARARGS,
     "steps(pos, a, b, tension, free, pi, pj, room, energies, d, target, limit, stall, relist, "
     "passes,"
     " pull, alpha) -> (steps, rejected, energy, worst, status, alpha)"},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {
    .m_base = PyModuleDef_HEAD_INIT,
    .m_name = "_step",
    .m_doc = "The relaxation's steps.",
    .m_size = -1,
    .m_methods = methods,
};

PyMODINIT_FUNC PyInit__step(void) { return PyModule_Create(&module); }
