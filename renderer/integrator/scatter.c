/* renderer/integrator/scatter.c: the scattering interface (scatter.h) over the surface BSDF. */
#include "scatter.h"

#include <math.h>

#include "volumes.h"

/* The shading normal ns bent towards ng just enough that the mirror reflection of wo about it
 * leaves the surface at an elevation of at least t = min(0.9 (ng.wo), 0.01) above the geometric
 * plane (the approach of Cycles' ensure_valid_reflection; derived here, not copied). A normal
 * map or interpolated normal tilted away from a grazing view otherwise puts wo below the
 * shading hemisphere: the BSDF is zero there and the geometric guard rejects what is left, so
 * valid paths die and the pixels turn black (issue 14). ng and ns are on wo's side (ng.wo > 0).
 * In the plane of ng (z) and ns's tangential part (x), ns' = (sin a, cos a) reflects wo
 * (components wx, wz) to an elevation wx sin 2a + wz cos 2a = A cos(2a - phi) with
 * A = |(wx, wz)|, phi = atan2(wx, wz); it falls from wz > t at a = 0 to below t at ns's own
 * tilt, crossing t once, at 2a = phi + acos(t / A): the least bending that makes it valid. */
static vec3 shading_normal_valid_for(vec3 ng, vec3 ns, vec3 wo) {
    float wz = v3_dot(ng, wo);
    float t = 0.9f * wz < 0.01f ? 0.9f * wz : 0.01f; /* fminf(0.9 wz, 0.01) (NaN: 0.01) without the libm call */
    float won = v3_dot(ns, wo);
    vec3 r = v3_sub(v3_scale(ns, 2.0f * won), wo);
    if (v3_dot(ng, r) >= t) return ns;
    vec3 x = v3_sub(ns, v3_scale(ng, v3_dot(ns, ng)));
    float xl = v3_length(x);
    if (!(xl > 1e-7f) || !(wz > 0.0f)) return ng;
    x = v3_scale(x, 1.0f / xl);
    float wx = v3_dot(wo, x);
    float a_len = sqrtf(wx * wx + wz * wz);
    float a = 0.5f * (atan2f(wx, wz) + acosf(clampf(t / a_len, -1.0f, 1.0f)));
    vec3 n = v3_add(v3_scale(ng, cosf(a)), v3_scale(x, sinf(a)));
    return v3_normalize(n);
}

void scatter_init_surface_prepared(Scatter *s, const SurfaceHit *h, const BsdfParams *bsdf,
                                   const BsdfPrepared *prepared, vec3 wo_world) {
    s->guide = NULL;
    s->guide_mode = SCATTER_GUIDE_NONE;
    s->kind = SCATTER_BSDF;
    s->bsdf = bsdf;
    /* once per vertex (or per material, when fixed): every sample and evaluation below reuses it */
    if (!prepared) {
        bsdf_prepare(bsdf, &s->prep_own);
        prepared = &s->prep_own;
    }
    s->prep = prepared;
    s->transmissive = bsdf_prepared_has_transmission(s->prep);
    vec3 ng = h->ng, ns = h->ns;
    /* opaque surfaces are shaded on the side they are seen from; glass keeps +z outside */
    if (!s->transmissive && v3_dot(wo_world, ng) < 0.0f) { ng = v3_neg(ng); ns = v3_neg(ns); }
    s->ng = ng;
    s->wo_outside = v3_dot(wo_world, ng) > 0.0f;
    {
        /* on wo's side (glass keeps +z outside, so flip there and back) */
        float side = s->wo_outside ? 1.0f : -1.0f;
        ns = v3_scale(shading_normal_valid_for(v3_scale(ng, side), v3_scale(ns, side), wo_world), side);
    }
    Frame *f = &s->frame;
    f->n = ns;
    f->t = h->dpdu;
    if (v3_dot(f->t, ns) != 0.0f) f->t = v3_renormalize(v3_sub(f->t, v3_scale(ns, v3_dot(ns, f->t))));
    f->b = v3_cross(ns, f->t);
    s->wo = frame_to_local(f, wo_world);
}

void scatter_init_phase(Scatter *s, float g, vec3 wo_world) {
    s->guide = NULL;
    s->guide_mode = SCATTER_GUIDE_NONE;
    s->kind = SCATTER_PHASE;
    s->bsdf = NULL;
    s->prep = NULL;
    s->g = g;
    s->wo_world = wo_world;
    s->transmissive = 0;
}

