/* Instructions on the state (docs/twin.md, "The sweep, exactly").
 *
 * A sweep step finds, among the candidates of the broad phase, the contact with the smallest
 * exact sweep time (ties: smaller yarn id, then the segment nearer that yarn's start), then
 * builds Y, X and the restart point on the grid. Candidate order never matters: the choice is
 * a total order decided exactly.
 */
#include "swept.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define EPS 1.1102230246251565e-16

typedef struct {
    int32_t seg, end, yarn;
    int64_t c[3], d[3];
    Sgn sc, sd, w1, w2; /* sides of C and D; w1 = orient(C, D, A2, B), w2 = orient(C, D, B, A1) */
    double tlo, thi;    /* the sweep time t = |w2| / (|w1| + |w2|) lies in [tlo, thi] */
} Hit;

typedef struct {
    State *s;
    int32_t w, skip0, skip1;
    const int64_t *b, *a1, *a2;
    int64_t e1[3], e2[3]; /* a1 - b, a2 - b */
    Plane pl;
    QBox box;
    Hit best;
    int found, err;
} Search;

typedef struct {
    Plane *pl;
    const int64_t *b, *a1, *a2, *c, *d;
} Exact;

static int exact_cd(const void *v, big *a, big *b) {
    const Exact *x = v;
    return plane_big(x->pl, x->c, a) || plane_big(x->pl, x->d, b);
}

static int exact_t(const void *v, big *a, big *b) {
    const Exact *x = v;
    return orient_big(x->c, x->d, x->b, x->a1, a) || orient_big(x->c, x->d, x->a2, x->b, b);
}

/* a is nearer its yarn's start than b (two segments of one yarn) */
static int seg_before(const State *s, int32_t a, int32_t b) {
    for (int32_t n = s->next[a]; n != -1; n = s->next[n])
        if (n == b) return 1;
    return 0;
}

static int earlier(Search *q, const Hit *h, const Hit *g, int *out) {
    if (h->thi < g->tlo) return *out = 1, E_OK;
    if (h->tlo > g->thi) return *out = 0, E_OK;
    big hw2, hw1, gw2, gw1;
    Exact eh = {NULL, q->b, q->a1, q->a2, h->c, h->d}, eg = {NULL, q->b, q->a1, q->a2, g->c, g->d};
    int cmp;
    if (exact_t(&eh, &hw2, &hw1) || exact_t(&eg, &gw2, &gw1)) return E_ARITH;
    if (ratio_cmp_exact(&hw2, &hw1, &gw2, &gw1, &cmp)) return E_ARITH;
    if (cmp) return *out = cmp < 0, E_OK;
    if (h->yarn != g->yarn) return *out = h->yarn < g->yarn, E_OK;
    *out = seg_before(q->s, h->seg, g->seg);
    return E_OK;
}

static void time_bounds(Hit *h) {
    if (h->w1.s == 0) {
        h->tlo = h->thi = 1.0;
    } else if (h->w1.filtered && h->w2.filtered) {
        double a = fabs(h->w2.v), b = fabs(h->w1.v);
        double lo = (a - h->w2.e) / ((a - h->w2.e) + (b + h->w1.e));
        double hi = (a + h->w2.e) / ((a + h->w2.e) + (b - h->w1.e));
        h->tlo = lo * (1 - 8 * EPS);
        h->thi = hi * (1 + 8 * EPS);
    } else {
        h->tlo = 0.0;
        h->thi = 1.0;
    }
}

