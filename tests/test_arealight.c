/* Emissive meshes: the inner light tree over an area light's triangles (lighttree.h,
 * light_tree_build_triangles; cache-points spec §5.5), on Light structs built in memory:
 *   (a) on a one-sided bumpy sheet of ~2,000 triangles and a two-sided closed sphere, the
 *       triangle pmf sums to 1 at random shading points (surface and medium contexts);
 *   (b) light_tree_select reports exactly light_tree_pmf of the triangle it picks, and
 *       light_sample_li's pdf equals light_area_pdf_li for its sampled triangle and point;
 *   (c) Monte Carlo irradiance at a point with the tree (radiance cos / pdf) agrees with the
 *       same estimate by area-proportional sampling within 5 standard errors;
 *   (d) the tree has lower variance than the area CDF for a point close to one side of a
 *       large sheet (both printed);
 *   (e) the fallback: from behind a one-sided sheet the root has no importance, so the area
 *       CDF is used, and the pdf function agrees; small lights (<= 8 triangles) build no tree;
 *   (f) a 1,000,000-triangle mesh builds (its time is printed, not asserted);
 *   (g) the refit of another instance (light_tree_refit_triangles): over the same vertices it
 *       equals the build bit for bit; over a rotated, non-uniformly scaled, mirrored and moved
 *       copy it passes (a)-(c); a copy with another triangle count, or with a triangle that no
 *       longer emits, is refused (the caller builds);
 *   (h) a tree shared in object space (LightSharedTree): copies rotated and scaled 2.5x, and
 *       stretched 1.6x, that read the object-space tree pass (a)-(c); under the uniform scale
 *       its variance is at most 1.5x a world-space refit's at three contexts (both printed); a
 *       mirror, a 3x stretch and a shear are refused. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "stats.h"
#include "lights.h"
#include "lighttree.h"
#include "scene.h"

static uint64_t g_state = 0x243f6a8885a308d3ull;
static double rnd(void) { return splitmix_uniform(&g_state); }
static float rndf(float lo, float hi) { return lo + (hi - lo) * (float)rnd(); }

/* A light from a vertex grid: vertex (i, j) at pos(i, j), two triangles per cell. */
typedef vec3 (*GridFn)(int i, int j, int nu, int nv);

static Light grid_light(GridFn pos, int nu, int nv, float radiance, int two_sided) {
    Light l;
    memset(&l, 0, sizeof l);
    l.type = LIGHT_AREA;
    l.two_sided = two_sided;
    uint32_t nt = 2u * (uint32_t)nu * (uint32_t)nv;
    l.world_vertices = malloc((size_t)nt * 9 * sizeof(float));
    float *areas = malloc(nt * sizeof(float));
    double total = 0.0;
    uint32_t t = 0;
    for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
            vec3 a = pos(i, j, nu, nv), b = pos(i + 1, j, nu, nv), c = pos(i + 1, j + 1, nu, nv), d = pos(i, j + 1, nu, nv);
            vec3 tri[2][3] = {{a, c, b}, {a, d, c}}; /* wound so the normal is +y for the flat sheet */
            for (int k = 0; k < 2; ++k, ++t) {
                for (int v = 0; v < 3; ++v) {
                    l.world_vertices[9 * (size_t)t + 3 * v] = tri[k][v].x;
                    l.world_vertices[9 * (size_t)t + 3 * v + 1] = tri[k][v].y;
                    l.world_vertices[9 * (size_t)t + 3 * v + 2] = tri[k][v].z;
                }
                areas[t] = 0.5f * v3_length(v3_cross(v3_sub(tri[k][1], tri[k][0]), v3_sub(tri[k][2], tri[k][0])));
                total += areas[t];
            }
        }
    dist1d_init(&l.triangles, areas, nt);
    free(areas);
    l.area = (float)total;
    l.emission = v3(radiance, 0.8f * radiance, 0.6f * radiance);
    l.power = PI_F * l.area * v3_luminance(l.emission) * (two_sided ? 2.0f : 1.0f);
    CHECK(light_area_tree_build(&l) == 0, "tree build failed");
    return l;
}

