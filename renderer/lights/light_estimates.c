/* renderer/lights/light_estimates.c: unoccluded light-contribution estimates.
 *
 * For a receiver (p, n) every light gets an estimate of its unoccluded irradiance at p on the
 * plane with normal n (fluence when n is zero: volumes, transmissive surfaces). These are the
 * weights of the cache points paper's "optimal" per-vertex selection (Table 1), of the cache
 * points' near lists (§3.3) and far bins (§3.1.3: irradiance on the six cardinal planes and
 * the fluence, estimate7). Point and spot lights are exact (intensity cos / r^2); an area
 * light sums 16 fixed stratified points on it; a directional light is its irradiance times the
 * receiver cosine; the environment is integrated once over its cells (position-independent)
 * and blended over the six planes by max(0, n.a_i)^2, which sums to 1 for a unit n.
 * Every estimate is a deterministic function of (light, p, n). */
#include <stdlib.h>
#include <string.h>

#include "lights.h"
#include "scene.h"

#define AREA_ESTIMATE_SAMPLES 16
/* GCC and clang on x86: an AVX version of the area estimate, chosen at run time */
#if defined(__SSE2__) && defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
#define AREA_ESTIMATE_AVX 1
#endif

/* b_i(n) = max(0, n.a_i)^2 over the 6 cardinal axes sums to 1 for a unit n, so the six
 * planes blend into the irradiance on any plane without changing the total. */
static float env_irradiance_estimate(const Lights *ls, vec3 n) {
    if (v3_is_black(n)) return ls->env_estimate[6];
    float w[6] = {sqr(maxf(n.x, 0.0f)), sqr(maxf(-n.x, 0.0f)), sqr(maxf(n.y, 0.0f)),
                  sqr(maxf(-n.y, 0.0f)), sqr(maxf(n.z, 0.0f)), sqr(maxf(-n.z, 0.0f))};
    float e = 0.0f;
    for (int i = 0; i < 6; ++i) e += w[i] * ls->env_estimate[i];
    return e;
}

/* cosine factor of the receiver: max(0, n.w), or 1 for an omnidirectional receiver */
static inline float receiver_cos(vec3 n, vec3 w) {
    return v3_is_black(n) ? 1.0f : maxf(v3_dot(n, w), 0.0f);
}

/* Point k of an area light's 16 fixed stratified points (triangles in proportion to area) and
 * its triangle's unit normal: the same points for every call, so estimates are deterministic. */
static vec3 area_estimate_point(const Light *l, int k, vec3 *ng) {
    float u0 = ((float)k + 0.5f) / AREA_ESTIMATE_SAMPLES;
    float u1 = (float)((k * 7 + 3) % AREA_ESTIMATE_SAMPLES) / AREA_ESTIMATE_SAMPLES + 0.5f / AREA_ESTIMATE_SAMPLES;
    float u2 = (float)((k * 11 + 5) % AREA_ESTIMATE_SAMPLES) / AREA_ESTIMATE_SAMPLES + 0.5f / AREA_ESTIMATE_SAMPLES;
    float tri_pmf, u_tri;
    uint32_t t = dist1d_sample_discrete(&l->triangles, u0, &tri_pmf, &u_tri);
    const float *v = l->world_vertices + 9 * (size_t)t;
    vec3 a = v3(v[0], v[1], v[2]), b = v3(v[3], v[4], v[5]), c = v3(v[6], v[7], v[8]);
    vec2 bc = sample_uniform_triangle(u1, u2);
    *ng = v3_normalize(v3_cross(v3_sub(b, a), v3_sub(c, a)));
    return v3_add(v3_add(v3_scale(a, 1.0f - bc.x - bc.y), v3_scale(b, bc.x)), v3_scale(c, bc.y));
}

