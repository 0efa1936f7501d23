/* renderer/app/output.c: EXR/PNG output and the statistics JSON. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include <math.h>

#include "candela.h"
#include "io.h"

float candela_srgb_encode(float x) {
    if (!(x > 0.0f)) return 0.0f;
    if (x >= 1.0f) return 1.0f;
    return x <= 0.0031308f ? 12.92f * x : 1.055f * powf(x, 1.0f / 2.4f) - 0.055f;
}

void candela_cachepoint_png_paths(const char *png_path, char *point_png, char *light_png, size_t len) {
    size_t base = strlen(png_path);
    if (base >= 4 && strcasecmp(png_path + base - 4, ".png") == 0) base -= 4; /* x.PNG too */
    snprintf(point_png, len, "%.*s.cachepoint.png", (int)base, png_path);
    snprintf(light_png, len, "%.*s.cachepoint_light.png", (int)base, png_path);
}

int candela_write_outputs(const CandelaImage *img, const char *exr_path, const char *png_path,
                          char err[CANDELA_ERR_LEN]) {
    return candela_write_outputs_provenance(img, exr_path, png_path, NULL, err);
}

int candela_write_outputs_provenance(const CandelaImage *img, const char *exr_path, const char *png_path,
                                     const CandelaProvenance *provenance, char err[CANDELA_ERR_LEN]) {
    IoExrAttribute attrs[CANDELA_PROVENANCE_MAX];
    int nattrs = provenance ? provenance->count : 0;
    for (int k = 0; k < nattrs; ++k) attrs[k] = (IoExrAttribute){provenance->attrs[k].name, provenance->attrs[k].value};
    size_t n = (size_t)img->width * (size_t)img->height;
    int nch = img->recorder_debug ? 17 : 14;
    int ncp = img->selection_point ? 6 : 0; /* cachepoint.RGB, cachepoint_light.RGB after the others */
    int nspp = img->spp ? 1 : 0;            /* spp last */
    float *planes = malloc((size_t)(nch + ncp + nspp) * n * sizeof(float));
    if (!planes) { snprintf(err, CANDELA_ERR_LEN, "%s: out of memory", exr_path); return -1; }
    /* planar copies: R G B A albedo.RGB N.XYZ Z variance.RGB */
    for (size_t i = 0; i < n; ++i) {
        for (int k = 0; k < 3; ++k) {
            planes[k * n + i] = img->rgb[3 * i + k];
            planes[(4 + k) * n + i] = img->albedo[3 * i + k];
            planes[(7 + k) * n + i] = img->normal[3 * i + k];
            planes[(11 + k) * n + i] = img->variance[3 * i + k];
        }
        planes[3 * n + i] = 1.0f;
        planes[10 * n + i] = img->depth[i];
        if (img->recorder_debug)
            for (int k = 0; k < 3; ++k) planes[(14 + k) * n + i] = img->recorder_debug[3 * i + k];
        for (int k = 0; k < 3 && ncp; ++k) {
            planes[(nch + k) * n + i] = img->selection_point[3 * i + k];
            planes[(nch + 3 + k) * n + i] = img->selection_light[3 * i + k];
        }
        if (nspp) planes[(size_t)(nch + ncp) * n + i] = img->spp[i];
    }
    IoExrChannel ch[24] = {
        {"R", planes}, {"G", planes + n}, {"B", planes + 2 * n}, {"A", planes + 3 * n},
        {"albedo.R", planes + 4 * n}, {"albedo.G", planes + 5 * n}, {"albedo.B", planes + 6 * n},
        {"N.X", planes + 7 * n}, {"N.Y", planes + 8 * n}, {"N.Z", planes + 9 * n},
        {"Z", planes + 10 * n},
        {"variance.R", planes + 11 * n}, {"variance.G", planes + 12 * n}, {"variance.B", planes + 13 * n},
        {"recorder_debug.R", planes + 14 * n}, {"recorder_debug.G", planes + 15 * n}, {"recorder_debug.B", planes + 16 * n},
    };
    static const char *const cp_names[6] = {"cachepoint.R", "cachepoint.G", "cachepoint.B",
                                            "cachepoint_light.R", "cachepoint_light.G", "cachepoint_light.B"};
    for (int k = 0; k < ncp; ++k) ch[nch + k] = (IoExrChannel){cp_names[k], planes + (size_t)(nch + k) * n};
    if (nspp) ch[nch + ncp] = (IoExrChannel){"spp", planes + (size_t)(nch + ncp) * n};
    char ioerr[IO_ERR_LEN];
    int rc = io_write_exr(exr_path, img->width, img->height, ch, nch + ncp + nspp, nattrs ? attrs : NULL, nattrs, ioerr);
    free(planes);
    if (rc != 0) { snprintf(err, CANDELA_ERR_LEN, "%s", ioerr); return -1; }
    if (png_path) {
        float *rgb = malloc(3 * n * sizeof(float));
        if (!rgb) { snprintf(err, CANDELA_ERR_LEN, "%s: out of memory", png_path); return -1; }
        /* preview: linear radiance clipped to [0,1] and sRGB-encoded (Blender's "Standard") */
        for (size_t i = 0; i < 3 * n; ++i) rgb[i] = candela_srgb_encode(img->rgb[i]);
        rc = io_write_png(png_path, img->width, img->height, rgb, nattrs ? attrs : NULL, nattrs, ioerr);
        if (rc == 0 && img->selection_point) { /* the false colours as they are (no transfer curve) */
            char point_png[IO_PATH_MAX], light_png[IO_PATH_MAX];
            candela_cachepoint_png_paths(png_path, point_png, light_png, sizeof point_png);
            rc = io_write_png(point_png, img->width, img->height, img->selection_point, nattrs ? attrs : NULL, nattrs, ioerr);
            if (rc == 0) rc = io_write_png(light_png, img->width, img->height, img->selection_light, nattrs ? attrs : NULL, nattrs, ioerr);
        }
        free(rgb);
        if (rc != 0) { snprintf(err, CANDELA_ERR_LEN, "%s", ioerr); return -1; }
    }
    return 0;
}

