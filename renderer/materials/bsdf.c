/* renderer/materials/bsdf.c: the material BSDFs (see bsdf.h for the formulas of both models).
 *
 * Lobes, with their mixture weights in f (glTF model / Principled v1 model):
 *   METAL    m / -          GGX conductor, F = Schlick(base_color, F90 = 1) at h
 *   SPEC     (1-m)(1-t) / (1-(1-m)t)   GGX reflection; glTF: s Schlick(F0, 1) at h; Principled:
 *                           Cycles' white-to-cspec0 blend Fp (metal folded into cspec0)
 *   DIFFUSE  (1-m)(1-t)     glTF: (1 - s max F(h.wo)) base_color / pi; Principled: Disney diffuse
 *   GLASS    (1-m) t        rough (Walter 2007) or smooth dielectric, refraction tinted by
 *                           base_color and scaled by 1/eta^2; glTF: exact Fresnel at the microfacet
 *                           scaled by s; Principled: exact Fresnel at the macro normal
 *   COAT     c              glTF: fresnel_coat, everything above scaled by (1 - c Fc(|wo.z|)) and
 *                           the coat's DV by c Fc(|wo.z|); Principled: 0.25 c Fr(h.wi, 1.5) DV on top
 *
 * glTF's diffuse weight uses the Fresnel term at the half vector, so the diffuse term depends on
 * wi through h: it is sampled from the cosine anyway (its pdf does not need to follow f), and
 * eval/pdf stay consistent because the pdf is the mixture of the lobes' sampling densities,
 * whatever f is.
 *
 * Sampling picks one lobe with probabilities that depend only on (params, wo); inside the
 * glass lobe the choice between reflection and refraction uses the lobe's Fresnel term (of the
 * sampled microfacet for glTF, pbrt's DielectricBxDF; of the macro normal for Principled),
 * reusing the remapped lobe random number. Non-delta samples report f = bsdf_eval and pdf =
 * bsdf_pdf (the full mixture), so they match exactly. */
#include "bsdf.h"

#include <stddef.h>

#include "sampling.h"

/* |ior - 1| below this makes glass an exact pass-through (refraction with eta = 1 maps every
 * microfacet to wi = -wo, i.e. a delta even when rough). */
#define GLASS_IOR_EPS 1e-3f
/* Directions closer than this to the horizon produce no sample (f / |cos| would blow up). */
#define MIN_COS 1e-7f

enum { LOBE_METAL, LOBE_SPEC, LOBE_DIFFUSE, LOBE_GLASS, LOBE_COAT, LOBE_COUNT };

/* KHR_materials_clearcoat's coat: a dielectric of ior 1.5 (F0 = 0.04) */
#define COAT_F0 0.04f

typedef BsdfPrepared Prep;

static float sane01(float x, float fallback) {
    if (isnan(x)) return fallback;
    return clampf(x, 0.0f, 1.0f);
}

static double fr_dielectric(double cos_i, double eta);

static float luminance3(vec3 c) { return 0.3f * c.x + 0.6f * c.y + 0.1f * c.z; }

void bsdf_blender3_specular(const BsdfParams *p, float *specular, float *specular_tint) {
    /* Blender 3.4 io_import_scene_gltf2 (KHR_materials_specular.py): without the extension the
     * Principled node keeps its defaults */
    *specular = 0.5f;
    *specular_tint = 0.0f;
    if (!p->specular_ext) return;
    float t = sane01(p->transmission, 0.0f);
    float ior = isfinite(p->ior) && p->ior >= 1.0f ? p->ior : 1.5f;
    float f0 = sqr((ior - 1.0f) / (ior + 1.0f));
    vec3 sc = p->specular_color;
    sc = v3(isfinite(sc.x) ? maxf(sc.x, 0.0f) : 0.0f, isfinite(sc.y) ? maxf(sc.y, 0.0f) : 0.0f,
            isfinite(sc.z) ? maxf(sc.z, 0.0f) : 0.0f);
    /* t = 1 divides by zero in the importer: keep the node default then */
    /* the Principled socket keeps any value (Blender 3.4.1 keeps -0.5 and 1e6 as set). Clamped
     * here to [0, 12]: below 0 a dielectric's lobe is off in Cycles too (ior_s 1, cspec0
     * saturated to 0; a metal's cspec0 differs slightly), and 12 keeps Cycles'
     * ior_s = 2 / (1 - sqrt(0.08 S)) - 1 finite (S < 12.5) */
    if (t < 1.0f) *specular = clampf((luminance3(sc) - t) / (1.0f - t) * f0 / 0.08f, 0.0f, 12.0f);
    vec3 b = v3(sane01(p->base_color.x, 0.0f), sane01(p->base_color.y, 0.0f), sane01(p->base_color.z, 0.0f));
    float lb = luminance3(b), ls = luminance3(sc);
    vec3 nb = lb > 0.0f ? v3_scale(b, 1.0f / lb) : b;
    vec3 ns = ls > 0.0f ? v3_scale(sc, 1.0f / ls) : sc;
    if (nb.x == 1.0f && nb.y == 1.0f && nb.z == 1.0f) { *specular_tint = 1.0f; return; }
    float r[3], nbv[3] = {nb.x, nb.y, nb.z}, nsv[3] = {ns.x, ns.y, ns.z};
    for (int k = 0; k < 3; ++k) {
        float num = nsv[k] - 1.0f, den = nbv[k] - 1.0f;
        /* numpy's nan_to_num: 0/0 -> 0, x/0 -> +-FLT_MAX (clipped below) */
        r[k] = den != 0.0f ? num / den : (num == 0.0f ? 0.0f : (num > 0.0f ? 3.0e38f : -3.0e38f));
    }
    float tint = 0.3f * r[0] + 0.6f * r[1] + 0.1f * r[2];
    *specular_tint = isfinite(tint) ? clampf(tint, 0.0f, 1.0f) : (tint > 0.0f ? 1.0f : 0.0f);
}

