/* renderer/wavefront.c: the batched, sorted-deferred wavefront path tracer.
 *
 * candela_render():
 *   scene_load -> for each iteration (spp schedule 1,1,2,4,... capped) ->
 *     for each batch of paths -> waves (see wavefront.h) -> film accumulation
 *     -> iteration barrier (no ray in flight; hooks run here)
 * Path j of an iteration is pixel j % npixels, sample base + j / npixels, so batches are
 * contiguous runs of j and the film receives every pixel's samples in sample order whatever
 * the batch size or thread count: the image is bit-identical across both. */
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "candela.h"
#include "rng.h"
#include "scene.h"
#include "threads.h"
#include "wavefront.h"

#define DEFAULT_BATCH_SIZE (1u << 14) /* fits the path state in L2: shading gathers by slot */
#define MAX_BATCH_SIZE (1u << 22)
#define DEFAULT_MAX_ITERATION_SPP 64
#define RR_START_DEPTH 3
#define TRACE_CHUNK 256
#define SHADE_GRAIN 256
#define MAX_SLICES 256

static double now_seconds(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

void candela_options_default(CandelaOptions *o) {
    memset(o, 0, sizeof *o);
    o->spp = 16;
    o->seed = 0;
    o->max_depth = 8;
    o->light_sampler = CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
    o->light_units = CANDELA_LIGHT_UNITS_BLENDER;
    o->env_strength = 1.0f;
}

static const char *const LIGHT_SAMPLER_NAMES[] = {"uniform", "power", "tree", "optimal", "cachepoints"};

const char *candela_light_sampler_name(CandelaLightSampler s) {
    return (unsigned)s < sizeof LIGHT_SAMPLER_NAMES / sizeof LIGHT_SAMPLER_NAMES[0] ? LIGHT_SAMPLER_NAMES[s] : "unknown";
}

int candela_light_sampler_parse(const char *name, CandelaLightSampler *s) {
    for (unsigned i = 0; i < sizeof LIGHT_SAMPLER_NAMES / sizeof LIGHT_SAMPLER_NAMES[0]; ++i)
        if (strcmp(name, LIGHT_SAMPLER_NAMES[i]) == 0) { *s = (CandelaLightSampler)i; return 0; }
    return -1;
}

/* ---------------------------------------------------------------- state */

typedef struct Film {
    int width, height;
    double *sum, *sum2;      /* 3 per pixel */
    double *albedo, *normal; /* 3 per pixel */
    double *depth;           /* per pixel: sum of first-hit distances */
    uint32_t *hits, *count;
} Film;

typedef struct Renderer {
    const CandelaOptions *opt;
    Scene scene;
    ThreadPool *pool;
    PathState ps;
    WorkQueue rays, hits, escaped, shadows;
    uint64_t *sort_keys, *sort_keys_tmp;
    uint32_t *sort_tmp;
    pthread_mutex_t log_mutex;
    Film film;
    CandelaStats *stats;
    CandelaRayLog *ray_log;
    uint32_t batch_count;
    uint64_t batch_first;    /* index j of the batch's first path within the iteration */
    uint64_t sample_base;    /* first sample index of the iteration */
    uint32_t npixels;
    int is_tty;
    double progress_last;
    double render_start;
} Renderer;

static void *xcalloc(size_t n, size_t size, int *fail) {
    void *p = calloc(n ? n : 1, size);
    if (!p) *fail = 1;
    return p;
}

static int path_state_alloc(PathState *ps, uint32_t n) {
    int fail = 0;
    memset(ps, 0, sizeof *ps);
    ps->capacity = n;
    ps->rng_key = xcalloc(n, sizeof(uint64_t), &fail);
    ps->pixel = xcalloc(n, sizeof(uint32_t), &fail);
    ps->radiance = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->throughput = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->eta_scale = xcalloc(n, sizeof(float), &fail);
    ps->ray_org = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->ray_dir = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->prev_pos = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->prev_normal = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->prev_bsdf_pdf = xcalloc(n, sizeof(float), &fail);
    ps->prev_delta = xcalloc(n, 1, &fail);
    ps->prev_cache_point1 = xcalloc(n, sizeof(uint32_t), &fail);
    ps->prev_cp_near_total = xcalloc(n, sizeof(float), &fail);
    ps->hit_t = xcalloc(n, sizeof(float), &fail);
    ps->hit_u = xcalloc(n, sizeof(float), &fail);
    ps->hit_v = xcalloc(n, sizeof(float), &fail);
    ps->hit_inst = xcalloc(n, sizeof(uint32_t), &fail);
    ps->hit_geom = xcalloc(n, sizeof(uint32_t), &fail);
    ps->hit_prim = xcalloc(n, sizeof(uint32_t), &fail);
    ps->shadow_org = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->shadow_dir = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->shadow_tfar = xcalloc(n, sizeof(float), &fail);
    ps->shadow_contrib = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->shadow_slot = xcalloc(n, sizeof(uint32_t), &fail);
    ps->continues = xcalloc(n, 1, &fail);
    ps->has_shadow = xcalloc(n, 1, &fail);
    ps->aov_albedo = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->aov_normal = xcalloc(3 * (size_t)n, sizeof(float), &fail);
    ps->aov_depth = xcalloc(n, sizeof(float), &fail);
    return fail ? -1 : 0;
}

static void path_state_free(PathState *ps) {
    void *ptrs[] = {ps->rng_key, ps->pixel, ps->radiance, ps->throughput, ps->eta_scale, ps->ray_org,
                    ps->ray_dir, ps->prev_pos, ps->prev_normal, ps->prev_bsdf_pdf, ps->prev_delta, ps->prev_cache_point1, ps->prev_cp_near_total,
                    ps->hit_t, ps->hit_u, ps->hit_v, ps->hit_inst, ps->hit_geom, ps->hit_prim,
                    ps->shadow_org, ps->shadow_dir, ps->shadow_tfar, ps->shadow_contrib, ps->shadow_slot,
                    ps->continues, ps->has_shadow, ps->aov_albedo, ps->aov_normal, ps->aov_depth};
    for (size_t i = 0; i < sizeof ptrs / sizeof ptrs[0]; ++i) free(ptrs[i]);
    memset(ps, 0, sizeof *ps);
}

static inline vec3 load3(const float *a, uint32_t i) { return v3(a[3 * i], a[3 * i + 1], a[3 * i + 2]); }
static inline void store3(float *a, uint32_t i, vec3 v) { a[3 * i] = v.x; a[3 * i + 1] = v.y; a[3 * i + 2] = v.z; }

static inline float power_heuristic(float a, float b) {
    if (isinf(a)) return 1.0f;
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}

/* ---------------------------------------------------------------- sorting */

/* LSD radix sort of (key, item) pairs, 11 bits a pass; digits that are the same in every
 * key are skipped. Stable, so equal keys keep queue order (which is deterministic).
 * keys_tmp/items_tmp are scratch of length n. */
#define RADIX_BITS 11
#define RADIX_BUCKETS (1u << RADIX_BITS)
static void radix_sort(uint32_t *items, uint64_t *keys, uint32_t n, uint64_t *keys_tmp, uint32_t *items_tmp) {
    if (n < 2) return;
    uint64_t any = 0, all = ~0ull;
    for (uint32_t i = 0; i < n; ++i) { any |= keys[i]; all &= keys[i]; }
    uint64_t varying = any ^ all;
    uint64_t *k_in = keys, *k_out = keys_tmp;
    uint32_t *v_in = items, *v_out = items_tmp;
    uint32_t count[RADIX_BUCKETS];
    for (int shift = 0; shift < 64; shift += RADIX_BITS) {
        if (((varying >> shift) & (RADIX_BUCKETS - 1)) == 0) continue;
        memset(count, 0, sizeof count);
        for (uint32_t i = 0; i < n; ++i) count[(k_in[i] >> shift) & (RADIX_BUCKETS - 1)]++;
        uint32_t sum = 0;
        for (uint32_t b = 0; b < RADIX_BUCKETS; ++b) { uint32_t c = count[b]; count[b] = sum; sum += c; }
        for (uint32_t i = 0; i < n; ++i) {
            uint32_t dst = count[(k_in[i] >> shift) & (RADIX_BUCKETS - 1)]++;
            k_out[dst] = k_in[i];
            v_out[dst] = v_in[i];
        }
        uint64_t *tk = k_in; k_in = k_out; k_out = tk;
        uint32_t *tv = v_in; v_in = v_out; v_out = tv;
    }
    if (v_in != items) memcpy(items, v_in, n * sizeof *items);
}

static inline uint64_t morton_spread(uint64_t x) {
    /* 21 bits -> every third bit */
    x &= 0x1fffff;
    x = (x | x << 32) & 0x1f00000000ffffull;
    x = (x | x << 16) & 0x1f0000ff0000ffull;
    x = (x | x << 8) & 0x100f00f00f00f00full;
    x = (x | x << 4) & 0x10c30c30c30c30c3ull;
    x = (x | x << 2) & 0x1249249249249249ull;
    return x;
}

typedef struct SortCtx { Renderer *r; const uint32_t *items; uint64_t *keys; } SortCtx;

/* 30-bit Morton code of p quantised over the scene bounds (10 bits per axis) */
static inline uint64_t morton30(const Renderer *r, vec3 p) {
    vec3 lo = r->scene.bounds_min;
    vec3 ext = v3_sub(r->scene.bounds_max, lo);
    const float cells = 1024.0f;
    float f[3] = {(p.x - lo.x) / fmaxf(ext.x, 1e-20f), (p.y - lo.y) / fmaxf(ext.y, 1e-20f),
                  (p.z - lo.z) / fmaxf(ext.z, 1e-20f)};
    uint64_t q[3];
    for (int k = 0; k < 3; ++k) {
        float v = clampf(f[k], 0.0f, 0.999f) * cells;
        q[k] = isfinite(v) ? (uint64_t)v : 0;
    }
    return morton_spread(q[0]) | morton_spread(q[1]) << 1 | morton_spread(q[2]) << 2;
}

static void ray_keys_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    SortCtx *c = vctx;
    Renderer *r = c->r;
    const PathState *ps = &r->ps;
    for (size_t i = b; i < e; ++i) {
        uint32_t p = c->items[i];
        vec3 d = load3(ps->ray_dir, p), o = load3(ps->ray_org, p);
        uint64_t oct = (uint64_t)((d.x < 0) | ((d.y < 0) << 1) | ((d.z < 0) << 2));
        /* octant (3 bits) | Morton (30 bits); the stable sort keeps queue order for ties */
        c->keys[i] = oct << 30 | morton30(r, o);
    }
}

