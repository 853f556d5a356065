/* One step of the relaxation (docs/relax.md): the same arithmetic as a loop over nodes and
 * pairs, in the fixed order of the arrays given, so the same input gives the same bytes.
 * Built with the package (setup.py), -ffp-contract=off as the twin's kernel. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define CAP 0.45

typedef struct {
    const double *pos;
    double *out;
    const int64_t *a, *b, *pi, *pj;
    const double *tension, *free, *room;
    Py_ssize_t nodes, segs, pairs;
    double d, alpha;
    int passes;
} Step;

static double dot3(const double *u, const double *v) { return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]; }

static double clamp01(double x) { return x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x); }

/* Closest points of segments p0-p1 and q0-q1: parameters s, t; returns the distance and
 * the unit direction from the second to the first in n (zero when they meet). */
static double closest(const double *p0, const double *p1, const double *q0, const double *q1,
                      double *s_out, double *t_out, double *n) {
    double u[3], v[3], w[3], g[3];
    for (int k = 0; k < 3; k++) { u[k] = p1[k] - p0[k]; v[k] = q1[k] - q0[k]; w[k] = p0[k] - q0[k]; }
    double a = dot3(u, u), b = dot3(u, v), c = dot3(v, v), e = dot3(u, w), f = dot3(v, w);
    double den = a * c - b * b, s = 0.0, t;
    if (den > 1e-12 * a * c) s = clamp01((b * f - c * e) / den);
    t = c > 1e-300 ? (b * s + f) / c : 0.0;
    if (t < 0.0) { t = 0.0; s = a > 1e-300 ? clamp01(-e / a) : 0.0; }
    else if (t > 1.0) { t = 1.0; s = a > 1e-300 ? clamp01((b - e) / a) : 0.0; }
    for (int k = 0; k < 3; k++) g[k] = (p0[k] + s * u[k]) - (q0[k] + t * v[k]);
    double dist = sqrt(dot3(g, g));
    for (int k = 0; k < 3; k++) n[k] = dist > 1e-300 ? g[k] / dist : 0.0;
    *s_out = s; *t_out = t;
    return dist;
}

static double pair_at(const Step *st, const double *x, Py_ssize_t p, double *s, double *t, double *n,
                      int64_t *ends) {
    ends[0] = st->a[st->pi[p]]; ends[1] = st->b[st->pi[p]];
    ends[2] = st->a[st->pj[p]]; ends[3] = st->b[st->pj[p]];
    return closest(x + 3 * ends[0], x + 3 * ends[1], x + 3 * ends[2], x + 3 * ends[3], s, t, n);
}

static void caps(const Step *st, double *cap) {
    double s, t, n[3];
    int64_t e[4];
    memcpy(cap, st->room, (size_t)st->nodes * sizeof(double));
    for (Py_ssize_t p = 0; p < st->pairs; p++) {
        double limit = CAP * pair_at(st, st->pos, p, &s, &t, n, e);
        for (int k = 0; k < 4; k++) if (limit < cap[e[k]]) cap[e[k]] = limit;
    }
}

static void clamp_moves(double *move, const double *cap, Py_ssize_t nodes) {
    for (Py_ssize_t i = 0; i < nodes; i++) {
        double len = sqrt(dot3(move + 3 * i, move + 3 * i));
        if (len > cap[i]) for (int k = 0; k < 3; k++) move[3 * i + k] *= cap[i] / len;
    }
}

