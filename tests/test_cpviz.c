/* Cache point visualisation (README "Cache point AOV", "Cache point dump") on
 * tests/scenes/occluded_lights.gltf (a wall with a doorway, 32 point lights, an area light,
 * glass): the PLY of --dump-cachepoints parses, holds as many points as the statistics count
 * with consistent per-point fields and the colours of the AOV's palette; at 1 spp every
 * first hit's AOV colour is exactly the colour of one point of the dump (and black where the
 * camera ray escapes), many different points show up, and the top-entry colours are those of
 * lights or clusters; the AOV and the dump are bit-identical for 1 and 2 threads; the beauty
 * image is bit-identical with and without them; the flags refuse other samplers and names that
 * are not .ply. argv[1]: tests/scenes; argv[2]: a scratch folder. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cachepoint_viz.h"
#include "candela.h"
#include "check.h"

typedef struct PlyPoint {
    float x, y, z, radius;
    unsigned near, far, clusters, slots, sparse, learned;
    double attempts, visible;
    float mean_w, min_w;
    int r, g, b;
} PlyPoint;

/* Reads the dump: the header must be exactly the documented one. Returns the point count
 * (-1: a malformed file), *out the points. */
static long read_ply(const char *path, PlyPoint **out) {
    FILE *f = fopen(path, "r");
    *out = NULL;
    if (!f) return -1;
    char line[512];
    long n = -1;
    int props = 0, ok = fgets(line, sizeof line, f) && strcmp(line, "ply\n") == 0;
    ok = ok && fgets(line, sizeof line, f) && strcmp(line, "format ascii 1.0\n") == 0;
    while (ok && fgets(line, sizeof line, f)) {
        if (strncmp(line, "comment ", 8) == 0) continue;
        if (sscanf(line, "element vertex %ld", &n) == 1) continue;
        if (strncmp(line, "property ", 9) == 0) { ++props; continue; }
        if (strcmp(line, "end_header\n") == 0) break;
        ok = 0;
    }
    if (!ok || n < 0 || props != 17) { fclose(f); return -1; }
    PlyPoint *p = calloc((size_t)n + 1, sizeof *p);
    for (long i = 0; i < n && ok; ++i) {
        PlyPoint *q = &p[i];
        ok = fscanf(f, "%f %f %f %f %u %u %u %u %lf %lf %u %u %f %f %d %d %d", &q->x, &q->y, &q->z, &q->radius, &q->near,
                    &q->far, &q->clusters, &q->slots, &q->attempts, &q->visible, &q->sparse, &q->learned, &q->mean_w,
                    &q->min_w, &q->r, &q->g, &q->b) == 17;
    }
    char extra[8];
    if (ok && fscanf(f, "%7s", extra) == 1) ok = 0; /* nothing after the last point */
    fclose(f);
    if (!ok) { free(p); return -1; }
    *out = p;
    return n;
}

static int render(const char *scene, int spp, int threads, int aov, const char *dump, CandelaImage *img,
                  CandelaStats *st) {
    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = scene;
    o.width = 48;
    o.height = 32;
    o.spp = spp;
    o.threads = threads;
    o.quiet = 1;
    o.light_units = CANDELA_LIGHT_UNITS_RAW;
    o.light_sampler = CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
    o.aov_selection = aov;
    o.cachepoint_dump_path = dump;
    char err[CANDELA_ERR_LEN];
    int rc = candela_render(&o, img, st, NULL, err);
    CHECK(rc == 0, "%s: %s", scene, err);
    return rc;
}

static uint32_t rgb8(const float *c) {
    return (uint32_t)lrintf(c[0] * 255.0f) << 16 | (uint32_t)lrintf(c[1] * 255.0f) << 8 | (uint32_t)lrintf(c[2] * 255.0f);
}

