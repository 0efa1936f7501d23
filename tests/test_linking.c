/* Light linking and shadow linking (extras.candela_light_linking; README "Light linking"), for
 * every light sampler, with --max-depth 1 (direct light: NEE and BSDF-sampled hits on the
 * emitters, MIS-weighted). Scenes: tests/scenes/linking_*.gltf (scenes/make_scenes.py,
 * light_linking()): a floor in a left group and a right object, a plate, an area light
 * lamp_a, a point light and a second area light.
 *
 *  - receivers exclude ['left']: the left region renders as the scene where lamp_a does not
 *    emit, the right as the scene without linking. For uniform, power, tree and optimal this
 *    holds bit for bit (the left class's distribution is the one of the scene without lamp_a,
 *    a BSDF-sampled hit on lamp_a adds nothing there, and the right region is class 0, the
 *    unlinked path); for cache points (whose build sees every light) statistically.
 *  - receivers include ['right_floor', 'plate'] renders bit for bit as the exclude variant
 *    (same classes) except for cache points (statistically).
 *  - blockers exclude ['plate']: the image is lamp_a alone without the plate plus the others
 *    with it (linearity of direct light), off the plate's own pixels; both lists at once:
 *    left as without lamp_a, right as that sum.
 *  - the test can fail: lamp_a changes the left region, and the plate's shadow the right one,
 *    by many standard errors.
 * Statistical tolerances: region means within 5 standard errors from the renders' own
 * per-pixel variances. Cache points are also bit-identical for 1 and 2 threads with linking.
 * argv[1]: tests/scenes. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "candela.h"
#include "check.h"

#define RES 32
#define SPP 64

typedef struct Sampler { const char *name; CandelaLightSampler s; int exact; } Sampler;

static int render_cut(const char *dir, const char *scene, CandelaLightSampler s, int threads, uint32_t cut,
                      int linear, CandelaImage *img) {
    char path[1024];
    snprintf(path, sizeof path, "%s/linking_%s.gltf", dir, scene);
    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = path;
    o.width = o.height = RES;
    o.spp = SPP;
    o.seed = 11;
    o.threads = threads;
    o.quiet = 1;
    o.max_depth = 1;
    o.light_units = CANDELA_LIGHT_UNITS_RAW;
    o.light_sampler = s;
    o.cachepoint_cut_size = cut;
    o.cachepoint_build_linear = linear;
    char err[CANDELA_ERR_LEN];
    CandelaStats st;
    int rc = candela_render(&o, img, &st, NULL, err);
    CHECK(rc == 0, "%s: %s", scene, err);
    return rc;
}

static int render(const char *dir, const char *scene, CandelaLightSampler s, int threads, CandelaImage *img) {
    return render_cut(dir, scene, s, threads, 0, 0, img);
}

/* Pixel regions (the camera looks down at x, z in [-2, 2]; image right = +x, up = -z). */
enum { REGION_LEFT, REGION_RIGHT, REGION_ALL };
static int in_region(int region, int i, int j) {
    float x = -2.0f + 4.0f * ((float)i + 0.5f) / RES, z = -2.0f + 4.0f * ((float)j + 0.5f) / RES;
    int plate = x > 0.45f && x < 1.35f && z > -0.55f && z < 0.55f; /* its own pixels: not compared */
    if (region == REGION_LEFT) return x < -0.15f;
    if (region == REGION_RIGHT) return x > 0.15f && !plate;
    return !plate;
}

/* Mean and variance of the mean over a region (channels averaged). */
static void region_stats(const CandelaImage *im, int region, double *mean, double *var) {
    double s = 0.0, v = 0.0;
    int n = 0;
    for (int j = 0; j < RES; ++j)
        for (int i = 0; i < RES; ++i) {
            if (!in_region(region, i, j)) continue;
            for (int c = 0; c < 3; ++c) {
                size_t k = ((size_t)j * RES + (size_t)i) * 3 + (size_t)c;
                s += im->rgb[k];
                v += im->variance[k];
                ++n;
            }
        }
    *mean = s / n;
    *var = v / ((double)n * n);
}

