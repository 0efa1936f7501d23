/* cachepoints/build_internal.h (private): what the steps of the cache point build share.
 * build.c runs the steps in order (§3.1): merge.c (spatial sort, the two merge passes),
 * far_linear.c or far_cut.c (a point's near list and far bins), blur.c (the far-bin blur),
 * then flattens the result into the CachePoints arrays of internal.h; sort.c holds the
 * deterministic sorts and selections they use. Nothing here is used at render time. */
#ifndef CANDELA_CACHEPOINTS_BUILD_INTERNAL_H
#define CANDELA_CACHEPOINTS_BUILD_INTERNAL_H

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include "internal.h"

static inline float cp_dist2(const float *a, const float *b) {
    float dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return dx * dx + dy * dy + dz * dz;
}

/* Grows *a (elem bytes each) to hold at least `need` elements, doubling from 64. */
static inline int cp_grow(void **a, uint32_t *cap, uint32_t need, size_t elem) {
    if (need <= *cap) return 0;
    uint32_t nc = *cap ? *cap : 64;
    while (nc < need) nc *= 2;
    void *n = realloc(*a, (size_t)nc * elem);
    if (!n) return -1;
    *a = n;
    *cap = nc;
    return 0;
}

/* ---------------------------------------------------------------- sort.c */

/* A value and an id under the total order (value desc, id asc): ties by light id or list
 * position keep every result deterministic. */
typedef struct ValueIndex { float v; uint32_t id; } ValueIndex;

/* Ascending heap sort (in place, no allocation). */
void cp_sort_u64(uint64_t *a, size_t n);
/* Sorts (key << 32 | index) pairs by key with tmp[n] as scratch: LSD radix over the key's
 * bytes, skipping bytes every key shares. O(n) for the few hundred entries of a cut. */
void cp_sort_by_key(uint64_t *a, uint64_t *tmp, uint32_t n);
/* Moves the first k elements of the (value desc, id asc) order to the front of a[0, n). */
void cp_select_top(ValueIndex *a, uint32_t n, uint32_t k);
/* Moves the first m elements of that order to the front, m the smallest count whose sum
 * reaches target (n if none does); returns m. */
uint32_t cp_select_energy_prefix(ValueIndex *a, uint32_t n, double target);

/* ---------------------------------------------------------------- distributions */

typedef struct Dist {        /* per point, during the build */
    uint32_t near_count;
    uint32_t *near_key;      /* sorted */
    uint32_t *near_light;
    float *near_fluence;     /* fluence of each near light at x (for merge pass 2's similarity) */
    uint32_t far_count;
    FarEntry *far;           /* sorted by key */
} Dist;

/* build.c */
void cp_dist_free(Dist *d);
int cp_dist_alloc_near(Dist *d, uint32_t count);

/* The omni distribution of a point: near fluence plus the far fluence bin, normalised, as
 * (key, probability) sorted by key: what merge pass 2 compares (§3.1.4 leaves the
 * distribution open; the fluence one is orientation-free, so it suits surface and volume
 * points alike). */
typedef struct OmniDist { uint32_t count; uint32_t *key; float *p; } OmniDist;

/* merge.c: reduces a point's distribution to its omni distribution. */
int cp_omni_build(const Dist *d, OmniDist *o);

/* What a distribution builder sees. With omni != NULL each point's distribution is reduced
 * at once to its omni distribution (all merge pass 2 needs), so the build's memory stays
 * proportional to the final points; the full seven bins are computed afterwards for the
 * survivors only. */
typedef struct DistCtx {
    const float *pts;
    /* the r_p of Eq. 1: the final radius for the survivors; before merge pass 2 (§3.1.4)
     * defines it, its initial guess r0 (the mean kNN distance) */
    const float *near_radius;
    const CachePointLights *lights;
    const CachePointParams *params;
    const CachePoints *keys;   /* key space (cut build) */
    Dist *dist;
    OmniDist *omni;
    int failed;
} DistCtx;

/* A way to build point i's near list (Eq. 1) and far bins (§3.1.3) into c->dist[i], with
 * per-thread scratch. With c->omni set, only what the omni distribution needs. */
typedef struct DistBuilder {
    void *(*scratch_new)(const DistCtx *c);
    void (*scratch_free)(void *scratch);
    int (*point)(const DistCtx *c, void *scratch, size_t i); /* 0 ok, -1 out of memory */
} DistBuilder;

extern const DistBuilder cp_far_linear; /* far_linear.c: every light at every point (the paper) */
extern const DistBuilder cp_far_cut;    /* far_cut.c: a cut through the light tree */

/* build.c: the distributions of points [0, n) with the builder the params choose. */
int cp_build_distributions(const DistCtx *proto, uint32_t n);

/* far_linear.c: the §3.1.3 bin rule on the n nonzero entries of one bin (their sum: total):
 * keeps the shortest prefix of the (value desc, id asc) order holding energy_fraction of
 * the total, its length clamped to [min(min_per_bin, n), max_per_bin]; moves it to the
 * front and returns its length. */
uint32_t cp_bin_keep(const CachePointParams *P, ValueIndex *vi, uint32_t n, double total);

/* ---------------------------------------------------------------- merge.c (§3.1.1-§3.1.4) */

/* The diagonal of the points' bounding box (1 if degenerate). */
float cp_scene_scale(const float *pts, uint32_t n);
/* Merge pass 1 (§3.1.2) over pts[0, n), compacted in place; *survivors receives the count. */
int cp_merge_pass1(const CachePointParams *P, const CachePointCamera *camera, float *pts, uint32_t n,
                   uint32_t *survivors);
/* Merge pass 2 (§3.1.4) over pts[0, n): omni distributions (dist[0, n) is scratch, left
 * empty), Eqs. 2-3, the radii r_p, then the merge; pts and radius are compacted in place.
 * probes (may be NULL): receives the deleted points in index order (malloc'd, *num_probes). */
int cp_merge_pass2(const CachePoints *keys, const CachePointLights *L, const CachePointCamera *camera,
                   const CachePointParams *P, float *pts, uint32_t n, float scene_scale, Dist *dist, float *radius,
                   uint32_t *survivors, float **probes, uint32_t *num_probes);

/* ---------------------------------------------------------------- build.c, shared with progressive.c */

/* The key space of the cut build (keys = light-tree nodes, then infinite lights). 0 ok, -1
 * out of memory, -2 a malformed tree. */
int cp_key_space_init(CachePoints *cp, const CachePointLights *L);
/* From cp->pos, cp->radius and cp->n (the final points): their distributions (§3.1.3; those
 * of points [0, cp->num_raw) moved out of cp->raw), the kd-tree, the far blur (§3.1.5), the
 * flat arrays with W' = 1, the render tables; keep_raw: every point's own distribution is
 * kept in cp->raw. 0 ok, -1 out of memory (cp->raw is then consumed or freed). */
int cp_build_points(CachePoints *cp, const CachePointLights *L, int keep_raw);
void cp_raw_free(CachePoints *cp);
/* Frees the per-point arrays cp_build_points made (build.c), not the key space. */
void cp_points_free(CachePoints *cp);

/* ---------------------------------------------------------------- blur.c (§3.1.5) */

/* Blurs the final points' far lists (dist) into blurred[0, cp->n), out of place, and fills
 * cp->nbr, nbr_w and self_w (the Eq. 4 weights, reused by the visibility blur of §3.2.2).
 * Needs cp->pos, cp->kd and the key space. 0 ok, -1 out of memory. */
int cp_blur_far(CachePoints *cp, const Dist *dist, Dist *blurred);

#endif
