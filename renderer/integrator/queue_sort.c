/* renderer/integrator/queue_sort.c: the wavefront's queue sorts. Rays are sorted by (direction
 * octant, Morton code of the origin) so Embree traces coherent packets; hits by (glTF primitive,
 * Morton code of the hit point) so shading visits one material at a time, and consecutive
 * vertices are near each other (they share the light sampler's per-vertex lookups and texture
 * tiles: a large quad's two triangles say nothing about where on it a hit lies). The keys are
 * made where a path joins a queue (sort_key_ray, sort_key_hit); both sorts are stable radix
 * sorts of the keys' leading bits, so equal keys keep queue order, which is deterministic. */
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "integrator.h"
#include "sort.h"

/* The queue sorts only need coherence, not a total order: the keys' top QUEUE_KEY_BITS varying
 * bits are sorted, 8 bits a pass (at most three passes over 256 buckets: a slice holds a few
 * thousand paths, and 2,048-bucket passes had cost as much in bucket upkeep as in items). Keys
 * equal in those bits keep queue order, which is deterministic; the image never depends on the
 * order anyway (each path owns its random numbers and its film slot). */
#define QUEUE_KEY_BITS 24
#define QUEUE_DIGIT_BITS 8
#define QUEUE_BUCKETS (1u << QUEUE_DIGIT_BITS)
static void radix_sort_queue(uint32_t *items, uint64_t *keys, uint32_t n, uint64_t *keys_tmp, uint32_t *items_tmp) {
    if (n < 2) return;
    uint64_t any = 0, all = ~0ull;
    for (uint32_t i = 0; i < n; ++i) { any |= keys[i]; all &= keys[i]; }
    uint64_t varying = any ^ all;
    if (!varying) return;
    int top = 63 - __builtin_clzll(varying);
    int low = top + 1 - QUEUE_KEY_BITS > 0 ? top + 1 - QUEUE_KEY_BITS : 0;
    enum { PASSES = QUEUE_KEY_BITS / QUEUE_DIGIT_BITS };
    uint32_t count[PASSES][QUEUE_BUCKETS];
    int shifts[PASSES], passes = 0;
    for (int shift = low; shift <= top; shift += QUEUE_DIGIT_BITS)
        if ((varying >> shift) & (QUEUE_BUCKETS - 1)) shifts[passes++] = shift;
    /* every pass's histogram in one read of the keys */
    memset(count, 0, sizeof count);
    for (uint32_t i = 0; i < n; ++i)
        for (int k = 0; k < passes; ++k) count[k][(keys[i] >> shifts[k]) & (QUEUE_BUCKETS - 1)]++;
    uint64_t *k_in = keys, *k_out = keys_tmp;
    uint32_t *v_in = items, *v_out = items_tmp;
    for (int k = 0; k < passes; ++k) {
        radix_pass(k_in, v_in, k_out, v_out, n, shifts[k], count[k], QUEUE_BUCKETS);
        uint64_t *tk = k_in; k_in = k_out; k_out = tk;
        uint32_t *tv = v_in; v_in = v_out; v_out = tv;
    }
    if (v_in != items) memcpy(items, v_in, n * sizeof *items);
}

/* 5 bits spread to every third bit: a 10-bit axis of the Morton codes below is two lookups */
static const uint16_t SPREAD5[32] = {
    0x0000, 0x0001, 0x0008, 0x0009, 0x0040, 0x0041, 0x0048, 0x0049, 0x0200, 0x0201, 0x0208,
    0x0209, 0x0240, 0x0241, 0x0248, 0x0249, 0x1000, 0x1001, 0x1008, 0x1009, 0x1040, 0x1041,
    0x1048, 0x1049, 0x1200, 0x1201, 0x1208, 0x1209, 0x1240, 0x1241, 0x1248, 0x1249};
static inline uint32_t spread10(uint32_t q) { return (uint32_t)SPREAD5[q & 31] | (uint32_t)SPREAD5[(q >> 5) & 31] << 15; }

void sort_init(Integrator *ig) {
    const Scene *scene = ig->scene;
    vec3 ext = v3_sub(scene->bounds_max, scene->bounds_min);
    const float cells = 1024.0f;
    ig->sort_origin = scene->bounds_min;
    ig->sort_scale = v3(cells / fmaxf(ext.x, 1e-20f), cells / fmaxf(ext.y, 1e-20f), cells / fmaxf(ext.z, 1e-20f));
}

/* 30-bit Morton code of p on a 1024^3 grid over the scene bounds (a point outside, or NaN,
 * goes to the nearest cell, or cell 0) */
static inline uint64_t morton30(const Integrator *ig, vec3 p) {
    uint32_t q[4];
#if defined(__SSE2__)
    /* the three axes in one register: max and min instructions return their second operand
     * for NaN, so NaN lands in cell 0 */
    __m128 f = _mm_mul_ps(_mm_sub_ps(_mm_setr_ps(p.x, p.y, p.z, 0.0f), _mm_setr_ps(ig->sort_origin.x, ig->sort_origin.y, ig->sort_origin.z, 0.0f)),
                          _mm_setr_ps(ig->sort_scale.x, ig->sort_scale.y, ig->sort_scale.z, 0.0f));
    f = _mm_min_ps(_mm_max_ps(f, _mm_setzero_ps()), _mm_set1_ps(1023.0f));
    _mm_storeu_si128((__m128i *)q, _mm_cvttps_epi32(f));
#else
    vec3 f = v3_mul(v3_sub(p, ig->sort_origin), ig->sort_scale);
    float c[3] = {f.x, f.y, f.z};
    for (int k = 0; k < 3; ++k) {
        float v = c[k] > 0.0f ? c[k] : 0.0f;
        q[k] = (uint32_t)(v < 1023.0f ? v : 1023.0f);
    }
#endif
    return (uint64_t)(spread10(q[0]) | spread10(q[1]) << 1 | spread10(q[2]) << 2);
}

uint64_t sort_key_ray(const Integrator *ig, const SceneRay *r) {
    vec3 d = r->dir;
    uint64_t oct = (uint64_t)((d.x < 0) | ((d.y < 0) << 1) | ((d.z < 0) << 2));
    return oct << 30 | morton30(ig, r->org);
}

uint64_t sort_key_hit(const Integrator *ig, const SceneRay *r, const SceneHit *h) {
    const Scene *scene = ig->scene;
    uint64_t primitive = scene->io.meshes[scene->instances[h->instance].mesh].first_primitive + h->local_prim;
    return primitive << 30 | morton30(ig, v3_madd(r->org, r->dir, h->t));
}

void sort_rays(const Integrator *ig, Slice *s) {
    (void)ig;
    if (s->wave == 0) return; /* camera rays, in pixel order (stage_generate makes no keys) */
    radix_sort_queue(s->rays, s->keys, s->num_rays, s->keys_tmp, s->items_tmp);
}

void sort_hits(const Integrator *ig, Slice *s) {
    (void)ig;
    radix_sort_queue(s->hits, s->keys, s->num_hits, s->keys_tmp, s->items_tmp);
}
