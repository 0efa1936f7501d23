/* renderer/sort.h (private): the stable radix sort and Morton codes the renderer sorts with
 * (the wavefront's queues in sort.c, the cache point candidates in lightselect_cachepoints.c). */
#ifndef CANDELA_SORT_H
#define CANDELA_SORT_H

#include <stdint.h>

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
