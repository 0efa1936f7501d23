/* renderer/materials/bsdf.h (private): the material BSDFs, two models (--material-model).
 *
 * Directions are in the local shading frame (normal = +z), both pointing away from the
 * surface; wo is the view side (V), wi the light side (L), h = normalize(wo + wi). f excludes
 * the cosine. Opaque lobes are zero unless wo.z > 0 and wi.z > 0 (the caller flips the frame of
 * opaque surfaces to face wo). For glass, +z is the outside: wo.z > 0 means the ray arrives from
 * outside (eta = ior), wo.z < 0 from inside. Refraction carries radiance, so the BTDF includes
 * the 1/eta^2 factor (pbrt's TransportMode::Radiance). bsdf_eval / bsdf_pdf return 0 for delta
 * lobes. Both models share the GGX pieces, with the SEPARABLE Smith masking-shadowing term
 * (what glTF Appendix B / KHR_materials_transmission and Cycles 3.4 both use):
 *   D(h) = a^2 / (pi ((h.z)^2 (a^2 - 1) + 1)^2),   G1(w) = 2 w.z / (w.z + sqrt(a^2 + (1 - a^2) w.z^2)),
 *   DV = D(h) G1(wo) G1(wi) / (4 wo.z wi.z),       a = roughness^2 (>= BSDF_MIN_ALPHA).
 *
 * BSDF_MODEL_GLTF (default): the glTF 2.0 specification, Appendix B, with its extensions:
 *   f = mix(dielectric, metal, metallic)
 *   metal      = Fs(base_color, 1, h.wo) DV                        (conductor_fresnel)
 *   dielectric = mix(opaque, glass, transmission)
 *   opaque     = (1 - s max_c Fd_c(h.wo)) base_color / pi  +  s Fd(h.wo) DV
 *               (KHR_materials_specular's fresnel_mix: Fd = Fs(min(F0_ior specular_color, 1), 1, .),
 *                F0_ior = ((ior-1)/(ior+1))^2 from KHR_materials_ior, s = specular factor)
 *   Fs(F0, F90, c) = F0 + (F90 - F0) (1 - c)^5 (Schlick), always at the half vector.
 *   The diffuse weight depends on h (not on wo alone); f stays reciprocal (h.wo = h.wi) but is
 *   NOT energy conserving at grazing wo: Fd(h.wo) -> 1 only near the mirror direction, so the
 *   specular lobe takes almost all the energy there while the diffuse keeps (1 - Fd(h.wo)) ~ 1
 *   elsewhere; the hemispherical albedo of a white dielectric rises above 1 as wo.z -> 0
 *   (tests/test_bsdf.c measures it; at normal incidence it stays below 1).
 *   glass      = rough dielectric (Walter et al. 2007, separable G), reflection s F(m.wo), refraction
 *                (1 - s F(m.wo)) tinted by base_color, F the exact dielectric Fresnel at the
 *                microfacet normal m; alpha < BSDF_DELTA_ALPHA is an exact delta (smooth glass).
 *                This is a solid refracting boundary (with KHR_materials_volume semantics), not
 *                KHR_materials_transmission's thin-walled Schlick BTDF.
 *   KHR_materials_clearcoat (fresnel_coat): f = (1 - c Fc(|wo.z|)) f_base + c Fc(|wo.z|) DV_coat,
 *   Fc = Fs(0.04, 1, .) at the shading normal (N.V, not the half vector), c the clearcoat factor,
 *   DV_coat of alpha = clearcoat_roughness^2. Not reciprocal (the spec evaluates the coat's
 *   Fresnel at the view direction); the albedo stays <= that of the base (the mix weights sum
 *   to 1 and DV's albedo is <= 1).
 *
 * BSDF_MODEL_BLENDER3: Blender 3.4's Principled BSDF v1 in Cycles (GGX distribution, the node's
 * default and what the glTF importer leaves), set up from the glTF material as Blender 3.4's glTF
 * importer does: Base Color, Metallic, Roughness, Transmission, IOR, Clearcoat and Clearcoat
 * Roughness copied; Specular 0.5 and Specular Tint 0 unless KHR_materials_specular is present,
 * then Specular = (lum(specular_color) - transmission) / (1 - transmission) F0_ior / 0.08 and
 * Specular Tint = clamp(lum((norm(specular_color) - 1) / (norm(base_color) - 1)), 0, 1) (lum =
 * 0.3 r + 0.6 g + 0.1 b, norm(c) = c / lum(c), 0/0 -> 0; 1 when norm(base_color) is white; the
 * importer ignores specularFactor; Specular is clamped to [0, 12] here). With m = metallic, t = transmission, r = roughness, S = Specular:
 *   f = (1-m)(1-t) base_color fd  +  (1 - (1-m) t) Fp(h.wi) DV  +  (1-m) t glass  +  coat
 *   fd = [(1 - FV/2)(1 - FL/2) + R (FL + FV + FL FV (R - 1))] / pi,  R = r (1 + wo.wi),
 *        FV = (1 - wo.z)^5, FL = (1 - wi.z)^5                     (Disney diffuse, Cycles' form)
 *   Fp(c) = cspec0 (1 - FH) + FH,  FH = (Fr(c, ior_s) - Fr(1, ior_s)) / (1 - Fr(1, ior_s)) in [0, 1],
 *        cspec0 = saturate(0.08 S ((1 - tint) + tint base_color / lum(base_color)) (1-m) + base_color m),
 *        ior_s = 2 / (1 - sqrt(0.08 S)) - 1, Fr the exact dielectric Fresnel
 *   glass = the rough dielectric above with Cycles' weights: reflection Fr(|wo.z|, ior) DV,
 *        refraction base_color (1 - Fr(|wo.z|, ior)) BTDF (Fresnel at the macro normal, untinted
 *        reflection: exact for Specular Tint 0)
 *   coat = 0.25 clearcoat Fr(h.wi, 1.5) DV_coat, added on top.
 * Principled v1 is NOT energy conserving: the specular lobe is added on top of a diffuse that is
 * not reduced by it (a smooth white plastic, Specular 0.5, reflects (1 - FV/2)(1 - 1/42) +
 * Fr(wo.z, 1.5): 1.016 at normal incidence, 1.155 at wo.z = 0.2), the retro-reflection of a rough
 * diffuse adds more (albedo 1.036 / 1.057 / 1.245 at roughness 1 and wo.z = 1 / 0.5 / 0.2), and
 * the coat is added on top of everything. What tests/test_bsdf.c checks instead: those closed
 * forms, the diffuse alone <= 1 at roughness 0, the metal (cspec0 = 1) equal to the GGX lobe's
 * albedo (1 when smooth). It is reciprocal (fd, Fp(h.wi) = Fp(h.wo) and DV are symmetric) except
 * for the glass. */
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
    int model;           /* BSDF_MODEL_*; 0 (zero-initialised) = glTF */
    int specular_ext;    /* 1: KHR_materials_specular was present (BSDF_MODEL_BLENDER3's importer rule) */
} BsdfParams;