/* 4 x 4 sheet in y = 0 with a gentle bump (normals vary), facing +y */
static vec3 sheet(int i, int j, int nu, int nv) {
    float x = -2.0f + 4.0f * (float)i / (float)nu, z = -2.0f + 4.0f * (float)j / (float)nv;
    return v3(x, 0.15f * sinf(1.7f * x) * cosf(1.3f * z), z);
}
/* 20 x 20 flat sheet in y = 0 */
static vec3 big_sheet(int i, int j, int nu, int nv) {
    return v3(-10.0f + 20.0f * (float)i / (float)nu, 0.0f, -10.0f + 20.0f * (float)j / (float)nv);
}
/* unit sphere around (0, 2, 0); u around, v pole to pole, outward normals */
static vec3 sphere(int i, int j, int nu, int nv) {
    float phi = 2.0f * PI_F * (float)(i % nu) / (float)nu, th = PI_F * (float)j / (float)nv;
    return v3(sinf(th) * cosf(phi), 2.0f + cosf(th), sinf(th) * sinf(phi));
}

/* light_sample_li reads the scene only for the light's material (texture, double-sidedness):
 * lights over a zeroed Scene with one primitive and material stand in. */
typedef struct Fake { Lights lights; Scene scene; ScenePrimitive prim; IoMaterial mat; } Fake;
static void fake_scene(Fake *f, const Light *l) {
    memset(f, 0, sizeof *f);
    f->mat.emissive_tex.image = -1;
    f->mat.base_color_tex.image = f->mat.metallic_roughness_tex.image = f->mat.normal_tex.image = -1;
    f->mat.clearcoat_tex.image = f->mat.clearcoat_roughness_tex.image = -1;
    f->mat.double_sided = l->two_sided;
    f->mat.emissive[0] = l->emission.x;
    f->mat.emissive[1] = l->emission.y;
    f->mat.emissive[2] = l->emission.z;
    f->mat.emissive_strength = 1.0f;
    f->prim.material = &f->mat;
    f->scene.prims = &f->prim;
    f->lights.scene = &f->scene;
    f->lights.environment = -1;
}

static vec3 tri_normal(const Light *l, uint32_t t) {
    const float *w = l->world_vertices + 9 * (size_t)t;
    vec3 a = v3(w[0], w[1], w[2]), b = v3(w[3], w[4], w[5]), c = v3(w[6], w[7], w[8]);
    return v3_normalize(v3_cross(v3_sub(b, a), v3_sub(c, a)));
}

/* (a) pmf sums, (b) select/pmf and sample/pdf agreement at `contexts` random contexts */
static void check_pmf(const char *name, const Light *l, vec3 lo, vec3 hi) {
    Fake f;
    fake_scene(&f, l);
    CHECK(l->tri_tree.node_count > 0 || l->shared_tree, "%s: no inner tree", name);
    uint32_t nt = l->triangles.n;
    int mismatch = 0, pdf_bad = 0, samples = 0, tree_contexts = 0;
    double worst_sum = 0.0;
    for (int q = 0; q < 40; ++q) {
        LightSampleContext ctx = {v3(rndf(lo.x, hi.x), rndf(lo.y, hi.y), rndf(lo.z, hi.z)),
                                  q % 4 == 3 ? v3s(0.0f) : v3_normalize(v3(rndf(-1, 1), rndf(-1, 1), rndf(-1, 1)))};
        double sum = 0.0;
        for (uint32_t t = 0; t < nt; ++t) sum += light_area_triangle_pmf(l, &ctx, t);
        if (fabs(sum - 1.0) > worst_sum) worst_sum = fabs(sum - 1.0);
        LightSampleContext local; /* ctx in the tree's frame (object space for a shared tree) */
        const LightTree *tree = light_area_tree(l, &ctx, &local);
        if (tree) {
            ++tree_contexts;
            double tsum = 0.0;
            for (uint32_t t = 0; t < nt; ++t) tsum += light_tree_pmf(tree, &local, t);
            CHECK(fabs(tsum - 1.0) < 1e-4, "%s: tree pmf sums to %.7f", name, tsum);
            for (int s = 0; s < 2000; ++s) {
                float pmf;
                uint32_t t = light_tree_select(tree, &local, (float)rnd(), &pmf);
                if (t >= nt || !(pmf > 0.0f) || pmf != light_tree_pmf(tree, &local, t)) ++mismatch;
            }
        }
        for (int s = 0; s < 200; ++s) {
            LightLiSample smp;
            if (!light_sample_li(&f.lights, l, &ctx, (float)rnd(), (float)rnd(), (float)rnd(), 0.5f, &smp)) continue;
            ++samples;
            vec3 y = v3_madd(ctx.p, smp.wi, smp.distance);
            float pdf = light_area_pdf_li(l, &ctx, smp.triangle, y, tri_normal(l, smp.triangle));
            if (!(fabsf(pdf - smp.pdf) <= 1e-3f * smp.pdf)) {
                if (pdf_bad++ < 5) fprintf(stderr, "  %s: tri %u pdf %g vs sampled %g\n", name, smp.triangle, pdf, smp.pdf);
            }
        }
    }
    fprintf(stderr, "  (a,b) %s: %u triangles, %u nodes, %d/40 contexts on the tree, worst |sum-1| %.2e, %d samples\n",
            name, nt, l->shared_tree ? l->shared_tree->tree->node_count : l->tri_tree.node_count, tree_contexts, worst_sum,
            samples);
    CHECK(worst_sum < 1e-4, "%s: triangle pmf sum off by %g", name, worst_sum);
    CHECK(tree_contexts > 20, "%s: only %d contexts used the tree", name, tree_contexts);
    CHECK(mismatch == 0, "%s: %d selections disagree with light_tree_pmf", name, mismatch);
    CHECK(samples > 1000 && pdf_bad == 0, "%s: %d of %d sample pdfs disagree with light_area_pdf_li", name, pdf_bad, samples);
}

