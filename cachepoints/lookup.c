/* cachepoints/lookup.c: online visibility learning (§3.2) and render-time light selection
 * (§3.3) over the structure the build produces (internal.h). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

/* ---------------------------------------------------------------- visibility (§3.2) */

float cachepoints_visibility_weight(float successes, uint32_t attempts, float r_min) {
    float r = (successes + 1.0f) / ((float)attempts + 1.0f); /* Eq. 5 */
    return r <= r_min ? (r / r_min) * (r / r_min) : 1.0f;           /* Eq. 6: never 0 */
}

/* Where light `light` lives at point p: near entry (*near = 1) or far entry (the one whose
 * key range holds the light's key); 0 when no entry of p holds it. */
static int locate(const CachePoints *cp, uint32_t p, uint32_t light, int *near, uint32_t *at) {
    uint32_t key = cp_key_of_light(cp, light);
    if (key == CP_NONE) return 0;
    uint32_t a0 = cp->near_off[p], a1 = cp->near_off[p + 1];
    uint32_t k = cp_lower_bound(cp->near_key, a0, a1, key);
    if (k < a1 && cp->near_key[k] == key) { *near = 1; *at = k; return 1; }
    /* the last far entry with key <= the light's key */
    uint32_t lo = cp->far_off[p], hi = cp->far_off[p + 1];
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (cp->far[mid].key <= key) lo = mid + 1;
        else hi = mid;
    }
    if (lo == cp->far_off[p]) return 0;
    const FarEntry *f = &cp->far[lo - 1];
    if (key >= cp_key_end(cp, f->key)) return 0;
    *near = 0;
    *at = lo - 1;
    return 1;
}

uint32_t cachepoints_slot(const CachePoints *cp, uint32_t point, uint32_t light) {
    int near;
    uint32_t at;
    if (!cp || point >= cp->n || !locate(cp, point, light, &near, &at)) return CP_NONE;
    return near ? cp->near_slot[at] : cp->far_slot[at];
}

void cachepoints_record(CachePoints *cp, uint32_t slot, float visibility) {
    /* a light no entry of the point holds (picked by the uniform floor) has no counters */
    if (!cp || slot >= cp->vis_off[cp->n]) return;
    VisCounter *h = &cp->vis_count[slot];
    float v = visibility > 0.0f ? (visibility < 1.0f ? visibility : 1.0f) : 0.0f; /* NaN: 0 */
    uint32_t success = (uint32_t)lrintf(v * (float)CP_VIS_ONE);
    __atomic_fetch_add(&h->total, 1u, __ATOMIC_RELAXED);
    if (success) __atomic_fetch_add(&h->success, success, __ATOMIC_RELAXED);
}

void cachepoints_prefetch_counters(const CachePoints *cp, uint32_t slot) {
    if (cp && slot < cp->vis_off[cp->n]) __builtin_prefetch(&cp->vis_count[slot], 1);
}

float cachepoints_visibility(const CachePoints *cp, uint32_t point, uint32_t light) {
    uint32_t slot = cachepoints_slot(cp, point, light);
    return slot == CP_NONE ? 1.0f : cp->w_blurred[slot];
}

typedef struct VisCtx { CachePoints *cp; uint32_t max_slots; int failed; } VisCtx;

/* Eqs. 5-6 of a slot (H_success back from fixed point: exact, as a float holds 256 k
 * exactly when it holds k); W = 1 without a division while too few attempts were made for
 * R to reach R_min (R >= 1 / (attempts + 1)). */
static inline float slot_weight(const CachePoints *cp, uint32_t s) {
    if (cp->w_pool) return cp->w_pool[s]; /* pooled at this barrier (pool.c) */
    uint32_t t = cp->vis_count[s].total;
    if ((float)t * cp->params.r_min + cp->params.r_min < 0.999f) return 1.0f;
    return cachepoints_visibility_weight((float)cp->vis_count[s].success / (float)CP_VIS_ONE, t, cp->params.r_min);
}

/* Per point: rescales the counters that passed CP_VIS_RESCALE attempts (see internal.h),
 * then flags the point if a slot has W < 1. */
static void vis_low_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    CachePoints *cp = ((VisCtx *)vctx)->cp;
    for (size_t p = b; p < e; ++p) {
        uint8_t low = 0;
        for (uint32_t s = cp->vis_off[p]; s < cp->vis_off[p + 1]; ++s) {
            VisCounter *h = &cp->vis_count[s];
            if (h->total > CP_VIS_RESCALE) {
                h->total = (h->total + 1) / 2;
                h->success /= 2;
            }
            if (!low) low = slot_weight(cp, s) < 1.0f;
        }
        cp->vis_low[p] = low;
    }
}

/* §3.2.2: W'(p,e) = w_p W(p,e) + sum over neighbours n holding key e of w_n W(n,e), with W
 * from Eqs. 5-6 on the counters and the normalised Eq. 4 weights of the far-bin blur.
 * Deviation from the paper: the sum is divided by the weights of the points that hold e
 * (p and the neighbours listing it). As printed, a neighbour without e adds 0, so a light
 * few neighbours list (typically a near light) would sink towards w_p <= 1/2 even when
 * fully visible; renormalised, a fully visible light keeps W' = 1. Hence also: a point
 * whose neighbourhood has W = 1 everywhere has W' = 1 everywhere, and is skipped (reset to
 * 1 if it was not), so early barriers cost next to nothing. Each neighbour's sorted slot
 * list is merged against p's in one linear walk. */
static void vis_blur_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    VisCtx *c = vctx;
    CachePoints *cp = c->cp;
    uint32_t K = cp->params.blur_neighbours;
    float *wsum = malloc(((size_t)c->max_slots + 1) * sizeof(float));
    if (!wsum) { c->failed = 1; return; }
    for (size_t p = b; p < e; ++p) {
        uint32_t s0 = cp->vis_off[p], s1 = cp->vis_off[p + 1];
        int need = cp->vis_low[p];
        for (uint32_t j = 0; j < K && !need; ++j) {
            uint32_t nb = cp->nbr[p * K + j];
            need = nb != CP_NONE && cp->vis_low[nb];
        }
        cp->tables_dirty[p] = (uint8_t)(need || cp->vis_active[p]);
        if (!need) {
            if (cp->vis_active[p])
                for (uint32_t s = s0; s < s1; ++s) cp->w_blurred[s] = 1.0f;
            cp->vis_active[p] = 0;
            continue;
        }
        cp->vis_active[p] = 1;
        for (uint32_t s = s0; s < s1; ++s) {
            cp->w_blurred[s] = cp->self_w[p] * slot_weight(cp, s);
            wsum[s - s0] = cp->self_w[p];
        }
        for (uint32_t j = 0; j < K; ++j) {
            uint32_t nb = cp->nbr[p * K + j];
            if (nb == CP_NONE) continue;
            float w = cp->nbr_w[p * K + j];
            int trivial = !cp->vis_low[nb]; /* every W of nb is 1 */
            uint32_t a = s0, q = cp->vis_off[nb], q1 = cp->vis_off[nb + 1];
            while (a < s1 && q < q1) {
                uint32_t ka = cp->vis_key[a], kq = cp->vis_key[q];
                if (ka < kq) ++a;
                else if (ka > kq) ++q;
                else {
                    cp->w_blurred[a] += w * (trivial ? 1.0f : slot_weight(cp, q));
                    wsum[a - s0] += w;
                    ++a; ++q;
                }
            }
        }
        for (uint32_t s = s0; s < s1; ++s) cp->w_blurred[s] /= wsum[s - s0];
    }
    free(wsum);
}

