/* The state to bytes and back (see snapshot.h). Layout, all little-endian as in memory:
 * a header of int64 fields, then the arrays in the order written by state_dump. */
#include "snapshot.h"

#include <stdlib.h>
#include <string.h>

#define MAGIC 0x314b535742LL /* "BWSK1" */
#define NHEAD 13

typedef struct {
    unsigned char *p;
    size_t at, len;
} Buf;

static void put(Buf *b, const void *src, size_t n) {
    if (b->p) memcpy(b->p + b->at, src, n);
    b->at += n;
}

static void dump_into(Buf *b, const State *s, const unsigned char *dnum, size_t ldnum,
                      const unsigned char *dden, size_t ldden) {
    double df = s->d.f;
    int64_t dbits;
    memcpy(&dbits, &df, sizeof dbits);
    int64_t head[NHEAD] = {MAGIC, s->rows, s->cols, s->shift,       s->gz,          s->nn,    s->ny,
                           s->nw, s->nc,   dbits,   (int64_t)ldnum, (int64_t)ldden, s->d.zero};
    put(b, head, sizeof head);
    put(b, s->gx, sizeof(int64_t) * (size_t)s->cols);
    put(b, s->gy, sizeof(int64_t) * (size_t)s->rows);
    put(b, s->pos, sizeof(int64_t) * 3 * (size_t)s->nn);
    put(b, s->next, sizeof(int32_t) * (size_t)s->nn);
    put(b, s->prev, sizeof(int32_t) * (size_t)s->nn);
    put(b, s->nyarn, sizeof(int32_t) * (size_t)s->nn);
    put(b, s->head, sizeof(int32_t) * (size_t)s->ny);
    put(b, s->tail, sizeof(int32_t) * (size_t)s->ny);
    put(b, s->fixlen, sizeof(double) * (size_t)s->ny);
    put(b, s->wr, sizeof(int32_t) * (size_t)s->nw);
    put(b, s->wc, sizeof(int32_t) * (size_t)s->nw);
    put(b, s->occ, sizeof(int32_t) * (size_t)s->rows * (size_t)s->cols);
    put(b, s->contacts, sizeof(int32_t) * 5 * (size_t)s->nc);
    put(b, dnum, ldnum);
    put(b, dden, ldden);
}

unsigned char *state_dump(const State *s, const unsigned char *dnum, size_t ldnum,
                          const unsigned char *dden, size_t ldden, size_t *len) {
    Buf b = {NULL, 0, 0};
    dump_into(&b, s, dnum, ldnum, dden, ldden);
    b.p = malloc(b.at ? b.at : 1);
    if (!b.p) return NULL;
    *len = b.at;
    b.at = 0;
    dump_into(&b, s, dnum, ldnum, dden, ldden);
    return b.p;
}

static int take(Buf *b, void *dst, size_t n) {
    if (b->len - b->at < n) return -1;
    if (n) memcpy(dst, b->p + b->at, n);
    b->at += n;
    return 0;
}

/* Every yarn a chain from head to tail, every node in exactly one, links consistent. */
static const char *check_links(const State *s) {
    int64_t seen = 0;
    for (int32_t y = 0; y < s->ny; y++) {
        int32_t n = s->head[y], last = -1;
        if (s->head[y] < 0 || s->head[y] >= s->nn || s->tail[y] < 0 || s->tail[y] >= s->nn)
            return "a yarn's end is not a node";
        while (n != -1) {
            if (n < 0 || n >= s->nn || s->nyarn[n] != y || s->prev[n] != last || ++seen > s->nn)
                return "the node links are inconsistent";
            last = n;
            n = s->next[n];
        }
        if (last != s->tail[y]) return "a yarn does not end at its tail";
        if (y < s->nw && s->prev[last] < 0) return "a warp has no fixed node";
    }
    return seen == s->nn ? NULL : "a node belongs to no yarn";
}

static const char *check(const State *s) {
    for (int64_t i = 0; i < 3 * (int64_t)s->nn; i++)
        if (s->pos[i] >= GRID_LIMIT || s->pos[i] <= -GRID_LIMIT) return "a coordinate is too large";
    const char *why = check_links(s);
    if (why) return why;
    for (int32_t w = 0; w < s->nw; w++) {
        if (s->wr[w] < 0 || s->wr[w] >= s->rows || s->wc[w] < 0 || s->wc[w] >= s->cols)
            return "a warp's cell is outside the matrix";
        if (s->occ[(int64_t)s->wr[w] * s->cols + s->wc[w]] != w) return "occupancy disagrees";
    }
    for (int64_t i = 0; i < (int64_t)s->rows * s->cols; i++)
        if (s->occ[i] < -1 || s->occ[i] >= s->nw) return "occupancy names no warp";
    for (int64_t i = 0; i < s->nc; i++) {
        const int32_t *c = s->contacts + 5 * i;
        if (c[1] < 0 || c[1] >= s->nw || c[3] < 0 || c[3] >= s->ny || c[2] < 0 || c[2] >= s->nn ||
            c[4] < 0 || c[4] >= s->nn)
            return "a contact names no yarn or node";
    }
    return NULL;
}

static int rebuild(State *s) {
    for (int32_t n = 0; n < s->nn; n++) {
        int32_t m = s->next[n];
        if (m < 0) continue;
        int32_t y = s->nyarn[m];
        if (y < s->nw && s->tail[y] == m) continue; /* a free segment */
        if (grid_insert(s, n)) return E_NOMEM;
    }
    for (int32_t w = 0; w < s->nw; w++)
        if (free_touch(s, w)) return E_NOMEM;
    return E_OK;
}

