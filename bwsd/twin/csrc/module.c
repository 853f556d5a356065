/* bwsd.twin._kernel: the twin's compiled kernel as a Python type (see bwsd/twin/kernel.py).
 *
 * Arrays cross as bytes in native byte order; bwsd.twin reads them with numpy. An instruction
 * runs with the interpreter lock released. The object refuses a second caller while one is
 * inside (the Python side serialises its callers with a lock).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <stdlib.h>
#include <string.h>

#include "snapshot.h"
#include "swept.h"

typedef struct {
    PyObject_HEAD State s;
    int ready, busy;
    PyObject *dnum, *dden; /* the diameter's exact numerator and denominator, as bytes */
} Kernel;

static PyObject *KernelError;

static int enter(Kernel *k) {
    if (!k->ready) {
        PyErr_SetString(PyExc_RuntimeError, "the twin kernel is not initialised");
        return -1;
    }
    if (k->busy) {
        PyErr_SetString(PyExc_RuntimeError, "the twin kernel is in use by another thread");
        return -1;
    }
    k->busy = 1;
    return 0;
}

static PyObject *fail(Kernel *k, int code) {
    k->busy = 0;
    if (code == E_NOMEM) return PyErr_NoMemory();
    State *s = &k->s;
    PyObject *args = Py_BuildValue("(iLLLL)", code, (long long)s->err[0], (long long)s->err[1],
                                   (long long)s->err[2], (long long)s->err[3]);
    if (args) {
        PyErr_SetObject(KernelError, args);
        Py_DECREF(args);
    }
    return NULL;
}

static PyObject *bytes_of(const void *p, size_t n) {
    return PyBytes_FromStringAndSize(n ? p : "", (Py_ssize_t)n);
}

static void Kernel_dealloc(Kernel *k) {
    if (k->ready) state_free(&k->s);
    Py_XDECREF(k->dnum);
    Py_XDECREF(k->dden);
    Py_TYPE(k)->tp_free((PyObject *)k);
}

static int set_diameter(Kernel *k, double f, PyObject *num, PyObject *den) {
    State *s = &k->s;
    s->d.f = f;
    if (big_from_bytes(&s->d.num, (const unsigned char *)PyBytes_AS_STRING(num),
                       (int)PyBytes_GET_SIZE(num), 0) ||
        big_from_bytes(&s->d.den, (const unsigned char *)PyBytes_AS_STRING(den),
                       (int)PyBytes_GET_SIZE(den), 0) ||
        big_sign(&s->d.den) <= 0) {
        PyErr_SetString(PyExc_ValueError, "bad diameter");
        return -1;
    }
    s->d.zero = big_sign(&s->d.num) == 0;
    Py_INCREF(num);
    Py_INCREF(den);
    Py_XSETREF(k->dnum, num);
    Py_XSETREF(k->dden, den);
    return 0;
}

/* Kernel(gx, gy, gz, shift, d, d_num, d_den): guides' x per column and y per row (int64
 * bytes), the guides' z, the grid cell size 2^shift, the diameter (float and exact). */
static int Kernel_init(Kernel *k, PyObject *args, PyObject *kw) {
    static char *names[] = {"gx", "gy", "gz", "shift", "d", "d_num", "d_den", NULL};
    Py_buffer gx, gy;
    long long gz;
    int shift;
    double d;
    PyObject *num, *den;
    if (!PyArg_ParseTupleAndKeywords(args, kw, "y*y*LidSS", names, &gx, &gy, &gz, &shift, &d,
                                     &num, &den))
        return -1;
    int err = 0;
    Py_ssize_t cols = gx.len / 8, rows = gy.len / 8;
    if (cols < 1 || rows < 1 || shift < 1 || shift > 60 || k->ready) {
        PyErr_SetString(PyExc_ValueError, "bad kernel geometry");
        err = -1;
    }
    if (!err && state_init(&k->s, (int32_t)rows, (int32_t)cols, gx.buf, gy.buf, gz, shift)) {
        state_free(&k->s);
        PyErr_NoMemory();
        err = -1;
    }
    PyBuffer_Release(&gx);
    PyBuffer_Release(&gy);
    if (err) return -1;
    k->ready = 1;
    return set_diameter(k, d, num, den);
}

