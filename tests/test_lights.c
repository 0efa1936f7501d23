/* Light selection and light sampling: the PMF of every strategy sums to one over all lights,
 * select() reports exactly the PMF that pmf() evaluates, selection frequencies match the PMF
 * (chi-square), and light_sample_li's solid-angle pdf matches the standalone pdf functions
 * used for MIS. argv[1]: a glTF with many lights (../shared/assets/gltf/cornell_many_lights.gltf),
 * argv[2]: tests/scenes (for the environment scene). */
#include <math.h>
#include <string.h>

#include "check.h"
#include "stats.h"
#include "rng.h"
#include "light_sampler.h"
#include "media.h"
#include "scene.h"
#include "threads.h"

/* A strategy that learns from shadow rays, driven through the protocol alone: at vertices
 * around a test vertex (learning may be blurred over neighbouring vertices), every selection of one light reports that nothing reached it
 * (visibility 0), every other selection that all of it did. The light is the most likely one
 * at a test vertex among those whose outcome token no other light shares there (a strategy
 * may learn per cluster of lights; one light of a cluster cannot be told apart). After the
 * barrier that light is much less likely at the test vertex, the pmfs still sum to 1 and
 * select still reports the pmf. */
static void check_learning(const LightSampler *sampler, const Lights *ls, uint64_t key) {
    float scratch[LIGHT_SAMPLER_SCRATCH];
    LightSampleContext ctx = {v3(0.1f, 0.8f, -0.2f), v3(0, 1, 0), {0, 0.0f}, scratch};
    uint32_t hint = UINT32_MAX;
    light_sampler_prepare(sampler, &ctx, &hint);
    uint32_t *outcome_of = malloc(ls->count * sizeof *outcome_of);
    uint8_t *shared = calloc(ls->count, 1);
    for (uint32_t i = 0; i < ls->count; ++i) outcome_of[i] = LIGHT_OUTCOME_NONE;
    for (int s = 0; s < 20000; ++s) {
        float pmf;
        uint32_t outcome, l = light_sampler_select(sampler, &ctx, rng_uniform(key, 50000 + 2 * s),
                                                   rng_uniform(key, 50001 + 2 * s), &pmf, &outcome);
        outcome_of[l] = outcome;
    }
    for (uint32_t i = 0; i < ls->count; ++i)
        for (uint32_t j = 0; j < ls->count; ++j)
            if (i != j && outcome_of[i] != LIGHT_OUTCOME_NONE && outcome_of[i] == outcome_of[j]) shared[i] = 1;
    uint32_t target = UINT32_MAX;
    float best = -1.0f;
    for (uint32_t i = 0; i < ls->count; ++i) {
        float p = light_sampler_pmf(sampler, &ctx, i);
        if (outcome_of[i] != LIGHT_OUTCOME_NONE && !shared[i] && p > best) { best = p; target = i; }
    }
    free(outcome_of);
    free(shared);
    CHECK(target != UINT32_MAX, "no light has an outcome of its own at the test vertex");
    if (target == UINT32_MAX) return;
    int blocked = 0;
    for (int v = 0; v < 400; ++v) {
        LightSampleContext c = v == 0 ? ctx
                                      : (LightSampleContext){v3_add(ctx.p, v3(0.3f * rng_uniform(key, 60000 + 3 * v) - 0.15f,
                                                                              0.3f * rng_uniform(key, 60001 + 3 * v) - 0.15f,
                                                                              0.3f * rng_uniform(key, 60002 + 3 * v) - 0.15f)),
                                                             v3(0, 1, 0), {0, 0.0f}, scratch};
        light_sampler_prepare(sampler, &c, &hint);
        for (int s = 0; s < (v == 0 ? 20000 : 400); ++s) {
            float pmf;
            uint32_t outcome, l = light_sampler_select(sampler, &c, rng_uniform(key, 100000 * v + 2 * s),
                                                       rng_uniform(key, 100000 * v + 2 * s + 1), &pmf, &outcome);
            blocked += l == target;
            light_sampler_record(sampler, outcome, l == target ? 0.0f : 1.0f);
        }
    }
    light_sampler_barrier(sampler);
    LightSampleContext after = ctx;
    light_sampler_prepare(sampler, &after, &hint);
    float learned = light_sampler_pmf(sampler, &after, target);
    fprintf(stderr, "  %s: light %u blocked %d times: pmf %.4g -> %.4g\n", sampler->ops->name, target, blocked, best,
            learned);
    CHECK(learned < 0.5f * best, "an always-blocked light keeps pmf %g (was %g)", learned, best);
    double sum = 0.0;
    for (uint32_t i = 0; i < ls->count; ++i) sum += light_sampler_pmf(sampler, &after, i);
    CHECK(fabs(sum - 1.0) < 1e-4, "after learning the pmf sums to %.7f", sum);
    int mismatch = 0;
    for (int s = 0; s < 2000; ++s) {
        float pmf;
        uint32_t outcome, l = light_sampler_select(sampler, &after, rng_uniform(key, 90000 + 2 * s),
                                                   rng_uniform(key, 90001 + 2 * s), &pmf, &outcome);
        mismatch += pmf != light_sampler_pmf(sampler, &after, l);
    }
    CHECK(mismatch == 0, "after learning %d selections disagree with the pmf", mismatch);
}