static int alloc_arrays(State *s, int64_t nn, int64_t ny, int64_t nw, int64_t nc) {
    size_t n = (size_t)(nn ? nn : 1), y = (size_t)(ny ? ny : 1), w = (size_t)(nw ? nw : 1);
    s->pos = malloc(sizeof(int64_t) * 3 * n);
    s->next = malloc(sizeof(int32_t) * n);
    s->prev = malloc(sizeof(int32_t) * n);
    s->nyarn = malloc(sizeof(int32_t) * n);
    s->stamp = calloc(n, sizeof(uint32_t));
    s->head = malloc(sizeof(int32_t) * y);
    s->tail = malloc(sizeof(int32_t) * y);
    s->fixlen = malloc(sizeof(double) * y);
    s->wr = malloc(sizeof(int32_t) * w);
    s->wc = malloc(sizeof(int32_t) * w);
    s->frect = malloc(sizeof(int32_t) * 4 * w);
    s->fbox = malloc(sizeof(float) * 6 * w);
    s->wstamp = calloc(w, sizeof(uint32_t));
    s->wmark = calloc(w, 1);
    s->contacts = malloc(sizeof(int32_t) * 5 * (size_t)(nc ? nc : 1));
    s->cn = (int32_t)n;
    s->cy = (int32_t)y;
    s->cw = (int64_t)w;
    s->cc = nc ? nc : 1;
    if (!s->pos || !s->next || !s->prev || !s->nyarn || !s->stamp || !s->head || !s->tail ||
        !s->fixlen || !s->wr || !s->wc || !s->frect || !s->fbox || !s->wstamp || !s->wmark ||
        !s->contacts)
        return E_NOMEM;
    for (size_t i = 0; i < w; i++) {
        s->frect[4 * i] = s->frect[4 * i + 1] = 1;
        s->frect[4 * i + 2] = s->frect[4 * i + 3] = 0;
    }
    return E_OK;
}

int state_load(State *s, const unsigned char *buf, size_t len, const char **why) {
    Buf b = {(unsigned char *)buf, 0, len};
    int64_t h[NHEAD];
    *why = "truncated";
    memset(s, 0, sizeof *s);
    if (take(&b, h, sizeof h)) return E_ARITH;
    *why = "not a twin snapshot";
    if (h[0] != MAGIC) return E_ARITH;
    int64_t rows = h[1], cols = h[2], nn = h[5], ny = h[6], nw = h[7], nc = h[8];
    *why = "bad sizes";
    if (rows < 1 || cols < 1 || rows * cols > ((int64_t)1 << 31) || h[3] < 1 || h[3] > 60 ||
        nn < 0 || nn >= INT32_MAX || ny < 0 || ny > nn || nw < 0 || nw > ny || nc < 0 ||
        nc >= INT32_MAX || h[10] < 0 || h[10] > 8 * BIG_LIMBS || h[11] < 1 || h[11] > 8 * BIG_LIMBS)
        return E_ARITH;
    size_t need = sizeof(int64_t) * (size_t)(rows + cols + 3 * nn) +
                  sizeof(int32_t) * (size_t)(3 * nn + 2 * ny + 2 * nw + rows * cols + 5 * nc) +
                  sizeof(double) * (size_t)ny + (size_t)(h[10] + h[11]);
    *why = "truncated";
    if (len - b.at != need) return E_ARITH;
    int64_t *gx = malloc(sizeof(int64_t) * (size_t)cols),
            *gy = malloc(sizeof(int64_t) * (size_t)rows);
    if (!gx || !gy) return free(gx), free(gy), E_NOMEM;
    take(&b, gx, sizeof(int64_t) * (size_t)cols);
    take(&b, gy, sizeof(int64_t) * (size_t)rows);
    int err = E_OK;
    *why = "the guides are not in order";
    for (int64_t i = 1; i < cols; i++) err |= gx[i] <= gx[i - 1];
    for (int64_t i = 1; i < rows; i++) err |= gy[i] <= gy[i - 1];
    if (err) return free(gx), free(gy), E_ARITH;
    err = state_init(s, (int32_t)rows, (int32_t)cols, gx, gy, h[4], (int)h[3]);
    free(gx);
    free(gy);
    if (err || (err = alloc_arrays(s, nn, ny, nw, nc))) return err;
    s->nn = (int32_t)nn;
    s->ny = (int32_t)ny;
    s->nw = (int32_t)nw;
    s->nc = nc;
    take(&b, s->pos, sizeof(int64_t) * 3 * (size_t)nn);
    take(&b, s->next, sizeof(int32_t) * (size_t)nn);
    take(&b, s->prev, sizeof(int32_t) * (size_t)nn);
    take(&b, s->nyarn, sizeof(int32_t) * (size_t)nn);
    take(&b, s->head, sizeof(int32_t) * (size_t)ny);
    take(&b, s->tail, sizeof(int32_t) * (size_t)ny);
    take(&b, s->fixlen, sizeof(double) * (size_t)ny);
    take(&b, s->wr, sizeof(int32_t) * (size_t)nw);
    take(&b, s->wc, sizeof(int32_t) * (size_t)nw);
    take(&b, s->occ, sizeof(int32_t) * (size_t)(rows * cols));
    take(&b, s->contacts, sizeof(int32_t) * 5 * (size_t)nc);
    memcpy(&s->d.f, &h[9], sizeof(double));
    s->d.zero = h[12] != 0;
    big_from_bytes(&s->d.num, b.p + b.at, (int)h[10], 0);
    big_from_bytes(&s->d.den, b.p + b.at + h[10], (int)h[11], 0);
    *why = check(s);
    if (*why) return E_ARITH;
    *why = NULL;
    return rebuild(s);
}
