/* renderer/compare.c: `candela compare`, the equal-SPP comparison of light-selection
 * strategies.
 *
 * Renders the scene once per strategy at the same spp and seed, renders (or reuses) a
 * high-spp reference, and writes OUT/table.md, OUT/table.csv, OUT/<strategy>.exr and
 * OUT/<strategy>_error.png (false-colour relative error). Metrics per strategy:
 *   time        wall seconds of the whole render (load + build + iterations); with
 *               --timing-runs N every strategy is rendered N times, round-robin so slow
 *               spells of a shared machine hit all strategies alike, and the median is used
 *               (the repeats must give bit-identical images: renders are deterministic)
 *   peak memory peak resident set size during that render
 *   RMSE        sqrt(mean over pixels and channels of (x - ref)^2)
 *   relMSE      mean of (x - ref)^2 / (ref^2 + 0.01)
 *   TTUV        time-to-unit-variance = mean per-pixel variance of the estimate x time
 *               (the cache points paper's Table 3 measure: lower is better, independent of
 *               spp for an unbiased estimator at fixed cost per sample) */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "candela.h"
#include "io.h"

enum { COMPARE_MAX_STRATEGIES = 16, COMPARE_MAX_TIMING_RUNS = 15 };

typedef struct StrategyResult {
    const char *name;
    int skipped;
    const char *why;
    CandelaOptions opts;    /* what this strategy rendered with (for the timing repeats) */
    uint64_t image_hash;    /* of the first render's pixels: repeats must match it */
    int runs;
    double times[COMPARE_MAX_TIMING_RUNS], cp_times[COMPARE_MAX_TIMING_RUNS];
    double time, time_min, time_max, ttuv, rmse, relmse, mean_var, cp_time;
    size_t peak;
    uint32_t cp_count;
} StrategyResult;

/* FNV-1a over the pixel bytes: equal images, equal hashes (a repeat is compared with it). */
static uint64_t image_hash(const CandelaImage *img) {
    uint64_t h = 0xcbf29ce484222325ull;
    const unsigned char *b = (const unsigned char *)img->rgb;
    size_t n = (size_t)img->width * (size_t)img->height * 3 * sizeof(float);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 0x100000001b3ull;
    return h;
}

static double median(const double *v, int n) {
    double s[COMPARE_MAX_TIMING_RUNS];
    memcpy(s, v, (size_t)n * sizeof *s);
    for (int i = 1; i < n; ++i) /* insertion sort: n <= 15 */
        for (int j = i; j > 0 && s[j - 1] > s[j]; --j) { double t = s[j]; s[j] = s[j - 1]; s[j - 1] = t; }
    return n % 2 ? s[n / 2] : 0.5 * (s[n / 2 - 1] + s[n / 2]);
}

/* Blue (0) -> green -> yellow -> red (>= 1): a readable false-colour ramp for |error|. */
static void false_colour(float t, float rgb[3]) {
    t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
    const float stops[4][3] = {{0.05f, 0.05f, 0.5f}, {0.1f, 0.7f, 0.3f}, {0.95f, 0.9f, 0.1f}, {0.9f, 0.1f, 0.05f}};
    float x = t * 3.0f;
    int i = x >= 3.0f ? 2 : (int)x;
    float f = x - (float)i;
    for (int k = 0; k < 3; ++k) rgb[k] = stops[i][k] * (1.0f - f) + stops[i + 1][k] * f;
}

static int write_error_png(const char *path, const CandelaImage *img, const float *ref, char err[CANDELA_ERR_LEN]) {
    size_t n = (size_t)img->width * (size_t)img->height;
    float *rgb = malloc(3 * n * sizeof(float));
    if (!rgb) { snprintf(err, CANDELA_ERR_LEN, "%.400s: out of memory", path); return -1; }
    for (size_t i = 0; i < n; ++i) {
        double e = 0.0, r = 0.0;
        for (int k = 0; k < 3; ++k) {
            e += fabs((double)img->rgb[3 * i + k] - ref[3 * i + k]);
            r += ref[3 * i + k];
        }
        /* relative error, 0 .. 100% mapped over the ramp */
        false_colour((float)(e / (r + 0.03)), rgb + 3 * i);
    }
    char ioerr[IO_ERR_LEN];
    int rc = io_write_png(path, img->width, img->height, rgb, ioerr);
    free(rgb);
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
    return rc;
}

