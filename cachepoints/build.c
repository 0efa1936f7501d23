/* cachepoints/build.c: the cache point build (§3.1), step by step:
 *
 *   candidates -> spatial sort (§3.1.1) -> merge pass 1 (§3.1.2)     merge.c
 *   -> merge pass 2 (§3.1.4, Eqs. 2-3) on the points' fluence         merge.c, with
 *      distributions (§3.1.3)                                         far_linear.c / far_cut.c
 *   -> the seven far bins for the survivors (§3.1.3)                  far_linear.c / far_cut.c
 *   -> far-bin blur (§3.1.5, Eq. 4)                                   blur.c
 *   -> flat arrays (internal.h), render tables (lookup.c)             here
 *
 * Two ways to build a point's far distribution: linear (the paper: every light estimated at
 * every point) and cut (a cut through the scene's light tree, so that no point visits every
 * light: the paper's §5.2.2 scaling failure). This file also holds the parameters, the key
 * space of the cut build, and freeing. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"

void cachepoints_default_params(CachePointParams *p) {
    memset(p, 0, sizeof *p);
    p->knn = 20;
    p->near_factor = 4.0f;
    p->energy_fraction = 0.97f;
    p->min_per_bin = 4;
    p->max_per_bin = 256;
    p->max_near = 256;
    p->blur_neighbours = 16;
    p->r_min = 0.04f;
    p->epsilon = 0.03f;
    p->visibility = 1;
    p->build_cut = 0;
    p->cut_size = 128;
}

void cp_run_parallel(const CachePointParams *p, size_t n, size_t grain, void (*fn)(void *, size_t, size_t, int),
                     void *ctx) {
    if (p->parallel_for) p->parallel_for(p->pool, n, grain, fn, ctx);
    else if (n) fn(ctx, 0, n, 0);
}

/* ---------------------------------------------------------------- light distributions */

void cp_dist_free(Dist *d) {
    free(d->near_key); free(d->near_light); free(d->near_fluence); free(d->far);
    memset(d, 0, sizeof *d);
}

int cp_dist_alloc_near(Dist *d, uint32_t count) {
    d->near_count = count;
    d->near_key = malloc((count ? count : 1) * sizeof(uint32_t));
    d->near_light = malloc((count ? count : 1) * sizeof(uint32_t));
    d->near_fluence = malloc((count ? count : 1) * sizeof(float));
    return d->near_key && d->near_light && d->near_fluence ? 0 : -1;
}

static void dist_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    DistCtx *c = vctx;
    const DistBuilder *B = c->params->build_cut ? &cp_far_cut : &cp_far_linear;
    void *scratch = B->scratch_new(c);
    if (!scratch) { c->failed = 1; return; }
    for (size_t i = b; i < e && !c->failed; ++i) {
        int rc = B->point(c, scratch, i);
        if (rc == 0 && c->omni) {
            rc = cp_omni_build(&c->dist[i], &c->omni[i]);
            cp_dist_free(&c->dist[i]);
        }
        if (rc != 0) c->failed = 1;
    }
    B->scratch_free(scratch);
}

int cp_build_distributions(const DistCtx *proto, uint32_t n) {
    DistCtx c = *proto;
    c.failed = 0;
    cp_run_parallel(c.params, n, 16, dist_range, &c);
    return c.failed ? -1 : 0;
}

/* ---------------------------------------------------------------- key space */

/* Cut build: keys are the tree's nodes, then one per infinite light (see internal.h).
 * 0 ok, -1 out of memory, -2 a tree that is not the layout CachePointTree documents. */