void candela_json_string(FILE *f, const char *s) {
    char *q = io_json_quote(s); /* nlohmann/json's escaping (io/variants.cpp) */
    if (q) fputs(q, f);
    else fputs("null", f); /* out of memory: still valid JSON */
    free(q);
}

/* The statistics object, pretty-printed (two-space indentation, a member per line). */
static void stats_json(FILE *f, const CandelaOptions *o, const CandelaStats *s, const CandelaProvenance *prov) {
    uint64_t rays = s->rays_camera + s->rays_bounce + s->rays_shadow;
    double render = candela_stats_render_seconds(s);
    fputs("{\n  \"scene\": ", f);
    candela_json_string(f, o->scene_path);
    fprintf(f, ",\n  \"spp\": %d,\n  \"seed\": %llu,\n  \"max_depth\": %d,\n", o->spp, (unsigned long long)o->seed,
            o->max_depth);
    fprintf(f, "  \"sampler\": \"%s\",\n", candela_sampler_name(o->sampler));
    /* --crop: the box rendered, half-open, and the full image it is part of (the resolved --res) */
    if (o->crop[2] > 0)
        fprintf(f, "  \"crop\": {\"x0\": %d, \"y0\": %d, \"x1\": %d, \"y1\": %d, \"width\": %d, \"height\": %d, "
                   "\"image_width\": %d, \"image_height\": %d},\n",
                o->crop[0], o->crop[1], o->crop[2], o->crop[3], o->crop[2] - o->crop[0], o->crop[3] - o->crop[1],
                s->image_width, s->image_height);
    fprintf(f, "  \"spp_done\": %d,\n  \"spp_dropped\": %d,\n  \"spp_min\": %d,\n  \"spp_mean\": %.4f,\n  \"spp_histogram\": {",
            s->spp_done, s->spp_dropped, s->spp_min, s->spp_mean);
    for (int k = 0, first = 1; k < 21; ++k)
        if (s->spp_histogram[k]) {
            fprintf(f, "%s\"%d-%d\": %u", first ? "" : ", ", 1 << k, (2 << k) - 1, s->spp_histogram[k]);
            first = 0;
        }
    fprintf(f, "},\n");
    if (o->noise_threshold > 0.0f)
        fprintf(f, "  \"adaptive\": {\"noise_threshold\": %g, \"min_spp\": %d, \"pixels_still_sampling\": %u},\n",
                (double)o->noise_threshold, o->min_spp > 0 ? o->min_spp : CANDELA_DEFAULT_MIN_SPP, s->adaptive_active_pixels);
    if (o->time_limit > 0.0)
        fprintf(f, "  \"time_limit\": {\"seconds\": %g, \"stopped\": %s},\n", o->time_limit,
                s->time_limited ? "true" : "false");
    if (o->clamp_direct > 0.0f || o->clamp_indirect > 0.0f)
        fprintf(f, "  \"clamp\": {\"direct\": %g, \"indirect\": %g},\n", (double)o->clamp_direct,
                (double)o->clamp_indirect);
    fprintf(f, "  \"light_sampler\": \"%s\",\n", candela_light_sampler_name(o->light_sampler));
    fprintf(f, "  \"light_sampler_used\": \"%s\",\n", candela_light_sampler_name(s->light_sampler_used));
    /* wall seconds: load + build + the stages + other = total (candela.h) */
    fprintf(f, "  \"time_seconds\": {\"load\": %.6f, \"build\": %.6f, \"generate\": %.6f, \"sort\": %.6f, "
               "\"trace\": %.6f, \"medium\": %.6f, \"shade\": %.6f, \"shadow\": %.6f, \"learn\": %.6f, \"film\": %.6f, "
               "\"barrier\": %.6f, \"other\": %.6f, \"total\": %.6f},\n",
            s->time_load, s->time_build, s->time_generate, s->time_sort, s->time_trace, s->time_medium, s->time_shade,
            s->time_shadow, s->time_learn, s->time_film, s->time_barrier, candela_stats_other_seconds(s), s->time_total);
    /* the phases from file to first image: wall seconds, the peak memory by the phase's end and
     * the resident memory at its end (candela.h) */
    fputs("  \"phases\": {", f);
    for (int k = 0; k < CANDELA_PHASES; ++k)
        fprintf(f, "%s\"%s\": {\"seconds\": %.6f, \"peak_bytes\": %zu, \"rss_bytes\": %zu}", k ? ", " : "",
                candela_phase_name(k), s->phase_seconds[k], s->phase_peak_bytes[k], s->phase_rss_bytes[k]);
    fputs("},\n", f);
    /* the per-thread detail: each stage's seconds in a thread, averaged over a batch's threads */
    fprintf(f, "  \"stage_thread_seconds\": {\"threads\": %d, \"generate\": %.6f, \"sort\": %.6f, \"trace\": %.6f, "
               "\"medium\": %.6f, \"shade\": %.6f, \"shadow\": %.6f},\n",
            s->stage_threads, s->stage_thread_seconds[0], s->stage_thread_seconds[1], s->stage_thread_seconds[2],
            s->stage_thread_seconds[3], s->stage_thread_seconds[4], s->stage_thread_seconds[5]);
    fprintf(f, "  \"rays\": {\"camera\": %llu, \"bounce\": %llu, \"shadow\": %llu, \"total\": %llu},\n",
            (unsigned long long)s->rays_camera, (unsigned long long)s->rays_bounce,
            (unsigned long long)s->rays_shadow, (unsigned long long)rays);
    fprintf(f, "  \"rays_per_second\": %.1f,\n", render > 0 ? (double)rays / render : 0.0);
    fprintf(f, "  \"iterations\": %d,\n  \"paths\": %llu,\n", s->iterations, (unsigned long long)s->paths);
    fprintf(f, "  \"triangles\": %u,\n  \"lights\": %u,\n  \"instances\": %u,\n", s->num_triangles, s->num_lights,
            s->num_instances);
    fprintf(f, "  \"textures\": {\"count\": %u, \"count_8bit\": %u, \"bytes\": %llu},\n", s->num_textures,
            s->num_textures_8bit, (unsigned long long)s->texture_bytes);
    fprintf(f,
            "  \"cachepoints\": {\"build\": \"%s\", \"build_seconds\": %.6f, \"build_cpu_seconds\": %.6f, \"candidates\": %u, \"points\": %u, "
            "\"bytes\": %zu, \"mean_near\": %.3f, \"mean_far\": %.3f, \"mean_clusters\": %.3f, \"inserted\": %u, "
            "\"insertion_seconds\": %.6f, \"insertion_cpu_seconds\": %.6f},\n",
            o->cachepoint_build_linear ? "linear" : "cut", s->time_cachepoints, s->cpu_cachepoints, s->cachepoint_candidates,
            s->num_cachepoints, s->cachepoint_bytes, s->cachepoint_mean_near, s->cachepoint_mean_far,
            s->cachepoint_mean_clusters, s->cachepoints_inserted, s->time_cachepoint_insertion,
            s->cpu_cachepoint_insertion);
    fprintf(f, "  \"volumes\": {\"count\": %u, \"collisions\": %llu, \"capped_walks\": %llu, \"bytes\": %llu},\n",
            s->num_volumes, (unsigned long long)s->volume_collisions, (unsigned long long)s->volume_capped_walks,
            (unsigned long long)s->volume_bytes);
    fprintf(f,
            "  \"recorder\": {\"peak_bytes\": %zu, \"bound_bytes\": %zu, \"peak_vertices\": %u, \"vertices\": %llu, "
            "\"samples\": %llu, \"refused\": %llu, \"paths\": %llu, \"path_skip\": %.4f},\n",
            s->recorder_peak_bytes, s->recorder_bound_bytes, s->recorder_peak_vertices,
            (unsigned long long)s->recorder_vertices, (unsigned long long)s->recorder_samples,
            (unsigned long long)s->recorder_refused, (unsigned long long)s->recorder_paths, s->recorder_path_skip);
    fprintf(f,
            "  \"guiding\": {\"mode\": \"%s\", \"updates\": %d, \"samples\": %llu, \"leaves\": %u, \"bytes\": %zu, "
            "\"train_seconds\": %.6f",
            candela_guiding_name(o->guiding), s->guide_updates,
            (unsigned long long)s->guide_samples, s->guide_leaves, s->guide_bytes, s->guide_train_seconds);
    if (s->guide_updates && s->guide_share_per_leaf) {
        fprintf(f, ", \"bsdf_share_leaves\": {");
        for (int j = 0; j < CANDELA_GUIDE_SHARES; ++j)
            fprintf(f, "%s\"%g\": %u", j ? ", " : "", (double)s->guide_share_value[j], s->guide_share_leaves[j]);
        fprintf(f, "}");
    }
    if (o->guiding == CANDELA_GUIDING_AUTO)
        fprintf(f, ", \"auto\": \"%s\", \"auto_predicted_ttuv_ratio\": %.4f, \"auto_indirect_share\": %.4f",
                s->guide_auto == 1 ? "on" : s->guide_auto == 0 ? "off" : "undecided", (double)s->guide_auto_ratio,
                (double)s->guide_auto_indirect);
    fprintf(f, "},\n");
    if (prov && prov->count) {
        fputs("  \"provenance\": {", f);
        for (int k = 0; k < prov->count; ++k) {
            fputs(k ? ", " : "", f);
            candela_json_string(f, prov->attrs[k].name);
            fputs(": ", f);
            /* the options are a JSON object already (one line) */
            if (strcmp(prov->attrs[k].name, "candela:options") == 0) fputs(prov->attrs[k].value, f);
            else candela_json_string(f, prov->attrs[k].value);
        }
        fputs("},\n", f);
    }
    fprintf(f, "  \"peak_memory_bytes\": %zu\n}\n", s->peak_memory_bytes);
}

int candela_write_stats_json(const char *path, const CandelaOptions *o, const CandelaStats *s,
                             const CandelaProvenance *provenance, char err[CANDELA_ERR_LEN]) {
    /* through io's atomic writer: PATH.tmp-PID, checked, synced, renamed (io.h) */
    IoAtomicFile af;
    char ioerr[IO_ERR_LEN];
    int rc = io_atomic_begin(&af, path, "w", ioerr);
    if (rc == 0) {
        stats_json(af.f, o, s, provenance);
        rc = io_atomic_commit(&af, ioerr);
    }
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
    return rc ? -1 : 0;
}

int candela_stats_json_line(const CandelaOptions *o, const CandelaStats *s, char **json) {
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    if (!f) return -1;
    stats_json(f, o, s, NULL);
    if (fclose(f) != 0) {
        free(buf);
        return -1;
    }
    /* one line: drop each newline and the indentation after it (strings are escaped, so
     * every raw newline is layout) */
    size_t w = 0;
    for (size_t r = 0; r < len; ++r) {
        if (buf[r] == '\n') {
            while (r + 1 < len && buf[r + 1] == ' ') ++r;
            continue;
        }
        buf[w++] = buf[r];
    }
    buf[w] = 0;
    *json = buf;
    return 0;
}
