/* renderer/integrator/feature.c: the table of the integrator's features and the loops over it
 * (feature.h says what a feature is and why the order matters). */
#include "feature.h"

/* The order: the recorder first (its batch end sorts the samples guiding trains on, its
 * barrier counts what the iteration recorded before guiding's decides whether to record on),
 * then guiding, then the volume estimators' auto choices. */
static const IntegratorFeature *const FEATURES[] = {
    &feature_recorder,
    &feature_guiding,
    &feature_inscatter_auto,
    &feature_emission_auto,
};
#define NUM_FEATURES (sizeof FEATURES / sizeof FEATURES[0])

int features_validate(const CandelaOptions *o, const Scene *scene, char err[CANDELA_ERR_LEN]) {
    for (size_t i = 0; i < NUM_FEATURES; ++i)
        if (FEATURES[i]->validate && FEATURES[i]->validate(o, scene, err) != 0) return -1;
    return 0;
}

int features_init(Integrator *ig) {
    for (size_t i = 0; i < NUM_FEATURES; ++i)
        if (FEATURES[i]->init && FEATURES[i]->init(ig) != 0) return -1;
    return 0;
}

void features_free(Integrator *ig) {
    for (size_t i = 0; i < NUM_FEATURES; ++i)
        if (FEATURES[i]->free) FEATURES[i]->free(ig);
}

void features_slice_begin(Integrator *ig, Slice *s, uint32_t k) {
    for (size_t i = 0; i < NUM_FEATURES; ++i)
        if (FEATURES[i]->slice_begin) FEATURES[i]->slice_begin(ig, s, k);
}

void features_batch_end(Integrator *ig, Slice *slices, uint32_t n) {
    for (size_t i = 0; i < NUM_FEATURES; ++i)
        if (FEATURES[i]->batch_end) FEATURES[i]->batch_end(ig, slices, n);
}

void features_barrier(Integrator *ig) {
    for (size_t i = 0; i < NUM_FEATURES; ++i)
        if (FEATURES[i]->barrier) FEATURES[i]->barrier(ig);
}

int features_schedule_start(const Integrator *ig) {
    for (size_t i = 0; i < NUM_FEATURES; ++i) {
        int start = FEATURES[i]->schedule_start ? FEATURES[i]->schedule_start(ig) : -1;
        if (start >= 0) return start;
    }
    return -1;
}

void features_report(const Integrator *ig, CandelaStats *st) {
    for (size_t i = 0; i < NUM_FEATURES; ++i)
        if (FEATURES[i]->report) FEATURES[i]->report(ig, st);
}

int features_finish(Integrator *ig, char err[CANDELA_ERR_LEN]) {
    for (size_t i = 0; i < NUM_FEATURES; ++i)
        if (FEATURES[i]->finish && FEATURES[i]->finish(ig, err) != 0) return -1;
    return 0;
}

int features_save(const Integrator *ig, FILE *out) {
    int rc = 0;
    for (size_t i = 0; i < NUM_FEATURES; ++i)
        if (FEATURES[i]->save) rc |= FEATURES[i]->save(ig, out);
    return rc;
}

int features_load(Integrator *ig, FILE *in, const char **what) {
    for (size_t i = 0; i < NUM_FEATURES; ++i) {
        if (!FEATURES[i]->load) continue;
        *what = FEATURES[i]->name;
        int rc = FEATURES[i]->load(ig, in);
        if (rc != 0) return rc;
    }
    return 0;
}