int cp_key_space_init(CachePoints *cp, const CachePointLights *L) {
    cp->num_lights = L->count;
    cp->num_keys = L->count;
    if (!cp->params.build_cut) return 0;
    const CachePointTree *T = L->tree;
    uint32_t nn = T->node_count, ninf = 0;
    for (uint32_t l = 0; l < L->count; ++l) ninf += L->infinite[l] && T->light_leaf[l] == CP_NONE;
    cp->num_keys = nn + ninf;
    cp->light_key = malloc(((size_t)L->count + 1) * sizeof(uint32_t));
    cp->key_end = malloc(((size_t)cp->num_keys + 1) * sizeof(uint32_t));
    cp->key_light = malloc(((size_t)cp->num_keys + 1) * sizeof(uint32_t));
    if (!cp->light_key || !cp->key_end || !cp->key_light) return -1;
    /* depth-first layout: node k's subtree is k, its first child's subtree, its second's;
     * a tree not laid out so is an invalid parameter (-2) */
    for (uint32_t k = nn; k-- > 0;) {
        uint32_t light = T->leaf_light[k];
        int leaf = light != CP_NONE;
        if (!leaf && !(T->second_child[k] > k && T->second_child[k] < nn)) return -2; /* malformed tree */
        if (leaf && light >= L->count) return -2;
        cp->key_light[k] = light;
        cp->key_end[k] = leaf ? k + 1 : cp->key_end[T->second_child[k]];
    }
    uint32_t j = nn;
    for (uint32_t l = 0; l < L->count; ++l) {
        if (T->light_leaf[l] != CP_NONE && (T->light_leaf[l] >= nn || T->leaf_light[T->light_leaf[l]] != l)) return -2;
        cp->light_key[l] = T->light_leaf[l];
        if (L->infinite[l] && T->light_leaf[l] == CP_NONE) {
            cp->light_key[l] = j;
            cp->key_light[j] = l;
            cp->key_end[j] = j + 1;
            ++j;
        }
    }
    return 0;
}

/* ---------------------------------------------------------------- points, freeing */

uint32_t cachepoints_count(const CachePoints *cp) { return cp ? cp->n : 0; }

void cachepoints_point(const CachePoints *cp, uint32_t i, float pos[3], float *radius) {
    memcpy(pos, cp->pos + 3 * (size_t)i, 3 * sizeof(float));
    *radius = cp->radius[i];
}

/* What cp_build_points makes: every per-point array (a progressive rebuild replaces them; the
 * key space, the probes and the raw distributions stay). One list, so that a rebuild and
 * cachepoints_free cannot disagree about what a point owns. */
void cp_points_free(CachePoints *cp) {
    kdtree_free(&cp->kd);
    free(cp->pos); free(cp->radius);
    free(cp->near_off); free(cp->near_key); free(cp->near_light); free(cp->near_slot); free(cp->near_vis);
    free(cp->far_off); free(cp->far); free(cp->far_slot); free(cp->far_cdf);
    free(cp->vis_off); free(cp->vis_key); free(cp->vis_count); free(cp->far_bin_total); free(cp->w_blurred);
    free(cp->vis_low); free(cp->vis_active); free(cp->tables_dirty);
    free(cp->scatter_near); free(cp->scatter_far); free(cp->scatter_total);
    free(cp->nbr); free(cp->nbr_w); free(cp->self_w); free(cp->nbr_clear2);
    free(cp->w_pool);
}

void cachepoints_free(CachePoints *cp) {
    if (!cp) return;
    cp_points_free(cp);
    /* the key space (shared by every rebuild) */
    free(cp->light_key); free(cp->key_end); free(cp->key_light); free(cp->key_parent); free(cp->key_bound);
    free(cp->probe);
    cp_raw_free(cp);
    free(cp);
}

/* ---------------------------------------------------------------- flat arrays */

/* Flattens the final points' near lists and blurred far lists into CSR arrays, with one
 * visibility slot per key: a parallel count, prefix sums, then a parallel fill that frees
 * the per-point lists as it goes. A far entry for a light of the near list (brought in by
 * a neighbour's list in the blur) is dropped: the near list evaluates that light exactly at
 * the vertex (§3.3), and a light must have one entry only. */
typedef struct FlattenCtx { CachePoints *cp; Dist *dist, *blurred; int fill; size_t clusters[64]; } FlattenCtx;

