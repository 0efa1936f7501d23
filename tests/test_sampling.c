/* tests/test_sampling.c: every warp and tabulated distribution of renderer/util/sampling.h.
 *
 * For each sampler, the samples are mapped to a parameter square (s, t) in [0,1)^2 (for
 * directions: s from the polar angle, t = phi / 2pi) and histogrammed. The pdf, converted to a
 * density over (s, t) with the Jacobian of that map, is integrated over every bin with a tensor
 * Gauss-Legendre rule on a sub-grid; the sum of the bin integrals is the check that the pdf
 * integrates to one, and the bin integrals times N are the expected counts of a chi-square test
 * (bins with expected < 5 pooled, p-value threshold 1e-3). Random numbers come from
 * rng_uniform with fixed keys, so the test is deterministic. With ~30 chi-square tests at
 * 1e-3, about 3% of seeds would fail one by chance; SEED is one that passes, and the suite was
 * also run over 25 other seeds and at 20x the sample count without systematic failures. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "stats.h"
#include "rng.h"
#include "sampling.h"

#define PI_D 3.14159265358979323846
#ifndef SEED
#define SEED 0x5eedull
#endif
#define P_THRESHOLD 1e-3
#define MIN_EXPECTED 5.0

/* statistics: tests/stats.h */

/* ---------------------------------------------------------------- generic 2D harness */

typedef struct Warp Warp;
struct Warp {
    const char *name;
    int ns, nt;
    /* Draw one sample from uniforms; map it to (s,t). Return 0 if the sampler produced
     * nothing, 1 if (s,t) is valid, -1 if the sample fell outside the parameter domain. */
    int (*sample)(const Warp *w, float u1, float u2, double *s, double *t);
    /* Density of (s,t) (pdf times Jacobian). */
    double (*density)(const Warp *w, double s, double t);
    /* parameters */
    int dir_mode;       /* directions: 0 = s linear in z over [zlo,zhi], 1 = s = sqrt(1 - z) */
    double zlo, zhi;
    int flip;           /* directions: measure theta from -z */
    float alpha, cos_max;
    vec3 wo;
    vec3 (*dir_sample)(const Warp *w, float u1, float u2);
    double (*dir_pdf)(const Warp *w, vec3 d);
    const void *user;
};

/* 4-point Gauss-Legendre on [0,1]. */
static const double GL_X[4] = {0.0694318442029737, 0.3300094782075719, 0.6699905217924281, 0.9305681557970263};
static const double GL_W[4] = {0.1739274225687269, 0.3260725774312731, 0.3260725774312731, 0.1739274225687269};

/* Integrates density over every bin: each bin split sub x sub, 4x4 Gauss-Legendre per cell. */
static double integrate_bins(const Warp *w, int sub, double *expv) {
    double total = 0.0;
    double ds = 1.0 / w->ns, dt = 1.0 / w->nt;
    for (int i = 0; i < w->ns; ++i)
        for (int j = 0; j < w->nt; ++j) {
            double acc = 0.0;
            for (int a = 0; a < sub; ++a)
                for (int b = 0; b < sub; ++b)
                    for (int ga = 0; ga < 4; ++ga)
                        for (int gb = 0; gb < 4; ++gb) {
                            double s = (i + (a + GL_X[ga]) / sub) * ds;
                            double t = (j + (b + GL_X[gb]) / sub) * dt;
                            acc += GL_W[ga] * GL_W[gb] * w->density(w, s, t);
                        }
            acc *= ds * dt / ((double)sub * sub);
            expv[i * w->nt + j] = acc;
            total += acc;
        }
    return total;
}

