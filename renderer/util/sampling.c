/* renderer/util/sampling.c: warping functions, GGX microfacet helpers and tabulated distributions.
 * See sampling.h for the contract; tests/test_sampling.c checks every pdf. */
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include "sampling.h"

#include <float.h>
#include <stdlib.h>

/* Largest float strictly below 1: samples in [0,1) never reach 1. */
#define ONE_MINUS_EPS 0x1.fffffep-1f

/* ---------------------------------------------------------------- simple warps */

/* sin and cos of x in [-pi/4, pi/4], where no range reduction is needed: the minimax
 * polynomials of Cephes' sinf and cosf (within 2 ulp there). */
static inline void sincos_quarter(float x, float *s, float *c) {
    float z = x * x;
    *s = ((-1.9515295891e-4f * z + 8.3321608736e-3f) * z - 1.6666654611e-1f) * z * x + x;
    *c = ((2.443315711809948e-5f * z - 1.388731625493765e-3f) * z + 4.166664568298827e-2f) * z * z - 0.5f * z + 1.0f;
}

vec2 sample_concentric_disk(float u1, float u2) {
    /* Shirley & Chiu 1997, as in pbrt: the square's octant picks the angle's range. With
     * phi = (pi/4) minor / major in [-pi/4, pi/4], theta is phi (x major) or pi/2 - phi (y
     * major, so cos and sin swap): one short polynomial pair, no library call, and selects
     * rather than a branch on the octant (taken at random). */
    float ox = 2.0f * u1 - 1.0f, oy = 2.0f * u2 - 1.0f;
    vec2 r = {0.0f, 0.0f};
    if (ox == 0.0f && oy == 0.0f) return r;
    float radius, minor, s, c;
#if defined(__SSE2__)
    /* the selects as bit masks (GCC made branches of them) */
    const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
    __m128 vx = _mm_set_ss(ox), vy = _mm_set_ss(oy);
    __m128 x_major = _mm_cmpgt_ss(_mm_and_ps(vx, abs_mask), _mm_and_ps(vy, abs_mask));
    radius = _mm_cvtss_f32(_mm_or_ps(_mm_and_ps(x_major, vx), _mm_andnot_ps(x_major, vy)));
    minor = _mm_cvtss_f32(_mm_or_ps(_mm_and_ps(x_major, vy), _mm_andnot_ps(x_major, vx)));
    sincos_quarter((PI_F / 4.0f) * (minor / radius), &s, &c);
    __m128 vs = _mm_set_ss(s), vc = _mm_set_ss(c);
    r.x = radius * _mm_cvtss_f32(_mm_or_ps(_mm_and_ps(x_major, vc), _mm_andnot_ps(x_major, vs)));
    r.y = radius * _mm_cvtss_f32(_mm_or_ps(_mm_and_ps(x_major, vs), _mm_andnot_ps(x_major, vc)));
#else
    int x_major = fabsf(ox) > fabsf(oy);
    radius = x_major ? ox : oy;
    minor = x_major ? oy : ox;
    sincos_quarter((PI_F / 4.0f) * (minor / radius), &s, &c);
    r.x = radius * (x_major ? c : s);
    r.y = radius * (x_major ? s : c);
#endif
    return r;
}

/* cos and sin of 2 pi u for u in [0, 1): the octant's centre angle from a table, the rest
 * (|a| <= pi/8) by Taylor polynomials (error below 1e-8 there), rotated by the centre: no
 * division, branch or library call. */
static inline void sincos_turn(float u, float *s, float *c) {
    static const float CENTRE_COS[8] = {0.923879533f, 0.382683432f, -0.382683432f, -0.923879533f,
                                        -0.923879533f, -0.382683432f, 0.382683432f, 0.923879533f};
    static const float CENTRE_SIN[8] = {0.382683432f, 0.923879533f, 0.923879533f, 0.382683432f,
                                        -0.382683432f, -0.923879533f, -0.923879533f, -0.382683432f};
    float f = u * 8.0f;
    int k = (int)f;
    k = k < 0 ? 0 : (k > 7 ? 7 : k);
    float a = (f - (float)k - 0.5f) * (PI_F / 4.0f), z = a * a;
    float sa = a + a * z * (-1.0f / 6.0f + z * (1.0f / 120.0f - z * (1.0f / 5040.0f)));
    float ca = 1.0f - 0.5f * z + z * z * (1.0f / 24.0f - z * (1.0f / 720.0f));
    *c = ca * CENTRE_COS[k] - sa * CENTRE_SIN[k];
    *s = sa * CENTRE_COS[k] + ca * CENTRE_SIN[k];
}