typedef struct TableCtx { CachePoints *cp; int all; } TableCtx;

/* Per point: W' of each near entry, and per bin the running sums of value x W'. The paper
 * builds the CDFs at lookup (§3.1.3, §3.3); they depend only on the point and W', so they
 * are built here once per barrier, for the points whose W' changed. */
static void tables_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    TableCtx *c = vctx;
    CachePoints *cp = c->cp;
    for (size_t p = b; p < e; ++p) {
        if (!c->all && !cp->tables_dirty[p]) continue;
        for (uint32_t k = cp->near_off[p]; k < cp->near_off[p + 1]; ++k) cp->near_vis[k] = cp->w_blurred[cp->near_slot[k]];
        for (int i = 0; i < CP_FAR_BINS; ++i) {
            double run = 0.0;
            for (uint32_t k = cp->far_off[p]; k < cp->far_off[p + 1]; ++k) {
                float v = cp->far[k].value[i];
                if (v > 0.0f && isfinite(v)) run += (double)(v * cp->w_blurred[cp->far_slot[k]]);
                *cp_cdf(cp, (uint32_t)p, i, k) = (float)run;
            }
            cp->far_bin_total[p * CP_BIN_STRIDE + i] =
                cp->far_off[p + 1] > cp->far_off[p] ? *cp_cdf(cp, (uint32_t)p, i, cp->far_off[p + 1] - 1) : 0.0f;
        }
    }
}

void cp_rebuild_tables(CachePoints *cp, int all) {
    TableCtx c = {cp, all};
    cp_run_parallel(&cp->params, cp->n, 256, tables_range, &c);
}

void cachepoints_update_visibility(CachePoints *cp) {
    if (!cp || !cp->params.visibility) return;
    VisCtx c = {cp, 0, 0};
    for (uint32_t p = 0; p < cp->n; ++p) {
        uint32_t s = cp->vis_off[p + 1] - cp->vis_off[p];
        if (s > c.max_slots) c.max_slots = s;
    }
    if (cp->params.pool_visibility && cp_pool_visibility(cp) != 0) c.failed = 1;
    if (!c.failed) cp_run_parallel(&cp->params, cp->n, 256, vis_low_range, &c);
    if (!c.failed) cp_run_parallel(&cp->params, cp->n, 256, vis_blur_range, &c);
    if (c.failed) { /* out of memory: W' = 1 everywhere rather than half-updated weights */
        for (uint32_t s = 0; s < cp->vis_off[cp->n]; ++s) cp->w_blurred[s] = 1.0f;
        memset(cp->vis_active, 0, cp->n);
        cp_rebuild_tables(cp, 1);
        return;
    }
    cp_rebuild_tables(cp, 0);
}

/* ---------------------------------------------------------------- selection (§3.3) */

/* §3.3 blends the cardinal bins by the similarity of each bin's axis a_i to the normal, with
 * weights summing to 1, without giving the function: b_i(n) = max(0, n.a_i)^2 sums to
 * |n|^2 = 1 for a unit normal. Without a normal (volumes, and here also transmissive
 * surfaces, whose lights may lie behind them) only the fluence bin. */
static void bin_blend(const float *n, float b[CP_FAR_BINS]) {
    for (int i = 0; i < CP_FAR_BINS; ++i) b[i] = 0.0f;
    if (!n) { b[CP_OMNI_BIN] = 1.0f; return; }
    b[0] = n[0] > 0.0f ? n[0] * n[0] : 0.0f;
    b[1] = n[0] < 0.0f ? n[0] * n[0] : 0.0f;
    b[2] = n[1] > 0.0f ? n[1] * n[1] : 0.0f;
    b[3] = n[1] < 0.0f ? n[1] * n[1] : 0.0f;
    b[4] = n[2] > 0.0f ? n[2] * n[2] : 0.0f;
    b[5] = n[2] < 0.0f ? n[2] * n[2] : 0.0f;
}

/* Exact weight of near entry k at the vertex: its estimate times W' (§3.3). */
static float near_weight(const CachePoints *cp, const CachePointLights *L, uint32_t k, const float x[3],
                         const float *n) {
    float w = L->estimate(L->user, cp->near_light[k], x, n);
    if (!(w > 0.0f) || !isfinite(w)) return 0.0f;
    return w * cp->near_vis[k];
}

/* Weight of far entry k of point p in bin i: the step of the running sums (what the binary
 * search realises), blended over the bins. Select and pmf both call this. */
static float far_weight(const CachePoints *cp, uint32_t p, uint32_t k, const float b[CP_FAR_BINS]) {
    float w = 0.0f;
    for (int i = 0; i < CP_FAR_BINS; ++i) {
        if (!(b[i] > 0.0f)) continue;
        const float *c = cp_cdf(cp, p, i, k);
        w += b[i] * (k > cp->far_off[p] ? c[0] - c[-1] : c[0]);
    }
    return w;
}

static float far_total(const CachePoints *cp, uint32_t p, const float b[CP_FAR_BINS]) {
    float t = 0.0f;
    const float *bt = cp->far_bin_total + (size_t)p * CP_BIN_STRIDE; /* == the last running sums */
    for (int i = 0; i < CP_FAR_BINS; ++i)
        if (b[i] > 0.0f) t += b[i] * bt[i];
    return t;
}

static inline float pmf_from(float w, float total, float eps, uint32_t count) {
    if (!(total > 0.0f)) return 1.0f / (float)count;
    return (1.0f - eps) * (w / total) + eps / (float)count;
}

uint32_t cachepoints_nearest(const CachePoints *cp, const float x[3]) {
    return kdtree_nearest(&cp->kd, x, NULL);
}