static int load_reference(const char *path, int w, int h, float **out, char err[CANDELA_ERR_LEN]) {
    const char *names[3] = {"R", "G", "B"};
    size_t n = (size_t)w * (size_t)h;
    float *ref = malloc(3 * n * sizeof(float));
    if (!ref) { snprintf(err, CANDELA_ERR_LEN, "%.400s: out of memory", path); return -1; }
    for (int k = 0; k < 3; ++k) {
        int rw, rh;
        float *ch = NULL;
        char ioerr[IO_ERR_LEN];
        if (io_read_exr_channel(path, names[k], &rw, &rh, &ch, ioerr) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
            free(ref);
            return -1;
        }
        if (rw != w || rh != h) {
            snprintf(err, CANDELA_ERR_LEN, "%s: reference is %dx%d, the comparison renders %dx%d", path, rw, rh, w, h);
            free(ch); free(ref);
            return -1;
        }
        for (size_t i = 0; i < n; ++i) ref[3 * i + k] = ch[i];
        free(ch);
    }
    *out = ref;
    return 0;
}

/* A strategy name: a light sampler, or cachepoints with -linear, -cut and/or -novis suffixes. */
static int parse_strategy(const char *tok, CandelaLightSampler *s, CandelaOptions *o) {
    if (strncmp(tok, "cachepoints", 11) != 0) return candela_light_sampler_parse(tok, s);
    *s = CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
    for (const char *t = tok + 11; *t;) {
        if (strncmp(t, "-linear", 7) == 0) { o->cachepoint_build_linear = 1; t += 7; }
        else if (strncmp(t, "-cut", 4) == 0) { o->cachepoint_build_linear = 0; t += 4; }
        else if (strncmp(t, "-novis", 6) == 0) { o->cachepoint_no_visibility = 1; t += 6; }
        else return -1;
    }
    return 0;
}