static void check_strategy_occl(const char *path, CandelaLightSampler strategy, const char *env, int occlusion) {
    CandelaOptions o;
    candela_options_default(&o);
    o.optimal_occlusion = occlusion;
    o.scene_path = path;
    o.light_sampler = strategy;
    o.width = o.height = 8;
    /* the learning check visits vertices within 0.15 of one point: it needs the points there
     * as dense as the paper's fixed 100,000 candidates make them, not as few as an 8x8 image
     * needs (the default scales the candidates with the pixels) */
    o.cachepoint_candidates = 100000;
    o.cachepoint_pilots = 65536;
    o.env_path = env;
    Scene scene;
    char err[CANDELA_ERR_LEN];
    int rc = scene_load(&scene, &o, err);
    CHECK(rc == 0, "%s", err);
    if (rc != 0) return;
    Lights lights;
    rc = lights_build(&lights, &scene, NULL, o.light_units, err, sizeof err);
    CHECK(rc == 0, "%s", err);
    if (rc != 0) { scene_free(&scene); return; }
    /* the strategy is driven through the light-selection protocol alone (light_sampler.h) */
    ThreadPool *pool = threadpool_create(2);
    LightSampler sampler;
    rc = light_sampler_create(&sampler, &lights, &scene, NULL, pool, &o, err);
    CHECK(rc == 0, "light sampler: %s", err);
    if (rc != 0) { lights_free(&lights); scene_free(&scene); threadpool_destroy(pool); return; }
    CHECK(strcmp(sampler.ops->name, candela_light_sampler_name(strategy)) == 0, "asked for %s, got %s (fell back?)",
          candela_light_sampler_name(strategy), sampler.ops->name);
    const Lights *ls = &lights;
    CHECK(ls->count > 1, "lights: %u", ls->count);
    {
        /* the estimate table (area points eight per AVX register where the CPU has AVX, four
         * per SSE2 register otherwise: both are run) is bit for bit the reference estimate,
         * for every light, at random receivers facing any way and omnidirectional */
        LightEstimateTable table;
        CHECK(light_estimate_table_build(&table, ls) == 0, "estimate table: out of memory");
        uint64_t tkey = rng_path_key(11, 4, 2);
        int mismatches = 0;
        for (int i = 0; i < 4000; ++i) {
            if (i == 2000) table.avx = 0; /* the second half on the SSE2 (or scalar) lanes */
            vec3 x = v3(rng_uniform(tkey, 6 * i) * 4 - 2, rng_uniform(tkey, 6 * i + 1) * 4 - 1, rng_uniform(tkey, 6 * i + 2) * 4 - 2);
            vec3 nrm = i % 5 == 4 ? v3s(0.0f)
                                  : v3_normalize(v3(rng_uniform(tkey, 6 * i + 3) * 2 - 1, rng_uniform(tkey, 6 * i + 4) * 2 - 1,
                                                    rng_uniform(tkey, 6 * i + 5) * 2 - 1));
            for (uint32_t l = 0; l < ls->count; ++l) {
                float a = light_contribution_estimate_table(ls, &table, l, x, nrm);
                float b = light_contribution_estimate(ls, &ls->lights[l], x, nrm);
                mismatches += memcmp(&a, &b, sizeof a) != 0;
            }
        }
        CHECK(mismatches == 0, "%s: %d table estimates differ from the reference's bits", path, mismatches);
        light_estimate_table_free(&table);
    }
    uint64_t key = rng_path_key(3, 1, 2);
    /* optimal is O(lights) per call (and a shadow ray per light with occlusion): fewer draws */
    const int contexts = strategy == CANDELA_LIGHT_SAMPLER_OPTIMAL ? (occlusion ? 2 : 4) : 8;
    const int N = strategy == CANDELA_LIGHT_SAMPLER_OPTIMAL ? 20000 : 200000;
    for (int q = 0; q < contexts; ++q) {
        /* the last context is a point in a medium (zero normal) */
        LightSampleContext ctx = {v3(rng_uniform(key, 3 * q) * 2 - 1, rng_uniform(key, 3 * q + 1) * 2, rng_uniform(key, 3 * q + 2) * 2 - 1),
                                  q == 7 ? v3(0, 0, 0) : v3(0, 1, 0)};
        /* Every strategy sums to exactly 1 whenever some light has power. The tree too: where
         * the bounds say a point sees neither child of a node, it splits by power instead of
         * returning "no light" (lighttree.h), so a sum of 0 is never expected here. */
        double sum = 0.0;
        for (uint32_t i = 0; i < ls->count; ++i) sum += light_sampler_pmf(&sampler, &ctx, i);
        CHECK(fabs(sum - 1.0) < 1e-4, "strategy %d: pmf sums to %.7f", (int)strategy, sum);
        /* as the wavefront does: prepare the vertex once (the strategy's per-vertex work, e.g.
         * its cache point and near lights' weights); the prepared context must give exactly the
         * unprepared probabilities */
        float scratch[LIGHT_SAMPLER_SCRATCH];
        LightSampleContext raw = ctx;
        ctx.scratch = scratch;
        uint32_t hint = UINT32_MAX;
        light_sampler_prepare(&sampler, &ctx, &hint);
        int prepared_differs = 0;
        for (uint32_t i = 0; i < ls->count; ++i)
            prepared_differs += light_sampler_pmf(&sampler, &ctx, i) != light_sampler_pmf(&sampler, &raw, i);
        CHECK(prepared_differs == 0, "strategy %d: %d pmfs differ between prepared and raw contexts", (int)strategy,
              prepared_differs);
        /* select/pmf consistency and frequencies */
        uint32_t *hist = calloc(ls->count, sizeof *hist);
        int mismatch = 0;
        for (int s = 0; s < N; ++s) {
            float pmf;
            uint32_t outcome;
            uint32_t i = light_sampler_select(&sampler, &ctx, rng_uniform(key, 1000 + s), rng_uniform(key, 900000 + s),
                                              &pmf, &outcome);
            if (i >= ls->count || pmf != light_sampler_pmf(&sampler, &ctx, i)) ++mismatch;
            else hist[i]++;
        }
        CHECK(mismatch == 0, "%d selections disagree with light_sampler_pmf", mismatch);
        double *obs = malloc(ls->count * sizeof *obs), *expv = malloc(ls->count * sizeof *expv);
        for (uint32_t i = 0; i < ls->count; ++i) {
            obs[i] = hist[i];
            expv[i] = N * (double)light_sampler_pmf(&sampler, &ctx, i);
        }
        int dof;
        double stat, p = chi2_pvalue(obs, expv, (int)ls->count, &dof, &stat);
        CHECK(dof <= 0 || p > 1e-5, "selection histogram chi2 %.1f (dof %d), p = %.2g", stat, dof, p);
        free(obs);
        free(expv);
        free(hist);
    }
    if (light_sampler_learns(&sampler)) check_learning(&sampler, ls, key);
    /* sample_li pdf == standalone pdf (area: light_area_pdf_li, env: light_env_pdf_li) */
    vec3 p = v3(0.1f, 0.7f, 0.2f);
    LightSampleContext pctx = {p, v3(0, 1, 0)};
    int checked = 0;
    for (uint32_t i = 0; i < ls->count; ++i) {
        const Light *l = &ls->lights[i];
        for (int s = 0; s < 50; ++s) {
            LightLiSample smp;
            if (!light_sample_li(ls, l, &pctx, rng_uniform(key, 5000 + 3 * s), rng_uniform(key, 5001 + 3 * s),
                                 rng_uniform(key, 5002 + 3 * s), 0.5f, &smp))
                continue;
            CHECK(isfinite(smp.pdf) && smp.pdf > 0, "light %u: pdf %g", i, smp.pdf);
            if (l->type == LIGHT_ENVIRONMENT) {
                float pdf = light_env_pdf_li(ls, smp.wi);
                CHECK(fabsf(pdf - smp.pdf) <= 2e-3f * smp.pdf, "env pdf %g vs %g", pdf, smp.pdf);
                ++checked;
            } else if (l->type == LIGHT_AREA) {
                /* the sampled point and its triangle's normal */
                vec3 y = v3_madd(p, smp.wi, smp.distance);
                CHECK(smp.triangle < l->triangles.n, "triangle %u of %u", smp.triangle, l->triangles.n);
                const float *w = l->world_vertices + 9 * (size_t)smp.triangle;
                vec3 a = v3(w[0], w[1], w[2]), b = v3(w[3], w[4], w[5]), c = v3(w[6], w[7], w[8]);
                vec3 n = v3_normalize(v3_cross(v3_sub(b, a), v3_sub(c, a)));
                float pdf = light_area_pdf_li(l, &pctx, smp.triangle, y, n);
                CHECK(fabsf(pdf - smp.pdf) <= 2e-3f * smp.pdf, "area pdf %g vs %g", pdf, smp.pdf);
                ++checked;
            }
        }
    }
    CHECK(checked > 0, "no area/env light sample was checked");
    light_sampler_free(&sampler);
    lights_free(&lights);
    scene_free(&scene);
    threadpool_destroy(pool);
}