/* Runs the integral and chi-square checks. int_tol: allowed |integral - 1|. */
static void run_warp(const Warp *w, uint32_t id, int n_samples, int sub, double int_tol) {
    int nb = w->ns * w->nt;
    double *obs = calloc((size_t)nb + 1, sizeof(double));
    double *expv = calloc((size_t)nb + 1, sizeof(double));
    double integral = integrate_bins(w, sub, expv);
    CHECK(fabs(integral - 1.0) < int_tol, "%s: pdf integrates to %.7f", w->name, integral);
    int outside = 0, none = 0;
    for (int k = 0; k < n_samples; ++k) {
        uint64_t key = rng_path_key(SEED, id, (uint64_t)k);
        double s, t;
        int r = w->sample(w, rng_uniform(key, 0), rng_uniform(key, 1), &s, &t);
        if (r == 0) { ++none; continue; }
        if (r < 0) { ++outside; continue; }
        int i = (int)(s * w->ns), j = (int)(t * w->nt);
        if (i < 0) i = 0;
        if (i >= w->ns) i = w->ns - 1;
        if (j < 0) j = 0;
        if (j >= w->nt) j = w->nt - 1;
        obs[i * w->nt + j] += 1.0;
    }
    CHECK(outside == 0, "%s: %d samples outside the domain", w->name, outside);
    CHECK(none == 0, "%s: %d samples failed", w->name, none);
    for (int i = 0; i < nb; ++i) expv[i] *= n_samples;
    int dof;
    double stat;
    double p = chi2_pvalue(obs, expv, nb, &dof, &stat);
    fprintf(stderr, "  %-40s integral %.6f  chi2 %.1f dof %d  p %.4f\n", w->name, integral, stat, dof, p);
    CHECK(p > P_THRESHOLD, "%s: chi-square p = %g (stat %.1f, dof %d)", w->name, p, stat, dof);
    free(obs);
    free(expv);
}

/* ---------------------------------------------------------------- directions */

static int dir_to_st(const Warp *w, vec3 d, double *s, double *t) {
    double x = d.x, y = d.y, z = d.z;
    if (w->flip) { x = -x; y = -y; z = -z; } /* point reflection keeps a right-handed map */
    double len = sqrt(x * x + y * y + z * z);
    if (!(fabs(len - 1.0) < 1e-4)) return -1;
    z /= len;
    if (w->dir_mode == 0) {
        if (z < w->zlo - 1e-6 || z > w->zhi + 1e-6) return -1;
        *s = (w->zhi - z) / (w->zhi - w->zlo);
    } else {
        if (z < -1e-6) return -1;
        *s = sqrt(fmax(0.0, 1.0 - z)); /* hemisphere, s = sqrt(2) sin(theta/2) */
    }
    double phi = atan2(y, x);
    if (phi < 0.0) phi += 2.0 * PI_D;
    *t = phi / (2.0 * PI_D);
    return 1;
}

static int dir_sample_st(const Warp *w, float u1, float u2, double *s, double *t) {
    vec3 d = w->dir_sample(w, u1, u2);
    if (!v3_is_finite(d)) return -1;
    return dir_to_st(w, d, s, t);
}

static double dir_density(const Warp *w, double s, double t) {
    double z, jac;
    if (w->dir_mode == 0) {
        z = w->zhi - s * (w->zhi - w->zlo);
        jac = (w->zhi - w->zlo) * 2.0 * PI_D;
    } else {
        z = 1.0 - s * s;
        jac = 2.0 * s * 2.0 * PI_D;
    }
    double r = sqrt(fmax(0.0, 1.0 - z * z));
    double phi = 2.0 * PI_D * t;
    vec3 d = v3((float)(r * cos(phi)), (float)(r * sin(phi)), (float)z);
    if (w->flip) d = v3_neg(d);
    return w->dir_pdf(w, d) * jac;
}

static vec3 ds_cosine(const Warp *w, float u1, float u2) { (void)w; return sample_cosine_hemisphere(u1, u2); }
static double dp_cosine(const Warp *w, vec3 d) { (void)w; return pdf_cosine_hemisphere(d); }
static vec3 ds_sphere(const Warp *w, float u1, float u2) { (void)w; return sample_uniform_sphere(u1, u2); }
static double dp_sphere(const Warp *w, vec3 d) { (void)w; (void)d; return pdf_uniform_sphere(); }
static vec3 ds_cone(const Warp *w, float u1, float u2) { return sample_uniform_cone(u1, u2, w->cos_max); }
static double dp_cone(const Warp *w, vec3 d) { return d.z >= w->cos_max ? pdf_uniform_cone(w->cos_max) : 0.0; }
static vec3 ds_ggx(const Warp *w, float u1, float u2) { return ggx_sample_visible_normal(w->wo, w->alpha, u1, u2); }
static double dp_ggx(const Warp *w, vec3 d) { return ggx_pdf_visible_normal(w->wo, d, w->alpha); }

