/* renderer/util/sort.h (private): the stable radix sort and Morton codes the renderer sorts with
 * (the wavefront's queues in integrator/queue_sort.c, the cache point candidates in
 * lights/lightselect_cachepoints.c). */
#ifndef CANDELA_SORT_H
#define CANDELA_SORT_H

#include <stdint.h>

/* One LSD pass: the pairs scattered from (k_in, v_in) to (k_out, v_out) by the digit
 * (key >> shift) & (buckets - 1), whose histogram count[] holds; stable. */
static inline void radix_pass(const uint64_t *k_in, const uint32_t *v_in, uint64_t *k_out, uint32_t *v_out, uint32_t n,
                              int shift, uint32_t *count, uint32_t buckets) {
    uint32_t sum = 0;
    for (uint32_t b = 0; b < buckets; ++b) { uint32_t c = count[b]; count[b] = sum; sum += c; }
    for (uint32_t i = 0; i < n; ++i) {
        uint32_t dst = count[(k_in[i] >> shift) & (buckets - 1)]++;
        k_out[dst] = k_in[i];
        v_out[dst] = v_in[i];
    }
}

/* Stable LSD radix sort of (keys[i], items[i]) pairs by key; scratch of length n each. */
void radix_sort_pairs(uint32_t *items, uint64_t *keys, uint32_t n, uint64_t *keys_tmp, uint32_t *items_tmp);

/* The low 21 bits of x spread to every third bit (x0 -> bit 0, x1 -> bit 3, ...): one axis of
 * a Morton code. */
static inline uint64_t morton_spread21(uint64_t x) {
    x &= 0x1fffff;
    x = (x | x << 32) & 0x1f00000000ffffull;
    x = (x | x << 16) & 0x1f0000ff0000ffull;
    x = (x | x << 8) & 0x100f00f00f00f00full;
    x = (x | x << 4) & 0x10c30c30c30c30c3ull;
    x = (x | x << 2) & 0x1249249249249249ull;
    return x;
}

#endif
