/* renderer/film.c: the film: per-pixel sums over the render, and their resolution into the
 * image (mean, variance of the mean, first-hit AOVs). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "checkpoint.h"
#include "integrator.h"

int film_alloc(Film *f, int w, int h) {
    size_t n = (size_t)w * (size_t)h;
    memset(f, 0, sizeof *f);
    f->width = w; f->height = h;
    f->sum = calloc(3 * n, sizeof(double));
    f->sum2 = calloc(3 * n, sizeof(double));
    f->albedo = calloc(3 * n, sizeof(double));
    f->normal = calloc(3 * n, sizeof(double));
    f->depth = calloc(n, sizeof(double));
    f->hits = calloc(n, sizeof(uint32_t));
    f->count = calloc(n, sizeof(uint32_t));
    if (!f->sum || !f->sum2 || !f->albedo || !f->normal || !f->depth || !f->hits || !f->count) {
        film_free(f);
        return -1;
    }
    return 0;
}

void film_free(Film *f) {
    free(f->sum); free(f->sum2); free(f->albedo); free(f->normal); free(f->depth); free(f->hits); free(f->count);
    free(f->recorder);
    free(f->sel_aov);
    free(f->stopped);
    memset(f, 0, sizeof *f);
}

static inline void add3(double *sum, vec3 v) { sum[0] += v.x; sum[1] += v.y; sum[2] += v.z; }

void film_add_paths(Film *f, const PathState *ps, uint32_t count) {
    for (uint32_t i = 0; i < count; ++i) {
        uint32_t px = ps->pixel[i];
        vec3 L = ps->radiance[i];
        if (!v3_is_finite(L)) L = v3s(0.0f); /* never reached in tests; keeps one bad path from poisoning a pixel */
        add3(f->sum + 3 * (size_t)px, L);
        f->sum2[3 * px] += (double)L.x * L.x;
        f->sum2[3 * px + 1] += (double)L.y * L.y;
        f->sum2[3 * px + 2] += (double)L.z * L.z;
        f->count[px]++;
        if (f->recorder) {
            vec3 d = ps->aov_recorder[i];
            if (v3_is_finite(d)) add3(f->recorder + 3 * (size_t)px, d);
        }
        if (isfinite(ps->aov_depth[i])) {
            add3(f->albedo + 3 * (size_t)px, ps->aov_albedo[i]);
            add3(f->normal + 3 * (size_t)px, ps->aov_normal[i]);
            f->depth[px] += ps->aov_depth[i];
            f->hits[px]++;
            if (f->sel_aov) {
                add3(f->sel_aov + 6 * (size_t)px, ps->aov_sel_point[i]);
                add3(f->sel_aov + 6 * (size_t)px + 3, ps->aov_sel_light[i]);
            }
        }
    }
}

int film_resolve(const Film *f, CandelaImage *img) {
    size_t n = (size_t)f->width * (size_t)f->height;
    memset(img, 0, sizeof *img);
    img->width = f->width; img->height = f->height;
    img->rgb = malloc(3 * n * sizeof(float));
    img->variance = malloc(3 * n * sizeof(float));
    img->albedo = malloc(3 * n * sizeof(float));
    img->normal = malloc(3 * n * sizeof(float));
    img->depth = malloc(n * sizeof(float));
    if (!img->rgb || !img->variance || !img->albedo || !img->normal || !img->depth) {
        candela_image_free(img);
        return -1;
    }
    for (size_t i = 0; i < n; ++i) {
        double cnt = f->count[i];
        for (int k = 0; k < 3; ++k) {
            double mean = cnt > 0 ? f->sum[3 * i + k] / cnt : 0.0;
            img->rgb[3 * i + k] = (float)mean;
            double var = cnt > 1 ? (f->sum2[3 * i + k] - cnt * mean * mean) / (cnt - 1.0) / cnt : 0.0;
            img->variance[3 * i + k] = (float)(var > 0.0 ? var : 0.0);
            img->albedo[3 * i + k] = f->hits[i] ? (float)(f->albedo[3 * i + k] / f->hits[i]) : 0.0f;
            img->normal[3 * i + k] = f->hits[i] ? (float)(f->normal[3 * i + k] / f->hits[i]) : 0.0f;
        }
        img->depth[i] = f->hits[i] ? (float)(f->depth[i] / f->hits[i]) : INFINITY;
    }
    if (f->recorder) {
        img->recorder_debug = malloc(3 * n * sizeof(float));
        if (!img->recorder_debug) { candela_image_free(img); return -1; }
        for (size_t i = 0; i < 3 * n; ++i)
            img->recorder_debug[i] = f->count[i / 3] ? (float)(f->recorder[i] / f->count[i / 3]) : 0.0f;
    }
    if (f->aov_spp) {
        img->spp = malloc(n * sizeof(float));
        if (!img->spp) { candela_image_free(img); return -1; }
        for (size_t i = 0; i < n; ++i) img->spp[i] = (float)f->count[i];
    }
    if (f->sel_aov) {
        img->selection_point = malloc(3 * n * sizeof(float));
        img->selection_light = malloc(3 * n * sizeof(float));
        if (!img->selection_point || !img->selection_light) { candela_image_free(img); return -1; }
        for (size_t i = 0; i < n; ++i)
            for (int k = 0; k < 3; ++k) {
                double h = f->hits[i];
                img->selection_point[3 * i + k] = h > 0 ? (float)(f->sel_aov[6 * i + k] / h) : 0.0f;
                img->selection_light[3 * i + k] = h > 0 ? (float)(f->sel_aov[6 * i + 3 + k] / h) : 0.0f;
            }
    }
    return 0;
}