static void hit_keys_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    SortCtx *c = vctx;
    Renderer *r = c->r;
    const PathState *ps = &r->ps;
    for (size_t i = b; i < e; ++i) {
        uint32_t p = c->items[i];
        const SceneInstance *inst = &r->scene.instances[ps->hit_inst[p]];
        uint64_t global = r->scene.io.meshes[inst->mesh].first_primitive + ps->hit_geom[p];
        /* (glTF primitive, Morton code of the hit point): the primitive shares material and
         * vertex data across instances; inside it, spatial order keeps consecutive vertices
         * near each other, so they share cache points and texture tiles (a large quad's two
         * triangles say nothing about where on it a hit lies) */
        vec3 hp = v3_madd(load3(ps->ray_org, p), load3(ps->ray_dir, p), ps->hit_t[p]);
        c->keys[i] = global << 30 | morton30(r, hp);
    }
}

/* ---------------------------------------------------------------- stages */

typedef struct GenerateCtx { Renderer *r; } GenerateCtx;

static void generate_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    Renderer *r = ((GenerateCtx *)vctx)->r;
    PathState *ps = &r->ps;
    const Camera *cam = &r->scene.camera;
    for (size_t i = b; i < e; ++i) {
        uint64_t j = r->batch_first + i;
        uint32_t pixel = (uint32_t)(j % r->npixels);
        uint64_t sample = r->sample_base + j / r->npixels;
        uint64_t key = rng_path_key(r->opt->seed, pixel, sample);
        ps->rng_key[i] = key;
        ps->pixel[i] = pixel;
        float fx = (float)(pixel % (uint32_t)cam->width) + rng_uniform(key, RNG_DIM_PIXEL_X);
        float fy = (float)(pixel / (uint32_t)cam->width) + rng_uniform(key, RNG_DIM_PIXEL_Y);
        vec3 o, d;
        camera_generate_ray(cam, fx, fy, &o, &d);
        store3(ps->ray_org, (uint32_t)i, o);
        store3(ps->ray_dir, (uint32_t)i, d);
        store3(ps->radiance, (uint32_t)i, v3s(0.0f));
        store3(ps->throughput, (uint32_t)i, v3s(1.0f));
        ps->eta_scale[i] = 1.0f;
        ps->prev_delta[i] = 1;
        ps->prev_bsdf_pdf[i] = 0.0f;
        store3(ps->aov_albedo, (uint32_t)i, v3s(0.0f));
        store3(ps->aov_normal, (uint32_t)i, v3s(0.0f));
        ps->aov_depth[i] = INFINITY;
        r->rays.items[i] = (uint32_t)i;
    }
}