static void pull(const Step *st, const double *x, double *move, double *stiff) {
    memset(move, 0, (size_t)st->nodes * 3 * sizeof(double));
    memset(stiff, 0, (size_t)st->nodes * sizeof(double));
    for (Py_ssize_t q = 0; q < st->segs; q++) {
        const double *pa = x + 3 * st->a[q], *pb = x + 3 * st->b[q];
        double seg[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
        double len = sqrt(dot3(seg, seg));
        if (len < 1e-12) len = 1e-12;
        double k = st->tension[q] / len;
        for (int c = 0; c < 3; c++) { move[3 * st->a[q] + c] += k * seg[c]; move[3 * st->b[q] + c] -= k * seg[c]; }
        stiff[st->a[q]] += k; stiff[st->b[q]] += k;
    }
    for (Py_ssize_t i = 0; i < st->nodes; i++)
        for (int c = 0; c < 3; c++)
            move[3 * i + c] = stiff[i] > 0 ? st->alpha * move[3 * i + c] / stiff[i] * st->free[3 * i + c] : 0.0;
}

/* Push every overlapping pair apart (position-based, averaged over each node's pairs). */
static void separate(const Step *st, double *x, double *acc, double *hits) {
    double s, t, n[3];
    int64_t e[4];
    memset(acc, 0, (size_t)st->nodes * 3 * sizeof(double));
    memset(hits, 0, (size_t)st->nodes * sizeof(double));
    for (Py_ssize_t p = 0; p < st->pairs; p++) {
        double dist = pair_at(st, x, p, &s, &t, n, e);
        if (!(dist < st->d)) continue;
        double w[4] = {1.0 - s, s, -(1.0 - t), -t};
        for (int c = 0; c < 3; c++) {
            double denom = 0.0;
            for (int k = 0; k < 4; k++) denom += w[k] * w[k] * st->free[3 * e[k] + c];
            if (denom <= 0.0) continue;
            double lam = (st->d - dist) * n[c] / denom;
            for (int k = 0; k < 4; k++) acc[3 * e[k] + c] += w[k] * st->free[3 * e[k] + c] * lam;
        }
        for (int k = 0; k < 4; k++) if (w[k] != 0.0) hits[e[k]] += 1.0;
    }
    for (Py_ssize_t i = 0; i < st->nodes; i++) {
        double h = hits[i] > 1.0 ? hits[i] : 1.0;
        for (int c = 0; c < 3; c++) x[3 * i + c] += acc[3 * i + c] / h;
    }
}

static void measure(const Step *st, double *energy, double *worst) {
    double s, t, n[3], e_sum = 0.0, w_max = 0.0;
    int64_t e[4];
    for (Py_ssize_t q = 0; q < st->segs; q++) {
        const double *pa = st->out + 3 * st->a[q], *pb = st->out + 3 * st->b[q];
        double seg[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
        e_sum += st->tension[q] * sqrt(dot3(seg, seg));
    }
    for (Py_ssize_t p = 0; p < st->pairs; p++) {
        double over = st->d - pair_at(st, st->out, p, &s, &t, n, e);
        if (over > w_max) w_max = over;
    }
    *energy = e_sum; *worst = w_max;
}

static int run(const Step *st, double *energy, double *worst) {
    size_t n3 = (size_t)st->nodes * 3;
    double *cap = malloc((size_t)st->nodes * sizeof(double)), *hits = malloc((size_t)st->nodes * sizeof(double));
    double *move = malloc(n3 * sizeof(double)), *acc = malloc(n3 * sizeof(double));
    if (!cap || !hits || !move || !acc) { free(cap); free(hits); free(move); free(acc); return -1; }
    caps(st, cap);
    memcpy(st->out, st->pos, n3 * sizeof(double));
    if (st->alpha > 0.0) {
        pull(st, st->pos, move, hits);
        clamp_moves(move, cap, st->nodes);
        for (size_t i = 0; i < n3; i++) st->out[i] += move[i];
    }
    for (int k = 0; k < st->passes; k++) separate(st, st->out, acc, hits);
    for (size_t i = 0; i < n3; i++) move[i] = st->out[i] - st->pos[i];
    clamp_moves(move, cap, st->nodes);
    for (size_t i = 0; i < n3; i++) st->out[i] = st->pos[i] + move[i];
    measure(st, energy, worst);
    free(cap); free(hits); free(move); free(acc);
    return 0;
}

static int check(Py_buffer *buf, Py_ssize_t items, size_t size, const char *what) {
    if (buf->len != items * (Py_ssize_t)size) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd items", what, items);
        return -1;
    }
    return 0;
}

static PyObject *py_step(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer pos, out, a, b, tension, freeb, pi, pj, room;
    double d, alpha, energy = 0.0, worst = 0.0;
    int passes, rc = -1;
    if (!PyArg_ParseTuple(args, "y*w*y*y*y*y*y*y*y*ddi", &pos, &out, &a, &b, &tension, &freeb,
                          &pi, &pj, &room, &d, &alpha, &passes))
        return NULL;
    Step st = {pos.buf, out.buf, a.buf, b.buf, pi.buf, pj.buf, tension.buf, freeb.buf, room.buf,
               pos.len / 24, a.len / 8, pi.len / 8, d, alpha, passes};
    if (check(&out, st.nodes * 3, 8, "out") == 0 && check(&b, st.segs, 8, "b") == 0 &&
        check(&tension, st.segs, 8, "tension") == 0 && check(&freeb, st.nodes * 3, 8, "free") == 0 &&
        check(&pj, st.pairs, 8, "pj") == 0 && check(&room, st.nodes, 8, "room") == 0) {
        Py_BEGIN_ALLOW_THREADS
        rc = run(&st, &energy, &worst);
        Py_END_ALLOW_THREADS
        if (rc != 0) PyErr_NoMemory();
    }
    PyBuffer_Release(&pos); PyBuffer_Release(&out); PyBuffer_Release(&a); PyBuffer_Release(&b);
    PyBuffer_Release(&tension); PyBuffer_Release(&freeb); PyBuffer_Release(&pi);
    PyBuffer_Release(&pj); PyBuffer_Release(&room);
    if (rc != 0) return NULL;
    return Py_BuildValue("dd", energy, worst);
}

static PyMethodDef methods[] = {
    {"step", py_step, METH_VARARGS,
     "step(pos, out, a, b, tension, free, pi, pj, room, d, alpha, passes) -> (energy, worst)"},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_step", "One relaxation step.", -1, methods};

PyMODINIT_FUNC PyInit__step(void) { return PyModule_Create(&module); }
