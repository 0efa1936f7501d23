/* cachepoints/merge.c: from candidates to the final cache points (§3.1.1-§3.1.4): the
 * spatial sort that gives every candidate its index, merge pass 1 (§3.1.2: spatially
 * close points), then merge pass 2 (§3.1.4: neighbours with similar light distributions,
 * Eqs. 2-3, within the radius r_p it defines).
 *
 * Both passes keep the lowest index of a neighbourhood and delete the rest. Applied to
 * every point at once (the paper's parallel loop read literally), overlapping neighbourhoods
 * cascade: in 1-D with spacing 1 and radius 1.5 every point but index 0 is deleted, and a
 * 6,000-candidate test scene kept a single point. The paper's radius of 1e-5 hides this
 * (neighbourhoods never overlap), but it also merges only coincident points, which cannot
 * give the paper's own 388,888 -> 48,364 points of Fig. 3; we merge within pixel-sized
 * radii (pass 1: one pixel's footprint; pass 2: r_p, at least 3 pixels), where they do
 * overlap. So we use the sequential reading: in index order, a point still alive deletes
 * the neighbours with a higher index inside its radius. Survivors are then
 * radius-separated, the result is the same where neighbourhoods do not overlap, and it is
 * deterministic by construction. The kNN queries (the expensive part) run in parallel into
 * a neighbour table first. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"

/* r_px: the world size of one pixel at x (§3.1.4's floor is 3 r_px) */
static float pixel_footprint(const CachePointCamera *c, const float *x) {
    if (c->pixel_angle > 0.0f) return sqrtf(cp_dist2(x, c->position)) * c->pixel_angle;
    return c->pixel_size;
}

/* The diagonal of the points' bounding box (1 if degenerate): the scale of the merge radii. */
float cp_scene_scale(const float *pts, uint32_t n) {
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) {
            lo[k] = fminf(lo[k], pts[3 * i + k]);
            hi[k] = fmaxf(hi[k], pts[3 * i + k]);
        }
    float s = sqrtf((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) + (hi[2] - lo[2]) * (hi[2] - lo[2]));
    return s > 0.0f ? s : 1.0f;
}

/* Keeps the points whose deleted flag is 0, in order (and their extra value, if any). */
static uint32_t compact(float *pts, float *extra, const uint8_t *deleted, uint32_t n) {
    uint32_t m = 0;
    for (uint32_t i = 0; i < n; ++i) {
        if (deleted[i]) continue;
        memmove(pts + 3 * (size_t)m, pts + 3 * (size_t)i, 3 * sizeof(float));
        if (extra) extra[m] = extra[i];
        ++m;
    }
    return m;
}

/* ---------------------------------------------------------------- the merge of both passes */

typedef struct NeighbourCtx {
    const float *pts;
    const KdTree *kd;
    uint32_t knn;
    const float *radius;               /* per point, or NULL: use the camera footprint */
    const CachePointCamera *camera;
    uint32_t *nbr;                     /* knn per point, UINT32_MAX padded */
} NeighbourCtx;

static void neighbour_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    NeighbourCtx *c = vctx;
    for (size_t i = b; i < e; ++i) {
        const float *x = c->pts + 3 * i;
        float r = c->radius ? c->radius[i] : pixel_footprint(c->camera, x);
        uint32_t *out = c->nbr + i * c->knn;
        uint32_t k = kdtree_knn(c->kd, x, c->knn, r * r, (uint32_t)i, out, NULL);
        for (uint32_t j = k; j < c->knn; ++j) out[j] = UINT32_MAX;
    }
}

/* The sequential thinning over a neighbour table (knn per point, UINT32_MAX padded). */
static void thin(const CachePointParams *P, const uint32_t *nbr, uint32_t n, uint8_t *deleted) {
    for (uint32_t i = 0; i < n; ++i) {
        if (deleted[i]) continue;
        for (uint32_t j = 0; j < P->knn; ++j) {
            uint32_t q = nbr[(size_t)i * P->knn + j];
            if (q != UINT32_MAX && q > i) deleted[q] = 1;
        }
    }
}

