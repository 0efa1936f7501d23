/* cachepoints/progressive.c: progressive, discontinuity-guided insertion of cache points
 * between iterations (beyond the paper: §5.2.1 proposes adding points at later iterations,
 * "using ray hits as new candidates ... then updating the existing points' distributions";
 * the cache placement paper's discontinuity-guided sampling, DGS, §3.2, adapted as the
 * digest's section C.3 proposes).
 *
 * The one-shot build places points before anything is known about visibility. After an
 * iteration, each point's visibility counters (§3.2.1) say what fraction of its shadow rays
 * reached their light. Where two neighbouring points disagree strongly (a shadow boundary,
 * a wall between two rooms, the edge of a spot's cone through an occluder), the vertices
 * between them take whichever point is nearer and inherit its learned visibility: the
 * field is under-resolved there. We insert points there:
 *
 *  1. Probes: the candidates merge pass 2 deleted (digest C.2 step 1: surface hits of the
 *     pilot paths and box candidates, all of them once within r_p of a kept point).
 *  2. Score of a probe q (the DGS discontinuity D(s), Eq. 4, without its geometry term,
 *     which the cache placement paper drops for importance caching): with c the point q
 *     uses and c2 the nearest other point among c's blur neighbours, D = max(0, |V_c - V_c2|
 *     - 2 sigma) x d(q, c) / d(q, c2), V the point's visibility rate over all its slots,
 *     sigma the binomial standard error of the difference (so noise from few attempts does
 *     not insert points), and the distance ratio (1 on the bisector of c and c2) placing the
 *     insertion between the two, where the field jumps.
 *  3. Budgeted selection (DGS's fixed budget instead of a threshold, §3.2 last paragraphs):
 *     per round up to budget x (points of the build) / rounds probes, in the order (score
 *     desc, probe index asc), a probe with D above a small floor, at least half of c's radius
 *     from c and half a radius from any probe accepted before it.
 *  4. Rebuild: the old points keep their index, position and radius; the new ones are
 *     appended with the radius min(r_c, r_c2); every point's distribution, the kd-tree, the
 *     far blur and the flat arrays are rebuilt (cp_build_points, as in the build), so the
 *     old points' lists see their new neighbours (§5.2.1's "update the existing cache
 *     points' distributions"). Learned visibility is kept: each old point's counters move to
 *     the slot of the same key, a new point starts from its parent's (capped, see
 *     inherit_range), then the barrier's Eqs. 5-6 and blur run as usual.
 *
 * Everything happens at the iteration barrier (no ray in flight: the paper's §1 read-write
 * lock problem does not arise) and depends only on the counters (integer sums, independent
 * of the thread count), the build and the probes' index order: deterministic. Selection
 * stays exact for whatever points exist, so the image stays unbiased. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "build_internal.h"

#define CP_PROGRESSIVE_MIN_ATTEMPTS 4u  /* a point with fewer shadow rays has no visibility rate yet */
#define CP_PROGRESSIVE_MIN_SCORE 0.05f  /* below this a probe is not a discontinuity (noise floor) */

/* ---------------------------------------------------------------- scores */

typedef struct ScoreCtx {
    const CachePoints *cp;
    const double *rate;    /* per point: visibility rate V */
    const double *attempts;
    float *score;          /* per probe */
    uint32_t *pair;        /* per probe: c, c2 */
} ScoreCtx;

static void score_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    ScoreCtx *c = vctx;
    const CachePoints *cp = c->cp;
    uint32_t K = cp->params.blur_neighbours, hint = CP_NONE;
    for (size_t i = b; i < e; ++i) {
        const float *q = cp->probe + 3 * i;
        c->score[i] = 0.0f;
        c->pair[2 * i] = c->pair[2 * i + 1] = CP_NONE;
        uint32_t p = cp_nearest_point(cp, q, hint);
        hint = p; /* probes are in the candidates' spatial order */
        float d1 = sqrtf(cp_dist2(q, cp->pos + 3 * (size_t)p));
        /* the runner-up: the nearest of p's blur neighbours (ties: lowest index) */
        uint32_t p2 = CP_NONE;
        float best = INFINITY;
        for (uint32_t j = 0; j < K; ++j) {
            uint32_t nb = cp->nbr[(size_t)p * K + j];
            if (nb == CP_NONE) continue;
            float d = cp_dist2(q, cp->pos + 3 * (size_t)nb);
            if (d < best || (d == best && nb < p2)) { best = d; p2 = nb; }
        }
        if (p2 == CP_NONE) continue;
        c->pair[2 * i] = p;
        c->pair[2 * i + 1] = p2;
        double a1 = c->attempts[p], a2 = c->attempts[p2];
        if (a1 < CP_PROGRESSIVE_MIN_ATTEMPTS || a2 < CP_PROGRESSIVE_MIN_ATTEMPTS) continue;
        double v1 = c->rate[p], v2 = c->rate[p2];
        double pooled = (v1 * a1 + v2 * a2) / (a1 + a2);
        double sigma = sqrt(fmax(pooled * (1.0 - pooled), 0.0) * (1.0 / a1 + 1.0 / a2));
        double jump = fabs(v1 - v2) - 2.0 * sigma;
        float d2 = sqrtf(best);
        if (jump > 0.0 && d2 > 0.0f) c->score[i] = (float)jump * (d1 / d2);
    }
}