static void try_segment(Search *q, int32_t seg, int32_t end, int32_t yarn) {
    const State *s = q->s;
    const int64_t *C = P(s, seg), *D = P(s, end);
    Hit h;
    plane_side(&q->pl, C, &h.sc);
    plane_side(&q->pl, D, &h.sd);
    if ((h.sc.s >= 0) == (h.sd.s >= 0)) return;
    /* with B as origin and C' = C - B: w2 = -A1'.(a x C'), w1 = A2'.(a x C'), a = D - C */
    int64_t a[3] = {D[0] - C[0], D[1] - C[1], D[2] - C[2]};
    int64_t c[3] = {C[0] - q->b[0], C[1] - q->b[1], C[2] - q->b[2]};
    Cross x;
    cross_init(&x, a, c);
    cross_side(&x, q->e1, &h.w2);
    h.w2.v = -h.w2.v;
    h.w2.s = -h.w2.s;
    if (h.w2.s == 0) return;
    cross_side(&x, q->e2, &h.w1);
    if (h.w1.s != 0 && h.w1.s != h.w2.s) return;
    Sgn wb;
    orient_sgn(C, D, q->a1, q->a2, &wb);
    if (wb.s != h.w2.s) return;
    h.seg = seg;
    h.end = end;
    h.yarn = yarn;
    memcpy(h.c, C, sizeof h.c);
    memcpy(h.d, D, sizeof h.d);
    time_bounds(&h);
    int better = 1;
    if (q->found && (q->err = earlier(q, &h, &q->best, &better))) return;
    if (better) {
        q->best = h;
        q->found = 1;
    }
}

static inline int box_meets(const float *lo, const float *hi, const QBox *b) {
    return hi[0] >= b->flo[0] && lo[0] <= b->fhi[0] && hi[1] >= b->flo[1] && lo[1] <= b->fhi[1] &&
           hi[2] >= b->flo[2] && lo[2] <= b->fhi[2];
}

static void scan_cell(Search *q, int64_t ci, uint32_t st) {
    State *s = q->s;
    const Cell *c = &s->cells[ci];
    float zlo = q->box.flo[2];
    for (int32_t b = (c->n - 1) / BLOCK; c->n && b >= 0 && !q->err; b--) {
        if (c->pmax[b] < zlo) break;
        int32_t end = c->n < (b + 1) * BLOCK ? c->n : (b + 1) * BLOCK;
        for (int32_t i = b * BLOCK; i < end; i++) {
            const Entry *e = &c->e[i];
            if (!box_meets(&e->xlo, &e->xhi, &q->box)) continue;
            int32_t seg = e->seg;
            if (s->stamp[seg] == st) continue;
            s->stamp[seg] = st;
            if (s->nyarn[seg] == q->w || seg == q->skip0 || seg == q->skip1) continue;
            try_segment(q, seg, s->next[seg], s->nyarn[seg]);
        }
    }
    const FCell *f = &s->fcells[ci];
    for (int32_t i = 0; i < f->n && !q->err; i++) {
        int32_t j = f->w[i];
        if (s->wstamp[j] == st) continue;
        s->wstamp[j] = st;
        int32_t seg = last_fixed(s, j);
        if (j == q->w || seg == q->skip0 || seg == q->skip1) continue;
        const float *box = s->fbox + 6 * (int64_t)j;
        if (box_meets(box, box + 3, &q->box)) try_segment(q, seg, s->tail[j], j);
    }
}

/* The first contact of the triangle (b, a1, a2) for warp w; q->found says if there is one. */
static void search(Search *q) {
    State *s = q->s;
    plane_init(&q->pl, q->b, q->a1, q->a2);
    if (q->pl.flat) return; /* every point lies on the plane: nothing crosses it */
    for (int k = 0; k < 3; k++) {
        q->e1[k] = q->a1[k] - q->b[k];
        q->e2[k] = q->a2[k] - q->b[k];
    }
    const int64_t *pts[3] = {q->b, q->a1, q->a2};
    qbox_of(&q->box, pts, 3);
    int32_t iy0, iy1;
    raster(s, pts, 3, &iy0, &iy1);
    uint32_t st = next_stamp(s);
    for (int32_t iy = iy0; iy <= iy1 && !q->err; iy++)
        for (int32_t ix = s->rx0[iy]; ix <= s->rx1[iy] && !q->err; ix++)
            scan_cell(q, (int64_t)iy * s->gnx + ix, st);
}