typedef struct TraceCtx { Renderer *r; const uint32_t *items; int coherent; } TraceCtx;

static void trace_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    TraceCtx *c = vctx;
    Renderer *r = c->r;
    PathState *ps = &r->ps;
    struct RTCRayHit rh[TRACE_CHUNK];
    struct RTCIntersectContext ictx;
    rtcInitIntersectContext(&ictx);
    ictx.flags = c->coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    for (size_t s = b; s < e; s += TRACE_CHUNK) {
        unsigned m = (unsigned)((e - s) < TRACE_CHUNK ? (e - s) : TRACE_CHUNK);
        for (unsigned k = 0; k < m; ++k) {
            uint32_t p = c->items[s + k];
            struct RTCRayHit *h = &rh[k];
            h->ray.org_x = ps->ray_org[3 * p]; h->ray.org_y = ps->ray_org[3 * p + 1]; h->ray.org_z = ps->ray_org[3 * p + 2];
            h->ray.dir_x = ps->ray_dir[3 * p]; h->ray.dir_y = ps->ray_dir[3 * p + 1]; h->ray.dir_z = ps->ray_dir[3 * p + 2];
            h->ray.tnear = 0.0f;
            h->ray.tfar = INFINITY;
            h->ray.time = 0.0f;
            h->ray.mask = 0xffffffffu;
            h->ray.id = p;
            h->ray.flags = 0;
            h->hit.geomID = RTC_INVALID_GEOMETRY_ID;
            h->hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect1M(r->scene.top, &ictx, rh, m, sizeof(struct RTCRayHit));
        for (unsigned k = 0; k < m; ++k) {
            uint32_t p = c->items[s + k];
            const struct RTCRayHit *h = &rh[k];
            if (h->hit.geomID == RTC_INVALID_GEOMETRY_ID) {
                ps->hit_t[p] = INFINITY;
            } else {
                ps->hit_t[p] = h->ray.tfar;
                ps->hit_u[p] = h->hit.u;
                ps->hit_v[p] = h->hit.v;
                ps->hit_inst[p] = h->hit.instID[0];
                ps->hit_geom[p] = h->hit.geomID;
                ps->hit_prim[p] = h->hit.primID;
            }
        }
    }
}

typedef struct ShadeCtx { Renderer *r; const uint32_t *items; uint32_t depth; } ShadeCtx;

static void escaped_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    ShadeCtx *c = vctx;
    Renderer *r = c->r;
    PathState *ps = &r->ps;
    const Scene *scene = &r->scene;
    for (size_t i = b; i < e; ++i) {
        uint32_t p = c->items[i];
        if (scene->lights.environment < 0) continue;
        vec3 d = load3(ps->ray_dir, p);
        vec3 le = scene_env_radiance(scene, d);
        if (v3_is_black(le)) continue;
        float w = 1.0f;
        if (!ps->prev_delta[p]) {
            LightSampleContext lc = {load3(ps->prev_pos, p), load3(ps->prev_normal, p), ps->prev_cache_point1[p],
                                     ps->prev_cp_near_total[p]};
            float pl = light_select_pmf(&scene->lights, &lc, (uint32_t)scene->lights.environment) *
                       light_env_pdf_li(scene, d);
            w = power_heuristic(ps->prev_bsdf_pdf[p], pl);
        }
        vec3 L = v3_add(load3(ps->radiance, p), v3_scale(v3_mul(load3(ps->throughput, p), le), w));
        store3(ps->radiance, p, L);
    }
}

#define SHADE_PREFETCH 8
static inline void prefetch_path(const PathState *ps, uint32_t p) {
    __builtin_prefetch(&ps->rng_key[p]);
    __builtin_prefetch(&ps->hit_inst[p]);
    __builtin_prefetch(&ps->hit_geom[p]);
    __builtin_prefetch(&ps->hit_prim[p]);
    __builtin_prefetch(&ps->hit_u[p]);
    __builtin_prefetch(&ps->hit_v[p]);
    __builtin_prefetch(&ps->hit_t[p]);
    __builtin_prefetch(&ps->ray_dir[3 * p]);
    __builtin_prefetch(&ps->throughput[3 * p], 1);
    __builtin_prefetch(&ps->radiance[3 * p], 1);
    __builtin_prefetch(&ps->prev_pos[3 * p], 1);
    __builtin_prefetch(&ps->prev_normal[3 * p], 1);
    __builtin_prefetch(&ps->prev_delta[p], 1);
    __builtin_prefetch(&ps->prev_bsdf_pdf[p], 1);
    __builtin_prefetch(&ps->eta_scale[p], 1);
}

