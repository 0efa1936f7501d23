/* renderer/integrator/film.c: the film: per-pixel sums over the render, and their resolution into the
 * image (mean, variance of the mean, first-hit AOVs). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ckpt_io.h"
#include "integrator.h"
#include "film.h"

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
    free(f->target);
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

int film_drop(Film *f) {
    size_t n = (size_t)f->width * (size_t)f->height;
    for (size_t i = 1; i < n; ++i)
        if (f->count[i] != f->count[0]) return -1;
    uint32_t held = n ? f->count[0] : 0;
    memset(f->sum, 0, 3 * n * sizeof *f->sum);
    memset(f->sum2, 0, 3 * n * sizeof *f->sum2);
    memset(f->albedo, 0, 3 * n * sizeof *f->albedo);
    memset(f->normal, 0, 3 * n * sizeof *f->normal);
    memset(f->depth, 0, n * sizeof *f->depth);
    memset(f->hits, 0, n * sizeof *f->hits);
    memset(f->count, 0, n * sizeof *f->count);
    if (f->recorder) memset(f->recorder, 0, 3 * n * sizeof *f->recorder);
    if (f->sel_aov) memset(f->sel_aov, 0, 6 * n * sizeof *f->sel_aov);
    f->dropped += held;
    return 0;
}

int film_resolve(const Film *f, CandelaImage *img) {
    size_t n = (size_t)f->width * (size_t)f->height;
    memset(img, 0, sizeof *img);
    img->width = f->width; img->height = f->height;
    img->full_width = f->width; img->full_height = f->height; /* the render says where a crop lies */
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

/* ---------------------------------------------------------------- adaptive sampling
 *
 * The rule (renderer/README.md, --noise-threshold): every pixel takes the pilot, the samples of
 * the first barrier at or past --min-spp (K samples, the same K for every pixel: none has
 * stopped before). At that barrier each pixel gets a fixed target count
 *
 *   n_p = clamp(ceil(4 sigma_p / (T mu_p)), K, 2^30)      (the render caps it at --spp)
 *
 * with sigma_p^2 the per-sample variance (summed over channels) pooled over the pilots of the
 * pixels in a square window around p (adaptive_radius), p itself left out, and mu_p the mean
 * over channels of every other pixel's pilot mean (the image's mean without p; with --crop the
 * film, hence the image here, is the crop, while the window keeps the full image's scale:
 * Film.window_side). The pixel then
 * stops at the first barrier where its count reaches n_p (the schedule's barriers: 16, 32, 64,
 * then every 64 unguided). Targets never change after the pilot: checkpoints carry them
 * (Film.target), and a resumed render stops the same pixels at the same barriers.
 *
 * Why n proportional to sigma: one more sample lowers a pixel's expected squared error by about
 * sigma^2 / n^2; stopping all pixels at the same such value (sigma / n = T mu / 4) is the
 * allocation of least summed squared error for the samples spent (Lagrange). Cycles' rule, which
 * stops at equal error (n proportional to sigma^2), has, at the same budget, exactly uniform
 * sampling's MSE. T keeps the scale of ea27fd5: a pixel's standard error relative to the image's
 * mean, times sqrt(16 / n), below T.
 *
 * Why nothing of p's own samples: a rule that reads a pixel's own samples stops it early when
 * those samples happen to be low (in a heavy-tailed interior a pixel that has not met a rare
 * bright path has a low mean and a low variance), and that is a bias: ea27fd5 darkened images
 * 6-13 %. Here n_p is a function of the other pixels' pilot samples alone. Every pixel's samples
 * are drawn from its own random numbers (a function of seed, pixel and sample index: sequence.h),
 * so for a fixed scene and fixed light sampling n_p is independent of p's samples x_1, x_2, ...,
 * each of which has expectation the pixel's value m_p; hence
 *   E[ (1/n_p) sum_{k <= n_p} x_k | n_p ] = m_p,   and E[estimate] = m_p:
 * every pixel, and the image, is unbiased whatever the allocation (a poor allocation costs
 * variance, never bias). Second-order caveat: what a render learns as it goes (the light
 * sampler's learned visibility, path guiding's fields, the auto probes) is trained on every pixel's samples,
 * p's early ones included, and the neighbours' pilots were drawn with it; n_p thus depends on
 * p's early samples through the learned state, a coupling spread over the whole image (plain
 * renders with learning have the same kind). Without learning (a light sampler that learns
 * nothing, no guiding) the independence is exact. */

/* sqrt(16): T compares a standard error relative to the image mean, times sqrt(16 / n) */
#define ADAPTIVE_SCALE 4.0
/* the largest target (a count the schedule never reaches: the render's --spp caps it) */
#define ADAPTIVE_TARGET_MAX (1u << 30)