static int add_len(State *s, int32_t y, double delta) {
    return set_fixlen(s, y, s->fixlen[y] + delta);
}

/* Insert Y into the hit segment and X before w's free node, record the contact. */
static int make_contact(State *s, int32_t w, const Hit *h, const int64_t *b, const int64_t *y,
                        const int64_t *x, int32_t instr) {
    int32_t yn, xn, bn = last_fixed(s, w), f = s->tail[w], hy = h->yarn;
    int err = node_new(s, y, hy, &yn);
    if (!err) err = set_next(s, h->seg, yn);
    if (!err) err = set_prev(s, yn, h->seg);
    if (!err) err = set_next(s, yn, h->end);
    if (!err) err = set_prev(s, h->end, yn);
    if (err) return err;
    double lc = seg_len(h->c, y), ld = seg_len(y, h->d);
    if (hy < s->nw && h->end == s->tail[hy]) { /* a free segment: its lower part is fixed now */
        err = grid_insert(s, h->seg);
        if (!err) err = add_len(s, hy, lc);
        if (!err) err = free_touch(s, hy);
    } else {
        err = grid_insert(s, yn);
        if (!err) err = add_len(s, hy, (lc + ld) - seg_len(h->c, h->d));
    }
    if (!err) err = node_new(s, x, w, &xn);
    if (!err) err = set_next(s, bn, xn);
    if (!err) err = set_prev(s, xn, bn);
    if (!err) err = set_next(s, xn, f);
    if (!err) err = set_prev(s, f, xn);
    if (!err) err = grid_insert(s, bn);
    if (!err) err = add_len(s, w, seg_len(b, x));
    int32_t rec[5] = {instr, w, xn, hy, yn};
    if (!err) err = contact_add(s, rec);
    return err;
}

/* A contact whose node Y or X lies within one diameter of the guide plane, or above it, is
 * a jam (docs/twin.md): the yarns would lock at the guides. err: moving yarn, hit yarn, the
 * higher node's z, the guides' z. */
static int jam_check(State *s, int32_t w, int32_t hit, const int64_t *y, const int64_t *x) {
    int64_t z = y[2] > x[2] ? y[2] : x[2];
    int jam = 0, err = within_diameter(s->gz - z, &s->d, &jam);
    if (err || !jam) return err;
    s->err[0] = w;
    s->err[1] = hit;
    s->err[2] = z;
    s->err[3] = s->gz;
    return E_JAM;
}

/* Move warp w's free node to target, inserting a node pair at every contact on the way. */
static int sweep(State *s, int32_t w, const int64_t *target, int32_t instr) {
    int64_t a1[3], a2[3], b[3], y[3], x[3], r[3], m[3], u[3];
    memcpy(a1, P(s, s->tail[w]), sizeof a1);
    memcpy(a2, target, sizeof a2);
    int32_t skip0 = -1, skip1 = -1;
    for (int iter = 0; iter <= MAX_CONTACTS_PER_SWEEP; iter++) {
        memcpy(b, P(s, last_fixed(s, w)), sizeof b);
        Search q = {.s = s, .w = w, .skip0 = skip0, .skip1 = skip1, .b = b, .a1 = a1, .a2 = a2};
        search(&q);
        if (q.err) return q.err;
        if (!q.found) {
            int err = set_pos(s, s->tail[w], a2);
            return err ? err : free_touch(s, w);
        }
        const Hit *h = &q.best;
        Exact ex = {&q.pl, b, a1, a2, h->c, h->d};
        int err = lerp_round(h->c, h->d, &h->sc, &h->sd, exact_cd, &ex, y);
        for (int k = 0; k < 3; k++) {
            m[k] = a2[k] - a1[k];
            u[k] = h->d[k] - h->c[k];
        }
        if (!err) err = rest_round(y, m, u, &s->d, x);
        if (!err) err = jam_check(s, w, h->yarn, y, x);
        if (!err) err = lerp_round(a1, a2, &h->w2, &h->w1, exact_t, &ex, r);
        if (!err) err = make_contact(s, w, h, b, y, x, instr);
        if (err) return err;
        skip0 = h->seg;
        skip1 = s->nn - 2; /* Y */
        memcpy(a1, r, sizeof a1);
    }
    s->err[0] = w;
    return E_CONTACTS;
}