/* One point's term of the area-light estimate, (A L / 16) cos_l cos_r / r^2 (cos_r = 1 for an
 * omnidirectional receiver), written with unnormalised d = y - p as (A L / 16) (c / d2) (b / d2)
 * with c = -ng.d and b = n.d: one division, where normalising d had taken a square root and
 * three divisions (the estimate was the largest part of the default sampler's shading cost on
 * scenes/bench.gltf). An omnidirectional receiver's b / d2 is 1 / r = sqrt(1 / d2). Zero where
 * the point is behind either surface, at p, or beyond float range. scale = A L / 16. The
 * vector versions below do the same operations in the same order, so the same bits. */
static inline float area_point_term(float scale, vec3 y, vec3 ng, vec3 p, vec3 n, int two_sided, int omni) {
    float dx = y.x - p.x, dy = y.y - p.y, dz = y.z - p.z;
    float d2 = dx * dx + dy * dy + dz * dz;
    float inv = 1.0f / d2;
    float c = -(ng.x * dx + ng.y * dy + ng.z * dz);
    if (two_sided) c = fabsf(c);
    float b = omni ? sqrtf(inv) : (n.x * dx + n.y * dy + n.z * dz) * inv;
    float t = scale * (c * inv) * b;
    int valid = (d2 > 1e-12f) & (d2 < INFINITY) & (c > 0.0f) & (b > 0.0f);
    return valid ? t : 0.0f;
}

/* The 16 terms' sum as a tree, halves first (t[j] + t[j + 8], then + 4, + 2, + 1): what the
 * vector versions add in their registers, so every version has the same bits. */
static inline float area_terms_sum(const float t[AREA_ESTIMATE_SAMPLES]) {
    float s8[8], s4[4];
    for (int j = 0; j < 8; ++j) s8[j] = t[j] + t[j + 8];
    for (int j = 0; j < 4; ++j) s4[j] = s8[j] + s8[j + 4];
    return (s4[0] + s4[2]) + (s4[1] + s4[3]);
}

/* The points seen from p for the seven-bin estimate: for each, the unit direction from p and
 * the unoccluded contribution L cos_l / r^2 * A / 16. Returns the number written. */
static int area_estimate_samples(const Light *l, vec3 p, vec3 dirs[AREA_ESTIMATE_SAMPLES],
                                 float contrib[AREA_ESTIMATE_SAMPLES]) {
    float L = v3_luminance(l->emission);
    if (!(L > 0.0f)) return 0;
    int count = 0;
    for (int k = 0; k < AREA_ESTIMATE_SAMPLES; ++k) {
        vec3 ng, y = area_estimate_point(l, k, &ng);
        vec3 d = v3_sub(y, p);
        float d2 = v3_dot(d, d);
        if (!(d2 > 1e-12f)) continue;
        vec3 w = v3_scale(d, 1.0f / sqrtf(d2));
        float cos_l = -v3_dot(ng, w);
        if (l->two_sided) cos_l = fabsf(cos_l);
        if (!(cos_l > 0.0f)) continue;
        dirs[count] = w;
        contrib[count] = L * cos_l / d2 * l->area / AREA_ESTIMATE_SAMPLES;
        ++count;
    }
    return count;
}

/* --- the estimate table: the same estimates with the position-independent part done once */

/* the lights light_contribution_estimate_table takes its LIGHT_POINT case for */
static int table_point_light(const Light *l) { return l->type == LIGHT_POINT && !light_is_shape(l); }