/* The pooling window's half-width: about 1/24 of the image's shorter side (the full image's with
 * --crop: Film.window_side; 8 pixels at 320x180,
 * 15 at 640x360). A pilot of 16 samples per pixel measures a heavy-tailed pixel's variance
 * mostly by whether it met a rare path: pooled over 3 x 3 the allocation follows that noise and
 * loses to uniform sampling (measured 0.65-0.87x on guiding_interior); the wide window costs
 * little where noise has structure (scenes/RESULTS.md, "Adaptive sampling"). */
static int adaptive_radius(int w, int h) {
    int r = ((w < h ? w : h) + 12) / 24;
    return r < 1 ? 1 : r;
}

/* The targets of every pixel from the film as it stands (the pilot). 0 ok, -1 out of memory. */
static int adaptive_targets(Film *f, float threshold) {
    const int w = f->width, h = f->height;
    const int r = f->window_side > 0 ? adaptive_radius(f->window_side, f->window_side) : adaptive_radius(w, h);
    const size_t n = (size_t)w * (size_t)h, stride = (size_t)w + 1;
    /* per pixel: the per-sample variance summed over channels (v) and the mean over channels (m),
     * from the film's sums; then the summed-area table of v, (w + 1) x (h + 1) */
    double *v = malloc(n * sizeof(double)), *m = malloc(n * sizeof(double));
    double *sat = calloc(stride * ((size_t)h + 1), sizeof(double));
    if (!v || !m || !sat) { free(v); free(m); free(sat); return -1; }
    double image_sum = 0.0; /* in pixel order: the same for any thread count */
    for (size_t i = 0; i < n; ++i) {
        const double cnt = f->count[i];
        v[i] = m[i] = 0.0;
        for (int k = 0; k < 3; ++k) {
            const double mean = cnt > 0.0 ? f->sum[3 * i + k] / cnt : 0.0;
            const double var = cnt > 1.0 ? (f->sum2[3 * i + k] - cnt * mean * mean) / (cnt - 1.0) : 0.0;
            v[i] += var > 0.0 ? var : 0.0;
            m[i] += mean / 3.0;
        }
        image_sum += m[i];
    }
    for (int y = 0; y < h; ++y) {
        double row = 0.0;
        for (int x = 0; x < w; ++x) {
            row += v[(size_t)y * (size_t)w + (size_t)x];
            sat[((size_t)y + 1) * stride + (size_t)x + 1] = sat[(size_t)y * stride + (size_t)x + 1] + row;
        }
    }
    for (int y = 0; y < h; ++y) {
        const int y0 = y - r < 0 ? 0 : y - r, y1 = y + r + 1 > h ? h : y + r + 1;
        for (int x = 0; x < w; ++x) {
            const int x0 = x - r < 0 ? 0 : x - r, x1 = x + r + 1 > w ? w : x + r + 1;
            const size_t i = (size_t)y * (size_t)w + (size_t)x;
            /* the window's neighbours, p left out (rounding can leave a tiny negative: 0) */
            const double window = sat[(size_t)y1 * stride + (size_t)x1] - sat[(size_t)y0 * stride + (size_t)x1] -
                                  sat[(size_t)y1 * stride + (size_t)x0] + sat[(size_t)y0 * stride + (size_t)x0] - v[i];
            const int neighbours = (y1 - y0) * (x1 - x0) - 1;
            double want = INFINITY; /* a 1 x 1 image: no neighbour to decide from, so no pixel stops early */
            if (neighbours > 0) {
                const double sigma = sqrt(window > 0.0 ? window / neighbours : 0.0);
                const double mu = (image_sum - m[i]) / (double)(n - 1); /* the image's mean without p */
                want = sigma > 0.0 ? ADAPTIVE_SCALE * sigma / ((double)threshold * mu) : 0.0;
            }
            const uint32_t pilot = f->count[i];
            f->target[i] = !(want < (double)ADAPTIVE_TARGET_MAX) ? ADAPTIVE_TARGET_MAX
                         : want <= (double)pilot                 ? pilot
                                                                 : (uint32_t)ceil(want);
        }
    }
    free(v); free(m); free(sat);
    return 0;
}

int film_adaptive_pilot_done(const Film *f) { return f->target && f->target[0] != 0; }

