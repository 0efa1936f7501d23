/* tests/test_crop.c: `--crop X0,Y0,X1,Y1` (README "Options", renderer/README.md "Crops").
 *
 * A crop renders pixels [X0, X1) x [Y0, Y1) of the full image with the full image's camera, and
 * every path's numbers are a function of (seed, the pixel's full-image position, sample)
 * (stage_generate.c, sequence.h). What a crop can and cannot equal:
 * - with a light sampler that learns nothing (uniform, power, tree, optimal), no guiding and no
 *   `auto` volume choice, each crop pixel is the full render's pixel bit for bit (every channel:
 *   mean, variance, albedo, normal, depth, spp), for both --sampler sequences, any thread count
 *   and batch size, a medium included; a crop of the whole image is the plain render, cache
 *   points included;
 * - cache points (pilot paths from the crop's pixels, visibility learned from its paths),
 *   guiding (fields trained on its paths) and adaptive sampling (the pilot rule over the crop's
 *   film) decide from the crop: checked statistically against the full render's region (the
 *   region means within 4 standard errors from the variance layers, per-pixel mean z^2 <= 1.5),
 *   and bit-identical for 1 and 2 threads;
 * - a control: a crop shifted by one pixel is not the region (the check can fail).
 * usage: test_crop SCENES_DIR TEST_SCENES_DIR */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "candela.h"
#include "check.h"

#define W 40
#define H 30

static const char *scenes_dir, *test_scenes_dir;
static char default_scene[4096], fog_scene[4096], occluded_scene[4096];

static void options(CandelaOptions *o, const char *scene, CandelaLightSampler ls, int spp) {
    candela_options_default(o);
    o->scene_path = scene;
    o->width = W;
    o->height = H;
    o->spp = spp;
    o->seed = 11;
    o->quiet = 1;
    o->no_warnings = 1;
    o->threads = 2;
    o->light_sampler = ls;
}

static int render(const CandelaOptions *o, CandelaImage *img) {
    char err[CANDELA_ERR_LEN];
    if (candela_render(o, img, NULL, NULL, err) != 0) {
        fprintf(stderr, "render: %s\n", err);
        memset(img, 0, sizeof *img);
        return -1;
    }
    return 0;
}

/* The channels of part (a crop) against full's pixels from (x0, y0): the first differing pixel
 * and channel, or -1 when every bit agrees. */
static long region_differs(const CandelaImage *full, const CandelaImage *part, int x0, int y0, const char **which) {
    const float *fc[6] = {full->rgb, full->variance, full->albedo, full->normal, full->depth, full->spp};
    const float *pc[6] = {part->rgb, part->variance, part->albedo, part->normal, part->depth, part->spp};
    static const char *const names[6] = {"rgb", "variance", "albedo", "normal", "depth", "spp"};
    static const int per[6] = {3, 3, 3, 3, 1, 1};
    for (int c = 0; c < 6; ++c) {
        if (!fc[c] != !pc[c]) { *which = names[c]; return 0; }
        if (!fc[c]) continue;
        for (int y = 0; y < part->height; ++y)
            for (int x = 0; x < part->width; ++x)
                if (memcmp(pc[c] + per[c] * ((size_t)y * part->width + x),
                           fc[c] + per[c] * ((size_t)(y0 + y) * full->width + x0 + x), per[c] * sizeof(float)) != 0) {
                    *which = names[c];
                    return (long)y * part->width + x;
                }
    }
    return -1;
}

/* The crop's mean against the full render's region: z of the image means (standard errors
 * from the variance layers) and the mean per-pixel z^2. */