static int cmp_u32(const void *a, const void *b) {
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

static int in_sorted(const uint32_t *a, size_t n, uint32_t v) { return bsearch(&v, a, n, sizeof v, cmp_u32) != NULL; }

static char *slurp(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *b = malloc((size_t)n + 1);
    *len = b && fread(b, 1, (size_t)n, f) == (size_t)n ? (size_t)n : 0;
    fclose(f);
    return b;
}

int main(int argc, char **argv) {
    if (argc < 3) SKIP("usage: test_cpviz SCENES_DIR SCRATCH_DIR");
    char scene[1024], ply1[1024], ply2[1024];
    snprintf(scene, sizeof scene, "%s/occluded_lights.gltf", argv[1]);
    snprintf(ply1, sizeof ply1, "%s/cpviz_1.ply", argv[2]);
    snprintf(ply2, sizeof ply2, "%s/cpviz_2.ply", argv[2]);

    /* 1 spp: each pixel's AOV is one vertex's colour, not a mean */
    CandelaImage a, b;
    CandelaStats sa, sb;
    if (render(scene, 1, 1, 1, ply1, &a, &sa) != 0) return test_exit();
    CHECK(a.selection_point && a.selection_light, "the AOV is in the image");
    PlyPoint *pts = NULL;
    long n = read_ply(ply1, &pts);
    CHECK(n >= 10, "%s: a PLY with points (%ld)", ply1, n);
    CHECK(n == (long)sa.num_cachepoints, "PLY points %ld, statistics %u", n, sa.num_cachepoints);
    if (n < 10 || !a.selection_point) return test_exit();

    uint32_t *palette = malloc((size_t)n * sizeof *palette);
    double attempts = 0.0;
    long learned = 0;
    for (long i = 0; i < n; ++i) {
        const PlyPoint *q = &pts[i];
        CHECK(isfinite(q->x) && isfinite(q->y) && isfinite(q->z) && q->radius > 0.0f, "point %ld: position/radius", i);
        CHECK(q->slots == q->near + q->far && q->clusters <= q->far, "point %ld: %u slots for %u near + %u far", i,
              q->slots, q->near, q->far);
        CHECK(q->visible >= 0.0 && q->visible <= q->attempts, "point %ld: visible %g of %g attempts", i, q->visible,
              q->attempts);
        CHECK(q->sparse <= q->slots && q->learned <= q->slots, "point %ld: slot counts", i);
        CHECK(q->min_w > 0.0f && q->min_w <= q->mean_w && q->mean_w <= 1.0f, "point %ld: W' min %g mean %g", i, q->min_w,
              q->mean_w);
        vec3 c = cachepoint_false_colour((uint32_t)i, CACHEPOINT_COLOUR_POINT);
        const float cf[3] = {c.x, c.y, c.z};
        CHECK(((uint32_t)q->r << 16 | (uint32_t)q->g << 8 | (uint32_t)q->b) == rgb8(cf), "point %ld: colour", i);
        palette[i] = rgb8(cf);
        attempts += q->attempts;
        learned += q->learned;
    }
    CHECK(attempts > 0.0, "visibility learning counted attempts");
    fprintf(stderr, "  %ld points, %.0f attempts, %ld slots with W' != 1\n", n, attempts, learned);
    qsort(palette, (size_t)n, sizeof *palette, cmp_u32);

    /* every first hit's colour is a point's; misses are black; many points are seen */
    size_t npx = (size_t)a.width * a.height, hits = 0, coloured = 0;
    uint32_t *seen = malloc(npx * sizeof *seen), *seen_light = malloc(npx * sizeof *seen_light);
    size_t nseen = 0, nseen_light = 0;
    for (size_t i = 0; i < npx; ++i) {
        const float *c = a.selection_point + 3 * i, *l = a.selection_light + 3 * i;
        int black = c[0] == 0.0f && c[1] == 0.0f && c[2] == 0.0f;
        if (!isfinite(a.depth[i])) {
            CHECK(black && l[0] == 0.0f && l[1] == 0.0f && l[2] == 0.0f, "pixel %zu: a miss has no colour", i);
            continue;
        }
        ++hits;
        if (black) continue; /* a delta (glass) first hit selects no light */
        ++coloured;
        uint32_t v = rgb8(c);
        CHECK(fabsf(c[0] * 255.0f - rintf(c[0] * 255.0f)) < 1e-3f, "pixel %zu: colour off the palette grid", i);
        CHECK(in_sorted(palette, (size_t)n, v), "pixel %zu: colour %06x is no point's", i, v);
        seen[nseen++] = v;
        if (!(l[0] == 0.0f && l[1] == 0.0f && l[2] == 0.0f)) seen_light[nseen_light++] = rgb8(l);
    }
    qsort(seen, nseen, sizeof *seen, cmp_u32);
    qsort(seen_light, nseen_light, sizeof *seen_light, cmp_u32);
    size_t distinct = 0, distinct_light = 0;
    for (size_t i = 0; i < nseen; ++i) distinct += i == 0 || seen[i] != seen[i - 1];
    for (size_t i = 0; i < nseen_light; ++i) distinct_light += i == 0 || seen_light[i] != seen_light[i - 1];
    fprintf(stderr, "  %zu hits, %zu coloured; %zu distinct points, %zu distinct top entries\n", hits, coloured, distinct,
            distinct_light);
    CHECK(coloured > hits / 2, "most first hits use a point (%zu of %zu)", coloured, hits);
    CHECK(distinct >= 50, "the point colour changes across the image: %zu distinct", distinct);
    CHECK(nseen_light > coloured / 2 && distinct_light >= 2, "top entries: %zu coloured, %zu distinct", nseen_light,
          distinct_light);

    /* 1 and 2 threads: the same AOV and the same dump, byte for byte */
    if (render(scene, 1, 2, 1, ply2, &b, &sb) == 0) {
        CHECK(memcmp(a.selection_point, b.selection_point, 3 * npx * sizeof(float)) == 0 &&
                  memcmp(a.selection_light, b.selection_light, 3 * npx * sizeof(float)) == 0,
              "the AOV differs between 1 and 2 threads");
        size_t l1 = 0, l2 = 0;
        char *f1 = slurp(ply1, &l1), *f2 = slurp(ply2, &l2);
        CHECK(f1 && f2 && l1 == l2 && l1 > 0 && memcmp(f1, f2, l1) == 0, "the dump differs between 1 and 2 threads");
        free(f1); free(f2);
        candela_image_free(&b);
    }
    candela_image_free(&a);

    /* the beauty image does not depend on the AOV or the dump (4 spp: learning at barriers) */
    if (render(scene, 4, 2, 1, ply2, &a, &sa) == 0) {
        if (render(scene, 4, 2, 0, NULL, &b, &sb) == 0) {
            CHECK(memcmp(a.rgb, b.rgb, 3 * npx * sizeof(float)) == 0, "the AOV changed the image");
            CHECK(!b.selection_point && !b.selection_light, "no AOV unless asked");
            candela_image_free(&b);
        }
        /* a mean over the hits of palette colours and black (glass): within [0, 1] */
        for (size_t i = 0; i < 3 * npx; ++i)
            CHECK(a.selection_point[i] >= 0.0f && a.selection_point[i] <= 1.0f + 1e-6f, "pixel channel %zu: %g", i,
                  a.selection_point[i]);
        candela_image_free(&a);
    }

    /* the flags: other samplers refused, a name that is not .ply refused */
    {
        CandelaOptions o;
        char err[CANDELA_ERR_LEN];
        candela_options_default(&o);
        char *args1[] = {"--aov", "cachepoint", "--light-sampler", "power"};
        int i = 0;
        CHECK(candela_parse_render_flag(&o, 4, args1, &i, err) == 1 && o.aov_selection == 1, "--aov cachepoint parses");
        i = 2;
        CHECK(candela_parse_render_flag(&o, 4, args1, &i, err) == 1, "--light-sampler parses");
        CHECK(candela_options_check(&o, err) != 0 && strstr(err, "--aov cachepoint"), "--aov cachepoint with power: '%s'",
              err);
        candela_options_default(&o);
        char *args2[] = {"--dump-cachepoints", "points.txt"};
        i = 0;
        CHECK(candela_parse_render_flag(&o, 2, args2, &i, err) == -1 && strstr(err, "FILE.ply"), "a .txt dump: '%s'", err);
        char *args3[] = {"--dump-cachepoints", "points.ply", "--light-sampler", "tree"};
        i = 0;
        CHECK(candela_parse_render_flag(&o, 4, args3, &i, err) == 1 && o.cachepoint_dump_path, "--dump-cachepoints parses");
        i = 2;
        candela_parse_render_flag(&o, 4, args3, &i, err);
        CHECK(candela_options_check(&o, err) != 0 && strstr(err, "--dump-cachepoints"), "a dump with tree: '%s'", err);
    }
    free(pts); free(palette); free(seen); free(seen_light);
    remove(ply1); remove(ply2);
    return test_exit();
}
