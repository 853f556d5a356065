/* The twin's state: arrays, logged mutators, undo and redo, the broad-phase grid. */
#include "state.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define EPS 1.1102230246251565e-16

static int grow(void **p, size_t elem, int64_t need, int64_t *cap) {
    if (need <= *cap) return E_OK;
    int64_t c = *cap ? *cap : 64;
    while (c < need) c *= 2;
    void *q = realloc(*p, (size_t)c * elem);
    if (!q) return E_NOMEM;
    *p = q;
    *cap = c;
    return E_OK;
}

static int grow_nodes(State *s, int32_t need) {
    if (need <= s->cn) return E_OK;
    int64_t c = s->cn ? s->cn : 256;
    while (c < need) c *= 2;
    int64_t *pos = realloc(s->pos, (size_t)c * 3 * sizeof(int64_t));
    if (pos) s->pos = pos;
    int32_t *next = realloc(s->next, (size_t)c * sizeof(int32_t));
    if (next) s->next = next;
    int32_t *prev = realloc(s->prev, (size_t)c * sizeof(int32_t));
    if (prev) s->prev = prev;
    int32_t *ny = realloc(s->nyarn, (size_t)c * sizeof(int32_t));
    if (ny) s->nyarn = ny;
    uint32_t *st = realloc(s->stamp, (size_t)c * sizeof(uint32_t));
    if (st) s->stamp = st;
    if (!pos || !next || !prev || !ny || !st) return E_NOMEM;
    memset(s->stamp + s->cn, 0, (size_t)(c - s->cn) * sizeof(uint32_t));
    s->cn = (int32_t)c;
    return E_OK;
}

static int grow_yarns(State *s, int32_t need) {
    if (need <= s->cy) return E_OK;
    int64_t c = s->cy ? s->cy : 64;
    while (c < need) c *= 2;
    int32_t *h = realloc(s->head, (size_t)c * sizeof(int32_t));
    if (h) s->head = h;
    int32_t *t = realloc(s->tail, (size_t)c * sizeof(int32_t));
    if (t) s->tail = t;
    double *f = realloc(s->fixlen, (size_t)c * sizeof(double));
    if (f) s->fixlen = f;
    if (!h || !t || !f) return E_NOMEM;
    s->cy = (int32_t)c;
    return E_OK;
}

int state_init(State *s, int32_t rows, int32_t cols, const int64_t *gx, const int64_t *gy,
               int64_t gz, int shift) {
    memset(s, 0, sizeof *s);
    s->rows = rows;
    s->cols = cols;
    s->gz = gz;
    s->shift = shift;
    s->gx = malloc(sizeof(int64_t) * (size_t)cols);
    s->gy = malloc(sizeof(int64_t) * (size_t)rows);
    s->occ = malloc(sizeof(int32_t) * (size_t)rows * (size_t)cols);
    if (!s->gx || !s->gy || !s->occ) return E_NOMEM;
    memcpy(s->gx, gx, sizeof(int64_t) * (size_t)cols);
    memcpy(s->gy, gy, sizeof(int64_t) * (size_t)rows);
    for (int64_t i = 0; i < (int64_t)rows * cols; i++) s->occ[i] = -1;
    int64_t cell = (int64_t)1 << shift;
    s->ox = gx[0] - 2 * cell;
    s->oy = gy[0] - 2 * cell;
    s->gnx = (int32_t)(((gx[cols - 1] - s->ox) >> shift) + 3);
    s->gny = (int32_t)(((gy[rows - 1] - s->oy) >> shift) + 3);
    size_t ncell = (size_t)s->gnx * (size_t)s->gny;
    s->cells = calloc(ncell, sizeof(Cell));
    s->fcells = calloc(ncell, sizeof(FCell));
    s->rx0 = malloc(sizeof(int32_t) * (size_t)s->gny);
    s->rx1 = malloc(sizeof(int32_t) * (size_t)s->gny);
    if (!s->cells || !s->fcells || !s->rx0 || !s->rx1) return E_NOMEM;
    return E_OK;
}

