/* tests/test_volumes.c: volumes/ module. Media from homogeneous coefficients and from dense
 * grids (io_volume_grid_from_dense), against closed forms:
 *   - Beer-Lambert by ratio tracking and by delta (spectral) tracking, homogeneous RGB and a
 *     constant grid; transmittance through a linear ramp grid (closed form) and an oblique
 *     ray through the whole grid (optical depth integrated numerically from the dense values
 *     with the test's own trilinear interpolation);
 *   - the first-scatter distance distribution (chi-square, grey) and the weighted scatter
 *     density per channel (chromatic, with and without a chromatic path throughput);
 *   - the majorant: over random grids, transforms and rays, no point of a segment exceeds
 *     its majorant and the segments tile the clipped interval exactly;
 *   - emission gathered by spectral tracking against L_e sigma_a / sigma_t (1 - exp(-sigma_t d));
 *   - two overlapping media (merged majorants): transmittance, and the scattering events
 *     split between the media with unbiased weights per channel;
 *   - Henyey-Greenstein (integral, chi-square, sample pdf = phase), the blackbody colour, and
 *     bad input (one-line errors, NaN / negative / huge densities never hang).
 * Monte Carlo checks allow 5 standard errors of the sample mean (estimated from the sample
 * variance); every generator is seeded, so runs are deterministic. argv[1], optional: the
 * shared assets folder (slab.vdb; skipped when absent). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "stats.h"
#include "volumes.h"

#define PI_D 3.14159265358979323846
#define NSE 5.0 /* tolerance in standard errors */

/* ---------------------------------------------------------------- helpers */

typedef struct { uint64_t s; } TestRng;

static float test_rng_next(void *state) {
    uint64_t z = (((TestRng *)state)->s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    z ^= z >> 31;
    return (float)(z >> 40) * (1.0f / 16777216.0f); /* 24 bits: strictly below 1 */
}

static VolumeRng make_rng(TestRng *r, uint64_t seed) {
    r->s = seed;
    VolumeRng v = {test_rng_next, r};
    return v;
}

static double urand(TestRng *r) { return test_rng_next(r); }

/* Running mean and standard error. */
typedef struct { double n, s, s2; } Acc;
static void acc_add(Acc *a, double x) { a->n += 1.0; a->s += x; a->s2 += x * x; }
static double acc_mean(const Acc *a) { return a->s / a->n; }
static double acc_se(const Acc *a) {
    double m = acc_mean(a), var = (a->s2 - a->n * m * m) / (a->n - 1.0);
    return sqrt(var > 0.0 ? var / a->n : 0.0);
}
/* within NSE standard errors (plus a float-rounding floor for zero-variance estimates) */
static int acc_ok(const Acc *a, double expect) {
    return fabs(acc_mean(a) - expect) <= NSE * acc_se(a) + 1e-6 * (1.0 + fabs(expect));
}

static void identity(float m[16]) {
    memset(m, 0, 16 * sizeof(float));
    m[0] = m[5] = m[10] = m[15] = 1.0f;
}

/* index -> world: uniform scale s, then translation t */
static void scale_translate(float m[16], float s, float tx, float ty, float tz) {
    identity(m);
    m[0] = m[5] = m[10] = s;
    m[12] = tx;
    m[13] = ty;
    m[14] = tz;
}

static int make_grid(const float *v, int nx, int ny, int nz, const float i2w[16], const char *name, IoVolumeGrid *g) {
    char err[IO_ERR_LEN] = "";
    int rc = io_volume_grid_from_dense(v, nx, ny, nz, i2w, name, g, err);
    CHECK(rc == 0, "grid '%s': %s", name, err);
    return rc;
}

static VolumeDesc grid_desc(const IoVolumeGrid *density, float scale, float albedo) {
    VolumeDesc d;
    memset(&d, 0, sizeof d);
    d.density = density;
    identity(d.node_to_world);
    d.density_scale = scale;
    d.albedo[0] = d.albedo[1] = d.albedo[2] = albedo;
    d.emission_color[0] = d.emission_color[1] = d.emission_color[2] = 1.0f;
    return d;
}

static int one_line(const char *err) { return err[0] != 0 && strchr(err, '\n') == NULL; }

static float sigma_t_at(const Medium *m, const float p[3]) {
    MediumCoefficients c;
    medium_eval(m, p, &c);
    float st = 0.0f;
    for (int k = 0; k < 3; ++k) st = fmaxf(st, c.sigma_a[k] + c.sigma_s[k]);
    return st;
}

/* Trilinear interpolation of a dense array in index space (the test's own reference):
 * voxels outside [0, n) are 0, non-finite and negative values count as 0. */
static double dense_trilinear(const float *v, int nx, int ny, int nz, const double p[3]) {
    double f[3] = {floor(p[0]), floor(p[1]), floor(p[2])};
    double w[3] = {p[0] - f[0], p[1] - f[1], p[2] - f[2]};
    double s = 0.0;
    for (int c = 0; c < 8; ++c) {
        int x = (int)f[0] + (c >> 2), y = (int)f[1] + ((c >> 1) & 1), z = (int)f[2] + (c & 1);
        double val = 0.0;
        if (x >= 0 && y >= 0 && z >= 0 && x < nx && y < ny && z < nz) {
            float q = v[x + nx * (y + ny * z)];
            val = q > 0.0f && isfinite(q) ? q : 0.0;
        }
        s += val * ((c >> 2) ? w[0] : 1.0 - w[0]) * (((c >> 1) & 1) ? w[1] : 1.0 - w[1]) * ((c & 1) ? w[2] : 1.0 - w[2]);
    }
    return s;
}

static void normalize3(float v[3]) {
    float l = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; ++k) v[k] /= l;
}

/* Mean transmittance of n ratio-tracking estimates through one view, per channel. */
static void ratio_estimate(const MediaView *view, const float o[3], const float d[3], float tmin, float tmax, int n,
                           uint64_t seed, Acc acc[3], VolumeStats *st) {
    TestRng r;
    VolumeRng rng = make_rng(&r, seed);
    memset(acc, 0, 3 * sizeof(Acc));
    for (int i = 0; i < n; ++i) {
        float T[3];
        media_transmittance(view, o, d, tmin, tmax, &rng, T, st);
        for (int k = 0; k < 3; ++k) acc_add(&acc[k], T[k]);
    }
}

/* Delta (spectral) tracking estimate of the transmittance of a non-scattering view: the
 * weight of the walks that pass (albedo 0: the others are absorbed). */
static void delta_estimate(const MediaView *view, const float o[3], const float d[3], float tmin, float tmax, int n,
                           uint64_t seed, Acc acc[3], VolumeStats *st) {
    TestRng r;
    VolumeRng rng = make_rng(&r, seed);
    memset(acc, 0, 3 * sizeof(Acc));
    const float beta[3] = {1.0f, 1.0f, 1.0f};
    for (int i = 0; i < n; ++i) {
        VolumeEvent ev;
        media_sample_event(view, o, d, tmin, tmax, beta, &rng, &ev, st);
        for (int k = 0; k < 3; ++k) acc_add(&acc[k], ev.type == VOLUME_EVENT_PASSED ? ev.weight[k] : 0.0);
    }
}

/* ---------------------------------------------------------------- Beer-Lambert */

static void test_beer_lambert(void) {
    /* homogeneous, RGB: a different extinction per channel */
    Medium h;
    char err[IO_ERR_LEN] = "";
    const float sa[3] = {0.2f, 0.5f, 1.0f}, ss[3] = {0.3f, 0.5f, 1.0f}, sa_only[3] = {0.5f, 1.0f, 2.0f}, zero[3] = {0};
    CHECK(medium_init_homogeneous(&h, sa, ss, 0.3f, err) == 0, "%s", err);
    Medium ha;
    CHECK(medium_init_homogeneous(&ha, sa_only, zero, 0.0f, err) == 0, "%s", err);
    MediaView v = {{&h}, 1}, va = {{&ha}, 1};
    const float o[3] = {0.3f, -1.0f, 2.0f};
    float d[3] = {1.0f, 2.0f, -0.5f};
    normalize3(d);
    const double dist[3] = {0.25, 1.0, 2.5};
    VolumeStats st = {0};
    for (int i = 0; i < 3; ++i) {
        Acc r[3], dl[3];
        ratio_estimate(&v, o, d, 0.0f, (float)dist[i], 20000, 11 + i, r, &st);
        delta_estimate(&va, o, d, 0.0f, (float)dist[i], 20000, 21 + i, dl, &st);
        for (int k = 0; k < 3; ++k) {
            double ex = exp(-(sa[k] + ss[k]) * dist[i]);
            CHECK(acc_ok(&r[k], ex), "homogeneous ratio tracking d %g ch %d: %g +- %g vs %g", dist[i], k,
                  acc_mean(&r[k]), acc_se(&r[k]), ex);
            CHECK(acc_ok(&dl[k], ex), "homogeneous delta tracking d %g ch %d: %g +- %g vs %g", dist[i], k,
                  acc_mean(&dl[k]), acc_se(&dl[k]), ex);
        }
        printf("homogeneous d %.2f: ratio (%.4f %.4f %.4f) delta (%.4f %.4f %.4f) exact (%.4f %.4f %.4f)\n", dist[i],
               acc_mean(&r[0]), acc_mean(&r[1]), acc_mean(&r[2]), acc_mean(&dl[0]), acc_mean(&dl[1]), acc_mean(&dl[2]),
               exp(-0.5 * dist[i]), exp(-1.0 * dist[i]), exp(-2.0 * dist[i]));
    }
    medium_free(&h);
    medium_free(&ha);

    /* a constant grid: 32^3 voxels of 1/32 m, density 1 x scale 3; rays inside, away from
     * the edges (the trilinear field is constant between voxel centres 0 and 31) */
    enum { N = 32 };
    float *vals = malloc(sizeof(float) * N * N * N);
    for (int i = 0; i < N * N * N; ++i) vals[i] = 1.0f;
    float i2w[16];
    scale_translate(i2w, 1.0f / N, 0.0f, 0.0f, 0.0f);
    IoVolumeGrid g;
    if (make_grid(vals, N, N, N, i2w, "density", &g) == 0) {
        Medium gm, ga;
        VolumeDesc desc = grid_desc(&g, 3.0f, 0.6f);
        CHECK(medium_init_vdb(&gm, &desc, err) == 0, "%s", err);
        desc.albedo[0] = desc.albedo[1] = desc.albedo[2] = 0.0f;
        CHECK(medium_init_vdb(&ga, &desc, err) == 0, "%s", err);
        MediaView gv = {{&gm}, 1}, gva = {{&ga}, 1};
        const float go[3] = {0.1f, 0.5f, 0.47f};
        float gd[3] = {1.0f, 0.1f, -0.05f};
        normalize3(gd);
        const double gdist[3] = {0.1, 0.3, 0.7};
        for (int i = 0; i < 3; ++i) {
            Acc r[3], dl[3];
            ratio_estimate(&gv, go, gd, 0.0f, (float)gdist[i], 20000, 31 + i, r, &st);
            delta_estimate(&gva, go, gd, 0.0f, (float)gdist[i], 20000, 41 + i, dl, &st);
            double ex = exp(-3.0 * gdist[i]);
            CHECK(acc_ok(&r[1], ex), "grid ratio tracking d %g: %g +- %g vs %g", gdist[i], acc_mean(&r[1]),
                  acc_se(&r[1]), ex);
            CHECK(acc_ok(&dl[1], ex), "grid delta tracking d %g: %g +- %g vs %g", gdist[i], acc_mean(&dl[1]),
                  acc_se(&dl[1]), ex);
            printf("constant grid d %.2f: ratio %.4f +- %.4f, delta %.4f +- %.4f, exact %.4f\n", gdist[i],
                   acc_mean(&r[1]), acc_se(&r[1]), acc_mean(&dl[1]), acc_se(&dl[1]), ex);
        }
        /* inside, a segment's majorant is the constant sigma_t (tight, up to the slack) */
        MajorantIterator it;
        medium_majorant_begin(&gm, go, gd, 0.0f, 0.5f, &it);
        float t0, t1, maj;
        int nseg = 0;
        while (medium_majorant_next(&it, &t0, &t1, &maj)) {
            ++nseg;
            CHECK(maj >= 3.0f && maj <= 3.0f * 1.001f, "constant grid: majorant %g, sigma_t 3", maj);
        }
        CHECK(nseg == 1, "constant grid: %d segments over a uniform region (merged: 1)", nseg);

        /* decomposition tracking (Kutz et al. 2017 §4): a chromatic homogeneous medium (the
         * control component) overlapping the grid; with and without it, the transmittance of
         * the absorbing pair and the scattered weight E[w 1{scatter}] = sigma_s / sigma_t (1 -
         * exp(-sigma_t d)) of the scattering pair match the closed forms per channel */
        Medium hh, hha;
        const float hsa[3] = {0.4f, 0.8f, 1.2f}, hss[3] = {0.6f, 0.4f, 0.2f}, hsa_only[3] = {1.0f, 1.2f, 1.4f}, z3[3] = {0};
        CHECK(medium_init_homogeneous(&hh, hsa, hss, 0.0f, err) == 0, "%s", err);
        CHECK(medium_init_homogeneous(&hha, hsa_only, z3, 0.0f, err) == 0, "%s", err);
        const double dd = 0.5;
        uint64_t grid_lookups[2] = {0, 0};
        for (int dec = 0; dec < 2; ++dec) {
            MediaView pa = {{&hha, &ga}, 2, dec}, ps = {{&hh, &gm}, 2, dec};
            Acc dl[3], sw[3];
            VolumeStats dst = {0};
            delta_estimate(&pa, go, gd, 0.0f, (float)dd, 40000, 51 + dec, dl, &dst);
            grid_lookups[dec] = dst.grid_collisions;
            CHECK(dst.collisions > 0, "no collisions");
            if (dec) /* control collisions (rate 1.4 of 4.4) skip the grid */
                CHECK(dst.grid_collisions < 0.8 * dst.collisions, "decomposition: %llu of %llu collisions looked up the grid",
                      (unsigned long long)dst.grid_collisions, (unsigned long long)dst.collisions);
            else
                CHECK(dst.grid_collisions == dst.collisions, "spectral tracking skipped grid lookups");
            TestRng r;
            VolumeRng rng = make_rng(&r, 61 + dec);
            memset(sw, 0, sizeof sw);
            const float one[3] = {1.0f, 1.0f, 1.0f};
            for (int i = 0; i < 40000; ++i) {
                VolumeEvent ev;
                media_sample_event(&ps, go, gd, 0.0f, (float)dd, one, &rng, &ev, &st);
                for (int k = 0; k < 3; ++k) acc_add(&sw[k], ev.type == VOLUME_EVENT_SCATTER ? ev.weight[k] : 0.0);
            }
            for (int k = 0; k < 3; ++k) {
                double tex = exp(-(hsa_only[k] + 3.0) * dd);
                double st_k = hsa[k] + hss[k] + 3.0, ss_k = hss[k] + 0.6 * 3.0;
                double sex = ss_k / st_k * (1.0 - exp(-st_k * dd));
                CHECK(acc_ok(&dl[k], tex), "%s tracking, homogeneous + grid, ch %d: T %g +- %g vs %g",
                      dec ? "decomposition" : "spectral", k, acc_mean(&dl[k]), acc_se(&dl[k]), tex);
                CHECK(acc_ok(&sw[k], sex), "%s tracking, homogeneous + grid, ch %d: scattered %g +- %g vs %g",
                      dec ? "decomposition" : "spectral", k, acc_mean(&sw[k]), acc_se(&sw[k]), sex);
            }
            printf("%s tracking, homogeneous + grid: T (%.4f %.4f %.4f) scattered (%.4f %.4f %.4f), grid lookups %llu\n",
                   dec ? "decomposition" : "spectral", acc_mean(&dl[0]), acc_mean(&dl[1]), acc_mean(&dl[2]),
                   acc_mean(&sw[0]), acc_mean(&sw[1]), acc_mean(&sw[2]), (unsigned long long)grid_lookups[dec]);
        }
        medium_free(&hh);
        medium_free(&hha);
        medium_free(&gm);
        medium_free(&ga);
        io_volume_grid_free(&g);
    }
    free(vals);
    printf("Beer-Lambert: %llu collisions\n", (unsigned long long)st.collisions);
    CHECK(st.capped_walks == 0, "capped walks %llu", (unsigned long long)st.capped_walks);
}