static void flatten_range(void *vctx, size_t b, size_t e, int thread) {
    FlattenCtx *c = vctx;
    CachePoints *cp = c->cp;
    size_t clusters = 0;
    for (size_t i = b; i < e; ++i) {
        Dist *d = &c->dist[i], *bl = &c->blurred[i];
        uint32_t a = 0, f = 0, v = 0, x = 0, y = 0;
        if (c->fill) { a = cp->near_off[i]; f = cp->far_off[i]; v = cp->vis_off[i]; }
        /* one merge walk over the two sorted lists */
        while (x < d->near_count || y < bl->far_count) {
            uint32_t kx = x < d->near_count ? d->near_key[x] : CP_NONE;
            uint32_t ky = y < bl->far_count ? bl->far[y].key : CP_NONE;
            if (kx <= ky) {
                if (c->fill) {
                    cp->near_key[a] = kx;
                    cp->near_light[a] = d->near_light[x];
                    cp->near_slot[a] = v;
                    cp->vis_key[v] = kx;
                }
                ++a; ++v; ++x;
                if (kx == ky) ++y; /* near wins */
            } else {
                if (c->fill) {
                    cp->far[f] = bl->far[y];
                    cp->far_slot[f] = v;
                    cp->vis_key[v] = ky;
                    clusters += cp_key_light(cp, ky) == CP_NONE;
                }
                ++f; ++v; ++y;
            }
        }
        if (c->fill) {
            cp_dist_free(d);
            cp_dist_free(bl);
        } else { /* counts, turned into offsets by the caller */
            cp->near_off[i + 1] = a;
            cp->far_off[i + 1] = f;
            cp->vis_off[i + 1] = v;
        }
    }
    __atomic_fetch_add(&c->clusters[thread & 63], clusters, __ATOMIC_RELAXED);
}

static int flatten(CachePoints *cp, Dist *dist, Dist *blurred) {
    uint32_t n = cp->n;
    cp->near_off = malloc((n + 1) * sizeof(uint32_t));
    cp->far_off = malloc((n + 1) * sizeof(uint32_t));
    cp->vis_off = malloc((n + 1) * sizeof(uint32_t));
    cp->vis_low = calloc(n + 1, 1);
    cp->vis_active = calloc(n + 1, 1);
    cp->tables_dirty = calloc(n + 1, 1);
    if (!cp->near_off || !cp->far_off || !cp->vis_off || !cp->vis_low || !cp->vis_active || !cp->tables_dirty) return -1;
    FlattenCtx c = {cp, dist, blurred, 0, {0}};
    cp_run_parallel(&cp->params, n, 64, flatten_range, &c);
    size_t a = 0, f = 0, v = 0;
    cp->near_off[0] = cp->far_off[0] = cp->vis_off[0] = 0;
    for (uint32_t i = 0; i < n; ++i) {
        a += cp->near_off[i + 1];
        f += cp->far_off[i + 1];
        v += cp->vis_off[i + 1];
        if (v >= UINT32_MAX) return -1; /* offsets are 32-bit */
        cp->near_off[i + 1] = (uint32_t)a;
        cp->far_off[i + 1] = (uint32_t)f;
        cp->vis_off[i + 1] = (uint32_t)v;
    }
    cp->near_key = malloc((a + 1) * sizeof(uint32_t));
    cp->near_light = malloc((a + 1) * sizeof(uint32_t));
    cp->near_slot = malloc((a + 1) * sizeof(uint32_t));
    cp->near_vis = malloc((a + 1) * sizeof(float));
    cp->far = malloc((f + 1) * sizeof(FarEntry));
    cp->far_slot = malloc((f + 1) * sizeof(uint32_t));
    cp->vis_key = malloc((v + 1) * sizeof(uint32_t));
    cp->vis_count = calloc(v + 1, sizeof(VisCounter));
    size_t bt_bytes = ((size_t)n * CP_BIN_STRIDE * sizeof(float) + 63) / 64 * 64 + 64;
    cp->far_bin_total = aligned_alloc(64, bt_bytes); /* a point's 32-byte block never straddles a line */
    if (cp->far_bin_total) memset(cp->far_bin_total, 0, bt_bytes);
    cp->w_blurred = malloc((v + 1) * sizeof(float));
    cp->far_cdf = malloc((f + 1) * CP_FAR_BINS * sizeof(float));
    if (!cp->near_key || !cp->near_light || !cp->near_slot || !cp->near_vis || !cp->far || !cp->far_slot ||
        !cp->vis_key || !cp->vis_count || !cp->far_bin_total || !cp->w_blurred || !cp->far_cdf)
        return -1;
    c.fill = 1;
    cp_run_parallel(&cp->params, n, 64, flatten_range, &c);
    size_t clusters = 0;
    for (int t = 0; t < 64; ++t) clusters += c.clusters[t];
    for (size_t s = 0; s < v; ++s) cp->w_blurred[s] = 1.0f; /* first iteration: W = 1 */
    uint32_t K = cp->params.blur_neighbours;
    cp->stats.bytes = (size_t)n * (3 + 1 + 3 + 2 * K + 1 + CP_BIN_STRIDE) * sizeof(float) + a * 16 + f * (sizeof(FarEntry) + 4 + 4 * CP_FAR_BINS) +
                      v * 16 + (size_t)cp->num_keys * 8 + (cp->light_key ? (size_t)cp->num_lights * 4 : 0) +
                      (size_t)n * 19 /* kd-tree, flags */;
    cp->stats.mean_near = n ? (double)a / n : 0.0;
    cp->stats.mean_far = n ? (double)f / n : 0.0;
    cp->stats.mean_far_clusters = n ? (double)clusters / n : 0.0;
    return 0;
}

