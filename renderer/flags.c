/* renderer/flags.c: the render flags of the command line, parsed in one place.
 *
 * `candela render` (main.c) and every variant of `candela compare --variants` go through
 * candela_parse_render_flag, so a variant accepts exactly the flags a render does and a bad
 * value gives the same message. Flags that are not render options (outputs, --quiet, the
 * subcommands' own) stay with their command. Messages carry no "candela: " prefix: the
 * caller adds its own context (the program name, or the variant's name). */
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "candela.h"

/* The largest image: 16384 per side, 64 Mpixels in all (the film takes ~100 bytes per pixel). */
#define MAX_RES_SIDE 16384
#define MAX_RES_PIXELS (64 << 20)

static int missing(const char *flag, char err[CANDELA_ERR_LEN]) {
    snprintf(err, CANDELA_ERR_LEN, "missing value for %s", flag);
    return -1;
}

static int parse_long(const char *flag, const char *s, long lo, long hi, long *out, char err[CANDELA_ERR_LEN]) {
    if (!s) return missing(flag, err);
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (errno || end == s || *end != 0 || v < lo || v > hi) {
        snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for %s (expected an integer in [%ld, %ld])", s, flag, lo, hi);
        return -1;
    }
    *out = v;
    return 0;
}

static int parse_float(const char *flag, const char *s, float lo, float hi, float *out, char err[CANDELA_ERR_LEN]) {
    if (!s) return missing(flag, err);
    char *end;
    errno = 0;
    float v = strtof(s, &end);
    if (errno || end == s || *end != 0 || !(v >= lo && v <= hi)) {
        snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for %s (expected a number in [%g, %g])", s, flag, lo, hi);
        return -1;
    }
    *out = v;
    return 0;
}

/* One of names[] (NULL-terminated) -> values[k]; else the message "unknown value ... (a, b)". */
static int parse_choice(const char *flag, const char *s, const char *const *names, const int *values, int *out,
                        const char *what, char err[CANDELA_ERR_LEN]) {
    if (!s) return missing(flag, err);
    char list[128] = "";
    for (int k = 0; names[k]; ++k) {
        if (strcmp(s, names[k]) == 0) { *out = values[k]; return 0; }
        snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", k ? ", " : "", names[k]);
    }
    if (what) snprintf(err, CANDELA_ERR_LEN, "unknown %s '%.200s' (%s)", what, s, list);
    else snprintf(err, CANDELA_ERR_LEN, "unknown value '%.200s' for %s (%s)", s, flag, list);
    return -1;
}

static const char *const ON_OFF_AUTO[] = {"on", "off", "auto", NULL};
static const int ON_OFF_AUTO_VALUES[] = {1, 0, 2};