static void region_z(const CandelaImage *full, const CandelaImage *part, int x0, int y0, double *z_mean, double *z2) {
    double sf = 0, sp = 0, vf = 0, vp = 0, acc = 0;
    size_t n = (size_t)part->width * part->height;
    for (int y = 0; y < part->height; ++y)
        for (int x = 0; x < part->width; ++x)
            for (int k = 0; k < 3; ++k) {
                size_t i = 3 * ((size_t)y * part->width + x), j = 3 * ((size_t)(y0 + y) * full->width + x0 + x);
                double a = part->rgb[i + k], b = full->rgb[j + k], va = part->variance[i + k], vb = full->variance[j + k];
                sp += a; sf += b; vp += va; vf += vb;
                acc += va + vb > 0 ? (a - b) * (a - b) / (va + vb) : 0.0;
            }
    double m = 3.0 * (double)n;
    *z_mean = (sp - sf) / m / sqrt((vp + vf) / (m * m));
    *z2 = acc / m;
}

static void crop_of(CandelaOptions *o, int x0, int y0, int x1, int y1) {
    o->crop[0] = x0; o->crop[1] = y0; o->crop[2] = x1; o->crop[3] = y1;
}

/* A crop whose pixels must be the full render's bit for bit. */
static void bit_identical(const char *label, const CandelaOptions *base) {
    CandelaImage full, part, part1;
    CandelaOptions o = *base;
    if (render(&o, &full) != 0) { CHECK(0, "%s: full render", label); return; }
    crop_of(&o, 7, 5, 29, 21);
    o.batch_size = 97; /* batches cut the crop's paths elsewhere than the full render's */
    if (render(&o, &part) != 0) { CHECK(0, "%s: crop render", label); candela_image_free(&full); return; }
    o.threads = 1;
    o.batch_size = 0;
    if (render(&o, &part1) != 0) { CHECK(0, "%s: crop render, 1 thread", label); return; }
    CHECK(part.width == 22 && part.height == 16 && part.full_width == W && part.full_height == H && part.crop_x == 7 &&
              part.crop_y == 5, "%s: %dx%d at (%d, %d) of %dx%d", label, part.width, part.height, part.crop_x, part.crop_y,
          part.full_width, part.full_height);
    const char *which = "";
    long at = region_differs(&full, &part, 7, 5, &which);
    CHECK(at < 0, "%s: crop pixel %ld (%s) is not the full render's", label, at, which);
    at = region_differs(&part, &part1, 0, 0, &which);
    CHECK(at < 0, "%s: 1 and 2 threads differ at %ld (%s)", label, at, which);
    /* the control: one pixel off is another image */
    CHECK(region_differs(&full, &part, 8, 5, &which) >= 0, "%s: the crop equals the region shifted by a pixel", label);
    candela_image_free(&full);
    candela_image_free(&part);
    candela_image_free(&part1);
}