static PyObject *Kernel_add_warp(Kernel *k, PyObject *args) {
    int r, c;
    long long x, y, z;
    if (!PyArg_ParseTuple(args, "iiLLL", &r, &c, &x, &y, &z) || enter(k)) return NULL;
    State *s = &k->s;
    if (r < 0 || r >= s->rows || c < 0 || c >= s->cols || s->occ[(int64_t)r * s->cols + c] >= 0 ||
        s->ny != s->nw) {
        k->busy = 0;
        PyErr_SetString(PyExc_ValueError, "bad fill cell");
        return NULL;
    }
    int64_t fell[3] = {x, y, z};
    int err = warp_add(s, r, c, fell);
    if (err) return fail(k, err);
    k->busy = 0;
    return PyLong_FromLong(s->nw - 1);
}

static const State *sort_state;

static int by_yarn(const void *a, const void *b) {
    int32_t ya = sort_state->nyarn[*(const int32_t *)a], yb = sort_state->nyarn[*(const int32_t *)b];
    return ya < yb ? -1 : ya > yb;
}

/* New nodes in yarn order (yarns ascending, each yarn's from its start), so each one's
 * predecessor is old or comes before it. Six int64 per node: id, yarn, predecessor, x, y, z.
 * Each yarn is walked back from its end only as far as its deepest new node. */
static PyObject *new_nodes(const State *s, int32_t nn0) {
    int64_t count = s->nn - nn0;
    int64_t *out = malloc(sizeof(int64_t) * 6 * (size_t)(count ? count : 1));
    int32_t *ids = malloc(sizeof(int32_t) * (size_t)(count ? count : 1));
    if (!out || !ids) return free(out), free(ids), PyErr_NoMemory();
    for (int64_t i = 0; i < count; i++) ids[i] = nn0 + (int32_t)i;
    sort_state = s; /* under the interpreter lock: one caller at a time */
    qsort(ids, (size_t)count, sizeof(int32_t), by_yarn);
    for (int64_t g = 0; g < count;) {
        int32_t y = s->nyarn[ids[g]];
        int64_t end = g;
        while (end < count && s->nyarn[ids[end]] == y) end++;
        int64_t at = end; /* fill this yarn's rows from the back */
        for (int32_t n = s->tail[y]; n != -1 && at > g; n = s->prev[n]) {
            if (n < nn0) continue;
            int64_t *o = out + 6 * --at;
            o[0] = n;
            o[1] = y;
            o[2] = s->prev[n];
            memcpy(o + 3, P(s, n), 3 * sizeof(int64_t));
        }
        g = end;
    }
    PyObject *b = bytes_of(out, sizeof(int64_t) * 6 * (size_t)count);
    free(out);
    free(ids);
    return b;
}

/* Moved warps: six int64 each (warp, x, y, z, row, col) and their path length change. */
static PyObject *moved(const State *s, const Moved *mv) {
    int64_t *rows = malloc(sizeof(int64_t) * 6 * (size_t)(mv->n ? mv->n : 1));
    double *change = malloc(sizeof(double) * (size_t)(mv->n ? mv->n : 1));
    if (!rows || !change) return free(rows), free(change), PyErr_NoMemory();
    for (int32_t i = 0; i < mv->n; i++) {
        int32_t w = mv->warps[i];
        int64_t *o = rows + 6 * i;
        o[0] = w;
        memcpy(o + 1, P(s, s->tail[w]), 3 * sizeof(int64_t));
        o[4] = s->wr[w];
        o[5] = s->wc[w];
        change[i] = path_length(s, w) - mv->before[i];
    }
    PyObject *res = Py_BuildValue("(NN)", bytes_of(rows, sizeof(int64_t) * 6 * (size_t)mv->n),
                                  bytes_of(change, sizeof(double) * (size_t)mv->n));
    free(rows);
    free(change);
    return res;
}

typedef struct {
    int32_t nn0, ny0;
    int64_t nc0;
} Mark;

static Mark begin(State *s) {
    s->logging = 1;
    s->nlog = 0;
    return (Mark){s->nn, s->ny, s->nc};
}

