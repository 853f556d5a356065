/* bwsd.twin._kernel: the twin's compiled kernel as a Python type (used by bwsd/twin/model.py).
 *
 * Arrays cross as bytes in native byte order; bwsd.twin reads them with numpy. Every method
 * that reads or changes the state does its work in C between KERNEL_BEGIN and KERNEL_END,
 * with the kernel taken: a second caller is refused while one is inside (the Python side
 * serialises its callers with a lock). The instructions (shift, takeup, weft, replay) and
 * dump run with the interpreter lock released; add_warp and the queries, short, keep it:
 * a thread that gives the lock away waits up to a switch interval to take it back while
 * another thread runs Python, and the daemon's event loop reads the twin. Kernel.load reads
 * a dump with the lock released too, into a kernel no other caller can see yet; Kernel(...)
 * builds one under the lock.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <stdlib.h>
#include <string.h>

#include "snapshot.h"
#include "swept.h"

typedef struct {
    PyObject_HEAD
    State s;
    int ready, busy;
    unsigned char *dnum, *dden; /* the diameter's exact numerator and denominator, as given */
    size_t ldnum, ldden;
} Kernel;

static PyObject *KernelError;

/* Refusals of a call, beside the kernel's own codes (exact.h). */
enum {
    E_REFUSED = -1,   /* the kernel was not taken: the exception is set */
    E_BAD_CELL = 100, /* ValueError: add_warp on a cell outside the matrix or filled */
    E_BAD_YARN,       /* IndexError: chains of a yarn out of range */
    E_BAD_NODE,       /* IndexError: points of a node id out of range */
};

/* Takes the kernel for one call: E_OK, or E_REFUSED with the exception set when it is not
 * initialised or another caller is inside. */
static int kernel_take(Kernel *k) {
    if (!k->ready) {
        PyErr_SetString(PyExc_RuntimeError, "the twin kernel is not initialised");
        return E_REFUSED;
    }
    if (k->busy) {
        PyErr_SetString(PyExc_RuntimeError, "the twin kernel is in use by another thread");
        return E_REFUSED;
    }
    k->busy = 1;
    return E_OK;
}

/* Raises err: MemoryError, an argument's refusal, or KernelError(code, details). */
static void raise_error(const Kernel *k, int err) {
    const State *s = &k->s;
    switch (err) {
    case E_NOMEM: PyErr_NoMemory(); return;
    case E_BAD_CELL: PyErr_SetString(PyExc_ValueError, "bad fill cell"); return;
    case E_BAD_YARN: PyErr_SetString(PyExc_IndexError, "yarn out of range"); return;
    case E_BAD_NODE: PyErr_SetString(PyExc_IndexError, "node id out of range"); return;
    default: break;
    }
    PyObject *args = Py_BuildValue("(iLLLL)", err, (long long)s->err[0], (long long)s->err[1],
                                   (long long)s->err[2], (long long)s->err[3]);
    if (args) {
        PyErr_SetObject(KernelError, args);
        Py_DECREF(args);
    }
}

/* Gives the kernel back; err, if set, is raised first (its details are in the state).
 * Returns err. */
static int kernel_give(Kernel *k, int err) {
    if (err) raise_error(k, err);
    k->busy = 0;
    return err;
}

/* The kernel's part of a method, after shapely's GEOS_INIT / GEOS_FINISH and their _THREADS
 * variants (src/geos.h):
 *
 *     int err;
 *     KERNEL_BEGIN(k, err, RELEASE_LOCK)  (or KEEP_LOCK)
 *         ... C only: no Python object or function, no return, no goto out of it ...
 *     KERNEL_END(k, err)
 *     if (err) return NULL;  (the exception is set; free what the C part made)
 *     ... the result from what the C part left in C variables ...
 *
 * KERNEL_BEGIN takes the kernel and, with RELEASE_LOCK, releases the interpreter lock; when
 * the kernel cannot be taken it sets err to E_REFUSED (the exception set) and the C part is
 * skipped. The C part sets err (E_OK when it succeeds); it touches nothing of Python with
 * either mode, so a method may change its mode alone. KERNEL_END takes the interpreter lock
 * back if it was released, raises err if set and gives the kernel back: no path leaves the
 * kernel taken.
 */
