/* Light BVH (renderer/lights/lighttree.c), on Light structs built in memory (no scene):
 *   (a) 10,000 random point/spot lights with random powers, a few one- and two-sided area
 *       lights, a directional light and a zero-power light: at 50 random contexts (surface
 *       points and medium points) the pmf sums to 1 over all lights, 100k selections report
 *       exactly light_tree_pmf() of the light they pick, and the selection frequencies pass a
 *       chi-square test (bins with expected count < 5 pooled);
 *   (b) two-light trees whose probabilities are worked out by hand from the importance
 *       (point lights: phi |n.w| / d^2; spot: times cos of the angle off its axis, zero outside
 *       the outer cone; both invisible: split by power), plus degenerate trees (no light, one
 *       light, only infinite lights, only zero-power lights);
 *   (c) a 1,000,000-point-light build succeeds (its time is printed, not asserted);
 *   (d) the importance culls only lights that cannot contribute (brute force over points on
 *       every light: pmf > 0 wherever some point of a light reaches the receiver), a node is
 *       0 only when every light below it is, and pbrt-v4's terms by hand: spots weigh by
 *       intensity, two-sided emitters keep their normal cone, receivers are one-sided. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "stats.h"
#include "lights.h"
#include "lighttree.h"

static uint64_t g_state = 0x9e3779b97f4a7c15ull;
static double rnd(void) { return splitmix_uniform(&g_state); }
static float rndf(float lo, float hi) { return lo + (hi - lo) * (float)rnd(); }
static vec3 rnd_dir(void) {
    float z = rndf(-1.0f, 1.0f), phi = rndf(0.0f, 2.0f * PI_F), r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
    return v3(r * cosf(phi), r * sinf(phi), z);
}

static Light point_light(vec3 p, float power) {
    Light l;
    memset(&l, 0, sizeof l);
    l.type = LIGHT_POINT;
    l.position = p;
    l.power = power;
    return l;
}
/* `power` here is the tree's phi, 4 pi times the peak intensity (Light.power, the flux, is
 * set to the same positive value; the tree only checks that it is positive) */
static Light spot_light(vec3 p, vec3 dir, float outer, float power) {
    Light l = point_light(p, power);
    l.type = LIGHT_SPOT;
    l.intensity = v3s(power / (4.0f * PI_F));
    l.direction = v3_normalize(dir);
    l.cos_outer = cosf(outer);
    l.cos_inner = cosf(0.5f * outer);
    return l;
}
/* A quad of two triangles, centre c, edge vectors e1, e2; front face along e1 x e2. */
static Light quad_light(vec3 c, vec3 e1, vec3 e2, float radiance, int two_sided) {
    Light l;
    memset(&l, 0, sizeof l);
    l.type = LIGHT_AREA;
    l.two_sided = two_sided;
    vec3 a = v3_sub(v3_sub(c, v3_scale(e1, 0.5f)), v3_scale(e2, 0.5f));
    vec3 b = v3_add(a, e1), d = v3_add(a, e2), e = v3_add(b, e2);
    vec3 v[6] = {a, b, e, a, e, d};
    l.world_vertices = malloc(18 * sizeof(float));
    for (int i = 0; i < 6; ++i) {
        l.world_vertices[3 * i] = v[i].x;
        l.world_vertices[3 * i + 1] = v[i].y;
        l.world_vertices[3 * i + 2] = v[i].z;
    }
    float area = v3_length(v3_cross(e1, e2));
    float areas[2] = {0.5f * area, 0.5f * area};
    dist1d_init(&l.triangles, areas, 2);
    l.area = area;
    l.emission = v3s(radiance);
    l.power = PI_F * area * radiance * (two_sided ? 2.0f : 1.0f);
    return l;
}
static void free_lights(Light *ls, uint32_t n) {
    for (uint32_t i = 0; i < n; ++i)
        if (ls[i].type == LIGHT_AREA) {
            dist1d_free(&ls[i].triangles);
            free(ls[i].world_vertices);
        }
    free(ls);
}

/* ---------------------------------------------------------------- (a) */