static void prepare_blender3(const BsdfParams *p, Prep *q) {
    float spec, tint;
    bsdf_blender3_specular(p, &spec, &tint);
    q->p_rough = sane01(p->roughness, 1.0f);
    float lb = luminance3(q->base);
    vec3 ctint = lb > 0.0f ? v3_scale(q->base, 1.0f / lb) : v3s(1.0f);
    vec3 tmp = v3_add(v3s(1.0f - tint), v3_scale(ctint, tint));
    vec3 c0 = v3_add(v3_scale(tmp, spec * 0.08f * (1.0f - q->m)), v3_scale(q->base, q->m));
    q->cspec0 = v3(clampf(c0.x, 0.0f, 1.0f), clampf(c0.y, 0.0f, 1.0f), clampf(c0.z, 0.0f, 1.0f));
    q->ior_s = 2.0f / (1.0f - sqrtf(maxf(0.08f * spec, 0.0f))) - 1.0f;
    q->f0_s = (float)fr_dielectric(1.0, (double)q->ior_s);
    /* svm_closure.h: the specular closure exists when Specular or Metallic is above the cutoff */
    float w = 1.0f - (1.0f - q->m) * q->t;
    q->w_spec3 = w > 1e-5f && (spec > 1e-5f || q->m > 1e-5f) ? w : 0.0f;
    q->glass_fscale = 1.0f;
}

static void prepare(const BsdfParams *p, Prep *q) {
    q->model = p->model == BSDF_MODEL_BLENDER3 ? BSDF_MODEL_BLENDER3 : BSDF_MODEL_GLTF;
    q->base = v3(sane01(p->base_color.x, 0.0f), sane01(p->base_color.y, 0.0f), sane01(p->base_color.z, 0.0f));
    q->m = sane01(p->metallic, 0.0f);
    q->t = sane01(p->transmission, 0.0f);
    q->specular = sane01(p->specular, 0.0f);
    float r = sane01(p->roughness, 1.0f);
    q->roughness = r;
    float ior = p->ior;
    if (!(ior >= 1.0f) || !isfinite(ior)) ior = isinf(ior) && ior > 0.0f ? 1e4f : 1.0f;
    q->ior = minf(ior, 1e4f);
    float a = r * r;
    q->alpha = maxf(a, BSDF_MIN_ALPHA);
    q->alpha_glass = maxf(a, BSDF_DELTA_ALPHA);
    q->glass_delta = a < BSDF_DELTA_ALPHA || q->ior - 1.0f < GLASS_IOR_EPS;
    float r0 = sqr((q->ior - 1.0f) / (q->ior + 1.0f));
    vec3 sc = p->specular_color;
    sc = v3(isfinite(sc.x) ? maxf(sc.x, 0.0f) : 0.0f, isfinite(sc.y) ? maxf(sc.y, 0.0f) : 0.0f,
            isfinite(sc.z) ? maxf(sc.z, 0.0f) : 0.0f);
    q->f0_spec = v3_scale(v3_min(v3_scale(sc, r0), v3s(1.0f)), q->specular);
    q->f90_spec = q->specular;
    q->spec_on = q->ior != 1.0f && q->specular > 0.0f;
    q->coat = sane01(p->clearcoat, 0.0f);
    float rc = sane01(p->clearcoat_roughness, 0.0f);
    q->alpha_coat = maxf(rc * rc, BSDF_MIN_ALPHA);
    q->glass_fscale = q->specular;
    if (q->model == BSDF_MODEL_BLENDER3) prepare_blender3(p, q);
    /* lobe_probs' weights are then w_diffuse = 1 * max(base) * (1 - 0) and nothing else */
    q->lambert = q->model == BSDF_MODEL_GLTF && q->m == 0.0f && q->t == 0.0f && !q->spec_on && !(q->coat > 0.0f);
    float w = v3_max_component(q->base);
    q->lambert_prob = w > 0.0f ? w * (1.0f / w) : 0.0f;
}

