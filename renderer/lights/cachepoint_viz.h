/* renderer/lights/cachepoint_viz.h (private): cache point visualisation: the false colours of
 * `--aov cachepoint` and the PLY file of `--dump-cachepoints`. */
#ifndef CANDELA_CACHEPOINT_VIZ_H
#define CANDELA_CACHEPOINT_VIZ_H

#include <stdint.h>

#include "cachepoints.h"
#include "candela.h"
#include "vecmath.h"

/* Salts of the two palettes, so point k and light k get unrelated colours. */
#define CACHEPOINT_COLOUR_POINT 0x9e3779b9u
#define CACHEPOINT_COLOUR_LIGHT 0x85ebca6bu
#define CACHEPOINT_COLOUR_CLUSTER 0xc2b2ae35u

/* A bright false colour of id (a hash, every channel a multiple of 1/255 in [40/255, 1], so
 * the 8-bit PNG and the PLY's colour hold it exactly and no colour is near black). */
vec3 cachepoint_false_colour(uint32_t id, uint32_t salt);

/* Writes every point as an ASCII PLY vertex (see README "Cache point dump"; cp NULL: none):
 * through a temporary name, renamed when complete. 0 ok; -1 with a one-line message in err. */
int cachepoint_write_ply(const CachePoints *cp, const char *path, char err[CANDELA_ERR_LEN]);

#endif
