/* The Blender add-on's area lights (issue 14): scenes/blender_area/area.gltf was built with Blender's
 * Python (scenes/blender/make_area.py) and exported by Blender 3.4's glTF exporter with the
 * Candela add-on (scenes/blender/candela_gltf_extras.py), which writes the rectangle and disk
 * area lights the exporter drops as `candela_area_light` extras and the dim constant world as
 * `candela_environment`. Candela renders it and its image mean must match the Cycles 3.4
 * reference statistics stored beside it (rendered on a machine with Blender; CI never runs
 * Blender) within 3% per channel.
 *
 * The same program checks area_nolights.gltf (the scene without its lights: the add-on's constant
 * world EXR, its Specular 0 materials and the metal sphere under the world alone) against
 * area_nolights.cycles_lambert.json; meson passes the scene and the reference (tests/meson.build).
 *
 * Reference: area.cycles_lambert.json, Cycles with the non-metallic Principled BSDFs replaced by
 * Lambert (as ../shared/tools/cycles_render.py --lambert): the scene's dielectrics have Specular 0
 * and the comparison is about the lights, not Blender's Disney diffuse (the material models are
 * compared on the interior, scenes/blender_compare.py).
 *
 * Tolerance: 3%, or 5 standard errors of the ratio if the noise of the two means allows no
 * tighter test (Candela's standard error from its per-pixel variance of the mean, Cycles' from
 * the spread of its independent seeds, stored in the JSON). With 64 spp both are about 0.1% of
 * the mean, so the test is the 3%; the test fails if the noise would make 3% meaningless.
 *
 * Measured (scratch merges of branches shapes 8356af9 / a96eece + materials + addon): ratios 0.9989,
 * 0.9992, 0.9996 per channel (64 spp); with an area radiance of power / (pi A) instead of Cycles'
 * power / (4 A) it was 1.26. A Candela without candela_area_light support (main before shapes)
 * loads only the world: with the optional third argument (the scene's light count, the world
 * included) the test skips then instead of failing. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "candela.h"
#include "check.h"

/* The JSON's numbers after "key": [ (n of them) or "key": (one). Returns 0 on success. */
static int json_numbers(const char *text, const char *key, double *out, int n) {
    char pattern[64];
    snprintf(pattern, sizeof pattern, "\"%s\":", key);
    const char *p = strstr(text, pattern);
    if (!p) return 1;
    p += strlen(pattern);
    while (*p == ' ' || *p == '\n') ++p;
    if (n > 1 || *p == '[') {
        if (*p != '[') return 1;
        ++p;
    }
    for (int i = 0; i < n; ++i) {
        char *end;
        out[i] = strtod(p, &end);
        if (end == p) return 1;
        p = end;
        while (*p == ',' || *p == ' ' || *p == '\n') ++p;
    }
    return 0;
}

static char *read_text(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *s = malloc((size_t)n + 1);
    if (s && fread(s, 1, (size_t)n, f) != (size_t)n) {
        free(s);
        s = NULL;
    }
    if (s) s[n] = 0;
    fclose(f);
    return s;
}

int main(int argc, char **argv) {
    if (argc < 3) {
        fprintf(stderr, "usage: test_blender_area SCENE.gltf REFERENCE.json [LIGHTS] (scenes/blender_area; LIGHTS:\n"
                        "  skip when fewer lights load, i.e. Candela ignores candela_area_light)\n");
        return 2;
    }
    char *json = read_text(argv[2]);
    CHECK(json != NULL, "cannot read %s", argv[2]);
    if (!json) return test_exit();
    double width, height, depth, ref_mean[3], ref_se[3];
    int bad = json_numbers(json, "width", &width, 1) | json_numbers(json, "height", &height, 1) |
              json_numbers(json, "max_depth", &depth, 1) | json_numbers(json, "mean", ref_mean, 3) |
              json_numbers(json, "mean_se", ref_se, 3);
    free(json);
    CHECK(!bad, "%s: missing width, height, max_depth, mean or mean_se", argv[2]);
    if (bad) return test_exit();

    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = argv[1];
    o.width = (int)width;
    o.height = (int)height;
    o.spp = 64;
    o.max_depth = (int)depth;
    o.seed = 7;
    o.threads = 2;
    o.quiet = 1;
    CandelaImage img;
    memset(&img, 0, sizeof img);
    CandelaStats st;
    memset(&st, 0, sizeof st);
    char err[CANDELA_ERR_LEN];
    err[0] = 0;
    int rc = candela_render(&o, &img, &st, NULL, err);
    CHECK(rc == 0, "%s: %s", argv[1], err);
    if (rc != 0) return test_exit();

    /* A Candela that predates candela_area_light (before branch "shapes") loads the area scene with
     * its world as the only light: nothing to compare, skip (meson's 77) rather than fail. */
    if (argc > 3 && st.num_lights < (unsigned)atoi(argv[3])) {
        candela_image_free(&img);
        SKIP("%s: %u lights loaded, the scene has %s: this Candela ignores candela_area_light", argv[1],
             st.num_lights, argv[3]);
    }
    size_t n = (size_t)img.width * (size_t)img.height;
    double sum[3] = {0, 0, 0}, var[3] = {0, 0, 0};
    for (size_t i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) {
            sum[c] += img.rgb[3 * i + c];
            var[c] += img.variance[3 * i + c];
        }
    fprintf(stderr, "  %s: %u lights, %dx%d, %d spp, depth %d\n", argv[1], st.num_lights, img.width,
            img.height, o.spp, o.max_depth);
    for (int c = 0; c < 3; ++c) {
        double mean = sum[c] / (double)n;
        double se = sqrt(var[c]) / (double)n; /* variance of the image mean: sum of the pixels' / n^2 */
        double ratio = mean / ref_mean[c];
        double ratio_se = ratio * sqrt((se / mean) * (se / mean) + (ref_se[c] / ref_mean[c]) * (ref_se[c] / ref_mean[c]));
        double tol = fmax(0.03, 5.0 * ratio_se);
        fprintf(stderr, "  channel %c: candela %.5f (se %.5f), cycles %.5f (se %.5f): ratio %.4f +- %.4f, tolerance %.4f\n",
                "RGB"[c], mean, se, ref_mean[c], ref_se[c], ratio, ratio_se, tol);
        CHECK(fabs(ratio - 1.0) <= tol, "channel %c: Candela / Cycles = %.4f, outside 1 +- %.4f", "RGB"[c], ratio, tol);
        CHECK(5.0 * ratio_se < 0.03, "channel %c: the means' noise (se %.4f) allows no 3%% test", "RGB"[c], ratio_se);
    }
    candela_image_free(&img);
    return test_exit();
}