void state_free(State *s) {
    size_t ncell = (size_t)s->gnx * (size_t)s->gny;
    if (s->cells)
        for (size_t i = 0; i < ncell; i++) {
            free(s->cells[i].e);
            free(s->cells[i].pmax);
        }
    if (s->fcells)
        for (size_t i = 0; i < ncell; i++) free(s->fcells[i].w);
    void *all[] = {s->gx,    s->gy,     s->pos,    s->next,   s->prev, s->nyarn,
                   s->stamp, s->head,   s->tail,   s->fixlen, s->wr,   s->wc,
                   s->frect, s->fbox,   s->wstamp, s->wmark,  s->occ,  s->contacts,
                   s->cells, s->fcells, s->rx0,    s->rx1,    s->log};
    for (size_t i = 0; i < sizeof all / sizeof all[0]; i++) free(all[i]);
    memset(s, 0, sizeof *s);
}

/* ----- the log ----- */

static int log_op(State *s, int32_t op, int32_t a, int64_t v0, int64_t v1, int64_t v2, int64_t v3,
                  int64_t v4, int64_t v5) {
    if (!s->logging) return E_OK;
    if (grow((void **)&s->log, sizeof(Op), s->nlog + 1, &s->clog)) return E_NOMEM;
    Op *o = &s->log[s->nlog++];
    o->op = op;
    o->a = a;
    o->v[0] = v0;
    o->v[1] = v1;
    o->v[2] = v2;
    o->v[3] = v3;
    o->v[4] = v4;
    o->v[5] = v5;
    return E_OK;
}

static int64_t dbits(double v) {
    int64_t b;
    memcpy(&b, &v, sizeof b);
    return b;
}

static double bitsd(int64_t b) {
    double v;
    memcpy(&v, &b, sizeof v);
    return v;
}

static int node_append(State *s, const int64_t *xyz, int32_t yarn) {
    if (grow_nodes(s, s->nn + 1)) return E_NOMEM;
    int32_t id = s->nn++;
    memcpy(s->pos + 3 * (int64_t)id, xyz, 3 * sizeof(int64_t));
    s->next[id] = s->prev[id] = -1;
    s->nyarn[id] = yarn;
    return E_OK;
}

int node_new(State *s, const int64_t *xyz, int32_t yarn, int32_t *id) {
    for (int k = 0; k < 3; k++)
        if (xyz[k] >= GRID_LIMIT || xyz[k] <= -GRID_LIMIT) return E_LIMIT;
    int32_t n = s->nn;
    if (log_op(s, OP_NODE, n, xyz[0], xyz[1], xyz[2], yarn, 0, 0)) return E_NOMEM;
    if (node_append(s, xyz, yarn)) {
        s->nlog -= s->logging;
        return E_NOMEM;
    }
    *id = n;
    return E_OK;
}

int set_next(State *s, int32_t node, int32_t v) {
    if (log_op(s, OP_NEXT, node, s->next[node], v, 0, 0, 0, 0)) return E_NOMEM;
    s->next[node] = v;
    return E_OK;
}

int set_prev(State *s, int32_t node, int32_t v) {
    if (log_op(s, OP_PREV, node, s->prev[node], v, 0, 0, 0, 0)) return E_NOMEM;
    s->prev[node] = v;
    return E_OK;
}

int set_pos(State *s, int32_t node, const int64_t *xyz) {
    int64_t *p = s->pos + 3 * (int64_t)node;
    if (log_op(s, OP_POS, node, p[0], p[1], p[2], xyz[0], xyz[1], xyz[2])) return E_NOMEM;
    memcpy(p, xyz, 3 * sizeof(int64_t));
    return E_OK;
}

int set_cell(State *s, int32_t w, int32_t r, int32_t c) {
    if (log_op(s, OP_CELL, w, s->wr[w], s->wc[w], r, c, 0, 0)) return E_NOMEM;
    s->wr[w] = r;
    s->wc[w] = c;
    return E_OK;
}

