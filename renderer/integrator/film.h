/* renderer/integrator/film.h (private): the film: every path's radiance summed per pixel, in sample order (film.c). */
#ifndef CANDELA_FILM_H
#define CANDELA_FILM_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "candela.h"
#include "path_state.h"

/* Per-pixel sums over the render (double: thousands of samples per pixel). */
typedef struct Film {
    int width, height;
    double *sum, *sum2;      /* 3 per pixel: sums of L and L^2 */
    double *albedo, *normal; /* 3 per pixel: sums over the paths whose camera ray hit */
    double *depth;           /* per pixel: sum of first-hit distances */
    uint32_t *hits, *count;  /* per pixel: camera rays that hit; samples */
    double *recorder;        /* 3 per pixel (--aov recorder-debug; else NULL): sums of the recorder's splats */
    double *sel_aov;         /* 6 per pixel (the light sampler's AOV, CandelaOptions.aov_selection; else NULL):
                              * sums over the hits of its two false colours (light_sampler_aov) */
    uint8_t *stopped;        /* per pixel with adaptive sampling (else NULL): 1 once it stopped sampling */
    uint32_t *target;        /* per pixel with adaptive sampling (else NULL): the samples it takes, fixed
                              * at the pilot barrier from its neighbours' pilots (0 before) */
    uint32_t dropped;        /* samples per pixel taken but not in the sums (film_drop: path guiding's
                              * unguided bootstrap), the same for every pixel */
    int aov_spp;             /* film_resolve writes CandelaImage.spp */
    int window_side;         /* adaptive sampling's window scale: the full image's shorter side (a --crop
                              * film is part of that image); 0: the film's own */
} Film;

int film_alloc(Film *f, int width, int height);
void film_free(Film *f);
/* Adds paths [0, count) of the batch, in path order, so every pixel sums its samples in
 * sample order whatever the batch size or thread count. */
void film_add_paths(Film *f, const PathState *ps, uint32_t count);
/* Drops every sample the film holds, which must be the same number per pixel (no adaptive
 * sampling): the sums restart, `dropped` counts them. 0 ok, -1 (nothing changed): the pixels'
 * counts differ. */
int film_drop(Film *f);
/* Mean, variance of the mean (sample variance / n) and AOVs. 0 ok, -1 out of memory. */
int film_resolve(const Film *f, CandelaImage *img);
/* The film's checkpoint section (ckpt_io.h). film_load checks the size (and the recorder AOV's presence); -3: an
 * adaptive film of the rule before the pilot rule (not resumable). */
int film_save(const Film *f, FILE *out);
int film_load(Film *f, FILE *in);
/* A loaded shard film fit to merge: every pixel's count equal to the shard's samples less the
 * film's dropped ones, sums finite (film.c). -1 with the first bad pixel in what. */
int film_check(const Film *f, uint64_t samples, char *what, size_t len);
/* The same for a checkpoint's film: a pixel still sampling counts [done, most], one adaptive
 * sampling stopped [1, done], each less the film's dropped samples (at most done). */
int film_check_counts(const Film *f, uint64_t done, uint64_t most, const char *declares, char *what, size_t len);
/* Adaptive sampling (film.c has the rule and why it is unbiased). At an iteration barrier past
 * --min-spp: the first call takes the film as it stands as the pilot (every pixel the same
 * count) and fixes each pixel's target count from its neighbours' pilot statistics, never its
 * own; every call stops the pixels whose count reached their target. Needs f->stopped and
 * f->target. Returns the number of pixels still sampling. A function of the film alone. */
uint32_t film_adaptive_update(Film *f, float threshold);
/* 1 once the pilot has fixed the targets (f->target set), else 0. */
int film_adaptive_pilot_done(const Film *f);

#endif