static float pow5(float x) { float x2 = x * x; return x2 * x2 * x; }

static vec3 schlick(vec3 f0, float f90, float c) {
    float w = pow5(1.0f - clampf(c, 0.0f, 1.0f));
    return v3(f0.x + (f90 - f0.x) * w, f0.y + (f90 - f0.y) * w, f0.z + (f90 - f0.z) * w);
}

/* max over channels of the dielectric layer's Schlick Fresnel (0 when the layer is off). */
static float spec_fmax(const Prep *q, float c) {
    if (!q->spec_on) return 0.0f;
    float f0 = v3_max_component(q->f0_spec);
    return f0 + (q->f90_spec - f0) * pow5(1.0f - clampf(c, 0.0f, 1.0f));
}

/* c Fc(cos): the share the coat reflects (0 without a coat). */
static float coat_fresnel(const Prep *q, float c) {
    if (!(q->coat > 0.0f)) return 0.0f;
    return q->coat * (COAT_F0 + (1.0f - COAT_F0) * pow5(1.0f - clampf(fabsf(c), 0.0f, 1.0f)));
}

/* Exact unpolarised dielectric Fresnel; cos_i < 0 means arriving from the eta side. Double
 * precision: the glass lobe is evaluated in double so that the reciprocity of the rough
 * dielectric survives rounding (the two argument orders build the half vector differently). */
static double fr_dielectric(double cos_i, double eta) {
    cos_i = cos_i < -1.0 ? -1.0 : (cos_i > 1.0 ? 1.0 : cos_i);
    if (cos_i < 0.0) { eta = 1.0 / eta; cos_i = -cos_i; }
    double sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.0) return 1.0;
    double cos_t = sqrt(1.0 - sin2_t);
    double r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    double r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    double f = 0.5 * (r_parl * r_parl + r_perp * r_perp);
    return f < 0.0 ? 0.0 : (f > 1.0 ? 1.0 : f);
}

/* Double-precision GGX pieces for the glass lobe (same formulas as sampling.c). */
static double ggx_d_dbl(double x, double y, double z, double alpha) {
    double a2 = alpha * alpha;
    double t = z * z + (x * x + y * y) / a2;
    double den = 3.14159265358979323846 * a2 * t * t;
    return den > 0.0 ? 1.0 / den : 0.0;
}

static double ggx_lambda_dbl(double x, double y, double z, double alpha) {
    double sin2 = x * x + y * y, cos2 = z * z;
    if (sin2 == 0.0) return 0.0;
    if (cos2 == 0.0) return INFINITY;
    return 0.5 * (sqrt(1.0 + alpha * alpha * sin2 / cos2) - 1.0);
}

/* Cycles' interpolate_fresnel_color: white-to-cspec0 blend by the normalised exact Fresnel of
 * ior_s at cos c (Principled v1's specular colour). */
static vec3 principled_fresnel(const Prep *q, float c) {
    float fh = 0.0f;
    if (q->f0_s < 1.0f) fh = ((float)fr_dielectric(c, (double)q->ior_s) - q->f0_s) / (1.0f - q->f0_s);
    /* in [0, 1]: for a large ior_s (Specular near its bound) the unpolarised Fresnel dips below
     * its normal-incidence value before grazing, and the blend would go negative */
    fh = clampf(fh, 0.0f, 1.0f);
    return v3_add(v3_scale(q->cspec0, 1.0f - fh), v3s(fh));
}

/* Lobe selection probabilities; they depend only on (q, wo). Opaque lobes vanish unless
 * wo.z > 0; the small floors keep a lobe selectable wherever its f can be nonzero. */