int set_occ(State *s, int32_t idx, int32_t v) {
    if (log_op(s, OP_OCC, idx, s->occ[idx], v, 0, 0, 0, 0)) return E_NOMEM;
    s->occ[idx] = v;
    return E_OK;
}

int contact_add(State *s, const int32_t *rec) {
    if (grow((void **)&s->contacts, 5 * sizeof(int32_t), s->nc + 1, &s->cc)) return E_NOMEM;
    if (log_op(s, OP_CONTACT, 0, rec[0], rec[1], rec[2], rec[3], rec[4], 0)) return E_NOMEM;
    memcpy(s->contacts + 5 * s->nc, rec, 5 * sizeof(int32_t));
    s->nc++;
    return E_OK;
}

static int yarn_append(State *s, int32_t head, int32_t tail) {
    if (grow_yarns(s, s->ny + 1)) return E_NOMEM;
    s->head[s->ny] = head;
    s->tail[s->ny] = tail;
    s->fixlen[s->ny] = 0.0;
    s->ny++;
    return E_OK;
}

int yarn_new(State *s, int32_t head, int32_t tail, int32_t *id) {
    if (log_op(s, OP_YARN, s->ny, head, tail, 0, 0, 0, 0)) return E_NOMEM;
    *id = s->ny;
    return yarn_append(s, head, tail);
}

int set_fixlen(State *s, int32_t y, double v) {
    if (log_op(s, OP_FIXLEN, y, dbits(s->fixlen[y]), dbits(v), 0, 0, 0, 0)) return E_NOMEM;
    s->fixlen[y] = v;
    return E_OK;
}

int set_gz(State *s, int64_t gz) {
    if (log_op(s, OP_GZ, 0, s->gz, gz, 0, 0, 0, 0)) return E_NOMEM;
    s->gz = gz;
    return E_OK;
}

double seg_len(const int64_t *a, const int64_t *b) {
    double dx = (double)(b[0] - a[0]), dy = (double)(b[1] - a[1]), dz = (double)(b[2] - a[2]);
    return sqrt(dx * dx + dy * dy + dz * dz);
}

/* ----- the grid ----- */

static inline int32_t cidx(int64_t v, int64_t o, int shift, int32_t n) {
    int64_t i = (v - o) >> shift;
    return i < 0 ? 0 : (i >= n ? n - 1 : (int32_t)i);
}

static inline int32_t cidx_d(double v, int64_t o, int shift, int32_t n) {
    if (v < -9.0e15) return 0;
    if (v > 9.0e15) return n - 1;
    return cidx((int64_t)v, o, shift, n);
}

static inline float f_down(int64_t q) {
    float f = (float)q;
    return (double)f > (double)q ? nextafterf(f, -INFINITY) : f;
}

static inline float f_up(int64_t q) {
    float f = (float)q;
    return (double)f < (double)q ? nextafterf(f, INFINITY) : f;
}

void qbox_of(QBox *q, const int64_t *const *pts, int n) {
    for (int k = 0; k < 3; k++) {
        int64_t lo = pts[0][k], hi = pts[0][k];
        for (int i = 1; i < n; i++) {
            if (pts[i][k] < lo) lo = pts[i][k];
            if (pts[i][k] > hi) hi = pts[i][k];
        }
        q->lo[k] = lo;
        q->hi[k] = hi;
        q->flo[k] = f_down(lo);
        q->fhi[k] = f_up(hi);
    }
}

/* The cells the (x, y) projection of the convex hull of pts (up to 3 points) may touch:
 * for each cell row iy in [iy0, iy1], columns s->rx0[iy] .. s->rx1[iy]. */
