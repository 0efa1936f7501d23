/* tests/test_guiding.c: the radiance recorder and path guiding end to end (issue 10).
 *   (a) without skipping, the recorder-debug AOV (every primary vertex's sample times its
 *       throughput, plus what the camera ray found itself) equals the image to float rounding:
 *       the recorder loses and double-counts nothing;
 *   (b) with path and vertex skipping (a budget of 1 vertex per path) it converges to the image:
 *       the image means agree within 5 standard errors of their difference (pixels are
 *       independent: the standard error comes from the spread of the per-pixel differences);
 *   (c) guided renders (one-sample MIS and RIS) converge to the unguided image: the image-mean
 *       difference within 5 standard errors (from the film's variances), and in each block of a
 *       4 x 4 grid too (a local bias, e.g. a pdf used inconsistently in one lobe);
 *   (d) guided renders are bit-identical for 1 and 2 threads, and for two batch sizes;
 *   (e) path-space regularisation (--path-regularization) leaves a scene of rough (Lambert)
 *       surfaces bit-identical and changes one with glass and glossy metal, and brightens
 *       nothing out of proportion (the image mean within 10%);
 *   (f) --guiding auto: on scenes/cornell_indirect.gltf (lit through the ceiling) its probe
 *       chooses guiding, converges to the unguided image, is bit-identical for 1 and 2 threads
 *       and is the `mis` render bit for bit (the probe records and trains as mis does); on scenes/default.gltf (direct light) it chooses off and the image is the
 *       unguided render's bit for bit;
 *   (g) the guide's unguided bootstrap (the first 8 spp) is dropped from the image once guided
 *       samples follow, in renders of 32 spp or more: every pixel of a 40-spp guided render holds
 *       32 samples (the 96-spp renders of (c) are such images, and converge), one of 16 spp or
 *       unguided all its samples, and `auto` drops exactly when it guides.
 * Scenes: tests/scenes/two_lights.gltf (a floor and a wall lit by an emissive quad and three
 * point lights: direct light with MIS plus diffuse interreflection, every surface guidable) and
 * scenes/default.gltf (glossy metal, glass, emission). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "candela.h"
#include "check.h"

typedef struct Render {
    CandelaImage img;
    CandelaStats st;
    int ok;
} Render;

static float g_regularization = 0.0f;
static float g_bsdf_share = 0.5f; /* --guide-bsdf-share: 0 learns it per leaf */

static CandelaGuideRoulette g_roulette = CANDELA_GUIDE_ROULETTE_CORRECTED; /* --guide-roulette */

/* The guided variants the tests run: MIS, RIS, MIS with learned BSDF shares and the caustic guard,
 * and MIS with the adjoint-driven roulette. */
#define VARIANTS 4
static CandelaGuiding variant(int v) {
    g_bsdf_share = v == 2 ? 0.0f : 0.5f;
    g_roulette = v == 3 ? CANDELA_GUIDE_ROULETTE_ADJOINT : CANDELA_GUIDE_ROULETTE_CORRECTED;
    return v == 1 ? CANDELA_GUIDING_RIS : CANDELA_GUIDING_MIS;
}
static const char *const variant_name[VARIANTS] = {"MIS", "RIS", "MIS, learned BSDF share and the caustic guard",
                                                   "MIS, adjoint-driven roulette"};

static Render render(const char *scene, int w, int h, int spp, CandelaGuiding guiding, int aov, int budget, int threads,
                     uint32_t batch, uint64_t seed) {
    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = scene;
    o.width = w;
    o.height = h;
    o.spp = spp;
    o.seed = seed;
    o.threads = threads;
    o.quiet = 1;
    o.guiding = guiding;
    o.aov_recorder_debug = aov;
    o.recorder_budget = budget;
    o.batch_size = batch;
    o.path_regularization = g_regularization;
    o.guide_bsdf_share = g_bsdf_share;
    o.guide_roulette = g_roulette;
    /* the learned share's variant also runs the caustic guard (off by default) */
    if (g_bsdf_share == 0.0f) o.guide_caustic_threshold = 0.002f;
    Render r = {0};
    char err[CANDELA_ERR_LEN];
    r.ok = candela_render(&o, &r.img, &r.st, NULL, err) == 0;
    CHECK(r.ok, "%s: %s", scene, err);
    return r;
}