static float lobe_probs(const Prep *q, vec3 wo, float prob[LOBE_COUNT]) {
    /* scalars, not a stack array: partial stores into an array that is then reloaded whole
     * stalled store forwarding and made this the hottest function of the shade stage */
    float w_metal = 0.0f, w_spec = 0.0f, w_diffuse = 0.0f, w_glass = 0.0f, w_coat = 0.0f;
    if (q->model == BSDF_MODEL_BLENDER3) {
        if (wo.z > 0.0f) {
            if (q->w_spec3 > 0.0f) {
                float fs = v3_max_component(principled_fresnel(q, wo.z));
                w_spec = q->w_spec3 * maxf(fs, 0.02f);
            }
            w_diffuse = (1.0f - q->m) * (1.0f - q->t) * v3_max_component(q->base);
            if (q->coat > 0.0f) w_coat = 0.25f * q->coat * maxf((float)fr_dielectric(wo.z, 1.5), 0.02f);
        }
        if (wo.z != 0.0f) w_glass = (1.0f - q->m) * q->t;
    } else if (wo.z > 0.0f) {
        float c = wo.z;
        if (q->m > 0.0f) {
            vec3 fm = schlick(q->base, 1.0f, c);
            float fmax = v3_max_component(fm);
            w_metal = q->m * (fmax > 0.05f ? fmax : 0.05f);
        }
        float opaque = (1.0f - q->m) * (1.0f - q->t);
        if (opaque > 0.0f) {
            float fs = spec_fmax(q, c);
            float floor_spec = 0.02f * q->specular;
            if (q->spec_on) w_spec = opaque * (fs > floor_spec ? fs : floor_spec);
            w_diffuse = opaque * v3_max_component(q->base) * (1.0f - fs);
        }
    }
    if (q->model == BSDF_MODEL_GLTF && wo.z != 0.0f) w_glass = (1.0f - q->m) * q->t;
    if (q->model == BSDF_MODEL_GLTF && q->coat > 0.0f) {
        /* the base lobes are seen through the coat; the coat itself from outside only */
        float fc = coat_fresnel(q, wo.z), through = 1.0f - fc;
        w_metal *= through;
        w_spec *= through;
        w_diffuse *= through;
        w_glass *= through;
        if (wo.z > 0.0f) w_coat = fc > 0.02f * q->coat ? fc : 0.02f * q->coat;
    }
    float sum = w_metal + w_spec + w_diffuse + w_glass + w_coat;
    float inv = sum > 0.0f ? 1.0f / sum : 0.0f;
    prob[LOBE_METAL] = w_metal * inv;
    prob[LOBE_SPEC] = w_spec * inv;
    prob[LOBE_DIFFUSE] = w_diffuse * inv;
    prob[LOBE_GLASS] = w_glass * inv;
    prob[LOBE_COAT] = w_coat * inv;
    return sum;
}

/* ---------------------------------------------------------------- lobe evaluation */

/* GGX reflection, wo.z, wi.z > 0: returns D G / (4 co ci), the half vector and the VNDF
 * reflection pdf (which does not depend on whether the lobe's value vanishes). */
static float ggx_reflect_common(vec3 wo, vec3 wi, float alpha, vec3 *wm_out, float *pdf) {
    *pdf = 0.0f;
    vec3 h = v3_add(wo, wi);
    float l2 = v3_dot(h, h);
    if (!(l2 > 0.0f)) return 0.0f;
    vec3 wm = v3_scale(h, 1.0f / sqrtf(l2));
    *wm_out = wm;
    float c = v3_dot(wo, wm);
    float den = 4.0f * wo.z * wi.z;
    if (!(den > 0.0f) || !(c > 0.0f)) return 0.0f;
    float pr = ggx_pdf_visible_normal(wo, wm, alpha) / (4.0f * c);
    *pdf = isfinite(pr) ? pr : 0.0f;
    /* separable Smith (glTF Appendix B's V, Cycles 3.4's G1(wo) G1(wi)) */
    float v = ggx_d(wm, alpha) * ggx_g1(wo, alpha) * ggx_g1(wi, alpha) / den;
    return isfinite(v) ? v : 0.0f;
}

/* Glass in the canonical frame: wo.z > 0, eta = ior below / ior above. Returns f (scalar part,
 * without tint: *refracted tells the caller to tint) and the lobe-internal pdf. */