/* After an instruction: raise its error (rolled back), keep it, or describe and roll it back. */
static PyObject *finish(Kernel *k, int err, int predict, Moved *mv, Mark mk) {
    State *s = &k->s;
    PyObject *res = NULL;
    if (err) {
        undo_to(s, 0);
    } else if (!predict) {
        res = Py_None;
        Py_INCREF(res);
    } else {
        PyObject *parts[5] = {bytes_of(s->log, sizeof(Op) * (size_t)s->nlog),
                              bytes_of(s->contacts + 5 * mk.nc0,
                                       sizeof(int32_t) * 5 * (size_t)(s->nc - mk.nc0)),
                              new_nodes(s, mk.nn0), moved(s, mv),
                              bytes_of(s->occ, sizeof(int32_t) * (size_t)s->rows * s->cols)};
        if (parts[0] && parts[1] && parts[2] && parts[3] && parts[4])
            res = Py_BuildValue("(NNNNNii)", parts[0], parts[1], parts[2], parts[3], parts[4],
                                mk.ny0, s->ny);
        else
            for (int i = 0; i < 5; i++) Py_XDECREF(parts[i]);
        undo_to(s, 0);
    }
    s->nlog = 0;
    s->logging = 0;
    free(mv->warps);
    free(mv->before);
    if (err) return fail(k, err);
    k->busy = 0;
    return res;
}

/* shift(axis, moves, instruction, predict): axis 0 row, 1 col; moves int32 (line, k, lo, hi)
 * quads (cells lo..hi of the line move; 0..last for the whole line).
 * predict: return (record, contacts, new nodes, (moved, length changes), occupancy, first new
 * yarn, yarns) and leave the state as it was; otherwise keep the result and return None. */
static PyObject *Kernel_shift(Kernel *k, PyObject *args) {
    int axis, instr, predict;
    Py_buffer moves;
    if (!PyArg_ParseTuple(args, "iy*ip", &axis, &moves, &instr, &predict)) return NULL;
    if (enter(k)) return PyBuffer_Release(&moves), NULL;
    int32_t *m = malloc(moves.len ? (size_t)moves.len : 1);
    if (!m) return PyBuffer_Release(&moves), k->busy = 0, PyErr_NoMemory();
    memcpy(m, moves.buf, (size_t)moves.len);
    int32_t n = (int32_t)(moves.len / 16);
    PyBuffer_Release(&moves);
    State *s = &k->s;
    Mark mk = begin(s);
    Moved mv = {NULL, NULL, 0};
    int err;
    Py_BEGIN_ALLOW_THREADS err = run_shift(s, axis, m, n, instr, &mv);
    Py_END_ALLOW_THREADS free(m);
    return finish(k, err, predict, &mv, mk);
}

/* takeup(gz, instruction, predict): every free node sweeps to its guide at the new z */
static PyObject *Kernel_takeup(Kernel *k, PyObject *args) {
    long long gz;
    int instr, predict;
    if (!PyArg_ParseTuple(args, "Lip", &gz, &instr, &predict) || enter(k)) return NULL;
    State *s = &k->s;
    Mark mk = begin(s);
    Moved mv = {NULL, NULL, 0};
    int err;
    Py_BEGIN_ALLOW_THREADS err = run_takeup(s, gz, instr, &mv);
    Py_END_ALLOW_THREADS return finish(k, err, predict, &mv, mk);
}

/* weft(x0, y0, z0, x1, y1, z1, predict): a two-node yarn (the shed is checked by the caller) */
static PyObject *Kernel_weft(Kernel *k, PyObject *args) {
    long long a, b, c, d, e, f;
    int predict;
    if (!PyArg_ParseTuple(args, "LLLLLLp", &a, &b, &c, &d, &e, &f, &predict) || enter(k))
        return NULL;
    int64_t p0[3] = {a, b, c}, p1[3] = {d, e, f};
    State *s = &k->s;
    Mark mk = begin(s);
    Moved mv = {NULL, NULL, 0};
    int err = run_weft(s, p0, p1);
    return finish(k, err, predict, &mv, mk);
}

/* replay(log): apply a prediction's record to the state it was made on */
static PyObject *Kernel_replay(Kernel *k, PyObject *args) {
    Py_buffer log;
    if (!PyArg_ParseTuple(args, "y*", &log)) return NULL;
    if (enter(k)) return PyBuffer_Release(&log), NULL;
    int err;
    State *s = &k->s;
    Py_BEGIN_ALLOW_THREADS err = redo(s, log.buf, log.len / (Py_ssize_t)sizeof(Op));
    Py_END_ALLOW_THREADS PyBuffer_Release(&log);
    if (err) return fail(k, err);
    k->busy = 0;
    Py_RETURN_NONE;
}