static double pixel_mean(const float *rgb, size_t i) { return (rgb[3 * i] + rgb[3 * i + 1] + rgb[3 * i + 2]) / 3.0; }

static void test_debug_aov(const char *scene) {
    /* (a) exact without skipping */
    Render r = render(scene, 48, 36, 8, CANDELA_GUIDING_OFF, 1, 0, 2, 0, 1);
    if (r.ok) {
        CHECK(r.img.recorder_debug != NULL, "the AOV is in the image");
        size_t n = (size_t)r.img.width * r.img.height;
        double worst = 0.0, sum = 0.0;
        for (size_t i = 0; r.img.recorder_debug && i < 3 * n; ++i) {
            double a = r.img.rgb[i], b = r.img.recorder_debug[i];
            double rel = fabs(a - b) / fmax(fabs(a), 1e-3);
            worst = fmax(worst, rel);
            sum += a;
        }
        fprintf(stderr, "  (a) %s: recorder-debug vs image, worst relative difference %.3g (image mean %.4f), "
                        "%.2f recorded vertices per path\n",
                scene, worst, sum / (3.0 * n), (double)r.st.recorder_vertices / (double)r.st.recorder_paths);
        CHECK(worst < 1e-4, "(a) %s: the recorder-debug AOV differs from the image by %.3g (relative)", scene, worst);
        CHECK(r.st.recorder_path_skip == 0.0f, "(a) no skipping with a budget of 0");
        CHECK(r.st.recorder_peak_bytes > 0 && r.st.recorder_peak_bytes <= r.st.recorder_bound_bytes,
              "(a) recorder memory %zu within its bound %zu", r.st.recorder_peak_bytes, r.st.recorder_bound_bytes);
    }
    candela_image_free(&r.img);

    /* (b) converges with skipping */
    Render s = render(scene, 48, 36, 64, CANDELA_GUIDING_OFF, 1, 1, 2, 0, 2);
    if (s.ok && s.img.recorder_debug) {
        size_t n = (size_t)s.img.width * s.img.height;
        double sd = 0.0, sd2 = 0.0, differs = 0.0;
        for (size_t i = 0; i < n; ++i) {
            double d = pixel_mean(s.img.recorder_debug, i) - pixel_mean(s.img.rgb, i);
            sd += d;
            sd2 += d * d;
            differs += fabs(d) > 1e-6 * fmax(1.0, pixel_mean(s.img.rgb, i));
        }
        double mean = sd / n, se = sqrt(fmax(sd2 / n - mean * mean, 0.0) / (n - 1));
        fprintf(stderr, "  (b) %s with skipping (path skip %.3f): mean difference %.3g, standard error %.3g, %.0f of %zu "
                        "pixels differ\n",
                scene, s.st.recorder_path_skip, mean, se, differs, n);
        CHECK(s.st.recorder_path_skip > 0.0f, "(b) the budget of 1 skips paths");
        CHECK(differs > n / 10, "(b) skipping changes the AOV (%.0f pixels differ)", differs);
        CHECK(fabs(mean) <= 5.0 * se, "(b) %s: the AOV's mean is off by %.3g (%.1f standard errors)", scene, mean,
              mean / se);
    }
    candela_image_free(&s.img);
}