int light_estimate_table_build(LightEstimateTable *t, const Lights *ls) {
    memset(t, 0, sizeof *t);
    t->slot = malloc(((size_t)ls->count + 1) * sizeof *t->slot);
    t->lum = malloc(((size_t)ls->count + 1) * sizeof *t->lum);
    uint32_t areas = 0;
    for (uint32_t i = 0; t->slot && i < ls->count; ++i) {
        int area = light_is_areal(&ls->lights[i]) && v3_luminance(ls->lights[i].emission) > 0.0f;
        t->slot[i] = area ? areas++ : UINT32_MAX;
    }
    t->points = malloc(((size_t)areas + 1) * sizeof *t->points);
    uint32_t points = 0;
    for (uint32_t i = 0; i < ls->count; ++i) points += table_point_light(&ls->lights[i]);
    size_t padded = ((size_t)points + 3) / 4 * 4 + 4;
    t->point_light = malloc(((size_t)points + 1) * sizeof *t->point_light);
    t->other_light = malloc(((size_t)ls->count - points + 1) * sizeof *t->other_light);
    t->point_x = calloc(4 * padded, sizeof(float));
    if (!t->slot || !t->lum || !t->points || !t->point_light || !t->other_light || !t->point_x) { light_estimate_table_free(t); return -1; }
    t->point_y = t->point_x + padded;
    t->point_z = t->point_y + padded;
    t->point_lum = t->point_z + padded;
#if defined(AREA_ESTIMATE_AVX)
    t->avx = __builtin_cpu_supports("avx");
#endif
    for (uint32_t i = 0; i < ls->count; ++i) {
        const Light *l = &ls->lights[i];
        if (!table_point_light(l)) { t->other_light[t->num_other_lights++] = i; continue; }
        uint32_t k = t->num_point_lights++;
        t->point_light[k] = i;
        t->point_x[k] = l->position.x;
        t->point_y[k] = l->position.y;
        t->point_z[k] = l->position.z;
        t->point_lum[k] = v3_luminance(l->intensity);
    }
    for (uint32_t i = 0; i < ls->count; ++i) {
        const Light *l = &ls->lights[i];
        t->lum[i] = light_is_areal(l) ? v3_luminance(l->emission) : v3_luminance(l->intensity);
        if (t->slot[i] == UINT32_MAX) continue;
        LightEstimatePoints *e = &t->points[t->slot[i]];
        for (int k = 0; k < AREA_ESTIMATE_SAMPLES; ++k) {
            vec3 ng, y = area_estimate_point(l, k, &ng);
            e->y[0][k] = y.x; e->y[1][k] = y.y; e->y[2][k] = y.z;
            e->ng[0][k] = ng.x; e->ng[1][k] = ng.y; e->ng[2][k] = ng.z;
        }
    }
    return 0;
}

void light_estimate_table_free(LightEstimateTable *t) {
    free(t->slot);
    free(t->lum);
    free(t->points);
    free(t->point_light);
    free(t->other_light);
    free(t->point_x);
    memset(t, 0, sizeof *t);
}

/* An area light's estimate over its table points: each point's area_point_term in its own
 * lane, then the terms added as area_terms_sum's tree, in the registers. Bit for bit
 * light_contribution_estimate: every lane does its float operations in the same order (no
 * contraction: SSE2 has no fused multiply-add), an invalid point's term is +0 in both
 * (test_lights compares the bits). With SSE2 (every x86-64) four points at a time in explicit vector registers (GCC left
 * the plain loop scalar); with AVX eight; elsewhere the scalar term. */
