/* cachepoints/internal.h (private): the CachePoints structure shared by the build (build.c
 * and its steps, build_internal.h) and the render-time side (lookup.c: visibility learning
 * and selection).
 *
 * Entries are addressed by *keys*. With the linear build (the paper's) a key is a light
 * index. With the cut build a key is a node of the scene's light tree (a depth-first binary
 * tree, so the lights below node k are exactly the leaves with keys in [k, key_end[k])), and
 * infinite lights, which are not in the tree, get the keys node_count, node_count + 1, ...
 * A far entry whose key is not a leaf is a *cluster*: selecting it descends the light tree
 * below the node. Every list is sorted by key, so "the entry holding light l" is one binary
 * search for the last key <= key_of(l) followed by a range check. */
#ifndef CANDELA_CACHEPOINTS_INTERNAL_H
#define CANDELA_CACHEPOINTS_INTERNAL_H

#include <stdint.h>

#include "cachepoints.h"
#include "kdtree.h"

#define CP_MIN_POINTS 10 /* §3.1.1: fewer, and the caller selects per vertex instead */
#define CP_FAR_BINS 7
#define CP_OMNI_BIN 6
#define CP_NONE UINT32_MAX

#define CP_BIN_STRIDE 8 /* 7 bins padded to 32 bytes */

/* H_total and H_success of a slot (§3.2.1, Eq. 5), adjacent: cachepoints_record adds the
 * attempt and its success with one touch of one cache line, once the shadow ray's outcome
 * is known. total counts attempts. success sums their visibility (the fraction of the
 * shadow ray that got through: 0 or 1 on surfaces) in fixed point, CP_VIS_ONE per fully
 * visible attempt: integer atomics add in any order to the same sum, so learning does not
 * depend on the thread count, and 0/1 outcomes give exactly the integer counts of Eq. 5.
 * Overflow: success <= CP_VIS_ONE x total; at each barrier a slot whose total exceeds
 * CP_VIS_RESCALE has both halved (total rounded up, success down, so the invariant holds),
 * which keeps R and bounds success by 2^31 + CP_VIS_ONE x the records of one iteration: no
 * overflow while a slot gets fewer than 2^23 records between two barriers. */
typedef struct VisCounter {
    uint32_t total, success;
} VisCounter;

#define CP_VIS_ONE 256u           /* a fully visible attempt in success: 8 fractional bits */
#define CP_VIS_RESCALE (1u << 23) /* a total above this is halved at the barrier */

typedef struct FarEntry {
    uint32_t key;
    float value[CP_FAR_BINS]; /* irradiance on +X -X +Y -Y +Z -Z, fluence (unoccluded) */
} FarEntry;