static int greedy_merge(const CachePointParams *P, const float *pts, const KdTree *kd, uint32_t n,
                        const float *radius, const CachePointCamera *camera, uint8_t *deleted) {
    uint32_t *nbr = malloc((size_t)n * P->knn * sizeof *nbr);
    if (!nbr) return -1;
    NeighbourCtx c = {pts, kd, P->knn, radius, camera, nbr};
    cp_run_parallel(P, n, 512, neighbour_range, &c);
    thin(P, nbr, n, deleted);
    free(nbr);
    return 0;
}

/* ---------------------------------------------------------------- merge pass 1 (§3.1.2) */

int cp_merge_pass1(const CachePointParams *P, const CachePointCamera *camera, float *pts, uint32_t n,
                   uint32_t *survivors) {
    KdTree kd;
    *survivors = 0;
    uint8_t *deleted = calloc(n, 1);
    if (!deleted || kdtree_build(&kd, pts, n) != 0) { free(deleted); return -1; }
    int failed = greedy_merge(P, pts, &kd, n, NULL, camera, deleted) != 0;
    kdtree_free(&kd);
    if (!failed) *survivors = compact(pts, NULL, deleted, n);
    free(deleted);
    return failed ? -1 : 0;
}

/* ---------------------------------------------------------------- merge pass 2 (§3.1.4) */

int cp_omni_build(const Dist *d, OmniDist *o) {
    uint32_t n = d->near_count + d->far_count;
    o->key = malloc((n ? n : 1) * sizeof(uint32_t));
    o->p = malloc((n ? n : 1) * sizeof(float));
    if (!o->key || !o->p) return -1;
    uint32_t a = 0, b = 0, m = 0;
    double total = 0.0;
    while (a < d->near_count || b < d->far_count) {
        uint32_t ka = a < d->near_count ? d->near_key[a] : CP_NONE;
        uint32_t kb = b < d->far_count ? d->far[b].key : CP_NONE;
        float v;
        uint32_t k;
        if (ka <= kb) { k = ka; v = d->near_fluence[a++]; if (ka == kb) ++b; }
        else { k = kb; v = d->far[b++].value[CP_OMNI_BIN]; }
        if (!(v > 0.0f)) continue;
        o->key[m] = k; o->p[m] = v; total += v; ++m;
    }
    for (uint32_t i = 0; i < m; ++i) o->p[i] = (float)(o->p[i] / total);
    o->count = m;
    return 0;
}

/* M (Eq. 2) with the similarity S of each shared light (Eq. 3) as its weighted size */
static float similarity(const OmniDist *A, const OmniDist *B) {
    if (A->count + B->count == 0) return 1.0f;
    uint32_t a = 0, b = 0;
    double s = 0.0;
    while (a < A->count && b < B->count) {
        if (A->key[a] < B->key[b]) ++a;
        else if (A->key[a] > B->key[b]) ++b;
        else {
            double pa = A->p[a], pb = B->p[b];
            s += pa + pb > 0.0 ? 1.0 - fabs(pb - pa) / (pa + pb) : 1.0;
            ++a; ++b;
        }
    }
    return (float)(2.0 * s / (double)(A->count + B->count));
}

/* The two kNN passes of merge pass 2 over the same neighbours. First (omni == NULL) r0, the
 * mean distance to the kNN: §3.1.4's initial guess of r_p, which Eq. 1 already needs for
 * the omni distributions before §3.1.4 defines r_p (no neighbours: 1% of the scene's size).
 * Then M_avg over the omni distributions (Eq. 2) and r_p. */
typedef struct Pass2Ctx {
    const float *pts;
    const KdTree *kd;
    const CachePointCamera *camera;
    const OmniDist *omni;      /* NULL: the r0 pass */
    uint32_t knn;
    float r0_fallback;
    float *r0;
    float *radius;
    /* the kNN of every point, found once by the r0 pass and reused by the M_avg pass and the
     * merge (knn per point: indices UINT32_MAX padded, squared distances; the count) */
    uint32_t *nbr;
    float *nbr_d2;
    uint8_t *nbr_count;
} Pass2Ctx;