static void test_random(void) {
    enum { NPUNCT = 10000, NAREA = 6, N = NPUNCT + NAREA + 2 };
    Light *ls = calloc(N, sizeof *ls);
    uint32_t n = 0;
    for (int i = 0; i < NPUNCT; ++i) {
        vec3 p = v3(rndf(-10, 10), rndf(0, 5), rndf(-10, 10));
        float power = (float)exp(rndf(-3.0f, 3.0f));
        if (i % 3 == 0) ls[n++] = spot_light(p, rnd_dir(), rndf(0.05f, 1.5f), power);
        else ls[n++] = point_light(p, power);
    }
    for (int i = 0; i < NAREA; ++i)
        ls[n++] = quad_light(v3(rndf(-8, 8), rndf(1, 5), rndf(-8, 8)), v3_scale(rnd_dir(), rndf(0.2f, 3.0f)),
                             v3_scale(rnd_dir(), rndf(0.2f, 3.0f)), rndf(1.0f, 20.0f), i % 2);
    Light dir;
    memset(&dir, 0, sizeof dir);
    dir.type = LIGHT_DIRECTIONAL;
    dir.direction = v3(0, -1, 0);
    dir.power = 50.0f;
    ls[n++] = dir;
    ls[n++] = point_light(v3(0, 1, 0), 0.0f); /* zero power: never chosen */
    CHECK(n == N, "%u lights", n);

    LightTree t;
    double t0 = test_seconds();
    CHECK(light_tree_build(&t, ls, n) == 0, "build failed");
    fprintf(stderr, "  (a) %u lights: build %.3f s, %u nodes, p_inf %g\n", n, test_seconds() - t0, t.node_count, t.p_inf);
    CHECK(t.node_count == 2 * (N - 2) - 1, "node count %u", t.node_count);
    CHECK(t.num_infinite == 1 && t.p_inf == 0.5f, "infinite lights %u, p_inf %g", t.num_infinite, t.p_inf);

    double *pmf = malloc(n * sizeof *pmf);
    uint32_t *hist = malloc(n * sizeof *hist);
    enum { NSEL = 100000, NCTX = 50 };
    int bad_sum = 0, chi_fail = 0, mismatch = 0, zero_pmf_light = 0;
    for (int q = 0; q < NCTX; ++q) {
        LightSampleContext ctx;
        ctx.p = v3(rndf(-12, 12), rndf(-1, 6), rndf(-12, 12));
        ctx.n = q % 5 == 4 ? v3s(0.0f) : rnd_dir(); /* every fifth: a medium point */
        double sum = 0.0;
        for (uint32_t i = 0; i < n; ++i) {
            pmf[i] = light_tree_pmf(&t, &ctx, i);
            sum += pmf[i];
            if (!(pmf[i] >= 0.0)) ++bad_sum;
        }
        zero_pmf_light += pmf[n - 1] != 0.0;
        /* the directional light (travelling -y) and the BVH share equally where both can
         * contribute; below the receiver's horizon the light gets nothing */
        double expect_dir = v3_is_black(ctx.n) || ctx.n.y > 0.0f ? 0.5 : 0.0;
        CHECK(pmf[n - 2] == expect_dir, "ctx %d: directional pmf %g, expected %g", q, pmf[n - 2], expect_dir);
        if (!(fabs(sum - 1.0) < 1e-4)) {
            ++bad_sum;
            fprintf(stderr, "FAIL ctx %d: pmf sums to %.7f\n", q, sum);
        }
        memset(hist, 0, n * sizeof *hist);
        for (int s = 0; s < NSEL; ++s) {
            float p;
            uint32_t i = light_tree_select(&t, &ctx, (float)rnd(), &p);
            if (i >= n || p != light_tree_pmf(&t, &ctx, i) || !(p > 0.0f)) ++mismatch;
            else hist[i]++;
        }
        double *obs = malloc(n * sizeof *obs), *expv = malloc(n * sizeof *expv);
        for (uint32_t i = 0; i < n; ++i) { obs[i] = hist[i]; expv[i] = NSEL * pmf[i]; }
        int dof;
        double chi2, pv = chi2_pvalue(obs, expv, (int)n, &dof, &chi2);
        free(obs);
        free(expv);
        if (dof > 0 && !(pv > 1e-5)) {
            ++chi_fail;
            fprintf(stderr, "FAIL ctx %d: chi2 %.1f (dof %d), p = %.2g\n", q, chi2, dof, pv);
        }
        if (q < 3) fprintf(stderr, "  (a) ctx %d: sum %.7f, chi2 dof %d\n", q, sum, dof);
    }
    CHECK(bad_sum == 0, "%d contexts with a bad pmf sum", bad_sum);
    CHECK(mismatch == 0, "%d selections disagree with light_tree_pmf", mismatch);
    CHECK(chi_fail == 0, "%d contexts fail the chi-square test", chi_fail);
    CHECK(zero_pmf_light == 0, "the zero-power light was given a probability");
    free(pmf);
    free(hist);
    light_tree_free(&t);
    free_lights(ls, n);
}