static void check_strategy(const char *path, CandelaLightSampler strategy, const char *env) {
    check_strategy_occl(path, strategy, env, 0);
}

/* `auto`'s documented choice (light_sampler.h) from the lights alone: power for one light,
 * optimal while the estimate cost (punctual 1, area LIGHT_SAMPLER_AUTO_AREA_COST) is at most
 * LIGHT_SAMPLER_AUTO_EXACT_COST, cache points above it or with media (but power for one light). */
static void check_auto_choice(void) {
    static Light ls[300];
    CandelaOptions o;
    candela_options_default(&o);
    CHECK(o.light_sampler == CANDELA_LIGHT_SAMPLER_AUTO, "the default is not auto");
    struct { uint32_t points, areas; CandelaLightSampler want; } cases[] = {
        {1, 0, CANDELA_LIGHT_SAMPLER_POWER},        {0, 1, CANDELA_LIGHT_SAMPLER_POWER},
        {4, 1, CANDELA_LIGHT_SAMPLER_OPTIMAL},      {128, 0, CANDELA_LIGHT_SAMPLER_OPTIMAL},
        {64, 8, CANDELA_LIGHT_SAMPLER_OPTIMAL},     {129, 0, CANDELA_LIGHT_SAMPLER_CACHEPOINTS},
        {16, 64, CANDELA_LIGHT_SAMPLER_CACHEPOINTS}, {300, 0, CANDELA_LIGHT_SAMPLER_CACHEPOINTS}};
    for (size_t c = 0; c < sizeof cases / sizeof cases[0]; ++c) {
        uint32_t n = cases[c].points + cases[c].areas;
        for (uint32_t i = 0; i < n; ++i) ls[i].type = i < cases[c].points ? LIGHT_POINT : LIGHT_AREA;
        Lights lights = {.lights = ls, .count = n, .environment = -1};
        CandelaLightSampler got = light_sampler_auto_choice(&lights, NULL, &o);
        CHECK(got == cases[c].want, "auto with %u point and %u area lights chose %s, not %s", cases[c].points,
              cases[c].areas, candela_light_sampler_name(got), candela_light_sampler_name(cases[c].want));
        /* with media: cache points (in-scattering sampling needs their weights), but for one light,
         * where power's own estimate gives them without a build */
        SceneMedia media = {.num_homogeneous = 1};
        got = light_sampler_auto_choice(&lights, &media, &o);
        CandelaLightSampler want = n <= 1 ? CANDELA_LIGHT_SAMPLER_POWER : CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
        CHECK(got == want, "auto with media and %u lights chose %s, not %s", n, candela_light_sampler_name(got),
              candela_light_sampler_name(want));
    }
}

int main(int argc, char **argv) {
    check_auto_choice();
    if (argc < 3) SKIP("usage: test_lights MANY_LIGHTS.gltf SCENES_DIR");
    FILE *f = fopen(argv[1], "rb");
    if (!f) SKIP("%s not found (shared assets absent)", argv[1]);
    fclose(f);
    char env[1024];
    snprintf(env, sizeof env, "%s/sky.hdr", argv[2]);
    FILE *fe = fopen(env, "rb");
    const char *envp = fe ? env : NULL;
    if (fe) fclose(fe);
    check_strategy(argv[1], CANDELA_LIGHT_SAMPLER_UNIFORM, envp);
    check_strategy(argv[1], CANDELA_LIGHT_SAMPLER_POWER, envp);
    check_strategy(argv[1], CANDELA_LIGHT_SAMPLER_TREE, envp);
    check_strategy(argv[1], CANDELA_LIGHT_SAMPLER_OPTIMAL, envp);
    check_strategy_occl(argv[1], CANDELA_LIGHT_SAMPLER_OPTIMAL, envp, 1);
    check_strategy(argv[1], CANDELA_LIGHT_SAMPLER_CACHEPOINTS, envp);
    return test_exit();
}