/* Per-sample variance of each channel of pixel i (0 with fewer than 2 samples). */
static void pixel_sample_variance(const Film *f, size_t i, double var[3]) {
    double n = f->count[i];
    for (int k = 0; k < 3; ++k) {
        double mean = n > 0.0 ? f->sum[3 * i + k] / n : 0.0;
        double v = n > 1.0 ? (f->sum2[3 * i + k] - n * mean * mean) / (n - 1.0) : 0.0;
        var[k] = v > 0.0 ? v : 0.0;
    }
}

/* sum_c sqrt(var_c / n) / sqrt(sum_c mean_c + 1e-4) */
static double relative_error(const Film *f, size_t i, const double var[3]) {
    double n = f->count[i], se = 0.0, sum = 0.0;
    for (int k = 0; k < 3; ++k) {
        se += sqrt(var[k] / n);
        sum += f->sum[3 * i + k] / n;
    }
    return se / sqrt(fmax(sum, 0.0) + 1e-4);
}

double film_pixel_error(const Film *f, size_t i) {
    if (f->count[i] < 2) return INFINITY;
    int w = f->width, h = f->height, x = (int)(i % (size_t)w), y = (int)(i / (size_t)w);
    double own[3], pooled[3] = {0, 0, 0}, v[3];
    pixel_sample_variance(f, i, own);
    int m = 0;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            int nx = x + dx, ny = y + dy;
            if (nx < 0 || nx >= w || ny < 0 || ny >= h) continue;
            pixel_sample_variance(f, (size_t)ny * (size_t)w + (size_t)nx, v);
            for (int k = 0; k < 3; ++k) pooled[k] += v[k];
            ++m;
        }
    for (int k = 0; k < 3; ++k) pooled[k] /= m;
    return fmax(relative_error(f, i, own), relative_error(f, i, pooled));
}

uint32_t film_adaptive_update(Film *f, float threshold) {
    int w = f->width, h = f->height;
    /* 1: still sampling and noisy; 2: still sampling, converged; 0: stopped before */
    uint8_t *state = malloc((size_t)w * (size_t)h);
    if (!state) { /* keep sampling everywhere: the image is right, only slower */
        uint32_t active = 0;
        for (size_t i = 0; i < (size_t)w * (size_t)h; ++i) active += !f->stopped[i];
        return active;
    }
    for (size_t i = 0; i < (size_t)w * (size_t)h; ++i)
        state[i] = f->stopped[i] ? 0 : (film_pixel_error(f, i) >= threshold ? 1 : 2);
    uint32_t active = 0;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            size_t i = (size_t)y * (size_t)w + (size_t)x;
            if (state[i] == 0) continue;
            int noisy = 0;
            for (int dy = -1; dy <= 1 && !noisy; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    int nx = x + dx, ny = y + dy;
                    if (nx >= 0 && nx < w && ny >= 0 && ny < h && state[(size_t)ny * (size_t)w + (size_t)nx] == 1) {
                        noisy = 1;
                        break;
                    }
                }
            if (noisy) ++active;
            else f->stopped[i] = 1;
        }
    free(state);
    return active;
}

void candela_iteration_mean(const CandelaIterationInfo *info, float *rgb) {
    const Film *f = info->film;
    size_t n = (size_t)f->width * (size_t)f->height;
    for (size_t i = 0; i < n; ++i) { /* the same double division and rounding as film_resolve */
        double cnt = f->count[i];
        for (int k = 0; k < 3; ++k) rgb[3 * i + k] = (float)(cnt > 0 ? f->sum[3 * i + k] / cnt : 0.0);
    }
}

void candela_image_free(CandelaImage *img) {
    free(img->rgb); free(img->variance); free(img->albedo); free(img->normal); free(img->depth); free(img->recorder_debug);
    free(img->selection_point); free(img->selection_light); free(img->spp);
    memset(img, 0, sizeof *img);
}

/* ---------------------------------------------------------------- checkpoints */

#define FILM_TAG CKPT_TAG('F', 'I', 'L', 'M')
#define FILM_VERSION 1u

/* Every Film array: the sums of L and L^2, counts, AOV sums, the recorder AOV and adaptive
 * sampling's stopped pixels. */
static int32_t film_arrays(const Film *f) {
    return (f->recorder != NULL) | (f->sel_aov != NULL) << 1 | (f->stopped != NULL) << 2;
}