enum { KEEP_LOCK, RELEASE_LOCK };

#define KERNEL_BEGIN(k, err, lock)                                                                 \
    if (((err) = kernel_take(k)) == E_OK) {                                                        \
        PyThreadState *kernel_save_ = (lock) == RELEASE_LOCK ? PyEval_SaveThread() : NULL;

#define KERNEL_END(k, err)                                                                         \
    if (kernel_save_) PyEval_RestoreThread(kernel_save_);                                          \
    (err) = kernel_give((k), (err));                                                               \
    }

/* A malloc'ed array made in the C part of a call, to become bytes after it. */
typedef struct {
    void *p;
    size_t n;
} Bytes;

static int bytes_alloc(Bytes *b, size_t n) {
    b->p = malloc(n ? n : 1);
    b->n = n;
    return b->p ? E_OK : E_NOMEM;
}

static int bytes_copy(Bytes *b, const void *p, size_t n) {
    int err = bytes_alloc(b, n);
    if (!err && n) memcpy(b->p, p, n);
    return err;
}

static void bytes_free(Bytes *b, int count) {
    for (int i = 0; i < count; i++) {
        free(b[i].p);
        b[i].p = NULL;
    }
}

/* count arrays as bytes (one bytes object, or a tuple of count) after a call that made them;
 * NULL when err is set or memory runs out. The arrays are freed. */
static PyObject *reply(Bytes *b, int count, int err) {
    PyObject *res = NULL;
    if (!err && count == 1) res = PyBytes_FromStringAndSize(b[0].p, (Py_ssize_t)b[0].n);
    if (!err && count > 1 && (res = PyTuple_New(count)))
        for (int i = 0; i < count; i++) {
            PyObject *o = PyBytes_FromStringAndSize(b[i].p, (Py_ssize_t)b[i].n);
            if (!o) {
                Py_CLEAR(res);
                break;
            }
            PyTuple_SET_ITEM(res, i, o);
        }
    bytes_free(b, count);
    return res;
}

static void Kernel_dealloc(Kernel *k) {
    if (k->ready) state_free(&k->s);
    free(k->dnum);
    free(k->dden);
    Py_TYPE(k)->tp_free((PyObject *)k);
}

/* Keeps the diameter's exact numerator and denominator as given (dumps carry them). */
static int keep_diameter(Kernel *k, const unsigned char *num, size_t ln, const unsigned char *den,
                         size_t ld) {
    free(k->dnum);
    free(k->dden);
    k->dnum = malloc(ln ? ln : 1);
    k->dden = malloc(ld ? ld : 1);
    if (!k->dnum || !k->dden) return E_NOMEM;
    memcpy(k->dnum, num, ln);
    memcpy(k->dden, den, ld);
    k->ldnum = ln;
    k->ldden = ld;
    return E_OK;
}

/* The diameter: f as a float, num / den exactly (little-endian bytes, bwsd/twin/exact.py). */
static int set_diameter(Kernel *k, double f, const unsigned char *num, size_t ln,
                        const unsigned char *den, size_t ld) {
    State *s = &k->s;
    s->d.f = f;
    if (big_from_bytes(&s->d.num, num, (int)ln, 0) || big_from_bytes(&s->d.den, den, (int)ld, 0) ||
        big_sign(&s->d.den) <= 0)
        return E_ARITH;
    s->d.zero = big_sign(&s->d.num) == 0;
    return keep_diameter(k, num, ln, den, ld);
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
    if (!PyArg_ParseTupleAndKeywords(args, kw, "y*y*LidSS", names, &gx, &gy, &gz, &shift, &d, &num,
                                     &den))
        return -1;
    Py_ssize_t cols = gx.len / 8, rows = gy.len / 8;
    int err = E_OK;
    if (cols < 1 || rows < 1 || cols > INT32_MAX || rows > INT32_MAX || shift < 1 || shift > 60 ||
        k->ready) {
        PyErr_SetString(PyExc_ValueError, "bad kernel geometry");
        err = E_REFUSED;
    }
    if (!err) err = state_init(&k->s, (int32_t)rows, (int32_t)cols, gx.buf, gy.buf, gz, shift);
    if (!err)
        err = set_diameter(
            k, d, (const unsigned char *)PyBytes_AS_STRING(num), (size_t)PyBytes_GET_SIZE(num),
            (const unsigned char *)PyBytes_AS_STRING(den), (size_t)PyBytes_GET_SIZE(den));
    PyBuffer_Release(&gx);
    PyBuffer_Release(&gy);
    if (err == E_OK) {
        k->ready = 1;
        return 0;
    }
    if (err != E_REFUSED) { /* not ready: nothing may use or free it again */
        state_free(&k->s);
        if (err == E_NOMEM)
            PyErr_NoMemory();
        else
            PyErr_SetString(PyExc_ValueError, "bad diameter");
    }
    return -1;
}

