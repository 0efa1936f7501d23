/* renderer/bsdf.h (private): the glTF metallic-roughness BSDF and its dielectric variant.
 *
 * Model (glTF 2.0 spec appendix B, with KHR_materials_specular / _transmission / _ior):
 *   f = mix(dielectric, metal, metallic)
 *   metal      = GGX conductor, Fresnel = Schlick(base_color)
 *   dielectric = mix(opaque_dielectric, glass, transmission)
 *   opaque_dielectric = specular_layer(F) + (1 - specular * max(F)) * base_color / pi
 *   glass      = rough dielectric (Walter et al. 2007), reflection F, refraction (1-F) tinted by
 *                base_color; alpha < BSDF_DELTA_ALPHA is an exact delta (smooth glass)
 * with F the Schlick Fresnel of F0 = ((ior-1)/(ior+1))^2 * specular_color * specular and
 * F90 = specular, and alpha = roughness^2, clamped to >= BSDF_MIN_ALPHA for reflection.
 * KHR_materials_clearcoat layers a coat over all of it: f = coat + (1 - c Fc(wo)) (1 - c Fc(wi))
 * f_base, the coat a GGX reflection of alpha = clearcoat_roughness^2 weighted by c Fc(wo.h),
 * Fc the Schlick Fresnel of ior 1.5 (F0 0.04), c the clearcoat factor.
 *
 * Conventions: directions are in the local shading frame (normal = +z), both pointing away
 * from the surface. f excludes the cosine. Opaque lobes are zero unless wo.z > 0 and
 * wi.z > 0 (the caller flips the frame of opaque surfaces to face wo). For glass, +z is the
 * outside: wo.z > 0 means the ray arrives from outside (eta = ior), wo.z < 0 from inside.
 * Refraction carries radiance, so the BTDF includes the 1/eta^2 factor (pbrt's
 * TransportMode::Radiance). bsdf_eval / bsdf_pdf return 0 for delta lobes. */
#ifndef CANDELA_BSDF_H
#define CANDELA_BSDF_H

#include "vecmath.h"

#define BSDF_DELTA_ALPHA 1e-3f
#define BSDF_MIN_ALPHA 1e-3f

typedef struct BsdfParams {
    vec3 base_color;     /* linear albedo / metal F0 / glass tint */
    float metallic;      /* [0,1] */
    float roughness;     /* perceptual [0,1], alpha = roughness^2 */
    float specular;      /* KHR_materials_specular factor [0,1]; 0 = pure Lambert */
    vec3 specular_color; /* KHR_materials_specular colour factor */
    float transmission;  /* [0,1] */
    float ior;           /* > 1 (1.5 default); ior == 1 disables the specular layer */
    float clearcoat;     /* KHR_materials_clearcoat: coat weight [0,1]; 0 = no coat */
    float clearcoat_roughness; /* perceptual [0,1], the coat's alpha = roughness^2 */
} BsdfParams;

enum {
    BSDF_REFLECTION = 1,
    BSDF_TRANSMISSION = 2,
    BSDF_DELTA = 4  /* the sampled direction came from a delta lobe: no MIS, pdf is a pmf */
};

typedef struct BsdfSample {
    vec3 wi;       /* local frame */
    vec3 f;        /* BSDF value (without cosine); for delta lobes the delta's weight */
    float pdf;     /* solid-angle pdf of the whole mixture; for delta lobes the lobe pmf */
    int flags;     /* BSDF_* */
} BsdfSample;

/* The weight of a sample is f * |wi.z| / pdf. Returns 0 when no direction was produced. */
int bsdf_sample(const BsdfParams *p, vec3 wo, float u_lobe, float u1, float u2, BsdfSample *s);
vec3 bsdf_eval(const BsdfParams *p, vec3 wo, vec3 wi);
float bsdf_pdf(const BsdfParams *p, vec3 wo, vec3 wi);
/* Both at once (next-event estimation needs both; one pass over the lobes). */
vec3 bsdf_eval_pdf(const BsdfParams *p, vec3 wo, vec3 wi, float *pdf);
/* 1 if every lobe of p is a delta (smooth glass with metallic 0, transmission 1, no coat): NEE is
 * useless there and the renderer skips it. */
int bsdf_is_delta(const BsdfParams *p);
/* 1 if path guiding may sample directions here: no delta lobe, and some lobe rougher than
 * BSDF_GUIDE_MIN_ROUGHNESS (perceptual; a diffuse lobe counts as fully rough). */
#define BSDF_GUIDE_MIN_ROUGHNESS 0.05f
int bsdf_guidable(const BsdfParams *p);
/* 1 if p has a transmission lobe (the frame must not be flipped to face wo). */
int bsdf_has_transmission(const BsdfParams *p);

#endif
