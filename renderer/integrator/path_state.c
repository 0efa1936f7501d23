/* renderer/integrator/path_state.c: allocation of the per-path state (path_state.h). */
#include "path_state.h"

#include <stdlib.h>
#include <string.h>

int path_state_alloc(PathState *ps, uint32_t n) {
    memset(ps, 0, sizeof *ps);
    ps->capacity = n;
    int fail = 0;
#define PATH_STATE_ALLOC(type, name, prefetch)                  \
    ps->name = calloc(n ? n : 1, sizeof *ps->name);             \
    fail |= ps->name == NULL;
    PATH_STATE_FIELDS(PATH_STATE_ALLOC)
#undef PATH_STATE_ALLOC
    if (fail) { path_state_free(ps); return -1; }
    return 0;
}

void path_state_free(PathState *ps) {
#define PATH_STATE_FREE(type, name, prefetch) free(ps->name);
    PATH_STATE_FIELDS(PATH_STATE_FREE)
#undef PATH_STATE_FREE
    memset(ps, 0, sizeof *ps);
}