/* add_warp(row, col, x, y, z): a warp at an empty cell, its fell point; returns its yarn */
static PyObject *Kernel_add_warp(Kernel *k, PyObject *args) {
    int r, c, err;
    long long x, y, z;
    int32_t warp = 0;
    if (!PyArg_ParseTuple(args, "iiLLL", &r, &c, &x, &y, &z)) return NULL;
    int64_t fell[3] = {x, y, z};
    KERNEL_BEGIN(k, err, KEEP_LOCK)
        State *s = &k->s;
        if (r < 0 || r >= s->rows || c < 0 || c >= s->cols ||
            s->occ[(int64_t)r * s->cols + c] >= 0 || s->ny != s->nw)
            err = E_BAD_CELL;
        else
            err = warp_add(s, r, c, fell);
        warp = s->nw - 1;
    KERNEL_END(k, err)
    if (err) return NULL;
    return PyLong_FromLong(warp);
}

static int by_key(const void *a, const void *b) {
    int64_t ka = *(const int64_t *)a, kb = *(const int64_t *)b;
    return ka < kb ? -1 : ka > kb;
}

/* New nodes in yarn order (yarns ascending, each yarn's from its start), so each one's
 * predecessor is old or comes before it. Six int64 per node: id, yarn, predecessor, x, y, z.
 * Each yarn is walked back from its end only as far as its deepest new node. */