/* ---------------------------------------------------------------- (b) */

/* Builds over two lights and compares both pmfs (and a few selections) with p0, p1. */
static void expect2(const char *name, const Light *two, LightSampleContext ctx, double p0, double p1) {
    LightTree t;
    CHECK(light_tree_build(&t, two, 2) == 0, "%s: build", name);
    float a = light_tree_pmf(&t, &ctx, 0), b = light_tree_pmf(&t, &ctx, 1);
    CHECK(fabs(a - p0) <= 1e-5 * fmax(p0, 1e-30) + 1e-7 && fabs(b - p1) <= 1e-5 * fmax(p1, 1e-30) + 1e-7,
          "%s: pmf %.7g %.7g, expected %.7g %.7g", name, a, b, p0, p1);
    int n0 = 0;
    for (int s = 0; s < 1000; ++s) {
        float p;
        uint32_t i = light_tree_select(&t, &ctx, (s + 0.5f) / 1000.0f, &p);
        CHECK(i < 2 && p == (i ? b : a), "%s: select %u pmf %g", name, i, p);
        n0 += i == 0;
    }
    CHECK(abs(n0 - (int)lround(1000 * p0)) <= 1, "%s: %d of 1000 stratified picks chose light 0, p0 %g", name, n0, p0);
    fprintf(stderr, "  (b) %-28s pmf %.6f %.6f (expected %.6f %.6f)\n", name, a, b, p0, p1);
    light_tree_free(&t);
}