double path_length(const State *s, int32_t w) {
    return s->fixlen[w] + seg_len(P(s, last_fixed(s, w)), P(s, s->tail[w]));
}

static void note_moved(const State *s, Moved *mv, uint8_t *seen, int32_t w) {
    if (seen[w]) return;
    seen[w] = 1;
    mv->warps[mv->n] = w;
    mv->before[mv->n++] = path_length(s, w);
}

/* Plan every case's move in execution order (logged), refusing before anything sweeps.
 * moves: (line, k, lo, hi) quads; only the cases on cells lo..hi of the line move, and each
 * must stay on them (lo = 0, hi = the last cell for a whole line). */
static int plan_shift(State *s, int axis, const int32_t *moves, int32_t nmoves, int32_t *plan,
                      int64_t *np) {
    int32_t limit = axis == 0 ? s->rows : s->cols, along = axis == 0 ? s->cols : s->rows;
    *np = 0;
    for (int32_t e = 0; e < nmoves; e++) {
        int32_t line = moves[4 * e], k = moves[4 * e + 1], lo = moves[4 * e + 2],
                hi = moves[4 * e + 3];
        if (line < 0 || line >= limit || lo < 0 || hi >= along || lo > hi) {
            s->err[0] = e;
            s->err[1] = line;
            return E_LINE;
        }
        for (int32_t i = lo; i <= hi; i++) {
            int32_t pos = k > 0 ? hi + lo - i : i; /* the leading case first */
            int32_t r = axis == 0 ? line : pos, c = axis == 0 ? pos : line;
            int32_t w = s->occ[(int64_t)r * s->cols + c];
            if (w < 0) continue;
            int32_t tr = axis == 0 ? r : r + k, tc = axis == 0 ? c + k : c;
            int32_t to = axis == 0 ? tc : tr;
            s->err[0] = w;
            s->err[1] = tr;
            s->err[2] = tc;
            if (tr < 0 || tr >= s->rows || tc < 0 || tc >= s->cols) return E_MOVE_OUT;
            if (to < lo || to > hi) {
                s->err[3] = e;
                return E_MOVE_SPAN;
            }
            int32_t other = s->occ[(int64_t)tr * s->cols + tc];
            if (other >= 0) {
                s->err[3] = other;
                return E_MOVE_BUSY;
            }
            int err = set_occ(s, r * s->cols + c, -1);
            if (!err) err = set_occ(s, tr * s->cols + tc, w);
            if (!err) err = set_cell(s, w, tr, tc);
            if (err) return err;
            plan[3 * *np] = w;
            plan[3 * *np + 1] = tr;
            plan[3 * (*np)++ + 2] = tc;
        }
    }
    return E_OK;
}

int run_shift(State *s, int axis, const int32_t *moves, int32_t nmoves, int32_t instr, Moved *mv) {
    int64_t cap = (int64_t)nmoves * (axis == 0 ? s->cols : s->rows), np = 0; /* at most */
    int32_t *plan = malloc(sizeof(int32_t) * 3 * (size_t)(cap ? cap : 1));
    uint8_t *seen = calloc((size_t)s->nw + 1, 1);
    mv->warps = malloc(sizeof(int32_t) * (size_t)(s->nw + 1));
    mv->before = malloc(sizeof(double) * (size_t)(s->nw + 1));
    mv->n = 0;
    int err = !plan || !seen || !mv->warps || !mv->before ? E_NOMEM : E_OK;
    if (!err) err = plan_shift(s, axis, moves, nmoves, plan, &np);
    for (int64_t i = 0; i < np && !err; i++) note_moved(s, mv, seen, plan[3 * i]);
    for (int64_t i = 0; i < np && !err; i++) {
        int64_t target[3] = {s->gx[plan[3 * i + 2]], s->gy[plan[3 * i + 1]], s->gz};
        err = sweep(s, plan[3 * i], target, instr);
    }
    free(plan);
    free(seen);
    return err;
}