static PyObject *Kernel_counts(Kernel *k, PyObject *noargs) {
    (void)noargs;
    const State *s = &k->s;
    return Py_BuildValue("(iiiLL)", s->nn, s->ny, s->nw, (long long)s->nc, (long long)s->gz);
}

/* A copy of one of the state's arrays, taken while no other caller is inside. */
static PyObject *array_copy(Kernel *k, const void *p, size_t n) {
    if (enter(k)) return NULL;
    PyObject *b = bytes_of(p, n);
    k->busy = 0;
    return b;
}

/* positions(): int64 x, y, z of every node */
static PyObject *Kernel_positions(Kernel *k, PyObject *noargs) {
    (void)noargs;
    return array_copy(k, k->s.pos, sizeof(int64_t) * 3 * (size_t)k->s.nn);
}

/* points(ids): int64 x, y, z of the given node ids (int32 bytes) */
static PyObject *Kernel_points(Kernel *k, PyObject *args) {
    Py_buffer ids;
    if (!PyArg_ParseTuple(args, "y*", &ids)) return NULL;
    if (enter(k)) return PyBuffer_Release(&ids), NULL;
    const State *s = &k->s;
    Py_ssize_t n = ids.len / 4;
    const int32_t *id = ids.buf;
    int64_t *out = malloc(sizeof(int64_t) * 3 * (size_t)(n ? n : 1));
    int bad = out == NULL;
    for (Py_ssize_t i = 0; i < n && !bad; i++) {
        if (id[i] < 0 || id[i] >= s->nn) bad = 2;
        else memcpy(out + 3 * i, P(s, id[i]), 3 * sizeof(int64_t));
    }
    PyBuffer_Release(&ids);
    k->busy = 0;
    if (bad) {
        free(out);
        if (bad == 1) return PyErr_NoMemory();
        PyErr_SetString(PyExc_IndexError, "node id out of range");
        return NULL;
    }
    PyObject *b = bytes_of(out, sizeof(int64_t) * 3 * (size_t)n);
    free(out);
    return b;
}

/* chains(first, last): node ids of yarns first .. last - 1 in order (int32), and each yarn's
 * start in that list (int64, one more than the yarns) */
static PyObject *Kernel_chains(Kernel *k, PyObject *args) {
    int first, last;
    if (!PyArg_ParseTuple(args, "ii", &first, &last) || enter(k)) return NULL;
    const State *s = &k->s;
    if (first < 0 || last > s->ny || first > last) {
        k->busy = 0;
        PyErr_SetString(PyExc_IndexError, "yarn out of range");
        return NULL;
    }
    int32_t *ids = malloc(sizeof(int32_t) * (size_t)(s->nn ? s->nn : 1));
    int64_t *start = malloc(sizeof(int64_t) * (size_t)(last - first + 1));
    if (!ids || !start) return free(ids), free(start), k->busy = 0, PyErr_NoMemory();
    int64_t at = 0;
    for (int32_t y = first; y < last; y++) {
        start[y - first] = at;
        for (int32_t n = s->head[y]; n != -1; n = s->next[n]) ids[at++] = n;
    }
    start[last - first] = at;
    PyObject *res = Py_BuildValue("(NN)", bytes_of(ids, sizeof(int32_t) * (size_t)at),
                                  bytes_of(start, sizeof(int64_t) * (size_t)(last - first + 1)));
    free(ids);
    free(start);
    k->busy = 0;
    return res;
}

/* contacts(): int32 (instruction, moving yarn, X, hit yarn, Y) per contact */
static PyObject *Kernel_contacts(Kernel *k, PyObject *noargs) {
    (void)noargs;
    return array_copy(k, k->s.contacts, sizeof(int32_t) * 5 * (size_t)k->s.nc);
}

