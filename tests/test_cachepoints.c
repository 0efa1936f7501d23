/* The cachepoints module on its own, with synthetic point lights and two directional
 * lights, for both builds (linear: the paper's; cut: far entries are clusters of a light
 * tree, here a synthetic balanced tree whose cluster estimate is the exact sum and whose
 * descent is proportional to it): Eqs. 5-6 anchor values, the build's return codes, build
 * determinism (serial vs a parallel-for that runs chunks in reverse order), PMFs that sum
 * to one, select/pmf agreement and selection frequencies, visibility learning pushing down
 * a light that is never visible, and fractional visibility outcomes (fixed-point counters,
 * exact for 0/1 outcomes, and their rescale). BSDF-aware selection (cachepoints_vertex_lobe):
 * pmfs sum to one, select reports exactly pmf() (with and without the prepared near weights),
 * selection frequencies follow pmf, no light falls below (1 - CACHEPOINTS_LOBE_MAX_MIX) of its
 * normal-only probability, the lobe moves probability toward lights along its axis, and a vertex
 * the lobe leaves alone selects bit for bit as without it. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "cachepoints.h"
#include "check.h"
#include "internal.h" /* the visibility counters, for the fixed-point and rescale checks */
#include "stats.h"

static uint64_t sm_state;
static double rnd(void) { return splitmix_uniform(&sm_state); }

#define NL 302 /* 300 point lights, then 2 directional lights */
#define NPOINT 300
static float light_pos[3 * NL], light_I[NL];
static uint8_t light_inf[NL];

static float point_estimate(const void *user, uint32_t l, const float x[3], const float *n) {
    (void)user;
    float d[3] = {light_pos[3 * l] - x[0], light_pos[3 * l + 1] - x[1], light_pos[3 * l + 2] - x[2]};
    float d2 = 1.0f;
    if (!light_inf[l]) { /* a point light; a directional light's "position" is its direction to it */
        d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        if (!(d2 > 1e-8f)) return 0.0f;
    } else {
        memcpy(d, light_pos + 3 * l, sizeof d);
    }
    float c = 1.0f;
    if (n) { c = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]) / sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]); if (c < 0.0f) c = 0.0f; }
    return light_I[l] * c / d2;
}

static const float AXES[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};

static void point_estimate7(const void *user, uint32_t l, const float x[3], float out[7]) {
    for (int i = 0; i < 6; ++i) out[i] = point_estimate(user, l, x, AXES[i]);
    out[6] = point_estimate(user, l, x, NULL);
}

/* ---- a balanced binary tree over the 300 point lights, depth-first layout */
#define MAXNODES (2 * NPOINT)
static uint32_t order[NPOINT];              /* lights in tree order */
static uint32_t node_lo[MAXNODES], node_hi[MAXNODES], second[MAXNODES], leaf_light[MAXNODES], light_leaf[NL];
static float node_box[MAXNODES][6];
static uint32_t node_count;

static int cmp_axis;
static int cmp_light(const void *a, const void *b) {
    float pa = light_pos[3 * *(const uint32_t *)a + cmp_axis], pb = light_pos[3 * *(const uint32_t *)b + cmp_axis];
    return pa < pb ? -1 : pa > pb;
}

static uint32_t build_node(uint32_t lo, uint32_t hi, int depth) {
    uint32_t idx = node_count++;
    node_lo[idx] = lo;
    node_hi[idx] = hi;
    for (int k = 0; k < 3; ++k) { node_box[idx][k] = INFINITY; node_box[idx][3 + k] = -INFINITY; }
    for (uint32_t i = lo; i < hi; ++i)
        for (int k = 0; k < 3; ++k) {
            node_box[idx][k] = fminf(node_box[idx][k], light_pos[3 * order[i] + k]);
            node_box[idx][3 + k] = fmaxf(node_box[idx][3 + k], light_pos[3 * order[i] + k]);
        }
    if (hi - lo == 1) {
        second[idx] = 0;
        leaf_light[idx] = order[lo];
        light_leaf[order[lo]] = idx;
        return idx;
    }
    cmp_axis = depth % 3;
    qsort(order + lo, hi - lo, sizeof *order, cmp_light);
    uint32_t mid = lo + (hi - lo) / 2;
    leaf_light[idx] = UINT32_MAX;
    build_node(lo, mid, depth + 1);
    second[idx] = build_node(mid, hi, depth + 1);
    return idx;
}

static void tree_bounds(const void *user, uint32_t node, float lo[3], float hi[3]) {
    (void)user;
    memcpy(lo, node_box[node], 3 * sizeof(float));
    memcpy(hi, node_box[node] + 3, 3 * sizeof(float));
}

static void tree_estimate7(const void *user, uint32_t node, const float x[3], float out[7]) {
    for (int i = 0; i < 7; ++i) out[i] = 0.0f;
    for (uint32_t k = node_lo[node]; k < node_hi[node]; ++k) {
        float v[7];
        point_estimate7(user, order[k], x, v);
        for (int i = 0; i < 7; ++i) out[i] += v[i];
    }
}

/* child weight: the subtree's summed estimate plus a floor, so every light can be reached */
static float subtree_weight(uint32_t node, const float x[3], const float *n) {
    float w = 1e-3f * (float)(node_hi[node] - node_lo[node]);
    for (uint32_t k = node_lo[node]; k < node_hi[node]; ++k) w += point_estimate(NULL, order[k], x, n);
    return w;
}

static uint32_t tree_descend(const void *user, uint32_t node, const float x[3], const float *n, float u, float *pmf) {
    (void)user;
    float pr = 1.0f;
    while (leaf_light[node] == UINT32_MAX) {
        float w0 = subtree_weight(node + 1, x, n), w1 = subtree_weight(second[node], x, n);
        float p0 = w0 / (w0 + w1);
        if (u < p0) { pr *= p0; u = u / p0; node = node + 1; }
        else { pr *= 1.0f - p0; u = (u - p0) / (1.0f - p0); node = second[node]; }
        if (u >= 1.0f) u = 0x1.fffffep-1f;
    }
    *pmf = pr;
    return leaf_light[node];
}

static float tree_descend_pmf(const void *user, uint32_t node, const float x[3], const float *n, uint32_t light) {
    (void)user;
    uint32_t target = light_leaf[light];
    float pr = 1.0f;
    while (leaf_light[node] == UINT32_MAX) {
        float w0 = subtree_weight(node + 1, x, n), w1 = subtree_weight(second[node], x, n);
        float p0 = w0 / (w0 + w1);
        if (target < second[node]) { pr *= p0; node = node + 1; }
        else { pr *= 1.0f - p0; node = second[node]; }
    }
    return leaf_light[node] == light ? pr : 0.0f;
}

/* runs chunks of 7 items in reverse order: a build that depended on order would differ */
static void reverse_parallel_for(void *pool, size_t n, size_t grain, void (*fn)(void *, size_t, size_t, int), void *ctx) {
    (void)pool; (void)grain;
    size_t chunk = 7;
    size_t count = (n + chunk - 1) / chunk;
    for (size_t c = count; c-- > 0;) fn(ctx, c * chunk, c * chunk + chunk < n ? c * chunk + chunk : n, (int)(c % 2));
}

