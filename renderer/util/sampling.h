/* renderer/util/sampling.h (private): warping functions and tabulated distributions.
 * Every sampler has a matching PDF function; tests/test_sampling.c checks that each PDF
 * integrates to one and that sample() and pdf() agree (chi-square over a histogram). */
#ifndef CANDELA_SAMPLING_H
#define CANDELA_SAMPLING_H

#include <stdint.h>
#include "vecmath.h"

/* Directions in the local frame (z up). */
vec3 sample_cosine_hemisphere(float u1, float u2);
float pdf_cosine_hemisphere(vec3 w);              /* cos(theta)/pi for w.z > 0, else 0 */
vec3 sample_uniform_sphere(float u1, float u2);
float pdf_uniform_sphere(void);                   /* 1/(4 pi) */
vec3 sample_uniform_cone(float u1, float u2, float cos_max); /* around +z */
float pdf_uniform_cone(float cos_max);
vec2 sample_concentric_disk(float u1, float u2);
/* Uniform point on a triangle as barycentrics (b1, b2); b0 = 1 - b1 - b2. */
vec2 sample_uniform_triangle(float u1, float u2);

/* Trowbridge-Reitz (GGX) microfacet distribution, anisotropy not used: alpha = roughness^2. */
float ggx_d(vec3 wm, float alpha);                     /* D(wm), wm in local frame */
float ggx_lambda(vec3 w, float alpha);
float ggx_g1(vec3 w, float alpha);
float ggx_g(vec3 wo, vec3 wi, float alpha);            /* height-correlated Smith */
/* Visible-normal sampling (Heitz 2018): a microfacet normal seen from wo (any hemisphere;
 * the result is in wo's hemisphere). pdf = G1(wo) max(0, wo.wm) D(wm) / |wo.z|. */
vec3 ggx_sample_visible_normal(vec3 wo, float alpha, float u1, float u2);
float ggx_pdf_visible_normal(vec3 wo, vec3 wm, float alpha);

/* Piecewise-constant 1D distribution over n cells of [0,1). All-zero or non-finite input
 * falls back to uniform so that sampling never divides by zero. */
typedef struct Distribution1D {
    uint32_t n;
    float *func;     /* n, the (sanitised) input */
    float *cdf;      /* n + 1, cdf[0] = 0, cdf[n] = 1 */
    float func_int;  /* integral of func over [0,1) = sum(func)/n (0 before the fallback) */
} Distribution1D;

int dist1d_init(Distribution1D *d, const float *func, uint32_t n); /* 0 ok, -1 out of memory */
void dist1d_free(Distribution1D *d);
/* Discrete: pick cell i with probability func[i]/sum. *u_remapped (may be NULL) is u
 * rescaled to [0,1) within the chosen cell, so it can be reused. */
uint32_t dist1d_sample_discrete(const Distribution1D *d, float u, float *pmf, float *u_remapped);
float dist1d_pmf(const Distribution1D *d, uint32_t i);
/* Continuous: x in [0,1) with density func(x)/func_int. */
float dist1d_sample_continuous(const Distribution1D *d, float u, float *pdf, uint32_t *cell);
float dist1d_pdf_continuous(const Distribution1D *d, float x);

/* Piecewise-constant 2D distribution on [0,1)^2, func[v * nu + u] (row v, column u). */
typedef struct Distribution2D {
    uint32_t nu, nv;
    Distribution1D *conditional; /* nv rows, each over u */
    Distribution1D marginal;     /* over v */
} Distribution2D;

int dist2d_init(Distribution2D *d, const float *func, uint32_t nu, uint32_t nv);
void dist2d_free(Distribution2D *d);
vec2 dist2d_sample(const Distribution2D *d, float u0, float u1, float *pdf); /* pdf w.r.t. area of [0,1)^2 */
float dist2d_pdf(const Distribution2D *d, vec2 uv);

#endif