/* Visibility rate and attempts per point: the counters summed over its slots. */
typedef struct RateCtx { const CachePoints *cp; double *rate, *attempts; } RateCtx;

static void rate_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    RateCtx *c = vctx;
    const CachePoints *cp = c->cp;
    for (size_t p = b; p < e; ++p) {
        uint64_t total = 0, success = 0;
        for (uint32_t s = cp->vis_off[p]; s < cp->vis_off[p + 1]; ++s) {
            total += cp->vis_count[s].total;
            success += cp->vis_count[s].success;
        }
        c->attempts[p] = (double)total;
        c->rate[p] = total ? (double)success / ((double)CP_VIS_ONE * (double)total) : 1.0;
    }
}

static int by_score(const void *a, const void *b) {
    const ValueIndex *x = a, *y = b;
    if (x->v != y->v) return x->v > y->v ? -1 : 1;
    return x->id < y->id ? -1 : x->id > y->id;
}

/* ---------------------------------------------------------------- rebuild */

/* Moves old's counters into nw's slots of the same key, per old point (same index in both). */
typedef struct MoveCtx { const CachePoints *old; CachePoints *nw; } MoveCtx;

static void move_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    MoveCtx *c = vctx;
    for (size_t p = b; p < e; ++p) {
        uint32_t a = c->old->vis_off[p], a1 = c->old->vis_off[p + 1];
        uint32_t q = c->nw->vis_off[p], q1 = c->nw->vis_off[p + 1];
        while (a < a1 && q < q1) {
            uint32_t ka = c->old->vis_key[a], kq = c->nw->vis_key[q];
            if (ka < kq) ++a;
            else if (ka > kq) ++q;
            else c->nw->vis_count[q++] = c->old->vis_count[a++];
        }
    }
}

/* A new point starts from the counters of the point its probe used (same key), capped at
 * CP_INHERIT_ATTEMPTS attempts with the same rate: the vertices that move to it were using
 * that point's learned visibility, so it keeps that until its own outcomes (which soon
 * outweigh the cap; Eq. 6 needs 25) say otherwise. Without it a new point would restart at
 * W = 1 and sample the occluded lights its parent had learned to avoid. */
#define CP_INHERIT_ATTEMPTS 32u
typedef struct InheritCtx { CachePoints *nw; const uint32_t *parent; uint32_t first; } InheritCtx;

static void inherit_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    InheritCtx *c = vctx;
    CachePoints *cp = c->nw;
    for (size_t j = b; j < e; ++j) {
        uint32_t p = c->first + (uint32_t)j, par = c->parent[j];
        uint32_t a = cp->vis_off[p], a1 = cp->vis_off[p + 1], q = cp->vis_off[par], q1 = cp->vis_off[par + 1];
        while (a < a1 && q < q1) {
            uint32_t ka = cp->vis_key[a], kq = cp->vis_key[q];
            if (ka < kq) ++a;
            else if (ka > kq) ++q;
            else {
                VisCounter h = cp->vis_count[q++];
                if (h.total > CP_INHERIT_ATTEMPTS) {
                    h.success = (uint32_t)((uint64_t)h.success * CP_INHERIT_ATTEMPTS / h.total);
                    h.total = CP_INHERIT_ATTEMPTS;
                }
                cp->vis_count[a++] = h;
            }
        }
    }
}

/* Appends m points (pos 3m, radius m) and rebuilds; the old points' counters move to their new
 * slots, and new point j inherits those of old point parent[j] (parent NULL: none, the caller
 * loads counters). On failure (-1, out of memory) cp is unchanged. */