static void shade_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    ShadeCtx *c = vctx;
    Renderer *r = c->r;
    PathState *ps = &r->ps;
    const Scene *scene = &r->scene;
    const Lights *lights = &scene->lights;
    const uint32_t depth = c->depth;
    uint32_t cp_hint = UINT32_MAX; /* hits are sorted by primitive: the last vertex's cache point is near */
    for (size_t i = b; i < e; ++i) {
        /* The hit queue is in (primitive, Morton) order, so slots are visited in random
         * order: prefetch the slot a few items ahead to overlap the cache misses. */
        if (i + SHADE_PREFETCH < e) prefetch_path(ps, c->items[i + SHADE_PREFETCH]);
        uint32_t p = c->items[i];
        uint64_t key = ps->rng_key[p];
        ps->continues[p] = 0;
        ps->has_shadow[p] = 0;
        vec3 wo = v3_neg(load3(ps->ray_dir, p));
        vec3 beta = load3(ps->throughput, p);
        vec3 L = load3(ps->radiance, p);

        SurfaceHit h;
        scene_surface_hit(scene, ps->hit_inst[p], ps->hit_geom[p], ps->hit_prim[p], ps->hit_u[p], ps->hit_v[p], &h);
        MaterialSample m;
        scene_material_at(scene, &h, &m);
        int transmissive = bsdf_has_transmission(&m.bsdf);
        vec3 ng = h.ng, ns = h.ns;
        if (!transmissive && v3_dot(wo, ng) < 0.0f) { ng = v3_neg(ng); ns = v3_neg(ns); }

        if (depth == 0) {
            store3(ps->aov_albedo, p, m.bsdf.base_color);
            store3(ps->aov_normal, p, ns);
            ps->aov_depth[p] = ps->hit_t[p];
        }

        /* emission found by the previous vertex's BSDF sample (or the camera) */
        int32_t light_index = scene->light_of_primitive[scene->instances[h.instance].light_table_base + h.local_prim];
        if (light_index >= 0) {
            vec3 le = scene_emitted_radiance(scene, &h, wo);
            if (!v3_is_black(le)) {
                float w = 1.0f;
                if (!ps->prev_delta[p]) {
                    vec3 prev = load3(ps->prev_pos, p);
                    LightSampleContext lc = {prev, load3(ps->prev_normal, p), ps->prev_cache_point1[p],
                                             ps->prev_cp_near_total[p]};
                    float pl = light_select_pmf(lights, &lc, (uint32_t)light_index) *
                               light_area_pdf_li(&lights->lights[light_index], &lc, h.triangle, h.p, h.ng);
                    w = power_heuristic(ps->prev_bsdf_pdf[p], pl);
                }
                L = v3_add(L, v3_scale(v3_mul(beta, le), w));
            }
        }
        store3(ps->radiance, p, L);
        if ((int)depth >= r->opt->max_depth) continue;

        Frame f;
        f.n = ns;
        f.t = h.dpdu;
        if (v3_dot(f.t, ns) != 0.0f) f.t = v3_normalize(v3_sub(f.t, v3_scale(ns, v3_dot(ns, f.t))));
        f.b = v3_cross(ns, f.t);
        vec3 wo_l = frame_to_local(&f, wo);

        /* light-selection context: transmissive surfaces receive light from both sides, so
         * they use the omnidirectional (fluence) estimates, as volumes do (spec §5.2) */
        vec3 ctx_n = transmissive ? v3s(0.0f) : ns;
        float cp_near_w[CACHEPOINTS_MAX_NEAR];
        LightSampleContext lc = {h.p, ctx_n, 0, 0.0f, cp_near_w};
        int delta = bsdf_is_delta(&m.bsdf);
        if (!delta) lights_prepare_context(lights, &lc, &cp_hint); /* one nearest-point query per vertex */
        /* next-event estimation */
        if (!delta && lights->count > 0) {
            float pmf;
            uint32_t slot;
            uint32_t li = light_select(lights, &lc, rng_uniform(key, rng_bounce_dim(depth, RNG_BOUNCE_LIGHT_SELECT)),
                                       rng_uniform(key, rng_bounce_dim(depth, RNG_BOUNCE_LIGHT_DESCEND)), &pmf, &slot);
            LightLiSample ls;
            if (lights->cachepoints) ps->shadow_slot[p] = slot; /* §3.2.1: the slot that chose */
            if (pmf > 0.0f &&
                light_sample_li(scene, &lights->lights[li], &lc, rng_uniform(key, rng_bounce_dim(depth, RNG_BOUNCE_LIGHT_U)),
                                rng_uniform(key, rng_bounce_dim(depth, RNG_BOUNCE_LIGHT_V)),
                                rng_uniform(key, rng_bounce_dim(depth, RNG_BOUNCE_LIGHT_W)), &ls)) {
                vec3 wi_l = frame_to_local(&f, ls.wi);
                float side_g = v3_dot(ls.wi, ng);
                /* reject directions whose geometric and shading hemispheres disagree (light leaks) */
                if (side_g * wi_l.z > 0.0f) {
                    float bsdf_pdf_wi;
                    vec3 fv = v3_scale(bsdf_eval_pdf(&m.bsdf, wo_l, wi_l, &bsdf_pdf_wi), fabsf(wi_l.z));
                    if (!v3_is_black(fv)) {
                        float light_pdf = pmf * ls.pdf;
                        float w = ls.is_delta ? 1.0f : power_heuristic(light_pdf, bsdf_pdf_wi);
                        vec3 contrib = v3_scale(v3_mul(v3_mul(beta, fv), ls.radiance), w / light_pdf);
                        if (v3_is_finite(contrib) && !v3_is_black(contrib)) {
                            vec3 o = offset_ray_origin(h.p, side_g > 0.0f ? ng : v3_neg(ng));
                            vec3 dir = ls.wi;
                            float tfar = INFINITY;
                            if (!isinf(ls.distance)) {
                                /* aim from the offset origin at the sampled point itself: keeping
                                 * the unoffset direction and length made the ray end behind
                                 * nearby emitters and darkened small scenes */
                                vec3 to = v3_sub(v3_madd(h.p, ls.wi, ls.distance), o);
                                float len = v3_length(to);
                                if (len > 0.0f) { dir = v3_scale(to, 1.0f / len); tfar = len * (1.0f - 1e-3f); }
                                else tfar = 0.0f;
                            }
                            store3(ps->shadow_org, p, o);
                            store3(ps->shadow_dir, p, dir);
                            ps->shadow_tfar[p] = tfar;
                            store3(ps->shadow_contrib, p, contrib);
                            ps->has_shadow[p] = 1;
                        }
                    }
                }
            }
            /* no shadow ray: the attempt failed already (the shadow stage counts the others) */
            if (lights->cachepoints && !ps->has_shadow[p]) cachepoints_record(lights->cachepoints, slot, 0.0f);
        }

        /* BSDF sampling for the continuation ray */
        BsdfSample bs;
        if (!bsdf_sample(&m.bsdf, wo_l, rng_uniform(key, rng_bounce_dim(depth, RNG_BOUNCE_BSDF_LOBE)),
                         rng_uniform(key, rng_bounce_dim(depth, RNG_BOUNCE_BSDF_U)),
                         rng_uniform(key, rng_bounce_dim(depth, RNG_BOUNCE_BSDF_V)), &bs))
            continue;
        vec3 wi = v3_normalize(frame_to_world(&f, bs.wi));
        float side_g = v3_dot(wi, ng);
        if (!(side_g * bs.wi.z > 0.0f) || !(bs.pdf > 0.0f)) continue;
        beta = v3_mul(beta, v3_scale(bs.f, fabsf(bs.wi.z) / bs.pdf));
        if (bs.flags & BSDF_TRANSMISSION) {
            float eta = m.bsdf.ior;
            ps->eta_scale[p] *= v3_dot(wo, ng) > 0.0f ? eta * eta : 1.0f / (eta * eta);
        }
        if (!v3_is_finite(beta) || v3_is_black(beta)) continue;
        /* Russian roulette on the throughput with refraction's radiance scaling removed */
        if (depth + 1 >= RR_START_DEPTH) {
            float q = fmaxf(0.0f, 1.0f - v3_max_component(beta) * ps->eta_scale[p]);
            q = fminf(q, 0.95f);
            if (rng_uniform(key, rng_bounce_dim(depth, RNG_BOUNCE_RR)) < q) continue;
            beta = v3_scale(beta, 1.0f / (1.0f - q));
        }
        store3(ps->throughput, p, beta);
        store3(ps->prev_pos, p, h.p);
        store3(ps->prev_normal, p, ctx_n);
        ps->prev_cache_point1[p] = lc.cache_point1;
        ps->prev_cp_near_total[p] = lc.cp_near_total;
        ps->prev_bsdf_pdf[p] = bs.pdf;
        ps->prev_delta[p] = (bs.flags & BSDF_DELTA) ? 1 : 0;
        store3(ps->ray_org, p, offset_ray_origin(h.p, side_g > 0.0f ? ng : v3_neg(ng)));
        store3(ps->ray_dir, p, wi);
        ps->continues[p] = 1;
    }
}