int raster(State *s, const int64_t *const *pts, int n, int32_t *iy0, int32_t *iy1) {
    int64_t ylo = pts[0][1], yhi = pts[0][1];
    for (int i = 1; i < n; i++) {
        if (pts[i][1] < ylo) ylo = pts[i][1];
        if (pts[i][1] > yhi) yhi = pts[i][1];
    }
    *iy0 = cidx(ylo, s->oy, s->shift, s->gny);
    *iy1 = cidx(yhi, s->oy, s->shift, s->gny);
    for (int32_t iy = *iy0; iy <= *iy1; iy++) {
        double lower = iy == 0 ? -INFINITY : (double)(s->oy + ((int64_t)iy << s->shift));
        double upper =
            iy == s->gny - 1 ? INFINITY : (double)(s->oy + ((int64_t)(iy + 1) << s->shift));
        double xmin = INFINITY, xmax = -INFINITY, tol = 0;
        for (int i = 0; i < n; i++) {
            double y = (double)pts[i][1], x = (double)pts[i][0];
            if (y >= lower && y <= upper) {
                if (x < xmin) xmin = x;
                if (x > xmax) xmax = x;
            }
        }
        for (int i = 0; i < n; i++) {
            const int64_t *p = pts[i], *q = pts[(i + 1) % n];
            if (p[1] == q[1]) continue;
            double py = (double)p[1], qy = (double)q[1];
            double lo = py < qy ? py : qy, hi = py < qy ? qy : py;
            double bounds[2] = {lower, upper};
            for (int k = 0; k < 2; k++) {
                double yb = bounds[k];
                if (!(yb > lo && yb < hi)) continue;
                double dx = (double)(q[0] - p[0]);
                double off = (yb - py) * dx / (qy - py);
                double x = (double)p[0] + off;
                double t = 8 * EPS * (fabs((double)p[0]) + fabs(off) + fabs(dx)) + 2;
                if (t > tol) tol = t;
                if (x < xmin) xmin = x;
                if (x > xmax) xmax = x;
            }
        }
        if (xmin > xmax) {
            s->rx0[iy] = 1;
            s->rx1[iy] = 0;
            continue;
        }
        s->rx0[iy] = cidx_d(floor(xmin - tol), s->ox, s->shift, s->gnx);
        s->rx1[iy] = cidx_d(ceil(xmax + tol), s->ox, s->shift, s->gnx);
    }
    return E_OK;
}

uint32_t next_stamp(State *s) {
    if (++s->qstamp == 0) {
        memset(s->stamp, 0, (size_t)s->cn * sizeof(uint32_t));
        if (s->wstamp) memset(s->wstamp, 0, (size_t)s->nw * sizeof(uint32_t));
        s->qstamp = 1;
    }
    return s->qstamp;
}

static int cell_push(Cell *c, const Entry *e) {
    if (c->n == c->cap) {
        int32_t cap = c->cap ? 2 * c->cap : BLOCK;
        Entry *ne = realloc(c->e, sizeof(Entry) * (size_t)cap);
        if (!ne) return E_NOMEM;
        c->e = ne;
        float *np = realloc(c->pmax, sizeof(float) * (size_t)(cap / BLOCK));
        if (!np) return E_NOMEM;
        c->pmax = np;
        c->cap = cap;
    }
    int32_t b = c->n / BLOCK;
    if (c->n % BLOCK == 0)
        c->pmax[b] = b && c->pmax[b - 1] > e->zhi ? c->pmax[b - 1] : e->zhi;
    else if (e->zhi > c->pmax[b])
        c->pmax[b] = e->zhi;
    c->e[c->n++] = *e;
    return E_OK;
}

static void cell_pop(Cell *c) {
    c->n--;
    int32_t b = c->n / BLOCK;
    if (c->n % BLOCK == 0) return;
    float m = b ? c->pmax[b - 1] : -INFINITY;
    for (int32_t i = b * BLOCK; i < c->n; i++)
        if (c->e[i].zhi > m) m = c->e[i].zhi;
    c->pmax[b] = m;
}

static int grid_apply(State *s, int32_t seg, int insert) {
    const int64_t *pts[2] = {P(s, seg), P(s, s->next[seg])};
    QBox q;
    qbox_of(&q, pts, 2);
    Entry e = {seg, q.flo[0], q.flo[1], q.flo[2], q.fhi[0], q.fhi[1], q.fhi[2]};
    int32_t iy0, iy1;
    raster(s, pts, 2, &iy0, &iy1);
    for (int32_t iy = iy0; iy <= iy1; iy++)
        for (int32_t ix = s->rx0[iy]; ix <= s->rx1[iy]; ix++) {
            Cell *c = &s->cells[(int64_t)iy * s->gnx + ix];
            if (insert) {
                if (cell_push(c, &e)) return E_NOMEM;
            } else {
                cell_pop(c);
            }
        }
    return E_OK;
}

