/* renderer/integrator/feature.h: the integrator's features as one ordered table.
 *
 * A feature is a part of the integrator with state that lives across batches and iterations:
 * the radiance recorder, path guiding, and the volume estimators' `auto` choices
 * (in-scattering sampling, emission sampling). Each exports one IntegratorFeature from its file
 * (the two volume auto choices share volume_auto.c and its probe); feature.c lists them in
 * order, and the integrator's driver (wavefront.c), the render loop (render.c) and the
 * checkpoint file (checkpoint.c) loop over that table through the functions below and name no
 * feature (tests/test_seams.sh checks it). Adding a feature is its
 * file and one row of the table (ARCHITECTURE.md, "Integrator features").
 *
 * Each hook decides for itself whether its feature is on (a feature that is off does nothing
 * in them); NULL hooks are skipped. The order of the table is the order of every loop: it is
 * part of the images (batch-end and barrier hooks read what earlier ones wrote) and of the
 * checkpoint format (each feature's state follows the previous one's). */
#ifndef CANDELA_FEATURE_H
#define CANDELA_FEATURE_H

#include <stdio.h>

#include "integrator.h"

typedef struct IntegratorFeature {
    const char *name; /* in messages: "the checkpoint's <name> state does not fit this render" */
    /* before anything is built: refuse options that cannot work with this scene (one line) */
    int (*validate)(const CandelaOptions *o, const Scene *scene, char err[CANDELA_ERR_LEN]);
    int (*init)(Integrator *ig); /* after the film and the path state; 0, or -1 (out of memory) */
    void (*free)(Integrator *ig);
    void (*slice_begin)(Integrator *ig, Slice *s, uint32_t k); /* a batch's slice k is set up */
    void (*batch_end)(Integrator *ig, Slice *slices, uint32_t n); /* serial, after the slices ran */
    void (*barrier)(Integrator *ig);                              /* no ray in flight */
    int (*schedule_start)(const Integrator *ig); /* the iteration its schedule starts from, or -1 */
    void (*report)(const Integrator *ig, CandelaStats *st);
    int (*finish)(Integrator *ig, char err[CANDELA_ERR_LEN]); /* after the last iteration: its outputs */
    int (*save)(const Integrator *ig, FILE *out);             /* its part of a checkpoint */
    int (*load)(Integrator *ig, FILE *in);
} IntegratorFeature;

extern const IntegratorFeature feature_recorder;        /* record.c */
extern const IntegratorFeature feature_guiding;         /* guide.c */
extern const IntegratorFeature feature_inscatter_auto;  /* volume_auto.c */
extern const IntegratorFeature feature_emission_auto;   /* volume_auto.c */

/* The loops over the table (feature.c). */
int features_validate(const CandelaOptions *o, const Scene *scene, char err[CANDELA_ERR_LEN]);
int features_init(Integrator *ig);
void features_free(Integrator *ig);
void features_slice_begin(Integrator *ig, Slice *s, uint32_t k);
void features_batch_end(Integrator *ig, Slice *slices, uint32_t n);
void features_barrier(Integrator *ig);
/* the first iteration of a schedule a feature asks for (guiding's 1-spp training), or -1 */
int features_schedule_start(const Integrator *ig);
void features_report(const Integrator *ig, CandelaStats *st);
int features_finish(Integrator *ig, char err[CANDELA_ERR_LEN]);
int features_save(const Integrator *ig, FILE *out);
/* 0; else -1 (or -2) with *what naming the feature whose state did not fit */
int features_load(Integrator *ig, FILE *in, const char **what);

#endif