static void shadow_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    ShadeCtx *c = vctx;
    Renderer *r = c->r;
    PathState *ps = &r->ps;
    CachePoints *cp = r->scene.lights.cachepoints;
    struct RTCRay rays[TRACE_CHUNK];
    struct RTCIntersectContext ictx;
    rtcInitIntersectContext(&ictx);
    for (size_t s = b; s < e; s += TRACE_CHUNK) {
        unsigned m = (unsigned)((e - s) < TRACE_CHUNK ? (e - s) : TRACE_CHUNK);
        for (unsigned k = 0; k < m; ++k) {
            uint32_t p = c->items[s + k];
            struct RTCRay *ray = &rays[k];
            ray->org_x = ps->shadow_org[3 * p]; ray->org_y = ps->shadow_org[3 * p + 1]; ray->org_z = ps->shadow_org[3 * p + 2];
            ray->dir_x = ps->shadow_dir[3 * p]; ray->dir_y = ps->shadow_dir[3 * p + 1]; ray->dir_z = ps->shadow_dir[3 * p + 2];
            ray->tnear = 0.0f;
            ray->tfar = ps->shadow_tfar[p];
            ray->time = 0.0f;
            ray->mask = 0xffffffffu;
            ray->id = p;
            ray->flags = 0;
            if (cp) cachepoints_prefetch_counters(cp, ps->shadow_slot[p]); /* arrives while tracing */
        }
        rtcOccluded1M(r->scene.top, &ictx, rays, m, sizeof(struct RTCRay));
        for (unsigned k = 0; k < m; ++k) {
            uint32_t p = c->items[s + k];
            if (rays[k].tfar >= 0.0f) { /* tfar becomes -inf when occluded */
                vec3 L = v3_add(load3(ps->radiance, p), load3(ps->shadow_contrib, p));
                store3(ps->radiance, p, L);
            }
            /* §3.2.1: the attempt, and a success if the shadow ray got through with a useful
             * (non-zero) contribution */
            if (cp) cachepoints_record(cp, ps->shadow_slot[p], rays[k].tfar >= 0.0f ? 1.0f : 0.0f);
        }
    }
}

/* ---------------------------------------------------------------- batch */