struct CachePoints {
    uint32_t n;
    float *pos;                /* 3n */
    float *radius;             /* n: r_p (§3.1.4) */
    /* key space (see above); light_key == NULL means key == light (linear build) */
    uint32_t num_lights, num_keys;
    uint32_t *light_key;       /* cut: per light, its key (CP_NONE: in no entry, only the floor) */
    uint32_t *key_end;         /* cut: per key, one past the last key of its subtree */
    uint32_t *key_light;       /* cut: per key, its light (CP_NONE for a cluster) */
    /* near lists (§3.1.3): keys sorted; the light and visibility slot of each entry */
    uint32_t *near_off, *near_key, *near_light, *near_slot;
    float *near_vis;           /* W' of each near entry (rebuilt at each barrier) */
    /* far lists after the blur (§3.1.5), sorted by key, disjoint from the near list */
    uint32_t *far_off;
    FarEntry *far;
    uint32_t *far_slot;        /* visibility slot of each far entry */
    /* running sums of value x W' per point and bin (bin-major inside a point's block, so the
     * binary search stays in one array). An entry's weight in bin i is defined as the
     * difference of consecutive running sums: exactly the probability the search realises. */
    float *far_cdf;
    /* per point, the 7 bin totals (the last running sum of each bin) side by side, so
     * blending the bins at a vertex touches one cache line, not seven */
    float *far_bin_total;      /* CP_BIN_STRIDE per point */
    /* visibility (§3.2): one slot per key of the near and far lists, sorted by key */
    uint32_t *vis_off, *vis_key;
    VisCounter *vis_count;     /* atomics (see VisCounter); a slot's two counters share a cache line */
    float *w_blurred;              /* W' (Eq. 6, then the §3.2.2 blur) used at render time */
    float *w_pool;                 /* pooled W per slot at the barrier (params.pool_visibility; pool.c), else NULL */
    uint32_t *key_parent;          /* pool.c mode 2 (cut build): per key, its parent in the light tree */
    uint8_t *vis_low;              /* per point: a slot has W < 1 (this barrier) */
    uint8_t *vis_active;           /* per point: some W' != 1 (its tables are not the W = 1 ones) */
    uint8_t *tables_dirty;         /* per point: W' changed, rebuild its tables */
    /* 16 nearest neighbours and normalised Eq. 4 weights, shared by both blurs */
    uint32_t *nbr;
    float *nbr_w, *self_w;
    /* per point: the squared distance within which a query's nearest point is the point or
     * one of its nbr (0.49^2 of the K-th neighbour's squared distance; INFINITY when it has
     * fewer than K), the render-time lookup's shortcut around the kd-tree */
    float *nbr_clear2;
    /* §4.2 scattering sample weights (scatter.c; NULL until cachepoints_build_scatter) */
    float *scatter_near;       /* s(p, e) of each near entry */
    float *scatter_far, *scatter_total; /* per point: the far lists' part, and near + far */
    /* BSDF-aware selection (cachepoints_prepare_lobes, cut build): per key a bounding sphere
     * (CachePointLights.bound's layout; clusters: around their tree node's box); NULL: none */
    float *key_bound;
    CachePointParams params;
    CachePointStats stats;
    KdTree kd;
    /* progressive insertion (progressive.c, params.progressive_rounds > 0): the probe pool
     * (the candidates merge pass 2 deleted, in index order), the points of the one-shot build
     * (those after it were inserted), and the barriers seen so far */
    float *probe;              /* 3 per probe */
    uint32_t num_probes, n_build, barriers;
    /* per point, its own distribution before the blur (build_internal.h's Dist), kept while
     * insertion rounds remain so a rebuild estimates only the new points; NULL otherwise */
    struct Dist *raw;
    uint32_t num_raw;
};

static inline uint32_t cp_key_of_light(const CachePoints *cp, uint32_t light) {
    if (light >= cp->num_lights) return CP_NONE;
    return cp->light_key ? cp->light_key[light] : light;
}
static inline uint32_t cp_key_end(const CachePoints *cp, uint32_t key) {
    return cp->key_end ? cp->key_end[key] : key + 1;
}
static inline uint32_t cp_key_light(const CachePoints *cp, uint32_t key) {
    return cp->key_light ? cp->key_light[key] : key;
}

/* First index in a[lo, hi) whose value is >= key. */
static inline uint32_t cp_lower_bound(const uint32_t *a, uint32_t lo, uint32_t hi, uint32_t key) {
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (a[mid] < key) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* Running sum of bin `bin` up to far entry k (inclusive) of point p. */
static inline float *cp_cdf(const CachePoints *cp, uint32_t p, int bin, uint32_t k) {
    uint32_t base = cp->far_off[p], count = cp->far_off[p + 1] - base;
    return cp->far_cdf + (size_t)CP_FAR_BINS * base + (size_t)bin * count + (k - base);
}

/* lookup.c: builds the per-point render tables (near_vis, far_cdf) from w_blurred, for every
 * point (all != 0) or for those marked in tables_dirty. */
void cp_rebuild_tables(CachePoints *cp, int all);
/* lookup.c: selection's blend of the far bins for a normal (NULL: the fluence bin). */
void cp_bin_blend(const float *n, float b[CP_FAR_BINS]);
/* pool.c: W of every slot from its own counters, or for a slot with fewer attempts than Eq. 6
 * needs from the counters pooled over its blur neighbours, into w_pool (allocated on first use).
 * 0 ok, -1 out of memory. */
int cp_pool_visibility(CachePoints *cp);
/* lookup.c: the nearest point to x (ties: lowest index), hint any point index or CP_NONE. */
uint32_t cp_nearest_point(const CachePoints *cp, const float x[3], uint32_t hint);
/* build.c: the parallel-for of the params, or a serial loop (the build and the barrier). */
void cp_run_parallel(const CachePointParams *p, size_t n, size_t grain, void (*fn)(void *, size_t, size_t, int),
                     void *ctx);

#endif