/* ---------------------------------------------------------------- the build */

/* A deep copy of a distribution (progressive insertion keeps the points' own ones). */
static int dist_copy(Dist *to, const Dist *from) {
    memset(to, 0, sizeof *to);
    if (cp_dist_alloc_near(to, from->near_count) != 0) return -1;
    memcpy(to->near_key, from->near_key, from->near_count * sizeof(uint32_t));
    memcpy(to->near_light, from->near_light, from->near_count * sizeof(uint32_t));
    memcpy(to->near_fluence, from->near_fluence, from->near_count * sizeof(float));
    to->far_count = from->far_count;
    to->far = malloc((from->far_count ? from->far_count : 1) * sizeof(FarEntry));
    if (!to->far) return -1;
    memcpy(to->far, from->far, from->far_count * sizeof(FarEntry));
    return 0;
}

/* The final points' distributions (§3.1.3), kd-tree, far blur (§3.1.5), flat arrays and
 * render tables: the part of the build after merge pass 2, which progressive.c reruns over
 * the old and the inserted points. A point's own (unblurred) distribution depends only on
 * its position and radius, so points [0, cp->num_raw) take theirs from cp->raw (moved out)
 * and only the others are estimated. With keep_raw, every point's is kept in cp->raw for
 * the next rebuild. */
int cp_build_points(CachePoints *cp, const CachePointLights *L, int keep_raw) {
    uint32_t n = cp->n, reuse = cp->raw && cp->num_raw <= n ? cp->num_raw : 0;
    const CachePointParams *P = &cp->params;
    Dist *dist = calloc(n, sizeof *dist);
    int failed = !dist;
    if (!failed) {
        if (reuse) memcpy(dist, cp->raw, reuse * sizeof *dist);
        free(cp->raw);
        cp->raw = NULL;
        cp->num_raw = 0;
    }
    /* the seven far bins (§3.1.3) */
    if (!failed && reuse < n) {
        DistCtx dc = {cp->pos + 3 * (size_t)reuse, cp->radius + reuse, L, P, cp, dist + reuse, NULL, 0};
        failed = cp_build_distributions(&dc, n - reuse) != 0;
    }
    if (!failed && keep_raw) {
        cp->raw = calloc(n, sizeof *cp->raw);
        failed = !cp->raw;
        for (uint32_t i = 0; i < n && !failed; ++i) failed = dist_copy(&cp->raw[i], &dist[i]) != 0;
        cp->num_raw = n;
    }
    Dist *blurred = NULL;
    if (!failed) {
        blurred = calloc(n, sizeof *blurred);
        failed = !blurred || kdtree_build(&cp->kd, cp->pos, n) != 0 ||
                 kdtree_build_clearance(&cp->kd) != 0; /* render-time 1-NN shortcut */
    }
    if (!failed) {
        /* blur the far bins out of place (§3.1.5); then the points' own lists are freed
         * before the flat arrays exist, so the build never holds three copies */
        failed = cp_blur_far(cp, dist, blurred) != 0;
        for (uint32_t i = 0; i < n; ++i) { free(dist[i].far); dist[i].far = NULL; dist[i].far_count = 0; }
    }
    if (!failed) failed = flatten(cp, dist, blurred) != 0;
    for (uint32_t i = 0; i < n && dist; ++i) cp_dist_free(&dist[i]);
    for (uint32_t i = 0; i < n && blurred; ++i) cp_dist_free(&blurred[i]);
    free(dist);
    free(blurred);
    if (failed) return -1;
    cp_rebuild_tables(cp, 1);
    return 0;
}

