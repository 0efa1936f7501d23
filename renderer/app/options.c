/* renderer/app/options.c: render option defaults and the light sampler names. */
#include <math.h>
#include <string.h>

#include "candela.h"

void candela_options_default(CandelaOptions *o) {
    memset(o, 0, sizeof *o);
    o->spp = 16;
    o->seed = 0;
    o->max_depth = 8;
    o->max_volume_bounces = 256;
    o->volume_emission_sampling = 2;  /* auto (scenes/volume_equal_time.py: never measurably worse) */
    o->volume_inscatter_sampling = 2; /* auto */
    o->texture_budget_mb = 8192;      /* 8 GiB of decoded texels (README "Limits") */
    o->volume_budget_mb = 8192;       /* 8 GiB of volume grids, majorants and emission grids (README "Limits") */
    o->light_sampler = CANDELA_LIGHT_SAMPLER_AUTO;   /* optimal with few lights, else cache points */
    o->light_units = CANDELA_LIGHT_UNITS_BLENDER;
    o->env_strength = 1.0f;
    o->env_rotation_deg = NAN;        /* not given: the scene's candela_environment.rotation */
    o->guiding = CANDELA_GUIDING_OFF;
    o->recorder_budget = -1;          /* the seed's soft budget of 4 vertices per path */
    o->guide_directional_filter = 1;  /* Müller 2019's directional box filter in guide training (README) */
    o->guide_bsdf_share = 0.5f;       /* defensive one-sample MIS; 0 learns it per leaf (guiding/README.md) */
    o->guide_min_bsdf_share = 0.5f;   /* learned BSDF shares stay at or above 1/2 (guiding/README.md) */
    o->guide_caustic_threshold = 0.0f; /* the caustic guard, off (guiding/README.md) */
    o->guide_caustic_share = 0.75f;
    o->guide_caustic_defense = 1.0f; /* the caustic defense (guiding/README.md) */
    o->cachepoint_bsdf = 1;           /* BSDF-aware cache point selection at glossy vertices (README) */
}

const char *candela_guiding_name(CandelaGuiding g) {
    static const char *const names[] = {"off", "mis", "ris", "auto"};
    return (unsigned)g < 4 ? names[g] : "unknown";
}

const char *candela_sampler_name(CandelaSampler s) {
    return s == CANDELA_SAMPLER_INDEPENDENT ? "independent" : s == CANDELA_SAMPLER_SOBOL ? "sobol" : "unknown";
}

static const char *const LIGHT_SAMPLER_NAMES[] = {"uniform", "power", "tree", "optimal", "cachepoints", "auto"};

const char *candela_light_sampler_name(CandelaLightSampler s) {
    return (unsigned)s < sizeof LIGHT_SAMPLER_NAMES / sizeof LIGHT_SAMPLER_NAMES[0] ? LIGHT_SAMPLER_NAMES[s] : "unknown";
}

int candela_light_sampler_parse(const char *name, CandelaLightSampler *s) {
    for (unsigned i = 0; i < sizeof LIGHT_SAMPLER_NAMES / sizeof LIGHT_SAMPLER_NAMES[0]; ++i)
        if (strcmp(name, LIGHT_SAMPLER_NAMES[i]) == 0) { *s = (CandelaLightSampler)i; return 0; }
    return -1;
}