/* A vertex without a lobe (the paper's selection) until cachepoints_vertex_lobe says otherwise. */
static inline void lobe_clear(CachePointVertex *v) {
    v->lobe_axis[0] = v->lobe_axis[1] = v->lobe_axis[2] = 0.0f;
    v->lobe_sharpness = v->lobe_mix = v->lobe_total = 0.0f;
}

static void vertex_near(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                        CachePointVertex *v, float *near_w) {
    lobe_clear(v);
    float t = 0.0f;
    uint32_t k0 = cp->near_off[v->point];
    for (uint32_t k = k0; k < cp->near_off[v->point + 1]; ++k) {
        float w = near_weight(cp, L, k, x, n);
        if (near_w) near_w[k - k0] = w;
        t += w;
    }
    v->near_total = t;
}

/* The far bin that running target t falls in (bin weights b[i] times the point's bin totals
 * bt[i]; non-positive ones skipped), and in *cum the weight before it; -1 when every bin is
 * empty (light_weight and light_weight_linked walk the bins alike). */
static inline int far_bin_pick(const float b[CP_FAR_BINS], const float *bt, float t, float *cum) {
    int bin = -1;
    float c = 0.0f;
    for (int i = 0; i < CP_FAR_BINS; ++i) {
        float wi = b[i] > 0.0f ? b[i] * bt[i] : 0.0f;
        if (!(wi > 0.0f)) continue;
        bin = i;
        if (t < c + wi) break;
        c += wi;
    }
    *cum = c;
    return bin;
}

/* The nearest point to x (ties: lowest index), exactly kdtree_nearest_hint's answer. Hits
 * arrive sorted, so x is usually near the hint (the previous vertex's point): inside the
 * hint's clearance, among the hint and its blur neighbours (nbr_clear2, see blur.c), which
 * costs K + 1 distances instead of a tree walk; else the tree, bounded by the hint. The
 * distances are kd_dist2's float formula (kdtree.h), so ties resolve as the tree's do. */
uint32_t cp_nearest_point(const CachePoints *cp, const float x[3], uint32_t hint) {
    if (hint < cp->n && cp->nbr_clear2) {
        const float *h = cp->pos + 3 * (size_t)hint;
        float dx = h[0] - x[0], dy = h[1] - x[1], dz = h[2] - x[2];
        float best_d = dx * dx + dy * dy + dz * dz;
        if (best_d < cp->nbr_clear2[hint]) {
            uint32_t K = cp->params.blur_neighbours, best = hint;
            const uint32_t *nb = cp->nbr + (size_t)hint * K;
            for (uint32_t j = 0; j < K && nb[j] != CP_NONE; ++j) {
                const float *q = cp->pos + 3 * (size_t)nb[j];
                float ex = q[0] - x[0], ey = q[1] - x[1], ez = q[2] - x[2];
                float d = ex * ex + ey * ey + ez * ez;
                if (d < best_d || (d == best_d && nb[j] < best)) { best_d = d; best = nb[j]; }
            }
            return best;
        }
    }
    return kdtree_nearest_hint(&cp->kd, x, hint, NULL);
}

void cachepoints_vertex(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                        uint32_t hint, CachePointVertex *v, float *near_w) {
    v->point = cp_nearest_point(cp, x, hint);
    vertex_near(cp, L, x, n, v, near_w);
}

void cachepoints_vertex_reuse(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                              uint32_t point, CachePointVertex *v, float *near_w) {
    if (point < cp->n) {
        const float *c = cp->pos + 3 * (size_t)point;
        float d2 = (x[0] - c[0]) * (x[0] - c[0]) + (x[1] - c[1]) * (x[1] - c[1]) + (x[2] - c[2]) * (x[2] - c[2]);
        if (d2 <= cp->radius[point] * cp->radius[point]) {
            v->point = point;
            vertex_near(cp, L, x, n, v, near_w);
            return;
        }
    }
    cachepoints_vertex(cp, L, x, n, point < cp->n ? point : UINT32_MAX, v, near_w);
}

/* Weight of `light` at the vertex (0 when no entry holds it): near exact, or the far entry's
 * weight times the probability of descending from a cluster to the light. */
static float light_weight(const CachePoints *cp, const CachePointLights *L, uint32_t p, const float x[3],
                          const float *n, const float b[CP_FAR_BINS], uint32_t light, uint32_t *slot) {
    int near;
    uint32_t at;
    *slot = CP_NONE;
    if (!locate(cp, p, light, &near, &at)) return 0.0f;
    if (near) { *slot = cp->near_slot[at]; return near_weight(cp, L, at, x, n); }
    *slot = cp->far_slot[at];
    float w = far_weight(cp, p, at, b);
    uint32_t key = cp->far[at].key;
    if (cp_key_light(cp, key) == CP_NONE) w *= L->tree->descend_pmf(L->user, key, x, n, light);
    return w;
}

/* The paper's pick (§3.3) of the entry at `target` in [0, near_total + ft) of the normal-only
 * weights: near lights exact, then a far bin and an entry inside it by binary search over the
 * running sums; a cluster descends the tree. Returns the light (CP_NONE: none, rounding) with
 * its weight in *w and its visibility slot in *slot. */
static uint32_t pick_normal(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                            const CachePointVertex *v, const float *near_w, const float b[CP_FAR_BINS], float ft,
                            float target, float u_descend, float *w, uint32_t *slot) {
    uint32_t p = v->point, pick = CP_NONE;
    if (target < v->near_total) {
        float cum = 0.0f;
        for (uint32_t k = cp->near_off[p]; k < cp->near_off[p + 1]; ++k) {
            float wk = near_w ? near_w[k - cp->near_off[p]] : near_weight(cp, L, k, x, n);
            if (!(wk > 0.0f)) continue;
            cum += wk;
            pick = cp->near_light[k];
            *w = wk;
            *slot = cp->near_slot[k];
            if (target < cum) break;
        }
    }
    if (pick == CP_NONE && ft > 0.0f) {
        /* a bin, then an entry inside it by binary search over the running sums */
        float t = target > v->near_total ? target - v->near_total : 0.0f;
        float cum;
        uint32_t f0 = cp->far_off[p], f1 = cp->far_off[p + 1];
        const float *bt = cp->far_bin_total + (size_t)p * CP_BIN_STRIDE;
        int bin = far_bin_pick(b, bt, t, &cum);
        if (bin >= 0) {
            float tb = (t - cum) / b[bin];
            const float *cdf = cp_cdf(cp, p, bin, f0);
            uint32_t lo = 0, hi = f1 - f0;
            while (lo < hi) { /* first entry whose running sum exceeds tb */
                uint32_t mid = lo + (hi - lo) / 2;
                if (cdf[mid] <= tb) lo = mid + 1;
                else hi = mid;
            }
            if (lo >= f1 - f0) lo = f1 - f0 - 1;
            /* rounding may land on a zero-weight entry: step back to one with weight */
            while (lo > 0 && !(cdf[lo] > cdf[lo - 1])) --lo;
            uint32_t k = f0 + lo, key = cp->far[k].key;
            *w = far_weight(cp, p, k, b);
            *slot = cp->far_slot[k];
            pick = cp_key_light(cp, key);
            if (pick == CP_NONE) { /* a cluster: descend the light tree below it */
                float pd;
                pick = L->tree->descend(L->user, key, x, n, u_descend, &pd);
                *w *= pd;
            }
        }
    }
    return pick;
}