static void log_rays(Renderer *r, const uint32_t *items, uint32_t count, int shadow) {
    CandelaRayLog *log = r->ray_log;
    if (!log) return;
    if (log->count + count > log->capacity) {
        size_t nc = log->capacity ? log->capacity : 1 << 20;
        while (nc < log->count + count) nc *= 2;
        float *a = realloc(log->org_dir_tfar, nc * 7 * sizeof(float));
        if (!a) return;
        log->org_dir_tfar = a;
        uint8_t *s = realloc(log->is_shadow, nc);
        if (!s) return;
        log->is_shadow = s;
        log->capacity = nc;
    }
    const PathState *ps = &r->ps;
    for (uint32_t i = 0; i < count; ++i) {
        uint32_t p = items[i];
        float *dst = log->org_dir_tfar + 7 * log->count;
        const float *o = shadow ? ps->shadow_org : ps->ray_org;
        const float *d = shadow ? ps->shadow_dir : ps->ray_dir;
        for (int k = 0; k < 3; ++k) { dst[k] = o[3 * p + k]; dst[3 + k] = d[3 * p + k]; }
        dst[6] = shadow ? ps->shadow_tfar[p] : INFINITY;
        log->is_shadow[log->count++] = (uint8_t)shadow;
    }
}

/* Per-thread wavefronts: the batch's slots are cut into one contiguous slice per thread and
 * each thread runs every wave of its slice (sort, trace, shade, shadow) on its own queues,
 * which live in its part of the shared queue arrays. Paths never interact, so this is the same
 * computation as one batch-wide wavefront, with no synchronisation inside a batch: a pool
 * call per stage (thousands per render) had cost a third of the 2-thread speed-up. */
typedef struct SliceStats {
    double generate, sort, trace, shade, shadow;
    uint64_t bounce, shadow_rays;
} SliceStats;

static void run_slice(Renderer *r, uint32_t s0, uint32_t s1, SliceStats *st) {
    PathState *ps = &r->ps;
    uint32_t *rays = r->rays.items + s0, *hits = r->hits.items + s0;
    uint32_t *escaped = r->escaped.items + s0, *shadows = r->shadows.items + s0;
    uint64_t *keys = r->sort_keys + s0, *keys_tmp = r->sort_keys_tmp + s0;
    uint32_t *items_tmp = r->sort_tmp + s0;
    double t0 = now_seconds();
    GenerateCtx g = {r};
    generate_range(&g, s0, s1, 0);
    double t = now_seconds();
    st->generate += t - t0;
    uint32_t nrays = s1 - s0;
    for (uint32_t depth = 0; nrays > 0; ++depth) {
        if (depth > 0) st->bounce += nrays;
        /* sort rays by (direction octant, Morton code of the origin) */
        double ta = now_seconds();
        SortCtx sc = {r, rays, keys};
        ray_keys_range(&sc, 0, nrays, 0);
        radix_sort(rays, keys, nrays, keys_tmp, items_tmp);
        double tb = now_seconds();
        st->sort += tb - ta;
        if (r->ray_log) { /* bench instrumentation: kept out of the stage times */
            pthread_mutex_lock(&r->log_mutex);
            log_rays(r, rays, nrays, 0);
            pthread_mutex_unlock(&r->log_mutex);
            tb = now_seconds();
        }
        TraceCtx tc = {r, rays, depth == 0};
        trace_range(&tc, 0, nrays, 0);
        double tc_end = now_seconds();
        st->trace += tc_end - tb;
        /* partition into hit and escaped queues, in ray-queue order */
        uint32_t nhits = 0, nesc = 0;
        for (uint32_t i = 0; i < nrays; ++i) {
            uint32_t p = rays[i];
            if (isinf(ps->hit_t[p])) escaped[nesc++] = p;
            else hits[nhits++] = p;
        }
        ShadeCtx ec = {r, escaped, depth};
        escaped_range(&ec, 0, nesc, 0);
        /* sorted deferred shading: hits ordered by (geometry, primitive) */
        double td = now_seconds();
        if (nhits > 1) {
            SortCtx hc = {r, hits, keys};
            hit_keys_range(&hc, 0, nhits, 0);
            radix_sort(hits, keys, nhits, keys_tmp, items_tmp);
        }
        double te = now_seconds();
        st->sort += te - td;
        ShadeCtx shc = {r, hits, depth};
        shade_range(&shc, 0, nhits, 0);
        /* compaction, in hit-queue order */
        uint32_t nshadow = 0;
        nrays = 0;
        for (uint32_t i = 0; i < nhits; ++i) {
            uint32_t p = hits[i];
            if (ps->has_shadow[p]) shadows[nshadow++] = p;
            if (ps->continues[p]) rays[nrays++] = p;
        }
        double tf = now_seconds();
        st->shade += tf - te;
        st->shadow_rays += nshadow;
        if (r->ray_log) {
            pthread_mutex_lock(&r->log_mutex);
            log_rays(r, shadows, nshadow, 1);
            pthread_mutex_unlock(&r->log_mutex);
            tf = now_seconds();
        }
        ShadeCtx sh = {r, shadows, depth};
        shadow_range(&sh, 0, nshadow, 0);
        st->shadow += now_seconds() - tf;
    }
}

typedef struct SliceCtx { Renderer *r; uint32_t slices; SliceStats *stats; } SliceCtx;

static void slice_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    SliceCtx *c = vctx;
    for (size_t k = b; k < e; ++k) {
        uint32_t s0 = (uint32_t)((uint64_t)c->r->batch_count * k / c->slices);
        uint32_t s1 = (uint32_t)((uint64_t)c->r->batch_count * (k + 1) / c->slices);
        run_slice(c->r, s0, s1, &c->stats[k]);
    }
}