vec3 sample_cosine_hemisphere(float u1, float u2) {
    /* Malley: a uniform point on the unit disk (polar: r = sqrt(u1), phi = 2 pi u2) lifted to
     * the hemisphere. The random numbers are independent uniforms (no stratification for the
     * concentric map to keep), and polar needs neither a division nor an octant branch. */
    float r = sqrtf(u1 > 0.0f ? u1 : 0.0f), s, c;
    sincos_turn(u2, &s, &c);
    return v3(r * c, r * s, safe_sqrtf(1.0f - u1));
}

float pdf_cosine_hemisphere(vec3 w) { return w.z > 0.0f ? w.z * INV_PI_F : 0.0f; }

vec3 sample_uniform_sphere(float u1, float u2) {
    float z = 1.0f - 2.0f * u1;
    float r = safe_sqrtf(1.0f - z * z);
    float phi = 2.0f * PI_F * u2;
    return v3(r * cosf(phi), r * sinf(phi), z);
}

float pdf_uniform_sphere(void) { return INV_4PI_F; }

vec3 sample_uniform_cone(float u1, float u2, float cos_max) {
    float c = clampf(cos_max, -1.0f, 1.0f);
    float cos_t = (1.0f - u1) + u1 * c;
    float sin_t = safe_sqrtf(1.0f - cos_t * cos_t);
    float phi = 2.0f * PI_F * u2;
    return v3(sin_t * cosf(phi), sin_t * sinf(phi), cos_t);
}

float pdf_uniform_cone(float cos_max) {
    /* A degenerate cone (cos_max == 1) would be a delta; clamp the solid angle so the pdf stays
     * finite (it is then merely huge). */
    float solid = 2.0f * PI_F * (1.0f - clampf(cos_max, -1.0f, 1.0f));
    return 1.0f / fmaxf(solid, 1e-30f);
}

vec2 sample_uniform_triangle(float u1, float u2) {
    float su = sqrtf(u1);
    vec2 b = {1.0f - su, u2 * su};
    return b;
}

/* ---------------------------------------------------------------- GGX */

float ggx_d(vec3 wm, float alpha) {
    /* 1/(pi a^2 cos^4 (1 + tan^2/a^2)^2) = 1/(pi a^2 (cos^2 + sin^2/a^2)^2); even in wm.z. */
    float a2 = alpha * alpha;
    float cos2 = wm.z * wm.z;
    float sin2 = wm.x * wm.x + wm.y * wm.y;
    float t = cos2 + sin2 / a2;
    float den = PI_F * a2 * t * t;
    if (!(den > 0.0f)) return 0.0f;
    float d = 1.0f / den;
    return isfinite(d) ? d : 0.0f;
}

float ggx_lambda(vec3 w, float alpha) {
    float cos2 = w.z * w.z;
    float sin2 = w.x * w.x + w.y * w.y;
    if (sin2 == 0.0f) return 0.0f;
    if (cos2 == 0.0f) return INFINITY;
    float a2tan2 = alpha * alpha * (sin2 / cos2);
    return 0.5f * (sqrtf(1.0f + a2tan2) - 1.0f);
}

float ggx_g1(vec3 w, float alpha) { return 1.0f / (1.0f + ggx_lambda(w, alpha)); }

float ggx_g(vec3 wo, vec3 wi, float alpha) {
    return 1.0f / (1.0f + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha));
}