/* warps(): int32 (row, col, free node, last fixed node) per warp, and the occupancy */
static PyObject *Kernel_warps(Kernel *k, PyObject *noargs) {
    (void)noargs;
    if (enter(k)) return NULL;
    const State *s = &k->s;
    int32_t *out = malloc(sizeof(int32_t) * 4 * (size_t)(s->nw ? s->nw : 1));
    if (!out) return k->busy = 0, PyErr_NoMemory();
    for (int32_t w = 0; w < s->nw; w++) {
        out[4 * w] = s->wr[w];
        out[4 * w + 1] = s->wc[w];
        out[4 * w + 2] = s->tail[w];
        out[4 * w + 3] = last_fixed(s, w);
    }
    PyObject *res = Py_BuildValue("(NN)", bytes_of(out, sizeof(int32_t) * 4 * (size_t)s->nw),
                                  bytes_of(s->occ, sizeof(int32_t) * (size_t)s->rows * s->cols));
    free(out);
    k->busy = 0;
    return res;
}

/* lengths(): per yarn its path length in grid units (a warp's free segment included) */
static PyObject *Kernel_lengths(Kernel *k, PyObject *noargs) {
    (void)noargs;
    if (enter(k)) return NULL;
    const State *s = &k->s;
    double *out = malloc(sizeof(double) * (size_t)(s->ny ? s->ny : 1));
    if (!out) return k->busy = 0, PyErr_NoMemory();
    for (int32_t y = 0; y < s->ny; y++) out[y] = y < s->nw ? path_length(s, y) : s->fixlen[y];
    PyObject *b = bytes_of(out, sizeof(double) * (size_t)s->ny);
    free(out);
    k->busy = 0;
    return b;
}

/* near(lo x, y, z, hi x, y, z): int32 (start, end, yarn) of every segment whose box meets */
static PyObject *Kernel_near(Kernel *k, PyObject *args) {
    long long v[6];
    if (!PyArg_ParseTuple(args, "LLLLLL", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5]) || enter(k))
        return NULL;
    int64_t lo[3] = {v[0], v[1], v[2]}, hi[3] = {v[3], v[4], v[5]};
    int32_t *out = NULL;
    int64_t n = segments_near(&k->s, lo, hi, &out);
    k->busy = 0;
    if (n < 0) return PyErr_NoMemory();
    PyObject *b = bytes_of(out, sizeof(int32_t) * 3 * (size_t)n);
    free(out);
    return b;
}

static PyObject *Kernel_dump(Kernel *k, PyObject *noargs) {
    (void)noargs;
    if (enter(k)) return NULL;
    size_t len = 0;
    unsigned char *buf;
    State *s = &k->s;
    const unsigned char *num = (const unsigned char *)PyBytes_AS_STRING(k->dnum);
    const unsigned char *den = (const unsigned char *)PyBytes_AS_STRING(k->dden);
    size_t ln = (size_t)PyBytes_GET_SIZE(k->dnum), ld = (size_t)PyBytes_GET_SIZE(k->dden);
    Py_BEGIN_ALLOW_THREADS buf = state_dump(s, num, ln, den, ld, &len);
    Py_END_ALLOW_THREADS k->busy = 0;
    if (!buf) return PyErr_NoMemory();
    PyObject *b = bytes_of(buf, len);
    free(buf);
    return b;
}

static PyObject *Kernel_load(PyTypeObject *type, PyObject *args) {
    Py_buffer data;
    if (!PyArg_ParseTuple(args, "y*", &data)) return NULL;
    Kernel *k = (Kernel *)type->tp_alloc(type, 0);
    if (!k) return PyBuffer_Release(&data), NULL;
    const char *why = NULL;
    int err;
    Py_BEGIN_ALLOW_THREADS err = state_load(&k->s, data.buf, (size_t)data.len, &why);
    Py_END_ALLOW_THREADS k->ready = 1;
    if (!err) {
        /* the exact diameter: the last bytes of the dump */
        const unsigned char *end = (const unsigned char *)data.buf + data.len;
        int64_t head[13];
        memcpy(head, data.buf, sizeof head);
        k->dnum = PyBytes_FromStringAndSize((const char *)end - head[10] - head[11], (Py_ssize_t)head[10]);
        k->dden = PyBytes_FromStringAndSize((const char *)end - head[11], (Py_ssize_t)head[11]);
        if (!k->dnum || !k->dden) err = E_NOMEM;
    }
    PyBuffer_Release(&data);
    if (err) {
        Py_DECREF(k);
        if (err == E_NOMEM) return PyErr_NoMemory();
        PyErr_Format(PyExc_ValueError, "not a valid twin snapshot: %s", why ? why : "corrupt");
        return NULL;
    }
    return (PyObject *)k;
}