int candela_parse_render_flag(CandelaOptions *o, int argc, char *const *argv, int *i, char err[CANDELA_ERR_LEN]) {
    const char *a = argv[*i];
    const char *v = *i + 1 < argc ? argv[*i + 1] : NULL;
    long n = 0;
    float f = 0.0f;
    int c = 0;
    int rc = 0;
    /* flags without a value */
    if (strcmp(a, "--optimal-occlusion") == 0) { o->optimal_occlusion = 1; return 1; }
    if (strcmp(a, "--no-visibility") == 0) { o->cachepoint_no_visibility = 1; return 1; }
    if (strcmp(a, "--cachepoint-retruncate") == 0) { o->cachepoint_retruncate = 1; return 1; }
    /* flags with a value: every branch consumes it (*i advances past it on success) */
    if (strcmp(a, "--confine-to") == 0) {
        if (!v) return missing(a, err);
        if (!*v) { /* a farm script's unset variable: never "no confinement" */
            snprintf(err, CANDELA_ERR_LEN, "--confine-to needs a folder, not an empty name");
            return -1;
        }
        o->confine_dir = v;
    } else if (strcmp(a, "--volume-budget-mb") == 0) {
        if ((rc = parse_long(a, v, 0, 1 << 24, &n, err)) == 0) o->volume_budget_mb = (uint32_t)n;
    } else if (strcmp(a, "--texture-budget-mb") == 0) {
        if ((rc = parse_long(a, v, 0, 1 << 24, &n, err)) == 0) o->texture_budget_mb = (uint32_t)n;
    } else if (strcmp(a, "--cachepoint-cut-size") == 0) {
        if ((rc = parse_long(a, v, 1, 1 << 20, &n, err)) == 0) o->cachepoint_cut_size = (uint32_t)n;
    } else if (strcmp(a, "--cachepoint-pooling") == 0) {
        static const char *const names[] = {"off", "points", "lights", NULL};
        static const int values[] = {0, 1, 2};
        if ((rc = parse_choice(a, v, names, values, &c, NULL, err)) == 0) o->cachepoint_pooling = c;
    } else if (strcmp(a, "--cachepoint-progressive") == 0) {
        static const char *const names[] = {"on", "off", NULL};
        static const int values[] = {1, 2};
        if ((rc = parse_choice(a, v, names, values, &c, NULL, err)) == 0) o->cachepoint_progressive = c;
    } else if (strcmp(a, "--cachepoint-progressive-budget") == 0) {
        if ((rc = parse_float(a, v, 0.0f, 4.0f, &f, err)) == 0) o->cachepoint_progressive_budget = f;
    } else if (strcmp(a, "--cachepoint-bsdf") == 0) {
        static const char *const names[] = {"on", "off", NULL};
        static const int values[] = {1, 0};
        if ((rc = parse_choice(a, v, names, values, &c, NULL, err)) == 0) o->cachepoint_bsdf = c;
    } else if (strcmp(a, "--cachepoint-candidates") == 0) {
        if ((rc = parse_long(a, v, 0, 10000000, &n, err)) == 0) o->cachepoint_candidates = (uint32_t)n;
    } else if (strcmp(a, "--cachepoint-pilots") == 0) {
        if ((rc = parse_long(a, v, 0, 4000000, &n, err)) == 0) o->cachepoint_pilots = (uint32_t)n;
    } else if (strcmp(a, "--cachepoint-build") == 0) {
        static const char *const names[] = {"cut", "linear", NULL};
        static const int values[] = {0, 1};
        if ((rc = parse_choice(a, v, names, values, &c, "cache point build", err)) == 0) o->cachepoint_build_linear = c;
    } else if (strcmp(a, "--spp") == 0) {
        if ((rc = parse_long(a, v, 1, 1 << 20, &n, err)) == 0) o->spp = (int)n;
    } else if (strcmp(a, "--seed") == 0) {
        if ((rc = parse_long(a, v, 0, LONG_MAX, &n, err)) == 0) o->seed = (uint64_t)n;
    } else if (strcmp(a, "--threads") == 0) {
        if ((rc = parse_long(a, v, 1, 1024, &n, err)) == 0) o->threads = (int)n;
    } else if (strcmp(a, "--max-depth") == 0) {
        if ((rc = parse_long(a, v, 0, 1024, &n, err)) == 0) o->max_depth = (int)n;
    } else if (strcmp(a, "--max-volume-bounces") == 0) {
        if ((rc = parse_long(a, v, 0, 100000, &n, err)) == 0) o->max_volume_bounces = (int)n;
    } else if (strcmp(a, "--volume-emission-sampling") == 0) {
        if ((rc = parse_choice(a, v, ON_OFF_AUTO, ON_OFF_AUTO_VALUES, &c, NULL, err)) == 0) o->volume_emission_sampling = c;
    } else if (strcmp(a, "--volume-cachepoint-scatter") == 0) {
        if ((rc = parse_choice(a, v, ON_OFF_AUTO, ON_OFF_AUTO_VALUES, &c, NULL, err)) == 0) o->volume_inscatter_sampling = c;
    } else if (strcmp(a, "--sampler") == 0) {
        static const char *const names[] = {"sobol", "independent", NULL};
        static const int values[] = {CANDELA_SAMPLER_SOBOL, CANDELA_SAMPLER_INDEPENDENT};
        if ((rc = parse_choice(a, v, names, values, &c, "sampler", err)) == 0) o->sampler = (CandelaSampler)c;
    } else if (strcmp(a, "--guiding") == 0) {
        static const char *const names[] = {"off", "mis", "ris", "auto", NULL};
        static const int values[] = {CANDELA_GUIDING_OFF, CANDELA_GUIDING_MIS, CANDELA_GUIDING_RIS, CANDELA_GUIDING_AUTO};
        if ((rc = parse_choice(a, v, names, values, &c, NULL, err)) == 0) o->guiding = (CandelaGuiding)c;
    } else if (strcmp(a, "--path-regularization") == 0) {
        if ((rc = parse_float(a, v, 0.0f, 1.0f, &f, err)) == 0) o->path_regularization = f;
    } else if (strcmp(a, "--guide-spatial-filter") == 0) {
        static const char *const names[] = {"on", "off", NULL};
        static const int values[] = {1, 0};
        if ((rc = parse_choice(a, v, names, values, &c, NULL, err)) == 0) o->guide_spatial_filter = c;
    } else if (strcmp(a, "--guide-training-spp") == 0) {
        if ((rc = parse_long(a, v, 1, 1 << 20, &n, err)) == 0) o->guide_training_spp = (int)n;
    } else if (strcmp(a, "--guide-spatial-threshold") == 0) {
        if ((rc = parse_float(a, v, 1.0f, 1e9f, &f, err)) == 0) o->guide_spatial_threshold = f;
    } else if (strcmp(a, "--aov") == 0) {
        static const char *const names[] = {"recorder-debug", "cachepoint", "spp", NULL};
        static const int values[] = {1, 2, 3};
        if ((rc = parse_choice(a, v, names, values, &c, "AOV", err)) == 0) { /* repeatable: one AOV each */
            if (c == 1) o->aov_recorder_debug = 1;
            else if (c == 2) o->aov_selection = 1;
            else o->aov_spp = 1;
        }
    } else if (strcmp(a, "--noise-threshold") == 0) {
        if ((rc = parse_float(a, v, 1e-6f, 100.0f, &f, err)) == 0) o->noise_threshold = f;
    } else if (strcmp(a, "--min-spp") == 0) {
        if ((rc = parse_long(a, v, 1, 1 << 20, &n, err)) == 0) o->min_spp = (int)n;
    } else if (strcmp(a, "--time-limit") == 0) {
        if ((rc = parse_float(a, v, 1e-6f, 1e9f, &f, err)) == 0) o->time_limit = f;
    } else if (strcmp(a, "--clamp-direct") == 0) {
        if ((rc = parse_float(a, v, 1e-9f, 1e30f, &f, err)) == 0) o->clamp_direct = f;
    } else if (strcmp(a, "--clamp-indirect") == 0) {
        if ((rc = parse_float(a, v, 1e-9f, 1e30f, &f, err)) == 0) o->clamp_indirect = f;
    } else if (strcmp(a, "--dump-cachepoints") == 0) {
        if (!v) return missing(a, err);
        size_t len = strlen(v);
        if (len < 5 || strcmp(v + len - 4, ".ply") != 0) {
            snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for --dump-cachepoints (expected FILE.ply)", v);
            return -1;
        }
        o->cachepoint_dump_path = v;
    } else if (strcmp(a, "--recorder-budget") == 0) {
        if ((rc = parse_long(a, v, 0, 1 << 20, &n, err)) == 0) o->recorder_budget = (int)n;
    } else if (strcmp(a, "--recorder-mb") == 0) {
        if ((rc = parse_long(a, v, 1, 1 << 20, &n, err)) == 0) o->recorder_mb = (uint32_t)n;
    } else if (strcmp(a, "--batch") == 0) {
        if ((rc = parse_long(a, v, 1, 1 << 22, &n, err)) == 0) o->batch_size = (uint32_t)n;
    } else if (strcmp(a, "--env-strength") == 0) {
        if ((rc = parse_float(a, v, 0.0f, 1e9f, &f, err)) == 0) o->env_strength = f;
    } else if (strcmp(a, "--env-rotation") == 0) {
        if ((rc = parse_float(a, v, -1e6f, 1e6f, &f, err)) == 0) o->env_rotation_deg = f;
    } else if (strcmp(a, "--env") == 0) {
        if (!v) return missing(a, err);
        o->env_path = v;
    } else if (strcmp(a, "--camera") == 0) {
        if (!v) return missing(a, err);
        o->camera_name = v;
    } else if (strcmp(a, "--res") == 0) {
        if (!v) return missing(a, err);
        /* strtol with range checks: sscanf's %d wrapped 4294967304 to 8 */
        char *x = NULL, *end = NULL;
        errno = 0;
        long w = strtol(v, &x, 10), h = 0;
        int good = errno == 0 && x != v && *x == 'x' && (w >= 1 && w <= MAX_RES_SIDE);
        if (good) {
            h = strtol(x + 1, &end, 10);
            good = errno == 0 && end != x + 1 && *end == 0 && h >= 1 && h <= MAX_RES_SIDE &&
                   (long long)w * h <= MAX_RES_PIXELS;
        }
        if (!good) {
            snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for --res (expected WxH, 1..%d each, at most %d megapixels)",
                     v, MAX_RES_SIDE, MAX_RES_PIXELS >> 20);
            return -1;
        }
        o->width = (int)w;
        o->height = (int)h;
    } else if (strcmp(a, "--light-sampler") == 0) {
        if (!v) return missing(a, err);
        if (candela_light_sampler_parse(v, &o->light_sampler) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "unknown light sampler '%.200s' (auto, uniform, power, tree, optimal, cachepoints)", v);
            return -1;
        }
    } else if (strcmp(a, "--light-model") == 0) {
        static const char *const names[] = {"gltf", "blender3", NULL};
        static const int values[] = {CANDELA_LIGHT_MODEL_GLTF, CANDELA_LIGHT_MODEL_BLENDER3};
        if ((rc = parse_choice(a, v, names, values, &c, "light model", err)) == 0) o->light_model = (CandelaLightModel)c;
    } else if (strcmp(a, "--material-model") == 0) {
        static const char *const names[] = {"gltf", "blender3", NULL};
        static const int values[] = {CANDELA_MATERIAL_MODEL_GLTF, CANDELA_MATERIAL_MODEL_BLENDER3};
        if ((rc = parse_choice(a, v, names, values, &c, "material model", err)) == 0)
            o->material_model = (CandelaMaterialModel)c;
    } else if (strcmp(a, "--light-units") == 0) {
        static const char *const names[] = {"blender", "raw", NULL};
        static const int values[] = {CANDELA_LIGHT_UNITS_BLENDER, CANDELA_LIGHT_UNITS_RAW};
        if ((rc = parse_choice(a, v, names, values, &c, "light units", err)) == 0) o->light_units = (CandelaLightUnits)c;
    } else {
        return 0; /* not a render flag */
    }
    if (rc != 0) return -1;
    ++*i;
    return 1;
}

