/* renderer/integrator/volume_auto.h (private): the volume estimators' `auto` choices (volume_auto.c): the
 * per-path probe records the stages make (the probes' state, AutoProbe, is declared with the integrator's). */
#ifndef CANDELA_VOLUME_AUTO_H
#define CANDELA_VOLUME_AUTO_H

#include <math.h>

#include "integrator.h"

/* volume_auto.c: the volume estimators' `auto` choices, in-scattering sampling's and emission
 * sampling's: each a per-medium state (off, on, auto) and a probe (AutoProbe) whose accounting
 * after each batch and decision at a barrier are its entry in the feature table (feature.h);
 * the probes' records, path by path, are the inline functions below. */
/* Whether a camera segment through these media uses in-scattering sampling (a function of the
 * media and of the iteration's state only, so both techniques agree on it). */
int inscatter_segment_on(const Integrator *ig, const MediaView *view);

/* The auto choices' rule (both probes): with V_path the variance of the paths' radiance
 * measured with the feature on, V_on / V_off that of the feature's share of it with and
 * without the feature, C the mean cost of a path and c_feature what the feature adds to it,
 * keep the feature when (V_path - V_on + V_on) C < (V_path - V_on + V_off) (C - c_feature):
 * when it lowers the estimated time to unit variance. Returns that TTUV ratio (on / off). */
static inline double estimator_ttuv_ratio(double v_path, double v_on, double v_off, double C, double c_feature) {
    double v_rest = fmax(v_path - v_on, 0.0);
    double on = (v_rest + v_on) * C, off = (v_rest + v_off) * fmax(C - c_feature, 1e-9);
    return off > 0.0 ? on / off : (on > 0.0 ? INFINITY : 1.0);
}
static inline double sample_variance(double n, double sum, double sum2) {
    return n > 1.0 ? fmax((sum2 - sum * sum / n) / (n - 1.0), 0.0) : 0.0;
}

/* --volume-emission-sampling on / auto (volume_auto.c), as in-scattering sampling above: all
 * emissive volumes sample their emission by NEE during the probe (4 spp), then only those where
 * the estimated time to unit variance is lower with it (its entry in the feature table,
 * feature.h). */
/* The probe's record of a contribution of an emissive medium's emission to path p: `on` what
 * the path added (MIS-weighted NEE or tracking), `off` what tracking alone would add, cost. */
static inline void emission_probe_add(const Integrator *ig, uint32_t p, uint32_t medium_id, float on, float off,
                                      float cost) {
    const PathState *ps = &ig->ps;
    if (!ig->emission_auto.active) return;
    if (!ps->probe_em_medium[p]) ps->probe_em_medium[p] = medium_id + 1;
    if (ps->probe_em_medium[p] != medium_id + 1) return; /* one medium per path */
    ps->probe_em_on[p] += on;
    ps->probe_em_off[p] += off;
    ps->probe_em_cost[p] += cost;
}

/* ... of an NEE toward `light` (counted when it is an emissive volume): its contribution c
 * (luminance, 0 when blocked) and cost. */
static inline void emission_probe_nee(const Integrator *ig, uint32_t p, uint32_t light, float c, float cost) {
    if (!ig->emission_auto.active || light >= ig->lights->count) return;
    const Light *l = &ig->lights->lights[light];
    if (l->type == LIGHT_VOLUME) emission_probe_add(ig, p, l->medium, c, 0.0f, cost);
}

/* The probe's record of a camera segment's null-collision NEE (unweighted luminance c, and the
 * weight it got). */
static inline void inscatter_probe_null(const Integrator *ig, uint32_t p, float c, float w) {
    if (!ig->inscatter_auto.active) return;
    ig->ps.probe_null[p] += c;
    ig->ps.probe_mis[p] += w * c;
}

#endif