static float glass_eval_pdf(const Prep *q, vec3 wo_f, vec3 wi_f, double eta, float *pdf, int *refracted) {
    *pdf = 0.0f;
    *refracted = 0;
    double alpha = q->alpha_glass;
    double ox = wo_f.x, oy = wo_f.y, oz = wo_f.z, ix = wi_f.x, iy = wi_f.y, iz = wi_f.z;
    if (!(oz > 0.0) || iz == 0.0) return 0.0f;
    /* Renormalise in double: float directions are unit only to ~1e-7, which breaks the Snell
     * consistency of the generalised half vector enough to matter near the critical angle. */
    double lo2 = ox * ox + oy * oy + oz * oz, li2 = ix * ix + iy * iy + iz * iz;
    if (!(lo2 > 0.0) || !(li2 > 0.0)) return 0.0f;
    double no = 1.0 / sqrt(lo2), ni = 1.0 / sqrt(li2);
    ox *= no; oy *= no; oz *= no;
    ix *= ni; iy *= ni; iz *= ni;
    int reflect = iz > 0.0;
    double k = reflect ? 1.0 : eta;
    double mx = ox + k * ix, my = oy + k * iy, mz = oz + k * iz;
    double l2 = mx * mx + my * my + mz * mz;
    if (!(l2 > 1e-24)) return 0.0f;
    double inv = (mz < 0.0 ? -1.0 : 1.0) / sqrt(l2);
    mx *= inv; my *= inv; mz *= inv;
    double dot_o = ox * mx + oy * my + oz * mz, dot_i = ix * mx + iy * my + iz * mz;
    /* Discard back-facing microfacets. */
    if (!(dot_o > 0.0) || dot_i * iz <= 0.0) return 0.0f;
    /* glTF: the microfacet's Fresnel; Principled v1 (Cycles): the macro normal's, for both */
    double fr = q->glass_fscale * fr_dielectric(q->model == BSDF_MODEL_BLENDER3 ? oz : dot_o, eta);
    double d = ggx_d_dbl(mx, my, mz, alpha);
    double lo = ggx_lambda_dbl(ox, oy, oz, alpha), li = ggx_lambda_dbl(ix, iy, iz, alpha);
    double g = 1.0 / ((1.0 + lo) * (1.0 + li)); /* separable Smith, as the reflection lobes */
    /* Visible-normal pdf: G1(wo) (wo.wm) D(wm) / wo.z. */
    double pdf_wm = d * dot_o / ((1.0 + lo) * oz);
    double f, pdf_d;
    if (reflect) {
        f = fr * d * g / (4.0 * oz * iz);
        pdf_d = fr * pdf_wm / (4.0 * dot_o);
    } else {
        double tr = 1.0 - fr;
        double s = eta * dot_i + dot_o;
        double s2 = s * s;
        if (!(s2 > 0.0)) return 0.0f;
        /* Walter et al. 2007 eq. 21 with eta_o = 1, eta_i = eta: the 1/eta^2 radiance scaling
         * of pbrt's form cancels against the eta^2 of its denominator. */
        f = tr * d * g * fabs(dot_i * dot_o) / (oz * fabs(iz) * s2);
        pdf_d = tr * pdf_wm * fabs(dot_i) * eta * eta / s2;
        *refracted = 1;
    }
    float ff = (float)f, pf = (float)pdf_d;
    if (!isfinite(ff) || !isfinite(pf) || !(ff >= 0.0f) || !(pf >= 0.0f)) return 0.0f;
    *pdf = pf;
    return ff;
}

/* Disney diffuse as Cycles 3.x writes it (bsdf_principled_diffuse.h, PRINCIPLED_DIFFUSE_FULL),
 * without the base colour: Lambert with the two Schlick weights plus the retro-reflection. */
static float principled_diffuse(float roughness, vec3 wo, vec3 wi) {
    float fv = pow5(1.0f - clampf(wo.z, 0.0f, 1.0f)), fl = pow5(1.0f - clampf(wi.z, 0.0f, 1.0f));
    float rr = roughness * (1.0f + v3_dot(wo, wi));
    float f = (1.0f - 0.5f * fv) * (1.0f - 0.5f * fl) + rr * (fl + fv + fl * fv * (rr - 1.0f));
    return f * INV_PI_F;
}

/* h.wo = h.wi = cos of half the angle between wo and wi: the Fresnel argument of every
 * reflection lobe, written symmetrically in (wo, wi) so that f stays reciprocal to the bit. */
static float half_cos(vec3 wo, vec3 wi) { return sqrtf(maxf(0.0f, 0.5f * (1.0f + v3_dot(wo, wi)))); }

/* The opaque reflection lobes (wo.z > 0, wi.z > 0), glTF Appendix B. */
static vec3 gltf_opaque(const Prep *q, const float prob[LOBE_COUNT], vec3 wo, vec3 wi, float *pdf) {
    vec3 f = v3s(0.0f);
    float opaque = (1.0f - q->m) * (1.0f - q->t);
    int spec = opaque > 0.0f && q->spec_on;
    float c = half_cos(wo, wi);
    if (q->m > 0.0f || spec) {
        vec3 wm = v3(0.0f, 0.0f, 1.0f);
        float pdf_refl;
        float dg = ggx_reflect_common(wo, wi, q->alpha, &wm, &pdf_refl);
        if (q->m > 0.0f) f = v3_madd(f, schlick(q->base, 1.0f, c), q->m * dg);
        if (spec) f = v3_madd(f, schlick(q->f0_spec, q->f90_spec, c), opaque * dg);
        *pdf += (prob[LOBE_METAL] + prob[LOBE_SPEC]) * pdf_refl;
    }
    if (opaque > 0.0f) {
        /* KHR_materials_specular's fresnel_mix: the base weighted by 1 - s max(F(h.wo)) */
        float kd = 1.0f - spec_fmax(q, c);
        f = v3_madd(f, q->base, opaque * kd * INV_PI_F);
        *pdf += prob[LOBE_DIFFUSE] * wi.z * INV_PI_F;
    }
    return f;
}