void cp_raw_free(CachePoints *cp) {
    for (uint32_t i = 0; cp->raw && i < cp->num_raw; ++i) cp_dist_free(&cp->raw[i]);
    free(cp->raw);
    cp->raw = NULL;
    cp->num_raw = 0;
}

/* What the build cannot run with (-2): more neighbours than the fixed kNN arrays hold
 * (64), a uniform floor that is not a probability, or a cut build without a usable tree
 * (cp_key_space_init checks its layout). */
static int params_valid(const CachePointParams *P, const CachePointLights *L) {
    if (P->knn > 64 || P->blur_neighbours > 64) return 0;
    if (!(P->epsilon >= 0.0f && P->epsilon <= 1.0f)) return 0;
    if (!P->build_cut) return 1;
    const CachePointTree *T = L->tree;
    return T && T->node_bounds && T->node_estimate7 && T->descend && T->descend_pmf && P->cut_size >= 1 &&
           (T->node_count == 0 || (T->second_child && T->leaf_light)) && (L->count == 0 || T->light_leaf);
}

int cachepoints_build(CachePoints **out, const float *cand, uint32_t num_candidates, const CachePointLights *L,
                      const CachePointCamera *camera, const CachePointParams *P, CachePointStats *stats) {
    *out = NULL;
    CachePointStats st = {0};
    st.candidates = num_candidates;
    if (stats) *stats = st;
    if (!params_valid(P, L)) return -2;
    if (L->count == 0) return 1; /* nothing to select: no points needed */
    CachePoints *cp = calloc(1, sizeof *cp);
    if (!cp) return -1;
    cp->params = *P;
    if (cp->params.max_near > CACHEPOINTS_MAX_NEAR) cp->params.max_near = CACHEPOINTS_MAX_NEAR;
    P = &cp->params;
    int rc = cp_key_space_init(cp, L);
    if (rc != 0) { cachepoints_free(cp); return rc; }
    /* drop non-finite candidates */
    float *in = malloc(((size_t)num_candidates + 1) * 3 * sizeof(float));
    if (!in) { cachepoints_free(cp); return -1; }
    uint32_t nc = 0;
    for (uint32_t i = 0; i < num_candidates; ++i)
        if (isfinite(cand[3 * i]) && isfinite(cand[3 * i + 1]) && isfinite(cand[3 * i + 2]))
            memcpy(in + 3 * (size_t)nc++, cand + 3 * (size_t)i, 3 * sizeof(float));
    if (nc < CP_MIN_POINTS) { free(in); cachepoints_free(cp); return 1; }
    /* the candidates come in the caller's (spatial) order, which the merge passes follow */
    float scene_scale = cp_scene_scale(in, nc);
    cp->pos = in;

    uint32_t n1;
    int failed = cp_merge_pass1(P, camera, cp->pos, nc, &n1) != 0;
    st.after_pass1 = n1;
    if (failed || n1 < CP_MIN_POINTS) { cachepoints_free(cp); if (stats) *stats = st; return failed ? -1 : 1; }

    /* merge pass 2 sets the radii r_p of the survivors, which the far bins then use (Eq. 1) */
    Dist *dist = calloc(n1, sizeof *dist);
    cp->radius = malloc(n1 * sizeof(float));
    uint32_t n = 0;
    failed = !dist || !cp->radius ||
             cp_merge_pass2(cp, L, camera, P, cp->pos, n1, scene_scale, dist, cp->radius, &n,
                            P->progressive_rounds ? &cp->probe : NULL, &cp->num_probes) != 0;
    for (uint32_t i = 0; i < n1 && dist; ++i) cp_dist_free(&dist[i]); /* pass 2 leaves them empty */
    free(dist);
    cp->n = n;
    cp->n_build = n;
    if (!failed && n > 0) failed = cp_build_points(cp, L, P->progressive_rounds > 0) != 0;
    if (failed || n == 0) { cachepoints_free(cp); return failed ? -1 : 1; }
    st.final_points = n;
    st.bytes = cp->stats.bytes;
    st.mean_near = cp->stats.mean_near;
    st.mean_far = cp->stats.mean_far;
    st.mean_far_clusters = cp->stats.mean_far_clusters;
    cp->stats = st;
    if (stats) *stats = st;
    *out = cp;
    return 0;
}