static Warp dir_warp(const char *name, int mode, double zlo, double zhi,
                     vec3 (*ds)(const Warp *, float, float), double (*dp)(const Warp *, vec3)) {
    Warp w;
    memset(&w, 0, sizeof w);
    w.name = name;
    w.ns = 20;
    w.nt = 40;
    w.sample = dir_sample_st;
    w.density = dir_density;
    w.dir_mode = mode;
    w.zlo = zlo;
    w.zhi = zhi;
    w.dir_sample = ds;
    w.dir_pdf = dp;
    return w;
}

/* ---------------------------------------------------------------- planar warps */

/* Disk: s = r, t = phi/2pi; uniform density 1/pi on the disk, Jacobian r * 2pi. */
static int disk_sample(const Warp *w, float u1, float u2, double *s, double *t) {
    (void)w;
    vec2 p = sample_concentric_disk(u1, u2);
    double r = sqrt((double)p.x * p.x + (double)p.y * p.y);
    if (r > 1.0 + 1e-6) return -1;
    double phi = atan2(p.y, p.x);
    if (phi < 0.0) phi += 2.0 * PI_D;
    *s = r;
    *t = phi / (2.0 * PI_D);
    return 1;
}
static double disk_density(const Warp *w, double s, double t) { (void)w; (void)t; return 2.0 * s; }

/* Triangle: s = b1 + b2, t = b2 / (b1 + b2); uniform density 2 on the triangle, Jacobian s. */
static int tri_sample(const Warp *w, float u1, float u2, double *s, double *t) {
    (void)w;
    vec2 b = sample_uniform_triangle(u1, u2);
    if (b.x < 0.0f || b.y < 0.0f || b.x + b.y > 1.0f + 1e-6f) return -1;
    double sum = (double)b.x + b.y;
    *s = sum;
    *t = sum > 0.0 ? b.y / sum : 0.0;
    return 1;
}
static double tri_density(const Warp *w, double s, double t) { (void)w; (void)t; return 2.0 * s; }

/* ---------------------------------------------------------------- distributions */

static int d1c_sample(const Warp *w, float u1, float u2, double *s, double *t) {
    (void)u2;
    const Distribution1D *d = w->user;
    float pdf;
    uint32_t cell;
    float x = dist1d_sample_continuous(d, u1, &pdf, &cell);
    if (!(x >= 0.0f && x < 1.0f)) return -1;
    if (cell != (uint32_t)(x * d->n) && fabsf(x * d->n - roundf(x * d->n)) > 1e-4f) return -1;
    if (fabsf(pdf - dist1d_pdf_continuous(d, x)) > 1e-5f * pdf) return -1;
    *s = x;
    *t = 0.5;
    return 1;
}
static double d1c_density(const Warp *w, double s, double t) {
    (void)t;
    return dist1d_pdf_continuous(w->user, (float)s);
}

static int d2_sample(const Warp *w, float u1, float u2, double *s, double *t) {
    const Distribution2D *d = w->user;
    float pdf;
    vec2 p = dist2d_sample(d, u1, u2, &pdf);
    if (!(p.x >= 0.0f && p.x < 1.0f && p.y >= 0.0f && p.y < 1.0f)) return -1;
    if (fabsf(pdf - dist2d_pdf(d, p)) > 1e-5f * pdf) return -1;
    *s = p.x;
    *t = p.y;
    return 1;
}
static double d2_density(const Warp *w, double s, double t) {
    vec2 p = {(float)s, (float)t};
    return dist2d_pdf(w->user, p);
}

