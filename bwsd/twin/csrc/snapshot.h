/* The state to bytes and back: the primary arrays; the grids are rebuilt on load. */
#ifndef BWSD_SNAPSHOT_H
#define BWSD_SNAPSHOT_H

#include <stddef.h>

#include "state.h"

/* A malloc'ed buffer with the state; NULL when out of memory. */
unsigned char *state_dump(const State *s, const unsigned char *dnum, size_t ldnum,
                          const unsigned char *dden, size_t ldden, size_t *len);
/* A state from a dump; returns an error code, and a message for a malformed dump. */
int state_load(State *s, const unsigned char *buf, size_t len, const char **why);

#endif