static void test_by_hand(void) {
    Light two[2];
    /* two point lights: importance phi |n.w| / d^2 (box = point, so theta_b = 0) */
    vec3 p = v3(0, 0, 0), n = v3_normalize(v3(0.3f, 1.0f, 0.1f));
    two[0] = point_light(v3(1, 2, 0), 3.0f);
    two[1] = point_light(v3(-2, 1, 1), 1.0f);
    double imp[2];
    for (int i = 0; i < 2; ++i) {
        vec3 d = v3_sub(two[i].position, p);
        double d2 = v3_dot(d, d);
        imp[i] = two[i].power * fabs(v3_dot(n, d)) / sqrt(d2) / d2;
    }
    LightSampleContext ctx = {p, n};
    expect2("two points", two, ctx, imp[0] / (imp[0] + imp[1]), imp[1] / (imp[0] + imp[1]));
    /* medium point: no cosine factor */
    LightSampleContext med = {p, v3s(0.0f)};
    double m0 = 3.0 / 5.0, m1 = 1.0 / 6.0;
    expect2("two points, medium", two, med, m0 / (m0 + m1), m1 / (m0 + m1));
    /* spot at (0,2,0) aiming at (0.5,-1,0): p = origin is 0.4636 rad off its axis, inner
     * cone 0.4, outer 0.8: importance phi cos(angle - inner) |n.w| / d^2 */
    two[0] = spot_light(v3(0, 2, 0), v3(0.5f, -1.0f, 0.0f), 0.8f, 2.0f);
    {
        vec3 d = v3_sub(p, two[0].position);
        double dist = sqrt(v3_dot(d, d));
        double angle = acos(v3_dot(v3_scale(d, 1.0f / (float)dist), two[0].direction));
        double i0 = 2.0 * cos(angle - 0.4) * fabs(v3_dot(n, d)) / dist / (dist * dist);
        vec3 d1 = v3_sub(two[1].position, p);
        double dd1 = v3_dot(d1, d1);
        double i1 = 1.0 * fabs(v3_dot(n, d1)) / sqrt(dd1) / dd1;
        expect2("spot inside its cone + point", two, ctx, i0 / (i0 + i1), i1 / (i0 + i1));
    }
    /* the spot turned away (origin outside its outer cone): probability 0 */
    two[0] = spot_light(v3(0, 2, 0), v3(0.0f, 1.0f, 0.0f), 0.8f, 2.0f);
    expect2("spot facing away + point", two, ctx, 0.0, 1.0);
    /* both spots facing away: the bounds say nothing is visible, split by power */
    two[1] = spot_light(v3(-2, 1, 1), v3(-1.0f, 0.2f, 0.0f), 0.3f, 6.0f);
    expect2("both invisible: by power", two, ctx, 0.25, 0.75);
    /* one-sided quad facing down at height 2 vs the same facing up: only the first is seen */
    two[0] = quad_light(v3(0, 2, 0), v3(0, 0, 1), v3(1, 0, 0), 1.0f, 0); /* z x x = +y: faces up */
    two[1] = quad_light(v3(0, 2, 0), v3(1, 0, 0), v3(0, 0, 1), 1.0f, 0); /* x x z = -y: faces p */
    expect2("one-sided quads", two, ctx, 0.0, 1.0);
    free(two[0].world_vertices); dist1d_free(&two[0].triangles);
    free(two[1].world_vertices); dist1d_free(&two[1].triangles);

    /* degenerate trees */
    LightTree t;
    float pm;
    CHECK(light_tree_build(&t, NULL, 0) == 0, "empty build");
    CHECK(light_tree_select(&t, &ctx, 0.3f, &pm) == 0 && pm == 0.0f, "empty: pmf %g", pm);
    light_tree_free(&t);
    Light one = point_light(v3(5, 5, 5), 2.0f);
    CHECK(light_tree_build(&t, &one, 1) == 0, "one-light build");
    CHECK(light_tree_select(&t, &ctx, 0.7f, &pm) == 0 && pm == 1.0f && light_tree_pmf(&t, &ctx, 0) == 1.0f,
          "one light: pmf %g", pm);
    light_tree_free(&t);
    Light inf[3];
    memset(inf, 0, sizeof inf);
    inf[0].type = LIGHT_DIRECTIONAL;
    inf[1].type = LIGHT_ENVIRONMENT;
    inf[2] = point_light(v3(0, 3, 0), 0.0f);
    CHECK(light_tree_build(&t, inf, 3) == 0, "infinite-only build");
    int seen[3] = {0, 0, 0};
    for (int s = 0; s < 100; ++s) {
        uint32_t i = light_tree_select(&t, &ctx, (s + 0.5f) / 100.0f, &pm);
        CHECK(i < 2 && pm == 0.5f && light_tree_pmf(&t, &ctx, i) == pm, "infinite-only: %u pmf %g", i, pm);
        if (i < 3) seen[i]++;
    }
    CHECK(seen[0] == 50 && seen[1] == 50 && light_tree_pmf(&t, &ctx, 2) == 0.0f, "infinite-only: %d %d", seen[0], seen[1]);
    light_tree_free(&t);
    Light zero[2] = {point_light(v3(0, 1, 0), 0.0f), point_light(v3(0, 2, 0), 0.0f)};
    CHECK(light_tree_build(&t, zero, 2) == 0, "zero-power build");
    uint32_t zi = light_tree_select(&t, &ctx, 0.5f, &pm);
    CHECK(zi < 2 && pm == 0.0f && light_tree_pmf(&t, &ctx, 0) == 0.0f, "zero power: %u pmf %g", zi, pm);
    light_tree_free(&t);
}

/* Degenerate layouts: exponentially spaced lights on a line (SAOH peels a few lights per
 * level, so the depth cap and its median splits are used) and lights all at one point (no
 * split separates anything). The pmf must still sum to 1 and match selections. */