#if defined(__SSE2__)
#include <emmintrin.h>
static float area_estimate_lanes(const LightEstimatePoints *e, float scale, vec3 p, vec3 n, const int two_sided,
                                 const int omni) {
    __m128 term[AREA_ESTIMATE_SAMPLES / 4];
    const __m128 px = _mm_set1_ps(p.x), py = _mm_set1_ps(p.y), pz = _mm_set1_ps(p.z);
    const __m128 nx = _mm_set1_ps(n.x), ny = _mm_set1_ps(n.y), nz = _mm_set1_ps(n.z);
    const __m128 one = _mm_set1_ps(1.0f), zero = _mm_setzero_ps(), eps = _mm_set1_ps(1e-12f);
    const __m128 inf = _mm_set1_ps(INFINITY), vscale = _mm_set1_ps(scale), sign = _mm_set1_ps(-0.0f);
    for (int k = 0; k < AREA_ESTIMATE_SAMPLES; k += 4) {
        __m128 dx = _mm_sub_ps(_mm_loadu_ps(&e->y[0][k]), px);
        __m128 dy = _mm_sub_ps(_mm_loadu_ps(&e->y[1][k]), py);
        __m128 dz = _mm_sub_ps(_mm_loadu_ps(&e->y[2][k]), pz);
        __m128 d2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz));
        __m128 inv = _mm_div_ps(one, d2);
        __m128 c = _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_loadu_ps(&e->ng[0][k]), dx), _mm_mul_ps(_mm_loadu_ps(&e->ng[1][k]), dy)),
                              _mm_mul_ps(_mm_loadu_ps(&e->ng[2][k]), dz));
        c = _mm_xor_ps(c, sign);                   /* -(...) */
        if (two_sided) c = _mm_andnot_ps(sign, c); /* fabsf */
        __m128 b = omni ? _mm_sqrt_ps(inv)
                        : _mm_mul_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(nx, dx), _mm_mul_ps(ny, dy)), _mm_mul_ps(nz, dz)), inv);
        __m128 t = _mm_mul_ps(_mm_mul_ps(vscale, _mm_mul_ps(c, inv)), b);
        __m128 valid = _mm_and_ps(_mm_and_ps(_mm_cmpgt_ps(d2, eps), _mm_cmplt_ps(d2, inf)),
                                  _mm_and_ps(_mm_cmpgt_ps(c, zero), _mm_cmpgt_ps(b, zero)));
        term[k / 4] = _mm_and_ps(valid, t);
    }
    /* area_terms_sum: lanes j of (t0 + t8) + (t4 + t12), then j + 2, then j + 1 */
    __m128 s4 = _mm_add_ps(_mm_add_ps(term[0], term[2]), _mm_add_ps(term[1], term[3]));
    __m128 s2 = _mm_add_ps(s4, _mm_movehl_ps(s4, s4));
    return _mm_cvtss_f32(_mm_add_ss(s2, _mm_shuffle_ps(s2, s2, 1)));
}
#if defined(AREA_ESTIMATE_AVX)
#include <immintrin.h>
/* The same lanes eight at a time, for CPUs with AVX (chosen at run time: the build targets
 * every x86-64). AVX without FMA has the same IEEE operations as SSE2 (no contraction), so the
 * terms, and their sum in point order, are bit for bit the SSE2 version's. */