/* ---------------------------------------------------------------- scatter distances */

static void test_scatter_distance(void) {
    char err[IO_ERR_LEN] = "";
    const float o[3] = {0.0f, 0.0f, 0.0f}, d[3] = {0.0f, 0.0f, 1.0f};
    /* grey, purely scattering: the first scatter distance has density sigma_s exp(-sigma_t t) */
    {
        Medium m;
        const float sa[3] = {0}, ss[3] = {1.5f, 1.5f, 1.5f};
        CHECK(medium_init_homogeneous(&m, sa, ss, 0.0f, err) == 0, "%s", err);
        MediaView v = {{&m}, 1};
        enum { NB = 41, NS = 200000 };
        const double tmax = 20.0, tb = 4.0;
        double obs[NB] = {0}, expv[NB];
        TestRng r;
        VolumeRng rng = make_rng(&r, 77);
        int bad_weight = 0, passed = 0;
        for (int i = 0; i < NS; ++i) {
            VolumeEvent ev;
            media_sample_event(&v, o, d, 0.0f, (float)tmax, NULL, &rng, &ev, NULL);
            if (ev.type != VOLUME_EVENT_SCATTER) {
                ++passed;
                continue;
            }
            bad_weight += fabsf(ev.weight[0] - 1.0f) > 1e-5f || ev.medium != 0;
            int b = ev.t < tb ? (int)(ev.t / tb * (NB - 1)) : NB - 1;
            obs[b] += 1.0;
        }
        for (int b = 0; b < NB; ++b) {
            double a = b * tb / (NB - 1), e = b == NB - 1 ? tmax : (b + 1) * tb / (NB - 1);
            expv[b] = NS * (exp(-1.5 * a) - exp(-1.5 * e));
        }
        int dof;
        double stat, p = chi2_pvalue(obs, expv, NB, &dof, &stat);
        printf("grey scatter distance: chi2 %.1f dof %d p %.3f\n", stat, dof, p);
        CHECK(p > 1e-3, "first-scatter distance: chi2 %g dof %d p %g", stat, dof, p);
        CHECK(bad_weight == 0, "%d grey scatter weights differ from 1", bad_weight);
        CHECK(passed == 0, "%d walks passed 20 m of sigma_t 1.5", passed);
        medium_free(&m);
    }
    /* chromatic: E[weight_c 1(scatter at t in bin)] = integral over the bin of
     * sigma_s,c exp(-sigma_t,c t); the passing weight has mean exp(-sigma_t,c tmax) */
    {
        Medium m;
        const float sa[3] = {0.2f, 0.1f, 0.0f}, ss[3] = {0.5f, 1.0f, 2.0f};
        CHECK(medium_init_homogeneous(&m, sa, ss, 0.5f, err) == 0, "%s", err);
        MediaView v = {{&m}, 1};
        const float betas[2][3] = {{1.0f, 1.0f, 1.0f}, {1.0f, 0.3f, 2.0f}};
        enum { NB = 10, NS = 200000 };
        const double tmax = 3.0;
        for (int bi = 0; bi < 2; ++bi) {
            Acc bin[NB][3], pass[3];
            memset(bin, 0, sizeof bin);
            memset(pass, 0, sizeof pass);
            TestRng r;
            VolumeRng rng = make_rng(&r, 99 + bi);
            for (int i = 0; i < NS; ++i) {
                VolumeEvent ev;
                media_sample_event(&v, o, d, 0.0f, (float)tmax, betas[bi], &rng, &ev, NULL);
                int hit = ev.type == VOLUME_EVENT_SCATTER ? (int)(ev.t / tmax * NB) : -1;
                if (hit >= NB) hit = NB - 1;
                for (int b = 0; b < NB; ++b)
                    for (int k = 0; k < 3; ++k) acc_add(&bin[b][k], b == hit ? ev.weight[k] : 0.0);
                for (int k = 0; k < 3; ++k) acc_add(&pass[k], ev.type == VOLUME_EVENT_PASSED ? ev.weight[k] : 0.0);
            }
            int fails = 0;
            double worst = 0.0;
            for (int b = 0; b < NB; ++b)
                for (int k = 0; k < 3; ++k) {
                    double st = sa[k] + ss[k], a = b * tmax / NB, e = (b + 1) * tmax / NB;
                    double ex = ss[k] / st * (exp(-st * a) - exp(-st * e));
                    double z = (acc_mean(&bin[b][k]) - ex) / fmax(acc_se(&bin[b][k]), 1e-12);
                    worst = fmax(worst, fabs(z));
                    if (!acc_ok(&bin[b][k], ex)) {
                        ++fails;
                        fprintf(stderr, "  bin %d ch %d: %g +- %g vs %g\n", b, k, acc_mean(&bin[b][k]),
                                acc_se(&bin[b][k]), ex);
                    }
                }
            CHECK(fails == 0, "chromatic scatter density (beta %d): %d of %d bins off by > %g SE", bi, fails, NB * 3, NSE);
            for (int k = 0; k < 3; ++k) {
                double ex = exp(-(sa[k] + ss[k]) * tmax);
                CHECK(acc_ok(&pass[k], ex), "chromatic pass weight ch %d: %g +- %g vs %g", k, acc_mean(&pass[k]),
                      acc_se(&pass[k]), ex);
            }
            printf("chromatic scatter density (beta %.1f %.1f %.1f): worst bin %.2f SE; pass (%.4f %.4f %.4f) exact "
                   "(%.4f %.4f %.4f)\n",
                   betas[bi][0], betas[bi][1], betas[bi][2], worst, acc_mean(&pass[0]), acc_mean(&pass[1]),
                   acc_mean(&pass[2]), exp(-0.7 * tmax), exp(-1.1 * tmax), exp(-2.0 * tmax));
        }
        medium_free(&m);
    }
}

/* ---------------------------------------------------------------- heterogeneous */

static void test_heterogeneous(void) {
    /* The shared slab.vdb's field: 32^3 voxels over the 1 m box centred at the origin,
     * density = y + 0.5 at voxel centres, so the trilinear field is exactly y + 0.5 between
     * the outermost voxel centres (|y| <= 0.484). */
    enum { N = 32 };
    float *vals = malloc(sizeof(float) * N * N * N);
    for (int z = 0; z < N; ++z)
        for (int y = 0; y < N; ++y)
            for (int x = 0; x < N; ++x) vals[x + N * (y + N * z)] = ((float)y + 0.5f) / N;
    float i2w[16];
    const float off = -0.5f + 0.5f / N;
    scale_translate(i2w, 1.0f / N, off, off, off);
    IoVolumeGrid g;
    char err[IO_ERR_LEN] = "";
    if (make_grid(vals, N, N, N, i2w, "density", &g) == 0) {
        Medium m;
        const float scale = 3.0f;
        VolumeDesc desc = grid_desc(&g, scale, 0.8f);
        CHECK(medium_init_vdb(&m, &desc, err) == 0, "%s", err);
        MediaView v = {{&m}, 1};
        VolumeStats st = {0};
        Acc acc[3];
        /* axis-aligned, along +y from y = -0.4 to 0.4: tau = scale x 0.8 x 0.5 */
        {
            const float o[3] = {0.05f, -0.4f, -0.1f}, d[3] = {0.0f, 1.0f, 0.0f};
            ratio_estimate(&v, o, d, 0.0f, 0.8f, 40000, 5, acc, &st);
            double ex = exp(-scale * 0.8 * 0.5);
            CHECK(acc_ok(&acc[0], ex), "ramp, axis-aligned: %g +- %g vs %g", acc_mean(&acc[0]), acc_se(&acc[0]), ex);
            printf("ramp axis-aligned: %.4f +- %.4f, exact %.4f\n", acc_mean(&acc[0]), acc_se(&acc[0]), ex);
            /* residual ratio tracking (media_transmittance) against plain ratio tracking
             * (media_ratio_track) on the same ray: the control takes part of the optical
             * depth, so its standard error at equal count must be below plain's (0.69x here: the ramp
             * changes by a quarter of its range across a cell, so the controls are loose) */
            TestRng tr;
            VolumeRng rng = make_rng(&tr, 6);
            Acc plain = {0};
            for (int i = 0; i < 40000; ++i) {
                float T[3], nm;
                media_ratio_track(&v, o, d, 0.0f, 0.8f, &rng, T, &nm, NULL);
                acc_add(&plain, T[0]);
            }
            CHECK(acc_ok(&plain, ex), "ramp, plain ratio tracking: %g +- %g vs %g", acc_mean(&plain), acc_se(&plain), ex);
            CHECK(acc_se(&acc[0]) < 0.85 * acc_se(&plain), "residual ratio tracking's error %g not below 0.85 of plain's %g",
                  acc_se(&acc[0]), acc_se(&plain));
            printf("ramp axis-aligned: standard error residual %.5f, plain %.5f\n", acc_se(&acc[0]), acc_se(&plain));
        }
        /* oblique, inside the linear region: tau = scale x length x (mean y + 0.5) */
        {
            const float a[3] = {-0.3f, -0.4f, -0.2f}, b[3] = {0.35f, 0.45f, 0.3f};
            float d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
            double len = sqrt((double)d[0] * d[0] + (double)d[1] * d[1] + (double)d[2] * d[2]);
            normalize3(d);
            ratio_estimate(&v, a, d, 0.0f, (float)len, 40000, 6, acc, &st);
            double ex = exp(-scale * len * (0.5 * (a[1] + b[1]) + 0.5));
            CHECK(acc_ok(&acc[0], ex), "ramp, oblique: %g +- %g vs %g", acc_mean(&acc[0]), acc_se(&acc[0]), ex);
            printf("ramp oblique (closed form): %.4f +- %.4f, exact %.4f\n", acc_mean(&acc[0]), acc_se(&acc[0]), ex);
        }
        /* oblique through the whole grid, edges included: tau integrated numerically from the
         * dense values (midpoint rule, 200k steps, on the test's own trilinear field) */
        {
            const float o[3] = {-0.8f, -0.7f, -0.6f};
            float d[3] = {1.5f, 1.45f, 1.1f};
            normalize3(d);
            const double T = 2.5;
            double tau = 0.0;
            const int steps = 200000;
            for (int i = 0; i < steps; ++i) {
                double t = (i + 0.5) * T / steps, p[3];
                for (int k = 0; k < 3; ++k) p[k] = ((o[k] + t * d[k]) - off) * N;
                tau += dense_trilinear(vals, N, N, N, p);
            }
            tau *= scale * T / steps;
            ratio_estimate(&v, o, d, 0.0f, (float)T, 40000, 7, acc, &st);
            double ex = exp(-tau);
            CHECK(acc_ok(&acc[0], ex), "ramp, through: %g +- %g vs %g", acc_mean(&acc[0]), acc_se(&acc[0]), ex);
            printf("ramp oblique through the grid (numeric tau %.4f): %.4f +- %.4f, exact %.4f\n", tau,
                   acc_mean(&acc[0]), acc_se(&acc[0]), ex);
            Acc dl[3];
            desc.albedo[0] = desc.albedo[1] = desc.albedo[2] = 0.0f;
            Medium ma;
            CHECK(medium_init_vdb(&ma, &desc, err) == 0, "%s", err);
            MediaView va = {{&ma}, 1};
            delta_estimate(&va, o, d, 0.0f, (float)T, 40000, 8, dl, &st);
            CHECK(acc_ok(&dl[0], ex), "ramp, through, delta: %g +- %g vs %g", acc_mean(&dl[0]), acc_se(&dl[0]), ex);
            printf("  delta tracking: %.4f +- %.4f\n", acc_mean(&dl[0]), acc_se(&dl[0]));
            medium_free(&ma);
        }
        CHECK(st.capped_walks == 0, "capped walks");
        medium_free(&m);
        io_volume_grid_free(&g);
    }
    free(vals);

    /* medium_eval = the trilinear field of a random grid (leaf boundaries, the fast path and
     * the general path, the edges), against the reference interpolation */
    enum { NX = 37, NY = 29, NZ = 21 };
    float *rv = malloc(sizeof(float) * NX * NY * NZ);
    TestRng r = {1234};
    for (int i = 0; i < NX * NY * NZ; ++i) {
        double u = urand(&r);
        rv[i] = u < 0.2 ? 0.0f : u < 0.25 ? -1.0f : (float)(urand(&r) * 4.0);
    }
    float m16[16];
    scale_translate(m16, 0.05f, -1.0f, 0.25f, 3.0f);
    if (make_grid(rv, NX, NY, NZ, m16, "density", &g) == 0) {
        Medium m;
        VolumeDesc desc = grid_desc(&g, 2.0f, 0.5f);
        CHECK(medium_init_vdb(&m, &desc, err) == 0, "%s", err);
        double worst = 0.0;
        for (int i = 0; i < 200000; ++i) {
            double pi[3] = {urand(&r) * (NX + 4) - 2.5, urand(&r) * (NY + 4) - 2.5, urand(&r) * (NZ + 4) - 2.5};
            if (i < 1000) pi[0] = floor(pi[0]) + (i & 1 ? 0.0 : 0.999); /* corners and faces */
            float p[3] = {(float)(pi[0] * 0.05 - 1.0), (float)(pi[1] * 0.05 + 0.25), (float)(pi[2] * 0.05 + 3.0)};
            /* the reference at the index point the float world point maps to */
            double q[3] = {((double)p[0] + 1.0) / 0.05, ((double)p[1] - 0.25) / 0.05, ((double)p[2] - 3.0) / 0.05};
            double ref = 2.0 * dense_trilinear(rv, NX, NY, NZ, q);
            double got = sigma_t_at(&m, p);
            worst = fmax(worst, fabs(got - ref) / (1.0 + ref));
        }
        CHECK(worst < 1e-4, "medium_eval vs the trilinear reference: worst relative error %g", worst);
        printf("medium_eval vs reference trilinear: worst relative error %.2e\n", worst);
        medium_free(&m);
        io_volume_grid_free(&g);
    }
    free(rv);
}

/* ---------------------------------------------------------------- majorant */

static void random_rotation(TestRng *r, float R[9]) {
    double q[4], n = 0.0;
    for (int k = 0; k < 4; ++k) {
        q[k] = urand(r) * 2.0 - 1.0;
        n += q[k] * q[k];
    }
    n = sqrt(n);
    double w = q[0] / n, x = q[1] / n, y = q[2] / n, z = q[3] / n;
    double m[9] = {1 - 2 * (y * y + z * z), 2 * (x * y + w * z),     2 * (x * z - w * y),
                   2 * (x * y - w * z),     1 - 2 * (x * x + z * z), 2 * (y * z + w * x),
                   2 * (x * z + w * y),     2 * (y * z - w * x),     1 - 2 * (x * x + y * y)}; /* columns */
    for (int k = 0; k < 9; ++k) R[k] = (float)m[k];
}