/* Discrete 1D: chi-square of picked cells against the pmf; also checks the remapped u is
 * uniform within the cell (pooled over all cells, 16 sub-bins). */
static void test_dist1d_discrete(const float *func, uint32_t n, uint32_t id, int n_samples) {
    Distribution1D d;
    CHECK(dist1d_init(&d, func, n) == 0, "dist1d_init");
    double pmf_sum = 0.0;
    for (uint32_t i = 0; i < n; ++i) pmf_sum += dist1d_pmf(&d, i);
    CHECK(fabs(pmf_sum - 1.0) < 1e-5, "discrete pmf sums to %.7f", pmf_sum);
    double *obs = calloc(n, sizeof(double)), *expv = calloc(n, sizeof(double));
    double robs[16] = {0}, rexp[16];
    int bad = 0;
    for (int k = 0; k < n_samples; ++k) {
        uint64_t key = rng_path_key(SEED, id, (uint64_t)k);
        float pmf, ur;
        uint32_t i = dist1d_sample_discrete(&d, rng_uniform(key, 0), &pmf, &ur);
        if (i >= n || !(pmf > 0.0f) || pmf != dist1d_pmf(&d, i) || !(ur >= 0.0f && ur < 1.0f)) { ++bad; continue; }
        obs[i] += 1.0;
        robs[(int)(ur * 16.0f)] += 1.0;
    }
    CHECK(bad == 0, "discrete: %d invalid samples", bad);
    for (uint32_t i = 0; i < n; ++i) expv[i] = n_samples * (double)dist1d_pmf(&d, i);
    int dof;
    double stat, p = chi2_pvalue(obs, expv, (int)n, &dof, &stat);
    fprintf(stderr, "  %-40s pmf sum %.6f  chi2 %.1f dof %d  p %.4f\n", "dist1d discrete", pmf_sum, stat, dof, p);
    CHECK(p > P_THRESHOLD, "discrete chi-square p = %g", p);
    for (int i = 0; i < 16; ++i) rexp[i] = n_samples / 16.0;
    p = chi2_pvalue(robs, rexp, 16, &dof, &stat);
    fprintf(stderr, "  %-40s chi2 %.1f dof %d  p %.4f\n", "dist1d discrete u_remapped", stat, dof, p);
    CHECK(p > P_THRESHOLD, "u_remapped chi-square p = %g", p);
    free(obs);
    free(expv);
    dist1d_free(&d);
}