int run_takeup(State *s, int64_t gz, int32_t instr, Moved *mv) {
    mv->warps = malloc(sizeof(int32_t) * (size_t)(s->nw + 1));
    mv->before = malloc(sizeof(double) * (size_t)(s->nw + 1));
    mv->n = 0;
    if (!mv->warps || !mv->before) return E_NOMEM;
    for (int32_t w = 0; w < s->nw; w++) {
        mv->warps[mv->n] = w;
        mv->before[mv->n++] = path_length(s, w);
    }
    int err = set_gz(s, gz);
    for (int32_t w = 0; w < s->nw && !err; w++) {
        int64_t target[3] = {s->gx[s->wc[w]], s->gy[s->wr[w]], gz};
        err = sweep(s, w, target, instr);
    }
    return err;
}

int run_weft(State *s, const int64_t *p0, const int64_t *p1) {
    int32_t a, b, y, yarn = s->ny;
    int err = node_new(s, p0, yarn, &a);
    if (!err) err = node_new(s, p1, yarn, &b);
    if (!err) err = yarn_new(s, a, b, &y);
    if (!err) err = set_next(s, a, b);
    if (!err) err = set_prev(s, b, a);
    if (!err) err = set_fixlen(s, y, seg_len(p0, p1));
    if (!err) err = grid_insert(s, a);
    return err;
}

int64_t segments_near(State *s, const int64_t *lo, const int64_t *hi, int32_t **out) {
    const int64_t *pts[2] = {lo, hi};
    QBox q;
    qbox_of(&q, pts, 2);
    int64_t n = 0, cap = 64;
    int32_t *res = malloc(sizeof(int32_t) * 3 * (size_t)cap);
    if (!res) return -1;
    uint32_t st = next_stamp(s);
    int32_t iy0, iy1;
    int64_t corners[4][3] = {
        {lo[0], lo[1], 0}, {hi[0], lo[1], 0}, {hi[0], hi[1], 0}, {lo[0], hi[1], 0}};
    const int64_t *quad[4] = {corners[0], corners[1], corners[2], corners[3]};
    raster(s, quad, 4, &iy0, &iy1);
    for (int32_t iy = iy0; iy <= iy1; iy++)
        for (int32_t ix = s->rx0[iy]; ix <= s->rx1[iy]; ix++) {
            int64_t ci = (int64_t)iy * s->gnx + ix;
            const Cell *c = &s->cells[ci];
            const FCell *f = &s->fcells[ci];
            for (int32_t i = 0; i < c->n + f->n; i++) {
                int32_t seg, end, yarn;
                const float *blo, *bhi;
                if (i < c->n) {
                    seg = c->e[i].seg;
                    if (s->stamp[seg] == st) continue;
                    s->stamp[seg] = st;
                    end = s->next[seg];
                    yarn = s->nyarn[seg];
                    blo = &c->e[i].xlo;
                    bhi = &c->e[i].xhi;
                } else {
                    yarn = f->w[i - c->n];
                    if (s->wstamp[yarn] == st) continue;
                    s->wstamp[yarn] = st;
                    seg = last_fixed(s, yarn);
                    end = s->tail[yarn];
                    blo = s->fbox + 6 * (int64_t)yarn;
                    bhi = blo + 3;
                }
                if (!box_meets(blo, bhi, &q)) continue;
                if (n == cap) {
                    cap *= 2;
                    int32_t *nr = realloc(res, sizeof(int32_t) * 3 * (size_t)cap);
                    if (!nr) return free(res), -1;
                    res = nr;
                }
                res[3 * n] = seg;
                res[3 * n + 1] = end;
                res[3 * n++ + 2] = yarn;
            }
        }
    *out = res;
    return n;
}