/* The opaque reflection lobes (wo.z > 0, wi.z > 0), Principled v1. */
static vec3 principled_opaque(const Prep *q, const float prob[LOBE_COUNT], vec3 wo, vec3 wi, float *pdf) {
    vec3 f = v3s(0.0f);
    if (q->w_spec3 > 0.0f) {
        vec3 wm = v3(0.0f, 0.0f, 1.0f);
        float pdf_refl;
        float dg = ggx_reflect_common(wo, wi, q->alpha, &wm, &pdf_refl);
        f = v3_madd(f, principled_fresnel(q, half_cos(wo, wi)), q->w_spec3 * dg);
        *pdf += prob[LOBE_SPEC] * pdf_refl;
    }
    float wd = (1.0f - q->m) * (1.0f - q->t);
    if (wd > 0.0f) {
        f = v3_madd(f, q->base, wd * principled_diffuse(q->p_rough, wo, wi));
        *pdf += prob[LOBE_DIFFUSE] * wi.z * INV_PI_F;
    }
    return f;
}

/* eval_pdf's result: f and pdf, or zero for both when either is not finite. */
static vec3 finite_or_zero(vec3 f, float pdf, float *pdf_out) {
    if (!v3_is_finite(f) || !isfinite(pdf)) {
        f = v3s(0.0f);
        pdf = 0.0f;
    }
    if (pdf_out) *pdf_out = pdf;
    return f;
}

/* eval_pdf of a Lambert-only material (q->lambert): gltf_opaque's diffuse term with opaque =
 * kd = 1 and every other lobe's weight 0, the same operations on the same values. */
static vec3 lambert_eval_pdf(const Prep *q, vec3 wo, vec3 wi, float *pdf_out) {
    if (!(wo.z > 0.0f && wi.z > 0.0f)) return finite_or_zero(v3s(0.0f), 0.0f, pdf_out);
    return finite_or_zero(v3_scale(q->base, INV_PI_F), q->lambert_prob * wi.z * INV_PI_F, pdf_out);
}

/* Evaluate f and the mixture pdf (non-delta lobes only). */
static vec3 eval_pdf(const Prep *q, vec3 wo, vec3 wi, float *pdf_out) {
    if (q->lambert) return lambert_eval_pdf(q, wo, wi, pdf_out);
    vec3 f = v3s(0.0f);
    float pdf = 0.0f;
    float prob[LOBE_COUNT];
    lobe_probs(q, wo, prob);
    if (wo.z > 0.0f && wi.z > 0.0f)
        f = q->model == BSDF_MODEL_BLENDER3 ? principled_opaque(q, prob, wo, wi, &pdf) : gltf_opaque(q, prob, wo, wi, &pdf);
    float wg = (1.0f - q->m) * q->t;
    if (wg > 0.0f && !q->glass_delta && wo.z != 0.0f) {
        float s = wo.z > 0.0f ? 1.0f : -1.0f;
        double eta = wo.z > 0.0f ? (double)q->ior : 1.0 / (double)q->ior;
        float gp;
        int refr;
        float g = glass_eval_pdf(q, v3_scale(wo, s), v3_scale(wi, s), eta, &gp, &refr);
        f = refr ? v3_madd(f, q->base, wg * g) : v3_add(f, v3s(wg * g));
        pdf += prob[LOBE_GLASS] * gp;
    }
    if (q->coat > 0.0f) {
        vec3 wm = v3(0.0f, 0.0f, 1.0f);
        float pdf_coat = 0.0f, dg = 0.0f;
        if (wo.z > 0.0f && wi.z > 0.0f) dg = ggx_reflect_common(wo, wi, q->alpha_coat, &wm, &pdf_coat);
        if (q->model == BSDF_MODEL_BLENDER3) {
            /* Cycles' clearcoat closure: 0.25 c Fr(h.wi, 1.5) on top of everything */
            f = v3_add(f, v3s(0.25f * q->coat * (float)fr_dielectric(half_cos(wo, wi), 1.5) * dg));
        } else {
            /* KHR_materials_clearcoat's fresnel_coat: mix(base, coat, c Fc(N.V)) */
            float fc = coat_fresnel(q, wo.z);
            f = v3_add(v3_scale(f, 1.0f - fc), v3s(fc * dg));
        }
        pdf += prob[LOBE_COAT] * pdf_coat;
    }
    return finite_or_zero(f, pdf, pdf_out);
}