/* index -> world: rotation x per-axis scale, translation */
static void random_transform(TestRng *r, float m[16], int rotate) {
    float R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    if (rotate) random_rotation(r, R);
    identity(m);
    for (int c = 0; c < 3; ++c) {
        float s = (float)(0.01 + 0.1 * urand(r));
        for (int k = 0; k < 3; ++k) m[c * 4 + k] = R[c * 3 + k] * s;
    }
    for (int k = 0; k < 3; ++k) m[12 + k] = (float)(urand(r) * 2.0 - 1.0);
}

static void test_majorant(void) {
    TestRng r = {4242};
    char err[IO_ERR_LEN] = "";
    long points = 0, nonzero = 0, violations = 0, tiling_errors = 0, rays = 0, segments = 0, empty_rays = 0;
    long control_errors = 0, controlled = 0, sparse_rays = 0;
    VolumeStats st = {0};
    /* pass 1: the same grids and rays over the sparse form (bricks; forced, for these small
     * grids the dense form would be chosen), emitting media excepted (always dense) */
    for (int pass = 0; pass < 2; ++pass)
    for (int trial = 0; trial < 24; ++trial) {
        if (trial == 0) r = (TestRng){4242};
        int nx = 3 + (int)(urand(&r) * 38), ny = 3 + (int)(urand(&r) * 38), nz = 3 + (int)(urand(&r) * 38);
        float *v = malloc(sizeof(float) * (size_t)nx * ny * nz);
        /* sparse blobs of random density with empty space around (so cells differ) */
        double cx = urand(&r) * nx, cy = urand(&r) * ny, cz = urand(&r) * nz, rad = 2.0 + urand(&r) * 20.0;
        for (int z = 0; z < nz; ++z)
            for (int y = 0; y < ny; ++y)
                for (int x = 0; x < nx; ++x) {
                    double dd = sqrt((x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz));
                    double u = urand(&r);
                    v[x + nx * (y + ny * z)] = dd < rad ? (float)(u * u * 5.0) : u < 0.02 ? (float)(u * 100.0) : 0.0f;
                    /* every fourth grid dense (a fog, as the mist): cells with a control > 0 */
                    if (trial % 4 == 2) v[x + nx * (y + ny * z)] = (float)(1.0 + u);
                }
        v[0] = 1.0f; /* never all zero */
        float i2w[16];
        random_transform(&r, i2w, trial % 4 != 0);
        IoVolumeGrid g, ge;
        if (make_grid(v, nx, ny, nz, i2w, "density", &g) != 0) {
            free(v);
            continue;
        }
        VolumeDesc desc = grid_desc(&g, (float)(0.1 + 10.0 * urand(&r)), (float)urand(&r));
        int emissive = trial % 3 == 1;
        if (emissive) {
            /* an emission grid of another resolution and placement (the aux mapping) */
            float *e = malloc(sizeof(float) * 9 * 9 * 9);
            for (int i = 0; i < 729; ++i) e[i] = (float)(urand(&r) * 3.0);
            float ei2w[16];
            random_transform(&r, ei2w, 1);
            make_grid(e, 9, 9, 9, ei2w, "emission", &ge);
            free(e);
            desc.emission = &ge;
            desc.emission_scale = (float)(urand(&r) * 50.0);
            desc.emission_color[1] = 0.5f;
        }
        if (pass == 1) desc.dense_cells_max = 1;
        Medium m;
        int rc = medium_init_vdb(&m, &desc, err);
        CHECK(rc == 0, "random grid %d: %s", trial, err);
        if (rc == 0 && pass == 1)
            CHECK(m.majorant.bricks.entries != NULL && m.majorant.sigma_maj == NULL, "grid %d: the sparse form not built%s",
                  trial, emissive ? " (emitting)" : "");
        if (rc == 0) {
            if (pass == 1) sparse_rays += 400;
            for (int ray = 0; ray < 400; ++ray) {
                float o[3], d[3];
                for (int k = 0; k < 3; ++k) {
                    float c = 0.5f * (m.world_min[k] + m.world_max[k]), h = 0.5f * (m.world_max[k] - m.world_min[k]);
                    o[k] = c + (float)(urand(&r) * 3.0 - 1.5) * h;
                    d[k] = (float)(urand(&r) * 2.0 - 1.0);
                }
                if (ray % 5 == 0) d[ray % 3] = d[(ray + 1) % 3] = 0.0f; /* axis-parallel */
                if (ray % 7 == 0) d[ray % 3] = 0.0f;
                if (d[0] == 0.0f && d[1] == 0.0f && d[2] == 0.0f) d[2] = 1.0f;
                float s = (float)(0.1 + 10.0 * urand(&r)); /* d not unit */
                for (int k = 0; k < 3; ++k) d[k] *= s;
                float tmin = ray % 3 == 0 ? -INFINITY : (float)(urand(&r) * 0.5);
                float tmax = ray % 4 == 0 ? INFINITY : (float)(urand(&r) * 4.0);
                float c0, c1;
                int hit = medium_clip_ray(&m, o, d, tmin, tmax, &c0, &c1);
                MajorantIterator it;
                medium_majorant_begin(&m, o, d, tmin, tmax, &it);
                float t0, t1, maj, prev = 0.0f;
                int n = 0;
                ++rays;
                while (medium_majorant_next(&it, &t0, &t1, &maj)) {
                    if (n == 0 ? t0 != c0 : t0 != prev) ++tiling_errors;
                    if (!(t1 > t0) || !(maj >= 0.0f) || !isfinite(maj)) ++tiling_errors;
                    prev = t1;
                    ++n;
                    for (int j = 0; j < 16; ++j) {
                        float t = j == 0 ? t0 : j == 1 ? t1 : t0 + (float)urand(&r) * (t1 - t0);
                        float p[3] = {o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]};
                        float sig = sigma_t_at(&m, p);
                        ++points;
                        nonzero += sig > 0.0f;
                        if (sig > maj) {
                            if (violations < 5)
                                fprintf(stderr, "  violation: grid %d ray %d t %g in [%g, %g]: sigma_t %g > %g\n", trial,
                                        ray, t, t0, t1, sig, maj);
                            ++violations;
                        }
                    }
                    if (n > 100000) break;
                }
                segments += n;
                if (!hit) {
                    empty_rays += 1;
                    if (n != 0) ++tiling_errors;
                } else if (n == 0 || prev != c1) {
                    ++tiling_errors;
                }
                /* the control segments (residual ratio tracking): the same tiling, and
                 * ctl <= sigma_t <= maj at every point; an emitting medium has no control */
                medium_majorant_begin_control(&m, o, d, tmin, tmax, &it);
                float ctl;
                int nc = 0;
                prev = 0.0f;
                while (medium_majorant_next_control(&it, &t0, &t1, &maj, &ctl)) {
                    if (nc == 0 ? t0 != c0 : t0 != prev) ++tiling_errors;
                    if (!(ctl >= 0.0f) || !(ctl <= maj) || (emissive && ctl != 0.0f)) ++control_errors;
                    prev = t1;
                    controlled += ctl > 0.0f;
                    for (int j = 0; j < 8; ++j) {
                        float t = t0 + (float)urand(&r) * (t1 - t0);
                        float p[3] = {o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]};
                        float sig = sigma_t_at(&m, p);
                        if (sig < ctl || sig > maj) {
                            if (control_errors < 5)
                                fprintf(stderr, "  control violation: grid %d ray %d t %g: sigma_t %g not in [%g, %g]\n",
                                        trial, ray, t, sig, ctl, maj);
                            ++control_errors;
                        }
                    }
                    if (++nc > 100000) break;
                }
                if (hit && (nc < n || prev != c1)) ++tiling_errors;
                /* the trackers over the same ray terminate */
                if (ray % 8 == 0) {
                    MediaView view = {{&m}, 1};
                    float dn[3] = {d[0], d[1], d[2]}, T[3];
                    normalize3(dn);
                    TestRng rr;
                    VolumeRng rng = make_rng(&rr, (uint64_t)ray);
                    media_transmittance(&view, o, dn, 0.0f, 3.0f, &rng, T, &st);
                    VolumeEvent ev;
                    media_sample_event(&view, o, dn, 0.0f, 3.0f, NULL, &rng, &ev, &st);
                    CHECK(isfinite(T[0]) && T[0] >= 0.0f && isfinite(ev.weight[0]) && isfinite(ev.emitted[0]),
                          "tracker output not finite");
                }
            }
            medium_free(&m);
        }
        if (emissive) io_volume_grid_free(&ge);
        io_volume_grid_free(&g);
        free(v);
    }
    printf("majorant: %ld rays (%ld miss), %ld segments, %ld points (%ld with sigma_t > 0): %ld violations, %ld tiling "
           "errors\n",
           rays, empty_rays, segments, points, nonzero, violations, tiling_errors);
    CHECK(violations == 0, "%ld points above their segment's majorant", violations);
    CHECK(control_errors == 0, "%ld points below their segment's control (or a control above the majorant)",
          control_errors);
    CHECK(controlled > 0, "no control segment with sigma_c > 0: residual ratio tracking untested");
    printf("majorant: %ld control segments with sigma_c > 0, %ld rays over the sparse form\n", controlled, sparse_rays);
    CHECK(sparse_rays > 0, "no ray over the sparse form");
    CHECK(tiling_errors == 0, "%ld tiling errors (segments must tile the clipped interval)", tiling_errors);
    CHECK(nonzero > points / 20, "too few points inside the media (%ld of %ld)", nonzero, points);
    CHECK(st.capped_walks == 0, "capped walks %llu", (unsigned long long)st.capped_walks);

    /* NaN input and empty intervals: no segment */
    enum { N = 4 };
    float v[N * N * N];
    for (int i = 0; i < N * N * N; ++i) v[i] = 1.0f;
    float i2w[16];
    scale_translate(i2w, 0.25f, 0.0f, 0.0f, 0.0f);
    IoVolumeGrid g;
    if (make_grid(v, N, N, N, i2w, "density", &g) == 0) {
        Medium m;
        VolumeDesc desc = grid_desc(&g, 1.0f, 0.5f);
        CHECK(medium_init_vdb(&m, &desc, err) == 0, "%s", err);
        const float good_o[3] = {-1.0f, 0.5f, 0.5f}, good_d[3] = {1.0f, 0.0f, 0.0f};
        const float nan_o[3] = {NAN, 0.5f, 0.5f}, nan_d[3] = {1.0f, NAN, 0.0f}, far_o[3] = {-1.0f, 5.0f, 0.5f};
        const float zero_d[3] = {0.0f, 0.0f, 0.0f}, inside_o[3] = {0.5f, 0.5f, 0.5f};
        struct { const float *o, *d; float tmin, tmax; int expect; const char *what; } cases[] = {
            {good_o, good_d, 0.0f, 10.0f, 1, "a ray through"},
            {nan_o, good_d, 0.0f, 10.0f, 0, "NaN origin"},
            {good_o, nan_d, 0.0f, 10.0f, 0, "NaN direction"},
            {good_o, good_d, NAN, 10.0f, 0, "NaN tmin"},
            {good_o, good_d, 0.0f, NAN, 0, "NaN tmax"},
            {good_o, good_d, 5.0f, 1.0f, 0, "tmin > tmax"},
            {good_o, good_d, 0.0f, 0.5f, 0, "ends before the grid"},
            {far_o, good_d, 0.0f, 10.0f, 0, "misses"},
            {good_o, good_d, 0.0f, INFINITY, 1, "infinite tmax"},
            {inside_o, zero_d, 0.0f, 1.0f, 1, "zero direction inside"},
            {good_o, zero_d, 0.0f, 1.0f, 0, "zero direction outside"},
        };
        for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
            MajorantIterator it;
            medium_majorant_begin(&m, cases[i].o, cases[i].d, cases[i].tmin, cases[i].tmax, &it);
            float t0, t1, maj;
            int n = 0;
            while (medium_majorant_next(&it, &t0, &t1, &maj) && n < 1000) ++n;
            CHECK((n > 0) == cases[i].expect, "%s: %d segments", cases[i].what, n);
        }
        /* a far origin (t ~ 2e4): the same transmittance as from near by (tau = 1:
         * 4 voxels of density 1 across, 0.25 m each, ramps included) */
        {
            MediaView view = {{&m}, 1};
            const float near_o[3] = {-1.0f, 0.5f, 0.5f}, far_o[3] = {-2e4f, 0.5f, 0.5f};
            Acc an[3], af[3];
            VolumeStats st2 = {0};
            ratio_estimate(&view, near_o, good_d, 0.0f, INFINITY, 20000, 61, an, &st2);
            ratio_estimate(&view, far_o, good_d, 0.0f, INFINITY, 20000, 62, af, &st2);
            CHECK(acc_ok(&an[0], exp(-1.0)) && acc_ok(&af[0], exp(-1.0)), "far origin: T %g +- %g, near %g +- %g, exact %g",
                  acc_mean(&af[0]), acc_se(&af[0]), acc_mean(&an[0]), acc_se(&an[0]), exp(-1.0));
            printf("far origin (t ~ 2e4): T %.4f +- %.4f, near %.4f +- %.4f, exact %.4f\n", acc_mean(&af[0]),
                   acc_se(&af[0]), acc_mean(&an[0]), acc_se(&an[0]), exp(-1.0));
        }
        /* the trackers on NaN rays return at once */
        MediaView view = {{&m}, 1};
        TestRng rr;
        VolumeRng rng = make_rng(&rr, 5);
        float T[3];
        VolumeEvent ev;
        media_transmittance(&view, nan_o, good_d, 0.0f, 10.0f, &rng, T, NULL);
        CHECK(T[0] == 1.0f, "NaN ray transmittance %g", T[0]);
        media_sample_event(&view, good_o, nan_d, 0.0f, 10.0f, NULL, &rng, &ev, NULL);
        CHECK(ev.type == VOLUME_EVENT_PASSED && ev.weight[0] == 1.0f, "NaN ray event %d", ev.type);
        medium_free(&m);
        io_volume_grid_free(&g);
    }
}

/* ---------------------------------------------------------------- emission */