static PyObject *set_exact_only(PyObject *mod, PyObject *arg) {
    (void)mod;
    int on = PyObject_IsTrue(arg);
    if (on < 0) return NULL;
    exact_only = on;
    Py_RETURN_NONE;
}

static PyMethodDef module_methods[] = {
    {"set_exact_only", set_exact_only, METH_O,
     "Test hook: every float filter defers to the exact computation (same results, slower)."},
    {NULL, NULL, 0, NULL},
};

static PyMethodDef Kernel_methods[] = {
    {"add_warp", (PyCFunction)Kernel_add_warp, METH_VARARGS, "add_warp(row, col, x, y, z)"},
    {"shift", (PyCFunction)Kernel_shift, METH_VARARGS, "shift(axis, moves, instruction, predict)"},
    {"takeup", (PyCFunction)Kernel_takeup, METH_VARARGS, "takeup(gz, instruction, predict)"},
    {"weft", (PyCFunction)Kernel_weft, METH_VARARGS, "weft(x0, y0, z0, x1, y1, z1, predict)"},
    {"replay", (PyCFunction)Kernel_replay, METH_VARARGS, "replay(record)"},
    {"counts", (PyCFunction)Kernel_counts, METH_NOARGS, "(nodes, yarns, warps, contacts, gz)"},
    {"positions", (PyCFunction)Kernel_positions, METH_NOARGS, "int64 coordinates"},
    {"points", (PyCFunction)Kernel_points, METH_VARARGS, "points(ids)"},
    {"chains", (PyCFunction)Kernel_chains, METH_VARARGS, "chains(first, last)"},
    {"contacts", (PyCFunction)Kernel_contacts, METH_NOARGS, "int32 contact records"},
    {"warps", (PyCFunction)Kernel_warps, METH_NOARGS, "warp table and occupancy"},
    {"lengths", (PyCFunction)Kernel_lengths, METH_NOARGS, "path lengths (grid units)"},
    {"near", (PyCFunction)Kernel_near, METH_VARARGS, "segments near a box"},
    {"dump", (PyCFunction)Kernel_dump, METH_NOARGS, "the state as bytes"},
    {"load", (PyCFunction)Kernel_load, METH_VARARGS | METH_CLASS, "a kernel from dump()"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject KernelType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "bwsd.twin._kernel.Kernel",
    .tp_basicsize = sizeof(Kernel),
    .tp_dealloc = (destructor)Kernel_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "The twin's state and its compiled instructions.",
    .tp_methods = Kernel_methods,
    .tp_init = (initproc)Kernel_init,
    .tp_new = PyType_GenericNew,
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_kernel",
                                    "The twin's compiled kernel.", -1, module_methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__kernel(void) {
    if (PyType_Ready(&KernelType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    KernelError = PyErr_NewException("bwsd.twin._kernel.KernelError", PyExc_Exception, NULL);
    Py_INCREF(&KernelType);
    if (!KernelError || PyModule_AddObject(m, "Kernel", (PyObject *)&KernelType) < 0 ||
        PyModule_AddObject(m, "KernelError", KernelError) < 0 ||
        PyModule_AddIntConstant(m, "OP_SIZE", (long)sizeof(Op)) < 0 ||
        PyModule_AddIntConstant(m, "E_LIMIT", E_LIMIT) < 0 ||
        PyModule_AddIntConstant(m, "E_ARITH", E_ARITH) < 0 ||
        PyModule_AddIntConstant(m, "E_CONTACTS", E_CONTACTS) < 0 ||
        PyModule_AddIntConstant(m, "E_MOVE_OUT", E_MOVE_OUT) < 0 ||
        PyModule_AddIntConstant(m, "E_MOVE_BUSY", E_MOVE_BUSY) < 0 ||
        PyModule_AddIntConstant(m, "E_LINE", E_LINE) < 0 ||
        PyModule_AddIntConstant(m, "E_MOVE_SPAN", E_MOVE_SPAN) < 0 ||
        PyModule_AddIntConstant(m, "E_JAM", E_JAM) < 0) {
        Py_XDECREF(m);
        return NULL;
    }
    return m;
}