uint32_t film_adaptive_update(Film *f, float threshold) {
    const size_t n = (size_t)f->width * (size_t)f->height;
    if (!film_adaptive_pilot_done(f) && adaptive_targets(f, threshold) != 0) {
        uint32_t active = 0; /* out of memory: keep sampling everywhere (the image is right, only slower) */
        for (size_t i = 0; i < n; ++i) active += !f->stopped[i];
        return active;
    }
    uint32_t active = 0;
    for (size_t i = 0; i < n; ++i) {
        if (f->count[i] >= f->target[i]) f->stopped[i] = 1;
        active += !f->stopped[i];
    }
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
 * sampling's stopped pixels and targets. Bit 2 alone (stopped pixels without targets) was the
 * film of an adaptive render before the pilot rule (01f6ea2 and earlier): its pixels stopped by
 * another rule, so it cannot be resumed (film_load: -3). The layout of films without adaptive
 * sampling is unchanged, hence FILM_VERSION stays 1. */
#define FILM_ADAPTIVE_BITS (1 << 2 | 1 << 3)
/* Bit 4: a count of dropped samples follows the head (film_drop; films without are laid out as
 * before, and a build without it refuses a film with it). */
#define FILM_DROPPED_BIT (1 << 4)
static int32_t film_arrays(const Film *f) {
    return (f->recorder != NULL) | (f->sel_aov != NULL) << 1 | (f->stopped != NULL) << 2 | (f->target != NULL) << 3;
}

int film_save(const Film *f, FILE *out) {
    size_t n = (size_t)f->width * (size_t)f->height;
    int32_t head[3] = {f->width, f->height, film_arrays(f) | (f->dropped ? FILM_DROPPED_BIT : 0)};
    return ckpt_put_tag(out, FILM_TAG, FILM_VERSION) | ckpt_put(out, head, sizeof head) |
           (f->dropped ? ckpt_put(out, &f->dropped, sizeof f->dropped) : 0) |
           ckpt_put(out, f->sum, 3 * n * sizeof(double)) | ckpt_put(out, f->sum2, 3 * n * sizeof(double)) |
           ckpt_put(out, f->albedo, 3 * n * sizeof(double)) | ckpt_put(out, f->normal, 3 * n * sizeof(double)) |
           ckpt_put(out, f->depth, n * sizeof(double)) | ckpt_put(out, f->hits, n * sizeof(uint32_t)) |
           ckpt_put(out, f->count, n * sizeof(uint32_t)) |
           (f->recorder ? ckpt_put(out, f->recorder, 3 * n * sizeof(double)) : 0) |
           (f->sel_aov ? ckpt_put(out, f->sel_aov, 6 * n * sizeof(double)) : 0) |
           (f->stopped ? ckpt_put(out, f->stopped, n) : 0) |
           (f->target ? ckpt_put(out, f->target, n * sizeof(uint32_t)) : 0);
}

int film_load(Film *f, FILE *in) {
    size_t n = (size_t)f->width * (size_t)f->height;
    int32_t head[3];
    if (ckpt_get_tag(in, FILM_TAG, FILM_VERSION) || ckpt_get(in, head, sizeof head)) return -1;
    if (head[0] != f->width || head[1] != f->height) return -1;
    f->dropped = 0;
    if (head[2] & FILM_DROPPED_BIT) {
        head[2] &= ~FILM_DROPPED_BIT;
        if (ckpt_get(in, &f->dropped, sizeof f->dropped) || f->dropped == 0) return -1;
    }
    if (head[2] != film_arrays(f))
        return (head[2] & FILM_ADAPTIVE_BITS) == 1 << 2 && (film_arrays(f) & FILM_ADAPTIVE_BITS) == FILM_ADAPTIVE_BITS
                   ? -3 : -1;
    return ckpt_get(in, f->sum, 3 * n * sizeof(double)) | ckpt_get(in, f->sum2, 3 * n * sizeof(double)) |
           ckpt_get(in, f->albedo, 3 * n * sizeof(double)) | ckpt_get(in, f->normal, 3 * n * sizeof(double)) |
           ckpt_get(in, f->depth, n * sizeof(double)) | ckpt_get(in, f->hits, n * sizeof(uint32_t)) |
           ckpt_get(in, f->count, n * sizeof(uint32_t)) |
           (f->recorder ? ckpt_get(in, f->recorder, 3 * n * sizeof(double)) : 0) |
           (f->sel_aov ? ckpt_get(in, f->sel_aov, 6 * n * sizeof(double)) : 0) |
           (f->stopped ? ckpt_get(in, f->stopped, n) : 0) |
           (f->target ? ckpt_get(in, f->target, n * sizeof(uint32_t)) : 0);
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
    if (f->dropped > done) {
        snprintf(what, len, "it dropped %u samples per pixel of the %llu the %s declares", f->dropped,
                 (unsigned long long)done, declares);
        return -1;
    }
    done -= f->dropped; /* the sums hold the rest */
    most -= f->dropped;
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