static void test_emission(void) {
    enum { N = 32 };
    float *vals = malloc(sizeof(float) * N * N * N), *temp = malloc(sizeof(float) * N * N * N);
    for (int i = 0; i < N * N * N; ++i) {
        vals[i] = 1.0f;
        temp[i] = 3000.0f;
    }
    float i2w[16];
    scale_translate(i2w, 1.0f / N, 0.0f, 0.0f, 0.0f);
    IoVolumeGrid g, gt;
    char err[IO_ERR_LEN] = "";
    if (make_grid(vals, N, N, N, i2w, "density", &g) || make_grid(temp, N, N, N, i2w, "temperature", &gt)) {
        free(vals);
        free(temp);
        return;
    }
    const float o[3] = {0.1f, 0.45f, 0.55f};
    float d[3] = {1.0f, 0.2f, 0.1f};
    normalize3(d);
    const float sigma = 2.0f;
    float bb[3];
    blackbody_rgb(3000.0f, bb);
    /* an emission grid of its own resolution and placement: 16^3 voxels of 1/16 m over
     * the same box, constant 1 */
    enum { NE = 16 };
    float *evals = malloc(sizeof(float) * NE * NE * NE), ei2w[16];
    for (int i = 0; i < NE * NE * NE; ++i) evals[i] = 1.0f;
    scale_translate(ei2w, 1.0f / NE, 0.0f, 0.0f, 0.0f);
    IoVolumeGrid ge;
    int have_ge = make_grid(evals, NE, NE, NE, ei2w, "emission", &ge) == 0;
    free(evals);
    for (int variant = 0; variant < 4; ++variant) {
        /* 0: emission grid, pure absorber; 1: temperature grid, pure absorber; 2: emission
         * grid, albedo 0.5 (scattering ends the walk too); 3: 0 with the coarser emission grid */
        if (variant == 3 && !have_ge) break;
        VolumeDesc desc = grid_desc(&g, sigma, variant == 2 ? 0.5f : 0.0f);
        desc.emission_scale = 5.0f;
        const float color[3] = {1.0f, 0.5f, 0.25f};
        if (variant == 1) {
            desc.temperature = &gt;
        } else {
            desc.emission = variant == 3 ? &ge : &g; /* constant 1 */
            memcpy(desc.emission_color, color, sizeof color);
        }
        Medium m;
        CHECK(medium_init_vdb(&m, &desc, err) == 0, "%s", err);
        CHECK(m.emissive, "variant %d not emissive", variant);
        MediaView v = {{&m}, 1};
        float le[3];
        for (int k = 0; k < 3; ++k) le[k] = 5.0f * (variant == 1 ? bb[k] : color[k]);
        MediumCoefficients c;
        float p[3] = {0.5f, 0.5f, 0.5f};
        medium_eval(&m, p, &c);
        CHECK(fabsf(c.emission[0] - le[0]) < 1e-3f * le[0] && fabsf(c.emission[2] - le[2]) < 1e-3f * le[2],
              "L_e (%g %g %g) vs (%g %g %g)", c.emission[0], c.emission[1], c.emission[2], le[0], le[1], le[2]);
        /* the majorant carries the emission term (lum(sigma_a L_e) > sigma_t here) */
        MajorantIterator it;
        medium_majorant_begin(&m, o, d, 0.0f, 0.5f, &it);
        float t0, t1, maj;
        medium_majorant_next(&it, &t0, &t1, &maj);
        float sa = sigma * (1.0f - desc.albedo[0]);
        float lum = 0.2126f * sa * le[0] + 0.7152f * sa * le[1] + 0.0722f * sa * le[2];
        CHECK(maj >= fminf(lum, (float)N) && maj <= 1.001f * fmaxf(sigma, fminf(lum, (float)N)),
              "emission majorant %g (sigma_t %g, lum(sigma_a L_e) %g)", maj, sigma, lum);
        const double dist[2] = {0.2, 0.6};
        for (int i = 0; i < 2; ++i) {
            Acc acc[3];
            memset(acc, 0, sizeof acc);
            TestRng r;
            VolumeRng rng = make_rng(&r, 500 + 10 * variant + i);
            VolumeStats st = {0};
            for (int s = 0; s < 40000; ++s) {
                VolumeEvent ev;
                media_sample_event(&v, o, d, 0.0f, (float)dist[i], NULL, &rng, &ev, &st);
                for (int k = 0; k < 3; ++k) acc_add(&acc[k], ev.emitted[k]);
            }
            for (int k = 0; k < 3; ++k) {
                double ex = le[k] * (double)sa / sigma * (1.0 - exp(-sigma * dist[i]));
                CHECK(acc_ok(&acc[k], ex), "emission variant %d d %g ch %d: %g +- %g vs %g", variant, dist[i], k,
                      acc_mean(&acc[k]), acc_se(&acc[k]), ex);
            }
            printf("emission %s d %.1f: (%.4f %.4f %.4f) +- (%.4f %.4f %.4f), exact (%.4f %.4f %.4f); %.1f "
                   "collisions per walk\n",
                   variant == 0   ? "grid absorber"
                   : variant == 1 ? "blackbody absorber"
                   : variant == 2 ? "grid albedo 0.5"
                                  : "coarser emission grid",
                   dist[i],
                   acc_mean(&acc[0]), acc_mean(&acc[1]), acc_mean(&acc[2]), acc_se(&acc[0]), acc_se(&acc[1]),
                   acc_se(&acc[2]), le[0] * sa / sigma * (1.0 - exp(-sigma * dist[i])),
                   le[1] * sa / sigma * (1.0 - exp(-sigma * dist[i])), le[2] * sa / sigma * (1.0 - exp(-sigma * dist[i])),
                   (double)st.collisions / 40000.0);
        }
        medium_free(&m);
    }
    io_volume_grid_free(&g);
    io_volume_grid_free(&gt);
    if (have_ge) io_volume_grid_free(&ge);
    free(vals);
    free(temp);
}

/* ---------------------------------------------------------------- emission sampling (§4.3) */

/* A direction from equal-area coordinates: z = cos(theta) in [-1, 1], phi in [0, 2 pi). */
static void eq_dir(double z, double phi, float d[3]) {
    double r = sqrt(fmax(0.0, 1.0 - z * z));
    d[0] = (float)(r * cos(phi));
    d[1] = (float)(r * sin(phi));
    d[2] = (float)z;
}

/* The integral of medium_emission_pdf over the sphere by the midpoint rule on an equal-area
 * grid (nz x nphi cells of solid angle 4 pi / (nz nphi)). */
static double pdf_sphere_integral(const Medium *m, const float o[3], int nz, int nphi) {
    double sum = 0.0;
    for (int i = 0; i < nz; ++i) {
        double z = -1.0 + 2.0 * (i + 0.5) / nz;
        for (int j = 0; j < nphi; ++j) {
            float d[3];
            eq_dir(z, 2.0 * PI_D * (j + 0.5) / nphi, d);
            sum += medium_emission_pdf(m, o, d);
        }
    }
    return sum * 4.0 * PI_D / ((double)nz * nphi);
}

/* The emitting test media: a smooth blob of density with an emission grid of another pattern
 * (0: axis-aligned, 1: rotated with anisotropic voxels, 3: axis-aligned with an emission grid
 * of half the resolution, i.e. another index space), and 2: a temperature grid with a hot spot
 * in a constant density. */
enum { ES_NX = 20, ES_NY = 12, ES_NZ = 16, ES_NT = 24 };
static int emission_test_medium(int which, Medium *m, IoVolumeGrid *g, IoVolumeGrid *ge, uint64_t dense_cells_max) {
    char err[IO_ERR_LEN] = "";
    if (which == 4) {
        /* tiles: a 512^3 emitting box (4^3 upper-node tiles of density and emission) with voxels
         * of detail: in the sparse form its inner bricks are uniform emitting bricks (one entry of
         * the energy CDF each, crossed at once by the pdf's DDA), the others hold their cells */
        float i2w4[16];
        scale_translate(i2w4, 1.0f / 512.0f, -0.5f, -0.5f, -0.5f);
        const int32_t box[6] = {0, 0, 0, 511, 511, 511};
        const float dbox = 1.5f, ebox = 2.0f;
        const int32_t hot[3 * 3] = {100, 200, 300, 256, 256, 256, 500, 10, 400};
        const float hd[3] = {6.0f, 0.5f, 3.0f}, he[3] = {9.0f, 0.0f, 4.0f};
        int rc4 = io_volume_grid_from_voxels(hot, hd, 3, box, &dbox, 1, i2w4, "density", g, err);
        if (rc4 == 0 && (rc4 = io_volume_grid_from_voxels(hot, he, 3, box, &ebox, 1, i2w4, "emission", ge, err)) != 0)
            io_volume_grid_free(g);
        CHECK(rc4 == 0, "emission medium 4: %s", err);
        if (rc4) return -1;
        VolumeDesc desc = grid_desc(g, 2.0f, 0.3f);
        desc.dense_cells_max = dense_cells_max;
        desc.emission = ge;
        desc.emission_scale = 3.0f;
        rc4 = medium_init_vdb(m, &desc, err);
        CHECK(rc4 == 0, "emission medium 4: %s", err);
        if (rc4) {
            io_volume_grid_free(g);
            io_volume_grid_free(ge);
            return -1;
        }
        if (dense_cells_max)
            CHECK(m->majorant.nubricks > 0, "emission medium 4: %d uniform emitting bricks", m->majorant.nubricks);
        return 0;
    }
    int nx = which == 2 ? ES_NT : ES_NX, ny = which == 2 ? ES_NT : ES_NY, nz = which == 2 ? ES_NT : ES_NZ;
    size_t n = (size_t)nx * ny * nz;
    float *dv = malloc(sizeof(float) * n), *ev = malloc(sizeof(float) * n), i2w[16];
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y)
            for (int x = 0; x < nx; ++x) {
                size_t i = (size_t)x + (size_t)nx * ((size_t)y + (size_t)ny * (size_t)z);
                if (which == 2) {
                    double r2 = (x - 16.0) * (x - 16.0) + (y - 8.0) * (y - 8.0) + (z - 12.0) * (z - 12.0);
                    dv[i] = 1.0f;
                    ev[i] = r2 < 30.0 ? (float)(3500.0 - 60.0 * r2) : 300.0f; /* kelvin */
                } else {
                    double bx = (x - 9.0) / 7.0, by = (y - 6.0) / 5.0, bz = (z - 7.0) / 6.0;
                    double b = 1.0 - (bx * bx + by * by + bz * bz);
                    dv[i] = b > 0.0 ? (float)(0.2 + 3.0 * b) : 0.0f;
                    ev[i] = (x + 2 * y + 3 * z) % 7 == 0 ? 4.0f : x > 12 ? 1.0f : 0.0f;
                }
            }
    if (which == 1) {
        TestRng r = {77};
        random_transform(&r, i2w, 1);
    } else {
        scale_translate(i2w, 0.05f, -0.5f, -0.3f, -0.4f);
    }
    int rc = make_grid(dv, nx, ny, nz, i2w, "density", g);
    if (rc == 0 && which == 3) { /* half resolution: voxel (x, y, z) of the emission grid is ev's (2x, 2y, 2z) */
        float ei2w[16];
        scale_translate(ei2w, 0.1f, -0.5f, -0.3f, -0.4f);
        for (int z = 0; z < nz / 2; ++z)
            for (int y = 0; y < ny / 2; ++y)
                for (int x = 0; x < nx / 2; ++x)
                    ev[x + (nx / 2) * (y + (ny / 2) * z)] = ev[2 * x + nx * (2 * y + ny * 2 * z)];
        if ((rc = make_grid(ev, nx / 2, ny / 2, nz / 2, ei2w, "emission", ge)) != 0) io_volume_grid_free(g);
    } else if (rc == 0 && (rc = make_grid(ev, nx, ny, nz, i2w, which == 2 ? "temperature" : "emission", ge)) != 0) {
        io_volume_grid_free(g);
    }
    free(dv);
    free(ev);
    if (rc) return -1;
    VolumeDesc desc = grid_desc(g, 2.0f, 0.3f);
    desc.dense_cells_max = dense_cells_max;
    desc.emission_scale = 3.0f;
    const float color[3] = {1.0f, 0.6f, 0.3f};
    if (which == 2) {
        desc.temperature = ge;
    } else {
        desc.emission = ge;
        memcpy(desc.emission_color, color, sizeof color);
    }
    rc = medium_init_vdb(m, &desc, err);
    CHECK(rc == 0, "emission medium %d: %s", which, err);
    if (rc) {
        io_volume_grid_free(g);
        io_volume_grid_free(ge);
    }
    return rc;
}