static int insert_points(CachePoints *cp, const CachePointLights *L, const float *pos, const float *radius,
                         const uint32_t *parent, uint32_t m, int keep_raw) {
    uint32_t n = cp->n, total = n + m;
    CachePoints nw;
    memset(&nw, 0, sizeof nw);
    nw.params = cp->params;
    /* the key space depends only on the lights: shared, then moved */
    nw.num_lights = cp->num_lights;
    nw.num_keys = cp->num_keys;
    nw.light_key = cp->light_key;
    nw.key_end = cp->key_end;
    nw.key_light = cp->key_light;
    nw.key_parent = cp->key_parent;
    nw.key_bound = cp->key_bound; /* the lobe bounds of the keys (cachepoints_prepare_lobes) */
    nw.raw = cp->raw; /* the old points' own distributions: moved, only the new ones are estimated */
    nw.num_raw = cp->num_raw;
    cp->raw = NULL;
    cp->num_raw = 0;
    nw.n = total;
    nw.pos = malloc(((size_t)total + 1) * 3 * sizeof(float));
    nw.radius = malloc(((size_t)total + 1) * sizeof(float));
    int failed = !nw.pos || !nw.radius;
    if (!failed) {
        memcpy(nw.pos, cp->pos, (size_t)n * 3 * sizeof(float));
        memcpy(nw.pos + 3 * (size_t)n, pos, (size_t)m * 3 * sizeof(float));
        memcpy(nw.radius, cp->radius, (size_t)n * sizeof(float));
        memcpy(nw.radius + n, radius, (size_t)m * sizeof(float));
        failed = cp_build_points(&nw, L, keep_raw) != 0;
    }
    if (failed) { /* cp keeps its points (without its kept distributions: a later rebuild estimates all) */
        cp_points_free(&nw);
        cp_raw_free(&nw);
        return -1;
    }
    MoveCtx mc = {cp, &nw};
    cp_run_parallel(&cp->params, n, 256, move_range, &mc);
    if (parent) {
        InheritCtx ic = {&nw, parent, n};
        cp_run_parallel(&cp->params, m, 256, inherit_range, &ic);
    }
    CachePointStats st = cp->stats;
    st.final_points = total;
    st.bytes = nw.stats.bytes;
    st.mean_near = nw.stats.mean_near;
    st.mean_far = nw.stats.mean_far;
    st.mean_far_clusters = nw.stats.mean_far_clusters;
    nw.stats = st;
    nw.probe = cp->probe;
    nw.num_probes = cp->num_probes;
    nw.n_build = cp->n_build;
    nw.barriers = cp->barriers;
    cp_points_free(cp);
    *cp = nw;
    return 0;
}

/* ---------------------------------------------------------------- the round */

static int insertion_round(CachePoints *cp, const CachePointLights *L, int last, uint32_t *inserted) {
    const CachePointParams *P = &cp->params;
    uint32_t n = cp->n, np = cp->num_probes;
    uint32_t budget = (uint32_t)ceil((double)P->progressive_budget * cp->n_build / P->progressive_rounds);
    if (np == 0 || budget == 0) return 0;
    double *rate = malloc(((size_t)n + 1) * sizeof(double)), *attempts = malloc(((size_t)n + 1) * sizeof(double));
    float *score = malloc(((size_t)np + 1) * sizeof(float));
    uint32_t *pair = malloc(((size_t)np + 1) * 2 * sizeof(uint32_t));
    ValueIndex *order = malloc(((size_t)np + 1) * sizeof(ValueIndex));
    float *new_pos = malloc(((size_t)budget + 1) * 3 * sizeof(float)), *new_r = malloc(((size_t)budget + 1) * sizeof(float));
    uint32_t *parent = malloc(((size_t)budget + 1) * sizeof(uint32_t));
    int rc = rate && attempts && score && pair && order && new_pos && new_r && parent ? 0 : -1;
    uint32_t m = 0;
    if (rc == 0) {
        RateCtx r = {cp, rate, attempts};
        cp_run_parallel(P, n, 256, rate_range, &r);
        ScoreCtx s = {cp, rate, attempts, score, pair};
        cp_run_parallel(P, np, 256, score_range, &s);
        uint32_t k = 0;
        for (uint32_t i = 0; i < np; ++i)
            if (score[i] > CP_PROGRESSIVE_MIN_SCORE) order[k++] = (ValueIndex){score[i], i};
        qsort(order, k, sizeof *order, by_score); /* a total order: deterministic */
        for (uint32_t j = 0; j < k && m < budget; ++j) {
            uint32_t i = order[j].id, c = pair[2 * i], c2 = pair[2 * i + 1];
            const float *q = cp->probe + 3 * (size_t)i;
            float rc1 = cp->radius[c];
            if (cp_dist2(q, cp->pos + 3 * (size_t)c) < 0.25f * rc1 * rc1) continue;
            float r = fminf(rc1, cp->radius[c2]);
            int close = 0;
            for (uint32_t a = 0; a < m && !close; ++a) {
                float sep = 0.5f * fmaxf(r, new_r[a]);
                close = cp_dist2(q, new_pos + 3 * (size_t)a) < sep * sep;
            }
            if (close) continue;
            memcpy(new_pos + 3 * (size_t)m, q, 3 * sizeof(float));
            parent[m] = c;
            new_r[m++] = r;
        }
    }
    free(rate); free(attempts); free(score); free(pair); free(order);
    if (rc == 0 && m > 0) rc = insert_points(cp, L, new_pos, new_r, parent, m, !last);
    free(new_pos); free(new_r); free(parent);
    if (rc == 0) *inserted = m;
    return rc;
}