int film_save(const Film *f, FILE *out) {
    size_t n = (size_t)f->width * (size_t)f->height;
    int32_t head[3] = {f->width, f->height, film_arrays(f)};
    return ckpt_put_tag(out, FILM_TAG, FILM_VERSION) | ckpt_put(out, head, sizeof head) |
           ckpt_put(out, f->sum, 3 * n * sizeof(double)) | ckpt_put(out, f->sum2, 3 * n * sizeof(double)) |
           ckpt_put(out, f->albedo, 3 * n * sizeof(double)) | ckpt_put(out, f->normal, 3 * n * sizeof(double)) |
           ckpt_put(out, f->depth, n * sizeof(double)) | ckpt_put(out, f->hits, n * sizeof(uint32_t)) |
           ckpt_put(out, f->count, n * sizeof(uint32_t)) |
           (f->recorder ? ckpt_put(out, f->recorder, 3 * n * sizeof(double)) : 0) |
           (f->sel_aov ? ckpt_put(out, f->sel_aov, 6 * n * sizeof(double)) : 0) |
           (f->stopped ? ckpt_put(out, f->stopped, n) : 0);
}

int film_load(Film *f, FILE *in) {
    size_t n = (size_t)f->width * (size_t)f->height;
    int32_t head[3];
    if (ckpt_get_tag(in, FILM_TAG, FILM_VERSION) || ckpt_get(in, head, sizeof head)) return -1;
    if (head[0] != f->width || head[1] != f->height || head[2] != film_arrays(f)) return -1;
    return ckpt_get(in, f->sum, 3 * n * sizeof(double)) | ckpt_get(in, f->sum2, 3 * n * sizeof(double)) |
           ckpt_get(in, f->albedo, 3 * n * sizeof(double)) | ckpt_get(in, f->normal, 3 * n * sizeof(double)) |
           ckpt_get(in, f->depth, n * sizeof(double)) | ckpt_get(in, f->hits, n * sizeof(uint32_t)) |
           ckpt_get(in, f->count, n * sizeof(uint32_t)) |
           (f->recorder ? ckpt_get(in, f->recorder, 3 * n * sizeof(double)) : 0) |
           (f->sel_aov ? ckpt_get(in, f->sel_aov, 6 * n * sizeof(double)) : 0) |
           (f->stopped ? ckpt_get(in, f->stopped, n) : 0);
}

/* What a film file must hold to be merged or resumed (a forged or damaged file's checksum can
 * be right): every pixel counts the samples the file declares (so a merged count is the render's
 * spp, never 0 or wrapped), at most that many first hits, and every sum finite (sums of squares
 * and hit distances also >= 0). A pixel still sampling counts [done, most] (most > done: a
 * checkpoint of an interrupted iteration, part of whose paths are in); one adaptive sampling
 * stopped (f->stopped, 0 or 1) counts [1, done]; `declares` names the file in the message ("shard").
 * 0 ok, -1 with the first bad pixel in what. */
int film_check_counts(const Film *f, uint64_t done, uint64_t most, const char *declares, char *what, size_t len) {
    size_t n = (size_t)f->width * (size_t)f->height;
    for (size_t i = 0; i < n; ++i) {
        const int x = (int)(i % (size_t)f->width), y = (int)(i / (size_t)f->width);
        const int stopped = f->stopped && f->stopped[i];
        if (f->stopped && f->stopped[i] > 1) {
            snprintf(what, len, "pixel (%d, %d) has a stopped flag of %u", x, y, f->stopped[i]);
            return -1;
        }
        const uint64_t lo = stopped ? 1 : done, hi = stopped ? done : most;
        if (f->count[i] < lo || f->count[i] > hi) {
            if (lo == hi)
                snprintf(what, len, "pixel (%d, %d) counts %u samples, the %s declares %llu", x, y, f->count[i], declares,
                         (unsigned long long)lo);
            else
                snprintf(what, len, "pixel (%d, %d) counts %u samples, not %llu to %llu%s", x, y, f->count[i],
                         (unsigned long long)lo, (unsigned long long)hi, stopped ? " (stopped by adaptive sampling)" : "");
            return -1;
        }
        if (f->hits[i] > f->count[i]) {
            snprintf(what, len, "pixel (%d, %d) has %u first hits of %u samples", x, y, f->hits[i], f->count[i]);
            return -1;
        }
        int good = isfinite(f->depth[i]) && f->depth[i] >= 0.0;
        for (int k = 0; k < 3; ++k) {
            good &= isfinite(f->sum[3 * i + k]) && isfinite(f->sum2[3 * i + k]) && f->sum2[3 * i + k] >= 0.0;
            good &= isfinite(f->albedo[3 * i + k]) && isfinite(f->normal[3 * i + k]);
            if (f->recorder) good &= isfinite(f->recorder[3 * i + k]);
        }
        for (int k = 0; f->sel_aov && k < 6; ++k) good &= isfinite(f->sel_aov[6 * i + k]);
        if (!good) {
            snprintf(what, len, "pixel (%d, %d) holds a sum that is not a finite number (or a negative square or distance)", x, y);
            return -1;
        }
    }
    return 0;
}

int film_check(const Film *f, uint64_t samples, char *what, size_t len) {
    return film_check_counts(f, samples, samples, "shard", what, len);
}