__attribute__((target("avx"))) static float area_estimate_lanes8(const LightEstimatePoints *e, float scale, vec3 p,
                                                                  vec3 n, const int two_sided, const int omni) {
    __m256 term[AREA_ESTIMATE_SAMPLES / 8];
    const __m256 px = _mm256_set1_ps(p.x), py = _mm256_set1_ps(p.y), pz = _mm256_set1_ps(p.z);
    const __m256 nx = _mm256_set1_ps(n.x), ny = _mm256_set1_ps(n.y), nz = _mm256_set1_ps(n.z);
    const __m256 one = _mm256_set1_ps(1.0f), zero = _mm256_setzero_ps(), eps = _mm256_set1_ps(1e-12f);
    const __m256 inf = _mm256_set1_ps(INFINITY), vscale = _mm256_set1_ps(scale), sign = _mm256_set1_ps(-0.0f);
    for (int k = 0; k < AREA_ESTIMATE_SAMPLES; k += 8) {
        __m256 dx = _mm256_sub_ps(_mm256_loadu_ps(&e->y[0][k]), px);
        __m256 dy = _mm256_sub_ps(_mm256_loadu_ps(&e->y[1][k]), py);
        __m256 dz = _mm256_sub_ps(_mm256_loadu_ps(&e->y[2][k]), pz);
        __m256 d2 = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)), _mm256_mul_ps(dz, dz));
        __m256 inv = _mm256_div_ps(one, d2);
        __m256 c = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_loadu_ps(&e->ng[0][k]), dx),
                                               _mm256_mul_ps(_mm256_loadu_ps(&e->ng[1][k]), dy)),
                                 _mm256_mul_ps(_mm256_loadu_ps(&e->ng[2][k]), dz));
        c = _mm256_xor_ps(c, sign);
        if (two_sided) c = _mm256_andnot_ps(sign, c);
        __m256 b = omni ? _mm256_sqrt_ps(inv)
                        : _mm256_mul_ps(_mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(nx, dx), _mm256_mul_ps(ny, dy)),
                                                      _mm256_mul_ps(nz, dz)),
                                        inv);
        __m256 t = _mm256_mul_ps(_mm256_mul_ps(vscale, _mm256_mul_ps(c, inv)), b);
        __m256 valid = _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(d2, eps, _CMP_GT_OQ), _mm256_cmp_ps(d2, inf, _CMP_LT_OQ)),
                                     _mm256_and_ps(_mm256_cmp_ps(c, zero, _CMP_GT_OQ), _mm256_cmp_ps(b, zero, _CMP_GT_OQ)));
        term[k / 8] = _mm256_and_ps(valid, t);
    }
    /* area_terms_sum: lanes j of t0 + t8, then j + 4, j + 2, j + 1 */
    __m256 s8 = _mm256_add_ps(term[0], term[1]);
    __m128 s4 = _mm_add_ps(_mm256_castps256_ps128(s8), _mm256_extractf128_ps(s8, 1));
    __m128 s2 = _mm_add_ps(s4, _mm_movehl_ps(s4, s4));
    return _mm_cvtss_f32(_mm_add_ss(s2, _mm_shuffle_ps(s2, s2, 1)));
}
#endif
#else
static float area_estimate_lanes(const LightEstimatePoints *e, float scale, vec3 p, vec3 n, const int two_sided,
                                 const int omni) {
    float term[AREA_ESTIMATE_SAMPLES];
    for (int k = 0; k < AREA_ESTIMATE_SAMPLES; ++k)
        term[k] = area_point_term(scale, v3(e->y[0][k], e->y[1][k], e->y[2][k]), v3(e->ng[0][k], e->ng[1][k], e->ng[2][k]),
                                  p, n, two_sided, omni);
    return area_terms_sum(term);
}
#endif

static float area_estimate_table(const LightEstimateTable *t, const Light *l, const LightEstimatePoints *e, float L,
                                 vec3 p, vec3 n) {
    int omni = v3_is_black(n);
    float scale = L * l->area / AREA_ESTIMATE_SAMPLES;
#if defined(AREA_ESTIMATE_AVX)
    if (t->avx) {
        if (l->two_sided) return omni ? area_estimate_lanes8(e, scale, p, n, 1, 1) : area_estimate_lanes8(e, scale, p, n, 1, 0);
        return omni ? area_estimate_lanes8(e, scale, p, n, 0, 1) : area_estimate_lanes8(e, scale, p, n, 0, 0);
    }
#else
    (void)t;
#endif
    if (l->two_sided) return omni ? area_estimate_lanes(e, scale, p, n, 1, 1) : area_estimate_lanes(e, scale, p, n, 1, 0);
    return omni ? area_estimate_lanes(e, scale, p, n, 0, 1) : area_estimate_lanes(e, scale, p, n, 0, 0);
}

/* Bit for bit light_contribution_estimate (the same float operations in the same order), with
 * the area light's 16 points and the luminances read from the table. */