int scatter_sample(const Scatter *s, float u_lobe, float u1, float u2, ScatterSample *out) {
    if (s->kind == SCATTER_PHASE) {
        (void)u_lobe;
        float wo[3] = {s->wo_world.x, s->wo_world.y, s->wo_world.z}, wi[3];
        float pdf = hg_sample(s->g, wo, u1, u2, wi);
        if (!(pdf > 0.0f)) return 0;
        out->wi = v3(wi[0], wi[1], wi[2]);
        out->weight = v3s(1.0f); /* HG is sampled exactly: f / pdf = 1 */
        out->pdf = pdf;
        out->delta = 0;
        out->transmitted = 0;
        out->rr_factor = 1.0f;
        out->scatter_pdf = pdf;
        out->guide_pdf = 0.0f;
        return 1;
    }
    BsdfSample bs;
    if (!bsdf_prepared_sample(s->prep, s->wo, u_lobe, u1, u2, &bs)) return 0;
    vec3 wi = v3_renormalize(frame_to_world(&s->frame, bs.wi));
    float side_g = v3_dot(wi, s->ng);
    if (!(side_g * bs.wi.z > 0.0f) || !(bs.pdf > 0.0f)) return 0;
    out->wi = wi;
    out->weight = v3_scale(bs.f, fabsf(bs.wi.z) / bs.pdf);
    out->pdf = bs.pdf;
    out->delta = (bs.flags & BSDF_DELTA) != 0;
    out->transmitted = (bs.flags & BSDF_TRANSMISSION) != 0;
    out->rr_factor = 1.0f;
    if (bs.flags & BSDF_TRANSMISSION) {
        /* radiance is scaled by 1/eta^2 across refraction; the roulette looks through it */
        float eta = s->bsdf->ior;
        out->rr_factor = s->wo_outside ? eta * eta : 1.0f / (eta * eta);
    }
    out->scatter_pdf = bs.pdf;
    out->guide_pdf = 0.0f;
    return 1;
}

/* The function alone: f |cos| and its own pdf. */
static vec3 function_eval(const Scatter *s, vec3 wi, float *pdf) {
    if (s->kind == SCATTER_PHASE) {
        float wo[3] = {s->wo_world.x, s->wo_world.y, s->wo_world.z}, w[3] = {wi.x, wi.y, wi.z};
        float p = hg_phase(s->g, wo, w);
        *pdf = p;
        return v3s(p);
    }
    vec3 wi_l = frame_to_local(&s->frame, wi);
    float side_g = v3_dot(wi, s->ng);
    *pdf = 0.0f;
    if (!(side_g * wi_l.z > 0.0f)) return v3s(0.0f);
    return v3_scale(bsdf_prepared_eval_pdf(s->prep, s->wo, wi_l, pdf), fabsf(wi_l.z));
}

int scatter_guidable(const Scatter *s) {
    return s->kind == SCATTER_PHASE ? fabsf(s->g) < SCATTER_PHASE_GUIDE_MAX_G : bsdf_prepared_guidable(s->prep);
}

void scatter_set_guide(Scatter *s, const GuideDistribution *d, ScatterGuideMode mode, int training) {
    s->guide = NULL;
    s->guide_mode = SCATTER_GUIDE_NONE;
    if (!d || mode == SCATTER_GUIDE_NONE) return; /* the caller asked scatter_guidable (a BSDF preparation) */
    s->guide = d;
    s->guide_mode = mode;
    s->guide_share = guide_distribution_bsdf_share(d);
    s->guide_pdf_wanted = training;
}

static float guide_pdf_of(const Scatter *s, vec3 wi) {
    const float d[3] = {wi.x, wi.y, wi.z};
    return guide_distribution_pdf(s->guide, d);
}

vec3 scatter_eval(const Scatter *s, vec3 wi, float *pdf) {
    float unused;
    return function_eval(s, wi, pdf ? pdf : &unused); /* the function's own pdf: see scatter.h */
}

/* The roulette factor that brings a guided weight back to the function's own sampling weight
 * (ch. 1 §4.1.1, Eqs. 17-19): f|cos|/p_function over the weight used (luminance), where that
 * raises the survival: where the guide sent more samples than the function would (a bright
 * direction), the guided weight is smaller and the plain roulette would kill the paths guiding
 * exists for. Where the guide sent fewer (p < p_function: a direction it thinks dark), the
 * factor would be below 1 and the roulette would kill more readily than the throughput says,
 * boosting its survivors to 1 / rr_scale on top of the larger weight one-sample MIS already gave
 * them; those are where the guide is wrong (caustics through glass, glossy lobes it has not
 * learned), so the factor is 1 there. Measured (scenes/RESULTS.md, "Guided roulette"): at 640x480
 * guiding_interior's relMSE 1.67x lower for 1.12x the time, the box's at 192x192 1.41x lower. */
static float guided_rr_factor(vec3 f, float p_function, vec3 weight) {
    float lw = v3_luminance(weight), lf = v3_luminance(f);
    return p_function > 0.0f && lw > 0.0f ? fmaxf((lf / p_function) / lw, 1.0f) : 1.0f;
}

void scatter_prefetch_guided(const Scatter *s, const float u[6]) {
    if (!s->guide) return;
    int ris = s->guide_mode != SCATTER_GUIDE_MIS;
    if (ris || u[0] >= s->guide_share) guide_distribution_prefetch_sample(s->guide, ris ? u[3] : u[1]);
    if (ris || (u[0] < s->guide_share && (s->guide_share < 1.0f || s->guide_pdf_wanted)))
        guide_distribution_prefetch_pdf(s->guide);
}