/* Irradiance at ctx (luminance): mean and variance of radiance cos / pdf over n samples. */
static void irradiance(const Light *l, const LightSampleContext *ctx, int n, double *mean, double *var) {
    Fake f;
    fake_scene(&f, l);
    double s1 = 0.0, s2 = 0.0;
    for (int i = 0; i < n; ++i) {
        LightLiSample smp;
        double x = 0.0;
        if (light_sample_li(&f.lights, l, ctx, (float)rnd(), (float)rnd(), (float)rnd(), 0.5f, &smp)) {
            double c = ctx->n.x == 0.0f && ctx->n.y == 0.0f && ctx->n.z == 0.0f ? 1.0 : fmax(0.0, v3_dot(smp.wi, ctx->n));
            x = v3_luminance(smp.radiance) * c / smp.pdf;
        }
        s1 += x;
        s2 += x * x;
    }
    *mean = s1 / n;
    *var = fmax(0.0, s2 / n - *mean * *mean);
}

/* (c) the tree and the area CDF estimate the same irradiance */
static void check_unbiased(const char *name, const Light *l, LightSampleContext ctx) {
    Light flat = *l;
    flat.tri_tree.node_count = 0; /* same light, area CDF */
    flat.shared_tree = NULL;
    const int N = 200000;
    double mt, vt, mc, vc;
    irradiance(l, &ctx, N, &mt, &vt);
    irradiance(&flat, &ctx, N, &mc, &vc);
    double se = sqrt(vt / N + vc / N);
    fprintf(stderr, "  (c) %s: E tree %.6f, area CDF %.6f, |diff| %.2f se (variance %.4g vs %.4g)\n", name, mt, mc,
            se > 0 ? fabs(mt - mc) / se : 0.0, vt, vc);
    CHECK(mt > 0.0 && fabs(mt - mc) <= 5.0 * se, "%s: tree %g vs area %g (se %g)", name, mt, mc, se);
}

static void free_light(Light *l) { light_area_free(l); }

static void test_bumpy_sheet(void) {
    Light l = grid_light(sheet, 32, 32, 5.0f, 0); /* 2,048 triangles, one-sided, facing +y */
    check_pmf("sheet", &l, v3(-3, -0.5f, -3), v3(3, 2, 3));
    check_unbiased("sheet, above", &l, (LightSampleContext){v3(0.7f, 0.5f, -0.4f), v3(0, -1, 0)});
    check_unbiased("sheet, tilted", &l, (LightSampleContext){v3(-2.5f, 1.0f, 0.3f), v3_normalize(v3(1, -1, 0))});
    check_unbiased("sheet, medium", &l, (LightSampleContext){v3(1.0f, 0.3f, 1.5f), v3s(0.0f)});
    /* (e) from well behind the one-sided sheet the root sees nothing: area CDF, same pmf */
    LightSampleContext back = {v3(0.3f, -30.0f, 0.2f), v3(0, 1, 0)};
    CHECK(light_tree_node_importance(&l.tri_tree.nodes[0], back.p, back.n) == 0.0f, "root importance from behind");
    int same = 1;
    for (uint32_t t = 0; t < l.triangles.n; ++t) same &= light_area_triangle_pmf(&l, &back, t) == dist1d_pmf(&l.triangles, t);
    CHECK(same, "behind: the triangle pmf is not the area CDF's");
    free_light(&l);
}

