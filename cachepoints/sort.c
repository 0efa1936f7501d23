/* cachepoints/sort.c: the deterministic sorts and selections of the build (declared in
 * build_internal.h). None allocates; every order is total, so results never depend on
 * the input order of equal elements or on the thread that runs them. */
#include <string.h>

#include "build_internal.h"

static void sift_down_u64(uint64_t *a, size_t root, size_t n) {
    for (;;) {
        size_t child = 2 * root + 1;
        if (child >= n) break;
        if (child + 1 < n && a[child] < a[child + 1]) ++child;
        if (!(a[root] < a[child])) break;
        uint64_t t = a[root]; a[root] = a[child]; a[child] = t;
        root = child;
    }
}

void cp_sort_u64(uint64_t *a, size_t n) {
    for (size_t start = n / 2; start-- > 0;) sift_down_u64(a, start, n);
    for (size_t end = n; end > 1; --end) {
        uint64_t t = a[0]; a[0] = a[end - 1]; a[end - 1] = t;
        sift_down_u64(a, 0, end - 1);
    }
}

void cp_sort_by_key(uint64_t *a, uint64_t *tmp, uint32_t n) {
    for (int byte = 4; byte < 8; ++byte) {
        uint32_t count[256] = {0};
        int shift = 8 * byte;
        for (uint32_t i = 0; i < n; ++i) count[(a[i] >> shift) & 0xff]++;
        if (n == 0 || count[(a[0] >> shift) & 0xff] == n) continue;
        uint32_t sum = 0;
        for (int d = 0; d < 256; ++d) { uint32_t c = count[d]; count[d] = sum; sum += c; }
        for (uint32_t i = 0; i < n; ++i) tmp[count[(a[i] >> shift) & 0xff]++] = a[i];
        memcpy(a, tmp, n * sizeof *a);
    }
}

/* ---- selections under (value desc, id asc): quickselect-style partitions, O(n) expected.
 * The far-bin rule needs only the membership of a prefix of the sorted order, never its
 * order. */

static inline int vi_before(const ValueIndex *a, const ValueIndex *b) {
    return a->v > b->v || (a->v == b->v && a->id < b->id);
}

static void vi_insertion_sort(ValueIndex *a, uint32_t n) {
    for (uint32_t i = 1; i < n; ++i) {
        ValueIndex x = a[i];
        uint32_t j = i;
        while (j > 0 && vi_before(&x, &a[j - 1])) { a[j] = a[j - 1]; --j; }
        a[j] = x;
    }
}

/* Partitions a[lo, hi) around a median-of-three pivot; returns the pivot's final index. */
static uint32_t vi_partition(ValueIndex *a, uint32_t lo, uint32_t hi) {
    uint32_t mid = lo + (hi - lo) / 2, last = hi - 1;
    if (vi_before(&a[mid], &a[lo])) { ValueIndex t = a[mid]; a[mid] = a[lo]; a[lo] = t; }
    if (vi_before(&a[last], &a[lo])) { ValueIndex t = a[last]; a[last] = a[lo]; a[lo] = t; }
    if (vi_before(&a[mid], &a[last])) { ValueIndex t = a[mid]; a[mid] = a[last]; a[last] = t; }
    ValueIndex pivot = a[last]; /* the median */
    uint32_t store = lo;
    for (uint32_t i = lo; i < last; ++i)
        if (vi_before(&a[i], &pivot)) { ValueIndex t = a[i]; a[i] = a[store]; a[store] = t; ++store; }
    ValueIndex t = a[store]; a[store] = a[last]; a[last] = t;
    return store;
}

uint32_t cp_select_energy_prefix(ValueIndex *a, uint32_t n, double target) {
    uint32_t lo = 0, hi = n;
    double acc = 0.0;
    while (hi - lo > 24) {
        uint32_t p = vi_partition(a, lo, hi);
        double before = 0.0;
        for (uint32_t i = lo; i < p; ++i) before += a[i].v;
        if (acc + before >= target) { hi = p; continue; }
        acc += before + a[p].v;
        if (acc >= target) return p + 1;
        lo = p + 1;
    }
    vi_insertion_sort(a + lo, hi - lo);
    for (uint32_t i = lo; i < hi; ++i) {
        acc += a[i].v;
        if (acc >= target) return i + 1;
    }
    return hi < n ? hi : n;
}

void cp_select_top(ValueIndex *a, uint32_t n, uint32_t k) {
    uint32_t lo = 0, hi = n;
    while (hi - lo > 24 && k > lo && k < hi) {
        uint32_t p = vi_partition(a, lo, hi);
        if (p == k || p + 1 == k) return;
        if (p > k) hi = p;
        else lo = p + 1;
    }
    vi_insertion_sort(a + lo, hi - lo);
}
