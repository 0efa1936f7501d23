/* renderer/app/bench.c: `candela bench` instrumentation: the log of every ray a render traced,
 * and its replay through bare Embree (one ray at a time, rtcIntersect1 / rtcOccluded1 behind
 * the scene ray interface) on the same threads, for the renderer / bare-Embree ratio. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "integrator.h"

void ray_log_append(CandelaRayLog *log, const SceneRay *rays, const uint32_t *items, uint32_t n, int shadow) {
    if (log->failed) return;
    /* bounded before it grows: doubling past the bound would wrap the size (to a small
     * allocation, or to 0 and a loop that never ends) */
    if (log->count > CANDELA_RAY_LOG_MAX || n > CANDELA_RAY_LOG_MAX - log->count) { log->failed = 1; return; }
    if (log->count + n > log->capacity) {
        size_t nc = log->capacity ? log->capacity : 1 << 20;
        while (nc < log->count + n) nc *= 2; /* at most 2^32: no wrap */
        float *a = realloc(log->org_dir_tfar, nc * 7 * sizeof(float));
        if (a) log->org_dir_tfar = a;
        uint8_t *s = a ? realloc(log->is_shadow, nc) : NULL;
        if (s) log->is_shadow = s;
        if (!a || !s) { log->failed = 1; return; }
        log->capacity = nc;
    }
    for (uint32_t i = 0; i < n; ++i) {
        const SceneRay *r = &rays[items[i]];
        float *dst = log->org_dir_tfar + 7 * log->count;
        dst[0] = r->org.x; dst[1] = r->org.y; dst[2] = r->org.z;
        dst[3] = r->dir.x; dst[4] = r->dir.y; dst[5] = r->dir.z;
        dst[6] = shadow ? r->tfar : INFINITY;
        log->is_shadow[log->count++] = (uint8_t)shadow;
    }
}

void candela_ray_log_free(CandelaRayLog *log) {
    free(log->org_dir_tfar);
    free(log->is_shadow);
    memset(log, 0, sizeof *log);
}

typedef struct ReplayCtx { const Scene *scene; const CandelaRayLog *log; } ReplayCtx;

static void replay_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    const ReplayCtx *c = vctx;
    for (size_t i = b; i < e; ++i) {
        const float *r = c->log->org_dir_tfar + 7 * i;
        SceneRay ray = {v3(r[0], r[1], r[2]), 0.0f, v3(r[3], r[4], r[5]), r[6]};
        if (c->log->is_shadow[i]) {
            (void)scene_visible1(c->scene, ray);
        } else {
            SceneHit hit;
            (void)scene_intersect1(c->scene, ray, &hit);
        }
    }
}

int candela_replay_rays(const CandelaOptions *o, const CandelaRayLog *log, int threads, double *seconds,
                        char err[CANDELA_ERR_LEN]) {
    Scene scene;
    if (scene_load(&scene, o, err) != 0) return -1;
    ThreadPool *pool = threadpool_create(threads);
    if (!pool) { scene_free(&scene); snprintf(err, CANDELA_ERR_LEN, "candela: out of memory"); return -1; }
    ReplayCtx c = {&scene, log};
    double t0 = clock_seconds();
    threadpool_parallel_for(pool, log->count, 4096, replay_range, &c);
    *seconds = clock_seconds() - t0;
    threadpool_destroy(pool);
    scene_free(&scene);
    return 0;
}