static void test_unbiased(const char *scene, int w, int h, int spp) {
    Render off = render(scene, w, h, spp, CANDELA_GUIDING_OFF, 0, -1, 2, 0, 3);
    for (int g = 0; g < VARIANTS; ++g) {
        Render on = render(scene, w, h, spp, variant(g), 0, -1, 2, 0, 4);
        g_bsdf_share = 0.5f;
        g_roulette = CANDELA_GUIDE_ROULETTE_CORRECTED;
        if (off.ok && on.ok) {
            size_t n = (size_t)w * h;
            double sd = 0.0, sv = 0.0, var_on = 0.0, var_off = 0.0;
            for (size_t i = 0; i < n; ++i) {
                sd += pixel_mean(on.img.rgb, i) - pixel_mean(off.img.rgb, i);
                double v = (pixel_mean(on.img.variance, i) + pixel_mean(off.img.variance, i)) / 3.0;
                sv += v;
                var_on += pixel_mean(on.img.variance, i);
                var_off += pixel_mean(off.img.variance, i);
            }
            double z = sd / sqrt(sv);
            /* a 4 x 4 grid of blocks, each a z-score of its mean difference: a local bias (a pdf
             * used inconsistently in one lobe) would show in a block. The per-pixel variances of
             * heavy-tailed pixels are underestimated at this spp (a block chi-square of two
             * unguided renders came out 3.3), so blocks are large and the bound is 5 */
            double zmax = 0.0;
            for (int by = 0; by < 4; ++by)
                for (int bx = 0; bx < 4; ++bx) {
                    double d = 0.0, v = 0.0;
                    for (int y = by * h / 4; y < (by + 1) * h / 4; ++y)
                        for (int x = bx * w / 4; x < (bx + 1) * w / 4; ++x) {
                            size_t i = (size_t)y * w + x;
                            d += pixel_mean(on.img.rgb, i) - pixel_mean(off.img.rgb, i);
                            v += (pixel_mean(on.img.variance, i) + pixel_mean(off.img.variance, i)) / 3.0;
                        }
                    if (v > 0.0) zmax = fmax(zmax, fabs(d) / sqrt(v));
                }
            fprintf(stderr, "  (c) %s %s: image mean difference %.2f standard errors; largest of 16 blocks %.2f; "
                            "variance guided/unguided %.3f; %d guiding updates\n",
                    scene, variant_name[g], z, zmax, var_on / var_off, on.st.guide_updates);
            CHECK(fabs(z) < 5.0, "(c) %s: guided (%d) differs from unguided by %.2f standard errors", scene, g, z);
            CHECK(zmax < 5.0, "(c) %s: guided (%d) differs in a block by %.2f standard errors", scene, g, zmax);
            CHECK(on.st.guide_updates > 8 && on.st.guide_samples > 0, "(c) the field trained (%d updates)",
                  on.st.guide_updates);
            uint32_t learned = 0, held = 0;
            for (int k = 0; k < CANDELA_GUIDE_SHARES; ++k) {
                held += on.st.guide_share_leaves[k];
                if (on.st.guide_share_value[k] != 0.5f) learned += on.st.guide_share_leaves[k];
            }
            fprintf(stderr, "      %u of %u leaves hold a BSDF share other than 1/2\n", learned, held);
            /* variant 2 chooses shares per leaf (learned, and the caustic guard); MIS at its defaults
             * (the guard off) and RIS keep 1/2 everywhere */
            CHECK(on.st.guide_share_per_leaf == (g == 2) && held == on.st.guide_leaves && (g == 2 || learned == 0),
                  "(c) %s: shares per leaf %d, %u of %u leaves away from 1/2", variant_name[g], on.st.guide_share_per_leaf,
                  learned, held);
        }
        candela_image_free(&on.img);
    }
    candela_image_free(&off.img);
}

static void test_determinism(const char *scene) {
    for (int g = 0; g < VARIANTS; ++g) {
        Render a = render(scene, 40, 30, 12, variant(g), 1, -1, 1, 0, 5);
        Render b = render(scene, 40, 30, 12, variant(g), 1, -1, 2, 0, 5);
        Render c = render(scene, 40, 30, 12, variant(g), 1, -1, 2, 333, 5);
        /* without the AOV an NEE ray adds its light to its parent's vertex instead of a vertex of
         * its own (recorder_fold_child): the same training sums in the same order, so, within
         * the training spp (the AOV keeps recording after them), the same image bit for bit */
        Render e = render(scene, 40, 30, 12, variant(g), 0, -1, 2, 0, 5);
        g_bsdf_share = 0.5f;
        g_roulette = CANDELA_GUIDE_ROULETTE_CORRECTED;
        size_t bytes = 40 * 30 * 3 * sizeof(float);
        if (a.ok && b.ok && c.ok && e.ok) {
            CHECK(memcmp(a.img.rgb, b.img.rgb, bytes) == 0, "(d) guiding %d: 1 and 2 threads differ", g);
            CHECK(memcmp(a.img.rgb, c.img.rgb, bytes) == 0, "(d) guiding %d: batch sizes differ", g);
            CHECK(memcmp(a.img.recorder_debug, b.img.recorder_debug, bytes) == 0, "(d) guiding %d: the AOV differs", g);
            CHECK(memcmp(b.img.rgb, e.img.rgb, bytes) == 0, "(d) guiding %d: NEE folding changed the image", g);
        }
        candela_image_free(&a.img);
        candela_image_free(&b.img);
        candela_image_free(&c.img);
        candela_image_free(&e.img);
    }
}