static void test_sphere(void) {
    Light l = grid_light(sphere, 40, 25, 3.0f, 1); /* 2,000 triangles (80 degenerate at the poles), two-sided */
    uint32_t zero = 0;
    for (uint32_t t = 0; t < l.triangles.n; ++t) zero += l.triangles.func[t] == 0.0f;
    check_pmf("sphere", &l, v3(-3, -1, -3), v3(3, 5, 3));
    LightSampleContext in = {v3(0.1f, 2.2f, -0.3f), v3(0, 1, 0)};
    for (uint32_t t = 0; t < l.triangles.n; ++t)
        if (l.triangles.func[t] == 0.0f) CHECK(light_area_triangle_pmf(&l, &in, t) == 0.0f, "degenerate triangle %u", t);
    CHECK(zero > 0, "expected degenerate pole triangles");
    check_unbiased("sphere, outside", &l, (LightSampleContext){v3(1.2f, 3.4f, 0.5f), v3_normalize(v3(-1, -1, 0))});
    check_unbiased("sphere, inside", &l, in);
    free_light(&l);
}

/* (d) a point close to one side of a large sheet: the tree concentrates on the nearby triangles */
static void test_variance(void) {
    Light l = grid_light(big_sheet, 32, 32, 1.0f, 0); /* 20 x 20, 2,048 triangles */
    LightSampleContext ctx = {v3(-9.0f, 0.3f, 0.5f), v3(0, -1, 0)};
    const int N = 100000;
    double mt, vt, mc, vc;
    irradiance(&l, &ctx, N, &mt, &vt);
    Light flat = l;
    flat.tri_tree.node_count = 0;
    irradiance(&flat, &ctx, N, &mc, &vc);
    double se = sqrt(vt / N + vc / N);
    fprintf(stderr, "  (d) near the edge of a 20x20 sheet: E tree %.5f area %.5f; variance tree %.5g, area CDF %.5g (%.1fx)\n",
            mt, mc, vt, vc, vt > 0 ? vc / vt : 0.0);
    CHECK(fabs(mt - mc) <= 5.0 * se, "big sheet: tree %g vs area %g", mt, mc);
    CHECK(vt < vc, "tree variance %g not below the area CDF's %g", vt, vc);
    free_light(&l);
}

/* (e) small lights keep the area CDF; (f) 1M-triangle build */
static void test_small_and_million(void) {
    Light small = grid_light(sheet, 2, 2, 1.0f, 0); /* 8 triangles */
    CHECK(small.tri_tree.node_count == 0, "8-triangle light built a tree");
    free_light(&small);
    Light big;
    memset(&big, 0, sizeof big);
    double t0 = test_seconds();
    big = grid_light(sphere, 1000, 500, 1.0f, 0); /* 1,000,000 triangles */
    double t1 = test_seconds();
    light_tree_free(&big.tri_tree);
    double t2 = test_seconds();
    CHECK(light_area_tree_build(&big) == 0, "1M build failed");
    double dt = test_seconds() - t2;
    fprintf(stderr, "  (f) 1,000,000-triangle sphere: inner tree build %.2f s (%u nodes; grid + CDF + tree %.2f s)\n", dt,
            big.tri_tree.node_count, t1 - t0);
    LightSampleContext ctx = {v3(0.3f, 3.5f, 0.2f), v3(0, -1, 0)};
    int mismatch = 0;
    for (int s = 0; s < 1000; ++s) {
        float p;
        uint32_t i = light_tree_select(&big.tri_tree, &ctx, (float)rnd(), &p);
        if (i >= big.triangles.n || !(p > 0.0f) || p != light_tree_pmf(&big.tri_tree, &ctx, i)) ++mismatch;
    }
    CHECK(mismatch == 0, "1M: %d selections disagree with the pmf", mismatch);
    free_light(&big);
}

