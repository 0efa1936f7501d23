/* renderer/sort.c: the wavefront's queue sorts. Rays are sorted by (direction octant, Morton
 * code of the origin) so Embree traces coherent packets; hits by (glTF primitive, Morton code of
 * the hit point) so shading visits one material at a time, and consecutive vertices are near
 * each other (they share the light sampler's per-vertex lookups and texture tiles: a large quad's two triangles say
 * nothing about where on it a hit lies). Both are stable radix sorts, so equal keys keep queue
 * order, which is deterministic. */
#include <string.h>

#include "integrator.h"
#include "sort.h"

/* LSD radix sort of (key, item) pairs, 11 bits a pass; digits that are the same in every key
 * are skipped. keys_tmp / items_tmp are scratch of length n. */
#define RADIX_BITS 11
#define RADIX_BUCKETS (1u << RADIX_BITS)
void radix_sort_pairs(uint32_t *items, uint64_t *keys, uint32_t n, uint64_t *keys_tmp, uint32_t *items_tmp) {
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

/* 30-bit Morton code of p quantised over the scene bounds (10 bits per axis) */
static inline uint64_t morton30(const Scene *scene, vec3 p) {
    vec3 lo = scene->bounds_min;
    vec3 ext = v3_sub(scene->bounds_max, lo);
    const float cells = 1024.0f;
    float f[3] = {(p.x - lo.x) / fmaxf(ext.x, 1e-20f), (p.y - lo.y) / fmaxf(ext.y, 1e-20f),
                  (p.z - lo.z) / fmaxf(ext.z, 1e-20f)};
    uint64_t q[3];
    for (int k = 0; k < 3; ++k) {
        float v = clampf(f[k], 0.0f, 0.999f) * cells;
        q[k] = isfinite(v) ? (uint64_t)v : 0;
    }
    return morton_spread21(q[0]) | morton_spread21(q[1]) << 1 | morton_spread21(q[2]) << 2;
}

void sort_rays(const Integrator *ig, Slice *s) {
    const PathState *ps = &ig->ps;
    for (uint32_t i = 0; i < s->num_rays; ++i) {
        const SceneRay *r = &ps->ray[s->rays[i]];
        vec3 d = r->dir;
        uint64_t oct = (uint64_t)((d.x < 0) | ((d.y < 0) << 1) | ((d.z < 0) << 2));
        s->keys[i] = oct << 30 | morton30(ig->scene, r->org);
    }
    radix_sort_pairs(s->rays, s->keys, s->num_rays, s->keys_tmp, s->items_tmp);
}

void sort_hits(const Integrator *ig, Slice *s) {
    if (s->num_hits < 2) return;
    const PathState *ps = &ig->ps;
    const Scene *scene = ig->scene;
    for (uint32_t i = 0; i < s->num_hits; ++i) {
        uint32_t p = s->hits[i];
        const SceneHit *h = &ps->hit[p];
        uint64_t primitive = scene->io.meshes[scene->instances[h->instance].mesh].first_primitive + h->local_prim;
        vec3 hp = v3_madd(ps->ray[p].org, ps->ray[p].dir, h->t);
        s->keys[i] = primitive << 30 | morton30(scene, hp);
    }
    radix_sort_pairs(s->hits, s->keys, s->num_hits, s->keys_tmp, s->items_tmp);
}