static void test_emission_sampling(void) {
    char err[IO_ERR_LEN] = "";
    /* media that do not emit */
    {
        Medium h;
        const float sa[3] = {1, 1, 1}, ss[3] = {1, 1, 1}, o[3] = {0, 0, 0}, d[3] = {0, 0, 1};
        float p[3], c[3];
        CHECK(medium_init_homogeneous(&h, sa, ss, 0.0f, err) == 0, "%s", err);
        medium_emission_centroid(&h, c);
        CHECK(medium_emission_power(&h) == 0.0f && medium_emission_sample(&h, 0.5f, 0.5f, 0.5f, 0.5f, p) == 0.0f &&
                  medium_emission_pdf(&h, o, d) == 0.0f && c[0] == 0.0f,
              "a homogeneous medium emits");
        enum { N = 8 };
        float vals[N * N * N], i2w[16];
        for (int i = 0; i < N * N * N; ++i) vals[i] = 1.0f;
        scale_translate(i2w, 0.1f, 0.0f, 0.0f, 0.0f);
        IoVolumeGrid g;
        if (make_grid(vals, N, N, N, i2w, "density", &g) == 0) {
            VolumeDesc desc = grid_desc(&g, 1.0f, 0.0f);
            Medium m;
            CHECK(medium_init_vdb(&m, &desc, err) == 0, "%s", err);
            CHECK(medium_emission_power(&m) == 0.0f && medium_emission_sample(&m, 0.5f, 0.5f, 0.5f, 0.5f, p) == 0.0f &&
                      medium_emission_pdf(&m, o, d) == 0.0f,
                  "a grid without emission emits");
            medium_free(&m);
            /* a constant emitting absorber: the power is sigma_a L_e x volume (voxel centres) up
             * to the floors of the border cells (< 0.1 %), the centroid the voxels' centre */
            desc.emission = &g;
            desc.emission_scale = 2.0f;
            CHECK(medium_init_vdb(&m, &desc, err) == 0, "%s", err);
            double expect = 1.0 * 2.0 * 1.0 * (N * 0.1) * (N * 0.1) * (N * 0.1);
            medium_emission_centroid(&m, c);
            CHECK(fabs(medium_emission_power(&m) - expect) < 1e-3 * expect, "power %g vs %g",
                  (double)medium_emission_power(&m), expect);
            CHECK(fabsf(c[0] - 0.35f) < 1e-3f && fabsf(c[1] - 0.35f) < 1e-3f && fabsf(c[2] - 0.35f) < 1e-3f,
                  "centroid (%g %g %g) vs 0.35", c[0], c[1], c[2]);
            printf("emission power of a constant absorber %.5f (exact %.5f), centroid (%.4f %.4f %.4f) vs 0.35\n",
                   (double)medium_emission_power(&m), expect, c[0], c[1], c[2]);
            medium_free(&m);
            io_volume_grid_free(&g);
        }
    }
    /* each medium in the dense form, then in the sparse form (forced: the emission-energy grid
     * over the bricks' slots, the pdf's DDA crossing empty blocks at once) */
    for (int pass = 0; pass < 10; ++pass) {
        const int which = pass % 5, sparse = pass >= 5;
        Medium m;
        IoVolumeGrid g, ge;
        if (emission_test_medium(which, &m, &g, &ge, sparse ? 1 : 0)) continue;
        CHECK((m.majorant.bricks.entries != NULL) == sparse, "emission medium %d: the %s form not built", which,
              sparse ? "sparse" : "dense");
        float cen[3];
        medium_emission_centroid(&m, cen);
        CHECK(medium_emission_power(&m) > 0.0f, "medium %d does not emit", which);
        if (which == 0) { /* bad input: never a NaN, a point outside or a hang */
            const float nan3[3] = {NAN, 0.0f, 0.0f}, inf3[3] = {0.0f, INFINITY, 0.0f}, dz[3] = {0.0f, 0.0f, 1.0f};
            CHECK(medium_emission_pdf(&m, nan3, dz) == 0.0f && medium_emission_pdf(&m, cen, nan3) == 0.0f &&
                      medium_emission_pdf(&m, inf3, dz) == 0.0f,
                  "pdf of a non-finite ray");
            const float us[4][4] = {{1.0f, 1.0f, 1.0f, 1.0f}, {-1.0f, -0.5f, 2.0f, 0.0f}, {NAN, NAN, NAN, NAN},
                                    {0.0f, 0.0f, 0.0f, 0.0f}};
            for (int i = 0; i < 4; ++i) {
                float p[3];
                float pv = medium_emission_sample(&m, us[i][0], us[i][1], us[i][2], us[i][3], p);
                CHECK(pv > 0.0f && isfinite(pv) && p[0] >= m.world_min[0] && p[0] <= m.world_max[0] &&
                          p[1] >= m.world_min[1] && p[1] <= m.world_max[1] && p[2] >= m.world_min[2] &&
                          p[2] <= m.world_max[2],
                      "sample for u set %d: pdf %g at (%g %g %g)", i, pv, p[0], p[1], p[2]);
            }
            MediaView v = {{&m}, 1};
            TestRng r;
            VolumeRng rng = make_rng(&r, 5);
            float L[3];
            media_emission_line(&v, 0, cen, dz, NAN, 1.0f, &rng, L, NULL);
            CHECK(L[0] == 0.0f && L[1] == 0.0f && L[2] == 0.0f, "line over a NaN interval");
            media_emission_line(&v, 0, nan3, dz, 0.0f, 1.0f, &rng, L, NULL);
            CHECK(L[0] == 0.0f && L[1] == 0.0f && L[2] == 0.0f, "line from a NaN origin");
            media_emission_line(&v, -1, cen, dz, 0.0f, 1.0f, &rng, L, NULL);
            CHECK(L[0] == 0.0f && L[1] == 0.0f && L[2] == 0.0f, "line of emitter -1");
        }
        float ext[3];
        for (int k = 0; k < 3; ++k) ext[k] = m.world_max[k] - m.world_min[k];
        float ext_max = fmaxf(ext[0], fmaxf(ext[1], ext[2]));
        /* origins: the centroid, near a corner inside, and two outside (beyond the volume's
         * slab on every axis: an origin level with a face sees that face edge-on, a support
         * edge in a sliver of directions thinner than the chi-square's quadrature resolves) */
        float origins[4][3];
        for (int k = 0; k < 3; ++k) {
            origins[0][k] = cen[k];
            origins[1][k] = m.world_min[k] + 0.15f * ext[k];
            origins[2][k] = cen[k] + (k == 0 ? 1.5f : k == 1 ? 0.7f : 0.9f) * ext_max;
            origins[3][k] = m.world_min[k] - (k == 1 ? 0.7f : 0.3f) * ext_max;
        }
        for (int oi = 0; oi < 4; ++oi) {
            double integral = pdf_sphere_integral(&m, origins[oi], 500, 1000);
            CHECK(fabs(integral - 1.0) < 3e-3, "medium %d origin %d: pdf integrates to %.6f", which, oi, integral);
            printf("emission pdf medium %d%s origin %d (%s): integral over the sphere %.6f\n", which, sparse ? " (sparse)" : "",
                   oi, oi < 2 ? "inside" : "outside", integral);
        }
        /* the directions of sampled points against the pdf (chi-square), and the returned
         * volume pdf against the cell's P_v / V_v being positive and the point in the bounds */
        for (int oi = 0; oi < 4; oi += 2) {
            enum { BZ = 24, BP = 48, SUB = 16, NS = 200000 };
            static double obs[BZ * BP], expv[BZ * BP];
            memset(obs, 0, sizeof obs);
            const float *o = origins[oi];
            TestRng r = {9000u + 10u * (uint64_t)which + (uint64_t)oi};
            long outside = 0, zero_pdf = 0;
            for (int s = 0; s < NS; ++s) {
                float p[3];
                float pv = medium_emission_sample(&m, (float)urand(&r), (float)urand(&r), (float)urand(&r),
                                                  (float)urand(&r), p);
                if (!(pv > 0.0f)) ++zero_pdf;
                for (int k = 0; k < 3; ++k)
                    if (!(p[k] >= m.world_min[k] - 1e-5f * ext_max && p[k] <= m.world_max[k] + 1e-5f * ext_max))
                        ++outside;
                float d[3] = {p[0] - o[0], p[1] - o[1], p[2] - o[2]};
                normalize3(d);
                double phi = atan2(d[1], d[0]);
                if (phi < 0.0) phi += 2.0 * PI_D;
                int bz = (int)((d[2] + 1.0) * 0.5 * BZ), bp = (int)(phi / (2.0 * PI_D) * BP);
                bz = bz < 0 ? 0 : bz >= BZ ? BZ - 1 : bz;
                bp = bp < 0 ? 0 : bp >= BP ? BP - 1 : bp;
                obs[bz * BP + bp] += 1.0;
            }
            CHECK(outside == 0 && zero_pdf == 0, "medium %d: %ld samples outside, %ld with pdf 0", which, outside,
                  zero_pdf);
            double tot = 0.0;
            for (int bz = 0; bz < BZ; ++bz)
                for (int bp = 0; bp < BP; ++bp) {
                    double e = 0.0;
                    for (int i = 0; i < SUB; ++i)
                        for (int j = 0; j < SUB; ++j) {
                            float d[3];
                            eq_dir(-1.0 + 2.0 * (bz + (i + 0.5) / SUB) / BZ, 2.0 * PI_D * (bp + (j + 0.5) / SUB) / BP, d);
                            e += medium_emission_pdf(&m, o, d);
                        }
                    expv[bz * BP + bp] = e * 4.0 * PI_D / ((double)BZ * BP * SUB * SUB) * NS;
                    tot += expv[bz * BP + bp];
                }
            int dof;
            double stat, pval = chi2_pvalue(obs, expv, BZ * BP, &dof, &stat);
            CHECK(pval > 1e-4, "medium %d origin %d: sampled directions vs pdf, chi2 %g dof %d p %g", which, oi, stat,
                  dof, pval);
            printf("emission sampling medium %d%s origin %d: chi2 %.1f dof %d p %.4f (expected total %.4f of %d)\n", which,
                   sparse ? " (sparse)" : "", oi, stat, dof, pval, tot / NS, NS);
        }
        medium_free(&m);
        io_volume_grid_free(&g);
        io_volume_grid_free(&ge);
    }
}

/* Emission-optimised tracking (media_emission_line, §4.3 Algorithm 1): against the closed
 * form L_e sigma_a / sigma_t,all (1 - exp(-sigma_t,all d)) for a constant emitting grid alone
 * and inside a chromatic homogeneous absorber (the emitter second in the view); against the
 * emission media_sample_event gathers on a heterogeneous grid, and emitted_by's split of it
 * between two emitting media of one view (same means within 5 standard errors). */
static void test_emission_line(void) {
    char err[IO_ERR_LEN] = "";
    enum { N = 32, NS = 40000 };
    float *vals = malloc(sizeof(float) * N * N * N), i2w[16];
    for (int i = 0; i < N * N * N; ++i) vals[i] = 1.0f;
    scale_translate(i2w, 1.0f / N, 0.0f, 0.0f, 0.0f);
    IoVolumeGrid g;
    if (make_grid(vals, N, N, N, i2w, "density", &g)) {
        free(vals);
        return;
    }
    free(vals);
    const float o[3] = {0.1f, 0.45f, 0.55f};
    float d[3] = {1.0f, 0.2f, 0.1f};
    normalize3(d);
    const float sigma = 2.0f, color[3] = {1.0f, 0.5f, 0.25f};
    const float hom_sa[3] = {0.5f, 1.0f, 2.0f}, hom_ss[3] = {0.0f, 0.0f, 0.0f};
    Medium hom;
    CHECK(medium_init_homogeneous(&hom, hom_sa, hom_ss, 0.0f, err) == 0, "%s", err);
    for (int variant = 0; variant < 3; ++variant) {
        /* 0: pure absorber; 1: albedo 0.5; 2: pure absorber inside the homogeneous absorber */
        VolumeDesc desc = grid_desc(&g, sigma, variant == 1 ? 0.5f : 0.0f);
        desc.emission = &g;
        desc.emission_scale = 5.0f;
        memcpy(desc.emission_color, color, sizeof color);
        Medium m;
        if (medium_init_vdb(&m, &desc, err)) {
            CHECK(0, "%s", err);
            continue;
        }
        MediaView v = {{&m}, 1};
        int emitter = 0;
        if (variant == 2) {
            v.media[0] = &hom;
            v.media[1] = &m;
            v.count = 2;
            emitter = 1;
        }
        float sa = sigma * (1.0f - desc.albedo[0]);
        const double dist[2] = {0.2, 0.6};
        uint64_t collisions[2][2] = {{0}}; /* [density][distance] */
        for (int density = 0; density < 2; ++density)
        for (int i = 0; i < 2; ++i) {
            Acc acc[3];
            memset(acc, 0, sizeof acc);
            TestRng r;
            VolumeRng rng = make_rng(&r, 700 + 10 * variant + i + 100 * density);
            VolumeStats st = {0};
            for (int s = 0; s < NS; ++s) {
                float L[3];
                if (density == 0)
                    media_emission_line(&v, emitter, o, d, 0.0f, (float)dist[i], &rng, L, &st);
                else /* next-event estimation's sparser process: the same mean */
                    media_emission_line_at(&v, emitter, o, d, 0.0f, (float)dist[i], VOLUME_LINE_COARSE, &rng, L, &st);
                for (int k = 0; k < 3; ++k) acc_add(&acc[k], L[k]);
            }
            collisions[density][i] = st.collisions;
            double ex[3];
            for (int k = 0; k < 3; ++k) {
                double stall = sigma + (variant == 2 ? hom_sa[k] : 0.0);
                ex[k] = 5.0 * color[k] * sa / stall * (1.0 - exp(-stall * dist[i]));
                CHECK(acc_ok(&acc[k], ex[k]), "emission line variant %d d %g ch %d: %g +- %g vs %g", variant, dist[i], k,
                      acc_mean(&acc[k]), acc_se(&acc[k]), ex[k]);
            }
            CHECK(st.capped_walks == 0, "capped walks");
            printf("emission line%s %s d %.1f: (%.4f %.4f %.4f) +- (%.4f %.4f %.4f), exact (%.4f %.4f %.4f); %.1f "
                   "collisions per walk\n", density ? " (coarse)" : "",
                   variant == 0 ? "grid absorber" : variant == 1 ? "grid albedo 0.5" : "grid in a chromatic absorber",
                   dist[i], acc_mean(&acc[0]), acc_mean(&acc[1]), acc_mean(&acc[2]), acc_se(&acc[0]), acc_se(&acc[1]),
                   acc_se(&acc[2]), ex[0], ex[1], ex[2], (double)st.collisions / NS);
        }
        /* the coarse process collides less where the emission term sets the majorant: the
         * term 5 x sa x lum(color) is ~6/m for the absorbers, above the coarse cap (32/m per
         * voxel / 8 = 4/m) and above sigma_t = 2: fewer collisions; with albedo 0.5 (~3/m) it
         * is under that cap: the same majorant */
        for (int i = 0; i < 2; ++i)
            CHECK(variant == 1 ? collisions[1][i] <= collisions[0][i] * 11 / 10 : collisions[1][i] < collisions[0][i] * 8 / 10,
                  "coarse line collisions %llu vs standard %llu", (unsigned long long)collisions[1][i],
                  (unsigned long long)collisions[0][i]);
        /* an emitter index outside the view or not emissive gives 0 */
        float L[3] = {1, 1, 1};
        TestRng r;
        VolumeRng rng = make_rng(&r, 1);
        media_emission_line(&v, v.count, o, d, 0.0f, 0.5f, &rng, L, NULL);
        CHECK(L[0] == 0.0f && L[1] == 0.0f && L[2] == 0.0f, "emitter out of the view");
        if (variant == 2) {
            media_emission_line(&v, 0, o, d, 0.0f, 0.5f, &rng, L, NULL);
            CHECK(L[0] == 0.0f && L[1] == 0.0f && L[2] == 0.0f, "a homogeneous emitter");
        }
        medium_free(&m);
    }
    io_volume_grid_free(&g);

    /* heterogeneous: two emitting media (the blob of emission_test_medium and its
     * temperature-grid sibling, overlapping) and a scattering homogeneous medium in one
     * view; each emitter's line estimate against media_sample_event's emitted_by, and the
     * sum of emitted_by against emitted */
    Medium a, b;
    IoVolumeGrid ga, gea, gb, geb;
    if (emission_test_medium(0, &a, &ga, &gea, 0)) return;
    if (emission_test_medium(2, &b, &gb, &geb, 0)) {
        medium_free(&a);
        io_volume_grid_free(&ga);
        io_volume_grid_free(&gea);
        return;
    }
    const float fog_sa[3] = {0.1f, 0.2f, 0.3f}, fog_ss[3] = {0.8f, 0.6f, 0.4f};
    Medium fog;
    CHECK(medium_init_homogeneous(&fog, fog_sa, fog_ss, 0.3f, err) == 0, "%s", err);
    MediaView v = {{&a, &fog, &b}, 3};
    float ho[3] = {-0.6f, -0.1f, 0.05f}, hd[3] = {1.0f, 0.15f, -0.05f};
    normalize3(hd);
    const float beta[3] = {1.0f, 0.7f, 0.4f};
    Acc line[2][3], by[2][3];
    memset(line, 0, sizeof line);
    memset(by, 0, sizeof by);
    TestRng r1, r2;
    VolumeRng rng1 = make_rng(&r1, 4711), rng2 = make_rng(&r2, 4712);
    VolumeStats st_line = {0}, st_ev = {0};
    double max_split_err = 0.0;
    enum { NH = 100000 };
    for (int s = 0; s < NH; ++s) {
        VolumeEvent ev;
        media_sample_event(&v, ho, hd, 0.0f, 2.0f, beta, &rng2, &ev, &st_ev);
        for (int k = 0; k < 3; ++k) {
            double sum = 0.0;
            for (int i = 0; i < VOLUME_MAX_OVERLAP; ++i) sum += ev.emitted_by[i][k];
            max_split_err = fmax(max_split_err, fabs(sum - ev.emitted[k]) / (1e-6 + fabs(ev.emitted[k])));
            acc_add(&by[0][k], ev.emitted_by[0][k]);
            acc_add(&by[1][k], ev.emitted_by[2][k]);
        }
        CHECK(ev.emitted_by[1][0] == 0.0f && ev.emitted_by[3][0] == 0.0f, "emission from a non-emitting medium");
        for (int e = 0; e < 2; ++e) {
            float L[3];
            media_emission_line(&v, e == 0 ? 0 : 2, ho, hd, 0.0f, 2.0f, &rng1, L, &st_line);
            for (int k = 0; k < 3; ++k) acc_add(&line[e][k], L[k]);
        }
    }
    CHECK(max_split_err < 1e-4, "emitted_by sums to emitted up to %g", max_split_err);
    for (int e = 0; e < 2; ++e) {
        for (int k = 0; k < 3; ++k) {
            double diff = acc_mean(&line[e][k]) - acc_mean(&by[e][k]);
            double se = sqrt(acc_se(&line[e][k]) * acc_se(&line[e][k]) + acc_se(&by[e][k]) * acc_se(&by[e][k]));
            CHECK(fabs(diff) <= NSE * se + 1e-7, "emitter %d ch %d: line %g +- %g vs spectral tracking %g +- %g", e, k,
                  acc_mean(&line[e][k]), acc_se(&line[e][k]), acc_mean(&by[e][k]), acc_se(&by[e][k]));
        }
        printf("heterogeneous emitter %d: line (%.5f %.5f %.5f) +- (%.5f %.5f %.5f), spectral tracking emitted_by "
               "(%.5f %.5f %.5f) +- (%.5f %.5f %.5f)\n",
               e, acc_mean(&line[e][0]), acc_mean(&line[e][1]), acc_mean(&line[e][2]), acc_se(&line[e][0]),
               acc_se(&line[e][1]), acc_se(&line[e][2]), acc_mean(&by[e][0]), acc_mean(&by[e][1]), acc_mean(&by[e][2]),
               acc_se(&by[e][0]), acc_se(&by[e][1]), acc_se(&by[e][2]));
    }
    printf("heterogeneous: emitted_by sums to emitted within %.2g (relative); %.1f collisions per line walk, %.1f per "
           "free flight\n",
           max_split_err, (double)st_line.collisions / (2.0 * NH), (double)st_ev.collisions / NH);
    CHECK(st_line.capped_walks == 0 && st_ev.capped_walks == 0, "capped walks");
    medium_free(&a);
    medium_free(&b);
    io_volume_grid_free(&ga);
    io_volume_grid_free(&gea);
    io_volume_grid_free(&gb);
    io_volume_grid_free(&geb);
}

