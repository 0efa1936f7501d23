/* tests/test_sdtree.c: the guiding field (guiding/sdtree.c, Müller et al. 2017 SD-tree).
 * Uniform before training; after training on a bright cone plus a dim constant: the pdf
 * integrates to 1 (equal-area grid, the (u, v) image and Monte Carlo), sample and pdf agree
 * pointwise and in a chi-square histogram (which must reject a transposed or mirrored
 * histogram), the cone is learned and the quadtree refined; spatial splitting separates two
 * regions with different bright directions; the memory cap bounds splitting; two fields fed
 * the same samples are bit-identical; the directional filter spreads a sample over a cell-sized box
 * around it (and only with it on); bad samples are skipped and do not count; outside
 * points get a valid distribution; the PLY export; each leaf learns the BSDF share of guided MIS
 * that minimises its estimator's second moment, within the floor. Fixed seeds, no timing
 * assertions. */
#include "check.h"
#include "guiding.h"
#include "stats.h"

#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#define PI 3.14159265358979323846
#define UNIFORM_PDF ((float)(1.0 / (4.0 * PI)))

static float rnd(uint64_t *s) { return (float)splitmix_uniform(s); }

static void uniform_dir(uint64_t *s, float d[3]) {
    double z = 1 - 2 * splitmix_uniform(s), phi = 2 * PI * splitmix_uniform(s);
    double r = sqrt(fmax(0.0, 1 - z * z));
    d[0] = (float)(r * cos(phi));
    d[1] = (float)(r * sin(phi));
    d[2] = (float)z;
}

static void normalize(float d[3]) {
    float l = sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int k = 0; k < 3; ++k) d[k] /= l;
}