static void test_degenerate_layouts(void) {
    enum { N = 100000 };
    Light *ls = malloc(N * sizeof *ls);
    for (int layout = 0; layout < 2; ++layout) {
        for (int i = 0; i < N; ++i)
            ls[i] = point_light(layout == 0 ? v3(expf(0.0008f * (float)i), 0, 0) : v3(1, 2, 3), 1.0f + (float)(i % 7));
        LightTree t;
        CHECK(light_tree_build(&t, ls, N) == 0, "layout %d: build", layout);
        int maxd = 0, bad_trail = 0;
        for (uint32_t i = 0; i < N; ++i) {
            uint64_t tr = t.trail[i];
            uint32_t node = 0;
            int d = 0;
            while (t.nodes[node].light == LIGHT_TREE_INTERIOR) {
                node = (tr & 1) ? t.nodes[node].child : node + 1;
                tr >>= 1;
                ++d;
            }
            bad_trail += t.nodes[node].light != i;
            if (d > maxd) maxd = d;
        }
        CHECK(bad_trail == 0, "layout %d: %d bit trails lead to another light", layout, bad_trail);
        LightSampleContext ctx = {v3(30.0f, 1.0f, 0.5f), v3(0, 1, 0)};
        double sum = 0.0;
        for (uint32_t i = 0; i < N; ++i) sum += light_tree_pmf(&t, &ctx, i);
        CHECK(fabs(sum - 1.0) < 1e-4, "layout %d: pmf sums to %.7f", layout, sum);
        int mismatch = 0;
        for (int s = 0; s < 10000; ++s) {
            float p;
            uint32_t i = light_tree_select(&t, &ctx, (float)rnd(), &p);
            if (i >= N || !(p > 0.0f) || p != light_tree_pmf(&t, &ctx, i)) ++mismatch;
        }
        CHECK(mismatch == 0, "layout %d: %d selections disagree with the pmf", layout, mismatch);
        CHECK(maxd <= 64, "layout %d: depth %d", layout, maxd);
        fprintf(stderr, "  %s: max depth %d, pmf sum %.7f\n", layout == 0 ? "exponential line" : "coincident", maxd, sum);
        light_tree_free(&t);
    }
    free(ls);
}

/* ---------------------------------------------------------------- (d) */

/* Whether `l` can send light to (p, n) by brute force: some point of it (the position; for a
 * quad 64 stratified points) emits towards p (spot falloff > 0, the emitting face) and lies
 * above the receiver's horizon (n zero: every direction). */
static int contributes(const Light *l, vec3 p, vec3 n) {
    if (l->type == LIGHT_POINT || l->type == LIGHT_SPOT) {
        vec3 d = v3_sub(p, l->position);
        float d2 = v3_dot(d, d);
        if (!(d2 > 0.0f)) return 0;
        vec3 w = v3_scale(d, 1.0f / sqrtf(d2));
        if (l->type == LIGHT_SPOT && !(light_spot_falloff(l, w) > 0.0f)) return 0;
        return v3_is_black(n) || -v3_dot(n, w) > 0.0f;
    }
    for (int k = 0; k < 64; ++k) {
        const float *v = l->world_vertices + 9 * (k & 1);
        vec3 a = v3(v[0], v[1], v[2]), b = v3(v[3], v[4], v[5]), c = v3(v[6], v[7], v[8]);
        float u0 = ((float)(k >> 1) + 0.5f) / 32.0f, u1 = (float)((k * 13) % 32 + 0.5f) / 32.0f;
        vec2 bc = sample_uniform_triangle(u0, u1);
        vec3 y = v3_add(v3_add(v3_scale(a, 1.0f - bc.x - bc.y), v3_scale(b, bc.x)), v3_scale(c, bc.y));
        vec3 ng = v3_normalize(v3_cross(v3_sub(b, a), v3_sub(c, a)));
        vec3 d = v3_sub(p, y);
        float cos_l = v3_dot(ng, d);
        if (l->two_sided) cos_l = fabsf(cos_l);
        if (cos_l > 1e-4f * v3_length(d) && (v3_is_black(n) || -v3_dot(n, d) > 1e-4f * v3_length(d))) return 1;
    }
    return 0;
}

/* Whether a light below `node` can contribute (reach[light] from contributes()); counts the
 * nodes with importance 0 above such a light (the bound would cull a light that matters). */
static int any_reaches(const LightTree *t, uint32_t node, vec3 p, vec3 n, const char *reach, int *not_conservative) {
    const LightTreeNode *nd = &t->nodes[node];
    int any = nd->light != LIGHT_TREE_INTERIOR
                  ? reach[nd->light]
                  : any_reaches(t, node + 1, p, n, reach, not_conservative) |
                        any_reaches(t, nd->child, p, n, reach, not_conservative);
    if (any && !(light_tree_node_importance(nd, p, n) > 0.0f)) ++*not_conservative;
    return any;
}

/* The importance culls only what cannot contribute: for random receivers (surface points,
 * and medium points with n = 0) around random points, spots (hard and soft cones), one- and
 * two-sided quads, (i) every light that can send light to the receiver has pmf > 0 (the
 * estimator stays unbiased), (ii) a node has importance 0 only when no light below it can
 * contribute, (iii) the pmf sums to 1 and selections report it bit for bit. */