static void run_batch(Renderer *r) {
    CandelaStats *st = r->stats;
    PathState *ps = &r->ps;
    uint32_t slices = (uint32_t)threadpool_size(r->pool);
    if (slices > MAX_SLICES) slices = MAX_SLICES;
    if (slices > r->batch_count) slices = r->batch_count;
    SliceStats ss[MAX_SLICES];
    memset(ss, 0, sizeof ss);
    SliceCtx c = {r, slices, ss};
    threadpool_parallel_for(r->pool, slices, 1, slice_range, &c);
    /* stage times: summed over the slices that ran concurrently, divided by their number */
    for (uint32_t k = 0; k < slices; ++k) {
        st->time_generate += ss[k].generate / slices;
        st->time_sort += ss[k].sort / slices;
        st->time_trace += ss[k].trace / slices;
        st->time_shade += ss[k].shade / slices;
        st->time_shadow += ss[k].shadow / slices;
        st->rays_bounce += ss[k].bounce;
        st->rays_shadow += ss[k].shadow_rays;
    }
    st->paths += r->batch_count;
    st->rays_camera += r->batch_count;

    /* film: serial, in path order, so every pixel sums its samples in sample order */
    double tg = now_seconds();
    Film *film = &r->film;
    for (uint32_t i = 0; i < r->batch_count; ++i) {
        uint32_t px = ps->pixel[i];
        vec3 L = load3(ps->radiance, i);
        if (!v3_is_finite(L)) L = v3s(0.0f); /* never reached in tests; keeps one bad path from poisoning a pixel */
        film->sum[3 * px] += L.x; film->sum[3 * px + 1] += L.y; film->sum[3 * px + 2] += L.z;
        film->sum2[3 * px] += (double)L.x * L.x;
        film->sum2[3 * px + 1] += (double)L.y * L.y;
        film->sum2[3 * px + 2] += (double)L.z * L.z;
        film->count[px]++;
        if (isfinite(ps->aov_depth[i])) {
            for (int k = 0; k < 3; ++k) {
                film->albedo[3 * px + k] += ps->aov_albedo[3 * i + k];
                film->normal[3 * px + k] += ps->aov_normal[3 * i + k];
            }
            film->depth[px] += ps->aov_depth[i];
            film->hits[px]++;
        }
    }
    st->time_film += now_seconds() - tg;
}

/* ---------------------------------------------------------------- progress */

static void report_progress(Renderer *r, uint64_t done, uint64_t total, int final) {
    if (r->opt->quiet) return;
    double t = now_seconds();
    double elapsed = t - r->render_start;
    double frac = total ? (double)done / (double)total : 1.0;
    double eta = frac > 0.0 ? elapsed * (1.0 - frac) / frac : 0.0;
    if (r->is_tty) {
        if (!final && t - r->progress_last < 0.2) return;
        r->progress_last = t;
        int width = 40, filled = (int)(frac * width);
        char bar[64];
        for (int i = 0; i < width; ++i) bar[i] = i < filled ? '#' : '-';
        bar[width] = 0;
        fprintf(stderr, "\r[%s] %5.1f%%  %6.1fs elapsed  ETA %6.1fs", bar, 100.0 * frac, elapsed, eta);
        if (final) fputc('\n', stderr);
        fflush(stderr);
    } else {
        if (!final && t - r->progress_last < 10.0) return;
        r->progress_last = t;
        fprintf(stderr, "candela: %5.1f%% done, %.1fs elapsed, ETA %.1fs\n", 100.0 * frac, elapsed, eta);
    }
}

/* The iteration barrier: no ray is in flight, so learned state can change without any
 * path seeing two versions of it. Cache points update their visibility weights here
 * (guiding will train here too), then progress is reported. */
static void iteration_barrier(Renderer *r, int iteration, uint64_t done, uint64_t total) {
    r->stats->iterations = iteration + 1;
    /* cache points: Eqs. 5-6 and the visibility blur from this iteration's counters (§3.2) */
    if (r->scene.lights.cachepoints) cachepoints_update_visibility(r->scene.lights.cachepoints);
    report_progress(r, done, total, done == total);
}

/* Peak resident memory of this render. Linux lets a process reset its high-water mark
 * (write "5" to /proc/self/clear_refs), so renders run one after another in one process
 * (candela compare, the tests) each report their own peak; elsewhere getrusage's lifetime
 * maximum is the fallback. */
static void peak_rss_reset(void) {
#ifdef __GLIBC__
    malloc_trim(0); /* hand the previous render's freed heap back first, or it counts here */
#endif
    FILE *f = fopen("/proc/self/clear_refs", "w");
    if (f) { fputs("5", f); fclose(f); }
}

static size_t peak_rss_bytes(void) {
    FILE *f = fopen("/proc/self/status", "r");
    if (f) {
        char line[256];
        size_t kb = 0;
        while (fgets(line, sizeof line, f))
            if (sscanf(line, "VmHWM: %zu kB", &kb) == 1) break;
        fclose(f);
        if (kb > 0) return kb * 1024u;
    }
    struct rusage ru;
    if (getrusage(RUSAGE_SELF, &ru) != 0) return 0;
    return (size_t)ru.ru_maxrss * 1024u;
}

/* ---------------------------------------------------------------- entry */

static int film_alloc(Film *f, int w, int h) {
    int fail = 0;
    size_t n = (size_t)w * (size_t)h;
    memset(f, 0, sizeof *f);
    f->width = w; f->height = h;
    f->sum = xcalloc(3 * n, sizeof(double), &fail);
    f->sum2 = xcalloc(3 * n, sizeof(double), &fail);
    f->albedo = xcalloc(3 * n, sizeof(double), &fail);
    f->normal = xcalloc(3 * n, sizeof(double), &fail);
    f->depth = xcalloc(n, sizeof(double), &fail);
    f->hits = xcalloc(n, sizeof(uint32_t), &fail);
    f->count = xcalloc(n, sizeof(uint32_t), &fail);
    return fail ? -1 : 0;
}

static void film_free(Film *f) {
    free(f->sum); free(f->sum2); free(f->albedo); free(f->normal); free(f->depth); free(f->hits); free(f->count);
    memset(f, 0, sizeof *f);
}

static int film_resolve(const Film *f, CandelaImage *img) {
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
    return 0;
}

void candela_image_free(CandelaImage *img) {
    free(img->rgb); free(img->variance); free(img->albedo); free(img->normal); free(img->depth);
    memset(img, 0, sizeof *img);
}

void candela_ray_log_free(CandelaRayLog *log) {
    free(log->org_dir_tfar);
    free(log->is_shadow);
    memset(log, 0, sizeof *log);
}