static int bit_equal(const CandelaImage *a, const CandelaImage *b, int region) {
    for (int j = 0; j < RES; ++j)
        for (int i = 0; i < RES; ++i)
            if (in_region(region, i, j) &&
                memcmp(a->rgb + ((size_t)j * RES + i) * 3, b->rgb + ((size_t)j * RES + i) * 3, 3 * sizeof(float)))
                return 0;
    return 1;
}

/* a's region mean against b's (+ c's when c is given): within 5 standard errors. */
static double z_of(const CandelaImage *a, const CandelaImage *b, const CandelaImage *c, int region) {
    double ma, va, mb, vb, mc = 0.0, vc = 0.0;
    region_stats(a, region, &ma, &va);
    region_stats(b, region, &mb, &vb);
    if (c) region_stats(c, region, &mc, &vc);
    double se = sqrt(va + vb + vc);
    return se > 0.0 ? (ma - mb - mc) / se : (ma == mb + mc ? 0.0 : INFINITY);
}

static void agree(const char *what, const char *sampler, const CandelaImage *a, const CandelaImage *b,
                  const CandelaImage *c, int region) {
    double z = z_of(a, b, c, region);
    fprintf(stderr, "  %-12s %-44s z = %+.2f%s\n", sampler, what, z, !c && bit_equal(a, b, region) ? " (bit-identical)" : "");
    CHECK(fabs(z) <= 5.0, "%s %s: region means differ by %.1f standard errors", sampler, what, z);
}

static void same(const char *what, const char *sampler, const CandelaImage *a, const CandelaImage *b, int region) {
    int eq = bit_equal(a, b, region);
    fprintf(stderr, "  %-12s %-44s %s\n", sampler, what, eq ? "bit-identical" : "DIFFERENT");
    CHECK(eq, "%s %s: not bit-identical", sampler, what);
}