void bsdf_prepare(const BsdfParams *p, BsdfPrepared *q) { prepare(p, q); }

vec3 bsdf_eval(const BsdfParams *p, vec3 wo, vec3 wi) {
    Prep q;
    prepare(p, &q);
    return eval_pdf(&q, wo, wi, NULL);
}

vec3 bsdf_prepared_eval_pdf(const BsdfPrepared *q, vec3 wo, vec3 wi, float *pdf) { return eval_pdf(q, wo, wi, pdf); }

float bsdf_pdf(const BsdfParams *p, vec3 wo, vec3 wi) {
    Prep q;
    prepare(p, &q);
    float pdf;
    eval_pdf(&q, wo, wi, &pdf);
    return pdf;
}

static vec3 reflect_about(vec3 wo, vec3 n) { return v3_sub(v3_scale(n, 2.0f * v3_dot(wo, n)), wo); }

/* Refraction of wo (dot(wo,n) > 0) through n with eta = eta_t / eta_o. Returns 0 on TIR. */
static int refract_about(vec3 wo, vec3 n, float eta, vec3 *wt) {
    float ci = v3_dot(wo, n);
    float sin2_t = maxf(1.0f - ci * ci, 0.0f) / (eta * eta);
    if (sin2_t >= 1.0f) return 0;
    float ct = sqrtf(1.0f - sin2_t);
    *wt = v3_normalize(v3_add(v3_scale(wo, -1.0f / eta), v3_scale(n, ci / eta - ct)));
    return 1;
}

int bsdf_sample(const BsdfParams *p, vec3 wo, float u_lobe, float u1, float u2, BsdfSample *s) {
    Prep q;
    prepare(p, &q);
    return bsdf_prepared_sample(&q, wo, u_lobe, u1, u2, s);
}

