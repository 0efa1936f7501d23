/* renderer/integrator/emission_auto.c: --volume-emission-sampling auto (the paper's §5.2.3 wish for an
 * automatic choice; the in-scattering twin is in inscatter.c).
 *
 * Emission sampling (§4.3: an emissive volume is also a light, NEE with line integration, MIS
 * with tracking) lowers the variance of what the volume lights, at the cost of NEE rays and line
 * integrals. With auto every emissive volume is a light, and for the first 4 spp every one is
 * sampled; the probe attributes a path to the first emissive medium it met and records the contributions of the first emissive medium it met: as
 * rendered (MIS-weighted NEE and tracking) and as tracking alone would have given them
 * (unweighted), with the NEE's cost (2 units per NEE of the volume: the shadow ray and the line
 * integral). At the barrier after the probe a medium keeps emission sampling where the
 * estimated time to unit variance is lower with it (auto_probe.c); for the others NEE skips the volume (a selected volume light contributes
 * nothing) and tracking's emission takes weight 1, which is again a partition of unity, so the
 * image stays unbiased. Sums run in path order; costs are counts, never clocks. */
#include "feature.h"

static void emission_auto_barrier(Integrator *ig) { auto_probe_barrier(&ig->emission_auto, ig->opt->quiet); }

static void emission_probe_batch(Integrator *ig, Slice *slices, uint32_t n) {
    const PathState *ps = &ig->ps;
    auto_probe_batch(&ig->emission_auto, ig, slices, n, ps->probe_em_medium, ps->probe_em_on, ps->probe_em_off,
                     ps->probe_em_cost);
}

/* --volume-emission-sampling on (1) or auto (2) where there are lights */
static int emission_auto_init(Integrator *ig) {
    int mode = ig->lights->count > 0 ? ig->opt->volume_emission_sampling : 0;
    AutoProbe *ap = &ig->emission_auto;
    if (auto_probe_init(ap, "--volume-emission-sampling", media_count(ig->media), ig->npixels, mode) != 0) return -1;
    /* only emissive volumes are lights: the others have nothing to sample */
    for (uint32_t m = 0; m < ap->num_media; ++m) ap->on[m] = ap->on[m] && m < ig->media->num_vdb && ig->media->vdb[m].emissive;
    return 0;
}

static void emission_auto_free(Integrator *ig) { auto_probe_free(&ig->emission_auto); }
static int emission_auto_save(const Integrator *ig, FILE *out) { return auto_probe_save(&ig->emission_auto, ig->npixels, out); }
static int emission_auto_load(Integrator *ig, FILE *in) { return auto_probe_load(&ig->emission_auto, ig->npixels, in); }

const IntegratorFeature feature_emission_auto = {
    .name = "emission sampling auto choice",
    .init = emission_auto_init,
    .free = emission_auto_free,
    .batch_end = emission_probe_batch,
    .barrier = emission_auto_barrier,
    .save = emission_auto_save,
    .load = emission_auto_load,
};