static int new_nodes(const State *s, int32_t nn0, Bytes *b) {
    int64_t count = s->nn - nn0;
    int64_t *key = malloc(sizeof(int64_t) * (size_t)(count ? count : 1)); /* yarn, then id */
    int err = bytes_alloc(b, sizeof(int64_t) * 6 * (size_t)count);
    if (!key || err) return free(key), E_NOMEM;
    int64_t *out = b->p;
    for (int32_t n = nn0; n < s->nn; n++) key[n - nn0] = ((int64_t)s->nyarn[n] << 32) | n;
    qsort(key, (size_t)count, sizeof(int64_t), by_key);
    for (int64_t g = 0; g < count;) {
        int32_t y = (int32_t)(key[g] >> 32);
        int64_t end = g;
        while (end < count && (int32_t)(key[end] >> 32) == y) end++;
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
    free(key);
    return E_OK;
}

/* Moved warps: six int64 each (warp, x, y, z, row, col), and their path length changes. */
static int moved(const State *s, const Moved *mv, Bytes *rows, Bytes *change) {
    int err = bytes_alloc(rows, sizeof(int64_t) * 6 * (size_t)mv->n);
    if (!err) err = bytes_alloc(change, sizeof(double) * (size_t)mv->n);
    if (err) return err;
    int64_t *row = rows->p;
    double *ch = change->p;
    for (int32_t i = 0; i < mv->n; i++) {
        int32_t w = mv->warps[i];
        int64_t *o = row + 6 * i;
        o[0] = w;
        memcpy(o + 1, P(s, s->tail[w]), 3 * sizeof(int64_t));
        o[4] = s->wr[w];
        o[5] = s->wc[w];
        ch[i] = path_length(s, w) - mv->before[i];
    }
    return E_OK;
}

typedef struct {
    int32_t nn0, ny0;
    int64_t nc0;
} Mark;

/* What an instruction leaves for its caller when it predicts. */
enum { RECORD, CONTACTS, NODES, MOVED, CHANGES, OCCUPANCY, PARTS };
typedef struct {
    int predict;
    Bytes part[PARTS];
    int32_t ny0, ny;
} Outcome;

static Mark begin(State *s) {
    s->logging = 1;
    s->nlog = 0;
    return (Mark){s->nn, s->ny, s->nc};
}

static int describe(const State *s, Mark mk, const Moved *mv, Outcome *out) {
    Bytes *p = out->part;
    int err = bytes_copy(&p[RECORD], s->log, sizeof(Op) * (size_t)s->nlog);
    if (!err)
        err = bytes_copy(&p[CONTACTS], s->contacts + 5 * mk.nc0,
                         sizeof(int32_t) * 5 * (size_t)(s->nc - mk.nc0));
    if (!err) err = new_nodes(s, mk.nn0, &p[NODES]);
    if (!err) err = moved(s, mv, &p[MOVED], &p[CHANGES]);
    size_t cells = (size_t)s->rows * (size_t)s->cols;
    if (!err) err = bytes_copy(&p[OCCUPANCY], s->occ, sizeof(int32_t) * cells);
    out->ny0 = mk.ny0;
    out->ny = s->ny;
    return err;
}

/* After an instruction (err its result): roll it back on an error, keep it, or describe it
 * in out and roll it back. Returns the error, if any. */
static int conclude(State *s, int err, Mark mk, Moved *mv, Outcome *out) {
    if (!err && out->predict) err = describe(s, mk, mv, out);
    if (err || out->predict) undo_to(s, 0);
    s->nlog = 0;
    s->logging = 0;
    free(mv->warps);
    free(mv->before);
    return err;
}

/* The instruction's result: None when kept, else (record, contacts, new nodes, (moved,
 * length changes), occupancy, first new yarn, yarns); NULL when err is set. */
static PyObject *outcome(Outcome *out, int err) {
    if (err || !out->predict) {
        bytes_free(out->part, PARTS);
        if (err) return NULL;
        Py_RETURN_NONE;
    }
    PyObject *moves = reply(out->part + MOVED, 2, E_OK);
    Bytes *p = out->part;
    PyObject *parts[4] = {reply(&p[RECORD], 1, E_OK), reply(&p[CONTACTS], 1, E_OK),
                          reply(&p[NODES], 1, E_OK), reply(&p[OCCUPANCY], 1, E_OK)};
    if (moves && parts[0] && parts[1] && parts[2] && parts[3])
        return Py_BuildValue("(NNNNNii)", parts[0], parts[1], parts[2], moves, parts[3], out->ny0,
                             out->ny);
    Py_XDECREF(moves);
    for (int i = 0; i < 4; i++) Py_XDECREF(parts[i]);
    return NULL;
}

/* shift(axis, moves, instruction, predict): axis 0 row, 1 col; moves int32 (line, k, lo, hi)
 * quads (cells lo..hi of the line move; 0..last for the whole line).
 * predict: return (record, contacts, new nodes, (moved, length changes), occupancy, first new
 * yarn, yarns) and leave the state as it was; otherwise keep the result and return None. */
static PyObject *Kernel_shift(Kernel *k, PyObject *args) {
    int axis, instr, err;
    Py_buffer moves;
    Outcome out = {0};
    if (!PyArg_ParseTuple(args, "iy*ip", &axis, &moves, &instr, &out.predict)) return NULL;
    KERNEL_BEGIN(k, err, RELEASE_LOCK)
        State *s = &k->s;
        Mark mk = begin(s);
        Moved mv = {NULL, NULL, 0};
        Bytes m; /* the moves, aligned */
        err = bytes_copy(&m, moves.buf, (size_t)moves.len);
        if (!err) err = run_shift(s, axis, m.p, (int32_t)(moves.len / 16), instr, &mv);
        free(m.p);
        err = conclude(s, err, mk, &mv, &out);
    KERNEL_END(k, err)
    PyBuffer_Release(&moves);
    return outcome(&out, err);
}

/* takeup(gz, instruction, predict): every free node sweeps to its guide at the new z */
static PyObject *Kernel_takeup(Kernel *k, PyObject *args) {
    long long gz;
    int instr, err;
    Outcome out = {0};
    if (!PyArg_ParseTuple(args, "Lip", &gz, &instr, &out.predict)) return NULL;
    KERNEL_BEGIN(k, err, RELEASE_LOCK)
        State *s = &k->s;
        Mark mk = begin(s);
        Moved mv = {NULL, NULL, 0};
        err = run_takeup(s, gz, instr, &mv);
        err = conclude(s, err, mk, &mv, &out);
    KERNEL_END(k, err)
    return outcome(&out, err);
}

/* weft(x0, y0, z0, x1, y1, z1, predict): a two-node yarn (the shed is checked by the caller) */
static PyObject *Kernel_weft(Kernel *k, PyObject *args) {
    long long a, b, c, d, e, f;
    int err;
    Outcome out = {0};
    if (!PyArg_ParseTuple(args, "LLLLLLp", &a, &b, &c, &d, &e, &f, &out.predict)) return NULL;
    int64_t p0[3] = {a, b, c}, p1[3] = {d, e, f};
    KERNEL_BEGIN(k, err, RELEASE_LOCK)
        State *s = &k->s;
        Mark mk = begin(s);
        Moved mv = {NULL, NULL, 0};
        err = run_weft(s, p0, p1);
        err = conclude(s, err, mk, &mv, &out);
    KERNEL_END(k, err)
    return outcome(&out, err);
}

/* replay(log): apply a prediction's record to the state it was made on */
static PyObject *Kernel_replay(Kernel *k, PyObject *args) {
    Py_buffer log;
    int err;
    if (!PyArg_ParseTuple(args, "y*", &log)) return NULL;
    KERNEL_BEGIN(k, err, RELEASE_LOCK)
        err = redo(&k->s, log.buf, log.len / (Py_ssize_t)sizeof(Op));
    KERNEL_END(k, err)
    PyBuffer_Release(&log);
    if (err) return NULL;
    Py_RETURN_NONE;
}

/* counts(): (nodes, yarns, warps, contacts, guides' z) */
static PyObject *Kernel_counts(Kernel *k, PyObject *noargs) {
    (void)noargs;
    int32_t nn = 0, ny = 0, nw = 0;
    int64_t nc = 0, gz = 0;
    int err;
    KERNEL_BEGIN(k, err, KEEP_LOCK)
        nn = k->s.nn;
        ny = k->s.ny;
        nw = k->s.nw;
        nc = k->s.nc;
        gz = k->s.gz;
    KERNEL_END(k, err)
    if (err) return NULL;
    return Py_BuildValue("(iiiLL)", nn, ny, nw, (long long)nc, (long long)gz);
}

/* positions(): int64 x, y, z of every node */
static PyObject *Kernel_positions(Kernel *k, PyObject *noargs) {
    (void)noargs;
    Bytes b = {0};
    int err;
    KERNEL_BEGIN(k, err, KEEP_LOCK)
        err = bytes_copy(&b, k->s.pos, sizeof(int64_t) * 3 * (size_t)k->s.nn);
    KERNEL_END(k, err)
    return reply(&b, 1, err);
}

static int points(const State *s, const int32_t *id, Py_ssize_t n, Bytes *b) {
    int err = bytes_alloc(b, sizeof(int64_t) * 3 * (size_t)n);
    int64_t *out = b->p;
    for (Py_ssize_t i = 0; i < n && !err; i++) {
        if (id[i] < 0 || id[i] >= s->nn)
            err = E_BAD_NODE;
        else
            memcpy(out + 3 * i, P(s, id[i]), 3 * sizeof(int64_t));
    }
    return err;
}

/* points(ids): int64 x, y, z of the given node ids (int32 bytes) */
static PyObject *Kernel_points(Kernel *k, PyObject *args) {
    Py_buffer ids;
    Bytes b = {0};
    int err;
    if (!PyArg_ParseTuple(args, "y*", &ids)) return NULL;
    KERNEL_BEGIN(k, err, KEEP_LOCK)
        err = points(&k->s, ids.buf, ids.len / 4, &b);
    KERNEL_END(k, err)
    PyBuffer_Release(&ids);
    return reply(&b, 1, err);
}

static int chains(const State *s, int first, int last, Bytes *ids, Bytes *start) {
    if (first < 0 || last > s->ny || first > last) return E_BAD_YARN;
    int err = bytes_alloc(ids, sizeof(int32_t) * (size_t)s->nn);
    if (!err) err = bytes_alloc(start, sizeof(int64_t) * (size_t)(last - first + 1));
    if (err) return err;
    int32_t *id = ids->p;
    int64_t *st = start->p, at = 0;
    for (int32_t y = first; y < last; y++) {
        st[y - first] = at;
        for (int32_t n = s->head[y]; n != -1; n = s->next[n]) id[at++] = n;
    }
    st[last - first] = at;
    ids->n = sizeof(int32_t) * (size_t)at;
    return E_OK;
}

/* chains(first, last): node ids of yarns first .. last - 1 in order (int32), and each yarn's
 * start in that list (int64, one more than the yarns) */
static PyObject *Kernel_chains(Kernel *k, PyObject *args) {
    int first, last, err;
    Bytes b[2] = {{0}};
    if (!PyArg_ParseTuple(args, "ii", &first, &last)) return NULL;
    KERNEL_BEGIN(k, err, KEEP_LOCK)
        err = chains(&k->s, first, last, &b[0], &b[1]);
    KERNEL_END(k, err)
    return reply(b, 2, err);
}

/* contacts(): int32 (instruction, moving yarn, X, hit yarn, Y) per contact */
static PyObject *Kernel_contacts(Kernel *k, PyObject *noargs) {
    (void)noargs;
    Bytes b = {0};
    int err;
    KERNEL_BEGIN(k, err, KEEP_LOCK)
        err = bytes_copy(&b, k->s.contacts, sizeof(int32_t) * 5 * (size_t)k->s.nc);
    KERNEL_END(k, err)
    return reply(&b, 1, err);
}

static int warps(const State *s, Bytes *table, Bytes *occ) {
    int err = bytes_alloc(table, sizeof(int32_t) * 4 * (size_t)s->nw);
    if (!err) err = bytes_copy(occ, s->occ, sizeof(int32_t) * (size_t)s->rows * (size_t)s->cols);
    if (err) return err;
    int32_t *out = table->p;
    for (int32_t w = 0; w < s->nw; w++) {
        out[4 * w] = s->wr[w];
        out[4 * w + 1] = s->wc[w];
        out[4 * w + 2] = s->tail[w];
        out[4 * w + 3] = last_fixed(s, w);
    }
    return E_OK;
}

/* warps(): int32 (row, col, free node, last fixed node) per warp, and the occupancy */
static PyObject *Kernel_warps(Kernel *k, PyObject *noargs) {
    (void)noargs;
    Bytes b[2] = {{0}};
    int err;
    KERNEL_BEGIN(k, err, KEEP_LOCK)
        err = warps(&k->s, &b[0], &b[1]);
    KERNEL_END(k, err)
    return reply(b, 2, err);
}

static int lengths(const State *s, Bytes *b) {
    int err = bytes_alloc(b, sizeof(double) * (size_t)s->ny);
    double *out = b->p;
    for (int32_t y = 0; y < s->ny && !err; y++)
        out[y] = y < s->nw ? path_length(s, y) : s->fixlen[y];
    return err;
}

/* lengths(): per yarn its path length in grid units (a warp's free segment included) */
static PyObject *Kernel_lengths(Kernel *k, PyObject *noargs) {
    (void)noargs;
    Bytes b = {0};
    int err;
    KERNEL_BEGIN(k, err, KEEP_LOCK)
        err = lengths(&k->s, &b);
    KERNEL_END(k, err)
    return reply(&b, 1, err);
}

/* near(lo x, y, z, hi x, y, z): int32 (start, end, yarn) of every segment whose box meets */
static PyObject *Kernel_near(Kernel *k, PyObject *args) {
    long long v[6];
    Bytes b = {0};
    int err;
    if (!PyArg_ParseTuple(args, "LLLLLL", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5])) return NULL;
    int64_t lo[3] = {v[0], v[1], v[2]}, hi[3] = {v[3], v[4], v[5]};
    KERNEL_BEGIN(k, err, KEEP_LOCK)
        int32_t *out = NULL;
        int64_t n = segments_near(&k->s, lo, hi, &out);
        err = n < 0 ? E_NOMEM : E_OK;
        b = (Bytes){out, sizeof(int32_t) * 3 * (size_t)(n < 0 ? 0 : n)};
    KERNEL_END(k, err)
    return reply(&b, 1, err);
}

