/* renderer/util/sort.c: radix_sort_pairs, the full stable sort of (key, item) pairs (sort.h has
 * its users; the wavefront's queue sorts are integrator/queue_sort.c's). */
#include <string.h>

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
        radix_pass(k_in, v_in, k_out, v_out, n, shift, count, RADIX_BUCKETS);
        uint64_t *tk = k_in; k_in = k_out; k_out = tk;
        uint32_t *tv = v_in; v_in = v_out; v_out = tv;
    }
    if (v_in != items) memcpy(items, v_in, n * sizeof *items);
}
