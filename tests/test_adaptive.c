/* tests/test_adaptive.c: adaptive sampling (--noise-threshold, --min-spp), --time-limit and the
 * firefly clamps (--clamp-direct, --clamp-indirect), through candela_render.
 *
 * - adaptive: every pixel's sample count is a point of the schedule between --min-spp and
 *   --spp, some pixels stop early and some go on to --spp; the image and the counts are
 *   bit-identical for 1 and 2 threads and any batch size; the image agrees with a
 *   non-adaptive render of another seed at 256 spp (the pilot rule is unbiased: per-pixel z^2
 *   against both variances at most 1 plus 5 sigma, each channel's image mean within 4 standard
 *   errors); a threshold no pixel reaches gives the non-adaptive image bit for bit (the rule's
 *   own properties on synthetic films: tests/test_adaptive_rule.c);
 * - --time-limit: a limit the first iteration already passes stops the render after it (1 spp,
 *   reported), an ample one changes nothing (no clock is asserted);
 * - clamps: a point light over a plane, direct light only (one NEE contribution per path): with
 *   --clamp-direct V every pixel is at most V and pixels whose samples all stay below V are
 *   bit-identical to the unclamped render; a V above every sample changes no bit; on the Cornell
 *   box with --clamp-indirect tiny, the image is the direct-light-only render's (to float
 *   rounding of the clamped remainders): the clamp acts per vertex type. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "candela.h"
#include "check.h"

static const char *g_scenes = ".";  /* tests/scenes */
static const char *g_bundled = "."; /* scenes/ */

static int render(CandelaOptions *o, CandelaImage *img, CandelaStats *st) {
    char err[CANDELA_ERR_LEN] = "";
    o->quiet = 1;
    o->no_warnings = 1;
    int rc = candela_render(o, img, st, NULL, err);
    CHECK(rc == 0, "render of %s failed: %s", o->scene_path, err);
    return rc;
}

static int same_floats(const float *a, const float *b, size_t n) { return memcmp(a, b, n * sizeof(float)) == 0; }

static void test_adaptive(void) {
    char path[4096];
    snprintf(path, sizeof path, "%s/cornell_box.gltf", g_bundled);
    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = path;
    o.width = o.height = 48;
    o.spp = 64;
    o.max_depth = 8;
    o.noise_threshold = 0.12f;
    o.min_spp = 8;
    o.aov_spp = 1;
    o.threads = 2;
    CandelaImage a, b, c, ref;
    CandelaStats sa, sb, sc, sr;
    if (render(&o, &a, &sa) != 0) return;
    size_t n = (size_t)a.width * (size_t)a.height;
    int early = 0, full = 0, off_schedule = 0;
    for (size_t i = 0; i < n; ++i) {
        int s = (int)a.spp[i];
        if (s != 8 && s != 16 && s != 32 && s != 64) ++off_schedule;
        early += s < 64;
        full += s == 64;
    }
    CHECK(off_schedule == 0, "%d pixels' sample counts are not 8, 16, 32 or 64", off_schedule);
    CHECK(early > (int)n / 20 && full > (int)n / 20, "adaptive: %d pixels stopped early, %d reached 64 (want both)", early,
          full);
    CHECK(sa.spp_min >= 8 && sa.spp_done == 64 && sa.spp_mean < 64.0, "stats: spp %d..%d, mean %g", sa.spp_min,
          sa.spp_done, sa.spp_mean);
    /* determinism: 1 thread, another batch size */
    o.threads = 1;
    o.batch_size = 777;
    if (render(&o, &b, &sb) == 0) {
        CHECK(same_floats(a.rgb, b.rgb, 3 * n) && same_floats(a.spp, b.spp, n),
              "adaptive render differs between 2 threads and 1 thread with batch 777");
        candela_image_free(&b);
    }
    /* a threshold no pixel reaches: the non-adaptive image */
    o.threads = 2;
    o.batch_size = 0;
    o.noise_threshold = 1e-6f;
    if (render(&o, &c, &sc) == 0) {
        CandelaOptions plain = o;
        plain.noise_threshold = 0.0f;
        plain.min_spp = 0;
        CandelaImage p;
        CandelaStats sp;
        if (render(&plain, &p, &sp) == 0) {
            CHECK(same_floats(c.rgb, p.rgb, 3 * n), "an unreachable threshold changed the image");
            candela_image_free(&p);
        }
        candela_image_free(&c);
    }
    /* agreement with a non-adaptive render of another seed: the pilot rule never reads a pixel's
     * own samples, so each pixel's estimate is unbiased. z^2 is one-sided: with Sobol' samples
     * the sample variance overestimates the error, so the mean z^2 is below 1 */
    CandelaOptions r = o;
    r.noise_threshold = 0.0f;
    r.min_spp = 0;
    r.aov_spp = 0;
    r.seed = 77;
    r.spp = 256;
    if (render(&r, &ref, &sr) == 0) {
        for (int k = 0; k < 3; ++k) {
            double z2 = 0.0, d = 0.0, v = 0.0;
            int m = 0;
            for (size_t i = 0; i < n; ++i) {
                double x = a.rgb[3 * i + k], y = ref.rgb[3 * i + k];
                double var = (double)a.variance[3 * i + k] + ref.variance[3 * i + k];
                d += x - y;
                v += var;
                if (var > 0.0) { z2 += (x - y) * (x - y) / var; ++m; }
            }
            double mz2 = m ? z2 / m : 0.0, tol = 5.0 * sqrt(2.0 / (m ? m : 1));
            CHECK(mz2 <= 1.0 + tol, "channel %d: mean z^2 %g against the non-adaptive render (at most 1 + %g)", k, mz2, tol);
            CHECK(fabs(d / n) <= 4.0 * sqrt(v) / n, "channel %d: mean difference %g > 4 standard errors %g", k, d / n,
                  4.0 * sqrt(v) / n);
        }
        candela_image_free(&ref);
    }
    candela_image_free(&a);
}