/* dump(): the state as bytes (Kernel.load reads them) */
static PyObject *Kernel_dump(Kernel *k, PyObject *noargs) {
    (void)noargs;
    Bytes b = {0};
    int err;
    KERNEL_BEGIN(k, err, RELEASE_LOCK)
        b.p = state_dump(&k->s, k->dnum, k->ldnum, k->dden, k->ldden, &b.n);
        err = b.p ? E_OK : E_NOMEM;
    KERNEL_END(k, err)
    return reply(&b, 1, err);
}

/* The state of a dump; the diameter's bytes end it. */
static int load(Kernel *k, const unsigned char *data, size_t len, const char **why) {
    int err = state_load(&k->s, data, len, why);
    if (err) return err;
    int64_t head[13];
    memcpy(head, data, sizeof head);
    size_t ln = (size_t)head[10], ld = (size_t)head[11]; /* checked by state_load */
    const unsigned char *end = data + len;
    return keep_diameter(k, end - ld - ln, ln, end - ld, ld);
}

/* Kernel.load(data): a kernel from dump() */
static PyObject *Kernel_load(PyTypeObject *type, PyObject *args) {
    Py_buffer data;
    if (!PyArg_ParseTuple(args, "y*", &data)) return NULL;
    Kernel *k = (Kernel *)type->tp_alloc(type, 0);
    if (!k) return PyBuffer_Release(&data), NULL;
    const char *why = NULL;
    int err;
    Py_BEGIN_ALLOW_THREADS
        err = load(k, data.buf, (size_t)data.len, &why);
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&data);
    if (!err) {
        k->ready = 1;
        return (PyObject *)k;
    }
    state_free(&k->s); /* not ready: the kernel's dealloc leaves the state alone */
    Py_DECREF(k);
    if (err == E_NOMEM) return PyErr_NoMemory();
    PyErr_Format(PyExc_ValueError, "not a valid twin snapshot: %s", why ? why : "corrupt");
    return NULL;
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
    .ob_base = PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "bwsd.twin._kernel.Kernel",
    .tp_basicsize = sizeof(Kernel),
    .tp_dealloc = (destructor)Kernel_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "The twin's state and its compiled instructions.",
    .tp_methods = Kernel_methods,
    .tp_init = (initproc)Kernel_init,
    .tp_new = PyType_GenericNew,
};