static uint32_t select_lobe(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                            const CachePointVertex *v, const float *near_w, float u, float u_descend, float *pmf,
                            uint32_t *slot);

uint32_t cachepoints_select(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                            const CachePointVertex *v, const float *near_w, float u, float u_descend, float *pmf,
                            uint32_t *slot) {
    if (v->lobe_mix > 0.0f) return select_lobe(cp, L, x, n, v, near_w, u, u_descend, pmf, slot);
    uint32_t N = L->count, p = v->point;
    float eps = cp->params.epsilon;
    float b[CP_FAR_BINS];
    bin_blend(n, b);
    float ft = far_total(cp, p, b), total = v->near_total + ft;
    uint32_t pick = CP_NONE;
    float w = 0.0f;
    *slot = CP_NONE;
    if (total > 0.0f && u >= eps) {
        float target = (u - eps) / (1.0f - eps) * total;
        pick = pick_normal(cp, L, x, n, v, near_w, b, ft, target, u_descend, &w, slot);
    }
    if (pick == CP_NONE || pick >= N) {
        /* the uniform floor (or rounding at the end of the tables) */
        float uu = total > 0.0f && u < eps ? u / eps : u;
        pick = (uint32_t)(uu * (float)N);
        if (pick >= N) pick = N - 1;
        w = light_weight(cp, L, p, x, n, b, pick, slot);
    }
    *pmf = pmf_from(w, total, eps, N);
    return pick;
}

static float pmf_lobe(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                      const CachePointVertex *v, uint32_t light);

float cachepoints_pmf(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                      const CachePointVertex *v, uint32_t light) {
    if (light >= L->count) return 0.0f;
    if (v->lobe_mix > 0.0f) return pmf_lobe(cp, L, x, n, v, light);
    float b[CP_FAR_BINS];
    bin_blend(n, b);
    float total = v->near_total + far_total(cp, v->point, b);
    uint32_t slot;
    return pmf_from(light_weight(cp, L, v->point, x, n, b, light, &slot), total, cp->params.epsilon, L->count);
}

/* ---------------------------------------------------------------- BSDF-aware selection (§6) */

#define CP_INV_4PI 0.0795774715f

/* The lobe's shape: a normalised density on the sphere around its axis with GGX's profile,
 *     D(c) = (1 + 2 lambda) / (4 pi) / (1 + lambda (1 - c))^2,   c = cos(angle to the axis),
 * which integrates to 1 over the sphere, peaks at (1 + 2 lambda) / (4 pi) and is uniform for
 * lambda = 0. Near the axis, 1 - c ~ t^2 / 2 and the mirror warp halves the half vector's angle,
 * so with lambda = 1 / (2 alpha^2 cos_o) (scatter_lobe.c) it is the GGX NDF's (1 + tan^2 t_h /
 * alpha^2)^-2. Its polynomial tail is GGX's too: a spherical Gaussian, whose tail falls like
 * e^(-lambda t^2 / 2), starved the lights a few lobe widths off the axis and measured worse
 * (glossy.gltf, 64 spp: 1.16x the MSE), and it needs no exp. */
static inline float lobe_peak(float lambda) { return (1.0f + 2.0f * lambda) * CP_INV_4PI; }

/* The lobe's mean density (1/sr) over a light or cluster bounded by the sphere (c, r) seen from
 * x (an infinite light: c its direction, r its angular radius). The sphere's cone, of half angle
 * t, widens the lobe: the lobe's width 1 / lambda and the cone's 1 / k add (as variances do when
 * two densities convolve), k = 4 / t^2 for a uniform cap of small t (E[t'^2] = t^2 / 2), here
 * 4 / sin^2 t - 2, which is 2 for a cone up to the horizon; evaluated at the cone's centre. x
 * inside the sphere: uniform. Select and pmf both call this. */
static float lobe_density(const CachePointVertex *v, const float x[3], const float *c, float r, int infinite) {
    float d0, d1, d2, inv_sin2;
    if (infinite) {
        if (!(r < 3.14159265f)) return CP_INV_4PI;
        d0 = c[0]; d1 = c[1]; d2 = c[2];
        float s = r < 1.57079633f ? sinf(r) : 1.0f;
        inv_sin2 = r > 0.0f ? 1.0f / (s * s) : INFINITY;
    } else {
        d0 = c[0] - x[0]; d1 = c[1] - x[1]; d2 = c[2] - x[2];
        float l2 = d0 * d0 + d1 * d1 + d2 * d2;
        if (!(l2 > r * r)) return CP_INV_4PI;
        float inv = 1.0f / sqrtf(l2);
        d0 *= inv; d1 *= inv; d2 *= inv;
        inv_sin2 = r > 0.0f ? l2 / (r * r) : INFINITY;
    }
    float lambda = v->lobe_sharpness;
    if (inv_sin2 < INFINITY) {
        float k = 4.0f * inv_sin2 - 2.0f;
        lambda = lambda * k / (lambda + k);
    }
    const float *a = v->lobe_axis;
    float t = 1.0f + lambda * (1.0f - (a[0] * d0 + a[1] * d1 + a[2] * d2));
    return lobe_peak(lambda) / (t * t);
}

/* The lobe density of near entry k / far entry k of the vertex (the spheres of keys: the
 * lights' bounds, and the boxes of light-tree clusters; cachepoints_prepare_lobes). */
static float near_lobe(const CachePoints *cp, const CachePointLights *L, const CachePointVertex *v, const float x[3],
                       uint32_t k) {
    uint32_t l = cp->near_light[k];
    const float *bd = L->bound + 4 * (size_t)l;
    return lobe_density(v, x, bd, bd[3], L->infinite[l]);
}