static void test_dist_edge_cases(void) {
    Distribution1D d;
    float zeros[5] = {0, 0, 0, 0, 0};
    CHECK(dist1d_init(&d, zeros, 5) == 0, "init zeros");
    CHECK(d.func_int == 0.0f, "all-zero func_int %g", d.func_int);
    CHECK(dist1d_pmf(&d, 3) == 0.2f, "all-zero pmf %g", dist1d_pmf(&d, 3));
    float pdf;
    uint32_t cell;
    float x = dist1d_sample_continuous(&d, 0.55f, &pdf, &cell);
    CHECK(pdf == 1.0f && cell == 2 && fabsf(x - 0.55f) < 1e-6f, "all-zero continuous x %g pdf %g cell %u", x, pdf, cell);
    CHECK(dist1d_pdf_continuous(&d, 0.3f) == 1.0f, "all-zero pdf");
    dist1d_free(&d);

    float bad[4] = {NAN, -1.0f, INFINITY, 2.0f};
    CHECK(dist1d_init(&d, bad, 4) == 0, "init bad");
    CHECK(d.func[0] == 0.0f && d.func[1] == 0.0f && d.func[2] == 0.0f && d.func[3] == 2.0f, "sanitised");
    CHECK(fabsf(d.func_int - 0.5f) < 1e-7f, "func_int %g", d.func_int);
    for (int k = 0; k <= 100; ++k) {
        float u = k < 100 ? k / 100.0f : 0x1.fffffep-1f;
        uint32_t i = dist1d_sample_discrete(&d, u, &pdf, NULL);
        CHECK(i == 3 && pdf == 1.0f, "only cell 3 is possible: u %g -> %u (pmf %g)", u, i, pdf);
        x = dist1d_sample_continuous(&d, u, &pdf, NULL);
        CHECK(x >= 0.75f && x < 1.0f && pdf == 4.0f, "continuous u %g -> x %g pdf %g", u, x, pdf);
    }
    /* Out-of-range / NaN u must not crash or leave [0,1). */
    x = dist1d_sample_continuous(&d, 1.0f, &pdf, NULL);
    CHECK(x < 1.0f && isfinite(pdf), "u = 1 -> %g", x);
    x = dist1d_sample_continuous(&d, NAN, &pdf, NULL);
    CHECK(x >= 0.0f && x < 1.0f && isfinite(pdf), "u = NaN -> %g", x);
    dist1d_free(&d);

    float one = 3.0f;
    CHECK(dist1d_init(&d, &one, 1) == 0, "init n=1");
    x = dist1d_sample_continuous(&d, 0.25f, &pdf, &cell);
    CHECK(x == 0.25f && pdf == 1.0f && cell == 0, "n=1 x %g pdf %g", x, pdf);
    dist1d_free(&d);

    Distribution2D d2;
    float z2[6] = {0};
    CHECK(dist2d_init(&d2, z2, 3, 2) == 0, "init 2d zeros");
    vec2 p = dist2d_sample(&d2, 0.3f, 0.8f, &pdf);
    CHECK(pdf == 1.0f && fabsf(p.x - 0.3f) < 1e-6f && fabsf(p.y - 0.8f) < 1e-6f, "2d all-zero uniform (%g,%g) pdf %g", p.x, p.y, pdf);
    dist2d_free(&d2);
}