int grid_insert(State *s, int32_t seg) {
    if (log_op(s, OP_GRID, seg, 0, 0, 0, 0, 0, 0)) return E_NOMEM;
    return grid_apply(s, seg, 1);
}

static int fcell_add(FCell *c, int32_t w) {
    if (c->n == c->cap) {
        int32_t cap = c->cap ? 2 * c->cap : 4;
        int32_t *nw = realloc(c->w, sizeof(int32_t) * (size_t)cap);
        if (!nw) return E_NOMEM;
        c->w = nw;
        c->cap = cap;
    }
    c->w[c->n++] = w;
    return E_OK;
}

static void fcell_remove(FCell *c, int32_t w) {
    for (int32_t i = 0; i < c->n; i++)
        if (c->w[i] == w) {
            c->w[i] = c->w[--c->n];
            return;
        }
}

/* Register warp w's free segment in the cells of its box (derived state: never logged). */
static int free_register(State *s, int32_t w) {
    int32_t f = s->tail[w];
    const int64_t *pts[2] = {P(s, s->prev[f]), P(s, f)};
    QBox q;
    qbox_of(&q, pts, 2);
    float *box = s->fbox + 6 * (int64_t)w;
    for (int k = 0; k < 3; k++) {
        box[k] = q.flo[k];
        box[3 + k] = q.fhi[k];
    }
    int32_t r[4] = {cidx(q.lo[0], s->ox, s->shift, s->gnx), cidx(q.lo[1], s->oy, s->shift, s->gny),
                    cidx(q.hi[0], s->ox, s->shift, s->gnx), cidx(q.hi[1], s->oy, s->shift, s->gny)};
    int32_t *old = s->frect + 4 * (int64_t)w;
    if (memcmp(r, old, sizeof r) == 0) return E_OK;
    for (int32_t iy = old[1]; iy <= old[3]; iy++)
        for (int32_t ix = old[0]; ix <= old[2]; ix++)
            fcell_remove(&s->fcells[(int64_t)iy * s->gnx + ix], w);
    for (int32_t iy = r[1]; iy <= r[3]; iy++)
        for (int32_t ix = r[0]; ix <= r[2]; ix++)
            if (fcell_add(&s->fcells[(int64_t)iy * s->gnx + ix], w)) return E_NOMEM;
    memcpy(old, r, sizeof r);
    return E_OK;
}

int free_touch(State *s, int32_t w) {
    if (log_op(s, OP_FREE, w, 0, 0, 0, 0, 0, 0)) return E_NOMEM;
    return free_register(s, w);
}

int warp_add(State *s, int32_t r, int32_t c, const int64_t *fell) {
    int32_t w = s->ny, a, b, y;
    int64_t guide[3] = {s->gx[c], s->gy[r], s->gz};
    if (w + 1 > s->cw) {
        int64_t cap = s->cw ? 2 * s->cw : 64;
        int32_t *wr = realloc(s->wr, sizeof(int32_t) * (size_t)cap);
        if (wr) s->wr = wr;
        int32_t *wc = realloc(s->wc, sizeof(int32_t) * (size_t)cap);
        if (wc) s->wc = wc;
        int32_t *fr = realloc(s->frect, 4 * sizeof(int32_t) * (size_t)cap);
        if (fr) s->frect = fr;
        float *fb = realloc(s->fbox, 6 * sizeof(float) * (size_t)cap);
        if (fb) s->fbox = fb;
        uint32_t *ws = realloc(s->wstamp, sizeof(uint32_t) * (size_t)cap);
        if (ws) s->wstamp = ws;
        uint8_t *wm = realloc(s->wmark, (size_t)cap);
        if (wm) s->wmark = wm;
        if (!wr || !wc || !fr || !fb || !ws || !wm) return E_NOMEM;
        s->cw = cap;
    }
    int err = node_new(s, fell, w, &a);
    if (!err) err = node_new(s, guide, w, &b);
    if (!err) err = yarn_new(s, a, b, &y);
    if (err) return err;
    s->next[a] = b;
    s->prev[b] = a;
    s->wr[w] = r;
    s->wc[w] = c;
    s->wstamp[w] = 0;
    s->wmark[w] = 0;
    int32_t *rect = s->frect + 4 * (int64_t)w;
    rect[0] = rect[1] = 1;
    rect[2] = rect[3] = 0;
    s->occ[(int64_t)r * s->cols + c] = w;
    s->nw = w + 1;
    return free_register(s, w);
}