static float far_lobe(const CachePoints *cp, const CachePointLights *L, const CachePointVertex *v, const float x[3],
                      uint32_t k) {
    uint32_t key = cp->far[k].key, l = cp_key_light(cp, key);
    const float *bd = (cp->key_bound ? cp->key_bound : L->bound) + 4 * (size_t)key;
    return lobe_density(v, x, bd, bd[3], l != CP_NONE && L->infinite[l]);
}

int cachepoints_prepare_lobes(CachePoints *cp, const CachePointLights *L) {
    if (!cp || !L->bound) return -1;
    if (!cp->key_light || cp->key_bound) return 0; /* linear build: keys are lights */
    cp->key_bound = malloc(((size_t)cp->num_keys + 1) * 4 * sizeof(float));
    if (!cp->key_bound) return -1;
    for (uint32_t key = 0; key < cp->num_keys; ++key) {
        float *kb = cp->key_bound + 4 * (size_t)key;
        uint32_t l = cp->key_light[key];
        if (l != CP_NONE) {
            for (int i = 0; i < 4; ++i) kb[i] = L->bound[4 * (size_t)l + i];
            continue;
        }
        float lo[3], hi[3], e2 = 0.0f; /* a cluster: the sphere around its box */
        L->tree->node_bounds(L->user, key, lo, hi);
        for (int i = 0; i < 3; ++i) {
            kb[i] = 0.5f * (lo[i] + hi[i]);
            e2 += (hi[i] - lo[i]) * (hi[i] - lo[i]);
        }
        kb[3] = 0.5f * sqrtf(e2);
    }
    return 0;
}

/* Near weight of entry k (the prepared one when near_w is given). */
static inline float near_w_of(const CachePoints *cp, const CachePointLights *L, uint32_t k, const float x[3],
                              const float *n, const float *near_w, uint32_t k0) {
    return near_w ? near_w[k - k0] : near_weight(cp, L, k, x, n);
}

/* far_weight of every far entry of point p into w, bin by bin over the running sums (the same
 * sums in the same order as far_weight, so the same floats); 0 when the point has more than
 * CP_LOBE_BULK entries (then far_weight per entry). */
#define CP_LOBE_BULK 512
static int far_weights_bulk(const CachePoints *cp, uint32_t p, const float b[CP_FAR_BINS], float w[CP_LOBE_BULK]) {
    uint32_t f0 = cp->far_off[p], m = cp->far_off[p + 1] - f0;
    if (m > CP_LOBE_BULK) return 0;
    for (uint32_t j = 0; j < m; ++j) w[j] = 0.0f;
    for (int i = 0; i < CP_FAR_BINS; ++i) {
        if (!(b[i] > 0.0f) || m == 0) continue;
        const float *c = cp_cdf(cp, p, i, f0), bi = b[i];
        w[0] += bi * c[0];
        for (uint32_t j = 1; j < m; ++j) w[j] += bi * (c[j] - c[j - 1]);
    }
    return 1;
}