/* ---------------------------------------------------------------- overlapping media */

/* A chromatic homogeneous medium and a constant grid in one view: the merged majorant walk
 * gives the product of the transmittances, and the scattering events split between the
 * media with the right weights: E[w_c 1(scatter in medium i)] = integral of
 * T_c(t) sigma_s,i,c(t) dt, per medium and channel. */
static double overlap_grid_field(double x) { /* the grid's trilinear field along the test ray */
    double u = 32.0 * x;
    return u <= -1.0 ? 0.0 : u < 0.0 ? u + 1.0 : u <= 31.0 ? 1.0 : u < 32.0 ? 32.0 - u : 0.0;
}

static void test_overlap(void) {
    enum { N = 32 };
    float *vals = malloc(sizeof(float) * N * N * N);
    for (int i = 0; i < N * N * N; ++i) vals[i] = 1.0f;
    float i2w[16];
    scale_translate(i2w, 1.0f / N, 0.0f, 0.0f, 0.0f);
    IoVolumeGrid g;
    char err[IO_ERR_LEN] = "";
    if (make_grid(vals, N, N, N, i2w, "density", &g)) {
        free(vals);
        return;
    }
    const float sa[3] = {0.1f, 0.3f, 0.6f}, ss[3] = {0.4f, 0.3f, 0.2f};
    const float gscale = 3.0f, galb = 0.6f;
    Medium h, gm;
    CHECK(medium_init_homogeneous(&h, sa, ss, 0.3f, err) == 0, "%s", err);
    VolumeDesc desc = grid_desc(&g, gscale, galb);
    CHECK(medium_init_vdb(&gm, &desc, err) == 0, "%s", err);
    MediaView v = {{&gm, &h}, 2};
    const float o[3] = {-0.5f, 0.5f, 0.5f}, d[3] = {1.0f, 0.0f, 0.0f};
    const double tmax = 2.0;
    /* references by quadrature along the ray */
    enum { Q = 200000 };
    double T_end[3], scat[2][3] = {{0}};
    {
        double tau_g = 0.0, dt = tmax / Q;
        for (int i = 0; i < Q; ++i) {
            double t = (i + 0.5) * dt, sg = gscale * overlap_grid_field(o[0] + t);
            double tg_mid = tau_g + 0.5 * sg * dt; /* grid optical depth at the midpoint */
            for (int k = 0; k < 3; ++k) {
                double T = exp(-(sa[k] + ss[k]) * t - tg_mid);
                scat[0][k] += T * galb * sg * dt;
                scat[1][k] += T * ss[k] * dt;
            }
            tau_g += sg * dt;
        }
        for (int k = 0; k < 3; ++k) T_end[k] = exp(-(sa[k] + ss[k]) * tmax - tau_g);
    }
    Acc rt[3];
    VolumeStats st = {0};
    ratio_estimate(&v, o, d, 0.0f, (float)tmax, 40000, 71, rt, &st);
    Acc pass[3], sc[2][3];
    memset(pass, 0, sizeof pass);
    memset(sc, 0, sizeof sc);
    TestRng r;
    VolumeRng rng = make_rng(&r, 72);
    const float beta[3] = {0.5f, 1.0f, 1.5f};
    int bad_medium = 0;
    for (int i = 0; i < 200000; ++i) {
        VolumeEvent ev;
        media_sample_event(&v, o, d, 0.0f, (float)tmax, beta, &rng, &ev, &st);
        bad_medium += ev.type == VOLUME_EVENT_SCATTER && (ev.medium < 0 || ev.medium > 1);
        for (int k = 0; k < 3; ++k) {
            acc_add(&pass[k], ev.type == VOLUME_EVENT_PASSED ? ev.weight[k] : 0.0);
            for (int mi = 0; mi < 2; ++mi)
                acc_add(&sc[mi][k], ev.type == VOLUME_EVENT_SCATTER && ev.medium == mi ? ev.weight[k] : 0.0);
        }
    }
    CHECK(bad_medium == 0, "%d scatter events name no medium of the view", bad_medium);
    for (int k = 0; k < 3; ++k) {
        CHECK(acc_ok(&rt[k], T_end[k]), "overlap ratio tracking ch %d: %g +- %g vs %g", k, acc_mean(&rt[k]),
              acc_se(&rt[k]), T_end[k]);
        CHECK(acc_ok(&pass[k], T_end[k]), "overlap pass weight ch %d: %g +- %g vs %g", k, acc_mean(&pass[k]),
              acc_se(&pass[k]), T_end[k]);
        for (int mi = 0; mi < 2; ++mi)
            CHECK(acc_ok(&sc[mi][k], scat[mi][k]), "overlap scatter in medium %d ch %d: %g +- %g vs %g", mi, k,
                  acc_mean(&sc[mi][k]), acc_se(&sc[mi][k]), scat[mi][k]);
    }
    printf("overlap: T ratio (%.4f %.4f %.4f) delta (%.4f %.4f %.4f) exact (%.4f %.4f %.4f)\n", acc_mean(&rt[0]),
           acc_mean(&rt[1]), acc_mean(&rt[2]), acc_mean(&pass[0]), acc_mean(&pass[1]), acc_mean(&pass[2]), T_end[0],
           T_end[1], T_end[2]);
    for (int mi = 0; mi < 2; ++mi)
        printf("  scatter in %s: (%.4f %.4f %.4f) exact (%.4f %.4f %.4f)\n", mi ? "homogeneous" : "grid",
               acc_mean(&sc[mi][0]), acc_mean(&sc[mi][1]), acc_mean(&sc[mi][2]), scat[mi][0], scat[mi][1], scat[mi][2]);
    CHECK(st.capped_walks == 0, "capped walks");
    medium_free(&h);
    medium_free(&gm);
    io_volume_grid_free(&g);
    free(vals);
}

/* ---------------------------------------------------------------- Henyey-Greenstein */

/* CDF of mu = cos(wi, -wo) under HG (the test's own closed form). */
static double hg_cdf(double g, double mu) {
    if (fabs(g) < 1e-3) return 0.5 * (mu + 1.0);
    return (1.0 - g * g) / (2.0 * g) * (1.0 / sqrt(1.0 + g * g - 2.0 * g * mu) - 1.0 / (1.0 + g));
}

static void test_hg(void) {
    const float gs[6] = {-0.9f, -0.3f, 0.0f, 0.5f, 0.95f, 5e-4f};
    float wo[3] = {0.3f, -0.5f, 0.8f};
    normalize3(wo);
    /* a frame around the forward direction -wo, for phi */
    float f[3] = {-wo[0], -wo[1], -wo[2]}, t[3], b[3];
    float up[3] = {0.0f, 0.0f, 1.0f};
    t[0] = up[1] * f[2] - up[2] * f[1];
    t[1] = up[2] * f[0] - up[0] * f[2];
    t[2] = up[0] * f[1] - up[1] * f[0];
    normalize3(t);
    b[0] = f[1] * t[2] - f[2] * t[1];
    b[1] = f[2] * t[0] - f[0] * t[2];
    b[2] = f[0] * t[1] - f[1] * t[0];
    for (int gi = 0; gi < 6; ++gi) {
        float g = gs[gi];
        /* integral over the sphere: midpoint rule in (mu, phi) around -wo */
        double integral = 0.0;
        const int nm = 100000, np = 4;
        for (int i = 0; i < nm; ++i)
            for (int j = 0; j < np; ++j) {
                double mu = -1.0 + (i + 0.5) * 2.0 / nm, phi = (j + 0.5) * 2.0 * PI_D / np, s = sqrt(1.0 - mu * mu);
                float wi[3];
                for (int k = 0; k < 3; ++k) wi[k] = (float)(s * cos(phi) * t[k] + s * sin(phi) * b[k] + mu * f[k]);
                integral += hg_phase(g, wo, wi);
            }
        integral *= (2.0 / nm) * (2.0 * PI_D / np);
        CHECK(fabs(integral - 1.0) < 2e-3, "HG g %g integrates to %g", g, integral);
        /* chi-square of hg_sample over (mu, phi) bins, bins denser towards the peak */
        enum { NMU = 48, NPHI = 8, NS = 1000000 };
        static double obs[NMU * NPHI], expv[NMU * NPHI];
        double edge[NMU + 1];
        for (int i = 0; i <= NMU; ++i) {
            double x = (double)i / NMU;
            edge[i] = g >= 0.0f ? 1.0 - 2.0 * (1.0 - x) * (1.0 - x) : -1.0 + 2.0 * x * x;
        }
        for (int i = 0; i < NMU; ++i)
            for (int j = 0; j < NPHI; ++j) {
                obs[i * NPHI + j] = 0.0;
                expv[i * NPHI + j] = NS * (hg_cdf(g, edge[i + 1]) - hg_cdf(g, edge[i])) / NPHI;
            }
        TestRng r = {1000 + gi};
        int pdf_mismatch = 0, not_unit = 0;
        for (int s = 0; s < NS; ++s) {
            float wi[3];
            float pdf = hg_sample(g, wo, test_rng_next(&r), test_rng_next(&r), wi);
            float ph = hg_phase(g, wo, wi);
            pdf_mismatch += !(fabsf(pdf - ph) <= 1e-6f * ph);
            float len = sqrtf(wi[0] * wi[0] + wi[1] * wi[1] + wi[2] * wi[2]);
            not_unit += fabsf(len - 1.0f) > 1e-5f;
            double mu = wi[0] * f[0] + wi[1] * f[1] + wi[2] * f[2];
            double phi = atan2(wi[0] * b[0] + wi[1] * b[1] + wi[2] * b[2], wi[0] * t[0] + wi[1] * t[1] + wi[2] * t[2]);
            if (phi < 0.0) phi += 2.0 * PI_D;
            int j = (int)(phi / (2.0 * PI_D) * NPHI);
            j = j < 0 ? 0 : j >= NPHI ? NPHI - 1 : j;
            int lo = 0, hi = NMU; /* edge[lo] <= mu < edge[hi] */
            while (hi - lo > 1) {
                int mid = (lo + hi) / 2;
                if (mu >= edge[mid]) lo = mid;
                else hi = mid;
            }
            obs[lo * NPHI + j] += 1.0;
        }
        int dof;
        double stat, p = chi2_pvalue(obs, expv, NMU * NPHI, &dof, &stat);
        printf("HG g %5.2f: integral %.5f, chi2 %.1f dof %d p %.3f\n", g, integral, stat, dof, p);
        CHECK(p > 1e-3, "HG g %g sampling: chi2 %g dof %d p %g", g, stat, dof, p);
        CHECK(pdf_mismatch == 0, "HG g %g: %d sample pdfs differ from hg_phase", g, pdf_mismatch);
        CHECK(not_unit == 0, "HG g %g: %d sampled directions not unit", g, not_unit);
    }
    /* convention: g > 0 favours wi = -wo */
    float back[3] = {-wo[0], -wo[1], -wo[2]};
    CHECK(hg_phase(0.5f, wo, back) > hg_phase(0.5f, wo, wo), "g > 0 must favour wi = -wo");
    CHECK(hg_phase(1e-4f, wo, back) == hg_phase(0.0f, wo, wo), "|g| < 1e-3 is isotropic exactly");
}

/* ---------------------------------------------------------------- blackbody */

static void test_blackbody(void) {
    const float temps[4] = {1000.0f, 3000.0f, 6500.0f, 1500.0f};
    for (int i = 0; i < 4; ++i) {
        float c[3];
        blackbody_rgb(temps[i], c);
        float lum = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
        printf("blackbody %5.0f K: (%.4f %.4f %.4f), luminance %.6f\n", temps[i], c[0], c[1], c[2], lum);
        CHECK(fabsf(lum - 1.0f) < 1e-4f, "blackbody %g K: luminance %g", temps[i], lum);
        CHECK(c[0] >= 0.0f && c[1] >= 0.0f && c[2] >= 0.0f, "blackbody %g K: negative component", temps[i]);
        if (temps[i] == 6500.0f) {
            float mx = fmaxf(c[0], fmaxf(c[1], c[2])), mn = fminf(c[0], fminf(c[1], c[2]));
            CHECK(mx <= 1.1f * mn, "6500 K not near white: (%g %g %g)", c[0], c[1], c[2]);
        }
        if (temps[i] == 1500.0f) CHECK(c[0] > c[1] && c[1] > c[2], "1500 K not reddish: (%g %g %g)", c[0], c[1], c[2]);
    }
    float c[3] = {1, 1, 1};
    blackbody_rgb(400.0f, c);
    CHECK(c[0] == 0.0f && c[1] == 0.0f && c[2] == 0.0f, "below 500 K: (%g %g %g)", c[0], c[1], c[2]);
    blackbody_rgb(NAN, c);
    CHECK(c[0] == 0.0f, "NaN kelvin");
    blackbody_rgb(1e9f, c);
    CHECK(isfinite(c[0]) && fabsf(0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2] - 1.0f) < 1e-4f, "1e9 K");
}

/* ---------------------------------------------------------------- bad input */