static struct PyModuleDef module = {
    .m_base = PyModuleDef_HEAD_INIT,
    .m_name = "_kernel",
    .m_doc = "The twin's compiled kernel.",
    .m_size = -1,
    .m_methods = module_methods,
};

PyMODINIT_FUNC PyInit__kernel(void) {
    if (PyType_Ready(&KernelType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    KernelError = PyErr_NewException("bwsd.twin._kernel.KernelError", PyExc_Exception, NULL);
    if (!KernelError || PyModule_AddObjectRef(m, "Kernel", (PyObject *)&KernelType) < 0 ||
        PyModule_AddObjectRef(m, "KernelError", KernelError) < 0 ||
        PyModule_AddIntConstant(m, "OP_SIZE", (long)sizeof(Op)) < 0 ||
        PyModule_AddIntConstant(m, "E_LIMIT", E_LIMIT) < 0 ||
        PyModule_AddIntConstant(m, "E_ARITH", E_ARITH) < 0 ||
        PyModule_AddIntConstant(m, "E_CONTACTS", E_CONTACTS) < 0 ||
        PyModule_AddIntConstant(m, "E_MOVE_OUT", E_MOVE_OUT) < 0 ||
        PyModule_AddIntConstant(m, "E_MOVE_BUSY", E_MOVE_BUSY) < 0 ||
        PyModule_AddIntConstant(m, "E_LINE", E_LINE) < 0 ||
        PyModule_AddIntConstant(m, "E_MOVE_SPAN", E_MOVE_SPAN) < 0 ||
        PyModule_AddIntConstant(m, "E_JAM", E_JAM) < 0) {
        Py_CLEAR(KernelError);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
