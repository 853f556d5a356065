/* Instructions on the state: the sweep of a free node (the triangle its segment sweeps, hence
 * the file's name; the design sweeps of bwsd/sweep are another thing), shifts, take-up, weft
 * insertion. */
#ifndef BWSD_SWEPT_H
#define BWSD_SWEPT_H

#include "state.h"

#define MAX_CONTACTS_PER_SWEEP 100000

/* The warps an instruction moved, in the order of their first move, with their path length
 * (grid units) before it. */
typedef struct {
    int32_t *warps;
    double *before;
    int32_t n;
} Moved;

int run_shift(State *s, int axis, const int32_t *moves, int32_t nmoves, int32_t instr, Moved *mv);
int run_takeup(State *s, int64_t gz, int32_t instr, Moved *mv);
int run_weft(State *s, const int64_t *p0, const int64_t *p1);
double path_length(const State *s, int32_t w);
/* Every segment (start node, end node, yarn) whose box meets the closed box [lo, hi]:
 * fixed segments and warps' free segments. Returns the count; *out is malloc'ed. */
int64_t segments_near(State *s, const int64_t *lo, const int64_t *hi, int32_t **out);

#endif