int scatter_sample_guided(const Scatter *s, const float u[6], ScatterSample *out) {
    if (!s->guide) return scatter_sample(s, u[0], u[1], u[2], out);
    const float alpha = s->guide_share;
    vec3 fsel; /* f |cos| of the chosen direction */
    if (s->guide_mode == SCATTER_GUIDE_MIS) {
        /* one-sample MIS (Eq. 4-6): the function's sample with probability alpha, else the guide's.
         * u[0] chooses and, rescaled, picks the function's lobe; either technique takes its
         * direction from u[1], u[2], so both stay stratified (scatter_numbers) */
        vec3 wi, f;
        float p_f, p_g;
        if (u[0] < alpha) {
            ScatterSample fs;
            if (!scatter_sample(s, fminf(u[0] / alpha, 0x1.fffffep-1f), u[1], u[2], &fs)) return 0;
            wi = fs.wi;
            p_f = fs.scatter_pdf;
            f = v3_scale(fs.weight, p_f); /* f |cos| */
            /* where the share is 1 the mixture is the function alone: no guide pdf (but the
             * share's training statistics read it) */
            p_g = alpha < 1.0f || s->guide_pdf_wanted ? guide_pdf_of(s, wi) : 0.0f;
        } else {
            float d[3];
            guide_distribution_sample(s->guide, u[1], u[2], d, &p_g);
            wi = v3(d[0], d[1], d[2]);
            f = function_eval(s, wi, &p_f);
            if (v3_is_black(f)) return 0; /* the guide proposed a direction the function rejects */
        }
        float pdf = alpha < 1.0f ? alpha * p_f + (1.0f - alpha) * p_g : p_f;
        if (!(pdf > 0.0f)) return 0;
        fsel = f;
        out->wi = wi;
        out->weight = v3_scale(f, 1.0f / pdf);
        out->pdf = pdf;
        out->scatter_pdf = p_f;
        out->guide_pdf = p_g;
    } else {
        /* RIS with one candidate of each (Eqs. 8-14): target t = f|cos| (beta/4pi + (1 - beta) L~),
         * L~ the guide's radiance: g on media, g / |cos| on surfaces, whose guides learn L |cos|
         * (renderer/integrator/guide.c) */
        const float beta = SCATTER_RIS_UNIFORM_SHARE;
        vec3 wc[2], fc[2];
        float pf[2] = {0, 0}, pg[2] = {0, 0}, w[2] = {0, 0}, t[2] = {0, 0};
        ScatterSample fs;
        if (scatter_sample(s, u[0], u[1], u[2], &fs)) {
            wc[0] = fs.wi;
            pf[0] = fs.scatter_pdf;
            fc[0] = v3_scale(fs.weight, pf[0]);
            pg[0] = guide_pdf_of(s, wc[0]);
        } else fc[0] = v3s(0.0f);
        float d[3];
        guide_distribution_sample(s->guide, u[3], u[4], d, &pg[1]);
        wc[1] = v3(d[0], d[1], d[2]);
        fc[1] = function_eval(s, wc[1], &pf[1]);
        for (int k = 0; k < 2; ++k) {
            float p = 0.5f * pf[k] + 0.5f * pg[k];
            float radiance = pg[k];
            if (s->kind == SCATTER_BSDF) radiance /= fmaxf(fabsf(v3_dot(wc[k], s->frame.n)), 1e-3f);
            t[k] = v3_luminance(fc[k]) * (beta * (float)(0.25 / M_PI) + (1.0f - beta) * radiance);
            w[k] = p > 0.0f && t[k] > 0.0f ? t[k] / p : 0.0f;
        }
        float sum = w[0] + w[1];
        if (!(sum > 0.0f) || !isfinite(sum)) return 0;
        int j = u[5] * sum < w[0] ? 0 : 1;
        if (w[j] == 0.0f) j = 1 - j;
        fsel = fc[j];
        out->wi = wc[j];
        out->weight = v3_scale(fc[j], 0.5f * sum / t[j]);
        out->pdf = 0.5f * pf[j] + 0.5f * pg[j]; /* the candidate pdf, as in every MIS weight (§3.3.1) */
        out->scatter_pdf = pf[j];
        out->guide_pdf = pg[j];
    }
    out->delta = 0;
    out->rr_factor = guided_rr_factor(fsel, out->scatter_pdf, out->weight);
    out->transmitted = 0;
    if (s->kind == SCATTER_BSDF) {
        /* the local z is wo's side for opaque surfaces and outside for transmissive ones */
        vec3 wi_l = frame_to_local(&s->frame, out->wi);
        out->transmitted = (wi_l.z > 0.0f) != (s->wo.z > 0.0f);
        if (out->transmitted) {
            float eta = s->bsdf->ior;
            out->rr_factor *= s->wo_outside ? eta * eta : 1.0f / (eta * eta);
        }
    }
    return v3_is_finite(out->weight);
}