static void pass2_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    Pass2Ctx *c = vctx;
    for (size_t i = b; i < e; ++i) {
        const float *x = c->pts + 3 * i;
        uint32_t *nb = c->nbr + i * c->knn;
        float *d2 = c->nbr_d2 + i * c->knn;
        uint32_t k;
        if (!c->omni) {
            k = kdtree_knn(c->kd, x, c->knn, INFINITY, (uint32_t)i, nb, d2);
            c->nbr_count[i] = (uint8_t)k;
            float s = 0.0f;
            for (uint32_t j = 0; j < k; ++j) s += sqrtf(d2[j]);
            c->r0[i] = k ? s / (float)k : c->r0_fallback;
            continue;
        }
        k = c->nbr_count[i];
        float msum = 0.0f;
        for (uint32_t j = 0; j < k; ++j) msum += similarity(&c->omni[i], &c->omni[nb[j]]);
        float mavg = k ? msum / (float)k : 1.0f, r0 = c->r0[i];
        /* r_p = r0 M_avg, limited to 25% of r0 and to at least 3 pixels (§3.1.4) */
        c->radius[i] = fmaxf(fmaxf(r0 * mavg, 0.25f * r0), 3.0f * pixel_footprint(c->camera, x));
    }
}

/* The merge's neighbours within r_p: the prefix of the stored kNN (sorted by distance, then
 * index) with d^2 <= r_p^2, exactly what a kNN query limited to that radius returns (the knn
 * nearest within r are the nearest knn when they all lie within r). */
static void pass2_within_radius(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    Pass2Ctx *c = vctx;
    for (size_t i = b; i < e; ++i) {
        uint32_t *nb = c->nbr + i * c->knn;
        const float *d2 = c->nbr_d2 + i * c->knn;
        float r = c->radius[i], r2 = r * r;
        for (uint32_t j = 0; j < c->knn; ++j)
            if (j >= c->nbr_count[i] || !(d2[j] <= r2)) nb[j] = UINT32_MAX;
    }
}

int cp_merge_pass2(const CachePoints *keys, const CachePointLights *L, const CachePointCamera *camera,
                   const CachePointParams *P, float *pts, uint32_t n, float scene_scale, Dist *dist, float *radius,
                   uint32_t *survivors, float **probes, uint32_t *num_probes) {
    *survivors = 0;
    if (probes) { *probes = NULL; *num_probes = 0; }
    float *r0 = malloc(n * sizeof(float));
    OmniDist *omni = calloc(n, sizeof *omni);
    uint8_t *deleted = calloc(n, 1);
    uint32_t *nbr = malloc((size_t)n * P->knn * sizeof *nbr + 1);
    float *nbr_d2 = malloc((size_t)n * P->knn * sizeof *nbr_d2 + 1);
    uint8_t *nbr_count = malloc((size_t)n + 1);
    KdTree kd;
    int failed = !r0 || !omni || !deleted || !nbr || !nbr_d2 || !nbr_count || kdtree_build(&kd, pts, n) != 0;
    if (!failed) {
        Pass2Ctx p2 = {pts, &kd, camera, NULL, P->knn, 0.01f * scene_scale, r0, radius, nbr, nbr_d2, nbr_count};
        cp_run_parallel(P, n, 512, pass2_range, &p2);
        kdtree_free(&kd); /* the neighbours are stored: no query follows */
        DistCtx oc = {pts, r0, L, P, keys, dist, omni, 0};
        failed = cp_build_distributions(&oc, n) != 0;
        if (!failed) {
            p2.omni = omni;
            cp_run_parallel(P, n, 256, pass2_range, &p2);
            cp_run_parallel(P, n, 512, pass2_within_radius, &p2);
            thin(P, nbr, n, deleted);
        }
    }
    free(nbr);
    free(nbr_d2);
    free(nbr_count);
    for (uint32_t i = 0; omni && i < n; ++i) { free(omni[i].key); free(omni[i].p); }
    free(omni);
    if (!failed && probes) { /* the deleted candidates, in index order: progressive.c's probe pool */
        uint32_t m = 0;
        for (uint32_t i = 0; i < n; ++i) m += deleted[i];
        *probes = malloc(((size_t)m + 1) * 3 * sizeof(float));
        if (!*probes) failed = 1;
        for (uint32_t i = 0; i < n && !failed; ++i)
            if (deleted[i]) memcpy(*probes + 3 * (size_t)(*num_probes)++, pts + 3 * (size_t)i, 3 * sizeof(float));
    }
    if (!failed) *survivors = compact(pts, radius, deleted, n);
    free(deleted);
    free(r0);
    return failed ? -1 : 0;
}