int candela_compare(const CandelaOptions *base, const CandelaCompareOptions *c, char err[CANDELA_ERR_LEN]) {
    /* every strategy name is checked before anything renders */
    {
        char list[512];
        int n_strategies = 0;
        snprintf(list, sizeof list, "%s", c->strategies);
        for (char *save = NULL, *tok = strtok_r(list, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
            CandelaLightSampler s;
            CandelaOptions check = *base;
            if (parse_strategy(tok, &s, &check) != 0) {
                snprintf(err, CANDELA_ERR_LEN, "unknown strategy '%s' in --strategies", tok);
                return -1;
            }
            ++n_strategies;
        }
        if (n_strategies == 0 || n_strategies > COMPARE_MAX_STRATEGIES) {
            snprintf(err, CANDELA_ERR_LEN, "--strategies: give 1 to %d strategies", COMPARE_MAX_STRATEGIES);
            return -1;
        }
    }
    if (mkdir(c->out_dir, 0777) != 0 && errno != EEXIST) {
        snprintf(err, CANDELA_ERR_LEN, "%s: cannot create the output folder: %s", c->out_dir, strerror(errno));
        return -1;
    }
    char path[4096];
    CandelaOptions o = *base;
    o.quiet = 1;
    float *ref = NULL;
    int width = 0, height = 0;
    double ref_time = 0.0;

    /* 1. reference: reuse an EXR, or render with the power sampler at reference_spp */
    if (c->reference_path) {
        /* the resolution must match: render one sample to learn it cheaply */
        CandelaOptions probe = o;
        probe.spp = 1;
        CandelaImage img;
        if (candela_render(&probe, &img, NULL, NULL, err) != 0) return -1;
        width = img.width; height = img.height;
        candela_image_free(&img);
        if (load_reference(c->reference_path, width, height, &ref, err) != 0) return -1;
    } else {
        CandelaOptions ro = o;
        ro.spp = c->reference_spp > 0 ? c->reference_spp : 16 * base->spp;
        ro.seed = base->seed + 0x5eed;  /* independent of the compared renders */
        ro.light_sampler = CANDELA_LIGHT_SAMPLER_TREE; /* the best general-purpose sampler here */
        CandelaImage img;
        CandelaStats st;
        if (!base->quiet) fprintf(stderr, "candela compare: reference, %d spp\n", ro.spp);
        if (candela_render(&ro, &img, &st, NULL, err) != 0) return -1;
        ref_time = st.time_total;
        width = img.width; height = img.height;
        snprintf(path, sizeof path, "%s/reference.exr", c->out_dir);
        if (candela_write_outputs(&img, path, NULL, err) != 0) { candela_image_free(&img); return -1; }
        size_t n = (size_t)width * (size_t)height;
        ref = malloc(3 * n * sizeof(float));
        if (!ref) { candela_image_free(&img); snprintf(err, CANDELA_ERR_LEN, "out of memory"); return -1; }
        memcpy(ref, img.rgb, 3 * n * sizeof(float));
        candela_image_free(&img);
    }
    size_t n = (size_t)width * (size_t)height;

    /* 2. every strategy at the same spp and seed */
    StrategyResult results[COMPARE_MAX_STRATEGIES];
    int count = 0;
    char list[512];
    snprintf(list, sizeof list, "%s", c->strategies);
    for (char *save = NULL, *tok = strtok_r(list, ",", &save); tok && count < COMPARE_MAX_STRATEGIES; tok = strtok_r(NULL, ",", &save)) {
        StrategyResult *r = &results[count];
        memset(r, 0, sizeof *r);
        r->name = strdup(tok);
        ++count;
        CandelaLightSampler s;
        o.cachepoint_no_visibility = base->cachepoint_no_visibility;
        o.cachepoint_build_linear = base->cachepoint_build_linear;
        if (parse_strategy(tok, &s, &o) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "unknown strategy '%s' in --strategies", tok);
            for (int i = 0; i < count; ++i) free((char *)results[i].name);
            free(ref);
            return -1;
        }
        o.light_sampler = s;
        if (s == CANDELA_LIGHT_SAMPLER_OPTIMAL && c->optimal_max_lights > 0) {
            CandelaOptions probe = o;
            probe.spp = 1;
            probe.width = probe.height = 1;
            probe.light_sampler = CANDELA_LIGHT_SAMPLER_POWER;
            CandelaImage img;
            CandelaStats st;
            if (candela_render(&probe, &img, &st, NULL, err) == 0) {
                candela_image_free(&img);
                if (st.num_lights > (uint32_t)c->optimal_max_lights) {
                    r->skipped = 1;
                    r->why = "skipped: O(lights) per vertex is too slow here (--optimal-max-lights)";
                    continue;
                }
            }
        }
        if (!base->quiet) fprintf(stderr, "candela compare: %s, %d spp\n", tok, o.spp);
        CandelaImage img;
        CandelaStats st;
        if (candela_render(&o, &img, &st, NULL, err) != 0) {
            for (int i = 0; i < count; ++i) free((char *)results[i].name);
            free(ref);
            return -1;
        }
        double se = 0.0, rel = 0.0, var = 0.0;
        for (size_t i = 0; i < 3 * n; ++i) {
            double d = (double)img.rgb[i] - ref[i];
            se += d * d;
            rel += d * d / ((double)ref[i] * ref[i] + 0.01);
            var += img.variance[i];
        }
        r->opts = o;
        r->image_hash = image_hash(&img);
        r->runs = 1;
        r->times[0] = st.time_total;
        r->cp_times[0] = st.time_cachepoints;
        r->time = st.time_total;
        r->cp_time = st.time_cachepoints;
        r->cp_count = st.num_cachepoints;
        r->peak = st.peak_memory_bytes;
        r->rmse = sqrt(se / (3.0 * (double)n));
        r->relmse = rel / (3.0 * (double)n);
        r->mean_var = var / (3.0 * (double)n);
        r->ttuv = r->mean_var * r->time;
        snprintf(path, sizeof path, "%s/%s.exr", c->out_dir, tok);
        int rc = candela_write_outputs(&img, path, NULL, err);
        snprintf(path, sizeof path, "%s/%s_error.png", c->out_dir, tok);
        if (rc == 0) rc = write_error_png(path, &img, ref, err);
        candela_image_free(&img);
        if (rc != 0) {
            for (int i = 0; i < count; ++i) free((char *)results[i].name);
            free(ref);
            return -1;
        }
    }
    free(ref);

    /* 3. timing repeats, round-robin; the median time (and build time) is reported */
    int runs = c->timing_runs < 1 ? 1 : c->timing_runs > COMPARE_MAX_TIMING_RUNS ? COMPARE_MAX_TIMING_RUNS : c->timing_runs;
    for (int run = 1; run < runs; ++run) {
        for (int i = 0; i < count; ++i) {
            StrategyResult *r = &results[i];
            if (r->skipped) continue;
            if (!base->quiet) fprintf(stderr, "candela compare: %s, timing run %d of %d\n", r->name, run + 1, runs);
            CandelaImage img;
            CandelaStats st;
            int rc = candela_render(&r->opts, &img, &st, NULL, err);
            if (rc == 0) {
                uint64_t hash = image_hash(&img);
                candela_image_free(&img);
                if (hash != r->image_hash) {
                    snprintf(err, CANDELA_ERR_LEN,
                             "%s: strategy %s gave a different image on a repeated render (not deterministic)",
                             base->scene_path, r->name);
                    rc = -1;
                }
            }
            if (rc != 0) {
                for (int j = 0; j < count; ++j) free((char *)results[j].name);
                return -1;
            }
            r->times[r->runs] = st.time_total;
            r->cp_times[r->runs] = st.time_cachepoints;
            ++r->runs;
            if (st.peak_memory_bytes < r->peak) r->peak = st.peak_memory_bytes; /* least disturbed run */
        }
    }
    for (int i = 0; i < count; ++i) {
        StrategyResult *r = &results[i];
        if (r->skipped) continue;
        r->time = median(r->times, r->runs);
        r->cp_time = median(r->cp_times, r->runs);
        r->time_min = r->time_max = r->times[0];
        for (int k = 1; k < r->runs; ++k) {
            if (r->times[k] < r->time_min) r->time_min = r->times[k];
            if (r->times[k] > r->time_max) r->time_max = r->times[k];
        }
        r->ttuv = r->mean_var * r->time;
    }

    /* 4. tables; TTUV also relative to the first strategy that ran */
    double ttuv0 = 0.0;
    for (int i = 0; i < count; ++i) if (!results[i].skipped) { ttuv0 = results[i].ttuv; break; }
    /* written under temporary names and renamed when complete */
    char md_tmp[4200], csv_tmp[4200], md_path[4200], csv_path[4200];
    snprintf(md_path, sizeof md_path, "%s/table.md", c->out_dir);
    snprintf(csv_path, sizeof csv_path, "%s/table.csv", c->out_dir);
    snprintf(md_tmp, sizeof md_tmp, "%s/table.md.tmp-%ld", c->out_dir, (long)getpid());
    snprintf(csv_tmp, sizeof csv_tmp, "%s/table.csv.tmp-%ld", c->out_dir, (long)getpid());
    /* (two files at once, so not registered with io_temp_begin, which would do this) */
    io_remove_stale_temps(md_path);
    io_remove_stale_temps(csv_path);
    FILE *md = fopen(md_tmp, "w");
    FILE *csv = fopen(csv_tmp, "w");
    if (!md || !csv) {
        if (md) { fclose(md); remove(md_tmp); }
        if (csv) { fclose(csv); remove(csv_tmp); }
        for (int i = 0; i < count; ++i) free((char *)results[i].name);
        snprintf(err, CANDELA_ERR_LEN, "%s: cannot write the tables", c->out_dir);
        return -1;
    }
    fprintf(md, "# %s, %dx%d, %d spp, seed %llu\n\n", base->scene_path, width, height, base->spp,
            (unsigned long long)base->seed);
    if (runs > 1)
        fprintf(md, "Times: median of %d renders per strategy, round-robin (min-max in brackets); TTUV uses the median.\n\n",
                runs);
    if (c->reference_path) fprintf(md, "Reference: %s\n\n", c->reference_path);
    else fprintf(md, "Reference: tree sampler, %d spp (%.2f s)\n\n",
                 c->reference_spp > 0 ? c->reference_spp : 16 * base->spp, ref_time);
    fprintf(md, "| strategy | time s | cache point build s | cache points | peak MiB | RMSE | relMSE | mean variance | TTUV | TTUV / first |\n");
    fprintf(md, "|---|---|---|---|---|---|---|---|---|---|\n");
    fprintf(csv, "strategy,time_s,cachepoint_build_s,cache_points,peak_mib,rmse,relmse,mean_variance,ttuv,ttuv_ratio,"
                 "time_min_s,time_max_s,timing_runs\n");
    for (int i = 0; i < count; ++i) {
        const StrategyResult *r = &results[i];
        if (r->skipped) {
            fprintf(md, "| %s | %s | | | | | | | | |\n", r->name, r->why);
            fprintf(csv, "%s,skipped,,,,,,,,,,,\n", r->name);
            continue;
        }
        char cpt[32] = "-", cpn[32] = "-";
        if (r->cp_count) {
            snprintf(cpt, sizeof cpt, "%.3f", r->cp_time);
            snprintf(cpn, sizeof cpn, "%u", r->cp_count);
        }
        char tm[64];
        if (r->runs > 1) snprintf(tm, sizeof tm, "%.3f (%.3f-%.3f)", r->time, r->time_min, r->time_max);
        else snprintf(tm, sizeof tm, "%.3f", r->time);
        fprintf(md, "| %s | %s | %s | %s | %.1f | %.5g | %.5g | %.5g | %.5g | %.3f |\n", r->name, tm, cpt, cpn,
                (double)r->peak / 1048576.0, r->rmse, r->relmse, r->mean_var, r->ttuv, ttuv0 > 0 ? r->ttuv / ttuv0 : 0.0);
        fprintf(csv, "%s,%.6f,%s,%s,%.3f,%.8g,%.8g,%.8g,%.8g,%.6f,%.6f,%.6f,%d\n", r->name, r->time,
                r->cp_count ? cpt : "", r->cp_count ? cpn : "", (double)r->peak / 1048576.0, r->rmse, r->relmse,
                r->mean_var, r->ttuv, ttuv0 > 0 ? r->ttuv / ttuv0 : 0.0, r->time_min, r->time_max, r->runs);
    }
    int werr = ferror(md) | ferror(csv);
    werr |= fclose(md) != 0;
    werr |= fclose(csv) != 0;
    if (werr || rename(md_tmp, md_path) != 0 || rename(csv_tmp, csv_path) != 0) {
        remove(md_tmp);
        remove(csv_tmp);
        for (int i = 0; i < count; ++i) free((char *)results[i].name);
        snprintf(err, CANDELA_ERR_LEN, "%s: cannot write the tables", c->out_dir);
        return -1;
    }
    FILE *f = fopen(md_path, "r");
    if (f) {
        char line[1024];
        while (fgets(line, sizeof line, f)) fputs(line, stdout);
        fclose(f);
    }
    for (int i = 0; i < count; ++i) free((char *)results[i].name);
    return 0;
}