float light_contribution_estimate_table(const Lights *ls, const LightEstimateTable *t, uint32_t light, vec3 p, vec3 n) {
    const Light *l = &ls->lights[light];
    if (light_is_shape(l) && !light_is_areal(l)) return light_contribution_estimate(ls, l, p, n);
    switch (l->type) {
    case LIGHT_POINT: {
        vec3 d = v3_sub(l->position, p);
        float d2 = v3_dot(d, d);
        if (!(d2 > 0.0f)) return 0.0f;
        vec3 w = v3_scale(d, 1.0f / sqrtf(d2));
        return t->lum[light] * receiver_cos(n, w) / d2;
    }
    case LIGHT_RECT:
    case LIGHT_DISK:
    case LIGHT_AREA:
        if (t->slot[light] == UINT32_MAX) return 0.0f; /* no emission */
        return area_estimate_table(t, l, &t->points[t->slot[light]], t->lum[light], p, n);
    default:
        return light_contribution_estimate(ls, l, p, n);
    }
}

#if defined(__SSE2__)
/* Point lights k .. k+3 of the table: light_contribution_estimate_table's LIGHT_POINT case in
 * four lanes (the same operations in the same order, so the same bits; the padding lanes are
 * computed and not stored). */
static void point_estimate_lanes(const LightEstimateTable *t, uint32_t k, vec3 p, vec3 n, int omni, float out[4]) {
    const __m128 zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f);
    __m128 dx = _mm_sub_ps(_mm_loadu_ps(t->point_x + k), _mm_set1_ps(p.x));
    __m128 dy = _mm_sub_ps(_mm_loadu_ps(t->point_y + k), _mm_set1_ps(p.y));
    __m128 dz = _mm_sub_ps(_mm_loadu_ps(t->point_z + k), _mm_set1_ps(p.z));
    __m128 d2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz));
    __m128 rc = one;
    if (!omni) {
        __m128 inv = _mm_div_ps(one, _mm_sqrt_ps(d2));
        __m128 dot = _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_set1_ps(n.x), _mm_mul_ps(dx, inv)),
                                           _mm_mul_ps(_mm_set1_ps(n.y), _mm_mul_ps(dy, inv))),
                                _mm_mul_ps(_mm_set1_ps(n.z), _mm_mul_ps(dz, inv)));
        rc = _mm_and_ps(_mm_cmpgt_ps(dot, zero), dot); /* maxf(dot, 0): NaN and -0 give +0 */
    }
    __m128 e = _mm_div_ps(_mm_mul_ps(_mm_loadu_ps(t->point_lum + k), rc), d2);
    _mm_storeu_ps(out, _mm_and_ps(_mm_cmpgt_ps(d2, zero), e)); /* !(d2 > 0): 0 */
}
#endif

void light_estimate_table_all(const Lights *ls, const LightEstimateTable *t, vec3 p, vec3 n, float *out) {
    for (uint32_t k = 0; k < t->num_other_lights; ++k) {
        uint32_t i = t->other_light[k];
        const Light *l = &ls->lights[i];
        /* light_contribution_estimate_table's area case without its dispatch */
        if (t->slot[i] != UINT32_MAX) out[i] = area_estimate_table(t, l, &t->points[t->slot[i]], t->lum[i], p, n);
        else out[i] = light_contribution_estimate_table(ls, t, i, p, n);
    }
#if defined(__SSE2__)
    int omni = v3_is_black(n);
    for (uint32_t k = 0; k < t->num_point_lights; k += 4) {
        float e[4];
        point_estimate_lanes(t, k, p, n, omni, e);
        for (uint32_t j = 0; j < 4 && k + j < t->num_point_lights; ++j) out[t->point_light[k + j]] = e[j];
    }
#else
    for (uint32_t k = 0; k < t->num_point_lights; ++k)
        out[t->point_light[k]] = light_contribution_estimate_table(ls, t, t->point_light[k], p, n);
#endif
}

/* The receiver cosine of the direction in a cone (axis w, sin^2 of its half-angle s2) nearest
 * to n: cos(max(theta_n - theta_max, 0)), so a sphere or sun partly above the horizon keeps a
 * weight (1 for an omnidirectional receiver). */