int cachepoints_progress(CachePoints *cp, const CachePointLights *lights, uint32_t *inserted) {
    *inserted = 0;
    if (!cp) return 0;
    uint32_t b = ++cp->barriers;
    const CachePointParams *P = &cp->params;
    if (!P->progressive_rounds) return 0;
    if (!P->visibility || b >= P->progressive_first + P->progressive_rounds) {
        cp_raw_free(cp); /* no round inserts any more (none without visibility learning): nothing to keep */
        return 0;
    }
    if (b < P->progressive_first) return 0;
    int last = b + 1 >= P->progressive_first + P->progressive_rounds;
    int rc = insertion_round(cp, lights, last, inserted);
    if (last) cp_raw_free(cp); /* no rebuild follows */
    return rc;
}

uint32_t cachepoints_inserted(const CachePoints *cp) { return cp ? cp->n - cp->n_build : 0; }

/* ---------------------------------------------------------------- checkpoints */

#define CP_INSERTED_MAGIC 0x4e495043u /* "CPIN" */
#define CP_INSERTED_VERSION 1u

static int put(FILE *out, const void *p, size_t n) { return fwrite(p, 1, n, out) == n ? 0 : -1; }
static int get(FILE *in, void *p, size_t n) { return fread(p, 1, n, in) == n ? 0 : -1; }

int cachepoints_save_inserted(const CachePoints *cp, FILE *out) {
    uint32_t head[5] = {CP_INSERTED_MAGIC, CP_INSERTED_VERSION, cp->n_build, cp->n, cp->barriers};
    uint32_t m = cp->n - cp->n_build;
    return put(out, head, sizeof head) | put(out, cp->pos + 3 * (size_t)cp->n_build, (size_t)m * 3 * sizeof(float)) |
           put(out, cp->radius + cp->n_build, (size_t)m * sizeof(float));
}

int cachepoints_load_inserted(CachePoints *cp, const CachePointLights *lights, FILE *in) {
    uint32_t head[5];
    if (get(in, head, sizeof head) || head[0] != CP_INSERTED_MAGIC || head[1] != CP_INSERTED_VERSION) return -1;
    /* a freshly built set of the same build, at most 2^26 inserted points (a damaged count) */
    if (head[2] != cp->n_build || cp->n != cp->n_build || head[3] < head[2] || head[3] - head[2] > (1u << 26))
        return -2;
    uint32_t m = head[3] - head[2];
    /* and no more than the file still holds (a damaged count allocates nothing absurd) */
    long at = ftell(in), end = -1;
    if (at >= 0 && fseek(in, 0, SEEK_END) == 0) end = ftell(in);
    if (at >= 0 && (fseek(in, at, SEEK_SET) != 0 || (end >= at && (uint64_t)m * 4 * sizeof(float) > (uint64_t)(end - at))))
        return -1;
    float *pos = malloc(((size_t)m + 1) * 3 * sizeof(float)), *r = malloc(((size_t)m + 1) * sizeof(float));
    int rc = pos && r ? 0 : -3;
    if (rc == 0 && (get(in, pos, (size_t)m * 3 * sizeof(float)) || get(in, r, (size_t)m * sizeof(float)))) rc = -1;
    const CachePointParams *P = &cp->params;
    int more = P->progressive_rounds && P->visibility && head[4] + 1 < P->progressive_first + P->progressive_rounds;
    if (rc == 0 && m > 0 && insert_points(cp, lights, pos, r, NULL, m, more) != 0) rc = -3;
    if (rc == 0 && !more) cp_raw_free(cp);
    if (rc == 0) cp->barriers = head[4];
    free(pos);
    free(r);
    return rc;
}