static void test_conservative(void) {
    enum { NL = 600, NCTX = 400 };
    Light *ls = calloc(NL, sizeof *ls);
    for (int i = 0; i < NL; ++i) {
        vec3 c = v3(rndf(-6, 6), rndf(0, 4), rndf(-6, 6));
        float power = (float)exp(rndf(-2.0f, 2.0f));
        switch (i % 4) {
        case 0: ls[i] = point_light(c, power); break;
        case 1: {
            float outer = rndf(0.02f, 1.5f);
            ls[i] = spot_light(c, rnd_dir(), outer, power);
            if (i % 8 == 1) ls[i].cos_inner = ls[i].cos_outer; /* a hard cone */
            break;
        }
        default:
            ls[i] = quad_light(c, v3_scale(rnd_dir(), rndf(0.05f, 2.0f)), v3_scale(rnd_dir(), rndf(0.05f, 2.0f)),
                               rndf(0.5f, 5.0f), i % 4 == 3);
        }
    }
    LightTree t;
    CHECK(light_tree_build(&t, ls, NL) == 0, "build");
    int culled = 0, not_conservative = 0, bad_sum = 0, mismatch = 0, contributing = 0;
    char *reach = malloc(NL);
    for (int q = 0; q < NCTX; ++q) {
        LightSampleContext ctx;
        memset(&ctx, 0, sizeof ctx);
        ctx.p = v3(rndf(-8, 8), rndf(-1, 5), rndf(-8, 8));
        ctx.n = q % 4 == 3 ? v3s(0.0f) : rnd_dir();
        double sum = 0.0;
        for (uint32_t i = 0; i < NL; ++i) {
            float pm = light_tree_pmf(&t, &ctx, i);
            sum += pm;
            reach[i] = (char)contributes(&ls[i], ctx.p, ctx.n);
            if (reach[i]) {
                ++contributing;
                if (!(pm > 0.0f)) {
                    if (culled < 5)
                        fprintf(stderr, "FAIL ctx %d: light %u (type %d) contributes, pmf %g\n", q, i, ls[i].type, pm);
                    ++culled;
                }
            }
        }
        if (!(fabs(sum - 1.0) < 1e-4)) ++bad_sum;
        any_reaches(&t, 0, ctx.p, ctx.n, reach, &not_conservative);
        for (int s = 0; s < 200; ++s) {
            float pm;
            uint32_t i = light_tree_select(&t, &ctx, (float)rnd(), &pm);
            if (i >= NL || !(pm > 0.0f) || pm != light_tree_pmf(&t, &ctx, i)) ++mismatch;
        }
    }
    fprintf(stderr, "  (d) %d contributing (light, receiver) pairs, %d culled, %d non-conservative nodes\n",
            contributing, culled, not_conservative);
    CHECK(contributing > NCTX * NL / 10, "only %d contributing pairs: the test says little", contributing);
    CHECK(culled == 0, "%d lights that contribute got pmf 0", culled);
    CHECK(not_conservative == 0, "%d nodes have importance 0 above a light that contributes", not_conservative);
    CHECK(bad_sum == 0, "%d contexts with a pmf sum away from 1", bad_sum);
    CHECK(mismatch == 0, "%d selections disagree with light_tree_pmf", mismatch);
    free(reach);
    light_tree_free(&t);
    free_lights(ls, NL);
}

/* The terms pbrt-v4's LightBounds adds over a plain power / d^2: (i) a spot weighs by its
 * intensity, not its flux: two spots of one intensity, one 1 degree and one 40 degrees wide,
 * both aimed at p from the same distance, are equally likely; (ii) a two-sided quad keeps its
 * normal cone: edge-on it gets only what its angular size allows, from behind it gets what
 * it gets from the front; (iii) the receiver is one-sided: a light wholly
 * below the horizon of n gets 0, and the same light for n = 0 (a medium point) does not. */