vec3 ggx_sample_visible_normal(vec3 wo, float alpha, float u1, float u2) {
    int flip = wo.z < 0.0f;
    vec3 v = flip ? v3_neg(wo) : wo;
    /* Heitz 2018: stretch to the hemisphere configuration. */
    vec3 vh = v3_normalize(v3(alpha * v.x, alpha * v.y, v.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = lensq > 0.0f ? v3_scale(v3(-vh.y, vh.x, 0.0f), 1.0f / sqrtf(lensq)) : v3(1.0f, 0.0f, 0.0f);
    vec3 t2 = v3_cross(vh, t1);
    float r = sqrtf(u1);
    float phi = 2.0f * PI_F * u2;
    float p1 = r * cosf(phi), p2 = r * sinf(phi);
    float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * safe_sqrtf(1.0f - p1 * p1) + s * p2;
    vec3 nh = v3_add(v3_add(v3_scale(t1, p1), v3_scale(t2, p2)),
                     v3_scale(vh, safe_sqrtf(1.0f - p1 * p1 - p2 * p2)));
    vec3 ne = v3_normalize(v3(alpha * nh.x, alpha * nh.y, maxf(nh.z, 0.0f)));
    return flip ? v3_neg(ne) : ne;
}

float ggx_pdf_visible_normal(vec3 wo, vec3 wm, float alpha) {
    if (wo.z == 0.0f || wo.z * wm.z <= 0.0f) return 0.0f;
    float cos_om = v3_dot(wo, wm);
    if (!(cos_om > 0.0f)) return 0.0f;
    float pdf = ggx_g1(wo, alpha) * cos_om * ggx_d(wm, alpha) / fabsf(wo.z);
    return isfinite(pdf) ? pdf : 0.0f;
}

/* ---------------------------------------------------------------- Distribution1D */

int dist1d_init(Distribution1D *d, const float *func, uint32_t n) {
    d->n = 0;
    d->func = NULL;
    d->cdf = NULL;
    d->func_int = 0.0f;
    if (n == 0) return -1;
    d->func = malloc(sizeof(float) * n);
    d->cdf = malloc(sizeof(float) * ((size_t)n + 1));
    if (!d->func || !d->cdf) {
        free(d->func);
        free(d->cdf);
        d->func = d->cdf = NULL;
        return -1;
    }
    d->n = n;
    double sum = 0.0;
    for (uint32_t i = 0; i < n; ++i) {
        float f = func ? func[i] : 0.0f;
        if (!isfinite(f) || !(f > 0.0f)) f = 0.0f;
        d->func[i] = f;
        sum += f;
    }
    double integral = sum / (double)n;
    if (integral > (double)FLT_MAX) {
        /* Rescale huge inputs so func_int stays finite (pdfs are unchanged). */
        double s = (double)FLT_MAX / integral * 0.5;
        for (uint32_t i = 0; i < n; ++i) d->func[i] = (float)(d->func[i] * s);
        sum *= s;
        integral *= s;
    }
    d->func_int = (float)integral;
    d->cdf[0] = 0.0f;
    if (sum > 0.0) {
        double acc = 0.0;
        for (uint32_t i = 1; i < n; ++i) {
            acc += d->func[i - 1];
            d->cdf[i] = (float)(acc / sum);
        }
    } else {
        for (uint32_t i = 1; i < n; ++i) d->cdf[i] = (float)((double)i / n);
    }
    d->cdf[n] = 1.0f;
    return 0;
}

void dist1d_free(Distribution1D *d) {
    free(d->func);
    free(d->cdf);
    d->func = d->cdf = NULL;
    d->n = 0;
    d->func_int = 0.0f;
}

/* Largest i in [0, n-1] with cdf[i] <= u (the cdf is non-decreasing from cdf[0] = 0; cells of
 * zero probability are never returned for u in [0,1), because their start equals the next
 * cell's start): a binary search whose step count depends on n only and whose step is a
 * conditional move, not a branch on the random u. */
static uint32_t find_cell(const Distribution1D *d, float u) {
    uint32_t lo = 0, len = d->n;
    while (len > 1) {
        uint32_t half = len / 2;
        lo = d->cdf[lo + half] <= u ? lo + half : lo;
        len -= half;
    }
    return lo;
}

static float sanitize_u(float u) {
    if (!(u >= 0.0f)) return 0.0f; /* also NaN */
    return u < 1.0f ? u : ONE_MINUS_EPS;
}

static float cell_offset(const Distribution1D *d, uint32_t i, float u) {
    float w = d->cdf[i + 1] - d->cdf[i];
    float du = w > 0.0f ? (u - d->cdf[i]) / w : 0.0f;
    return clampf(du, 0.0f, ONE_MINUS_EPS);
}

float dist1d_pmf(const Distribution1D *d, uint32_t i) {
    if (d->n == 0 || i >= d->n) return 0.0f;
    if (!(d->func_int > 0.0f)) return 1.0f / (float)d->n;
    return (float)((double)d->func[i] / ((double)d->func_int * d->n));
}

uint32_t dist1d_sample_discrete(const Distribution1D *d, float u, float *pmf, float *u_remapped) {
    u = sanitize_u(u);
    uint32_t i = find_cell(d, u);
    if (pmf) *pmf = dist1d_pmf(d, i);
    if (u_remapped) *u_remapped = cell_offset(d, i, u);
    return i;
}

/* Cell of x, computed exactly as dist1d_pdf_continuous does (float x * n). */
static uint32_t cell_of(const Distribution1D *d, float x) {
    float fx = x * (float)d->n;
    return fx <= 0.0f ? 0u : (fx >= (float)(d->n - 1) ? d->n - 1 : (uint32_t)fx);
}

float dist1d_sample_continuous(const Distribution1D *d, float u, float *pdf, uint32_t *cell) {
    u = sanitize_u(u);
    uint32_t i = find_cell(d, u);
    float du = cell_offset(d, i, u);
    if (pdf) *pdf = d->func_int > 0.0f ? d->func[i] / d->func_int : 1.0f;
    if (cell) *cell = i;
    float x = (float)(((double)i + du) / (double)d->n);
    if (!(x < 1.0f)) x = ONE_MINUS_EPS;
    /* Rounding may push x across a cell edge (into a cell that may have zero density); step
     * back so that the pdf lookup of x finds cell i again. */
    while (x > 0.0f && cell_of(d, x) > i) x = nextafterf(x, 0.0f);
    while (x < ONE_MINUS_EPS && cell_of(d, x) < i) x = nextafterf(x, 1.0f);
    return x;
}

float dist1d_pdf_continuous(const Distribution1D *d, float x) {
    if (d->n == 0 || isnan(x)) return 0.0f;
    uint32_t i = cell_of(d, x);
    return d->func_int > 0.0f ? d->func[i] / d->func_int : 1.0f;
}

/* ---------------------------------------------------------------- Distribution2D */

int dist2d_init(Distribution2D *d, const float *func, uint32_t nu, uint32_t nv) {
    d->nu = nu;
    d->nv = nv;
    d->conditional = NULL;
    d->marginal.n = 0;
    d->marginal.func = d->marginal.cdf = NULL;
    d->marginal.func_int = 0.0f;
    if (nu == 0 || nv == 0) return -1;
    d->conditional = calloc(nv, sizeof(Distribution1D));
    float *marg = malloc(sizeof(float) * nv);
    if (!d->conditional || !marg) {
        free(d->conditional);
        free(marg);
        d->conditional = NULL;
        return -1;
    }
    for (uint32_t v = 0; v < nv; ++v) {
        if (dist1d_init(&d->conditional[v], func ? func + (size_t)v * nu : NULL, nu) != 0) {
            for (uint32_t k = 0; k < v; ++k) dist1d_free(&d->conditional[k]);
            free(d->conditional);
            free(marg);
            d->conditional = NULL;
            return -1;
        }
        marg[v] = d->conditional[v].func_int;
    }
    int rc = dist1d_init(&d->marginal, marg, nv);
    free(marg);
    if (rc != 0) {
        for (uint32_t k = 0; k < nv; ++k) dist1d_free(&d->conditional[k]);
        free(d->conditional);
        d->conditional = NULL;
        return -1;
    }
    return 0;
}

void dist2d_free(Distribution2D *d) {
    if (d->conditional) {
        for (uint32_t v = 0; v < d->nv; ++v) dist1d_free(&d->conditional[v]);
        free(d->conditional);
    }
    d->conditional = NULL;
    dist1d_free(&d->marginal);
    d->nu = d->nv = 0;
}

vec2 dist2d_sample(const Distribution2D *d, float u0, float u1, float *pdf) {
    float pdf_v, pdf_u;
    uint32_t iv;
    float v = dist1d_sample_continuous(&d->marginal, u1, &pdf_v, &iv);
    float u = dist1d_sample_continuous(&d->conditional[iv], u0, &pdf_u, NULL);
    if (pdf) *pdf = pdf_u * pdf_v;
    vec2 r = {u, v};
    return r;
}

float dist2d_pdf(const Distribution2D *d, vec2 uv) {
    if (d->nv == 0 || isnan(uv.x) || isnan(uv.y)) return 0.0f;
    float fv = uv.y * (float)d->nv;
    uint32_t iv = fv <= 0.0f ? 0u : (fv >= (float)(d->nv - 1) ? d->nv - 1 : (uint32_t)fv);
    return dist1d_pdf_continuous(&d->marginal, uv.y) * dist1d_pdf_continuous(&d->conditional[iv], uv.x);
}