int main(void) {
    const int N = 1000000;
    uint32_t id = 0;
    Warp w;

    w = dir_warp("cosine hemisphere", 0, 0.0, 1.0, ds_cosine, dp_cosine);
    run_warp(&w, ++id, N, 4, 1e-6);
    w = dir_warp("uniform sphere", 0, -1.0, 1.0, ds_sphere, dp_sphere);
    run_warp(&w, ++id, N, 2, 1e-6);
    w = dir_warp("uniform cone cos_max 0.7", 0, 0.7, 1.0, ds_cone, dp_cone);
    w.cos_max = 0.7f;
    run_warp(&w, ++id, N, 2, 1e-6);
    w = dir_warp("uniform cone cos_max -0.4", 0, -0.4, 1.0, ds_cone, dp_cone);
    w.cos_max = -0.4f;
    run_warp(&w, ++id, N, 2, 1e-6);
    w = dir_warp("uniform cone cos_max 0.999", 0, 0.999, 1.0, ds_cone, dp_cone);
    w.cos_max = 0.999f;
    /* cos_max is stored as a float: the cone's true z range is [float(0.999), 1]. */
    w.zlo = (double)0.999f;
    run_warp(&w, ++id, N, 2, 1e-5);

    memset(&w, 0, sizeof w);
    w.name = "concentric disk";
    w.ns = 20; w.nt = 40;
    w.sample = disk_sample;
    w.density = disk_density;
    run_warp(&w, ++id, N, 2, 1e-6);

    memset(&w, 0, sizeof w);
    w.name = "uniform triangle";
    w.ns = 20; w.nt = 40;
    w.sample = tri_sample;
    w.density = tri_density;
    run_warp(&w, ++id, N, 2, 1e-6);

    /* GGX visible normals, histogrammed over wo's hemisphere with s = sqrt(1 - |z|) so that the
     * peak at the pole is spread over several bins and the hemisphere edge (where the pdf jumps
     * to 0) is a bin edge. The pdf still has a kink where wo.wm = 0 that the grid does not
     * follow; 8x8 sub-cells of 4x4 Gauss-Legendre keep the measured quadrature error < 1e-6,
     * so |integral - 1| < 1e-4 leaves a wide margin while catching any wrong factor. */
    const float alphas[4] = {0.05f, 0.2f, 0.5f, 1.0f};
    const vec3 wos[4] = {
        {0.0f, 0.0f, 1.0f},
        {0.866025f, 0.0f, 0.5f},                 /* 60 degrees */
        {0.6f, 0.79749f, 0.06f},                 /* grazing */
        {-0.42426f, 0.42426f, -0.8f},            /* lower hemisphere: sample is flipped */
    };
    static char names[16][64];
    int nn = 0;
    for (int a = 0; a < 4; ++a)
        for (int o = 0; o < 4; ++o) {
            vec3 wo = v3_normalize(wos[o]);
            snprintf(names[nn], sizeof names[nn], "ggx vndf alpha %.2f wo.z %+.2f", alphas[a], wo.z);
            w = dir_warp(names[nn++], 1, 0.0, 0.0, ds_ggx, dp_ggx);
            w.alpha = alphas[a];
            w.wo = wo;
            w.flip = wo.z < 0.0f;
            run_warp(&w, ++id, N, 8, 1e-4);
        }

    /* Consistency of the pieces: G1 = 1/(1+Lambda), G <= min(G1) and the documented D. */
    for (int k = 0; k < 1000; ++k) {
        uint64_t key = rng_path_key(SEED, 999, (uint64_t)k);
        vec3 a = sample_uniform_sphere(rng_uniform(key, 0), rng_uniform(key, 1));
        vec3 b = sample_uniform_sphere(rng_uniform(key, 2), rng_uniform(key, 3));
        float alpha = 0.01f + rng_uniform(key, 4);
        float g = ggx_g(a, b, alpha);
        CHECK(g <= fminf(ggx_g1(a, alpha), ggx_g1(b, alpha)) * (1.0f + 1e-6f) && g >= 0.0f, "G %g", g);
        double c = fabs(a.z), t2 = (1.0 - c * c) / (c * c);
        double q = 1.0 + t2 / ((double)alpha * alpha);
        double d_ref = 1.0 / (PI_D * alpha * alpha * pow(c, 4) * q * q);
        CHECK(fabs(ggx_d(a, alpha) - d_ref) <= 1e-3 * d_ref, "D %g vs %g", ggx_d(a, alpha), d_ref);
    }

    /* Tabulated distributions; inputs include zeros, a NaN, a negative and an infinity. */
    float f1[10] = {1.0f, 0.0f, 3.5f, 0.25f, NAN, 7.0f, -2.0f, 0.5f, INFINITY, 2.0f};
    test_dist1d_discrete(f1, 10, ++id, N);
    Distribution1D d1;
    CHECK(dist1d_init(&d1, f1, 10) == 0, "dist1d_init");
    memset(&w, 0, sizeof w);
    w.name = "dist1d continuous";
    w.ns = 50; w.nt = 1; /* 5 bins per cell: the density is constant in every bin */
    w.sample = d1c_sample;
    w.density = d1c_density;
    w.user = &d1;
    run_warp(&w, ++id, N, 1, 1e-5);
    dist1d_free(&d1);

    enum { NU = 8, NV = 5 };
    float f2[NU * NV];
    for (int i = 0; i < NU * NV; ++i) {
        uint64_t key = rng_path_key(SEED, 777, (uint64_t)i);
        f2[i] = rng_uniform(key, 0) < 0.2f ? 0.0f : 10.0f * sqr(rng_uniform(key, 1));
    }
    for (int u = 0; u < NU; ++u) f2[2 * NU + u] = 0.0f; /* an empty row */
    f2[3] = NAN;
    Distribution2D d2;
    CHECK(dist2d_init(&d2, f2, NU, NV) == 0, "dist2d_init");
    memset(&w, 0, sizeof w);
    w.name = "dist2d";
    w.ns = 40; w.nt = 20; /* 5 x 4 bins per cell */
    w.sample = d2_sample;
    w.density = d2_density;
    w.user = &d2;
    run_warp(&w, ++id, N, 1, 1e-5);
    dist2d_free(&d2);

    test_dist_edge_cases();
    return test_exit();
}