int main(int argc, char **argv) {
    if (argc < 2) SKIP("usage: test_linking SCENES_DIR");
    const char *dir = argv[1];
    const Sampler samplers[] = {{"uniform", CANDELA_LIGHT_SAMPLER_UNIFORM, 1},
                                {"power", CANDELA_LIGHT_SAMPLER_POWER, 1},
                                {"tree", CANDELA_LIGHT_SAMPLER_TREE, 1},
                                {"optimal", CANDELA_LIGHT_SAMPLER_OPTIMAL, 1},
                                {"cachepoints", CANDELA_LIGHT_SAMPLER_CACHEPOINTS, 0}};
    enum { BOTH, NOA, RECV, INCL, BLOCK, AONLY, LINKS, NV };
    const char *names[NV] = {"both", "noA", "receivers", "include", "blockers", "Aonly_noplate", "both_links"};
    for (size_t k = 0; k < sizeof samplers / sizeof *samplers; ++k) {
        const Sampler *S = &samplers[k];
        CandelaImage im[NV];
        memset(im, 0, sizeof im);
        int ok = 1;
        for (int v = 0; v < NV && ok; ++v) ok = render(dir, names[v], S->s, 2, &im[v]) == 0;
        if (ok) {
            /* the test has power: lamp_a lights the left region, the plate shadows the right */
            double zl = z_of(&im[BOTH], &im[NOA], NULL, REGION_LEFT), zr = z_of(&im[BLOCK], &im[BOTH], NULL, REGION_RIGHT);
            fprintf(stderr, "  %-12s %-44s z = %+.1f, %+.1f\n", S->name, "(power: lamp_a on left; plate's shadow)", zl, zr);
            CHECK(zl > 20.0 && zr > 5.0, "%s: the scenes do not tell linking apart (z %.1f, %.1f)", S->name, zl, zr);
            if (S->exact) {
                same("receivers exclude: left = without lamp_a", S->name, &im[RECV], &im[NOA], REGION_LEFT);
                same("receivers exclude: right = no linking", S->name, &im[RECV], &im[BOTH], REGION_RIGHT);
                same("receivers include = exclude (whole image)", S->name, &im[INCL], &im[RECV], REGION_ALL);
                same("both lists: left = without lamp_a", S->name, &im[LINKS], &im[NOA], REGION_LEFT);
            } else {
                agree("receivers exclude: left = without lamp_a", S->name, &im[RECV], &im[NOA], NULL, REGION_LEFT);
                agree("receivers exclude: right = no linking", S->name, &im[RECV], &im[BOTH], NULL, REGION_RIGHT);
                agree("receivers include = exclude (left)", S->name, &im[INCL], &im[RECV], NULL, REGION_LEFT);
                agree("receivers include = exclude (right)", S->name, &im[INCL], &im[RECV], NULL, REGION_RIGHT);
                agree("both lists: left = without lamp_a", S->name, &im[LINKS], &im[NOA], NULL, REGION_LEFT);
            }
            agree("blockers: left = lamp_a alone + others", S->name, &im[BLOCK], &im[AONLY], &im[NOA], REGION_LEFT);
            agree("blockers: right = lamp_a unshadowed + others", S->name, &im[BLOCK], &im[AONLY], &im[NOA],
                  REGION_RIGHT);
            agree("both lists: right = lamp_a unshadowed + others", S->name, &im[LINKS], &im[AONLY], &im[NOA],
                  REGION_RIGHT);
        }
        /* 48 more lights: far entries (single lights and, with a cut of 4, clusters that hold
         * lamp_a) are what cache points must drop or descend around */
        for (int linear = 0; linear <= !S->exact; ++linear) {
            enum { M_NOA, M_BOTH, M_RECV, M_NOC, M_EXCL, MN };
            CandelaImage many[MN];
            memset(many, 0, sizeof many);
            const char *mnames[MN] = {"many_noA", "many_both", "many_receivers", "many_noC", "many_exclusive"};
            const char *tag = linear ? "linear build" : "cut 4";
            int mok = 1;
            for (int v = 0; v < MN && mok; ++v) mok = render_cut(dir, mnames[v], S->s, 2, 4, linear, &many[v]) == 0;
            char what[4][96];
            snprintf(what[0], sizeof what[0], "48 more lights, %s: left = without lamp_a", tag);
            snprintf(what[1], sizeof what[1], "48 more lights, %s: right = no linking", tag);
            snprintf(what[2], sizeof what[2], "exclusive, %s: left = without lamp_a", tag);
            snprintf(what[3], sizeof what[3], "exclusive, %s: right = without lamp_c", tag);
            if (mok && S->exact) {
                same(what[0], S->name, &many[M_RECV], &many[M_NOA], REGION_LEFT);
                same(what[1], S->name, &many[M_RECV], &many[M_BOTH], REGION_RIGHT);
                same(what[2], S->name, &many[M_EXCL], &many[M_NOA], REGION_LEFT);
                same(what[3], S->name, &many[M_EXCL], &many[M_NOC], REGION_RIGHT);
            } else if (mok) {
                agree(what[0], S->name, &many[M_RECV], &many[M_NOA], NULL, REGION_LEFT);
                agree(what[1], S->name, &many[M_RECV], &many[M_BOTH], NULL, REGION_RIGHT);
                agree(what[2], S->name, &many[M_EXCL], &many[M_NOA], NULL, REGION_LEFT);
                agree(what[3], S->name, &many[M_EXCL], &many[M_NOC], NULL, REGION_RIGHT);
            }
            for (int v = 0; v < MN; ++v) candela_image_free(&many[v]);
        }
        if (!S->exact && ok) { /* determinism with linking: 1 and 2 threads */
            CandelaImage one;
            memset(&one, 0, sizeof one);
            if (render(dir, names[LINKS], S->s, 1, &one) == 0) same("both lists: 1 vs 2 threads", S->name, &one, &im[LINKS], REGION_ALL);
            candela_image_free(&one);
        }
        for (int v = 0; v < NV; ++v) candela_image_free(&im[v]);
    }
    return test_exit();
}
