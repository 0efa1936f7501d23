/* renderer/app/flags.c: combinations of render options that cannot work together.
 *
 * The flags themselves are rows of renderer/app/options_table.c, where candela_parse_render_flag
 * (candela render and every variant of candela compare --variants) and the CLI's parser read
 * them. Messages carry no "candela: " prefix: the caller adds its own context (the program
 * name, or the variant's name). */
#include <stdio.h>

#include "candela.h"

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
    /* --crop inside the image: here when --res is given (so --dry-run says it too), else where
     * the scene's camera fixes the resolution (scene.c) */
    if (o->crop[2] > 0 && o->width > 0 && o->height > 0 && (o->crop[2] > o->width || o->crop[3] > o->height)) {
        snprintf(err, CANDELA_ERR_LEN, "--crop %d,%d,%d,%d reaches outside the %dx%d image (X1 <= %d and Y1 <= %d)",
                 o->crop[0], o->crop[1], o->crop[2], o->crop[3], o->width, o->height, o->width, o->height);
        return -1;
    }
    if (o->min_spp && o->noise_threshold <= 0.0f) {
        snprintf(err, CANDELA_ERR_LEN, "--min-spp needs --noise-threshold (adaptive sampling)");
        return -1;
    }
    return 0;
}
