/* tests/test_shards.c: what `--sample-shard I/N` + `candela merge` guarantee (README "Sample
 * shards").
 *
 * Shard I renders samples [spp I/N, spp (I+1)/N) of every pixel with the full render's random
 * numbers. What a merge can and cannot equal:
 * - with a light sampler that learns nothing (power) and no guiding, every sample is the full
 *   render's sample bit for bit; only the order of the double sums differs (per shard, then
 *   added), so every merged pixel mean equals the full render's to float rounding (checked:
 *   within 4 float ulps, relative);
 * - with learning (cache points' visibility, guiding) each shard learns from its own samples
 *   only, so the estimates differ (both unbiased): checked statistically, per pixel
 *   z = (merged - full) / sqrt(var_merged + var_full) with the variances of the means the EXRs
 *   carry, mean z^2 <= 1.5 (about 1 for independent estimates, less for these correlated ones)
 *   and the image means within 4 sigma; a merge of shards rendered with a different seed is a
 *   control that must fail the bit-level check above;
 * - the variance channel of the merge is that of all samples: close to the full render's.
 * usage: test_shards SCENES_DIR (the repository's scenes/, for default.gltf) */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "candela.h"
#include "check.h"
#include "io.h"

#define SHARDS 4
#define SPP 32

typedef struct Img {
    int w, h;
    float *c[6]; /* R G B variance.R variance.G variance.B */
} Img;

static int read_img(const char *path, Img *im) {
    static const char *names[6] = {"R", "G", "B", "variance.R", "variance.G", "variance.B"};
    char err[IO_ERR_LEN];
    memset(im, 0, sizeof *im);
    for (int k = 0; k < 6; ++k)
        if (io_read_exr_channel(path, names[k], &im->w, &im->h, &im->c[k], err) != 0) {
            fprintf(stderr, "%s\n", err);
            return -1;
        }
    return 0;
}

static void free_img(Img *im) {
    for (int k = 0; k < 6; ++k) free(im->c[k]);
}

static void base_options(CandelaOptions *o, const char *scene, CandelaLightSampler ls, uint64_t seed) {
    candela_options_default(o);
    o->scene_path = scene;
    o->width = 32;
    o->height = 24;
    o->spp = SPP;
    o->seed = seed;
    o->quiet = 1;
    o->light_sampler = ls;
}

static int render_full(const char *scene, CandelaLightSampler ls, const char *exr) {
    CandelaOptions o;
    base_options(&o, scene, ls, 0);
    CandelaImage im;
    char err[CANDELA_ERR_LEN];
    int rc = candela_render(&o, &im, NULL, NULL, err);
    if (rc == 0) rc = candela_write_outputs(&im, exr, NULL, err);
    if (rc != 0) fprintf(stderr, "%s\n", err);
    candela_image_free(&im);
    return rc;
}

static int render_merged(const char *scene, CandelaLightSampler ls, uint64_t seed_of_shard1, const char *dir,
                         const char *exr) {
    char films[SHARDS][4096], err[CANDELA_ERR_LEN];
    const char *list[SHARDS];
    for (int i = 0; i < SHARDS; ++i) {
        CandelaOptions o;
        base_options(&o, scene, ls, i == 1 ? seed_of_shard1 : 0);
        snprintf(films[i], sizeof films[i], "%s/shard%d.film", dir, i);
        o.shard_index = (uint32_t)i;
        o.shard_count = SHARDS;
        o.film_path = films[i];
        list[i] = films[i];
        CandelaImage im;
        int rc = candela_render(&o, &im, NULL, NULL, err);
        candela_image_free(&im);
        if (rc != 0) { fprintf(stderr, "%s\n", err); return -1; }
    }
    if (seed_of_shard1 != 0) return candela_merge(exr, NULL, list, SHARDS, err) == 0 ? -2 : 0; /* must be refused */
    if (candela_merge(exr, NULL, list, SHARDS, err) != 0) { fprintf(stderr, "%s\n", err); return -1; }
    return 0;
}

/* Largest relative difference of the means, in float ulps (of the larger value). */
static double max_ulps(const Img *a, const Img *b) {
    double worst = 0.0;
    size_t n = (size_t)a->w * a->h;
    for (int k = 0; k < 3; ++k)
        for (size_t i = 0; i < n; ++i) {
            double x = a->c[k][i], y = b->c[k][i], m = fmax(fabs(x), fabs(y));
            if (m == 0.0) continue;
            double ulp = m * 0x1.0p-23;
            worst = fmax(worst, fabs(x - y) / ulp);
        }
    return worst;
}