/* ----- undo and redo ----- */

static int reregister(State *s) {
    for (int32_t w = 0; w < s->nw; w++)
        if (s->wmark[w]) {
            s->wmark[w] = 0;
            if (free_register(s, w)) return E_NOMEM;
        }
    return E_OK;
}

void undo_to(State *s, int64_t mark) {
    while (s->nlog > mark) {
        Op *o = &s->log[--s->nlog];
        switch (o->op) {
        case OP_NODE: s->nn--; break;
        case OP_NEXT: s->next[o->a] = (int32_t)o->v[0]; break;
        case OP_PREV: s->prev[o->a] = (int32_t)o->v[0]; break;
        case OP_POS: memcpy(s->pos + 3 * (int64_t)o->a, o->v, 3 * sizeof(int64_t)); break;
        case OP_CELL:
            s->wr[o->a] = (int32_t)o->v[0];
            s->wc[o->a] = (int32_t)o->v[1];
            break;
        case OP_OCC: s->occ[o->a] = (int32_t)o->v[0]; break;
        case OP_CONTACT: s->nc--; break;
        case OP_YARN: s->ny--; break;
        case OP_FIXLEN: s->fixlen[o->a] = bitsd(o->v[0]); break;
        case OP_GRID: grid_apply(s, o->a, 0); break;
        case OP_FREE: s->wmark[o->a] = 1; break;
        case OP_GZ: s->gz = o->v[0]; break;
        }
    }
    reregister(s); /* removing and adding back registrations needs no new memory */
}

int redo(State *s, const Op *ops, int64_t n) {
    int logging = s->logging;
    s->logging = 0;
    int err = E_OK;
    for (int64_t i = 0; i < n && !err; i++) {
        const Op *o = &ops[i];
        switch (o->op) {
        case OP_NODE: {
            int64_t xyz[3] = {o->v[0], o->v[1], o->v[2]};
            err = o->a != s->nn ? E_ARITH : node_append(s, xyz, (int32_t)o->v[3]);
            break;
        }
        case OP_NEXT: s->next[o->a] = (int32_t)o->v[1]; break;
        case OP_PREV: s->prev[o->a] = (int32_t)o->v[1]; break;
        case OP_POS: memcpy(s->pos + 3 * (int64_t)o->a, o->v + 3, 3 * sizeof(int64_t)); break;
        case OP_CELL:
            s->wr[o->a] = (int32_t)o->v[2];
            s->wc[o->a] = (int32_t)o->v[3];
            break;
        case OP_OCC: s->occ[o->a] = (int32_t)o->v[1]; break;
        case OP_CONTACT: {
            int32_t rec[5];
            for (int k = 0; k < 5; k++) rec[k] = (int32_t)o->v[k];
            err = contact_add(s, rec);
            break;
        }
        case OP_YARN: err = yarn_append(s, (int32_t)o->v[0], (int32_t)o->v[1]); break;
        case OP_FIXLEN: s->fixlen[o->a] = bitsd(o->v[1]); break;
        case OP_GRID: err = grid_apply(s, o->a, 1); break;
        case OP_FREE: s->wmark[o->a] = 1; break;
        case OP_GZ: s->gz = o->v[1]; break;
        default: err = E_ARITH;
        }
    }
    s->logging = logging;
    if (!err) err = reregister(s);
    return err;
}