static float receiver_cos_cone(vec3 n, vec3 w, float s2) {
    if (v3_is_black(n)) return 1.0f;
    float c = clampf(v3_dot(n, w), -1.0f, 1.0f), sn = sqrtf(fmaxf(0.0f, 1.0f - c * c));
    float cm = sqrtf(fmaxf(0.0f, 1.0f - s2)), sm = sqrtf(fminf(fmaxf(s2, 0.0f), 1.0f));
    if (c >= cm) return 1.0f; /* the normal inside the cone */
    return maxf(c * cm + sn * sm, 0.0f);
}

/* A sphere (radius r) seen from p: its intensity towards p over d^2 (never nearer than r), with
 * the receiver cosine of the nearest direction in its cone (the estimates' point formula, made
 * smooth and nonzero wherever part of the sphere is above p's horizon). */
static float sphere_estimate(const Light *l, vec3 p, vec3 n, int falloff) {
    vec3 d = v3_sub(l->position, p);
    float r2 = l->radius * l->radius;
    float d2 = maxf(v3_dot(d, d), r2);
    vec3 w = v3_scale(d, 1.0f / sqrtf(d2));
    float I = v3_luminance(l->intensity);
    if (falloff && l->type == LIGHT_SPOT) I *= light_spot_falloff(l, v3_neg(w));
    return I * receiver_cos_cone(n, w, r2 / d2) / d2;
}

float light_contribution_estimate(const Lights *ls, const Light *l, vec3 p, vec3 n) {
    if ((l->type == LIGHT_POINT || l->type == LIGHT_SPOT) && l->radius > 0.0f) return sphere_estimate(l, p, n, 1);
    if (l->type == LIGHT_DIRECTIONAL && l->sun_omc > 0.0f) {
        float omc = l->sun_omc;
        return v3_luminance(l->intensity) * receiver_cos_cone(n, v3_neg(l->direction), omc * (2.0f - omc));
    }
    switch (l->type) {
    case LIGHT_POINT:
    case LIGHT_SPOT: {
        vec3 d = v3_sub(l->position, p);
        float d2 = v3_dot(d, d);
        if (!(d2 > 0.0f)) return 0.0f;
        vec3 w = v3_scale(d, 1.0f / sqrtf(d2));
        float I = v3_luminance(l->intensity);
        if (l->type == LIGHT_SPOT) I *= light_spot_falloff(l, v3_neg(w));
        return I * receiver_cos(n, w) / d2;
    }
    case LIGHT_VOLUME: { /* a selection weight: the volume seen as a point at its emission centroid */
        vec3 d = v3_sub(l->position, p);
        float d2 = maxf(v3_dot(d, d), 1e-8f);
        return v3_luminance(l->intensity) * receiver_cos(n, v3_scale(d, 1.0f / sqrtf(d2))) / d2;
    }
    case LIGHT_DIRECTIONAL:
        return v3_luminance(l->intensity) * receiver_cos(n, v3_neg(l->direction));
    case LIGHT_ENVIRONMENT:
        return env_irradiance_estimate(ls, n);
    case LIGHT_RECT:
    case LIGHT_DISK:
    case LIGHT_AREA: {
        /* (A/16) sum L cos_l max(0, n.w) / r^2 over the 16 stratified points */
        float L = v3_luminance(l->emission);
        if (!(L > 0.0f)) return 0.0f;
        float scale = L * l->area / AREA_ESTIMATE_SAMPLES, term[AREA_ESTIMATE_SAMPLES];
        int omni = v3_is_black(n);
        for (int k = 0; k < AREA_ESTIMATE_SAMPLES; ++k) {
            vec3 ng, y = area_estimate_point(l, k, &ng);
            term[k] = area_point_term(scale, y, ng, p, n, l->two_sided, omni);
        }
        return area_terms_sum(term);
    }
    }
    return 0.0f;
}