static void renderer_free(Renderer *r) {
    path_state_free(&r->ps);
    free(r->rays.items); free(r->hits.items); free(r->escaped.items); free(r->shadows.items);
    free(r->sort_keys); free(r->sort_keys_tmp); free(r->sort_tmp);
    film_free(&r->film);
    if (r->pool) threadpool_destroy(r->pool);
    scene_free(&r->scene);
    pthread_mutex_destroy(&r->log_mutex);
}

int candela_render(const CandelaOptions *o, CandelaImage *image, CandelaStats *stats, CandelaRayLog *ray_log,
                   char err[CANDELA_ERR_LEN]) {
    CandelaStats local_stats;
    if (!stats) stats = &local_stats;
    memset(stats, 0, sizeof *stats);
    memset(image, 0, sizeof *image);
    if (o->spp < 1 || o->max_depth < 0 || o->width < 0 || o->height < 0 || o->width > 16384 || o->height > 16384) {
        snprintf(err, CANDELA_ERR_LEN, "%s: invalid render options (spp >= 1, 0 <= max depth, resolution <= 16384)",
                 o->scene_path ? o->scene_path : "candela");
        return -1;
    }
    Renderer *r = calloc(1, sizeof *r);
    if (!r) { snprintf(err, CANDELA_ERR_LEN, "candela: out of memory"); return -1; }
    r->opt = o;
    pthread_mutex_init(&r->log_mutex, NULL);
    r->stats = stats;
    r->ray_log = ray_log;
    r->is_tty = isatty(2);
    peak_rss_reset();
    double t_start = now_seconds();
    if (scene_load(&r->scene, o, err) != 0) { pthread_mutex_destroy(&r->log_mutex); free(r); return -1; }
    double t_loaded = now_seconds();
    stats->time_load = t_loaded - t_start;
    stats->num_triangles = r->scene.num_triangles_total;
    stats->num_lights = r->scene.lights.count;
    stats->num_instances = r->scene.io.num_instances;

    const Camera *cam = &r->scene.camera;
    r->npixels = (uint32_t)cam->width * (uint32_t)cam->height;
    uint32_t batch = o->batch_size ? o->batch_size : DEFAULT_BATCH_SIZE;
    if (batch > MAX_BATCH_SIZE) batch = MAX_BATCH_SIZE;
    uint64_t max_paths_per_iteration = (uint64_t)r->npixels * (uint64_t)o->spp;
    if (batch > max_paths_per_iteration) batch = (uint32_t)max_paths_per_iteration;
    r->pool = threadpool_create(o->threads);
    int fail = !r->pool || path_state_alloc(&r->ps, batch) != 0 || film_alloc(&r->film, cam->width, cam->height) != 0;
    r->rays.items = xcalloc(batch, sizeof(uint32_t), &fail);
    r->hits.items = xcalloc(batch, sizeof(uint32_t), &fail);
    r->escaped.items = xcalloc(batch, sizeof(uint32_t), &fail);
    r->shadows.items = xcalloc(batch, sizeof(uint32_t), &fail);
    r->sort_keys = xcalloc(batch, sizeof(uint64_t), &fail);
    r->sort_keys_tmp = xcalloc(batch, sizeof(uint64_t), &fail);
    r->sort_tmp = xcalloc(batch, sizeof(uint32_t), &fail);
    if (fail) {
        snprintf(err, CANDELA_ERR_LEN, "%s: out of memory allocating %u paths", o->scene_path, batch);
        renderer_free(r); free(r);
        return -1;
    }
    if (o->light_sampler == CANDELA_LIGHT_SAMPLER_CACHEPOINTS) {
        double tcp = now_seconds();
        if (lights_build_cachepoints(&r->scene, r->pool, o, err) != 0) { renderer_free(r); free(r); return -1; }
        stats->time_cachepoints = now_seconds() - tcp;
        stats->num_cachepoints = cachepoints_count(r->scene.lights.cachepoints);
        stats->cachepoint_candidates = r->scene.lights.cp_stats.candidates;
        stats->cachepoint_bytes = r->scene.lights.cp_stats.bytes;
        stats->cachepoint_mean_near = r->scene.lights.cp_stats.mean_near;
        stats->cachepoint_mean_far = r->scene.lights.cp_stats.mean_far;
        stats->cachepoint_mean_clusters = r->scene.lights.cp_stats.mean_far_clusters;
    }
    stats->time_build = now_seconds() - t_loaded;

    r->render_start = now_seconds();
    int max_iter_spp = o->max_iteration_spp > 0 ? o->max_iteration_spp : DEFAULT_MAX_ITERATION_SPP;
    uint64_t total_paths = (uint64_t)r->npixels * (uint64_t)o->spp, done_paths = 0;
    int spp_done = 0, iteration = 0;
    while (spp_done < o->spp) {
        /* schedule 1, 1, 2, 4, 8, ... capped, summing to spp */
        /* (the shift is bounded: at iteration 32 an unbounded 1 << 31 overflowed and the
         * schedule ran backwards) */
        int spp_i = iteration < 2 ? 1 : (iteration - 1 >= 30 ? max_iter_spp : 1 << (iteration - 1));
        if (spp_i > max_iter_spp) spp_i = max_iter_spp;
        if (spp_i > o->spp - spp_done) spp_i = o->spp - spp_done;
        r->sample_base = (uint64_t)spp_done;
        uint64_t iter_paths = (uint64_t)r->npixels * (uint64_t)spp_i;
        for (uint64_t first = 0; first < iter_paths; first += batch) {
            r->batch_first = first;
            r->batch_count = (uint32_t)((iter_paths - first) < batch ? (iter_paths - first) : batch);
            run_batch(r);
            done_paths += r->batch_count;
            report_progress(r, done_paths, total_paths, 0);
        }
        spp_done += spp_i;
        iteration_barrier(r, iteration, done_paths, total_paths);
        ++iteration;
    }
    stats->time_total = now_seconds() - t_start;
    int rc = film_resolve(&r->film, image);
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s: out of memory resolving the film", o->scene_path);
    stats->peak_memory_bytes = peak_rss_bytes();
    renderer_free(r);
    free(r);
    return rc;
}