static void test_regularization(const char *rough_scene, const char *glossy_scene) {
    for (int k = 0; k < 2; ++k) {
        const char *scene = k ? glossy_scene : rough_scene;
        g_regularization = 0.0f;
        Render a = render(scene, 32, 24, 8, CANDELA_GUIDING_MIS, 0, -1, 2, 0, 6);
        g_regularization = 0.5f;
        Render b = render(scene, 32, 24, 8, CANDELA_GUIDING_MIS, 0, -1, 2, 0, 6);
        g_regularization = 0.0f;
        if (a.ok && b.ok) {
            size_t n = 32 * 24;
            int same = memcmp(a.img.rgb, b.img.rgb, 3 * n * sizeof(float)) == 0;
            double ma = 0.0, mb = 0.0;
            for (size_t i = 0; i < n; ++i) { ma += pixel_mean(a.img.rgb, i); mb += pixel_mean(b.img.rgb, i); }
            fprintf(stderr, "  (e) %s: regularised %s, image mean %.4f vs %.4f\n", scene, same ? "identical" : "differs",
                    mb / n, ma / n);
            if (k == 0) CHECK(same, "(e) regularisation changed a scene of rough surfaces");
            else {
                CHECK(!same, "(e) regularisation did not change the glass and metal");
                CHECK(fabs(mb - ma) <= 0.1 * ma, "(e) regularisation moved the image mean by %.1f%%", 100.0 * (mb - ma) / ma);
            }
        }
        candela_image_free(&a.img);
        candela_image_free(&b.img);
    }
}

static void image_agrees(const char *what, const Render *a, const Render *b, int w, int h) {
    size_t n = (size_t)w * h;
    double sd = 0.0, sv = 0.0;
    for (size_t i = 0; i < n; ++i) {
        sd += pixel_mean(a->img.rgb, i) - pixel_mean(b->img.rgb, i);
        sv += (pixel_mean(a->img.variance, i) + pixel_mean(b->img.variance, i)) / 3.0;
    }
    double z = sd / sqrt(sv);
    fprintf(stderr, "  (f) %s: image mean difference %.2f standard errors\n", what, z);
    CHECK(fabs(z) < 5.0, "(f) %s: differs from unguided by %.2f standard errors", what, z);
}

/* (g): the bootstrap's samples leave the film (every pixel's count, the stats) exactly when the
 * render is long enough; with the spp AOV the per-pixel counts say the same. */
static void test_bootstrap_drop(const char *scene) {
    const int spp[2] = {40, 16}, held[2] = {32, 16};
    for (int k = 0; k < 2; ++k) {
        Render r = render(scene, 16, 12, spp[k], CANDELA_GUIDING_MIS, 0, -1, 2, 0, 7);
        if (r.ok) {
            fprintf(stderr, "  (g) %d spp guided: %d dropped, %d to %.1f in the image\n", spp[k], r.st.spp_dropped,
                    r.st.spp_min, r.st.spp_mean);
            CHECK(r.st.spp_done == spp[k] && r.st.spp_dropped == spp[k] - held[k] && r.st.spp_min == held[k] &&
                      r.st.spp_mean == held[k],
                  "(g) %d spp guided: %d dropped, %d to %.1f held, want %d", spp[k], r.st.spp_dropped, r.st.spp_min,
                  r.st.spp_mean, held[k]);
        }
        candela_image_free(&r.img);
    }
}