static float dot(const float a[3], const float b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* The (u, v) of a direction, as guiding.h defines the mapping (the octahedral map, written
 * here again): the direction over its L1 norm, the lower half folded to the corners. */
static void dir_uv(const float d[3], double *u, double *v) {
    double l1 = fabs(d[0]) + fabs(d[1]) + fabs(d[2]), a = d[0] / l1, b = d[1] / l1;
    if (d[2] < 0) {
        double fa = copysign(1 - fabs(b), a), fb = copysign(1 - fabs(a), b);
        a = fa;
        b = fb;
    }
    *u = 0.5 * (a + 1);
    *v = 0.5 * (b + 1);
}

/* The solid angle per unit of (u, v) area at (u, v): 4 / |p|^3, p the octahedron's point. */
static double solid_angle_per_uv(double u, double v) {
    double a = 2 * u - 1, b = 2 * v - 1, z = 1 - fabs(a) - fabs(b);
    if (z < 0) {
        double fa = copysign(1 - fabs(b), a), fb = copysign(1 - fabs(a), b);
        a = fa;
        b = fb;
    }
    double p2 = a * a + b * b + z * z;
    return 4.0 / (p2 * sqrt(p2));
}

/* The density an untrained leaf has for direction d: uniform over the (u, v) square. */
static float map_pdf(const float d[3]) {
    double u, v;
    dir_uv(d, &u, &v);
    return (float)(1.0 / solid_angle_per_uv(u, v));
}

/* A light field: radiance `bright` inside the cone of half-angle acos(cos_cone) around axis,
 * `dim` elsewhere; directions sampled uniformly (pdf 1/4pi) at positions uniform in a box. */
typedef struct {
    float axis[3], cos_cone, bright, dim;
    float lo[3], hi[3];
} Light;

/* What a training sample's leaf hint says: nothing, the leaf a lookup at its point finds, or a
 * wrong leaf (another one, drawn; or, for a point moved onto its leaf's high face, which the >=
 * rule gives the neighbour, that leaf). Every mode must train the same field. */
enum { HINT_NONE, HINT_RIGHT, HINT_WRONG };

static void train_hinted(GuideField *f, uint64_t *rng, const Light *L, int n, int hints) {
    GuideTrainingSample batch[512];
    int m = 0;
    for (int i = 0; i < n; ++i) {
        GuideTrainingSample *s = &batch[m++];
        memset(s, 0, sizeof *s); /* no BSDF-share statistic */
        for (int k = 0; k < 3; ++k) s->pos[k] = L->lo[k] + (L->hi[k] - L->lo[k]) * rnd(rng);
        uniform_dir(rng, s->dir);
        s->radiance = dot(s->dir, L->axis) > L->cos_cone ? L->bright : L->dim;
        s->pdf = UNIFORM_PDF;
        const GuideDistribution *d = guide_field_lookup(f, s->pos);
        uint32_t leaf = guide_field_leaf_of(f, d), leaves = guide_field_num_leaves(f);
        if (i % 3 == 0) { /* every mode: the point moved onto its leaf's high face on one axis */
            float lo[3], hi[3];
            guide_distribution_bounds(d, lo, hi);
            if (hi[i % 7 % 3] < 1.0f) s->pos[i % 7 % 3] = hi[i % 7 % 3]; /* an inner face */
        }
        s->leaf = hints == HINT_NONE ? GUIDE_NO_LEAF
                  : hints == HINT_RIGHT ? guide_field_leaf_of(f, guide_field_lookup(f, s->pos))
                  : i % 3 == 0 ? leaf
                               : (leaf + 1 + (uint32_t)i * 2654435761u % leaves) % (leaves + 1); /* never leaf; may be out of range */
        if (m == 512 || i == n - 1) {
            guide_field_record(f, batch, (size_t)m);
            m = 0;
        }
    }
}

static void train(GuideField *f, uint64_t *rng, const Light *L, int n) { train_hinted(f, rng, L, n, HINT_NONE); }

/* The integral of the pdf over the sphere from the (u, v) image (midpoint rule: the pixels'
 * solid angles from the map's density) and from an equal-area grid of directions. The image
 * holds solid-angle densities: *img becomes each pixel's probability. */
static double integral_image(const GuideDistribution *d, int res, float *img) {
    guide_distribution_image(d, res, res, img);
    double sum = 0;
    for (int j = 0; j < res; ++j)
        for (int i = 0; i < res; ++i) {
            double w = solid_angle_per_uv((i + 0.5) / res, (j + 0.5) / res) / ((double)res * res);
            img[j * res + i] = (float)(img[j * res + i] * w);
            sum += img[j * res + i];
        }
    return sum;
}

static double integral_grid(const GuideDistribution *d, int res) {
    double sum = 0;
    for (int j = 0; j < res; ++j)
        for (int i = 0; i < res; ++i) {
            double u = (i + 0.5) / res, v = (j + 0.5) / res;
            double z = 2 * u - 1, r = sqrt(fmax(0.0, 1 - z * z)), phi = 2 * PI * v;
            float dir[3] = {(float)(r * cos(phi)), (float)(r * sin(phi)), (float)z};
            sum += guide_distribution_pdf(d, dir);
        }
    return sum * 4 * PI / ((double)res * res);
}

static int bits_equal(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

/* ---------------------------------------------------------------- 1. uniform over the square before training */
static void test_uniform(void) {
    float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    GuideField *f = guide_field_create(lo, hi, NULL);
    CHECK(f != NULL, "create");
    if (!f) return;
    CHECK(guide_field_iterations(f) == 0, "iterations %d", guide_field_iterations(f));
    CHECK(guide_field_num_leaves(f) == 1, "leaves %u", guide_field_num_leaves(f));
    uint64_t rng = 1;
    int bad_pdf = 0, bad_len = 0, bad_sample_pdf = 0;
    for (int i = 0; i < 2000; ++i) {
        float pos[3] = {rnd(&rng), rnd(&rng), rnd(&rng)}, dir[3];
        const GuideDistribution *d = guide_field_lookup(f, pos);
        uniform_dir(&rng, dir);
        float want = map_pdf(dir);
        bad_pdf += fabsf(guide_distribution_pdf(d, dir) - want) > 1e-5f * want;
        float s[3], pdf;
        guide_distribution_sample(d, rnd(&rng), rnd(&rng), s, &pdf);
        bad_len += fabsf(sqrtf(dot(s, s)) - 1) > 1e-5f;
        bad_sample_pdf += fabsf(pdf - map_pdf(s)) > 1e-5f * map_pdf(s);
    }
    CHECK(bad_pdf == 0, "%d pdfs differ from the map's density", bad_pdf);
    CHECK(bad_len == 0, "%d sampled directions not unit length", bad_len);
    CHECK(bad_sample_pdf == 0, "%d sample pdfs differ from the map's density", bad_sample_pdf);
    float img[64];
    double total = integral_image(guide_field_lookup(f, lo), 8, img);
    int bad_img = 0;
    for (int i = 0; i < 64; ++i) bad_img += fabsf(img[i] - 1.0f / 64) > 1e-6f; /* equal probability per pixel */
    CHECK(bad_img == 0, "%d image pixels not uniform over the square", bad_img);
    CHECK(fabs(total - 1) < 1e-5, "integral %g", total);
    /* An update without samples learns nothing: still uniform. */
    CHECK(guide_field_update(f, 1.0f) == 0, "empty update");
    CHECK(guide_field_iterations(f) == 1, "iterations %d", guide_field_iterations(f));
    float z[3] = {0, 0, 1};
    CHECK(guide_distribution_pdf(guide_field_lookup(f, lo), z) == map_pdf(z), "uniform after an empty update");
    guide_field_free(f);
}

/* ---------------------------------------------------------------- 2-4. the trained cone */
static void test_trained(void) {
    float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    Light L = {{0.3f, -0.5f, 0.8f}, 0, 100.0f, 0.1f, {0, 0, 0}, {1, 1, 1}};
    normalize(L.axis);
    L.cos_cone = cosf(15.0f * (float)PI / 180.0f);
    float anti[3] = {-L.axis[0], -L.axis[1], -L.axis[2]}, centre[3] = {0.5f, 0.5f, 0.5f};
    GuideFieldParams c12k; /* PPG's c, which the leaf counts below are worked out for */
    guide_field_params_default(&c12k);
    c12k.spatial_threshold = 12000.0f;
    GuideField *f = guide_field_create(lo, hi, &c12k);
    CHECK(f != NULL, "create");
    if (!f) return;
    uint64_t rng = 42;
    size_t bytes0 = guide_field_bytes(f);

    /* 4. One update learns the cone. */
    train(f, &rng, &L, 50000);
    CHECK(guide_field_update(f, 1.0f) == 0, "update 0");
    size_t bytes1 = guide_field_bytes(f);
    const GuideDistribution *d = guide_field_lookup(f, centre);
    float p_axis = guide_distribution_pdf(d, L.axis), p_anti = guide_distribution_pdf(d, anti);
    fprintf(stderr, "after 1 update: leaves %u, bytes %zu -> %zu, pdf(axis) %g, pdf(-axis) %g (ratio %.0f)\n",
            guide_field_num_leaves(f), bytes0, bytes1, p_axis, p_anti, p_axis / p_anti);
    CHECK(p_axis > 10 * p_anti, "pdf toward the cone %g vs away %g", p_axis, p_anti);
    CHECK(bytes1 > bytes0, "bytes %zu -> %zu", bytes0, bytes1);
    /* 50000 samples against c = 12000: 50000 / 2^3 < 12000 <= 50000 / 2^2: eight leaves. */
    CHECK(guide_field_num_leaves(f) == 8, "leaves %u", guide_field_num_leaves(f));

    /* Two more iterations with doubling sample counts (the threshold grows by sqrt 2 each). */
    train(f, &rng, &L, 100000);
    CHECK(guide_field_update(f, 1.0f) == 0, "update 1");
    train(f, &rng, &L, 200000);
    CHECK(guide_field_update(f, 1.0f) == 0, "update 2");
    CHECK(guide_field_iterations(f) == 3, "iterations %d", guide_field_iterations(f));
    d = guide_field_lookup(f, centre);
    p_axis = guide_distribution_pdf(d, L.axis);
    p_anti = guide_distribution_pdf(d, anti);
    fprintf(stderr, "after 3 updates: leaves %u, bytes %zu, pdf(axis) %g, pdf(-axis) %g (ratio %.0f)\n",
            guide_field_num_leaves(f), guide_field_bytes(f), p_axis, p_anti, p_axis / p_anti);
    CHECK(p_axis > 100 * p_anti, "pdf toward the cone %g vs away %g", p_axis, p_anti);

    /* Refined below the initial 16 x 16 cells: two pixels of one 1/16 cell differ. */
    enum { RES = 1024 };
    float *img = malloc(sizeof(float) * RES * RES);
    CHECK(img != NULL, "malloc");
    if (!img) {
        guide_field_free(f);
        return;
    }
    double img_integral = integral_image(d, RES, img);
    int refined = 0;
    for (int j = 0; j < RES && !refined; ++j)
        for (int i = 1; i < RES; ++i)
            if (i % (RES / 16) && img[j * RES + i] != img[j * RES + i - 1]) {
                refined = 1;
                break;
            }
    CHECK(refined, "no cell finer than 1/16 after three updates");

    /* 2. The pdf integrates to 1. */
    double grid_integral = integral_grid(d, RES);
    fprintf(stderr, "integral: image %.7f, direction grid %.7f\n", img_integral, grid_integral);
    CHECK(fabs(img_integral - 1) < 1e-4, "image integral %.7f", img_integral);
    CHECK(fabs(grid_integral - 1) < 1e-3, "grid integral %.7f", grid_integral);
    {
        uint64_t r = 7;
        const int n = 400000;
        double sum = 0, sum2 = 0;
        for (int i = 0; i < n; ++i) {
            float dir[3];
            uniform_dir(&r, dir);
            double x = 4 * PI * guide_distribution_pdf(d, dir);
            sum += x;
            sum2 += x * x;
        }
        double mean = sum / n, se = sqrt(fmax(0.0, sum2 / n - mean * mean) / n);
        fprintf(stderr, "Monte Carlo integral %.5f +- %.5f (%.2f standard errors)\n", mean, se, (mean - 1) / se);
        CHECK(se > 0 && fabs(mean - 1) < 5 * se, "MC integral %.5f, standard error %.5f", mean, se);
    }

    /* 3. Sampling agrees with the pdf: pointwise, and in a histogram over (u, v). */
    {
        enum { BINS = 32, PER = RES / BINS };
        static double obs[BINS * BINS], obs_t[BINS * BINS], obs_m[BINS * BINS], expv[BINS * BINS];
        memset(obs, 0, sizeof obs);
        const int n = 400000;
        uint64_t r = 99;
        int mismatch = 0, off_edge = 0, nonpositive = 0, bad_len = 0;
        for (int i = 0; i < n; ++i) {
            float dir[3], pdf;
            guide_distribution_sample(d, rnd(&r), rnd(&r), dir, &pdf);
            float q = guide_distribution_pdf(d, dir);
            if (fabsf(pdf - q) > 1e-4f * q) {
                /* the one way they may differ: a point sampled a rounding error from its cell's
                 * edge whose float direction maps back across it (edges lie on multiples of 2^-10,
                 * the finest cells' side) */
                double eu, ev;
                dir_uv(dir, &eu, &ev);
                eu *= 1024.0;
                ev *= 1024.0;
                off_edge += fabs(eu - floor(eu + 0.5)) > 1e-3 && fabs(ev - floor(ev + 0.5)) > 1e-3;
                ++mismatch;
            }
            nonpositive += !(pdf > 0);
            bad_len += fabsf(sqrtf(dot(dir, dir)) - 1) > 1e-5f;
            double u, v;
            dir_uv(dir, &u, &v);
            int bu = (int)(u * BINS), bv = (int)(v * BINS);
            bu = bu < 0 ? 0 : bu >= BINS ? BINS - 1 : bu;
            bv = bv < 0 ? 0 : bv >= BINS ? BINS - 1 : bv;
            obs[bv * BINS + bu] += 1;
        }
        fprintf(stderr, "%d of %d sample pdfs differ from guide_distribution_pdf at a cell's edge\n", mismatch, n);
        CHECK(off_edge == 0, "%d sample pdfs differ from guide_distribution_pdf away from a cell's edge", off_edge);
        CHECK(mismatch <= n / 10000, "%d sample pdfs differ from guide_distribution_pdf", mismatch);
        CHECK(nonpositive == 0, "%d sampled directions with pdf <= 0", nonpositive);
        CHECK(bad_len == 0, "%d sampled directions not unit length", bad_len);
        /* Expected counts: the probabilities of each bin's image pixels (integral_image made them so). */
        for (int b = 0; b < BINS * BINS; ++b) expv[b] = 0;
        for (int j = 0; j < RES; ++j)
            for (int i = 0; i < RES; ++i) expv[(j / PER) * BINS + i / PER] += img[j * RES + i];
        for (int b = 0; b < BINS * BINS; ++b) expv[b] *= n;
        /* The same counts transposed (u and v swapped) and mirrored in v must be rejected:
         * the test can tell a sampler that confuses the axes. */
        for (int j = 0; j < BINS; ++j)
            for (int i = 0; i < BINS; ++i) {
                obs_t[j * BINS + i] = obs[i * BINS + j];
                obs_m[j * BINS + i] = obs[(BINS - 1 - j) * BINS + i];
            }
        int dof, dof_t, dof_m;
        double stat, stat_t, stat_m;
        double pv = chi2_pvalue(obs, expv, BINS * BINS, &dof, &stat);
        double pv_t = chi2_pvalue(obs_t, expv, BINS * BINS, &dof_t, &stat_t);
        double pv_m = chi2_pvalue(obs_m, expv, BINS * BINS, &dof_m, &stat_m);
        fprintf(stderr, "chi-square %.1f (dof %d, p %.4f); transposed %.3g (p %.3g); mirrored %.3g (p %.3g)\n", stat,
                dof, pv, stat_t, pv_t, stat_m, pv_m);
        CHECK(pv > 1e-4, "sample histogram vs pdf: chi2 %.1f dof %d p %g", stat, dof, pv);
        CHECK(pv_t < 1e-9, "transposed histogram not rejected: p %g", pv_t);
        CHECK(pv_m < 1e-9, "mirrored histogram not rejected: p %g", pv_m);
    }
    free(img);
    guide_field_free(f);
}

/* ---------------------------------------------------------------- 5. spatial splitting */
static GuideField *two_regions_hinted(uint64_t seed, int updates, int hints) {
    float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    GuideFieldParams p;
    guide_field_params_default(&p);
    p.spatial_threshold = 100;
    GuideField *f = guide_field_create(lo, hi, &p);
    if (!f) return NULL;
    Light a = {{0, 0, 1}, 0, 50.0f, 0.05f, {0, 0, 0}, {0.2f, 0.2f, 0.2f}};
    Light b = {{-1, 0, 0}, 0, 50.0f, 0.05f, {0.8f, 0.8f, 0.8f}, {1, 1, 1}};
    a.cos_cone = b.cos_cone = cosf(20.0f * (float)PI / 180.0f);
    uint64_t rng = seed;
    for (int it = 0; it < updates; ++it) {
        train_hinted(f, &rng, &a, 3000 << it, hints);
        train_hinted(f, &rng, &b, 3000 << it, hints);
        if (guide_field_update(f, 1.0f)) {
            guide_field_free(f);
            return NULL;
        }
    }
    return f;
}

static GuideField *two_regions(uint64_t seed, int updates) { return two_regions_hinted(seed, updates, HINT_NONE); }

static int box_contains(const GuideDistribution *d, const float p[3]) {
    float lo[3], hi[3];
    guide_distribution_bounds(d, lo, hi);
    for (int k = 0; k < 3; ++k)
        if (!(p[k] >= lo[k] && p[k] <= hi[k])) return 0;
    return 1;
}

static void test_spatial(void) {
    GuideField *f = two_regions(5, 3);
    CHECK(f != NULL, "two_regions");
    if (!f) return;
    float pa[3] = {0.1f, 0.1f, 0.1f}, pb[3] = {0.9f, 0.9f, 0.9f};
    float up[3] = {0, 0, 1}, left[3] = {-1, 0, 0}, cos_cone = cosf(20.0f * (float)PI / 180.0f);
    const GuideDistribution *da = guide_field_lookup(f, pa), *db = guide_field_lookup(f, pb);
    /* The preference as the probability mass each leaf puts into either cone (3% each under
     * a uniform pdf). A point pdf would be a poor measure here: small leaves learn from few
     * cone samples, and a cone around the pole spreads them over all the v cells. */
    double a_up = 0, a_left = 0, b_up = 0, b_left = 0;
    uint64_t rng = 31;
    const int n = 20000;
    for (int i = 0; i < n; ++i) {
        float dir[3], pdf;
        guide_distribution_sample(da, rnd(&rng), rnd(&rng), dir, &pdf);
        a_up += dot(dir, up) > cos_cone;
        a_left += dot(dir, left) > cos_cone;
        guide_distribution_sample(db, rnd(&rng), rnd(&rng), dir, &pdf);
        b_up += dot(dir, up) > cos_cone;
        b_left += dot(dir, left) > cos_cone;
    }
    a_up /= n, a_left /= n, b_up /= n, b_left /= n;
    fprintf(stderr, "two regions: %u leaves, %zu bytes; mass in the +z / -x cones: A %.3f / %.3f, B %.3f / %.3f\n",
            guide_field_num_leaves(f), guide_field_bytes(f), a_up, a_left, b_up, b_left);
    CHECK(guide_field_num_leaves(f) > 1, "leaves %u", guide_field_num_leaves(f));
    CHECK(da != db, "the two regions share a leaf");
    CHECK(box_contains(da, pa) && box_contains(db, pb), "leaf boxes do not contain their points");
    CHECK(a_up > 0.5 && a_left < 0.1, "region A prefers +z: %.3f vs %.3f", a_up, a_left);
    CHECK(b_left > 0.5 && b_up < 0.1, "region B prefers -x: %.3f vs %.3f", b_left, b_up);
    /* Every leaf's box contains the points that look it up. */
    rng = 3;
    int outside = 0;
    for (int i = 0; i < 2000; ++i) {
        float p[3] = {rnd(&rng), rnd(&rng), rnd(&rng)};
        outside += !box_contains(guide_field_lookup(f, p), p);
    }
    CHECK(outside == 0, "%d lookups outside their leaf's box", outside);
    /* The descent (its depth-12 grid, then the nodes) follows the >= split rule exactly: a leaf's
     * low corner, on split planes on every axis, finds the leaf; the float just below its high
     * corner finds it; its high face, where that is inside the field, finds a neighbour. */
    int wrong = 0, corners = 0;
    for (int i = 0; i < 4000; ++i) {
        float p[3] = {rnd(&rng), rnd(&rng), rnd(&rng)}, lo[3], hi[3];
        const GuideDistribution *d = guide_field_lookup(f, p);
        guide_distribution_bounds(d, lo, hi);
        float below[3] = {nextafterf(hi[0], lo[0]), nextafterf(hi[1], lo[1]), nextafterf(hi[2], lo[2])};
        wrong += guide_field_lookup(f, lo) != d;
        wrong += guide_field_lookup(f, below) != d;
        for (int k = 0; k < 3; ++k) {
            if (!(hi[k] < 1.0f)) continue; /* the field's bounds are [0, 1]: hi[k] is a split */
            float q[3] = {lo[0], lo[1], lo[2]};
            q[k] = hi[k];
            wrong += guide_field_lookup(f, q) == d;
            ++corners;
        }
    }
    CHECK(wrong == 0 && corners > 1000, "%d lookups on split planes miss the >= rule (%d faces)", wrong, corners);
    guide_field_free(f);

    /* The memory cap bounds splitting: many zero-radiance samples (no flux, so the quadtrees
     * keep their size) with c = 1 would split deep; the cap stops it. */
    float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    GuideFieldParams p;
    guide_field_params_default(&p);
    p.spatial_threshold = 1;
    GuideField *probe = guide_field_create(lo, hi, &p);
    CHECK(probe != NULL, "create");
    if (!probe) return;
    size_t cap = 10 * guide_field_bytes(probe);
    guide_field_free(probe);
    p.max_bytes = cap;
    GuideField *capped = guide_field_create(lo, hi, &p);
    CHECK(capped != NULL, "create");
    if (!capped) return;
    Light dark = {{0, 0, 1}, 0.5f, 0, 0, {0, 0, 0}, {1, 1, 1}};
    rng = 11;
    train(capped, &rng, &dark, 4000);
    CHECK(guide_field_update(capped, 1.0f) == 0, "capped update");
    fprintf(stderr, "memory cap %zu: %u leaves, %zu bytes\n", cap, guide_field_num_leaves(capped),
            guide_field_bytes(capped));
    CHECK(guide_field_num_leaves(capped) > 1, "capped field did not split at all");
    CHECK(guide_field_num_leaves(capped) < 4000, "cap did not limit splitting: %u leaves", guide_field_num_leaves(capped));
    CHECK(guide_field_bytes(capped) <= cap, "bytes %zu above the cap %zu", guide_field_bytes(capped), cap);
    guide_field_free(capped);
}

/* ---------------------------------------------------------------- 6. determinism */
static void test_determinism(void) {
    GuideField *f = two_regions(17, 3), *g = two_regions(17, 3);
    CHECK(f && g, "two_regions");
    if (f && g) {
        CHECK(guide_field_num_leaves(f) == guide_field_num_leaves(g), "leaves %u vs %u", guide_field_num_leaves(f),
              guide_field_num_leaves(g));
        CHECK(guide_field_bytes(f) == guide_field_bytes(g), "bytes %zu vs %zu", guide_field_bytes(f),
              guide_field_bytes(g));
        uint64_t rng = 23;
        int differ = 0;
        for (int i = 0; i < 5000; ++i) {
            float pos[3] = {rnd(&rng), rnd(&rng), rnd(&rng)}, dir[3];
            uniform_dir(&rng, dir);
            const GuideDistribution *a = guide_field_lookup(f, pos), *b = guide_field_lookup(g, pos);
            differ += !bits_equal(guide_distribution_pdf(a, dir), guide_distribution_pdf(b, dir));
            float u1 = rnd(&rng), u2 = rnd(&rng), da[3], db[3], pa, pb;
            guide_distribution_sample(a, u1, u2, da, &pa);
            guide_distribution_sample(b, u1, u2, db, &pb);
            differ += memcmp(da, db, sizeof da) != 0 || !bits_equal(pa, pb);
        }
        CHECK(differ == 0, "%d pdfs or samples differ between identical fields", differ);
    }
    guide_field_free(f);
    guide_field_free(g);
}

/* ---------------------------------------------------------------- 6b. checkpoints */
/* A trained field saved and loaded into a fresh field samples, evaluates and keeps training
 * exactly as the original; a truncated or foreign record is refused and leaves the field as it
 * was. */
static int fields_equal(const GuideField *f, const GuideField *g, uint64_t seed) {
    uint64_t rng = seed;
    int differ = guide_field_num_leaves(f) != guide_field_num_leaves(g) || guide_field_bytes(f) != guide_field_bytes(g) ||
                 guide_field_iterations(f) != guide_field_iterations(g);
    for (int i = 0; i < 3000; ++i) {
        float pos[3] = {rnd(&rng), rnd(&rng), rnd(&rng)}, dir[3];
        uniform_dir(&rng, dir);
        const GuideDistribution *a = guide_field_lookup(f, pos), *b = guide_field_lookup(g, pos);
        differ += !bits_equal(guide_distribution_pdf(a, dir), guide_distribution_pdf(b, dir));
        float u1 = rnd(&rng), u2 = rnd(&rng), da[3], db[3], pa, pb;
        guide_distribution_sample(a, u1, u2, da, &pa);
        guide_distribution_sample(b, u1, u2, db, &pb);
        differ += memcmp(da, db, sizeof da) != 0 || !bits_equal(pa, pb);
    }
    for (int i = 0; i < 300; ++i) { /* the learned BSDF shares too */
        float pos[3] = {rnd(&rng), rnd(&rng), rnd(&rng)};
        differ += !bits_equal(guide_distribution_bsdf_share(guide_field_lookup(f, pos)),
                              guide_distribution_bsdf_share(guide_field_lookup(g, pos)));
    }
    return differ == 0;
}

/* Whether guide_field_load accepts the first `bytes` of buf (0 when no temporary file). */
static int loads_from(GuideField *g, const char *buf, long bytes) {
    FILE *t = tmpfile();
    if (!t) return 0;
    fwrite(buf, 1, (size_t)bytes, t);
    rewind(t);
    int ok = guide_field_load(g, t) == 0;
    fclose(t);
    return ok;
}

static void test_checkpoint(void) {
    GuideField *f = two_regions(31, 3);
    float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    GuideFieldParams p;
    guide_field_params_default(&p);
    p.spatial_threshold = 100;
    GuideField *g = guide_field_create(lo, hi, &p);
    FILE *tmp = tmpfile();
    CHECK(f && g && tmp, "setup");
    if (!f || !g || !tmp) return;
    /* half an iteration's training pending in the building trees, as at a batch boundary */
    Light a = {{0, 0, 1}, 0, 50.0f, 0.05f, {0, 0, 0}, {0.2f, 0.2f, 0.2f}};
    a.cos_cone = cosf(20.0f * (float)PI / 180.0f);
    uint64_t rng = 99;
    train(f, &rng, &a, 5000);
    CHECK(guide_field_save(f, tmp) == 0, "save");
    long size = ftell(tmp);
    rewind(tmp);
    CHECK(guide_field_load(g, tmp) == 0, "load");
    CHECK(ftell(tmp) == size, "load read %ld of %ld bytes", ftell(tmp), size);
    CHECK(fields_equal(f, g, 5), "the loaded field differs");
    uint64_t r1 = 7, r2 = 7; /* both continue training identically */
    train(f, &r1, &a, 4000);
    train(g, &r2, &a, 4000);
    CHECK(guide_field_update(f, 2.0f) == 0 && guide_field_update(g, 2.0f) == 0, "update");
    CHECK(fields_equal(f, g, 6), "the loaded field trains differently");
    /* truncated at 64 points along it: refused, the field untouched */
    unsigned leaves = guide_field_num_leaves(g);
    int accepted = 0;
    char *buf = malloc((size_t)size);
    rewind(tmp);
    if (buf && fread(buf, 1, (size_t)size, tmp) == (size_t)size) {
        for (long cut = 0; cut < size; cut += size / 64 + 1) accepted += loads_from(g, buf, cut);
        /* a tree the splits cannot make (the lookup grid relies on axis = depth % 3, children
         * one deeper): the root's axis, then its first child's depth, changed. Records: a 28-byte
         * head, then 38 bytes a node (box, split, child, leaf, axis at 36, depth at 37) */
        const long node0 = 28, node_bytes = 38;
        for (int which = 0; which < 2 && size > node0 + 2 * node_bytes; ++which) {
            long at = which == 0 ? node0 + 36 : node0 + node_bytes + 37;
            buf[at] ^= 0x01;
            accepted += loads_from(g, buf, size);
            buf[at] ^= 0x01;
        }
        buf[0] ^= 0x55; /* a foreign magic */
        accepted += loads_from(g, buf, size);
    }
    CHECK(accepted == 0, "%d damaged records loaded", accepted);
    CHECK(guide_field_num_leaves(g) == leaves && fields_equal(f, g, 8), "a refused load changed the field");
    free(buf);
    fclose(tmp);
    guide_field_free(f);
    guide_field_free(g);
}

/* ---------------------------------------------------------------- 6c. leaf hints */
/* A training sample's leaf hint spares the descent but never changes what is learned: right
 * hints, none, and wrong ones (other leaves, out of range, a leaf whose high face the point lies
 * on) train bit for bit the same field; guide_field_leaf_of names only the field's own leaves. */
static void test_leaf_hints(void) {
    GuideField *f = two_regions_hinted(29, 3, HINT_NONE), *g = two_regions_hinted(29, 3, HINT_RIGHT),
               *h = two_regions_hinted(29, 3, HINT_WRONG);
    CHECK(f && g && h, "two_regions_hinted");
    if (f && g && h) {
        CHECK(guide_field_num_leaves(f) > 8, "a tree to hint into: %u leaves", guide_field_num_leaves(f));
        CHECK(fields_equal(f, g, 31), "right hints change the field");
        CHECK(fields_equal(f, h, 31), "wrong hints change the field");
        uint64_t rng = 37;
        int bad = 0;
        for (int i = 0; i < 2000; ++i) {
            float pos[3] = {rnd(&rng), rnd(&rng), rnd(&rng)};
            const GuideDistribution *d = guide_field_lookup(f, pos);
            uint32_t leaf = guide_field_leaf_of(f, d);
            bad += leaf >= guide_field_num_leaves(f) || !box_contains(d, pos) || guide_field_leaf_of(g, d) != GUIDE_NO_LEAF;
        }
        CHECK(bad == 0, "%d lookups named a wrong leaf index", bad);
        CHECK(guide_field_leaf_of(f, NULL) == GUIDE_NO_LEAF, "leaf_of(NULL)");
    }
    guide_field_free(f);
    guide_field_free(g);
    guide_field_free(h);
}

/* ---------------------------------------------------------------- 6d. the learned BSDF share */
/* Guided MIS samples of an integrand F = 1 inside a cone of 30 degrees around +z, 0 elsewhere,
 * drawn uniformly over the sphere (p = 1/4pi; the statistic is an importance-weighted estimate, so
 * any p it is told will do), in the box [x0, x1] x [0, 1]^2. The function's pdf is uniform; the
 * guide's is 1/Omega inside the cone (proportional to F: it pays to trust the guide) or, "wrong",
 * 0 inside and uniform over the rest (it pays to ignore it). n_with of the samples carry the
 * statistic; the others are zero-initialised there, as unguided ones are. */
static void train_share(GuideField *f, uint64_t *rng, float x0, float x1, int wrong, int n, int n_with) {
    const double cos_cone = cos(30.0 * PI / 180.0), omega = 2 * PI * (1 - cos_cone);
    GuideTrainingSample batch[256];
    int m = 0;
    for (int i = 0; i < n; ++i) {
        GuideTrainingSample *s = &batch[m++];
        memset(s, 0, sizeof *s);
        s->pos[0] = x0 + (x1 - x0) * rnd(rng);
        s->pos[1] = rnd(rng);
        s->pos[2] = rnd(rng);
        uniform_dir(rng, s->dir);
        int inside = s->dir[2] > cos_cone;
        s->radiance = inside ? 1.0f : 0.0f;
        s->pdf = UNIFORM_PDF;
        s->leaf = GUIDE_NO_LEAF;
        if (i < n_with) {
            s->share_value = (inside ? 1.0f : 0.0f) / UNIFORM_PDF;
            s->bsdf_pdf = UNIFORM_PDF;
            s->guide_pdf = wrong ? (inside ? 0.0f : (float)(1.0 / (4 * PI - omega))) : (inside ? (float)(1.0 / omega) : 0.0f);
        }
        if (m == 256 || i == n - 1) {
            guide_field_record(f, batch, (size_t)m);
            m = 0;
        }
    }
}

static float share_at(const GuideField *f, float x) {
    const float pos[3] = {x, 0.5f, 0.5f};
    return guide_distribution_bsdf_share(guide_field_lookup(f, pos));
}

static void test_bsdf_share(void) {
    float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    GuideFieldParams p;
    guide_field_params_default(&p);
    CHECK(p.learn_bsdf_share == 0 && p.min_bsdf_share == GUIDE_DEFAULT_MIN_BSDF_SHARE &&
              p.bsdf_share == GUIDE_DEFAULT_BSDF_SHARE && p.caustic_threshold == GUIDE_DEFAULT_CAUSTIC_THRESHOLD,
          "defaults");
    p.learn_bsdf_share = 1;
    p.spatial_threshold = 1e9f; /* one leaf unless a case asks for splits */
    uint64_t rng = 41;
    /* 1. a guide proportional to F: the floor (0.5 by default, 0.25 when allowed); one that
     * misses F: the function alone (1) */
    for (int c = 0; c < 4; ++c) {
        int wrong = c & 1;
        GuideFieldParams q = p;
        q.min_bsdf_share = c < 2 ? GUIDE_DEFAULT_MIN_BSDF_SHARE : 0.25f;
        GuideField *f = guide_field_create(lo, hi, &q);
        CHECK(f != NULL, "create");
        if (!f) return;
        CHECK(share_at(f, 0.5f) == GUIDE_DEFAULT_BSDF_SHARE, "untrained share %g", share_at(f, 0.5f));
        train_share(f, &rng, 0, 1, wrong, 4000, 4000);
        CHECK(share_at(f, 0.5f) == GUIDE_DEFAULT_BSDF_SHARE, "the share changed before an update");
        CHECK(guide_field_update(f, 1.0f) == 0, "update");
        float want = wrong ? 1.0f : q.min_bsdf_share;
        CHECK(share_at(f, 0.5f) == want, "case %d: learned share %g, want %g", c, share_at(f, 0.5f), want);
        guide_field_free(f);
    }
    /* 2. too few samples with the statistic (63 of 4000) keep the share, and their sums wait for
     * the next update: 1 more makes 64 */
    GuideField *f = guide_field_create(lo, hi, &p);
    CHECK(f != NULL, "create");
    if (!f) return;
    train_share(f, &rng, 0, 1, 1, 4000, 63);
    CHECK(guide_field_update(f, 1.0f) == 0 && share_at(f, 0.5f) == GUIDE_DEFAULT_BSDF_SHARE, "63 samples chose %g",
          share_at(f, 0.5f));
    train_share(f, &rng, 0, 1, 1, 1, 1);
    CHECK(guide_field_update(f, 1.0f) == 0 && share_at(f, 0.5f) == 1.0f, "64 samples over two updates chose %g",
          share_at(f, 0.5f));
    /* the choice stays until enough new samples ask otherwise */
    train_share(f, &rng, 0, 1, 0, 1000, 0);
    CHECK(guide_field_update(f, 1.0f) == 0 && share_at(f, 0.5f) == 1.0f, "unguided samples changed the share");
    train_share(f, &rng, 0, 1, 0, 4000, 4000);
    CHECK(guide_field_update(f, 1.0f) == 0 && share_at(f, 0.5f) == 0.5f, "the share did not follow new samples: %g",
          share_at(f, 0.5f));
    guide_field_free(f);
    /* 3. off: the given share everywhere */
    GuideFieldParams off = p;
    off.learn_bsdf_share = 0;
    off.bsdf_share = 0.75f;
    f = guide_field_create(lo, hi, &off);
    CHECK(f != NULL, "create");
    if (!f) return;
    train_share(f, &rng, 0, 1, 1, 4000, 4000);
    CHECK(guide_field_update(f, 1.0f) == 0 && share_at(f, 0.5f) == 0.75f, "off learned %g", share_at(f, 0.5f));
    guide_field_free(f);
    /* 4. per leaf: two halves of the box, the guide right in one and wrong in the other; the
     * first update splits (children inherit the parent's share and start their sums again), the
     * second chooses per leaf. A save and load keeps the shares. */
    GuideFieldParams split = p;
    split.spatial_threshold = 1000;
    f = guide_field_create(lo, hi, &split);
    GuideField *g = guide_field_create(lo, hi, &split);
    FILE *tmp = tmpfile();
    CHECK(f && g && tmp, "create");
    if (!f || !g || !tmp) return;
    for (int u = 0; u < 3; ++u) {
        train_share(f, &rng, 0, 0.5f, 0, 8000, 8000);
        train_share(f, &rng, 0.5f, 1, 1, 8000, 8000);
        CHECK(guide_field_update(f, 1.0f) == 0, "update %d", u);
    }
    CHECK(guide_field_num_leaves(f) > 2, "leaves %u", guide_field_num_leaves(f));
    CHECK(share_at(f, 0.2f) == 0.5f && share_at(f, 0.8f) == 1.0f, "per-leaf shares %g and %g", share_at(f, 0.2f),
          share_at(f, 0.8f));
    CHECK(guide_field_save(f, tmp) == 0, "save");
    rewind(tmp);
    CHECK(guide_field_load(g, tmp) == 0 && share_at(g, 0.2f) == 0.5f && share_at(g, 0.8f) == 1.0f,
          "loaded shares %g and %g", share_at(g, 0.2f), share_at(g, 0.8f));
    /* and the sums a checkpoint holds continue as they would have */
    uint64_t r1 = 5, r2 = 5;
    train_share(f, &r1, 0, 1, 0, 3000, 3000);
    train_share(g, &r2, 0, 1, 0, 3000, 3000);
    CHECK(guide_field_update(f, 1.0f) == 0 && guide_field_update(g, 1.0f) == 0, "update");
    CHECK(fields_equal(f, g, 12), "the loaded field's shares train differently");
    fclose(tmp);
    guide_field_free(f);
    guide_field_free(g);
}

/* The caustic guard: guided samples of a leaf, uniform over the sphere, 1 in `every` of which
 * reached a delta scatterer, carrying radiance `beyond` there and 1 elsewhere. */
static void train_caustic(GuideField *f, uint64_t *rng, int n, int every, float beyond) {
    GuideTrainingSample batch[256];
    int m = 0;
    for (int i = 0; i < n; ++i) {
        GuideTrainingSample *s = &batch[m++];
        memset(s, 0, sizeof *s);
        for (int k = 0; k < 3; ++k) s->pos[k] = rnd(rng);
        uniform_dir(rng, s->dir);
        s->delta_child = i % every == 0;
        s->radiance = s->delta_child ? beyond : 1.0f;
        s->pdf = s->bsdf_pdf = s->guide_pdf = UNIFORM_PDF;
        s->share_value = s->radiance * s->radiance * UNIFORM_PDF;
        s->leaf = GUIDE_NO_LEAF;
        if (m == 256 || i == n - 1) {
            guide_field_record(f, batch, (size_t)m);
            m = 0;
        }
    }
}

static void test_caustic_guard(void) {
    float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    GuideFieldParams p;
    guide_field_params_default(&p);
    p.spatial_threshold = 1e9f;
    uint64_t rng = 77;
    /* 1 sample in 100 (1% > 0.2%) reaches glass; dim beyond it (no caustic learned): the guard's
     * share;
     * as bright there as elsewhere or brighter (a window): the guide stays; 1 in 1000 (0.1%
     * < 0.2%): the guide stays; threshold 0: off */
    struct { int every; float beyond, threshold, want; } c[] = {
        {100, 0.0f, GUIDE_CAUSTIC_GUARD_THRESHOLD, GUIDE_DEFAULT_CAUSTIC_SHARE},
        {100, 0.5f, GUIDE_CAUSTIC_GUARD_THRESHOLD, GUIDE_DEFAULT_CAUSTIC_SHARE},
        {100, 1.0f, GUIDE_CAUSTIC_GUARD_THRESHOLD, 0.5f}, {100, 20.0f, GUIDE_CAUSTIC_GUARD_THRESHOLD, 0.5f},
        {1000, 0.0f, GUIDE_CAUSTIC_GUARD_THRESHOLD, 0.5f}, {100, 0.0f, 0.0f, 0.5f}};
    for (size_t k = 0; k < sizeof c / sizeof c[0]; ++k) {
        GuideFieldParams q = p;
        q.caustic_threshold = c[k].threshold;
        GuideField *f = guide_field_create(lo, hi, &q);
        CHECK(f != NULL, "create");
        if (!f) return;
        train_caustic(f, &rng, 20000, c[k].every, c[k].beyond);
        CHECK(guide_field_update(f, 1.0f) == 0, "update");
        CHECK(share_at(f, 0.5f) == c[k].want, "case %zu: share %g, want %g", k, share_at(f, 0.5f), c[k].want);
        /* a guarded leaf that then finds the light beyond the glass bright goes back to the guide */
        if (c[k].want != 0.5f) {
            train_caustic(f, &rng, 20000, c[k].every, 50.0f);
            CHECK(guide_field_update(f, 1.0f) == 0 && share_at(f, 0.5f) == 0.5f, "case %zu: bright caustic kept %g", k,
                  share_at(f, 0.5f));
        }
        guide_field_free(f);
    }
}

/* The caustic defense: samples uniform over the sphere (the function's pdf is the sample's), radiance
 * 1 except in a cap around +x (cos > 0.9: 5% of the sphere) where every ray reached glass and found
 * nothing beyond it. Without the defense the guide learns to send almost nothing into the cap; with
 * it, about c times the function's probability (5%), so a caustic there would keep its weight. */
static double cap_probability(const GuideField *f, uint64_t *rng, double *mean_ratio) {
    const float at[3] = {0.5f, 0.5f, 0.5f};
    const GuideDistribution *d = guide_field_lookup(f, at);
    int in = 0, n = 20000, inner = 0;
    for (int i = 0; i < n; ++i) {
        float dir[3], pdf;
        guide_distribution_sample(d, rnd(rng), rnd(rng), dir, &pdf);
        in += dir[0] > 0.9f;
    }
    /* the guide's density over the function's deep inside the cap, where no cell straddles its rim */
    double ratio = 0;
    for (int i = 0; i < n; ++i) {
        float dir[3];
        uniform_dir(rng, dir);
        if (!(dir[0] > 0.97f)) continue;
        ratio += guide_distribution_pdf(d, dir) / UNIFORM_PDF;
        inner++;
    }
    *mean_ratio = inner ? ratio / inner : 0;
    return (double)in / n;
}

static void test_caustic_defense(void) {
    float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    GuideFieldParams p;
    guide_field_params_default(&p);
    p.spatial_threshold = 1e9f;
    p.caustic_threshold = 0; /* the guard's share is not what is tested here */
    const float defense[] = {0.0f, 1.0f, 2.0f};
    for (int k = 0; k < 3; ++k) {
        GuideFieldParams q = p;
        q.caustic_defense = defense[k];
        GuideField *f = guide_field_create(lo, hi, &q);
        CHECK(f != NULL, "create");
        if (!f) return;
        uint64_t rng = 91;
        for (int u = 0; u < 3; ++u) {
            GuideTrainingSample batch[256];
            for (int i = 0; i < 40000; i += 256) {
                for (int j = 0; j < 256; ++j) {
                    GuideTrainingSample *s = &batch[j];
                    memset(s, 0, sizeof *s);
                    for (int c = 0; c < 3; ++c) s->pos[c] = rnd(&rng);
                    uniform_dir(&rng, s->dir);
                    s->delta_child = s->dir[0] > 0.9f;
                    s->radiance = s->delta_child ? 0.0f : 1.0f;
                    s->pdf = UNIFORM_PDF;
                    s->defense = s->delta_child ? 1.0f : 0.0f; /* p_f / p */
                    s->leaf = GUIDE_NO_LEAF;
                }
                guide_field_record(f, batch, 256);
            }
            CHECK(guide_field_update(f, 1.0f) == 0, "update");
        }
        double ratio, prob = cap_probability(f, &rng, &ratio);
        /* the cap's share of the learned flux: c P / (1 - P + c P) with P = 0.05 (the leaf's mean
         * flux per sample counts the cap's zeros: (1 - P) 4 pi), give or take the cells on its rim */
        double want = defense[k] * 0.05 / (0.95 + defense[k] * 0.05);
        if (defense[k] == 0) {
            /* only what the cells on the cap's rim spill (about 2%), and nothing deep inside it */
            CHECK(prob < 0.03 && ratio < 0.1, "no defense: the guide sends %.3f into the dark cap (density %.3f x the "
                  "function's deep inside it)", prob, ratio);
        } else {
            CHECK(fabs(prob - want) < 0.3 * want, "defense %g: the guide sends %.4f into the cap, want about %.4f",
                  defense[k], prob, want);
            CHECK(fabs(ratio - want / 0.05) < 0.3 * want / 0.05, "defense %g: density %.3f x the function's, want about %.3f",
                  defense[k], ratio, want / 0.05);
        }
        guide_field_free(f);
    }
}

/* ---------------------------------------------------------------- 7. bad input */
static GuideTrainingSample sample_at(float x, float y, float z, float radiance, float pdf) {
    GuideTrainingSample s = {{x, y, z}, {0, 0, 1}, radiance, pdf, GUIDE_NO_LEAF};
    return s;
}

static void test_bad_input(void) {
    float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
    GuideFieldParams p;
    guide_field_params_default(&p);
    p.spatial_threshold = 1; /* the first update splits a leaf with more than 1 sample */
    GuideField *f = guide_field_create(lo, hi, &p);
    CHECK(f != NULL, "create");
    if (!f) return;
    GuideTrainingSample s[16];
    int n = 0;
    s[n++] = sample_at(0.5f, 0.5f, 0.5f, 1.0f, UNIFORM_PDF); /* the one valid sample */
    s[n++] = sample_at(0.5f, 0.5f, 0.5f, NAN, UNIFORM_PDF);
    s[n++] = sample_at(0.5f, 0.5f, 0.5f, INFINITY, UNIFORM_PDF);
    s[n++] = sample_at(0.5f, 0.5f, 0.5f, 1.0f, 0.0f);
    s[n++] = sample_at(0.5f, 0.5f, 0.5f, 1.0f, -1.0f);
    s[n++] = sample_at(0.5f, 0.5f, 0.5f, 1.0f, NAN);
    s[n++] = sample_at(0.5f, 0.5f, 0.5f, 1.0f, INFINITY);
    s[n++] = sample_at(NAN, 0.5f, 0.5f, 1.0f, UNIFORM_PDF);
    s[n++] = sample_at(0.5f, INFINITY, 0.5f, 1.0f, UNIFORM_PDF);
    s[n] = sample_at(0.5f, 0.5f, 0.5f, 1.0f, UNIFORM_PDF);
    s[n].dir[2] = 0; /* zero direction */
    ++n;
    s[n] = sample_at(0.5f, 0.5f, 0.5f, 1.0f, UNIFORM_PDF);
    s[n].dir[0] = NAN;
    ++n;
    guide_field_record(f, s, (size_t)n);
    guide_field_record(f, NULL, 5); /* no samples: nothing happens */
    CHECK(guide_field_update(f, 1.0f) == 0, "update");
    CHECK(guide_field_num_leaves(f) == 1, "bad samples were counted: %u leaves", guide_field_num_leaves(f));
    const GuideDistribution *d = guide_field_lookup(f, lo);
    float up[3] = {0, 0, 1}, down[3] = {0, 0, -1};
    float p_up = guide_distribution_pdf(d, up), p_down = guide_distribution_pdf(d, down);
    CHECK(isfinite(p_up) && p_up > 0 && p_down == 0, "learned from the valid sample only: %g %g", p_up, p_down);
    float img[256 * 256];
    double integral = integral_image(d, 256, img);
    CHECK(fabs(integral - 1) < 1e-4, "integral %.6f", integral);
    guide_field_free(f);

    /* Control: two valid zero-radiance samples do count (they split), and a leaf without flux
     * stays uniform. Points outside the bounds are clamped into it and count too. */
    f = guide_field_create(lo, hi, &p);
    CHECK(f != NULL, "create");
    if (!f) return;
    s[0] = sample_at(5.0f, 5.0f, 5.0f, 0.0f, UNIFORM_PDF);
    s[1] = sample_at(-3.0f, 0.5f, 9.0f, 0.0f, 2.0f);
    guide_field_record(f, s, 2);
    CHECK(guide_field_update(f, 1.0f) == 0, "update");
    CHECK(guide_field_num_leaves(f) > 1, "zero-radiance samples were not counted: %u leaves", guide_field_num_leaves(f));
    uint64_t rng = 77;
    int not_uniform = 0;
    for (int i = 0; i < 200; ++i) {
        float pos[3] = {rnd(&rng), rnd(&rng), rnd(&rng)}, dir[3];
        uniform_dir(&rng, dir);
        not_uniform += guide_distribution_pdf(guide_field_lookup(f, pos), dir) != map_pdf(dir);
    }
    CHECK(not_uniform == 0, "%d pdfs not uniform (over the square) without flux", not_uniform);
    guide_field_free(f);

    /* Extreme but valid values (FLT_MAX radiance over the smallest pdf) stay finite. */
    f = guide_field_create(lo, hi, NULL);
    CHECK(f != NULL, "create");
    if (!f) return;
    s[0] = sample_at(0.5f, 0.5f, 0.5f, 3.4e38f, 1e-45f);
    s[1] = sample_at(0.5f, 0.5f, 0.5f, 1.0f, UNIFORM_PDF);
    s[1].dir[0] = 1;
    s[1].dir[2] = 0;
    guide_field_record(f, s, 2);
    CHECK(guide_field_update(f, 1.0f) == 0, "update");
    d = guide_field_lookup(f, lo);
    integral = integral_image(d, 256, img);
    CHECK(fabs(integral - 1) < 1e-4, "integral %.6f after extreme values", integral);

    /* A point outside the bounds (or NaN) gets a valid distribution. */
    float far[3] = {1e30f, -1e30f, NAN};
    d = guide_field_lookup(f, far);
    CHECK(d != NULL, "lookup outside");
    if (d) {
        float blo[3], bhi[3], dir[3], pdf;
        guide_distribution_bounds(d, blo, bhi);
        int ok = 1;
        for (int k = 0; k < 3; ++k) ok &= isfinite(blo[k]) && isfinite(bhi[k]) && blo[k] < bhi[k];
        CHECK(ok, "bounds of the outside leaf");
        guide_distribution_sample(d, 0.3f, 0.7f, dir, &pdf);
        CHECK(fabsf(sqrtf(dot(dir, dir)) - 1) < 1e-5f && isfinite(pdf) && pdf > 0, "outside sample %g", pdf);
        guide_distribution_sample(d, NAN, 1.5f, dir, &pdf); /* out-of-range uniforms are clamped */
        CHECK(fabsf(sqrtf(dot(dir, dir)) - 1) < 1e-5f && isfinite(pdf), "sample with NaN uniforms %g", pdf);
        float zero[3] = {0, 0, 0};
        CHECK(guide_distribution_pdf(d, zero) == 0, "pdf of a zero direction");
    }
    guide_field_free(f);

    /* Degenerate bounds (a point, NaN) still give a usable field. */
    float pt[3] = {2, 2, 2}, nan3[3] = {NAN, 0, 0};
    f = guide_field_create(pt, pt, NULL);
    CHECK(f && guide_field_lookup(f, pt) != NULL, "point bounds");
    guide_field_free(f);
    f = guide_field_create(nan3, pt, NULL);
    CHECK(f && guide_field_lookup(f, pt) != NULL, "NaN bounds");
    guide_field_free(f);
}

/* ---------------------------------------------------------------- 8. PLY */
static void test_ply(void) {
    GuideField *f = two_regions(5, 2);
    CHECK(f != NULL, "two_regions");
    if (!f) return;
    uint32_t leaves = guide_field_num_leaves(f);
    char path[256];
    snprintf(path, sizeof path, "/tmp/test_sdtree_%ld.ply", (long)getpid());
    FILE *out = fopen(path, "w");
    CHECK(out != NULL, "open %s: %s", path, strerror(errno));
    if (out) {
        CHECK(guide_field_write_ply(f, out) == 0, "write %s: %s", path, strerror(errno));
        fclose(out);
    }
    FILE *fp = fopen(path, "r");
    CHECK(fp != NULL, "reopen %s", path);
    if (fp) {
        char line[512];
        unsigned long vertices = 0, faces = 0, body = 0, quads = 0;
        int header = 1, first = 1, starts_ply = 0;
        while (fgets(line, sizeof line, fp)) {
            if (first) starts_ply = strcmp(line, "ply\n") == 0;
            first = 0;
            if (header) {
                sscanf(line, "element vertex %lu", &vertices);
                sscanf(line, "element face %lu", &faces);
                if (strcmp(line, "end_header\n") == 0) header = 0;
            } else {
                ++body;
                quads += line[0] == '4' && line[1] == ' ';
            }
        }
        fclose(fp);
        fprintf(stderr, "ply: %u leaves, %lu vertices, %lu faces, %lu body lines\n", leaves, vertices, faces, body);
        CHECK(starts_ply, "file does not start with ply");
        CHECK(vertices == 8ul * leaves, "element vertex %lu for %u leaves", vertices, leaves);
        CHECK(faces == 6ul * leaves, "element face %lu for %u leaves", faces, leaves);
        CHECK(body == 14ul * leaves, "%lu body lines", body);
        CHECK(quads >= 6ul * leaves, "%lu quad lines", quads);
    }
    remove(path);
    /* a full disk (/dev/full) is the call's failure, with its reason: the stream is flushed */
    FILE *full = fopen("/dev/full", "w");
    if (full) {
        errno = 0;
        int rc = guide_field_write_ply(f, full);
        CHECK(rc == -1 && errno == ENOSPC, "write to a full disk: rc %d errno %d", rc, errno);
        fclose(full);
    }
    guide_field_free(f);
}

/* Müller 2019's spatial filter: after a field has split on samples from everywhere (light from
 * +z), samples just left of the split plane x = 1/2 with light from -z change the leaf on the
 * right of the plane too when the filter is on (its jitter box reaches across), and leave it
 * alone when it is off. */
static void test_spatial_filter(void) {
    for (int filter = 0; filter <= 1; ++filter) {
        GuideFieldParams p;
        guide_field_params_default(&p);
        p.spatial_threshold = 100.0f;
        p.spatial_filter = filter;
        const float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
        GuideField *f = guide_field_create(lo, hi, &p);
        enum { N = 2000 };
        GuideTrainingSample *smp = malloc(N * sizeof *smp);
        for (int i = 0; i < N; ++i)
            smp[i] = (GuideTrainingSample){{(i % 43) / 43.0f, (i % 37) / 37.0f, (i % 41) / 41.0f}, {0, 0, 1}, 1.0f, 0.0795775f};
        guide_field_record(f, smp, N);
        guide_field_update(f, 1.0f);
        for (int i = 0; i < N; ++i)
            smp[i] = (GuideTrainingSample){{0.45f, (i % 37) / 37.0f, (i % 41) / 41.0f}, {0, 0, -1}, 100.0f, 0.0795775f};
        guide_field_record(f, smp, N);
        guide_field_update(f, 1.0f);
        const float right[3] = {0.55f, 0.5f, 0.5f}, down[3] = {0, 0, -1};
        float pdf = guide_distribution_pdf(guide_field_lookup(f, right), down);
        fprintf(stderr, "spatial filter %s: pdf towards -z across the plane %.4g (%u leaves)\n", filter ? "on" : "off", pdf,
                guide_field_num_leaves(f));
        if (filter) CHECK(pdf > 0.05f, "the spatial filter reaches the neighbouring leaf (pdf %g)", pdf);
        else CHECK(pdf < 0.01f, "without the filter the neighbouring leaf learned -z (pdf %g)", pdf);
        free(smp);
        guide_field_free(f);
    }
}

/* The direction of (u, v) near the map's centre (the upper hemisphere: |2u - 1| + |2v - 1| <= 1). */
static void uv_dir_upper(double u, double v, float d[3]) {
    double a = 2 * u - 1, b = 2 * v - 1, z = 1 - fabs(a) - fabs(b);
    d[0] = (float)a;
    d[1] = (float)b;
    d[2] = (float)z;
    normalize(d);
}

/* Directional filtering (Müller 2019): every sample at (u, v) = (0.5 + 1/64)^2, a quarter of a
 * cell into the first building tree's cell [8/16, 9/16)^2, near its corner at (1/2, 1/2). The box
 * of a cell's size around it puts 9/16 of the value into that cell, 3/16 into each side
 * neighbour and 1/16 into the diagonal one, so the learned pdf (one density per cell of that
 * tree) is in the ratios 9 : 3 : 1 there; unfiltered, the neighbours learn nothing. */
static void test_directional_filter(void) {
    for (int filter = 0; filter <= 1; ++filter) {
        GuideFieldParams p;
        guide_field_params_default(&p);
        CHECK(p.directional_filter == 1, "the directional filter is on by default");
        p.directional_filter = filter;
        p.spatial_threshold = 1e9f; /* one leaf */
        const float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
        GuideField *f = guide_field_create(lo, hi, &p);
        enum { N = 1000 };
        GuideTrainingSample *smp = malloc(N * sizeof *smp);
        float d[3];
        uv_dir_upper(0.5 + 1.0 / 64, 0.5 + 1.0 / 64, d);
        for (int i = 0; i < N; ++i)
            smp[i] = (GuideTrainingSample){{0.5f, 0.5f, 0.5f}, {d[0], d[1], d[2]}, 1.0f, UNIFORM_PDF};
        guide_field_record(f, smp, N);
        guide_field_update(f, 1.0f);
        const GuideDistribution *g = guide_field_lookup(f, smp[0].pos);
        float at[3], beside[3], far[3];
        uv_dir_upper(0.5 + 1.0 / 64, 0.5 + 1.0 / 64, at);
        uv_dir_upper(0.49, 0.49, beside);  /* the diagonal neighbour cell, inside the box */
        uv_dir_upper(0.49, 0.52, far);     /* the side neighbour cell, inside the box */
        float pa = guide_distribution_pdf(g, at), pb = guide_distribution_pdf(g, beside), pc = guide_distribution_pdf(g, far);
        fprintf(stderr, "directional filter %s: pdf at the samples %.4g, in the diagonal cell %.4g, the side cell %.4g\n",
                filter ? "on" : "off", pa, pb, pc);
        if (filter) {
            /* up to the map's density factor, which varies by a few % across these cells */
            CHECK(fabsf(pc / pa - 1.0f / 3.0f) < 0.05f && fabsf(pb / pa - 1.0f / 9.0f) < 0.02f,
                  "the filter's shares 9 : 3 : 1 (pdf %g : %g : %g)", pa, pc, pb);
        } else {
            CHECK(pb < 0.01f * pa && pc < 0.01f * pa, "unfiltered, the neighbouring cells learned light (pdf %g, %g against %g)",
                  pb, pc, pa);
        }
        free(smp);
        guide_field_free(f);
    }
}

/* Accumulation across updates: light from +z in iteration 0, from -z in iteration 1 (the
 * uniform pdf is 0.08; -z lies in a cell refined for +z, so one update learns it coarsely). Kept
 * (accumulate = 1, the default), the field still sends samples up; PPG 2017's fresh start
 * (accumulate = 0) has forgotten +z. */
static void test_accumulate(void) {
    for (int acc = 0; acc <= 1; ++acc) {
        GuideFieldParams p;
        guide_field_params_default(&p);
        p.accumulate = acc;
        const float lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
        GuideField *f = guide_field_create(lo, hi, &p);
        enum { N = 500 };
        GuideTrainingSample smp[N];
        for (int pass = 0; pass < 2; ++pass) {
            for (int i = 0; i < N; ++i)
                smp[i] = (GuideTrainingSample){{0.5f, 0.5f, 0.5f}, {0, 0, pass ? -1.0f : 1.0f}, 1.0f, 0.0795775f};
            guide_field_record(f, smp, N);
            guide_field_update(f, 1.0f);
        }
        const float at[3] = {0.5f, 0.5f, 0.5f}, up[3] = {0, 0, 1}, down[3] = {0, 0, -1};
        const GuideDistribution *d = guide_field_lookup(f, at);
        float pu = guide_distribution_pdf(d, up), pd = guide_distribution_pdf(d, down);
        fprintf(stderr, "accumulate %d: pdf up %.3g, down %.3g\n", acc, pu, pd);
        CHECK(pd > 0.1f, "accumulate %d: the last iteration's light is learned (pdf %g)", acc, pd);
        if (acc) CHECK(pu > 0.5f * pd, "accumulating keeps the first iteration's light (pdf up %g, down %g)", pu, pd);
        else CHECK(pu < 0.01f * pd, "a fresh start forgets the first iteration's light (pdf up %g, down %g)", pu, pd);
        guide_field_free(f);
    }
}

int main(void) {
    double t0 = test_seconds();
    test_accumulate();
    test_spatial_filter();
    test_directional_filter();
    test_uniform();
    test_trained();
    test_spatial();
    test_determinism();
    test_checkpoint();
    test_leaf_hints();
    test_bsdf_share();
    test_caustic_guard();
    test_caustic_defense();
    test_bad_input();
    test_ply();
    fprintf(stderr, "test_sdtree: %.2f s\n", test_seconds() - t0);
    return test_exit();
}