int candela_options_check(const CandelaOptions *o, char err[CANDELA_ERR_LEN]) {
    if (o->volume_inscatter_sampling == 1 && o->light_sampler != CANDELA_LIGHT_SAMPLER_CACHEPOINTS &&
        o->light_sampler != CANDELA_LIGHT_SAMPLER_AUTO) { /* auto then picks cache points */
        snprintf(err, CANDELA_ERR_LEN, "--volume-cachepoint-scatter on needs --light-sampler cachepoints");
        return -1;
    }
    if ((o->aov_selection || o->cachepoint_dump_path) && o->light_sampler != CANDELA_LIGHT_SAMPLER_CACHEPOINTS &&
        o->light_sampler != CANDELA_LIGHT_SAMPLER_AUTO) { /* auto: a warning when it chooses another */
        snprintf(err, CANDELA_ERR_LEN, "%s needs --light-sampler cachepoints (or auto)",
                 o->aov_selection ? "--aov cachepoint" : "--dump-cachepoints");
        return -1;
    }
    /* a shard's samples are a fixed range of every pixel's; stopping them by the shard's own film
     * (or clock) would give shards that merge into no render's image */
    if (o->shard_count && (o->noise_threshold > 0.0f || o->time_limit > 0.0)) {
        snprintf(err, CANDELA_ERR_LEN, "%s cannot be used with --sample-shard (a shard renders a fixed range of samples)",
                 o->noise_threshold > 0.0f ? "--noise-threshold" : "--time-limit");
        return -1;
    }
    if (o->min_spp && o->noise_threshold <= 0.0f) {
        snprintf(err, CANDELA_ERR_LEN, "--min-spp needs --noise-threshold (adaptive sampling)");
        return -1;
    }
    return 0;
}