/* (g) the refit: `src` moved by the affine map x -> M x + o */
static Light moved_copy(const Light *src, const float M[9], vec3 o) {
    Light l = *src;
    memset(&l.tri_tree, 0, sizeof l.tri_tree);
    memset(&l.triangles, 0, sizeof l.triangles);
    uint32_t nt = src->triangles.n;
    l.world_vertices = malloc((size_t)nt * 9 * sizeof(float));
    float *areas = malloc(nt * sizeof(float));
    double total = 0.0;
    for (uint32_t t = 0; t < nt; ++t) {
        vec3 w[3];
        for (int v = 0; v < 3; ++v) {
            const float *x = src->world_vertices + 9 * (size_t)t + 3 * v;
            w[v] = v3(M[0] * x[0] + M[1] * x[1] + M[2] * x[2] + o.x, M[3] * x[0] + M[4] * x[1] + M[5] * x[2] + o.y,
                      M[6] * x[0] + M[7] * x[1] + M[8] * x[2] + o.z);
            memcpy(l.world_vertices + 9 * (size_t)t + 3 * v, &w[v], 3 * sizeof(float));
        }
        areas[t] = 0.5f * v3_length(v3_cross(v3_sub(w[1], w[0]), v3_sub(w[2], w[0])));
        total += areas[t];
    }
    dist1d_init(&l.triangles, areas, nt);
    free(areas);
    l.area = (float)total;
    return l;
}

static void test_refit(void) {
    Light l = grid_light(sheet, 32, 32, 5.0f, 0);
    LightTree same;
    CHECK(light_tree_refit_triangles(&same, &l.tri_tree, l.world_vertices, l.triangles.n, v3_luminance(l.emission), 0) == 0,
          "refit over the same vertices failed");
    CHECK(same.node_count == l.tri_tree.node_count &&
              memcmp(same.nodes, l.tri_tree.nodes, same.node_count * sizeof *same.nodes) == 0 &&
              memcmp(same.trail, l.tri_tree.trail, l.triangles.n * sizeof *same.trail) == 0,
          "refit over the same vertices differs from the build");
    light_tree_free(&same);
    /* rotated about y by 50 degrees, scaled (2, 0.5, 1.5), mirrored in x (det < 0: normals flip) */
    float c = cosf(0.8727f), s = sinf(0.8727f);
    float M[9] = {-2.0f * c, 0.0f, 1.5f * s, 0.0f, 0.5f, 0.0f, 2.0f * s, 0.0f, 1.5f * c}; /* R_y diag(-2, .5, 1.5) */
    Light m = moved_copy(&l, M, v3(3.0f, 1.0f, -2.0f));
    CHECK(light_tree_refit_triangles(&m.tri_tree, &l.tri_tree, m.world_vertices, m.triangles.n, v3_luminance(m.emission),
                                     0) == 0,
          "refit of the moved copy failed");
    /* the mirror turns the one-sided sheet to face -y: a receiver below it, facing up */
    check_pmf("sheet, refit copy", &m, v3(-1, 0, -6), v3(7, 2, 2));
    check_unbiased("sheet, refit copy", &m, (LightSampleContext){v3(3.5f, 0.4f, -1.5f), v3(0, 1, 0)});
    LightTree refused;
    /* another count */
    CHECK(light_tree_refit_triangles(&refused, &l.tri_tree, m.world_vertices, m.triangles.n - 1, 1.0f, 0) == 1 &&
              refused.node_count == 0,
          "refit over another triangle count was not refused");
    /* triangle 7 collapsed to a point: it emits nothing here */
    for (int v = 1; v < 3; ++v) memcpy(m.world_vertices + 9 * 7 + 3 * v, m.world_vertices + 9 * 7, 3 * sizeof(float));
    CHECK(light_tree_refit_triangles(&refused, &l.tri_tree, m.world_vertices, m.triangles.n, 1.0f, 0) == 1,
          "refit with a triangle that no longer emits was not refused");
    free_light(&m);
    free_light(&l);
}

/* (h) a tree shared in object space (LightSharedTree): `obj`'s tree read by a copy placed by
 * x -> M x + o, M a rotation times a scale (column-major 4x4 as the scene's instances) */
static Light shared_copy(const Light *obj, const float M[9], vec3 o, LightSharedTree *frame) {
    float x[16] = {M[0], M[3], M[6], 0, M[1], M[4], M[7], 0, M[2], M[5], M[8], 0, o.x, o.y, o.z, 1};
    CHECK(light_shared_tree_frame(x, frame), "a rotation times a scale refused as a shared tree's frame");
    frame->tree = &obj->tri_tree;
    Light l = moved_copy(obj, M, o);
    l.shared_tree = frame;
    return l;
}