int bsdf_prepared_sample(const BsdfPrepared *qp, vec3 wo, float u_lobe, float u1, float u2, BsdfSample *s) {
    s->wi = v3(0.0f, 0.0f, 1.0f);
    s->f = v3s(0.0f);
    s->pdf = 0.0f;
    s->flags = 0;
    if (!v3_is_finite(wo) || wo.z == 0.0f) return 0;
    u_lobe = clampf(isnan(u_lobe) ? 0.0f : u_lobe, 0.0f, 0x1.fffffep-1f);
    u1 = clampf(isnan(u1) ? 0.0f : u1, 0.0f, 0x1.fffffep-1f);
    u2 = clampf(isnan(u2) ? 0.0f : u2, 0.0f, 0x1.fffffep-1f);

    if (qp->lambert) {
        /* the only lobe with weight: the general path below picks it whatever u_lobe is */
        if (!(wo.z > 0.0f) || !(qp->lambert_prob > 0.0f)) return 0;
        vec3 wi = sample_cosine_hemisphere(u1, u2);
        if (!(wi.z > MIN_COS)) return 0;
        s->flags = BSDF_REFLECTION;
        float pdf;
        vec3 f = lambert_eval_pdf(qp, wo, wi, &pdf);
        if (!(pdf > 0.0f) || !v3_is_finite(f)) return 0;
        if (!v3_is_finite(v3_scale(f, fabsf(wi.z) / pdf))) return 0;
        s->wi = wi;
        s->f = f;
        s->pdf = pdf;
        return 1;
    }
    float prob[LOBE_COUNT];
    if (!(lobe_probs(qp, wo, prob) > 0.0f)) return 0;
    int lobe = -1;
    float acc = 0.0f, u_rem = 0.0f;
    for (int k = 0; k < LOBE_COUNT; ++k) {
        if (prob[k] <= 0.0f) continue;
        lobe = k;
        if (u_lobe < acc + prob[k]) break;
        acc += prob[k];
    }
    if (lobe < 0) return 0;
    u_rem = clampf((u_lobe - acc) / prob[lobe], 0.0f, 0x1.fffffep-1f);

    vec3 wi;
    switch (lobe) {
    case LOBE_METAL:
    case LOBE_SPEC: {
        vec3 wm = ggx_sample_visible_normal(wo, qp->alpha, u1, u2);
        wi = reflect_about(wo, wm);
        if (!(wi.z > MIN_COS)) return 0;
        s->flags = BSDF_REFLECTION;
        break;
    }
    case LOBE_COAT: {
        vec3 wm = ggx_sample_visible_normal(wo, qp->alpha_coat, u1, u2);
        wi = reflect_about(wo, wm);
        if (!(wi.z > MIN_COS)) return 0;
        s->flags = BSDF_REFLECTION;
        break;
    }
    case LOBE_DIFFUSE:
        wi = sample_cosine_hemisphere(u1, u2);
        if (!(wi.z > MIN_COS)) return 0;
        s->flags = BSDF_REFLECTION;
        break;
    default: { /* LOBE_GLASS */
        float sg = wo.z > 0.0f ? 1.0f : -1.0f;
        float eta = wo.z > 0.0f ? qp->ior : 1.0f / qp->ior;
        vec3 o = v3_scale(wo, sg);
        float wg = (1.0f - qp->m) * qp->t;
        if (qp->glass_delta) {
            float fr = (float)(qp->glass_fscale * fr_dielectric(o.z, eta));
            vec3 w;
            float pr, weight_f;
            vec3 tint = v3s(1.0f);
            if (u_rem < fr) {
                w = v3(-o.x, -o.y, o.z);
                pr = fr;
                weight_f = fr;
                s->flags = BSDF_REFLECTION | BSDF_DELTA;
            } else {
                if (!refract_about(o, v3(0.0f, 0.0f, 1.0f), eta, &w)) return 0;
                pr = 1.0f - fr;
                weight_f = (1.0f - fr) / (eta * eta);
                tint = qp->base;
                s->flags = BSDF_TRANSMISSION | BSDF_DELTA;
            }
            if (!(fabsf(w.z) > MIN_COS) || !(pr > 0.0f)) return 0;
            if (qp->model == BSDF_MODEL_GLTF) weight_f *= 1.0f - coat_fresnel(qp, o.z); /* fresnel_coat */
            s->wi = v3_scale(w, sg);
            s->pdf = prob[LOBE_GLASS] * pr;
            /* weight = f |cos| / pdf = wg * weight_f * tint / (prob * pr): the lobe's mixture
             * weight over its selection probability. */
            s->f = v3_scale(tint, wg * weight_f / fabsf(w.z));
            if (!(s->pdf > 0.0f) || !v3_is_finite(s->f)) return 0;
            return 1;
        }
        vec3 wm = ggx_sample_visible_normal(o, qp->alpha_glass, u1, u2);
        float dot_o = v3_dot(o, wm);
        if (!(dot_o > 0.0f)) return 0;
        float fr = (float)(qp->glass_fscale * fr_dielectric(qp->model == BSDF_MODEL_BLENDER3 ? o.z : dot_o, eta));
        vec3 w;
        if (u_rem < fr) {
            w = reflect_about(o, wm);
            if (!(w.z > MIN_COS)) return 0;
            s->flags = BSDF_REFLECTION;
        } else {
            if (!refract_about(o, wm, eta, &w)) return 0;
            if (!(w.z < -MIN_COS)) return 0;
            s->flags = BSDF_TRANSMISSION;
        }
        wi = v3_scale(w, sg);
        break;
    }
    }
    float pdf;
    vec3 f = eval_pdf(qp, wo, wi, &pdf);
    if (!(pdf > 0.0f) || !v3_is_finite(f)) return 0;
    vec3 weight = v3_scale(f, fabsf(wi.z) / pdf);
    if (!v3_is_finite(weight)) return 0;
    s->wi = wi;
    s->f = f;
    s->pdf = pdf;
    return 1;
}

int bsdf_prepared_guidable(const BsdfPrepared *q) {
    if (q->t > 0.0f && q->glass_delta) return 0; /* a delta lobe, which a guide never samples */
    /* the seed's ch. 1 §3.1: the roughest lobe above 0.05 (a diffuse base is the roughest) */
    return (1.0f - q->m) * (1.0f - q->t) > 0.0f || q->roughness > BSDF_GUIDE_MIN_ROUGHNESS;
}

int bsdf_prepared_is_delta(const BsdfPrepared *q) {
    return q->m == 0.0f && q->t == 1.0f && q->glass_delta && q->coat == 0.0f;
}

int bsdf_prepared_has_transmission(const BsdfPrepared *q) { return q->t > 0.0f && q->m < 1.0f; }

int bsdf_is_delta(const BsdfParams *p) {
    Prep q;
    prepare(p, &q);
    return bsdf_prepared_is_delta(&q);
}

int bsdf_has_transmission(const BsdfParams *p) {
    Prep q;
    prepare(p, &q);
    return bsdf_prepared_has_transmission(&q);
}
