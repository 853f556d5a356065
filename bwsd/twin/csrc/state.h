/* The twin's state in flat arrays, its change log, and the persistent spatial grid.
 *
 * Nodes carry grid coordinates and links (a yarn is a doubly linked list of node ids, so a
 * contact inserts a node in O(1)). A segment is named by its first node. Every change goes
 * through a logged mutator: a prediction runs in place, copies its log (its redo record) and
 * rolls back; a commit replays that record; nothing is recomputed.
 *
 * Broad phase: the (x, y) plane is cut into square cells of 2^shift grid units. Every fixed
 * segment gets an entry (its id and its box in floats rounded outwards) in each cell its
 * (x, y) projection crosses, appended in creation order; each cell keeps, per block of
 * entries, the highest top among the block and every older one, so a query that starts
 * above that height skips the block and everything older. Warps' free segments, which
 * change at every move, are registered in the cells of their box.
 */
#ifndef BWSD_STATE_H
#define BWSD_STATE_H

#include <stdint.h>

#include "exact.h"

#define BLOCK 8

typedef struct {
    int32_t seg;
    float xlo, ylo, zlo, xhi, yhi, zhi;
} Entry;

typedef struct {
    Entry *e;
    float *pmax; /* per block: max zhi over this block and every older one */
    int32_t n, cap;
} Cell;

typedef struct {
    int32_t *w;
    int32_t n, cap;
} FCell;

enum {
    OP_NODE = 1,
    OP_NEXT,
    OP_PREV,
    OP_POS,
    OP_CELL,
    OP_OCC,
    OP_CONTACT,
    OP_YARN,
    OP_FIXLEN,
    OP_GRID,
    OP_FREE,
    OP_GZ
};

typedef struct {
    int32_t op, a;
    int64_t v[6];
} Op;

typedef struct {
    int32_t rows, cols;
    int64_t *gx, *gy; /* guide x per column, y per row */
    int64_t gz;       /* guide z now: round(d_mat + T) */
    Diam d;
    /* nodes */
    int32_t nn, cn;
    int64_t *pos;
    int32_t *next, *prev, *nyarn;
    uint32_t *stamp;
    /* yarns (warps first) */
    int32_t ny, cy;
    int32_t *head, *tail;
    double *fixlen; /* length of the fixed polyline, grid units */
    int32_t nw;
    int64_t cw; /* capacity of the per-warp arrays */
    int32_t *wr, *wc;
    int32_t *frect; /* 4 per warp: the cells its free segment is registered in */
    float *fbox;    /* 6 per warp: the free segment's box, rounded outwards */
    uint32_t *wstamp;
    uint8_t *wmark;
    int32_t *occ;
    /* contacts: instruction, moving yarn, X, hit yarn, Y */
    int64_t nc, cc;
    int32_t *contacts;
    /* grid */
    int shift;
    int64_t ox, oy;
    int32_t gnx, gny;
    Cell *cells;
    FCell *fcells;
    uint32_t qstamp;
    int32_t *rx0, *rx1; /* scratch: per cell row, the x range of a raster */
    /* log */
    int logging;
    Op *log;
    int64_t nlog, clog;
    /* details of the last error */
    int64_t err[4];
} State;

int state_init(State *s, int32_t rows, int32_t cols, const int64_t *gx, const int64_t *gy,
               int64_t gz, int shift);
void state_free(State *s);

/* logged mutators */
int node_new(State *s, const int64_t *xyz, int32_t yarn, int32_t *id);
int set_next(State *s, int32_t node, int32_t v);
int set_prev(State *s, int32_t node, int32_t v);
int set_pos(State *s, int32_t node, const int64_t *xyz);
int set_cell(State *s, int32_t w, int32_t r, int32_t c);
int set_occ(State *s, int32_t idx, int32_t v);
int contact_add(State *s, const int32_t *rec);
int yarn_new(State *s, int32_t head, int32_t tail, int32_t *id);
int set_fixlen(State *s, int32_t y, double v);
int grid_insert(State *s, int32_t seg);
int free_touch(State *s, int32_t w);
int set_gz(State *s, int64_t gz);
int warp_add(State *s, int32_t r, int32_t c, const int64_t *fell);

void undo_to(State *s, int64_t mark);
int redo(State *s, const Op *ops, int64_t n);

/* queries */
typedef struct {
    int64_t lo[3], hi[3];
    float flo[3], fhi[3];
} QBox;
void qbox_of(QBox *q, const int64_t *const *pts, int n);
int raster(State *s, const int64_t *const *pts, int n, int32_t *iy0, int32_t *iy1);
uint32_t next_stamp(State *s);
double seg_len(const int64_t *a, const int64_t *b);

static inline const int64_t *P(const State *s, int32_t node) { return s->pos + 3 * (int64_t)node; }
static inline int32_t last_fixed(const State *s, int32_t w) { return s->prev[s->tail[w]]; }

#endif