/* Env irradiance on the 6 cardinal planes and the fluence (index 6), integrated over the
 * lat-long cells once at build: position-independent (a dome at infinity). */
void light_env_estimates(const Scene *scene, float out[7]) {
    memset(out, 0, 7 * sizeof(float));
    const IoImage *im = &scene->env;
    if (im->width <= 0) return;
    const vec3 axes[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    double acc[7] = {0};
    for (int y = 0; y < im->height; ++y) {
        float v = ((float)y + 0.5f) / (float)im->height;
        float dw = (2.0f * PI_F / (float)im->width) * (PI_F / (float)im->height) * sinf(v * PI_F);
        for (int x = 0; x < im->width; ++x) {
            vec3 d = scene_env_uv_to_dir(scene, (vec2){((float)x + 0.5f) / (float)im->width, v});
            const float *t = im->rgba + 4 * ((size_t)y * (size_t)im->width + (size_t)x);
            double L = (double)v3_luminance(v3(t[0], t[1], t[2])) * scene->env_strength * dw;
            for (int i = 0; i < 6; ++i) acc[i] += L * maxf(v3_dot(axes[i], d), 0.0f);
            acc[6] += L;
        }
    }
    for (int i = 0; i < 7; ++i) out[i] = (float)acc[i];
}

/* The seven cache-point bins at once (§3.1.3): irradiance on the planes facing +X -X +Y -Y
 * +Z -Z and the fluence, from the same samples as light_contribution_estimate. */
void light_contribution_estimate7(const Lights *ls, const Light *l, vec3 p, float out[7]) {
    for (int i = 0; i < 7; ++i) out[i] = 0.0f;
    vec3 dirs[AREA_ESTIMATE_SAMPLES];
    float contrib[AREA_ESTIMATE_SAMPLES];
    int count = 0;
    switch (l->type) {
    case LIGHT_ENVIRONMENT:
        for (int i = 0; i < 7; ++i) out[i] = ls->env_estimate[i];
        return;
    case LIGHT_DIRECTIONAL:
        dirs[0] = v3_neg(l->direction);
        contrib[0] = v3_luminance(l->intensity);
        count = 1;
        break;
    case LIGHT_POINT:
    case LIGHT_SPOT:
    case LIGHT_VOLUME: {
        vec3 d = v3_sub(l->position, p);
        float d2 = v3_dot(d, d);
        if (!(d2 > 0.0f)) return;
        dirs[0] = v3_scale(d, 1.0f / sqrtf(d2));
        contrib[0] = light_contribution_estimate(ls, l, p, v3s(0.0f)); /* fluence incl. the cone */
        count = 1;
        break;
    }
    case LIGHT_RECT:
    case LIGHT_DISK:
    case LIGHT_AREA: {
        count = area_estimate_samples(l, p, dirs, contrib);
        break;
    }
    }
    for (int k = 0; k < count; ++k) {
        if (!(contrib[k] > 0.0f) || !isfinite(contrib[k])) continue;
        vec3 w = dirs[k];
        out[0] += contrib[k] * maxf(w.x, 0.0f);
        out[1] += contrib[k] * maxf(-w.x, 0.0f);
        out[2] += contrib[k] * maxf(w.y, 0.0f);
        out[3] += contrib[k] * maxf(-w.y, 0.0f);
        out[4] += contrib[k] * maxf(w.z, 0.0f);
        out[5] += contrib[k] * maxf(-w.z, 0.0f);
        out[6] += contrib[k];
    }
}

float light_peak_intensity(const Light *l) {
    switch (l->type) {
    case LIGHT_POINT:
    case LIGHT_SPOT:
    case LIGHT_VOLUME: return v3_luminance(l->intensity);
    case LIGHT_RECT:
    case LIGHT_DISK:
    case LIGHT_AREA: return v3_luminance(l->emission) * l->area; /* a flat emitter seen face on */
    default: return 0.0f;
    }
}