/* A crop that learns from its own pixels: within noise of the full render's region. */
static void within_noise(const char *label, const CandelaOptions *base) {
    CandelaImage full, part, part1;
    CandelaOptions o = *base;
    if (render(&o, &full) != 0) { CHECK(0, "%s: full render", label); return; }
    crop_of(&o, 4, 6, 36, 26);
    if (render(&o, &part) != 0) { CHECK(0, "%s: crop render", label); candela_image_free(&full); return; }
    o.threads = 1;
    if (render(&o, &part1) != 0) { CHECK(0, "%s: crop render, 1 thread", label); return; }
    double z, z2;
    region_z(&full, &part, 4, 6, &z, &z2);
    fprintf(stderr, "%s: crop mean vs the full render's region: z %.3f, per-pixel mean z^2 %.3f\n", label, z, z2);
    CHECK(fabs(z) <= 4.0, "%s: crop mean %.2f standard errors from the full render's region", label, z);
    CHECK(z2 <= 1.5, "%s: per-pixel mean z^2 %.3f", label, z2);
    const char *which = "";
    long at = region_differs(&part, &part1, 0, 0, &which);
    CHECK(at < 0, "%s: 1 and 2 threads differ at %ld (%s)", label, at, which);
    candela_image_free(&full);
    candela_image_free(&part);
    candela_image_free(&part1);
}

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: test_crop SCENES_DIR TEST_SCENES_DIR\n");
        return 2;
    }
    scenes_dir = argv[1];
    test_scenes_dir = argv[2];
    snprintf(default_scene, sizeof default_scene, "%s/default.gltf", scenes_dir);
    snprintf(fog_scene, sizeof fog_scene, "%s/rect_fog.gltf", test_scenes_dir);
    snprintf(occluded_scene, sizeof occluded_scene, "%s/occluded_lights.gltf", test_scenes_dir);
    CandelaOptions o;

    /* bit for bit: the samplers that learn nothing, both sequences, the AOV spp, a medium */
    static const struct { const char *name; CandelaLightSampler ls; } fixed[] = {
        {"uniform", CANDELA_LIGHT_SAMPLER_UNIFORM}, {"power", CANDELA_LIGHT_SAMPLER_POWER},
        {"tree", CANDELA_LIGHT_SAMPLER_TREE}, {"optimal", CANDELA_LIGHT_SAMPLER_OPTIMAL}};
    for (size_t k = 0; k < sizeof fixed / sizeof fixed[0]; ++k) {
        options(&o, default_scene, fixed[k].ls, 8);
        o.aov_spp = 1;
        bit_identical(fixed[k].name, &o);
    }
    options(&o, default_scene, CANDELA_LIGHT_SAMPLER_TREE, 8);
    o.sampler = CANDELA_SAMPLER_INDEPENDENT;
    bit_identical("tree, independent", &o);
    options(&o, occluded_scene, CANDELA_LIGHT_SAMPLER_TREE, 8);
    bit_identical("tree, occluded lights", &o);
    options(&o, fog_scene, CANDELA_LIGHT_SAMPLER_TREE, 8);
    o.volume_emission_sampling = 1;
    o.volume_inscatter_sampling = 0;
    bit_identical("tree, fog", &o);

    /* a crop of the whole image is the plain render, cache points and adaptive sampling too */
    {
        CandelaImage a, b;
        options(&o, occluded_scene, CANDELA_LIGHT_SAMPLER_CACHEPOINTS, 8);
        o.noise_threshold = 0.5f;
        o.min_spp = 2;
        o.aov_spp = 1;
        if (render(&o, &a) == 0) {
            crop_of(&o, 0, 0, W, H);
            if (render(&o, &b) == 0) {
                const char *which = "";
                long at = region_differs(&a, &b, 0, 0, &which);
                CHECK(at < 0 && b.width == W && b.height == H, "the whole-image crop differs at %ld (%s)", at, which);
                candela_image_free(&b);
            } else CHECK(0, "whole-image crop");
            candela_image_free(&a);
        } else CHECK(0, "plain render");
    }

    /* within noise: what learns from the crop's pixels */
    options(&o, occluded_scene, CANDELA_LIGHT_SAMPLER_CACHEPOINTS, 64);
    within_noise("cachepoints", &o);
    options(&o, default_scene, CANDELA_LIGHT_SAMPLER_CACHEPOINTS, 64);
    within_noise("cachepoints, default scene", &o);
    options(&o, default_scene, CANDELA_LIGHT_SAMPLER_TREE, 48);
    o.guiding = CANDELA_GUIDING_MIS;
    within_noise("guiding mis", &o);
    options(&o, default_scene, CANDELA_LIGHT_SAMPLER_TREE, 128);
    o.noise_threshold = 0.3f;
    o.min_spp = 16;
    within_noise("adaptive", &o);

    /* out of the image: one line naming the scene, the resolved resolution (640 wide) */
    {
        CandelaImage img;
        char err[CANDELA_ERR_LEN];
        options(&o, default_scene, CANDELA_LIGHT_SAMPLER_TREE, 1);
        o.width = o.height = 0;
        crop_of(&o, 0, 0, 641, 2);
        CHECK(candela_render(&o, &img, NULL, NULL, err) != 0 && strstr(err, "--crop 0,0,641,2 reaches outside the 640x") &&
                  !strchr(err, '\n'), "outside the default resolution: '%s'", err);
    }
    return test_exit();
}