static void test_bad_input(void) {
    char err[IO_ERR_LEN];
    Medium m;
    const float ok[3] = {0.1f, 0.2f, 0.3f};
    const float neg[3] = {0.1f, -0.2f, 0.3f}, nan3[3] = {0.1f, NAN, 0.3f}, inf3[3] = {INFINITY, 0.0f, 0.0f};
    struct { const float *sa, *ss; float g; const char *what; } hcases[] = {
        {neg, ok, 0.0f, "negative sigma_a"}, {ok, nan3, 0.0f, "NaN sigma_s"}, {inf3, ok, 0.0f, "infinite sigma_a"},
        {ok, ok, 1.0f, "g = 1"},             {ok, ok, -1.5f, "g = -1.5"},     {ok, ok, NAN, "NaN g"},
    };
    for (size_t i = 0; i < sizeof hcases / sizeof hcases[0]; ++i) {
        err[0] = 0;
        int rc = medium_init_homogeneous(&m, hcases[i].sa, hcases[i].ss, hcases[i].g, err);
        CHECK(rc == -1 && one_line(err), "%s: rc %d err '%s'", hcases[i].what, rc, err);
        if (i == 0) printf("bad input, e.g.: %s\n", err);
    }

    enum { N = 8 };
    float v[N * N * N];
    for (int i = 0; i < N * N * N; ++i) v[i] = 1.0f;
    float i2w[16];
    scale_translate(i2w, 0.125f, 0.0f, 0.0f, 0.0f);
    IoVolumeGrid g;
    if (make_grid(v, N, N, N, i2w, "density", &g) == 0) {
        VolumeDesc base = grid_desc(&g, 1.0f, 0.5f);
        for (int c = 0; c < 8; ++c) {
            VolumeDesc d = base;
            const char *what = "";
            switch (c) {
            case 0: d.density_scale = NAN; what = "NaN density_scale"; break;
            case 1: d.density_scale = -1.0f; what = "negative density_scale"; break;
            case 2: d.albedo[1] = 1.5f; what = "albedo 1.5"; break;
            case 3: d.anisotropy = 1.0f; what = "anisotropy 1"; break;
            case 4: memset(d.node_to_world, 0, sizeof d.node_to_world); what = "singular node"; break;
            case 5: d.node_to_world[13] = INFINITY; what = "infinite node"; break;
            case 6: d.density = NULL; what = "no density"; break;
            case 7: d.emission_color[0] = -1.0f; what = "negative emission colour"; break;
            }
            err[0] = 0;
            int rc = medium_init_vdb(&m, &d, err);
            CHECK(rc == -1 && one_line(err), "%s: rc %d err '%s'", what, rc, err);
            if (rc == 0) medium_free(&m);
        }
        io_volume_grid_free(&g);
    }

    /* NaN, infinite and negative densities count as 0: an empty medium, never a hang */
    for (int i = 0; i < N * N * N; ++i) v[i] = i % 3 == 0 ? NAN : i % 3 == 1 ? -2.0f : (i % 2 ? -INFINITY : INFINITY);
    if (make_grid(v, N, N, N, i2w, "density", &g) == 0) {
        VolumeDesc d = grid_desc(&g, 10.0f, 0.5f);
        int rc = medium_init_vdb(&m, &d, err);
        CHECK(rc == 0, "NaN grid: %s", err);
        if (rc == 0) {
            MediaView view = {{&m}, 1};
            const float o[3] = {-0.5f, 0.5f, 0.5f}, dir[3] = {1.0f, 0.0f, 0.0f};
            TestRng r;
            VolumeRng rng = make_rng(&r, 3);
            VolumeStats st = {0};
            float T[3];
            VolumeEvent ev;
            int bad = 0;
            for (int i = 0; i < 1000; ++i) {
                media_transmittance(&view, o, dir, 0.0f, 2.0f, &rng, T, &st);
                media_sample_event(&view, o, dir, 0.0f, 2.0f, NULL, &rng, &ev, &st);
                bad += T[0] != 1.0f || T[2] != 1.0f || ev.type != VOLUME_EVENT_PASSED || ev.weight[1] != 1.0f;
            }
            CHECK(bad == 0 && st.collisions == 0, "NaN / negative grid is not empty: %d, %llu collisions", bad,
                  (unsigned long long)st.collisions);
            float p[3] = {0.5f, 0.5f, 0.5f};
            CHECK(sigma_t_at(&m, p) == 0.0f, "NaN grid sigma_t");
            medium_free(&m);
        }
        io_volume_grid_free(&g);
    }

    /* a huge density is clamped (VOLUME_MAX_SIGMA_T) and every walk ends */
    for (int i = 0; i < N * N * N; ++i) v[i] = 1e30f;
    if (make_grid(v, N, N, N, i2w, "density", &g) == 0) {
        VolumeDesc d = grid_desc(&g, 1.0f, 0.7f);
        int rc = medium_init_vdb(&m, &d, err);
        CHECK(rc == 0, "huge grid: %s", err);
        if (rc == 0) {
            float p[3] = {0.5f, 0.5f, 0.5f};
            CHECK(sigma_t_at(&m, p) == VOLUME_MAX_SIGMA_T, "huge density not clamped: %g", sigma_t_at(&m, p));
            MediaView view = {{&m}, 1};
            const float o[3] = {-0.5f, 0.5f, 0.5f}, dir[3] = {1.0f, 0.0f, 0.0f};
            TestRng r;
            VolumeRng rng = make_rng(&r, 4);
            VolumeStats st = {0};
            double tsum = 0.0;
            int scattered = 0;
            double t0 = test_seconds();
            for (int i = 0; i < 1000; ++i) {
                float T[3];
                VolumeEvent ev;
                media_transmittance(&view, o, dir, 0.0f, 2.0f, &rng, T, &st);
                tsum += T[0];
                media_sample_event(&view, o, dir, 0.0f, 2.0f, NULL, &rng, &ev, &st);
                scattered += ev.type == VOLUME_EVENT_SCATTER;
            }
            printf("huge density: mean T %.3g, %d/1000 scattered, %llu collisions, %llu capped walks, %.3f s\n",
                   tsum / 1000, scattered, (unsigned long long)st.collisions, (unsigned long long)st.capped_walks,
                   test_seconds() - t0);
            CHECK(tsum / 1000 < 1e-3, "huge density: mean T %g", tsum / 1000);
            CHECK(scattered > 500, "huge density, albedo 0.7: %d of 1000 walks scattered", scattered);
            medium_free(&m);
        }
        io_volume_grid_free(&g);
    }

    /* a walk that would not end: only null collisions for the channels beta weighs (sigma_t
     * 1e6 in red, 0 elsewhere, beta = (0, 1, 1)) is capped and counted */
    {
        const float sa[3] = {1e6f, 0.0f, 0.0f}, ss[3] = {0};
        CHECK(medium_init_homogeneous(&m, sa, ss, 0.0f, err) == 0, "%s", err);
        MediaView view = {{&m}, 1};
        const float o[3] = {0}, dir[3] = {0.0f, 0.0f, 1.0f}, beta[3] = {0.0f, 1.0f, 1.0f};
        TestRng r;
        VolumeRng rng = make_rng(&r, 9);
        VolumeStats st = {0};
        VolumeEvent ev;
        media_sample_event(&view, o, dir, 0.0f, 1.0f, beta, &rng, &ev, &st);
        CHECK(st.capped_walks == 1 && ev.type == VOLUME_EVENT_ABSORBED && st.collisions == VOLUME_MAX_COLLISIONS,
              "capped walk: %llu capped, type %d, %llu collisions", (unsigned long long)st.capped_walks, ev.type,
              (unsigned long long)st.collisions);
        const float huge[3] = {1e30f, 1e30f, 1e30f};
        CHECK(medium_init_homogeneous(&m, huge, ss, 0.0f, err) == 0, "%s", err);
        CHECK(fabsf(m.sigma_a[0] - VOLUME_MAX_SIGMA_T) <= 1e-6f * VOLUME_MAX_SIGMA_T,
              "homogeneous extinction not clamped: %g", m.sigma_a[0]);
        medium_free(&m);
    }
}

/* ---------------------------------------------------------------- slab.vdb */

static void test_slab_asset(const char *dir) {
    char path[1024];
    snprintf(path, sizeof path, "%s/vdb/slab.vdb", dir);
    FILE *f = fopen(path, "rb");
    if (!f) return;
    fclose(f);
    IoVolumeGrid g;
    char err[IO_ERR_LEN] = "";
    if (io_load_vdb_grid(path, "density", &g, err) != 0) {
        CHECK(0, "slab.vdb: %s", err);
        return;
    }
    Medium m;
    VolumeDesc desc = grid_desc(&g, 2.0f, 0.0f);
    CHECK(medium_init_vdb(&m, &desc, err) == 0, "%s", err);
    /* density increases with y (orientation): the field at y = +0.3 exceeds y = -0.3 by
     * about the ramp (0.6 x 2) */
    float lo[3] = {0.0f, -0.3f, 0.0f}, hi[3] = {0.0f, 0.3f, 0.0f};
    float slo = sigma_t_at(&m, lo), shi = sigma_t_at(&m, hi);
    printf("slab.vdb: sigma_t(y = -0.3) %.4f, sigma_t(y = +0.3) %.4f\n", slo, shi);
    CHECK(fabsf((shi - slo) - 1.2f) < 0.1f && slo > 0.0f, "slab.vdb ramp: %g .. %g", slo, shi);
    medium_free(&m);
    io_volume_grid_free(&g);
}

/* ---------------------------------------------------------------- distance table (§4.2) */

/* The piecewise-linear distance density of in-scattering sampling: it integrates to 1, the
 * samples follow it (chi-square over fine bins), each sample's pdf is the density at it, an
 * all-zero table is uniform, and bad tables are refused. */
static void test_distance_table(void) {
    const float t[6] = {1.0f, 1.5f, 1.7f, 3.0f, 3.0f, 5.0f}, s[6] = {0.0f, 4.0f, 1.0f, 0.5f, 2.0f, 0.0f};
    VolumeDistanceTable tab;
    CHECK(volume_distance_table_init(&tab, t, s, 6, 0.1f) == 0, "a valid table was refused");
    enum { NB = 80, NS = 400000, STEPS = 200000 };
    double integral = 0.0;
    for (int i = 0; i < STEPS; ++i) integral += volume_distance_pdf(&tab, 1.0f + 4.0f * (i + 0.5f) / STEPS) * 4.0 / STEPS;
    CHECK(fabs(integral - 1.0) < 1e-3, "the distance density integrates to %g", integral);
    CHECK(volume_distance_pdf(&tab, 0.99f) == 0.0f && volume_distance_pdf(&tab, 5.01f) == 0.0f,
          "density outside [t0, t1]");
    double obs[NB] = {0}, expv[NB];
    TestRng r;
    VolumeRng rng = make_rng(&r, 5);
    int bad_pdf = 0;
    for (int i = 0; i < NS; ++i) {
        float pdf, x = volume_distance_sample(&tab, rng.next(rng.state), rng.next(rng.state), &pdf);
        bad_pdf += !(x >= 1.0f && x <= 5.0f) || fabsf(pdf - volume_distance_pdf(&tab, x)) > 1e-6f * fmaxf(pdf, 1.0f);
        int b = (int)((x - 1.0f) / 4.0f * NB);
        obs[b < 0 ? 0 : b >= NB ? NB - 1 : b] += 1.0;
    }
    for (int b = 0; b < NB; ++b) {
        double e = 0.0;
        for (int k = 0; k < 100; ++k) e += volume_distance_pdf(&tab, 1.0f + 4.0f * (b + (k + 0.5f) / 100.0f) / NB) * 4.0 / NB / 100.0;
        expv[b] = NS * e;
    }
    int dof;
    double stat, p = chi2_pvalue(obs, expv, NB, &dof, &stat);
    printf("distance table: integral %.5f, chi2 %.1f dof %d p %.3f\n", integral, stat, dof, p);
    CHECK(p > 1e-3, "distance samples: chi2 %g dof %d p %g", stat, dof, p);
    CHECK(bad_pdf == 0, "%d samples outside [t0, t1] or with a pdf other than the density's", bad_pdf);
    const float zero[3] = {0.0f, 0.0f, 0.0f}, t3[3] = {2.0f, 3.0f, 4.0f};
    CHECK(volume_distance_table_init(&tab, t3, zero, 3, 0.1f) == 0 && fabsf(volume_distance_pdf(&tab, 2.5f) - 0.5f) < 1e-6f,
          "an all-zero table is not uniform");
    const float bad_t[3] = {2.0f, 1.0f, 4.0f}, neg[3] = {1.0f, -1.0f, 1.0f}, same[2] = {2.0f, 2.0f};
    CHECK(volume_distance_table_init(&tab, bad_t, t3, 3, 0.1f) != 0, "decreasing stations accepted");
    CHECK(volume_distance_table_init(&tab, t3, neg, 3, 0.1f) != 0, "a negative weight accepted");
    CHECK(volume_distance_table_init(&tab, same, t3, 2, 0.1f) != 0, "an empty interval accepted");
    CHECK(volume_distance_table_init(&tab, t3, t3, 1, 0.1f) != 0, "one station accepted");
}

/* ---------------------------------------------------------------- sparse majorant (issue 29) */

/* Bounds and tiling over rays of one medium (as test_majorant), n rays from points in the world
 * box toward target points (blobs; NULL: random directions). Returns the violations. */
static long majorant_rays(const Medium *m, TestRng *r, int n, const float (*targets)[3], int ntargets, long *segments,
                          long *tiling) {
    long violations = 0;
    for (int ray = 0; ray < n; ++ray) {
        float o[3], d[3];
        for (int k = 0; k < 3; ++k) {
            float c = 0.5f * (m->world_min[k] + m->world_max[k]), h = 0.5f * (m->world_max[k] - m->world_min[k]);
            o[k] = c + (float)(urand(r) * 2.4 - 1.2) * h;
            d[k] = targets ? targets[ray % ntargets][k] + (float)(urand(r) - 0.5) * 0.002f - o[k] : (float)(urand(r) * 2.0 - 1.0);
        }
        if (ray % 5 == 0) d[ray % 3] = 0.0f; /* planes parallel to an axis */
        if (d[0] == 0.0f && d[1] == 0.0f && d[2] == 0.0f) d[2] = 1.0f;
        float c0, c1;
        int hit = medium_clip_ray(m, o, d, 0.0f, 2.0f, &c0, &c1);
        for (int control = 0; control < 2; ++control) {
            MajorantIterator it;
            if (control) medium_majorant_begin_control(m, o, d, 0.0f, 2.0f, &it);
            else medium_majorant_begin(m, o, d, 0.0f, 2.0f, &it);
            float t0, t1, maj, ctl, prev = 0.0f;
            int k = 0;
            while (medium_majorant_next_control(&it, &t0, &t1, &maj, &ctl) && k < 1000000) {
                if (k == 0 ? t0 != c0 : t0 != prev) ++*tiling;
                if (!(t1 > t0) || !(maj >= 0.0f) || !(ctl <= maj) || (!control && ctl != 0.0f)) ++*tiling;
                prev = t1;
                ++k;
                for (int j = 0; j < 6; ++j) {
                    float t = j == 0 ? t0 : j == 1 ? t1 : t0 + (float)urand(r) * (t1 - t0);
                    float p[3] = {o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]};
                    float sig = sigma_t_at(m, p);
                    if (sig > maj || (j > 1 && sig < ctl)) {
                        if (violations < 5)
                            fprintf(stderr, "  violation: ray %d t %g in [%g, %g]: sigma_t %g, majorant %g, control %g\n", ray, t, t0,
                                    t1, sig, maj, ctl);
                        ++violations;
                    }
                }
            }
            *segments += k;
            if (hit ? (k == 0 || prev != c1) : k != 0) ++*tiling;
        }
    }
    return violations;
}

/* The cases of issue 29: a 19 KB VDB with two 4^3 blobs 5,100 voxels apart took 2.2 GB and 25 s
 * (the majorant grid spanned their bounding box); a 594-byte one with a tile filling 4096^3
 * voxels 1.2 GB and 10 s; a voxel of 1e30. Now: the sparse form, memory in proportion to the
 * data (checked as numbers of bytes, never times), bounds and tiling exact, transmittance
 * unbiased through both; the per-medium budget and the coordinate limit refuse with one line. */