enum { BSDF_MODEL_GLTF = 0, BSDF_MODEL_BLENDER3 = 1 };

/* Blender 3.4's glTF importer: the Principled Specular and Specular Tint it derives from p (see
 * above). Exposed for the tests. */
void bsdf_blender3_specular(const BsdfParams *p, float *specular, float *specular_tint);

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

/* The parameters' derived constants (clamped inputs, Fresnel F0s, alphas, the Principled v1
 * specular colour): what every call below computes first. A vertex that samples and
 * evaluates its BSDF several times (NEE, the bounce, MIS pdfs) prepares once and calls the
 * bsdf_prepared_* forms, which give bit for bit the same results. The fields are bsdf.c's. */
typedef struct BsdfPrepared {
    int model;       /* BSDF_MODEL_* */
    vec3 base;       /* clamped to [0,1] */
    vec3 f0_spec;    /* dielectric layer F0 (includes specular factor) */
    float f90_spec;  /* = specular */
    int spec_on;     /* dielectric specular layer active (ior != 1 and specular > 0) */
    float m, t, specular, ior;
    float roughness; /* perceptual, clamped to [0,1] */
    float alpha;     /* opaque lobes, >= BSDF_MIN_ALPHA */
    float alpha_glass;
    int glass_delta;
    float coat;        /* clearcoat factor; 0: no coat */
    float alpha_coat;  /* >= BSDF_MIN_ALPHA */
    float glass_fscale; /* the glass Fresnel's scale: specular (glTF) or 1 (Principled) */
    /* BSDF_MODEL_BLENDER3 (Principled v1) */
    float p_rough;     /* Disney diffuse roughness (perceptual) */
    vec3 cspec0;       /* specular colour at normal incidence (metal folded in) */
    float ior_s;       /* the specular lobe's Fresnel ior, from Specular */
    float f0_s;        /* Fr(1, ior_s) */
    float w_spec3;     /* 1 - (1-m) t; 0 when the lobe is off */
    /* glTF model with the diffuse lobe alone (no metal, specular layer, transmission or coat):
     * eval and sample take a short path that does the same float operations, so the results
     * are bit for bit those of the general mixture */
    int lambert;
    float lambert_prob; /* the diffuse lobe's selection probability (w * (1 / w)) when wo.z > 0 */
} BsdfPrepared;
void bsdf_prepare(const BsdfParams *p, BsdfPrepared *q);
int bsdf_prepared_sample(const BsdfPrepared *q, vec3 wo, float u_lobe, float u1, float u2, BsdfSample *s);
vec3 bsdf_prepared_eval_pdf(const BsdfPrepared *q, vec3 wo, vec3 wi, float *pdf);
int bsdf_prepared_is_delta(const BsdfPrepared *q);
int bsdf_prepared_guidable(const BsdfPrepared *q);
int bsdf_prepared_has_transmission(const BsdfPrepared *q);

/* The weight of a sample is f * |wi.z| / pdf. Returns 0 when no direction was produced. */
int bsdf_sample(const BsdfParams *p, vec3 wo, float u_lobe, float u1, float u2, BsdfSample *s);
vec3 bsdf_eval(const BsdfParams *p, vec3 wo, vec3 wi);
float bsdf_pdf(const BsdfParams *p, vec3 wo, vec3 wi);
/* 1 if every lobe of p is a delta (smooth glass with metallic 0, transmission 1, no coat): NEE is
 * useless there and the renderer skips it. */
int bsdf_is_delta(const BsdfParams *p);
/* Path guiding may sample directions where no lobe is a delta and some lobe is rougher than
 * BSDF_GUIDE_MIN_ROUGHNESS (perceptual; a diffuse lobe counts as fully rough):
 * bsdf_prepared_guidable. */
#define BSDF_GUIDE_MIN_ROUGHNESS 0.05f
/* 1 if p has a transmission lobe (the frame must not be flipped to face wo). */
int bsdf_has_transmission(const BsdfParams *p);

#endif