void cachepoints_vertex_lobe(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                             const float *near_w, const float axis[3], float sharpness, float kappa,
                             CachePointVertex *v) {
    lobe_clear(v);
    if (!n || !L->bound || (cp->key_light && !cp->key_bound) || !(kappa > 0.0f) || !(sharpness >= 0.0f) || !isfinite(sharpness)) return;
    float alen = sqrtf(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    if (!(alen > 0.5f) || !isfinite(alen)) return;
    /* D_e <= the lobe's peak density, so g <= kappa peak / (1 + kappa peak): skip the pass over
     * the entries when even that is below the minimum */
    float peak = lobe_peak(sharpness);
    if (kappa * peak < CACHEPOINTS_LOBE_MIN_MIX / (1.0f - CACHEPOINTS_LOBE_MIN_MIX)) return;
    float b[CP_FAR_BINS];
    bin_blend(n, b);
    uint32_t p = v->point;
    float total = v->near_total + far_total(cp, p, b);
    if (!(total > 0.0f)) return;
    v->lobe_axis[0] = axis[0]; v->lobe_axis[1] = axis[1]; v->lobe_axis[2] = axis[2];
    v->lobe_sharpness = sharpness;
    /* W_D, in the order select's scan accumulates it: near entries, then far entries */
    float tl = 0.0f;
    uint32_t k0 = cp->near_off[p];
    for (uint32_t k = k0; k < cp->near_off[p + 1]; ++k) {
        float w = near_w_of(cp, L, k, x, n, near_w, k0);
        if (w > 0.0f) tl += w * near_lobe(cp, L, v, x, k);
    }
    float fw[CP_LOBE_BULK];
    int bulk = far_weights_bulk(cp, p, b, fw);
    for (uint32_t k = cp->far_off[p], f0 = k; k < cp->far_off[p + 1]; ++k) {
        float w = bulk ? fw[k - f0] : far_weight(cp, p, k, b);
        if (w > 0.0f) tl += w * far_lobe(cp, L, v, x, k);
    }
    float g = tl > 0.0f && isfinite(tl) ? 1.0f / (1.0f + total / (kappa * tl)) : 0.0f;
    if (!(g >= CACHEPOINTS_LOBE_MIN_MIX)) { lobe_clear(v); return; }
    v->lobe_mix = g < CACHEPOINTS_LOBE_MAX_MIX ? g : CACHEPOINTS_LOBE_MAX_MIX;
    v->lobe_total = tl;
}

/* The mixture's probability of a light with normal-only weight wn and lobe weight wl. */
static inline float pmf_mix(const CachePointVertex *v, float wn, float wl, float total, float eps, uint32_t count) {
    float g = v->lobe_mix;
    return (1.0f - eps) * ((1.0f - g) * (wn / total) + g * (wl / v->lobe_total)) + eps / (float)count;
}

/* The normal-only weight of `light` at the vertex (as light_weight) and its lobe weight. */
static float light_weight_lobe(const CachePoints *cp, const CachePointLights *L, uint32_t p, const float x[3],
                               const float *n, const float b[CP_FAR_BINS], const CachePointVertex *v,
                               uint32_t light, float *wl, uint32_t *slot) {
    int near;
    uint32_t at;
    *wl = 0.0f;
    *slot = CP_NONE;
    if (!locate(cp, p, light, &near, &at)) return 0.0f;
    float wn;
    if (near) {
        *slot = cp->near_slot[at];
        wn = near_weight(cp, L, at, x, n);
        if (wn > 0.0f) *wl = wn * near_lobe(cp, L, v, x, at);
        return wn;
    }
    *slot = cp->far_slot[at];
    wn = far_weight(cp, p, at, b);
    uint32_t key = cp->far[at].key;
    if (cp_key_light(cp, key) == CP_NONE) wn *= L->tree->descend_pmf(L->user, key, x, n, light);
    if (wn > 0.0f) *wl = wn * far_lobe(cp, L, v, x, at);
    return wn;
}

/* The mixture: with probability g an entry in proportion to w_e D_e (one pass over the
 * entries, in the order of cachepoints_vertex_lobe's sum; a cluster then descends as usual),
 * else the paper's pick; the uniform floor as before. */
static uint32_t select_lobe(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                            const CachePointVertex *v, const float *near_w, float u, float u_descend, float *pmf,
                            uint32_t *slot) {
    uint32_t N = L->count, p = v->point;
    float eps = cp->params.epsilon, g = v->lobe_mix;
    float b[CP_FAR_BINS];
    bin_blend(n, b);
    float ft = far_total(cp, p, b), total = v->near_total + ft;
    uint32_t pick = CP_NONE;
    float wn = 0.0f, wl = 0.0f;
    *slot = CP_NONE;
    if (total > 0.0f && u >= eps) {
        float uu = (u - eps) / (1.0f - eps);
        if (uu >= g) { /* the paper's pick */
            float target = (uu - g) / (1.0f - g) * total;
            pick = pick_normal(cp, L, x, n, v, near_w, b, ft, target, u_descend, &wn, slot);
        } else { /* the lobe's pick */
            float target = uu / g * v->lobe_total, cum = 0.0f;
            uint32_t k0 = cp->near_off[p], at = CP_NONE;
            int near = 0;
            for (uint32_t k = k0; k < cp->near_off[p + 1]; ++k) {
                float w = near_w_of(cp, L, k, x, n, near_w, k0);
                if (!(w > 0.0f)) continue;
                float wk = w * near_lobe(cp, L, v, x, k);
                if (!(wk > 0.0f)) continue;
                cum += wk;
                at = k;
                near = 1;
                if (target < cum) break;
            }
            float fw[CP_LOBE_BULK];
            int bulk = !(target < cum) && far_weights_bulk(cp, p, b, fw);
            if (!(target < cum))
                for (uint32_t k = cp->far_off[p], f0 = k; k < cp->far_off[p + 1]; ++k) {
                    float w = bulk ? fw[k - f0] : far_weight(cp, p, k, b);
                    if (!(w > 0.0f)) continue;
                    float wk = w * far_lobe(cp, L, v, x, k);
                    if (!(wk > 0.0f)) continue;
                    cum += wk;
                    at = k;
                    near = 0;
                    if (target < cum) break;
                }
            if (at != CP_NONE && near) {
                pick = cp->near_light[at];
            } else if (at != CP_NONE) {
                uint32_t key = cp->far[at].key;
                pick = cp_key_light(cp, key);
                if (pick == CP_NONE) { /* a cluster: descend the light tree below it */
                    float pd;
                    pick = L->tree->descend(L->user, key, x, n, u_descend, &pd);
                }
            }
        }
    }
    if (pick == CP_NONE || pick >= N) {
        /* the uniform floor (or rounding at the end of the tables) */
        float uu = total > 0.0f && u < eps ? u / eps : u;
        pick = (uint32_t)(uu * (float)N);
        if (pick >= N) pick = N - 1;
    }
    /* both weights as pmf computes them (one function, so the two agree bit for bit) */
    wn = light_weight_lobe(cp, L, p, x, n, b, v, pick, &wl, slot);
    *pmf = total > 0.0f ? pmf_mix(v, wn, wl, total, eps, N) : 1.0f / (float)N;
    return pick;
}

static float pmf_lobe(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                      const CachePointVertex *v, uint32_t light) {
    float b[CP_FAR_BINS];
    bin_blend(n, b);
    float total = v->near_total + far_total(cp, v->point, b);
    if (!(total > 0.0f)) return 1.0f / (float)L->count;
    uint32_t slot;
    float wl, wn = light_weight_lobe(cp, L, v->point, x, n, b, v, light, &wl, &slot);
    return pmf_mix(v, wn, wl, total, cp->params.epsilon, L->count);
}

/* The bin blend of selection, for the read-only views of inspect.c. */
void cp_bin_blend(const float *n, float b[CP_FAR_BINS]) { bin_blend(n, b); }

/* ---------------------------------------------------------------- light linking (§3.3) */

/* The added-back weight of exclusive light j of the link at the vertex: its exact estimate when
 * no entry of point p holds it, else 0 (it is sampled through its entry). */
static float exclusive_weight(const CachePoints *cp, const CachePointLights *L, uint32_t p, const float x[3],
                              const float *n, const CachePointLink *link, uint32_t j) {
    int near;
    uint32_t at, light = link->exclusive[j];
    if (light >= L->count || locate(cp, p, light, &near, &at)) return 0.0f;
    float w = L->estimate(L->user, light, x, n);
    return w > 0.0f && isfinite(w) ? w : 0.0f;
}

static inline uint32_t num_exclusive(const CachePointLink *link) {
    return link->num_exclusive < CACHEPOINTS_MAX_EXCLUSIVE ? link->num_exclusive : CACHEPOINTS_MAX_EXCLUSIVE;
}

/* The near weights with the disabled lights at 0, plus the added-back exclusive lights. */
static void vertex_near_linked(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                               const CachePointLink *link, CachePointVertex *v, float *near_w) {
    lobe_clear(v);
    float t = 0.0f;
    uint32_t k0 = cp->near_off[v->point];
    for (uint32_t k = k0; k < cp->near_off[v->point + 1]; ++k) {
        float w = link->enabled[cp->near_light[k]] ? near_weight(cp, L, k, x, n) : 0.0f;
        if (near_w) near_w[k - k0] = w;
        t += w;
    }
    for (uint32_t j = 0; j < num_exclusive(link); ++j) t += exclusive_weight(cp, L, v->point, x, n, link, j);
    v->near_total = t;
}

void cachepoints_vertex_linked(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                               uint32_t hint, const CachePointLink *link, CachePointVertex *v, float *near_w) {
    v->point = cp_nearest_point(cp, x, hint);
    vertex_near_linked(cp, L, x, n, link, v, near_w);
}

void cachepoints_vertex_reuse_linked(const CachePoints *cp, const CachePointLights *L, const float x[3],
                                     const float *n, uint32_t point, const CachePointLink *link, CachePointVertex *v,
                                     float *near_w) {
    if (point < cp->n) {
        const float *c = cp->pos + 3 * (size_t)point;
        float d2 = (x[0] - c[0]) * (x[0] - c[0]) + (x[1] - c[1]) * (x[1] - c[1]) + (x[2] - c[2]) * (x[2] - c[2]);
        if (d2 <= cp->radius[point] * cp->radius[point]) {
            v->point = point;
            vertex_near_linked(cp, L, x, n, link, v, near_w);
            return;
        }
    }
    cachepoints_vertex_linked(cp, L, x, n, point < cp->n ? point : UINT32_MAX, link, v, near_w);
}

/* A further uniform in [0, 1) from u and an attempt number (a 32-bit finaliser of u's bits):
 * deterministic, so select is a function of its arguments. */
static inline float rehash_uniform(float u, uint32_t a) {
    uint32_t h;
    memcpy(&h, &u, sizeof h);
    h ^= a * 0x9e3779b9u;
    h ^= h >> 16; h *= 0x7feb352du; h ^= h >> 15; h *= 0x846ca68bu; h ^= h >> 16;
    return (float)(h >> 8) * 0x1p-24f;
}

/* Whether far entry k is a single light the vertex may not use. */
static inline int far_disabled(const CachePoints *cp, uint32_t k, const CachePointLink *link) {
    uint32_t l = cp_key_light(cp, cp->far[k].key);
    return l != CP_NONE && l < cp->num_lights && !link->enabled[l];
}

/* The step of bin i's running sums at far entry k (its weight in that bin). */
static inline float far_step(const CachePoints *cp, uint32_t p, int i, uint32_t k) {
    const float *c = cp_cdf(cp, p, i, k);
    return k > cp->far_off[p] ? c[0] - c[-1] : c[0];
}

/* A far cluster of the point that holds disabled lights, and their share d of its descent at
 * the vertex (the descent's probability of ending on one of them). */
typedef struct ClusterCut { uint32_t k; float d; } ClusterCut;

/* The vertex's cluster cuts, sorted by entry (none when the class disables more than
 * CP_LINK_MAX_CUT lights: clusters are then kept whole, and a descent onto a disabled light
 * takes no sample). For each disabled light held by a cluster of p, its descent pmf. */
#define CP_LINK_MAX_CUT 64
#define CP_LINK_ATTEMPTS 4 /* descents per cluster pick before giving up (no sample) */
static uint32_t cluster_cuts(const CachePoints *cp, const CachePointLights *L, uint32_t p, const float x[3],
                             const float *n, const CachePointLink *link, ClusterCut cut[CP_LINK_MAX_CUT]) {
    if (!cp->key_light || !L->tree || !link->disabled || link->num_disabled > CP_LINK_MAX_CUT) return 0;
    uint32_t m = 0;
    for (uint32_t j = 0; j < link->num_disabled; ++j) {
        int near;
        uint32_t at, d = link->disabled[j];
        if (!locate(cp, p, d, &near, &at) || near || cp_key_light(cp, cp->far[at].key) != CP_NONE) continue;
        float pd = L->tree->descend_pmf(L->user, cp->far[at].key, x, n, d);
        if (!(pd > 0.0f)) continue;
        uint32_t i = 0;
        while (i < m && cut[i].k < at) ++i;
        if (i < m && cut[i].k == at) { cut[i].d += pd; continue; }
        memmove(cut + i + 1, cut + i, (m - i) * sizeof *cut);
        cut[i] = (ClusterCut){at, pd};
        ++m;
    }
    for (uint32_t i = 0; i < m; ++i) cut[i].d = fminf(fmaxf(cut[i].d, 0.0f), 1.0f);
    return m;
}

static float cut_of(const ClusterCut *cut, uint32_t m, uint32_t k) {
    for (uint32_t i = 0; i < m; ++i)
        if (cut[i].k == k) return cut[i].d;
    return 0.0f;
}

/* The cluster is picked with its enabled share (1 - d) of its weight, and CP_LINK_ATTEMPTS
 * descents end on `light` with probability p_descend(light) (1 + d + d^2 + d^3): its weight at
 * the vertex is the entry's times p_descend(light) times this, 1 - d^4. */
static inline float attempts_gain(float d) {
    float dm = d * d;
    return d > 0.0f ? 1.0f - dm * dm : 1.0f;
}

/* The bin totals of point p without its disabled single-light entries and without the disabled
 * shares of its clusters (one pass over the far list: the disabled singles are found where
 * they are, whatever their number). */
static void far_bin_totals_linked(const CachePoints *cp, uint32_t p, const float b[CP_FAR_BINS],
                                  const CachePointLink *link, const ClusterCut *cut, uint32_t ncut,
                                  float bt[CP_FAR_BINS]) {
    const float *t = cp->far_bin_total + (size_t)p * CP_BIN_STRIDE;
    float dis[CP_FAR_BINS] = {0};
    for (uint32_t k = cp->far_off[p]; k < cp->far_off[p + 1]; ++k) {
        if (!far_disabled(cp, k, link)) continue;
        for (int i = 0; i < CP_FAR_BINS; ++i)
            if (b[i] > 0.0f) dis[i] += far_step(cp, p, i, k);
    }
    for (uint32_t c = 0; c < ncut; ++c)
        for (int i = 0; i < CP_FAR_BINS; ++i)
            if (b[i] > 0.0f) dis[i] += far_step(cp, p, i, cut[c].k) * cut[c].d;
    for (int i = 0; i < CP_FAR_BINS; ++i) bt[i] = b[i] > 0.0f ? fmaxf(t[i] - dis[i], 0.0f) : 0.0f;
}

static float far_total_linked(const float b[CP_FAR_BINS], const float bt[CP_FAR_BINS]) {
    float t = 0.0f;
    for (int i = 0; i < CP_FAR_BINS; ++i)
        if (b[i] > 0.0f) t += b[i] * bt[i];
    return t;
}

/* Weight of an enabled `light` at the vertex (as light_weight; 0 for a disabled one). */
static float light_weight_linked(const CachePoints *cp, const CachePointLights *L, uint32_t p, const float x[3],
                                 const float *n, const float b[CP_FAR_BINS], const CachePointLink *link,
                                 const ClusterCut *cut, uint32_t ncut, uint32_t light, uint32_t *slot) {
    *slot = CP_NONE;
    if (light >= L->count || !link->enabled[light]) return 0.0f;
    int near;
    uint32_t at;
    if (!locate(cp, p, light, &near, &at)) { /* an added-back exclusive light, or none */
        uint32_t lo = 0, hi = num_exclusive(link);
        while (lo < hi) {
            uint32_t mid = lo + (hi - lo) / 2;
            if (link->exclusive[mid] < light) lo = mid + 1;
            else hi = mid;
        }
        return lo < num_exclusive(link) && link->exclusive[lo] == light ? exclusive_weight(cp, L, p, x, n, link, lo)
                                                                        : 0.0f;
    }
    float w = light_weight(cp, L, p, x, n, b, light, slot);
    /* a cluster with disabled lights: picked with its enabled share, then up to
     * CP_LINK_ATTEMPTS descents until one ends on an enabled light */
    if (!near && ncut) w *= attempts_gain(cut_of(cut, ncut, at));
    return w;
}

uint32_t cachepoints_select_linked(const CachePoints *cp, const CachePointLights *L, const float x[3],
                                   const float *n, const CachePointVertex *v, const float *near_w,
                                   const CachePointLink *link, float u, float u_descend, float *pmf, uint32_t *slot) {
    uint32_t N = link->count, p = v->point;
    float eps = cp->params.epsilon;
    *slot = CP_NONE;
    if (!N) { *pmf = 0.0f; return 0; }
    float b[CP_FAR_BINS], bt[CP_FAR_BINS];
    bin_blend(n, b);
    ClusterCut cut[CP_LINK_MAX_CUT];
    uint32_t ncut = cluster_cuts(cp, L, p, x, n, link, cut);
    far_bin_totals_linked(cp, p, b, link, cut, ncut, bt);
    float ft = far_total_linked(b, bt), total = v->near_total + ft;
    uint32_t pick = CP_NONE;
    float w = 0.0f;
    if (total > 0.0f && u >= eps) {
        float target = (u - eps) / (1.0f - eps) * total;
        if (target < v->near_total) {
            float cum = 0.0f;
            for (uint32_t k = cp->near_off[p]; k < cp->near_off[p + 1]; ++k) {
                float wk = near_w ? near_w[k - cp->near_off[p]]
                                  : (link->enabled[cp->near_light[k]] ? near_weight(cp, L, k, x, n) : 0.0f);
                if (!(wk > 0.0f)) continue;
                cum += wk;
                pick = cp->near_light[k];
                w = wk;
                *slot = cp->near_slot[k];
                if (target < cum) break;
            }
            if (!(target < cum)) /* then the added-back exclusive lights (no visibility slot) */
                for (uint32_t j = 0; j < num_exclusive(link); ++j) {
                    float wj = exclusive_weight(cp, L, p, x, n, link, j);
                    if (!(wj > 0.0f)) continue;
                    cum += wj;
                    pick = link->exclusive[j];
                    w = wj;
                    *slot = CP_NONE;
                    if (target < cum) break;
                }
        }
        if (pick == CP_NONE && ft > 0.0f) {
            float t = target > v->near_total ? target - v->near_total : 0.0f;
            float cum;
            int bin = far_bin_pick(b, bt, t, &cum);
            if (bin >= 0) {
                uint32_t f0 = cp->far_off[p], f1 = cp->far_off[p + 1];
                const float *cdf = cp_cdf(cp, p, bin, f0);
                /* a position in the bin without the disabled entries, carried past each disabled
                 * entry's interval (in entry order) into the bin's own running sums */
                float tb = fminf((t - cum) / b[bin], bt[bin]);
                for (uint32_t k = f0, c = 0; k < f1; ++k) {
                    float start = k > f0 ? cdf[k - f0 - 1] : 0.0f, step = cdf[k - f0] - start;
                    if (far_disabled(cp, k, link)) {
                        if (tb >= start) tb += step;
                    } else if (c < ncut && cut[c].k == k) { /* the cluster's disabled share: its interval's tail */
                        float keep = step * (1.0f - cut[c].d);
                        if (tb >= start + keep) tb += step - keep;
                        ++c;
                    }
                }
                uint32_t lo = 0, hi = f1 - f0;
                while (lo < hi) {
                    uint32_t mid = lo + (hi - lo) / 2;
                    if (cdf[mid] <= tb) lo = mid + 1;
                    else hi = mid;
                }
                if (lo >= f1 - f0) lo = f1 - f0 - 1;
                /* rounding may land on a zero-weight or disabled entry: step back to a usable one */
                while (lo > 0 && (!(cdf[lo] > cdf[lo - 1]) || far_disabled(cp, f0 + lo, link))) --lo;
                uint32_t k = f0 + lo, key = cp->far[k].key;
                if (!far_disabled(cp, k, link) && (lo > 0 ? cdf[lo] > cdf[lo - 1] : cdf[0] > 0.0f)) {
                    w = far_weight(cp, p, k, b);
                    *slot = cp->far_slot[k];
                    pick = cp_key_light(cp, key);
                    if (pick == CP_NONE) { /* a cluster: descend below it; it may hold disabled lights */
                        float pd, d = cut_of(cut, ncut, k);
                        pick = L->tree->descend(L->user, key, x, n, u_descend, &pd);
                        /* a cut cluster: further descents (their numbers hashed from u_descend)
                         * until one ends on an enabled light; attempts_gain is what that gives */
                        for (uint32_t a = 1; d > 0.0f && a < CP_LINK_ATTEMPTS && (pick >= L->count || !link->enabled[pick]); ++a)
                            pick = L->tree->descend(L->user, key, x, n, rehash_uniform(u_descend, a), &pd);
                        if (pick >= L->count || !link->enabled[pick]) { *slot = CP_NONE; *pmf = 0.0f; return 0; }
                        w *= pd * attempts_gain(d);
                    }
                }
            }
        }
    }
    if (pick == CP_NONE || pick >= L->count) {
        /* the uniform floor over the enabled lights (or rounding at the end of the tables) */
        float uu = total > 0.0f && u < eps ? u / eps : u;
        uint32_t i = (uint32_t)(uu * (float)N);
        if (i >= N) i = N - 1;
        pick = link->lights[i];
        w = light_weight_linked(cp, L, p, x, n, b, link, cut, ncut, pick, slot);
    }
    *pmf = pmf_from(w, total, eps, N);
    return pick;
}

float cachepoints_pmf_linked(const CachePoints *cp, const CachePointLights *L, const float x[3], const float *n,
                             const CachePointVertex *v, const CachePointLink *link, uint32_t light) {
    if (light >= L->count || !link->enabled[light] || !link->count) return 0.0f;
    float b[CP_FAR_BINS], bt[CP_FAR_BINS];
    bin_blend(n, b);
    ClusterCut cut[CP_LINK_MAX_CUT];
    uint32_t ncut = cluster_cuts(cp, L, v->point, x, n, link, cut);
    far_bin_totals_linked(cp, v->point, b, link, cut, ncut, bt);
    float total = v->near_total + far_total_linked(b, bt);
    uint32_t slot;
    return pmf_from(light_weight_linked(cp, L, v->point, x, n, b, link, cut, ncut, light, &slot), total,
                    cp->params.epsilon, link->count);
}