static void random_vertex(float x[3], float nrm[3], const float **n, int q) {
    for (int k = 0; k < 3; ++k) x[k] = (float)(rnd() * 10);
    for (int k = 0; k < 3; ++k) nrm[k] = (float)(rnd() - 0.5);
    float len = sqrtf(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
    for (int k = 0; k < 3; ++k) nrm[k] /= len;
    *n = q % 3 == 0 ? NULL : nrm;
}

/* Eqs. 5-6 as they were computed from integer counters before fractional outcomes. */
static float integer_weight(uint32_t successes, uint32_t attempts, float r_min) {
    float r = ((float)successes + 1.0f) / ((float)attempts + 1.0f);
    return r <= r_min ? (r / r_min) * (r / r_min) : 1.0f;
}

static int cmp_u32(const void *a, const void *b) {
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return x < y ? -1 : x > y;
}

/* Every distinct visibility slot of every point receives `count` records of `vis`, so that
 * all points holding a light agree and the visibility blur leaves W' = W (up to rounding). */
static void record_everywhere(CachePoints *cp, int count, float vis) {
    uint32_t slots[NL];
    for (uint32_t p = 0; p < cachepoints_count(cp); ++p) {
        uint32_t m = 0;
        for (uint32_t l = 0; l < NL; ++l) {
            uint32_t s = cachepoints_slot(cp, p, l);
            if (s != UINT32_MAX) slots[m++] = s;
        }
        qsort(slots, m, sizeof *slots, cmp_u32);
        for (uint32_t k = 0; k < m; ++k)
            if (k == 0 || slots[k] != slots[k - 1])
                for (int t = 0; t < count; ++t) cachepoints_record(cp, slots[k], vis);
    }
}

/* Fractional outcomes (a transmittance) in fixed point: 100 attempts at visibility 0.02 add
 * 100 x lrint(0.02 x 256) / 256 = 1.953 successes; 0/1 outcomes give exactly the integer
 * counts; the barrier's rescale halves a slot past 2^23 attempts and keeps W. */
static void fractional_visibility(const CachePointLights *L, const float *cand, uint32_t nc, const CachePointParams *P,
                                  const char *mode) {
    CachePointCamera cam = {{5.0f, 5.0f, 40.0f}, 2.0f * 0.4f / 64.0f, 0.0f};
    CachePoints *f = NULL, *z = NULL;
    int rf = cachepoints_build(&f, cand, nc, L, &cam, P, NULL), rz = cachepoints_build(&z, cand, nc, L, &cam, P, NULL);
    CHECK(rf == 0 && rz == 0, "%s: build %d %d", mode, rf, rz);
    if (rf || rz) { cachepoints_free(f); cachepoints_free(z); return; }
    const float x0[3] = {5, 5, 5};
    uint32_t p0 = cachepoints_nearest(f, x0), l0 = 0;
    while (l0 < NL && cachepoints_slot(f, p0, l0) == UINT32_MAX) ++l0;
    CHECK(l0 < NL, "%s: no light has a slot at x0", mode);
    if (l0 == NL) { cachepoints_free(f); cachepoints_free(z); return; }
    uint32_t s0 = cachepoints_slot(f, p0, l0);

    record_everywhere(f, 100, 0.02f);
    CHECK(f->vis_count[s0].total == 100 && f->vis_count[s0].success == 500, "%s: 100 x 0.02 counted %u / %u (fixed point)",
          mode, f->vis_count[s0].success, f->vis_count[s0].total);
    cachepoints_update_visibility(f);
    float wf = cachepoints_visibility(f, p0, l0), expect = cachepoints_visibility_weight(500.0f / 256.0f, 100, 0.04f);
    CHECK(fabsf(wf - expect) < 1e-5f, "%s: W' after 100 x 0.02 = %g, expected %g", mode, wf, expect);
    CHECK(wf < 0.6f && wf > integer_weight(1, 100, 0.04f) && wf < integer_weight(2, 100, 0.04f),
          "%s: 100 x 0.02 lies between 1 and 2 visible of 100: W' = %g", mode, wf);

    record_everywhere(z, 2, 1.0f);
    record_everywhere(z, 98, 0.0f);
    CHECK(z->vis_count[s0].total == 100 && z->vis_count[s0].success == 2 * 256, "%s: 2 of 100 counted %u / %u", mode,
          z->vis_count[s0].success, z->vis_count[s0].total);
    cachepoints_update_visibility(z);
    float wz = cachepoints_visibility(z, p0, l0);
    CHECK(fabsf(wz - integer_weight(2, 100, 0.04f)) < 1e-5f, "%s: W' after 2 of 100 = %g, expected %g", mode, wz,
          integer_weight(2, 100, 0.04f));

    /* rescale: total past 2^23 halves both (total rounded up) at the barrier */
    uint32_t t = (1u << 23) + 3, sc = (uint32_t)(0.02 * 256.0 * t);
    z->vis_count[s0].total = t;
    z->vis_count[s0].success = sc;
    float before = cachepoints_visibility_weight((float)sc / 256.0f, t, 0.04f);
    cachepoints_update_visibility(z);
    CHECK(z->vis_count[s0].total == (t + 1) / 2 && z->vis_count[s0].success == sc / 2, "%s: rescaled to %u / %u", mode,
          z->vis_count[s0].success, z->vis_count[s0].total);
    float after = cachepoints_visibility_weight((float)z->vis_count[s0].success / 256.0f, z->vis_count[s0].total, 0.04f);
    CHECK(fabsf(after - before) < 1e-4f * before && before < 0.3f, "%s: the rescale keeps W (%g -> %g)", mode, before, after);
    cachepoints_free(f);
    cachepoints_free(z);
}

/* Pooled visibility (pool.c): 10 failed attempts per slot leave every W' = 1 without pooling
 * (Eq. 6 needs 25); with it a slot's W is Eq. 6 on its counters pooled over its blur
 * neighbours holding the same key (checked against the sums computed here), below 1; a slot
 * with 25+ attempts of its own keeps its own W; bit-identical for a reversed parallel-for and
 * after a checkpoint save / load. */
static void progressive_insertion(const CachePointLights *L, const float *cand, uint32_t nc, const CachePointParams *P0,
                                  const char *mode);
static void pooled_visibility(const CachePointLights *L, const float *cand, uint32_t nc, const CachePointParams *P0,
                              const char *mode) {
    CachePointCamera cam = {{5.0f, 5.0f, 40.0f}, 2.0f * 0.4f / 64.0f, 0.0f};
    CachePointParams P = *P0, Q = *P0;
    Q.pool_visibility = 1;
    CachePointParams R = Q;
    R.parallel_for = reverse_parallel_for;
    CachePoints *off = NULL, *on = NULL, *rev = NULL, *own = NULL, *res = NULL;
    int rc = cachepoints_build(&off, cand, nc, L, &cam, &P, NULL) | cachepoints_build(&on, cand, nc, L, &cam, &Q, NULL) |
             cachepoints_build(&rev, cand, nc, L, &cam, &R, NULL) | cachepoints_build(&own, cand, nc, L, &cam, &Q, NULL) |
             cachepoints_build(&res, cand, nc, L, &cam, &Q, NULL);
    CHECK(rc == 0, "%s: pooled builds", mode);
    if (rc == 0) {
        record_everywhere(off, 10, 0.0f);
        record_everywhere(on, 10, 0.0f);
        record_everywhere(rev, 10, 0.0f);
        cachepoints_update_visibility(off);
        cachepoints_update_visibility(on);
        cachepoints_update_visibility(rev);
        uint32_t v = on->vis_off[on->n], low_off = 0, low_on = 0, exact = 0, checked = 0;
        for (uint32_t s = 0; s < v; ++s) {
            low_off += off->w_blurred[s] < 1.0f;
            low_on += on->w_blurred[s] < 1.0f;
        }
        CHECK(low_off == 0, "%s: without pooling %u slots learned from 10 attempts", mode, low_off);
        CHECK(low_on > v / 2, "%s: with pooling only %u of %u slots learned", mode, low_on, v);
        CHECK(memcmp(on->w_blurred, rev->w_blurred, v * sizeof(float)) == 0 &&
                  memcmp(on->w_pool, rev->w_pool, v * sizeof(float)) == 0,
              "%s: pooled W differs with the parallel-for order", mode);
        /* the pooled W of every slot against the sums recomputed here */
        uint32_t K = on->params.blur_neighbours;
        for (uint32_t p = 0; p < on->n; ++p)
            for (uint32_t s = on->vis_off[p]; s < on->vis_off[p + 1]; ++s) {
                double T = 10.0;
                for (uint32_t j = 0; j < K; ++j) {
                    uint32_t nb = on->nbr[p * K + j];
                    if (nb == UINT32_MAX) continue;
                    for (uint32_t q = on->vis_off[nb]; q < on->vis_off[nb + 1]; ++q)
                        if (on->vis_key[q] == on->vis_key[s]) T += (double)on->nbr_w[p * K + j] / on->self_w[p] * 10.0;
                }
                float r = (float)(1.0 / (T + 1.0)), w = r <= 0.04f ? (r / 0.04f) * (r / 0.04f) : 1.0f;
                exact += fabsf(on->w_pool[s] - w) <= 1e-6f * w;
                ++checked;
            }
        CHECK(exact == checked, "%s: %u of %u pooled W match the recomputed sums", mode, exact, checked);
        /* a slot with 30 visible attempts of its own among failing neighbours keeps W = 1 */
        record_everywhere(own, 10, 0.0f);
        const float x0[3] = {5, 5, 5};
        uint32_t p0 = cachepoints_nearest(own, x0), s0 = own->vis_off[p0];
        own->vis_count[s0].total = 30;
        own->vis_count[s0].success = 30 * 256;
        cachepoints_update_visibility(own);
        CHECK(own->w_pool[s0] == 1.0f, "%s: a slot with 30 visible attempts pooled to %g", mode, own->w_pool[s0]);
        /* checkpoint: save after one barrier, load into a fresh build, go on: the same W' */
        FILE *f = tmpfile();
        CHECK(f && cachepoints_save_learned(on, f) == 0, "%s: save", mode);
        if (f) {
            rewind(f);
            CHECK(cachepoints_load_learned(res, f) == 0, "%s: load", mode);
            fclose(f);
            record_everywhere(on, 5, 1.0f);
            record_everywhere(res, 5, 1.0f);
            cachepoints_update_visibility(on);
            cachepoints_update_visibility(res);
            CHECK(memcmp(on->w_blurred, res->w_blurred, v * sizeof(float)) == 0 &&
                      memcmp(on->far_cdf, res->far_cdf, (size_t)on->far_off[on->n] * 7 * sizeof(float)) == 0,
                  "%s: pooled learning differs after a checkpoint", mode);
        }
        fprintf(stderr, "%s: pooling: %u of %u slots below W' = 1 after 10 failures each (0 without)\n", mode, low_on, v);
    }
    /* mode 2 (cut build): one failure per slot is too little for the spatial pooling alone
     * (about 9 pooled attempts); the light tree's levels bring in the nearby lights' */
    if (rc == 0 && P0->build_cut) {
        CachePointParams M = Q, Mr = Q;
        M.pool_visibility = 2;
        Mr.pool_visibility = 2;
        Mr.parallel_for = reverse_parallel_for;
        CachePoints *m1 = NULL, *m2 = NULL, *m2r = NULL;
        int r2 = cachepoints_build(&m1, cand, nc, L, &cam, &Q, NULL) | cachepoints_build(&m2, cand, nc, L, &cam, &M, NULL) |
                 cachepoints_build(&m2r, cand, nc, L, &cam, &Mr, NULL);
        CHECK(r2 == 0, "%s: mode 2 builds", mode);
        if (r2 == 0) {
            record_everywhere(m1, 1, 0.0f);
            record_everywhere(m2, 1, 0.0f);
            record_everywhere(m2r, 1, 0.0f);
            cachepoints_update_visibility(m1);
            cachepoints_update_visibility(m2);
            cachepoints_update_visibility(m2r);
            uint32_t v = m1->vis_off[m1->n], low1 = 0, low2 = 0, above = 0;
            for (uint32_t s = 0; s < v; ++s) {
                low1 += m1->w_pool[s] < 1.0f;
                low2 += m2->w_pool[s] < 1.0f;
                above += m2->w_pool[s] > m1->w_pool[s]; /* more failures pooled: never a higher W */
            }
            fprintf(stderr, "%s: 1 failure per slot: %u slots pooled below W = 1 over points, %u over points and lights\n",
                    mode, low1, low2);
            CHECK(low2 > low1 && low2 > v / 4 && above == 0, "%s: light pooling: %u vs %u low, %u higher", mode, low2,
                  low1, above);
            CHECK(memcmp(m2->w_blurred, m2r->w_blurred, v * sizeof(float)) == 0, "%s: mode 2 depends on the order", mode);
        }
        cachepoints_free(m1); cachepoints_free(m2); cachepoints_free(m2r);
    }
    cachepoints_free(off); cachepoints_free(on); cachepoints_free(rev); cachepoints_free(own); cachepoints_free(res);
}

/* §4.2 scattering weights with simple callbacks: mu_s = 2 above z = 5, 0 below; every light
 * sample returns the light's intensity (so s(p, e) / I_e is the same for every near light of a
 * point: 2 x the fraction of its 4 ball points above z = 5). */
static float scatter_medium(const void *user, const float y[3], float *g) {
    (void)user;
    *g = 0.0f;
    return y[2] > 5.0f ? 2.0f : 0.0f;
}
static float scatter_light(const void *user, uint32_t light, const float y[3], float g, const float u[4]) {
    (void)user; (void)y; (void)g; (void)u;
    return light_I[light];
}

static void check_scatter(CachePoints *a, CachePoints *b, const CachePointLights *L, const char *mode) {
    CachePointScatter sc = {scatter_medium, scatter_light, NULL, 77};
    CHECK(cachepoints_build_scatter(a, L, &sc) == 0 && cachepoints_build_scatter(b, L, &sc) == 0,
          "%s: scatter weights", mode);
    int bad_ratio = 0, bad_total = 0, differ = 0, some = 0;
    for (uint32_t i = 0; i < cachepoints_count(a); ++i) {
        float ratio = -1.0f, near_sum = 0.0f;
        for (uint32_t l = 0; l < NL; ++l) {
            float w = cachepoints_scatter_weight(a, i, l);
            if (w < 0.0f) continue; /* not a near light of the point */
            float r = w / light_I[l];
            int allowed = 0;
            for (int k = 0; k <= 4; ++k) allowed |= fabsf(r - 0.5f * (float)k) < 1e-4f;
            if (!allowed || (ratio >= 0.0f && fabsf(r - ratio) > 1e-4f)) ++bad_ratio;
            ratio = r;
            near_sum += w;
        }
        float far = cachepoints_scatter_far(a, i), total = cachepoints_scatter_total(a, i);
        if (!(far >= 0.0f) || fabsf(total - (near_sum + far)) > 1e-3f * fmaxf(total, 1.0f)) ++bad_total;
        differ += total != cachepoints_scatter_total(b, i);
        some += total > 0.0f;
    }
    CHECK(bad_ratio == 0, "%s: %d near scattering weights are not I_e x 2 x (the share of the ball points in the medium)",
          mode, bad_ratio);
    CHECK(bad_total == 0, "%s: %d points whose S_p is not near + far", mode, bad_total);
    CHECK(differ == 0, "%s: scattering weights depend on the parallel-for order (%d points)", mode, differ);
    CHECK(some > 0 && some < (int)cachepoints_count(a), "%s: %d of %u points have scattering weight", mode, some,
          cachepoints_count(a));
    /* §3.3 reuse: a vertex inside a point's radius keeps that point, outside it gets the nearest */
    int bad_reuse = 0;
    for (uint32_t i = 0; i < cachepoints_count(a); i += 7) {
        float c[3], r;
        cachepoints_point(a, i, c, &r);
        float inside[3] = {c[0] + 0.9f * r, c[1], c[2]}, outside[3] = {c[0] + 3.0f * r + 1.0f, c[1], c[2]};
        CachePointVertex v;
        cachepoints_vertex_reuse(a, L, inside, NULL, i, &v, NULL);
        bad_reuse += v.point != i;
        cachepoints_vertex_reuse(a, L, outside, NULL, i, &v, NULL);
        bad_reuse += v.point != cachepoints_nearest(a, outside);
    }
    CHECK(bad_reuse == 0, "%s: %d vertices reused the wrong point", mode, bad_reuse);
    /* the lookup's shortcut (a query near the hint: the nearest among the hint and its blur
     * neighbours) gives exactly the kd-tree's nearest point, for queries at, near and between
     * points, with the hint right, a neighbour of the right one, or far away */
    int bad_hint = 0, queries = 0;
    uint32_t n_pts = cachepoints_count(a);
    for (uint32_t i = 0; i < n_pts; i += 3) {
        float c[3], r, o[3];
        cachepoints_point(a, i, c, &r);
        cachepoints_point(a, (i * 7919u + 13u) % n_pts, o, &r);
        for (int t = 0; t < 8; ++t) {
            float f = 0.0625f * (float)t; /* from the point towards another one */
            float x[3] = {c[0] + f * (o[0] - c[0]), c[1] + f * (o[1] - c[1]), c[2] + f * (o[2] - c[2])};
            uint32_t want = cachepoints_nearest(a, x);
            const uint32_t hints[3] = {i, want, (i + n_pts / 2) % n_pts};
            for (int h = 0; h < 3; ++h) {
                CachePointVertex v;
                cachepoints_vertex(a, L, x, NULL, hints[h], &v, NULL);
                bad_hint += v.point != want;
                ++queries;
            }
        }
    }
    CHECK(bad_hint == 0, "%s: %d of %d hinted lookups missed the nearest point", mode, bad_hint, queries);
}

/* Bounding spheres of the lights for the lobe (CachePointLights.bound): every third point light
 * a sphere of radius 0.3, the others points; the directional lights their direction, one with
 * an angular radius of 0.1. */
static float light_bound[4 * NL];

static void setup_bounds(void) {
    for (uint32_t l = 0; l < NL; ++l) {
        memcpy(light_bound + 4 * l, light_pos + 3 * l, 3 * sizeof(float));
        if (light_inf[l]) {
            float *d = light_bound + 4 * l, len = sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            for (int k = 0; k < 3; ++k) d[k] /= len;
            light_bound[4 * l + 3] = l == NL - 1 ? 0.1f : 0.0f;
        } else {
            light_bound[4 * l + 3] = l % 3 == 0 ? 0.3f : 0.0f;
        }
    }
}

/* cos of the angle between a and the direction from x to light l */
static double light_cos(const float a[3], const float x[3], uint32_t l) {
    double d[3];
    for (int k = 0; k < 3; ++k) d[k] = light_inf[l] ? light_pos[3 * l + k] : (double)light_pos[3 * l + k] - x[k];
    double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    return len > 0.0 ? (a[0] * d[0] + a[1] * d[1] + a[2] * d[2]) / len : 0.0;
}

static void check_lobe(CachePoints *a, const CachePointLights *L0, const char *mode) {
    CachePointLights Lb = *L0;
    Lb.bound = light_bound;
    const CachePointLights *L = &Lb;
    CHECK(cachepoints_prepare_lobes(a, L) == 0, "%s: cachepoints_prepare_lobes failed", mode);
    int mismatch = 0, below = 0, lobed = 0, toward = 0, same = 0;
    for (int q = 0; q < 12; ++q) {
        float x[3], nrm[3], axis[3];
        const float *n;
        random_vertex(x, nrm, &n, 1); /* always with a normal */
        /* a lobe around a direction in the normal's hemisphere */
        for (int k = 0; k < 3; ++k) axis[k] = (float)(rnd() - 0.5);
        float dn = axis[0] * n[0] + axis[1] * n[1] + axis[2] * n[2];
        for (int k = 0; k < 3; ++k) axis[k] += (fabsf(dn) + 0.3f) * n[k];
        float al = sqrtf(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
        for (int k = 0; k < 3; ++k) axis[k] /= al;
        const float sharp[4] = {3.0f, 30.0f, 300.0f, 3000.0f}, kappa[3] = {0.3f, 3.0f, INFINITY};
        float near_w[CACHEPOINTS_MAX_NEAR];
        CachePointVertex v0, v;
        cachepoints_vertex(a, L, x, n, UINT32_MAX, &v0, near_w);
        v = v0;
        cachepoints_vertex_lobe(a, L, x, n, near_w, axis, sharp[q % 4], kappa[q % 3], &v);
        CHECK(v.lobe_mix == 0.0f || (v.lobe_mix >= CACHEPOINTS_LOBE_MIN_MIX && v.lobe_mix <= CACHEPOINTS_LOBE_MAX_MIX),
              "%s: lobe mix %g outside [%g, %g]", mode, v.lobe_mix, CACHEPOINTS_LOBE_MIN_MIX, CACHEPOINTS_LOBE_MAX_MIX);
        if (v.lobe_mix > 0.0f) ++lobed;
        double sum = 0.0, cos_lobe = 0.0, cos_normal = 0.0;
        for (uint32_t l = 0; l < NL; ++l) {
            float p = cachepoints_pmf(a, L, x, n, &v, l), p0 = cachepoints_pmf(a, L, x, n, &v0, l);
            sum += p;
            if (p < (1.0f - CACHEPOINTS_LOBE_MAX_MIX) * p0 * (1.0f - 1e-5f)) ++below;
            cos_lobe += p * light_cos(axis, x, l);
            cos_normal += p0 * light_cos(axis, x, l);
        }
        CHECK(fabs(sum - 1.0) < 1e-4, "%s: lobe pmf sums to %.7f", mode, sum);
        if (v.lobe_mix > 0.0f && cos_lobe > cos_normal) ++toward;
        enum { S = 20000 };
        static uint32_t hist[NL];
        memset(hist, 0, sizeof hist);
        for (int s = 0; s < S; ++s) {
            float pmf;
            uint32_t slot;
            uint32_t l = cachepoints_select(a, L, x, n, &v, q % 2 ? near_w : NULL, (float)rnd(), (float)rnd(), &pmf, &slot);
            if (l >= NL || pmf != cachepoints_pmf(a, L, x, n, &v, l) || slot != cachepoints_slot(a, v.point, l)) ++mismatch;
            else hist[l]++;
        }
        static double obs[NL], expv[NL];
        for (uint32_t l = 0; l < NL; ++l) {
            obs[l] = hist[l];
            expv[l] = S * (double)cachepoints_pmf(a, L, x, n, &v, l);
        }
        int dof;
        double chi2, pv = chi2_pvalue(obs, expv, NL, &dof, &chi2);
        CHECK(dof <= 0 || pv > 1e-5, "%s: lobe selection chi2 %.1f (dof %d), p = %.2g", mode, chi2, dof, pv);
        /* a lobe too weak to matter: the vertex stays the paper's, bit for bit */
        CachePointVertex vw = v0;
        cachepoints_vertex_lobe(a, L, x, n, near_w, axis, 3.0f, 1e-4f, &vw);
        int eq = vw.lobe_mix == 0.0f;
        for (int s = 0; s < 200 && eq; ++s) {
            float u0 = (float)rnd(), u1 = (float)rnd(), p1, p2;
            uint32_t s1, s2;
            eq = cachepoints_select(a, L, x, n, &vw, near_w, u0, u1, &p1, &s1) ==
                     cachepoints_select(a, L, x, n, &v0, near_w, u0, u1, &p2, &s2) &&
                 p1 == p2 && s1 == s2;
        }
        same += eq;
        /* no normal: no lobe */
        CachePointVertex vn;
        cachepoints_vertex(a, L, x, NULL, UINT32_MAX, &vn, NULL);
        cachepoints_vertex_lobe(a, L, x, NULL, NULL, axis, 300.0f, 3.0f, &vn);
        CHECK(vn.lobe_mix == 0.0f, "%s: a vertex without a normal got a lobe", mode);
    }
    fprintf(stderr, "%s: lobe: %d of 12 vertices follow it, %d of them move toward its axis\n", mode, lobed, toward);
    CHECK(mismatch == 0, "%s: %d lobe selections disagree with cachepoints_pmf / cachepoints_slot", mode, mismatch);
    CHECK(below == 0, "%s: %d lights below (1 - g_max) of their normal-only probability", mode, below);
    CHECK(lobed >= 8, "%s: only %d of 12 vertices follow the lobe", mode, lobed);
    CHECK(toward == lobed, "%s: the lobe moved probability away from its axis at %d vertices", mode, lobed - toward);
    CHECK(same == 12, "%s: a weak lobe changed the selection at %d vertices", mode, 12 - same);
}

static void run(const CachePointLights *L, const float *cand, uint32_t nc, int cut) {
    const char *mode = cut ? "cut" : "linear";
    CachePointCamera cam = {{5.0f, 5.0f, 40.0f}, 2.0f * 0.4f / 64.0f, 0.0f};
    CachePointParams P;
    cachepoints_default_params(&P);
    P.build_cut = cut;
    P.cut_size = 24; /* small, so that clusters are common */
    CachePoints *a = NULL, *b = NULL;
    CachePointStats sa, sb;
    int ra = cachepoints_build(&a, cand, nc, L, &cam, &P, &sa);
    P.parallel_for = reverse_parallel_for;
    int rb = cachepoints_build(&b, cand, nc, L, &cam, &P, &sb);
    CHECK(ra == 0 && rb == 0, "%s: build %d %d", mode, ra, rb);
    if (ra || rb) return;
    fprintf(stderr, "%s: candidates %u -> pass 1 %u -> final %u points, %zu bytes; per point %.1f near, %.1f far (%.1f clusters)\n",
            mode, sa.candidates, sa.after_pass1, sa.final_points, sa.bytes, sa.mean_near, sa.mean_far,
            sa.mean_far_clusters);
    CHECK(sa.final_points > 10 && sa.final_points < sa.after_pass1 && sa.after_pass1 <= sa.candidates,
          "%s: merging: %u -> %u -> %u", mode, sa.candidates, sa.after_pass1, sa.final_points);
    if (cut) {
        /* the budget, the two infinite lights, and the siblings of the near lights' paths
         * (nodes holding a near light are always split; the tree is 9 levels deep) */
        CHECK(sa.mean_far <= P.cut_size + 2 + 9.0 * sa.mean_near, "cut: %.1f far entries per point for a budget of %u",
              sa.mean_far, P.cut_size);
        CHECK(sa.mean_far_clusters > 1.0, "cut: %.1f clusters per point: the cut is not exercised", sa.mean_far_clusters);
    } else {
        CHECK(sa.mean_far_clusters == 0.0, "linear: no clusters expected (%.1f)", sa.mean_far_clusters);
    }
    CHECK(cachepoints_count(a) == cachepoints_count(b), "%s: point counts differ: %u vs %u", mode, cachepoints_count(a),
          cachepoints_count(b));
    if (cachepoints_count(a) == cachepoints_count(b)) check_scatter(a, b, L, mode);
    int same = cachepoints_count(a) == cachepoints_count(b);
    for (uint32_t i = 0; same && i < cachepoints_count(a); ++i) {
        float pa[3], pb[3], r1, r2;
        cachepoints_point(a, i, pa, &r1);
        cachepoints_point(b, i, pb, &r2);
        if (memcmp(pa, pb, sizeof pa) != 0 || r1 != r2) same = 0;
    }
    CHECK(same, "%s: builds differ between serial and reversed-parallel execution", mode);

    /* PMFs: sum to one; select reports exactly pmf(); identical between the two builds */
    int mismatch = 0, differ = 0;
    for (int q = 0; q < 10; ++q) {
        float x[3], nrm[3];
        const float *n;
        random_vertex(x, nrm, &n, q);
        CachePointVertex va, vb;
        float near_w[CACHEPOINTS_MAX_NEAR]; /* odd queries: select reuses the near weights */
        cachepoints_vertex(a, L, x, n, UINT32_MAX, &va, q % 2 ? near_w : NULL);
        cachepoints_vertex(b, L, x, n, UINT32_MAX, &vb, NULL);
        CHECK(va.point == cachepoints_nearest(a, x), "%s: the vertex uses the nearest point", mode);
        double sum = 0.0;
        for (uint32_t l = 0; l < NL; ++l) {
            float pa = cachepoints_pmf(a, L, x, n, &va, l);
            sum += pa;
            if (pa != cachepoints_pmf(b, L, x, n, &vb, l)) ++differ;
        }
        CHECK(fabs(sum - 1.0) < 1e-4, "%s: pmf sums to %.7f", mode, sum);
        enum { S = 20000 };
        static uint32_t hist[NL];
        memset(hist, 0, sizeof hist);
        for (int s = 0; s < S; ++s) {
            float pmf;
            uint32_t slot;
            uint32_t l = cachepoints_select(a, L, x, n, &va, q % 2 ? near_w : NULL, (float)rnd(), (float)rnd(), &pmf, &slot);
            if (l >= NL || pmf != cachepoints_pmf(a, L, x, n, &va, l) || slot != cachepoints_slot(a, va.point, l)) ++mismatch;
            else hist[l]++;
        }
        static double obs[NL], expv[NL];
        for (uint32_t l = 0; l < NL; ++l) {
            obs[l] = hist[l];
            expv[l] = S * (double)cachepoints_pmf(a, L, x, n, &va, l);
        }
        int dof;
        double chi2, pv = chi2_pvalue(obs, expv, NL, &dof, &chi2);
        CHECK(dof <= 0 || pv > 1e-5, "%s: selection chi2 %.1f (dof %d), p = %.2g", mode, chi2, dof, pv);
    }
    CHECK(mismatch == 0, "%s: %d selections disagree with cachepoints_pmf / cachepoints_slot", mode, mismatch);
    CHECK(differ == 0, "%s: %d pmfs differ between the serial and parallel builds", mode, differ);
    check_lobe(a, L, mode);

    /* visibility learning: the most probable light at x0 that has a slot of its own always
     * fails, every other slot always succeeds */
    float x0[3] = {5, 5, 5};
    CachePointVertex v0;
    cachepoints_vertex(a, L, x0, NULL, UINT32_MAX, &v0, NULL);
    uint32_t p0 = v0.point, best = UINT32_MAX;
    for (uint32_t l = 0; l < NL; ++l) {
        uint32_t s = cachepoints_slot(a, p0, l);
        int own = s != UINT32_MAX;
        for (uint32_t m = 0; own && m < NL; ++m) own = m == l || cachepoints_slot(a, p0, m) != s;
        if (own && (best == UINT32_MAX || cachepoints_pmf(a, L, x0, NULL, &v0, l) > cachepoints_pmf(a, L, x0, NULL, &v0, best)))
            best = l;
    }
    CHECK(best != UINT32_MAX, "%s: no light has a slot of its own at x0", mode);
    if (best == UINT32_MAX) { cachepoints_free(a); cachepoints_free(b); return; }
    float before = cachepoints_pmf(a, L, x0, NULL, &v0, best);
    for (uint32_t p = 0; p < cachepoints_count(a); ++p)
        for (uint32_t l = 0; l < NL; ++l) {
            uint32_t s = cachepoints_slot(a, p, l);
            for (int t = 0; t < 99; ++t) {
                cachepoints_record(a, s, l != best ? 1.0f : 0.0f);
            }
        }
    cachepoints_update_visibility(a);
    cachepoints_vertex(a, L, x0, NULL, UINT32_MAX, &v0, NULL);
    uint32_t other = best == 0 ? 1 : 0;
    float wb = cachepoints_visibility(a, p0, best), wo = cachepoints_visibility(a, p0, other);
    float after = cachepoints_pmf(a, L, x0, NULL, &v0, best);
    fprintf(stderr, "%s: visibility: W'(occluded) %.4f, W'(other) %.4f; pmf(occluded) %.5f -> %.5f\n", mode, wb, wo,
            before, after);
    CHECK(fabsf(wb - 0.0625f) < 1e-5f, "%s: never-visible light after 99 attempts: W' = %g, expected 625/100^2", mode, wb);
    CHECK(fabsf(wo - 1.0f) < 1e-6f, "%s: a visible light keeps W' = 1 (%g)", mode, wo);
    CHECK(after < 0.5f * before, "%s: learning must push the occluded light down (%g -> %g)", mode, before, after);
    CHECK(after >= 0.03f / NL * 0.999f, "%s: the uniform floor keeps every light selectable (%g)", mode, after);
    double sum = 0.0;
    for (uint32_t l = 0; l < NL; ++l) sum += cachepoints_pmf(a, L, x0, NULL, &v0, l);
    CHECK(fabs(sum - 1.0) < 1e-4, "%s: pmf after learning sums to %.7f", mode, sum);
    cachepoints_free(a);
    cachepoints_free(b);
    P.parallel_for = NULL;
    fractional_visibility(L, cand, nc, &P, mode);
    pooled_visibility(L, cand, nc, &P, mode);
    progressive_insertion(L, cand, nc, &P, mode);
}

/* Every slot of point p gets `count` records of `vis`. */
static void record_point(CachePoints *cp, uint32_t p, int count, float vis) {
    for (uint32_t s = cp->vis_off[p]; s < cp->vis_off[p + 1]; ++s)
        for (int t = 0; t < count; ++t) cachepoints_record(cp, s, vis);
}

/* A shadow boundary: the points with x < 5 see every light, those with x >= 5 none (20
 * attempts per slot). */
static void record_boundary(CachePoints *cp) {
    for (uint32_t p = 0; p < cachepoints_count(cp); ++p) record_point(cp, p, 20, cp->pos[3 * p] < 5.0f ? 1.0f : 0.0f);
}

/* Progressive insertion (progressive.c): after a shadow boundary at x = 5 has been learned,
 * the inserted points lie along it (their mean distance to the plane a small fraction of the
 * built points'), within the budget, at the round's barrier only; bit-identical for a
 * reversed parallel-for; the old points keep their positions, radii and every counter of a
 * key they still hold; PMFs of the new set sum to 1 and select agrees with pmf; uniform
 * visibility inserts nothing (the noise floor); a checkpoint (inserted points + learned
 * state) loaded into a fresh build gives the same points and weights. */
static void progressive_insertion(const CachePointLights *L, const float *cand, uint32_t nc, const CachePointParams *P0,
                                  const char *mode) {
    CachePointCamera cam = {{5.0f, 5.0f, 40.0f}, 2.0f * 0.4f / 64.0f, 0.0f};
    CachePointParams P = *P0;
    P.progressive_rounds = 1;
    P.progressive_first = 2; /* the second barrier */
    P.progressive_budget = 0.3f;
    CachePointParams R = P;
    R.parallel_for = reverse_parallel_for;
    CachePoints *a = NULL, *b = NULL, *u = NULL, *c = NULL;
    int rc = cachepoints_build(&a, cand, nc, L, &cam, &P, NULL) | cachepoints_build(&b, cand, nc, L, &cam, &R, NULL) |
             cachepoints_build(&u, cand, nc, L, &cam, &P, NULL) | cachepoints_build(&c, cand, nc, L, &cam, &P, NULL);
    CHECK(rc == 0, "%s: progressive builds", mode);
    if (rc != 0) { cachepoints_free(a); cachepoints_free(b); cachepoints_free(u); cachepoints_free(c); return; }
    uint32_t n0 = cachepoints_count(a), ins = 99, ins_b = 99, ins_u = 99;
    CHECK(a->num_probes > n0, "%s: %u probes for %u points", mode, a->num_probes, n0);
    record_boundary(a);
    record_boundary(b);
    for (uint32_t p = 0; p < n0; ++p) record_point(u, p, 20, 1.0f);
    /* the first barrier counts only */
    CHECK(cachepoints_progress(a, L, &ins) == 0 && ins == 0 && cachepoints_count(a) == n0, "%s: barrier 1 inserted %u",
          mode, ins);
    cachepoints_progress(b, L, &ins_b);
    cachepoints_progress(u, L, &ins_u);
    cachepoints_update_visibility(a);
    cachepoints_update_visibility(b);
    cachepoints_update_visibility(u);
    /* the old counters, to compare after the rebuild */
    uint32_t v_old = a->vis_off[n0];
    uint32_t *off_old = malloc((n0 + 1) * sizeof *off_old), *key_old = malloc((v_old + 1) * sizeof *key_old);
    VisCounter *cnt_old = malloc((v_old + 1) * sizeof *cnt_old);
    float *pos_old = malloc(3 * n0 * sizeof *pos_old), *rad_old = malloc(n0 * sizeof *rad_old);
    memcpy(off_old, a->vis_off, (n0 + 1) * sizeof *off_old);
    memcpy(key_old, a->vis_key, v_old * sizeof *key_old);
    memcpy(cnt_old, a->vis_count, v_old * sizeof *cnt_old);
    memcpy(pos_old, a->pos, 3 * n0 * sizeof *pos_old);
    memcpy(rad_old, a->radius, n0 * sizeof *rad_old);

    rc = cachepoints_progress(a, L, &ins) | cachepoints_progress(b, L, &ins_b) | cachepoints_progress(u, L, &ins_u);
    uint32_t budget = (uint32_t)ceil(0.3 * n0);
    CHECK(rc == 0 && ins > 0 && ins <= budget && cachepoints_count(a) == n0 + ins && cachepoints_inserted(a) == ins,
          "%s: inserted %u of a budget of %u (%u points)", mode, ins, budget, cachepoints_count(a));
    CHECK(ins_u == 0 && cachepoints_count(u) == n0, "%s: uniform visibility inserted %u points", mode, ins_u);
    /* where: along x = 5 */
    double d_new = 0.0, d_old = 0.0;
    for (uint32_t i = n0; i < cachepoints_count(a); ++i) d_new += fabs(a->pos[3 * i] - 5.0);
    for (uint32_t i = 0; i < n0; ++i) d_old += fabs(a->pos[3 * i] - 5.0);
    d_new /= ins ? ins : 1;
    d_old /= n0;
    fprintf(stderr, "%s: progressive: %u points + %u inserted (budget %u) from %u probes; mean |x - 5| %.3f (built points %.3f)\n",
            mode, n0, ins, budget, a->num_probes, d_new, d_old);
    CHECK(d_new < 0.25 * d_old, "%s: inserted points lie %.3f from the boundary, the built ones %.3f", mode, d_new, d_old);
    /* the old points: same place, radius, and counters of every key they still hold */
    int moved = 0, lost = 0, kept = 0;
    for (uint32_t p = 0; p < n0; ++p) {
        moved += memcmp(a->pos + 3 * p, pos_old + 3 * p, 3 * sizeof(float)) != 0 || a->radius[p] != rad_old[p];
        uint32_t s = off_old[p], q = a->vis_off[p];
        while (s < off_old[p + 1] && q < a->vis_off[p + 1]) {
            if (key_old[s] < a->vis_key[q]) ++s;
            else if (key_old[s] > a->vis_key[q]) ++q;
            else {
                lost += memcmp(&cnt_old[s], &a->vis_count[q], sizeof(VisCounter)) != 0;
                ++kept; ++s; ++q;
            }
        }
    }
    CHECK(moved == 0 && lost == 0 && kept > (int)(v_old / 2), "%s: old points moved %d, counters lost %d (kept %d of %u)",
          mode, moved, lost, kept, v_old);
    /* determinism */
    uint32_t na = cachepoints_count(a);
    int same = na == cachepoints_count(b) && memcmp(a->pos, b->pos, 3 * na * sizeof(float)) == 0 &&
               memcmp(a->radius, b->radius, na * sizeof(float)) == 0 && a->vis_off[na] == b->vis_off[na];
    cachepoints_update_visibility(a);
    cachepoints_update_visibility(b);
    same = same && memcmp(a->w_blurred, b->w_blurred, a->vis_off[na] * sizeof(float)) == 0 &&
           memcmp(a->far_cdf, b->far_cdf, (size_t)a->far_off[na] * 7 * sizeof(float)) == 0;
    CHECK(same, "%s: progressive insertion differs with the parallel-for order", mode);
    /* the new set's PMFs */
    int mismatch = 0;
    for (int q = 0; q < 6; ++q) {
        float x[3], nrm[3];
        const float *n;
        random_vertex(x, nrm, &n, q);
        x[0] = 4.5f + 0.1f * (float)q; /* near the boundary, where the new points are */
        CachePointVertex v;
        cachepoints_vertex(a, L, x, n, UINT32_MAX, &v, NULL);
        double sum = 0.0;
        for (uint32_t l = 0; l < NL; ++l) sum += cachepoints_pmf(a, L, x, n, &v, l);
        CHECK(fabs(sum - 1.0) < 1e-4, "%s: after insertion the pmf sums to %.7f", mode, sum);
        for (int t = 0; t < 2000; ++t) {
            float pmf;
            uint32_t slot;
            uint32_t l = cachepoints_select(a, L, x, n, &v, NULL, (float)rnd(), (float)rnd(), &pmf, &slot);
            mismatch += l >= NL || pmf != cachepoints_pmf(a, L, x, n, &v, l) || slot != cachepoints_slot(a, v.point, l);
        }
    }
    CHECK(mismatch == 0, "%s: %d selections after insertion disagree with pmf / slot", mode, mismatch);
    /* later barriers insert nothing (one round) */
    record_boundary(a);
    CHECK(cachepoints_progress(a, L, &ins) == 0 && ins == 0 && cachepoints_count(a) == na, "%s: barrier 3 inserted %u",
          mode, ins);
    cachepoints_update_visibility(a);
    /* checkpoint: into a fresh build */
    FILE *f = tmpfile();
    CHECK(f && (cachepoints_save_inserted(a, f) | cachepoints_save_learned(a, f)) == 0, "%s: progressive save", mode);
    if (f) {
        rewind(f);
        int rl = cachepoints_load_inserted(c, L, f);
        CHECK(rl == 0 && cachepoints_load_learned(c, f) == 0, "%s: progressive load (%d)", mode, rl);
        fclose(f);
        uint32_t nn = cachepoints_count(c);
        CHECK(nn == na && memcmp(a->pos, c->pos, 3 * na * sizeof(float)) == 0 && c->vis_off[nn] == a->vis_off[na] &&
                  memcmp(a->w_blurred, c->w_blurred, a->vis_off[na] * sizeof(float)) == 0,
              "%s: the checkpoint restores other points (%u vs %u)", mode, nn, na);
        record_boundary(a);
        record_boundary(c);
        cachepoints_progress(a, L, &ins);
        cachepoints_progress(c, L, &ins_b);
        cachepoints_update_visibility(a);
        cachepoints_update_visibility(c);
        CHECK(ins == ins_b && memcmp(a->far_cdf, c->far_cdf, (size_t)a->far_off[na] * 7 * sizeof(float)) == 0,
              "%s: learning after the checkpoint differs", mode);
    }
    /* a record of another build is refused */
    f = tmpfile();
    if (f) {
        cachepoints_save_inserted(a, f);
        rewind(f);
        CHECK(cachepoints_load_inserted(a, L, f) == -2, "%s: a record loaded into a set with inserted points", mode);
        fclose(f);
    }
    free(off_old); free(key_old); free(cnt_old); free(pos_old); free(rad_old);
    cachepoints_free(a); cachepoints_free(b); cachepoints_free(u); cachepoints_free(c);
}

/* Return codes: -2 for parameters the build cannot run with, 1 for too few points or no
 * lights, and *out == NULL whenever the build does not return 0. */
static void build_errors(const CachePointLights *L, const float *cand, uint32_t nc) {
    CachePointCamera cam = {{5.0f, 5.0f, 40.0f}, 2.0f * 0.4f / 64.0f, 0.0f};
    CachePointParams P;
    CachePoints *cp;
    int rc;
#define EXPECT_BUILD(want, what, lights, count)                                                      \
    do {                                                                                             \
        cp = (CachePoints *)&P; /* must be reset to NULL */                                          \
        rc = cachepoints_build(&cp, cand, count, lights, &cam, &P, NULL);                           \
        CHECK(rc == (want) && cp == NULL, "%s: build returned %d (expected %d), out %p", what, rc, want, (void *)cp); \
        cachepoints_default_params(&P);                                                              \
    } while (0)
    cachepoints_default_params(&P);
    P.knn = 65;
    EXPECT_BUILD(-2, "knn 65", L, nc);
    P.blur_neighbours = 65;
    EXPECT_BUILD(-2, "blur_neighbours 65", L, nc);
    P.epsilon = 1.5f;
    EXPECT_BUILD(-2, "epsilon 1.5", L, nc);
    P.epsilon = NAN;
    EXPECT_BUILD(-2, "epsilon NaN", L, nc);
    CachePointLights no_tree = *L;
    no_tree.tree = NULL;
    P.build_cut = 1;
    EXPECT_BUILD(-2, "cut build without a tree", &no_tree, nc);
    P.build_cut = 1;
    P.cut_size = 0;
    EXPECT_BUILD(-2, "cut_size 0", L, nc);
    CachePointTree bad = *L->tree;
    bad.descend_pmf = NULL;
    CachePointLights bad_lights = *L;
    bad_lights.tree = &bad;
    P.build_cut = 1;
    EXPECT_BUILD(-2, "cut build without descend_pmf", &bad_lights, nc);
    static uint32_t bad_second[MAXNODES];
    memcpy(bad_second, second, sizeof bad_second);
    bad_second[0] = 0; /* the root's second child before the root: not depth-first */
    bad = *L->tree;
    bad.second_child = bad_second;
    P.build_cut = 1;
    EXPECT_BUILD(-2, "malformed tree", &bad_lights, nc);
    P.knn = 65; /* invalid parameters are reported before the fallback cases */
    EXPECT_BUILD(-2, "knn 65 with 5 candidates", L, 5);
    EXPECT_BUILD(1, "5 candidates", L, 5);
    CachePointLights none = *L;
    none.count = 0;
    EXPECT_BUILD(1, "no lights", &none, nc);
    P.build_cut = 1;
    EXPECT_BUILD(1, "no lights, cut build", &none, nc);
#undef EXPECT_BUILD
}

int main(void) {
    /* Eqs. 5-6 anchors (§3.2.1, R_min = 0.04): with no success, W = 1 up to 24 attempts
     * (R = 1/25 = R_min), then 625 / (attempts + 1)^2 */
    CHECK(cachepoints_visibility_weight(0, 24, 0.04f) == 1.0f, "W(0,24) = %g", cachepoints_visibility_weight(0, 24, 0.04f));
    CHECK(cachepoints_visibility_weight(0, 25, 0.04f) < 1.0f, "W(0,25) must be below 1");
    CHECK(fabsf(cachepoints_visibility_weight(0, 49, 0.04f) - 0.25f) < 1e-6f, "W(0,49) = %g", cachepoints_visibility_weight(0, 49, 0.04f));
    CHECK(fabsf(cachepoints_visibility_weight(0, 99, 0.04f) - 0.0625f) < 1e-6f, "W(0,99) = %g", cachepoints_visibility_weight(0, 99, 0.04f));
    CHECK(cachepoints_visibility_weight(0, 4000000000u, 0.04f) > 0.0f, "W never reaches 0");
    CHECK(cachepoints_visibility_weight(10, 20, 0.04f) == 1.0f, "visible light keeps W = 1");
    int differ = 0; /* integer successes give exactly the values of the integer-counter formula */
    for (uint32_t t = 0; t <= 400; ++t)
        for (uint32_t k = 0; k <= t; ++k) differ += cachepoints_visibility_weight((float)(256 * k) / 256.0f, t, 0.04f) != integer_weight(k, t, 0.04f);
    CHECK(differ == 0, "%d integer counts give W different from the integer formula", differ);
    CHECK(cachepoints_visibility_weight(1.5f, 100, 0.04f) < cachepoints_visibility_weight(2.0f, 100, 0.04f) &&
          cachepoints_visibility_weight(1.5f, 100, 0.04f) > cachepoints_visibility_weight(1.0f, 100, 0.04f),
          "fractional successes lie between their integer neighbours");

    sm_state = 42;
    for (int l = 0; l < NPOINT; ++l) {
        for (int k = 0; k < 3; ++k) light_pos[3 * l + k] = (float)(rnd() * 10.0);
        light_I[l] = (float)(0.1 + 10.0 * rnd() * rnd());
        light_inf[l] = 0;
        order[l] = (uint32_t)l;
    }
    const float dirs[2][3] = {{0.3f, 0.9f, 0.1f}, {-0.5f, 0.2f, -0.8f}};
    for (int j = 0; j < 2; ++j) {
        memcpy(light_pos + 3 * (NPOINT + j), dirs[j], sizeof dirs[j]);
        light_I[NPOINT + j] = 0.05f;
        light_inf[NPOINT + j] = 1;
        light_leaf[NPOINT + j] = UINT32_MAX;
    }
    build_node(0, NPOINT, 0);
    setup_bounds();
    enum { NC = 6000 };
    static float cand[3 * NC];
    for (int i = 0; i < NC; ++i)
        for (int k = 0; k < 3; ++k) cand[3 * i + k] = (float)(rnd() * 10.0);
    CachePointTree T = {node_count, second, leaf_light, light_leaf, tree_bounds, tree_estimate7, tree_descend, tree_descend_pmf};
    CachePointLights L = {NL, light_pos, light_inf, point_estimate7, point_estimate, NULL, &T};
    build_errors(&L, cand, NC);
    run(&L, cand, NC, 0);
    run(&L, cand, NC, 1);
    return test_exit();
}