static void statistics(const Img *a, const Img *b, double *mean_z2, double *mean_sigmas, double *var_ratio) {
    size_t n = (size_t)a->w * a->h, used = 0;
    double z2 = 0.0, da = 0.0, va = 0.0, vsum_a = 0.0, vsum_b = 0.0;
    for (int k = 0; k < 3; ++k)
        for (size_t i = 0; i < n; ++i) {
            double v = (double)a->c[3 + k][i] + b->c[3 + k][i], d = (double)a->c[k][i] - b->c[k][i];
            da += d;
            va += v;
            vsum_a += a->c[3 + k][i];
            vsum_b += b->c[3 + k][i];
            if (v > 0.0) { z2 += d * d / v; ++used; }
        }
    *mean_z2 = used ? z2 / (double)used : 0.0;
    *mean_sigmas = va > 0.0 ? fabs(da) / sqrt(va) : 0.0;
    *var_ratio = vsum_b > 0.0 ? vsum_a / vsum_b : 1.0;
}

int main(int argc, char **argv) {
    if (argc < 2) { fprintf(stderr, "usage: test_shards SCENES_DIR\n"); return 2; }
    char scene[4096], dir[] = "/tmp/candela_shards_XXXXXX", full[4200], merged[4200];
    snprintf(scene, sizeof scene, "%s/default.gltf", argv[1]);
    if (!mkdtemp(dir)) { perror("mkdtemp"); return 1; }
    snprintf(full, sizeof full, "%s/full.exr", dir);
    snprintf(merged, sizeof merged, "%s/merged.exr", dir);

    /* no learning: the samples are the full render's; the means agree to rounding */
    CHECK(render_full(scene, CANDELA_LIGHT_SAMPLER_POWER, full) == 0, "full render (power)");
    CHECK(render_merged(scene, CANDELA_LIGHT_SAMPLER_POWER, 0, dir, merged) == 0, "shards + merge (power)");
    Img a, b;
    if (read_img(full, &a) == 0 && read_img(merged, &b) == 0) {
        double ulps = max_ulps(&b, &a);
        CHECK(ulps <= 4.0, "power: merged means differ from the full render's by %.1f float ulps", ulps);
        double z2, sig, vr;
        statistics(&b, &a, &z2, &sig, &vr);
        CHECK(fabs(vr - 1.0) < 1e-4, "power: merged variance / full variance = %.6f", vr);
        free_img(&a);
        free_img(&b);
    } else {
        CHECK(0, "reading the power EXRs");
    }
    /* a shard of another seed is another render: the merge refuses it */
    CHECK(render_merged(scene, CANDELA_LIGHT_SAMPLER_POWER, 7, dir, merged) == 0, "merge accepted a shard of another seed");

    /* cache points (the default): each shard learns visibility from its own samples */
    CHECK(render_full(scene, CANDELA_LIGHT_SAMPLER_CACHEPOINTS, full) == 0, "full render (cachepoints)");
    CHECK(render_merged(scene, CANDELA_LIGHT_SAMPLER_CACHEPOINTS, 0, dir, merged) == 0, "shards + merge (cachepoints)");
    if (read_img(full, &a) == 0 && read_img(merged, &b) == 0) {
        double z2, sig, vr;
        statistics(&b, &a, &z2, &sig, &vr);
        fprintf(stderr, "cachepoints: mean z^2 %.3f, image means %.2f sigma apart, variance ratio %.3f, max %.0f ulps\n",
                z2, sig, vr, max_ulps(&b, &a));
        CHECK(z2 <= 1.5, "cachepoints: mean z^2 = %.3f", z2);
        CHECK(sig <= 4.0, "cachepoints: image means %.2f sigma apart", sig);
        CHECK(vr > 0.5 && vr < 2.0, "cachepoints: merged variance / full variance = %.3f", vr);
        free_img(&a);
        free_img(&b);
    } else {
        CHECK(0, "reading the cachepoints EXRs");
    }
    char cmd[4300];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", dir);
    return test_exit();
}