static void test_terms(void) {
    Light two[2];
    vec3 p = v3(0, 0, 0), up = v3(0, 1, 0);
    LightSampleContext ctx = {p, up};
    two[0] = spot_light(v3(-1, 3, 0), v3(1, -3, 0), 1.0f * PI_F / 180.0f, 5.0f);
    two[1] = spot_light(v3(1, 3, 0), v3(-1, -3, 0), 40.0f * PI_F / 180.0f, 5.0f);
    expect2("narrow and wide spot", two, ctx, 0.5, 0.5);

    /* a 1 m quad in the plane y = 0 at x = 3 (normal +y), p at the origin: edge-on, only its
     * angular size theta_b (sin theta_b = r/d, r = |diag|/2) lets it emit towards p: importance
     * phi sin(theta_b) / d^2, not phi / d^2 as a whole-sphere cone would give */
    two[0] = quad_light(v3(3, 0, 0), v3(1, 0, 0), v3(0, 0, 1), 1.0f, 1);
    two[1] = point_light(v3(0, 2, 0), 1.0f);
    LightSampleContext med = {p, v3s(0.0f)};
    {
        double i0 = 2.0 * PI_F * (sqrt(0.5) / 3.0) / 9.0, i1 = 1.0 / 4.0;
        expect2("two-sided quad edge-on", two, med, i0 / (i0 + i1), i1 / (i0 + i1));
    }
    free(two[0].world_vertices); dist1d_free(&two[0].triangles);
    /* the same quad above p at y = 2, seen from below (its back) and, mirrored, from above */
    two[0] = quad_light(v3(0, 2, 0), v3(0, 0, 1), v3(1, 0, 0), 1.0f, 1); /* z x x = +y: p is behind */
    two[1] = quad_light(v3(0, -2, 0), v3(0, 0, 1), v3(1, 0, 0), 1.0f, 1); /* faces +y: p is in front */
    expect2("two-sided quad front and back", two, med, 0.5, 0.5);
    free(two[0].world_vertices); dist1d_free(&two[0].triangles);
    free(two[1].world_vertices); dist1d_free(&two[1].triangles);

    /* a point light below the horizon (and a 0.5 m cluster of two, whose bounding sphere is
     * below it too): 0 for the surface point, by 1/d^2 for the medium point */
    two[0] = point_light(v3(1, -1, 0), 1.0f);
    two[1] = point_light(v3(0, 3, 0), 1.0f);
    expect2("point below the horizon", two, ctx, 0.0, 1.0);
    expect2("point below, medium receiver", two, med, 0.5 / (0.5 + 1.0 / 9.0), (1.0 / 9.0) / (0.5 + 1.0 / 9.0));
    /* (iv) a directional light below the horizon gets no share (the BVH takes it all); the BVH
     * wholly below the horizon gets none (the directional light takes it all); in a medium
     * both get pbrt-v4's equal shares */
    Light dir;
    memset(&dir, 0, sizeof dir);
    dir.type = LIGHT_DIRECTIONAL;
    dir.power = 1.0f;
    dir.direction = v3(0, 1, 0); /* travels up: lights surfaces facing down */
    two[0] = dir;
    two[1] = point_light(v3(0, 3, 0), 1.0f);
    expect2("directional below the horizon", two, ctx, 0.0, 1.0);
    expect2("directional, medium receiver", two, med, 0.5, 0.5);
    two[0].direction = v3(0.3f, -1.0f, 0.0f);
    two[1] = point_light(v3(0, -3, 0), 1.0f);
    expect2("BVH below the horizon", two, ctx, 1.0, 0.0);
}

/* ---------------------------------------------------------------- (c) */

static void test_million(void) {
    enum { N = 1000000 };
    Light *ls = malloc(N * sizeof *ls);
    for (int i = 0; i < N; ++i) ls[i] = point_light(v3(rndf(-100, 100), rndf(-100, 100), rndf(-100, 100)), rndf(0.1f, 10.0f));
    LightTree t;
    double t0 = test_seconds();
    int rc = light_tree_build(&t, ls, N);
    double dt = test_seconds() - t0;
    CHECK(rc == 0, "1M build failed");
    fprintf(stderr, "  (c) 1,000,000 point lights: build %.3f s, %u nodes\n", dt, t.node_count);
    LightSampleContext ctx = {v3(1, 2, 3), v3(0, 1, 0)};
    int mismatch = 0;
    for (int s = 0; s < 1000; ++s) {
        float p;
        uint32_t i = light_tree_select(&t, &ctx, (float)rnd(), &p);
        if (i >= N || !(p > 0.0f) || p != light_tree_pmf(&t, &ctx, i)) ++mismatch;
    }
    CHECK(mismatch == 0, "1M: %d selections disagree with the pmf", mismatch);
    light_tree_free(&t);
    free(ls);
}

int main(void) {
    test_by_hand();
    test_terms();
    test_conservative();
    test_random();
    test_degenerate_layouts();
    test_million();
    return test_exit();
}