static void test_majorant_sparse(void) {
    char err[IO_ERR_LEN] = "";
    TestRng r = {2929};
    float i2w[16];
    scale_translate(i2w, 1e-3f, 0.0f, 0.0f, 0.0f); /* 1 mm voxels: the blobs 5.1 m apart */
    /* two 4^3 blobs, 5,100 voxels apart along the diagonal (the finding), then 6,000 (the box
     * beyond 2^28 cells, which the bricks' dense directory refused) and 600,000 (a 600 m box of
     * 1 mm voxels): the same 40 KiB of tables, whatever the gap */
    IoVolumeGrid g;
    int rc;
    static const int32_t seps[3] = {5100, 6000, 600000};
    for (int si = 0; si < 3; ++si) {
    const int32_t sep = seps[si];
    const float sep_m = 1e-3f * (float)sep;
    int32_t ijk[2 * 64 * 3];
    float vals[2 * 64];
    int n = 0;
    for (int b = 0; b < 2; ++b)
        for (int z = 0; z < 4; ++z)
            for (int y = 0; y < 4; ++y)
                for (int x = 0; x < 4; ++x) {
                    int32_t base = b ? sep : 0;
                    ijk[3 * n] = base + x;
                    ijk[3 * n + 1] = base + y;
                    ijk[3 * n + 2] = base + z;
                    vals[n++] = (float)(0.5 + 1.5 * urand(&r));
                }
    rc = io_volume_grid_from_voxels(ijk, vals, (size_t)n, NULL, NULL, 0, i2w, "density", &g, err);
    CHECK(rc == 0, "two blobs: %s", err);
    if (rc == 0) {
        VolumeDesc desc = grid_desc(&g, 80.0f, 0.5f);
        Medium m;
        rc = medium_init_vdb(&m, &desc, err);
        CHECK(rc == 0, "two blobs: %s", err);
        if (rc == 0) {
            const MajorantGrid *mg = &m.majorant;
            double dense = 2.0 * 4.0 * mg->dims[0] * (double)mg->dims[1] * mg->dims[2];
            printf("sparse majorant, two blobs %d voxels apart: %d x %d x %d cells, %.2f MiB (dense %.0f MiB), medium %.2f MiB\n",
                   sep, mg->dims[0], mg->dims[1], mg->dims[2], mg->bytes / 1048576.0, dense / 1048576.0, m.memory_bytes / 1048576.0);
            CHECK(mg->bricks.entries != NULL && mg->sigma_maj == NULL, "two blobs: not the sparse form");
            CHECK(m.memory_bytes < (256u << 10), "two blobs %d apart: %.2f MiB for 128 voxels", sep, m.memory_bytes / 1048576.0);
            const float targets[2][3] = {{0.002f, 0.002f, 0.002f}, {sep_m + 0.002f, sep_m + 0.002f, sep_m + 0.002f}};
            long segments = 0, tiling = 0;
            long violations = majorant_rays(&m, &r, 3000, targets, 2, &segments, &tiling);
            violations += majorant_rays(&m, &r, 1000, NULL, 0, &segments, &tiling);
            CHECK(violations == 0, "two blobs: %ld points above their majorant or below their control", violations);
            CHECK(tiling == 0, "two blobs: %ld tiling errors", tiling);
            /* the diagonal through both blobs: a few segments per blob, one step per empty brick
             * run between them (it crossed ~1,900 cells one by one) */
            const float o[3] = {-0.01f, -0.01f, -0.01f}, d[3] = {0.57735027f, 0.57735027f, 0.57735027f};
            MajorantIterator it;
            medium_majorant_begin(&m, o, d, 0.0f, 2.0f * sep_m, &it);
            float t0, t1, maj;
            int k = 0;
            double tau_maj = 0.0;
            while (medium_majorant_next(&it, &t0, &t1, &maj)) {
                ++k;
                tau_maj += (double)maj * (t1 - t0);
            }
            CHECK(k > 2 && k < 200, "the diagonal: %d segments", k);
            /* its optical depth by quadrature (trilinear, in index space: 1/64 voxel steps over
             * each blob's support) against ratio tracking's mean, within 5 standard errors */
            double tau = 0.0;
            const double step = 1e-3 / 64.0 * 1.7320508;
            for (int b = 0; b < 2; ++b) {
                double a = (b ? (double)sep * 1e-3 : 0.0) - 0.002, e = (b ? (double)sep * 1e-3 : 0.0) + 0.006; /* along each axis */
                double ta = (a - o[0]) / d[0], tb = (e - o[0]) / d[0];
                for (double t = ta + 0.5 * step; t < tb; t += step) {
                    float p[3] = {o[0] + (float)t * d[0], o[1] + (float)t * d[1], o[2] + (float)t * d[2]};
                    tau += sigma_t_at(&m, p) * step;
                }
            }
            MediaView view = {{&m}, 1};
            Acc tr = {0};
            TestRng rr;
            VolumeRng rng = make_rng(&rr, 5);
            VolumeStats st = {0};
            for (int i = 0; i < 20000; ++i) {
                float T[3];
                media_transmittance(&view, o, d, 0.0f, 2.0f * sep_m, &rng, T, &st);
                acc_add(&tr, T[0]);
            }
            printf("sparse majorant: diagonal %d segments (majorant depth %.2f), T %.5f +- %.5f, exp(-tau) %.5f\n", k, tau_maj,
                   acc_mean(&tr), acc_se(&tr), exp(-tau));
            CHECK(tau > 0.5 && acc_ok(&tr, exp(-tau)), "two blobs: transmittance %.5f +- %.5f, exp(-tau) %.5f", acc_mean(&tr),
                  acc_se(&tr), exp(-tau));
            medium_free(&m);
        }
        /* the per-medium budget (a share of the scene's --volume-budget-mb) */
        VolumeDesc small = grid_desc(&g, 400.0f, 0.5f);
        small.memory_budget = 16u << 10; /* the blobs take about 40 KiB */
        Medium m2;
        rc = medium_init_vdb(&m2, &small, err);
        CHECK(rc != 0 && one_line(err) && strstr(err, "of volume memory left"), "two blobs over a 1 MiB budget: %s",
              rc ? err : "built");
        io_volume_grid_free(&g);
    }
    }

    /* a tile filling 4096^3 voxels (one root tile) and a voxel of data inside */
    const int32_t box[6] = {0, 0, 0, 4095, 4095, 4095};
    const float box_value = 0.25f;
    const int32_t hot[3] = {2000, 2000, 2000};
    const float hot_value = 3.0f;
    rc = io_volume_grid_from_voxels(hot, &hot_value, 1, box, &box_value, 1, i2w, "density", &g, err);
    CHECK(rc == 0, "tile fill: %s", err);
    if (rc == 0) {
        VolumeDesc desc = grid_desc(&g, 2.0f, 0.5f);
        Medium m;
        rc = medium_init_vdb(&m, &desc, err);
        CHECK(rc == 0, "tile fill: %s", err);
        if (rc == 0) {
            printf("sparse majorant, a 4096^3 tile: %.2f MiB (NanoVDB %.1f KiB)\n", m.memory_bytes / 1048576.0, g.size / 1024.0);
            CHECK(m.majorant.bricks.entries != NULL && m.memory_bytes < (16u << 20), "tile fill: %.1f MiB", m.memory_bytes / 1048576.0);
            const float targets[1][3] = {{2.0005f, 2.0005f, 2.0005f}};
            long segments = 0, tiling = 0;
            long violations = majorant_rays(&m, &r, 600, targets, 1, &segments, &tiling);
            violations += majorant_rays(&m, &r, 600, NULL, 0, &segments, &tiling);
            CHECK(violations == 0, "tile fill: %ld points above their majorant or below their control", violations);
            CHECK(tiling == 0, "tile fill: %ld tiling errors", tiling);
            /* inside the tile sigma_t is 0.5 exactly and the control equals it: residual ratio
             * tracking gives exp(-0.5 x length) with no variance */
            const float o[3] = {1.0f, 1.0f, 0.5f}, d[3] = {0.0f, 0.0f, 1.0f};
            MediaView view = {{&m}, 1};
            TestRng rr;
            VolumeRng rng = make_rng(&rr, 7);
            VolumeStats st = {0};
            float T[3];
            media_transmittance(&view, o, d, 0.0f, 2.0f, &rng, T, &st);
            CHECK(fabs(T[0] - exp(-1.0)) < 1e-4, "tile fill: T over 2 m of sigma_t 0.5 is %g, not %g", T[0], exp(-1.0));
            medium_free(&m);
        }
        io_volume_grid_free(&g);
    }

    /* an emitting medium: two emitting 4^3 blobs 5,104 voxels apart (at 5,100 the dense form needed
     * 9 GB, over the default budget; 5,104 keeps both blobs at the same place in their cells, so
     * the floored border cells match): the sparse form with its emission-energy grid over the bricks'
     * slots, its power twice one blob's (dense), samples from both blobs in proportion, each
     * with a positive pdf along its direction */
    {
        int32_t ijk[2 * 64 * 3];
        float vals[2 * 64];
        int n = 0;
        for (int b = 0; b < 2; ++b)
            for (int i = 0; i < 64; ++i) {
                ijk[3 * n] = (b ? 5104 : 0) + i % 4;
                ijk[3 * n + 1] = (b ? 5104 : 0) + i / 4 % 4;
                ijk[3 * n + 2] = (b ? 5104 : 0) + i / 16;
                vals[n++] = 1.0f + 0.25f * (float)(i % 5);
            }
        IoVolumeGrid gd = {0}, ge = {0}, gd1 = {0}, ge1 = {0};
        int ok = io_volume_grid_from_voxels(ijk, vals, 128, NULL, NULL, 0, i2w, "density", &gd, err) == 0;
        ok = ok && io_volume_grid_from_voxels(ijk, vals, 128, NULL, NULL, 0, i2w, "emission", &ge, err) == 0;
        ok = ok && io_volume_grid_from_voxels(ijk, vals, 64, NULL, NULL, 0, i2w, "density", &gd1, err) == 0;
        ok = ok && io_volume_grid_from_voxels(ijk, vals, 64, NULL, NULL, 0, i2w, "emission", &ge1, err) == 0;
        CHECK(ok, "emitting blobs: %s", err);
        if (ok) {
            VolumeDesc desc = grid_desc(&gd, 50.0f, 0.5f), one = grid_desc(&gd1, 50.0f, 0.5f);
            desc.emission = &ge;
            one.emission = &ge1;
            desc.emission_scale = one.emission_scale = 2.0f;
            Medium m, m1;
            int rc2 = medium_init_vdb(&m, &desc, err);
            CHECK(rc2 == 0, "emitting blobs: %s", err);
            int rc1 = medium_init_vdb(&m1, &one, err);
            CHECK(rc1 == 0, "one emitting blob: %s", err);
            if (rc2 == 0 && rc1 == 0) {
                printf("sparse majorant, two emitting blobs 5104 voxels apart: %.2f MiB, power %.6g (one blob %.6g)\n",
                       m.memory_bytes / 1048576.0, (double)medium_emission_power(&m), (double)medium_emission_power(&m1));
                CHECK(m.majorant.bricks.entries != NULL && m.memory_bytes < (1u << 20), "emitting blobs: %.2f MiB, sparse %d",
                      m.memory_bytes / 1048576.0, m.majorant.bricks.entries != NULL);
                CHECK(fabs(medium_emission_power(&m) - 2.0 * medium_emission_power(&m1)) < 1e-5 * medium_emission_power(&m),
                      "emitting blobs: power %g, not twice %g", (double)medium_emission_power(&m), (double)medium_emission_power(&m1));
                const float o[3] = {2.5f, 2.6f, 2.4f};
                long far = 0, bad = 0;
                enum { NS = 20000 };
                for (int i = 0; i < NS; ++i) {
                    float p[3];
                    float pv = medium_emission_sample(&m, (float)urand(&r), (float)urand(&r), (float)urand(&r), (float)urand(&r), p);
                    far += p[0] > 1.0f;
                    float d[3] = {p[0] - o[0], p[1] - o[1], p[2] - o[2]};
                    if (!(pv > 0.0f) || !(medium_emission_pdf(&m, o, d) > 0.0f)) ++bad;
                }
                CHECK(bad == 0, "emitting blobs: %ld samples with a zero pdf", bad);
                CHECK(fabs((double)far - 0.5 * NS) < 5.0 * sqrt(0.25 * NS), "emitting blobs: %ld of %d samples in the far blob", far, NS);
                /* majorant bounds over rays aimed at both blobs */
                const float targets[2][3] = {{0.002f, 0.002f, 0.002f}, {5.106f, 5.106f, 5.106f}};
                long segments = 0, tiling = 0;
                long violations = majorant_rays(&m, &r, 1000, targets, 2, &segments, &tiling);
                CHECK(violations == 0 && tiling == 0, "emitting blobs: %ld violations, %ld tiling errors", violations, tiling);
            }
            if (rc2 == 0) medium_free(&m);
            if (rc1 == 0) medium_free(&m1);
        }
        io_volume_grid_free(&gd);
        io_volume_grid_free(&ge);
        io_volume_grid_free(&gd1);
        io_volume_grid_free(&ge1);
    }

    /* the regions' defaults and borders: two root tiles of different values side by side, a
     * 128^3 upper tile of a third value inside one, an 8^3 box of a fourth, voxels on the
     * borders; bounds and tiling over rays aimed at every border */
    {
        const int32_t boxes[4 * 6] = {0,    0,    0,    4095, 4095, 4095, 4096, 0,   0,   8191, 4095, 4095,
                                      3968, 3968, 3968, 4095, 4095, 4095, 4096, 512, 512, 4103, 519,  519};
        const float bvals[4] = {0.25f, 1.0f, 2.5f, 0.0f};
        const int32_t vox[3 * 3] = {4095, 100, 100, 4096, 4095, 4095, 8191, 0, 0};
        const float vv[3] = {4.0f, 0.0f, 6.0f};
        rc = io_volume_grid_from_voxels(vox, vv, 3, boxes, bvals, 4, i2w, "density", &g, err);
        CHECK(rc == 0, "root tiles side by side: %s", err);
        if (rc == 0) {
            VolumeDesc desc = grid_desc(&g, 3.0f, 0.5f);
            Medium m;
            rc = medium_init_vdb(&m, &desc, err);
            CHECK(rc == 0, "root tiles side by side: %s", err);
            if (rc == 0) {
                printf("sparse majorant, two root tiles and details: %.2f MiB\n", m.memory_bytes / 1048576.0);
                CHECK(m.majorant.bricks.entries != NULL && m.memory_bytes < (16u << 20), "root tiles: %.1f MiB, sparse %d",
                      m.memory_bytes / 1048576.0, m.majorant.bricks.entries != NULL);
                const float targets[6][3] = {{4.096f, 2.0f, 2.0f},     {4.0f, 4.0f, 4.0f},      {4.1f, 0.516f, 0.516f},
                                             {4.0955f, 0.1f, 0.1f},    {8.1915f, 0.0f, 0.0f},   {4.096f, 4.0955f, 4.0955f}};
                long segments = 0, tiling = 0;
                long violations = majorant_rays(&m, &r, 1200, targets, 6, &segments, &tiling);
                violations += majorant_rays(&m, &r, 400, NULL, 0, &segments, &tiling);
                CHECK(violations == 0, "root tiles: %ld points above their majorant or below their control", violations);
                CHECK(tiling == 0, "root tiles: %ld tiling errors", tiling);
                medium_free(&m);
            }
            io_volume_grid_free(&g);
        }
    }

    /* a voxel of 1e30: world bounds beyond the coordinate limit, refused at once by the reader;
     * and a grid of 100 m voxels that a node scales by 1e11, by the medium */
    const float one = 1.0f;
    const int32_t at[3] = {0, 0, 0};
    scale_translate(i2w, 1e30f, 0.0f, 0.0f, 0.0f);
    rc = io_volume_grid_from_voxels(at, &one, 1, NULL, NULL, 0, i2w, "density", &g, err);
    CHECK(rc != 0 && one_line(err) && strstr(err, "reach beyond 1e+12 in the world (voxel size 1e+30)"), "a 1e30 voxel: %s", rc ? err : "accepted");
    if (rc == 0) io_volume_grid_free(&g);
    scale_translate(i2w, 100.0f, 0.0f, 0.0f, 0.0f);
    rc = io_volume_grid_from_voxels(at, &one, 1, NULL, NULL, 0, i2w, "density", &g, err);
    CHECK(rc == 0, "a 100 m voxel: %s", err);
    if (rc == 0) {
        VolumeDesc desc = grid_desc(&g, 1.0f, 0.5f);
        scale_translate(desc.node_to_world, 1e11f, 0.0f, 0.0f, 0.0f);
        Medium m;
        rc = medium_init_vdb(&m, &desc, err);
        CHECK(rc != 0 && one_line(err) && strstr(err, "beyond 1e+12"), "a node scaling a grid past 1e12: %s", rc ? err : "accepted");
        if (rc == 0) medium_free(&m);
        io_volume_grid_free(&g);
    }
}

int main(int argc, char **argv) {
    double t0 = test_seconds();
    test_distance_table();
    test_bad_input();
    test_hg();
    test_blackbody();
    test_beer_lambert();
    test_scatter_distance();
    test_heterogeneous();
    test_majorant();
    test_majorant_sparse();
    test_emission();
    test_emission_sampling();
    test_emission_line();
    test_overlap();
    if (argc > 1) test_slab_asset(argv[1]);
    printf("volumes: %.1f s\n", test_seconds() - t0);
    return test_exit();
}