static void test_shared(void) {
    Light l = grid_light(sheet, 32, 32, 5.0f, 0); /* object space: the sheet facing +y */
    float c = cosf(0.8727f), s = sinf(0.8727f), ca = cosf(0.3f), sa = sinf(0.3f);
    /* uniform: R_x(0.3) R_y(50 deg) x 2.5; the probabilities are a world-space tree's */
    float Ry[9] = {c, 0, s, 0, 1, 0, -s, 0, c}, Rx[9] = {1, 0, 0, 0, ca, -sa, 0, sa, ca}, U[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            U[3 * i + j] = 2.5f * (Rx[3 * i] * Ry[j] + Rx[3 * i + 1] * Ry[3 + j] + Rx[3 * i + 2] * Ry[6 + j]);
    LightSharedTree fu, fs;
    Light u = shared_copy(&l, U, v3(3.0f, 1.0f, -2.0f), &fu);
    check_pmf("sheet, shared, rotated and scaled 2.5x", &u, v3(-4, -2, -8), v3(10, 8, 4));
    check_unbiased("sheet, shared, rotated and scaled 2.5x", &u, (LightSampleContext){v3(3.5f, 2.4f, -1.5f), v3(0, -1, 0)});
    /* against the same splits refitted in world space (world boxes around the rotated
     * triangles, where the shared tree's are the object-space boxes rotated): as good */
    Light w = moved_copy(&l, U, v3(3.0f, 1.0f, -2.0f));
    CHECK(light_tree_refit_triangles(&w.tri_tree, &l.tri_tree, w.world_vertices, w.triangles.n, v3_luminance(w.emission),
                                     0) == 0,
          "refit of the uniformly scaled copy failed");
    LightSampleContext at[3] = {{v3(3.5f, 2.4f, -1.5f), v3(0, -1, 0)},
                                {v3(6.0f, 3.0f, 1.0f), v3_normalize(v3(-1, -1, 0))},
                                {v3(2.0f, 1.5f, -3.0f), v3s(0.0f)}};
    for (int k = 0; k < 3; ++k) {
        double ms, vs, mw, vw;
        irradiance(&u, &at[k], 100000, &ms, &vs);
        irradiance(&w, &at[k], 100000, &mw, &vw);
        fprintf(stderr, "  (h) context %d: variance shared %.4g, world-space refit %.4g (E %.5f, %.5f)\n", k, vs, vw, ms, mw);
        CHECK(vs <= 1.5 * vw, "context %d: the shared tree's variance %g above 1.5x the world refit's %g", k, vs, vw);
    }
    free_light(&w);
    /* stretched 1.6x along y after the rotation (the street's facades): still exact */
    float S[9] = {c, 0, s, 0, 1.6f, 0, -s, 0, c};
    Light st = shared_copy(&l, S, v3(-1.0f, 0.5f, 2.0f), &fs);
    check_pmf("sheet, shared, stretched 1.6x", &st, v3(-4, -2, -2), v3(2, 3, 6));
    check_unbiased("sheet, shared, stretched 1.6x", &st, (LightSampleContext){v3(-0.5f, 1.1f, 2.3f), v3(0, -1, 0)});
    check_unbiased("sheet, shared, stretched 1.6x, medium", &st, (LightSampleContext){v3(0.5f, 0.3f, 1.5f), v3s(0.0f)});
    /* refused: a mirror, a 3x stretch, a shear */
    float mir[16] = {-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    float str[16] = {1, 0, 0, 0, 0, 3, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    float shr[16] = {1, 0, 0, 0, 0.3f, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    LightSharedTree no;
    CHECK(!light_shared_tree_frame(mir, &no) && !light_shared_tree_frame(str, &no) && !light_shared_tree_frame(shr, &no),
          "a mirror, a 3x stretch or a shear accepted as a shared tree's frame");
    u.shared_tree = st.shared_tree = NULL;
    free_light(&u);
    free_light(&st);
    free_light(&l);
}

int main(void) {
    test_bumpy_sheet();
    test_sphere();
    test_variance();
    test_small_and_million();
    test_refit();
    test_shared();
    return test_exit();
}