static void test_time_limit(void) {
    char path[4096];
    snprintf(path, sizeof path, "%s/cornell_box.gltf", g_bundled);
    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = path;
    o.width = o.height = 16;
    o.spp = 32;
    o.time_limit = 1e-6; /* passed before the first barrier */
    CandelaImage a, b;
    CandelaStats sa, sb;
    if (render(&o, &a, &sa) == 0) {
        CHECK(sa.spp_done == 1 && sa.time_limited && sa.spp_min == 1 && sa.iterations == 1,
              "a 1 us limit: %d spp in %d iterations (time_limited %d), want 1 in 1", sa.spp_done, sa.iterations,
              sa.time_limited);
        candela_image_free(&a);
    }
    o.time_limit = 1e6;
    if (render(&o, &b, &sb) == 0) {
        CHECK(sb.spp_done == 32 && !sb.time_limited, "an ample limit: %d spp, time_limited %d", sb.spp_done,
              sb.time_limited);
        candela_image_free(&b);
    }
}

static void test_clamps(void) {
    char path[4096];
    snprintf(path, sizeof path, "%s/point_plane.gltf", g_scenes);
    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = path;
    o.width = o.height = 32;
    o.spp = 8;
    o.max_depth = 1;
    o.light_units = CANDELA_LIGHT_UNITS_RAW;
    CandelaImage u, c, h;
    CandelaStats s;
    if (render(&o, &u, &s) != 0) return;
    size_t n = (size_t)u.width * (size_t)u.height;
    float top = 0.0f;
    for (size_t i = 0; i < 3 * n; ++i) top = fmaxf(top, u.rgb[i]);
    const float limit = 0.5f * top;
    o.clamp_direct = limit;
    if (render(&o, &c, &s) == 0) {
        int above = 0, changed_below = 0, clamped = 0;
        for (size_t i = 0; i < n; ++i)
            for (int k = 0; k < 3; ++k) {
                float x = c.rgb[3 * i + k];
                above += x > limit * (1.0f + 1e-6f);
                clamped += x < u.rgb[3 * i + k];
                /* every sample of a pixel whose mean and variance put it far below the limit is below it */
                if (u.rgb[3 * i + k] + 10.0f * sqrtf(u.variance[3 * i + k] * 8.0f) < limit)
                    changed_below += x != u.rgb[3 * i + k];
            }
        CHECK(above == 0, "--clamp-direct %g: %d pixel channels above it", (double)limit, above);
        CHECK(clamped > 0, "--clamp-direct %g clamped nothing (the test proves nothing)", (double)limit);
        CHECK(changed_below == 0, "--clamp-direct: %d pixel channels below the limit changed", changed_below);
        candela_image_free(&c);
    }
    o.clamp_direct = 1e30f;
    if (render(&o, &h, &s) == 0) {
        CHECK(same_floats(u.rgb, h.rgb, 3 * n), "a clamp above every sample changed the image");
        candela_image_free(&h);
    }
    candela_image_free(&u);

    /* per vertex type: indirect clamped to nothing leaves the direct light exactly */
    snprintf(path, sizeof path, "%s/cornell_box.gltf", g_bundled);
    CandelaOptions d;
    candela_options_default(&d);
    d.scene_path = path;
    d.width = d.height = 24;
    d.spp = 8;
    d.max_depth = 1;
    CandelaOptions ind = d;
    ind.max_depth = 6;
    ind.clamp_indirect = 1e-12f;
    CandelaImage direct, clamped_ind, full;
    if (render(&d, &direct, &s) == 0 && render(&ind, &clamped_ind, &s) == 0) {
        ind.clamp_indirect = 0.0f;
        double worst = 0.0, more = 0.0, total = 0.0;
        if (render(&ind, &full, &s) == 0) {
            for (size_t i = 0; i < 3 * (size_t)24 * 24; ++i) {
                worst = fmax(worst, fabs(clamped_ind.rgb[i] - direct.rgb[i]) / fmax(direct.rgb[i], 1e-3));
                more += full.rgb[i] - direct.rgb[i];
                total += full.rgb[i];
            }
            CHECK(worst < 1e-5, "--clamp-indirect 1e-12: differs from the direct-only render by %g (relative)", worst);
            CHECK(more > 0.1 * total, "the Cornell box has little indirect light (%g of %g): the test proves nothing", more,
                  total);
            candela_image_free(&full);
        }
        candela_image_free(&direct);
        candela_image_free(&clamped_ind);
    }
}

int main(int argc, char **argv) {
    if (argc > 2) {
        g_scenes = argv[1];
        g_bundled = argv[2];
    }
    test_adaptive();
    test_time_limit();
    test_clamps();
    return test_exit();
}
