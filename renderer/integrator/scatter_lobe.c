/* renderer/integrator/scatter_lobe.c: a surface vertex's glossy lobe as light selection sees it
 * (scatter_light_lobe, scatter.h), for BSDF-aware cache point selection (--cachepoint-bsdf;
 * the cache points paper's §6 names joint BSDF / light selection as future work).
 *
 * The BSDF of bsdf.h is split, from wo, into a part that light selection treats like a
 * diffuse lobe (the diffuse layer, and specular lobes rougher than LIGHT_LOBE_MAX_ROUGHNESS,
 * whose angular spread is close to the cosine's) of albedo rho_d, and one glossy GGX lobe of
 * albedo rho_s (Schlick Fresnel at wo, as bsdf.c's lobe weights; the metal, the dielectric
 * specular layer and the clear coat, the sharpest one with weight giving the roughness). Only
 * a sampling weight: nothing here needs to be exact, it needs to be a deterministic function of
 * (the vertex, wo), which it is.
 *
 * The glossy lobe in wi is a normalised density around the mirror direction of sharpness lambda
 * (cachepoints/lookup.c gives it GGX's profile): a GGX NDF of roughness alpha has the width of a
 * spherical Gaussian of sharpness 2 / alpha^2 in the half vector, and the reflection warp divides
 * it by 4 |wo.n| (Wang et al. 2009, "All-frequency rendering of dynamic, spatially-varying
 * reflectance"), so lambda = 1 / (2 alpha^2 cos_o).
 * At the peak f_s cos_i = F G D(h) cos_h / (4 cos_o) ~ F x (the lobe's density in wi), so a
 * light of irradiance E (which carries cos_i ~ cos_o) adds about rho_s D(wi) E / cos_o against
 * the diffuse part's rho_d / pi E: the lobe's weight is kappa = pi rho_s / (rho_d cos_o). */
#include <math.h>

#include "scatter.h"

/* Perceptual roughness above which a specular lobe counts as diffuse for selection: its lobe
 * spreads over most of the hemisphere (lambda < 8 at normal incidence) and weighing lights by it
 * costs a pass over the point's entries for little. Below: glossy. Rough dielectrics (the
 * generated scenes' asphalt 0.8 and wood 0.6, and glTF's default 1) therefore take exactly the
 * normal-only path. */
#define LIGHT_LOBE_MAX_ROUGHNESS 0.5f
/* The lobe's cosine to wo is clamped to this (grazing views: the warp's 1 / cos_o blows up). */
#define LIGHT_LOBE_MIN_COS 0.05f
/* Sharper lobes than this are treated as this sharp (alpha ~ 0.01 at normal incidence): the
 * quantised axis and the lights' bounds are not more precise than that anyway. */
#define LIGHT_LOBE_MAX_SHARPNESS 1e4f

static float clamp01(float x, float fallback) { return isnan(x) ? fallback : clampf(x, 0.0f, 1.0f); }

static float schlick1(float f0, float f90, float c) {
    float m = 1.0f - clampf(c, 0.0f, 1.0f), m2 = m * m;
    return f0 + (f90 - f0) * m2 * m2 * m;
}

void scatter_light_lobe(const Scatter *s, LightLobe *lobe) {
    *lobe = (LightLobe){v3s(0.0f), 0.0f, 0.0f};
    if (s->kind != SCATTER_BSDF || s->transmissive) return; /* transmissive: fluence, no normal */
    float cos_o = s->wo.z;
    if (!(cos_o > 0.0f)) return;
    const BsdfParams *p = s->bsdf;
    float m = clamp01(p->metallic, 0.0f), t = clamp01(p->transmission, 0.0f);
    float spec = clamp01(p->specular, 0.0f), r = clamp01(p->roughness, 1.0f);
    float coat = clamp01(p->clearcoat, 0.0f), rc = clamp01(p->clearcoat_roughness, 0.0f);
    vec3 base = v3(clamp01(p->base_color.x, 0.0f), clamp01(p->base_color.y, 0.0f), clamp01(p->base_color.z, 0.0f));
    float base_avg = (base.x + base.y + base.z) / 3.0f;
    /* the base layer: metal (Fresnel of the base colour), the dielectric's specular layer and
     * its diffuse layer under it (bsdf.c's lobe weights, channel-averaged) */
    float ior = p->ior > 1.0f && isfinite(p->ior) ? fminf(p->ior, 1e4f) : 1.0f;
    float r0 = (ior - 1.0f) / (ior + 1.0f);
    vec3 sc = p->specular_color;
    float sc_max = fmaxf(fmaxf(isfinite(sc.x) ? sc.x : 0.0f, isfinite(sc.y) ? sc.y : 0.0f), isfinite(sc.z) ? sc.z : 0.0f);
    float f0 = fminf(r0 * r0 * fmaxf(sc_max, 0.0f), 1.0f) * spec;
    float f_spec = ior != 1.0f && spec > 0.0f ? schlick1(f0, spec, cos_o) : 0.0f;
    float opaque = (1.0f - m) * (1.0f - t);
    float w_base = m * schlick1(base_avg, 1.0f, cos_o) + opaque * f_spec;
    float w_diffuse = opaque * base_avg * (1.0f - f_spec);
    float w_coat = 0.0f;
    if (coat > 0.0f) { /* the coat reflects c Fc(wo) and passes the rest to the base */
        float fc = coat * schlick1(0.04f, 1.0f, cos_o);
        w_base *= 1.0f - fc;
        w_diffuse *= 1.0f - fc;
        w_coat = fc;
    }
    /* glossy: the lobes at most LIGHT_LOBE_MAX_ROUGHNESS rough; the sharpest of them that
     * carries weight gives the lobe's roughness, the rest count as diffuse */
    float rho_s = 0.0f, rho_d = w_diffuse, alpha = 1.0f;
    if (w_base > 0.0f && r <= LIGHT_LOBE_MAX_ROUGHNESS) { rho_s += w_base; alpha = r * r; }
    else rho_d += w_base;
    if (w_coat > 0.0f && rc <= LIGHT_LOBE_MAX_ROUGHNESS) { rho_s += w_coat; alpha = fminf(alpha, rc * rc); }
    else rho_d += w_coat;
    if (!(rho_s > 0.0f)) return;
    float c = fmaxf(cos_o, LIGHT_LOBE_MIN_COS);
    float a2 = fmaxf(alpha * alpha, 1e-12f);
    float lambda = fminf(1.0f / (2.0f * a2 * c), LIGHT_LOBE_MAX_SHARPNESS);
    float kappa = rho_d > 0.0f ? 3.14159265f * rho_s / (rho_d * c) : INFINITY;
    if (!(kappa > 0.0f)) return;
    vec3 n = s->frame.n, wo = frame_to_world(&s->frame, s->wo);
    lobe->axis = v3_normalize(v3_sub(v3_scale(n, 2.0f * v3_dot(n, wo)), wo));
    lobe->sharpness = lambda;
    lobe->weight = kappa;
}
