/* The cachepoints module on its own, with synthetic point lights: Eq. 5-6 anchor values,
 * build determinism (serial vs a parallel-for that runs chunks in reverse order), PMFs that
 * sum to one, select/pmf agreement and selection frequencies, and visibility learning
 * pushing down a light that is never visible. */
#include <math.h>
#include <string.h>

#include "cachepoints.h"
#include "check.h"
#include "stats.h"

static uint64_t sm_state;
static double rnd(void) { return splitmix_uniform(&sm_state); }

#define NL 300
static float light_pos[3 * NL], light_I[NL];
static uint8_t light_inf[NL];

static float point_estimate(const void *user, uint32_t l, const float x[3], const float *n) {
    (void)user;
    float d[3] = {light_pos[3 * l] - x[0], light_pos[3 * l + 1] - x[1], light_pos[3 * l + 2] - x[2]};
    float d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    if (!(d2 > 1e-8f)) return 0.0f;
    float c = 1.0f;
    if (n) { c = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]) / sqrtf(d2); if (c < 0.0f) c = 0.0f; }
    return light_I[l] * c / d2;
}

static void point_estimate7(const void *user, uint32_t l, const float x[3], float out[7]) {
    static const float axes[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    for (int i = 0; i < 6; ++i) out[i] = point_estimate(user, l, x, axes[i]);
    out[6] = point_estimate(user, l, x, NULL);
}

/* runs chunks of 7 items in reverse order: a build that depended on order would differ */
static void reverse_parallel_for(void *pool, size_t n, size_t grain, void (*fn)(void *, size_t, size_t, int), void *ctx) {
    (void)pool; (void)grain;
    size_t chunk = 7;
    size_t count = (n + chunk - 1) / chunk;
    for (size_t c = count; c-- > 0;) fn(ctx, c * chunk, c * chunk + chunk < n ? c * chunk + chunk : n, (int)(c % 2));
}

int main(void) {
    /* Eq. 5-6 anchors (spec §4.1) */
    CHECK(cachepoints_visibility_weight(0, 24, 0.04f) == 1.0f, "W(0,24) = %g", cachepoints_visibility_weight(0, 24, 0.04f));
    CHECK(cachepoints_visibility_weight(0, 25, 0.04f) < 1.0f, "W(0,25) must be below 1");
    CHECK(fabsf(cachepoints_visibility_weight(0, 49, 0.04f) - 0.25f) < 1e-6f, "W(0,49) = %g", cachepoints_visibility_weight(0, 49, 0.04f));
    CHECK(fabsf(cachepoints_visibility_weight(0, 99, 0.04f) - 0.0625f) < 1e-6f, "W(0,99) = %g", cachepoints_visibility_weight(0, 99, 0.04f));
    CHECK(cachepoints_visibility_weight(0, 4000000000u, 0.04f) > 0.0f, "W never reaches 0");
    CHECK(cachepoints_visibility_weight(10, 20, 0.04f) == 1.0f, "visible light keeps W = 1");

    sm_state = 42;
    for (int l = 0; l < NL; ++l) {
        for (int k = 0; k < 3; ++k) light_pos[3 * l + k] = (float)(rnd() * 10.0);
        light_I[l] = (float)(0.1 + 10.0 * rnd() * rnd());
        light_inf[l] = 0;
    }
    enum { NC = 6000 };
    static float cand[3 * NC];
    for (int i = 0; i < NC; ++i)
        for (int k = 0; k < 3; ++k) cand[3 * i + k] = (float)(rnd() * 10.0);
    CachePointLights L = {NL, light_pos, light_inf, point_estimate7, point_estimate, NULL};
    CachePointCamera cam = {{5.0f, 5.0f, 40.0f}, 2.0f * 0.4f / 64.0f, 0.0f};
    CachePointParams P;
    cachepoints_default_params(&P);
    CachePoints *a = NULL, *b = NULL;
    CachePointStats sa, sb;
    int ra = cachepoints_build(&a, cand, NC, &L, &cam, &P, &sa);
    P.parallel_for = reverse_parallel_for;
    int rb = cachepoints_build(&b, cand, NC, &L, &cam, &P, &sb);
    CHECK(ra == 0 && rb == 0, "build %d %d", ra, rb);
    if (ra || rb) return test_exit();
    fprintf(stderr, "candidates %u -> pass 1 %u -> final %u points, %.3f s, %zu bytes\n", sa.candidates,
            sa.after_pass1, sa.final_points, sa.seconds, sa.bytes);
    CHECK(sa.final_points > 10 && sa.final_points < sa.after_pass1 && sa.after_pass1 <= sa.candidates,
          "merging: %u -> %u -> %u", sa.candidates, sa.after_pass1, sa.final_points);
    CHECK(cachepoints_count(a) == cachepoints_count(b), "point counts differ: %u vs %u", cachepoints_count(a), cachepoints_count(b));
    int same = cachepoints_count(a) == cachepoints_count(b);
    for (uint32_t i = 0; same && i < cachepoints_count(a); ++i) {
        float pa[3], pb[3], r1, r2;
        cachepoints_point(a, i, pa, &r1);
        cachepoints_point(b, i, pb, &r2);
        if (memcmp(pa, pb, sizeof pa) != 0 || r1 != r2) same = 0;
    }
    CHECK(same, "builds differ between serial and reversed-parallel execution");

    /* PMFs: sum to one; select reports exactly pmf(); identical between the two builds */
    int mismatch = 0, differ = 0;
    for (int q = 0; q < 10; ++q) {
        float x[3] = {(float)(rnd() * 10), (float)(rnd() * 10), (float)(rnd() * 10)};
        float nrm[3] = {(float)(rnd() - 0.5), (float)(rnd() - 0.5), (float)(rnd() - 0.5)};
        float len = sqrtf(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
        for (int k = 0; k < 3; ++k) nrm[k] /= len;
        const float *n = q % 3 == 0 ? NULL : nrm;
        double sum = 0.0;
        for (uint32_t l = 0; l < NL; ++l) {
            float pa = cachepoints_pmf(a, &L, x, n, UINT32_MAX, l);
            sum += pa;
            if (pa != cachepoints_pmf(b, &L, x, n, UINT32_MAX, l)) ++differ;
        }
        CHECK(fabs(sum - 1.0) < 1e-4, "pmf sums to %.7f", sum);
        enum { S = 20000 };
        static uint32_t hist[NL];
        memset(hist, 0, sizeof hist);
        for (int s = 0; s < S; ++s) {
            float pmf;
            uint32_t cpi;
            uint32_t l = cachepoints_select(a, &L, x, n, UINT32_MAX, (float)rnd(), &pmf, &cpi);
            if (l >= NL || pmf != cachepoints_pmf(a, &L, x, n, UINT32_MAX, l) || pmf != cachepoints_pmf(a, &L, x, n, cpi, l) ||
                cpi != cachepoints_nearest(a, x))
                ++mismatch;
            else hist[l]++;
        }
        double chi2 = 0.0, pooled_o = 0.0, pooled_e = 0.0;
        int dof = -1;
        for (uint32_t l = 0; l < NL; ++l) {
            double e = S * (double)cachepoints_pmf(a, &L, x, n, UINT32_MAX, l);
            if (e < 5.0) { pooled_o += hist[l]; pooled_e += e; continue; }
            chi2 += (hist[l] - e) * (hist[l] - e) / e;
            ++dof;
        }
        if (pooled_e > 5.0) { chi2 += (pooled_o - pooled_e) * (pooled_o - pooled_e) / pooled_e; ++dof; }
        if (dof > 0) {
            double limit = dof * pow(1.0 - 2.0 / (9.0 * dof) + 4.5 * sqrt(2.0 / (9.0 * dof)), 3.0);
            CHECK(chi2 < limit, "selection chi2 %.1f > %.1f (dof %d)", chi2, limit, dof);
        }
    }
    CHECK(mismatch == 0, "%d selections disagree with cachepoints_pmf", mismatch);
    CHECK(differ == 0, "%d pmfs differ between the serial and parallel builds", differ);

    /* visibility learning: the most probable light at x0 always fails, the others succeed */
    float x0[3] = {5, 5, 5};
    uint32_t p0 = cachepoints_nearest(a, x0), best = 0;
    for (uint32_t l = 1; l < NL; ++l)
        if (cachepoints_pmf(a, &L, x0, NULL, UINT32_MAX, l) > cachepoints_pmf(a, &L, x0, NULL, UINT32_MAX, best)) best = l;
    float before = cachepoints_pmf(a, &L, x0, NULL, UINT32_MAX, best);
    for (uint32_t p = 0; p < cachepoints_count(a); ++p)
        for (int t = 0; t < 99; ++t)
            for (uint32_t l = 0; l < NL; ++l) cachepoints_record(a, p, l, l != best);
    cachepoints_update_visibility(a);
    float wb = cachepoints_visibility(a, p0, best), wo = cachepoints_visibility(a, p0, best == 0 ? 1 : 0);
    float after = cachepoints_pmf(a, &L, x0, NULL, UINT32_MAX, best);
    fprintf(stderr, "visibility: W'(occluded) %.4f, W'(other) %.4f; pmf(occluded) %.5f -> %.5f\n", wb, wo, before, after);
    CHECK(fabsf(wb - 0.0625f) < 1e-5f, "never-visible light after 99 attempts: W' = %g, expected 625/100^2", wb);
    CHECK(fabsf(wo - 1.0f) < 1e-6f, "a visible light keeps W' = 1 (%g)", wo);
    CHECK(after < 0.5f * before, "learning must push the occluded light down (%g -> %g)", before, after);
    CHECK(after >= 0.03f / NL * 0.999f, "the uniform floor keeps every light selectable (%g)", after);
    cachepoints_free(a);
    cachepoints_free(b);
    return test_exit();
}
