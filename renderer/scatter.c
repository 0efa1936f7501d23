/* renderer/scatter.c: the scattering interface (scatter.h) over the surface BSDF. */
#include "scatter.h"

#include "volumes.h"

void scatter_init_surface(Scatter *s, const SurfaceHit *h, const BsdfParams *bsdf, vec3 wo_world) {
    s->kind = SCATTER_BSDF;
    s->bsdf = *bsdf;
    s->transmissive = bsdf_has_transmission(bsdf);
    vec3 ng = h->ng, ns = h->ns;
    /* opaque surfaces are shaded on the side they are seen from; glass keeps +z outside */
    if (!s->transmissive && v3_dot(wo_world, ng) < 0.0f) { ng = v3_neg(ng); ns = v3_neg(ns); }
    s->ng = ng;
    s->wo_outside = v3_dot(wo_world, ng) > 0.0f;
    Frame *f = &s->frame;
    f->n = ns;
    f->t = h->dpdu;
    if (v3_dot(f->t, ns) != 0.0f) f->t = v3_normalize(v3_sub(f->t, v3_scale(ns, v3_dot(ns, f->t))));
    f->b = v3_cross(ns, f->t);
    s->wo = frame_to_local(f, wo_world);
}

void scatter_init_phase(Scatter *s, float g, vec3 wo_world) {
    s->kind = SCATTER_PHASE;
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
        return 1;
    }
    BsdfSample bs;
    if (!bsdf_sample(&s->bsdf, s->wo, u_lobe, u1, u2, &bs)) return 0;
    vec3 wi = v3_normalize(frame_to_world(&s->frame, bs.wi));
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
        float eta = s->bsdf.ior;
        out->rr_factor = s->wo_outside ? eta * eta : 1.0f / (eta * eta);
    }
    return 1;
}

vec3 scatter_eval(const Scatter *s, vec3 wi, float *pdf) {
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
    return v3_scale(bsdf_eval_pdf(&s->bsdf, s->wo, wi_l, pdf), fabsf(wi_l.z));
}