static void test_auto(const char *indirect, const char *direct) {
    const int w = 48, h = 48, spp = 64;
    Render off = render(indirect, w, h, spp, CANDELA_GUIDING_OFF, 0, -1, 2, 0, 3);
    Render on = render(indirect, w, h, spp, CANDELA_GUIDING_AUTO, 0, -1, 2, 0, 4);
    Render on1 = render(indirect, w, h, spp, CANDELA_GUIDING_AUTO, 0, -1, 1, 0, 4);
    Render mis = render(indirect, w, h, spp, CANDELA_GUIDING_MIS, 0, -1, 2, 0, 4);
    if (off.ok && on.ok && on1.ok && mis.ok) {
        fprintf(stderr, "  (f) %s: auto %s, predicted ratio %.2f, indirect share %.2f, %d updates\n", indirect,
                on.st.guide_auto == 1 ? "on" : "off", (double)on.st.guide_auto_ratio, (double)on.st.guide_auto_indirect,
                on.st.guide_updates);
        CHECK(on.st.guide_auto == 1 && on.st.guide_updates > 8 && on.st.guide_samples > 0,
              "(f) auto did not guide the indirect-lit box (choice %d, %d updates)", on.st.guide_auto, on.st.guide_updates);
        image_agrees("auto on the indirect box", &on, &off, w, h);
        CHECK(memcmp(on.img.rgb, on1.img.rgb, (size_t)w * h * 3 * sizeof(float)) == 0, "(f) auto: 1 and 2 threads differ");
        CHECK(memcmp(on.img.rgb, mis.img.rgb, (size_t)w * h * 3 * sizeof(float)) == 0,
              "(f) auto on is not the mis render bit for bit");
        CHECK(on.st.spp_dropped == 8 && on.st.spp_min == spp - 8 && off.st.spp_dropped == 0 && off.st.spp_min == spp,
              "(g) auto on dropped %d spp (holds %d), off %d (holds %d)", on.st.spp_dropped, on.st.spp_min,
              off.st.spp_dropped, off.st.spp_min);
    }
    candela_image_free(&mis.img);
    candela_image_free(&off.img);
    candela_image_free(&on.img);
    candela_image_free(&on1.img);
    Render doff = render(direct, 32, 24, 32, CANDELA_GUIDING_OFF, 0, -1, 2, 0, 5);
    Render dauto = render(direct, 32, 24, 32, CANDELA_GUIDING_AUTO, 0, -1, 2, 0, 5);
    if (doff.ok && dauto.ok) {
        CHECK(dauto.st.guide_auto == 0, "(f) auto guided the direct-lit default scene (predicted %.2f)",
              (double)dauto.st.guide_auto_ratio);
        CHECK(memcmp(doff.img.rgb, dauto.img.rgb, 32 * 24 * 3 * sizeof(float)) == 0,
              "(f) auto off is not the unguided render bit for bit");
        CHECK(dauto.st.spp_dropped == 0 && dauto.st.spp_min == 32, "(g) auto off dropped %d spp", dauto.st.spp_dropped);
    }
    candela_image_free(&doff.img);
    candela_image_free(&dauto.img);
}

int main(int argc, char **argv) {
    if (argc < 3) {
        fprintf(stderr, "usage: test_guiding TESTS_SCENES_DIR SCENES_DIR\n");
        return 2;
    }
    char two_lights[1024], def[1024], box[1024];
    snprintf(two_lights, sizeof two_lights, "%s/two_lights.gltf", argv[1]);
    snprintf(def, sizeof def, "%s/default.gltf", argv[2]);
    snprintf(box, sizeof box, "%s/cornell_indirect.gltf", argv[2]);
    double t0 = test_seconds();
    test_debug_aov(two_lights);
    test_debug_aov(def);
    test_unbiased(two_lights, 32, 24, 96);
    test_unbiased(def, 32, 24, 96);
    test_determinism(def);
    test_regularization(two_lights, def);
    test_bootstrap_drop(box);
    test_auto(box, def);
    fprintf(stderr, "test_guiding: %.1f s\n", test_seconds() - t0);
    return test_exit();
}
