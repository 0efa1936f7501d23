/* tests/test_kdtree.c: cachepoints kd-tree against brute force. For many point sets
 * (uniform, clustered, duplicates, plane, line, integer grid with distance ties, huge
 * coordinates overflowing to infinity, tiny ones underflowing to zero, NaN points, 0, 1
 * and a few points), random queries with random k, radius and exclude must return exactly
 * the brute-force (squared distance, index) order with bit-identical distances; 1-NN
 * likewise. Prints (does not assert) build and query timings on 1.1M points. */
#include "check.h"
#include "kdtree.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

static uint64_t sm_state;

static uint64_t sm_next(void) { /* splitmix64 */
    uint64_t z = (sm_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static float rnd01(void) { return (float)(sm_next() >> 40) * 0x1p-24f; }
static float rnd(float a, float b) { return a + (b - a) * rnd01(); }
static uint32_t rndu(uint32_t n) { return (uint32_t)(((sm_next() >> 32) * n) >> 32); }

/* The documented distance formula (kdtree.h). */
static float dist2(const float *p, const float *q) {
    float dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
    return dx * dx + dy * dy + dz * dz;
}

typedef struct {
    float d;
    uint32_t i;
} Cand;

static int cand_cmp(const void *a, const void *b) {
    const Cand *x = a, *y = b;
    if (x->d < y->d) return -1;
    if (x->d > y->d) return 1;
    return (x->i > y->i) - (x->i < y->i);
}

static uint32_t brute_knn(const float *pts, uint32_t n, const float *q, uint32_t k, float r2, uint32_t excl,
                          Cand *scratch, uint32_t *out_i, float *out_d) {
    uint32_t m = 0;
    for (uint32_t i = 0; i < n; ++i) {
        if (i == excl) continue;
        float d = dist2(&pts[3 * (size_t)i], q);
        if (d <= r2) scratch[m++] = (Cand){d, i};
    }
    qsort(scratch, m, sizeof *scratch, cand_cmp);
    if (m > k) m = k;
    for (uint32_t j = 0; j < m; ++j) {
        out_i[j] = scratch[j].i;
        out_d[j] = scratch[j].d;
    }
    return m;
}

static uint32_t brute_nearest(const float *pts, uint32_t n, const float *q, float *out_d) {
    float bd = INFINITY;
    uint32_t bi = UINT32_MAX;
    for (uint32_t i = 0; i < n; ++i) {
        float d = dist2(&pts[3 * (size_t)i], q);
        if (d < bd || (d == bd && i < bi)) {
            bd = d;
            bi = i;
        }
    }
    *out_d = bd;
    return bi;
}

static int same_bits(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

enum { MAXK = 64 };

static long shortcuts_taken; /* hint queries answered by the clearance shortcut */

/* Random queries against brute force on one point set. */
static void check_set(const char *name, const float *pts, uint32_t n, int queries) {
    KdTree tree;
    int rc = kdtree_build(&tree, pts, n);
    CHECK(rc == 0, "%s: build failed", name);
    if (rc) return;
    /* every other set: the clearance shortcut of kdtree_nearest_hint (must not change answers) */
    static int with_clearance = 0;
    with_clearance = !with_clearance;
    if (with_clearance) CHECK(kdtree_build_clearance(&tree) == 0, "%s: clearance failed", name);
    Cand *scratch = malloc(((size_t)n + 1) * sizeof *scratch);
    int fails = 0;
    for (int qi = 0; qi < queries && fails < 5; ++qi) {
        /* query: random in the (rough) domain, at a point, or near a point */
        float q[3];
        int qt = (int)rndu(3);
        if (n == 0 || qt == 0) {
            for (int c = 0; c < 3; ++c) q[c] = rnd(-1.5f, 1.5f);
        } else {
            uint32_t pi = rndu(n);
            for (int c = 0; c < 3; ++c) {
                float v = pts[3 * (size_t)pi + c];
                if (!isfinite(v)) v = 0.0f;
                q[c] = qt == 1 ? v : v + rnd(-1e-3f, 1e-3f);
            }
        }
        /* k: 1..40, sometimes 0 or beyond count */
        uint32_t k = 1 + rndu(40);
        uint32_t kt = rndu(20);
        if (kt == 0) k = 0;
        if (kt == 1) k = n + 1 + rndu(3);
        if (k > MAXK) k = MAXK;
        /* radius: infinite, zero, random, or exactly some point's distance (boundary tie) */
        float r2;
        switch (rndu(5)) {
        case 0: r2 = INFINITY; break;
        case 1: r2 = 0.0f; break;
        case 2: r2 = rnd01() * rnd01() * 0.5f; break;
        case 3: r2 = n ? dist2(&pts[3 * (size_t)rndu(n)], q) : 1.0f; break;
        default: r2 = INFINITY; break;
        }
        if (isnan(r2)) r2 = INFINITY;
        /* exclude: none, a random point, out of range */
        uint32_t excl;
        switch (rndu(4)) {
        case 0: excl = UINT32_MAX; break;
        case 1: excl = n ? rndu(n) : 0; break;
        case 2: excl = n + rndu(3); break;
        default: excl = UINT32_MAX; break;
        }

        uint32_t ti[MAXK], bi[MAXK], ti2[MAXK];
        float td[MAXK], bd[MAXK];
        for (int j = 0; j < MAXK; ++j) ti[j] = ti2[j] = 0xDEADBEEFu;
        uint32_t bn = brute_knn(pts, n, q, k, r2, excl, scratch, bi, bd);
        uint32_t tn = kdtree_knn(&tree, q, k, r2, excl, ti, td);
        uint32_t tn2 = kdtree_knn(&tree, q, k, r2, excl, ti2, NULL);
        int ok = tn == bn && tn2 == bn;
        for (uint32_t j = 0; ok && j < bn; ++j)
            ok = ti[j] == bi[j] && ti2[j] == bi[j] && same_bits(td[j], bd[j]);
        for (uint32_t j = bn; ok && j < MAXK; ++j) ok = ti[j] == 0xDEADBEEFu && ti2[j] == 0xDEADBEEFu;
        CHECK(ok, "%s: knn q=(%g %g %g) k=%u r2=%g excl=%u: tree %u/%u vs brute %u (first %u/%u vs %u)", name,
              (double)q[0], (double)q[1], (double)q[2], k, (double)r2, excl, tn, tn2, bn, tn ? ti[0] : 0,
              tn2 ? ti2[0] : 0, bn ? bi[0] : 0);
        fails += !ok;

        float nd, bnd;
        uint32_t ni = kdtree_nearest(&tree, q, &nd);
        uint32_t bni = brute_nearest(pts, n, q, &bnd);
        ok = ni == bni && (n == 0 || same_bits(nd, bnd)) && kdtree_nearest(&tree, q, NULL) == bni;
        /* a guess (a random point, the exact answer, the last point) never changes the answer */
        if (n > 0) {
            float hd;
            uint32_t guesses[3] = {(uint32_t)((unsigned)qi * 7919u) % n, bni, n - 1};
            for (int g = 0; g < 3 && ok; ++g) {
                ok = kdtree_nearest_hint(&tree, q, guesses[g], &hd) == bni && same_bits(hd, bnd);
                if (tree.clear2 && dist2(&pts[3 * (size_t)guesses[g]], q) < tree.clear2[guesses[g]])
                    ++shortcuts_taken;
            }
        }
        CHECK(ok, "%s: nearest q=(%g %g %g): tree %u (%g) vs brute %u (%g)", name, (double)q[0], (double)q[1],
              (double)q[2], ni, (double)nd, bni, (double)bnd);
        fails += !ok;
    }
    free(scratch);
    kdtree_free(&tree);
}

static float *alloc_pts(uint32_t n) { return malloc((size_t)(n ? n : 1) * 3 * sizeof(float)); }

static void test_sets(void) {
    const int Q = 400;
    uint32_t n;
    float *p;

    /* empty and single point */
    p = alloc_pts(1);
    p[0] = 0.25f, p[1] = -0.5f, p[2] = 1.0f;
    check_set("empty", p, 0, 50);
    check_set("single", p, 1, 100);
    free(p);
    {
        KdTree t;
        CHECK(kdtree_build(&t, NULL, 0) == 0, "empty build");
        float q[3] = {0, 0, 0}, d = 0;
        uint32_t idx[4];
        CHECK(kdtree_nearest(&t, q, &d) == UINT32_MAX && isinf(d), "empty nearest");
        CHECK(kdtree_knn(&t, q, 4, INFINITY, UINT32_MAX, idx, NULL) == 0, "empty knn");
        kdtree_free(&t);
        float one[3] = {1, 2, 3};
        CHECK(kdtree_build(&t, one, 1) == 0, "single build");
        CHECK(kdtree_knn(&t, q, 4, INFINITY, 0, idx, NULL) == 0, "single knn excluding itself");
        CHECK(kdtree_knn(&t, q, 4, INFINITY, 1, idx, NULL) == 1 && idx[0] == 0, "single knn");
        CHECK(kdtree_knn(&t, one, 4, 0.0f, UINT32_MAX, idx, NULL) == 1, "single knn radius 0");
        CHECK(kdtree_knn(&t, q, 4, 13.99f, UINT32_MAX, idx, NULL) == 0, "single knn out of radius");
        kdtree_free(&t);
    }

    /* small random sets (leaf-only and a few levels) */
    for (int s = 0; s < 40; ++s) {
        n = 2 + rndu(60);
        p = alloc_pts(n);
        for (uint32_t i = 0; i < 3 * n; ++i) p[i] = rnd(-1, 1);
        check_set("small", p, n, 60);
        free(p);
    }

    /* uniform */
    n = 5000;
    p = alloc_pts(n);
    for (uint32_t i = 0; i < 3 * n; ++i) p[i] = rnd(-1, 1);
    check_set("uniform", p, n, Q);
    free(p);

    /* clustered */
    n = 6000;
    p = alloc_pts(n);
    {
        float cc[16][3];
        for (int c = 0; c < 16; ++c)
            for (int a = 0; a < 3; ++a) cc[c][a] = rnd(-1, 1);
        for (uint32_t i = 0; i < n; ++i) {
            int c = (int)rndu(16);
            float s = (c & 1) ? 1e-3f : 3e-2f;
            for (int a = 0; a < 3; ++a) p[3 * i + a] = cc[c][a] + s * (rnd01() + rnd01() + rnd01() - 1.5f);
        }
    }
    check_set("clustered", p, n, Q);
    free(p);

    /* many duplicates: 7 distinct positions, plus identical runs */
    n = 3000;
    p = alloc_pts(n);
    {
        float pos[7][3];
        for (int c = 0; c < 7; ++c)
            for (int a = 0; a < 3; ++a) pos[c][a] = rnd(-1, 1);
        for (uint32_t i = 0; i < n; ++i) memcpy(&p[3 * i], pos[rndu(7)], sizeof pos[0]);
    }
    check_set("duplicates", p, n, Q);
    for (uint32_t i = 0; i < n; ++i) p[3 * i] = 0.5f, p[3 * i + 1] = -0.25f, p[3 * i + 2] = 0.125f;
    check_set("all identical", p, n, Q);
    free(p);

    /* plane z = 0.3 and a line */
    n = 4000;
    p = alloc_pts(n);
    for (uint32_t i = 0; i < n; ++i) p[3 * i] = rnd(-1, 1), p[3 * i + 1] = rnd(-1, 1), p[3 * i + 2] = 0.3f;
    check_set("plane", p, n, Q);
    for (uint32_t i = 0; i < n; ++i) p[3 * i] = 0.1f, p[3 * i + 1] = rnd(-1, 1), p[3 * i + 2] = -0.2f;
    check_set("line", p, n, Q);
    /* integer grid (lots of exact distance ties and duplicates) */
    for (uint32_t i = 0; i < 3 * n; ++i) p[i] = (float)((int)rndu(5) - 2) * 0.5f;
    check_set("grid", p, n, Q);
    /* sorted input along x (pivot robustness) */
    for (uint32_t i = 0; i < n; ++i) p[3 * i] = (float)i / (float)n, p[3 * i + 1] = 0, p[3 * i + 2] = 0;
    check_set("sorted", p, n, Q);
    /* tiny coordinates: squares underflow to zero, so many points are at distance 0 */
    for (uint32_t i = 0; i < 3 * n; ++i) p[i] = rnd(-1, 1) * 1e-22f;
    check_set("tiny", p, n, Q);
    /* huge coordinates: squared distances overflow to infinity; a few infinite points */
    for (uint32_t i = 0; i < 3 * n; ++i) p[i] = rnd(-1, 1) * (rndu(2) ? 3e19f : 1.0f);
    for (int j = 0; j < 10; ++j) p[rndu(3 * n)] = rndu(2) ? INFINITY : -INFINITY;
    check_set("huge", p, n, Q);
    /* NaN points are never returned */
    for (uint32_t i = 0; i < 3 * n; ++i) p[i] = rnd(-1, 1);
    for (int j = 0; j < 200; ++j) p[rndu(3 * n)] = NAN;
    check_set("nan points", p, n, Q);
    free(p);
}

/* Large k (heap path) including k = count and exclude. */
static void test_large_k(void) {
    uint32_t n = 700;
    float *p = alloc_pts(n);
    for (uint32_t i = 0; i < 3 * n; ++i) p[i] = (float)((int)rndu(7) - 3) * 0.25f; /* ties */
    KdTree t;
    CHECK(kdtree_build(&t, p, n) == 0, "build");
    Cand *scratch = malloc(n * sizeof *scratch);
    uint32_t *ti = malloc(n * sizeof *ti), *bi = malloc(n * sizeof *bi), *ti2 = malloc(n * sizeof *ti2);
    float *td = malloc(n * sizeof *td), *bd = malloc(n * sizeof *bd);
    for (int it = 0; it < 60; ++it) {
        float q[3] = {rnd(-1, 1), rnd(-1, 1), rnd(-1, 1)};
        uint32_t k = it < 10 ? n : 33 + rndu(n - 33);
        float r2 = (it & 1) ? INFINITY : rnd(0, 2);
        uint32_t excl = (it & 2) ? rndu(n) : UINT32_MAX;
        uint32_t bn = brute_knn(p, n, q, k, r2, excl, scratch, bi, bd);
        uint32_t tn = kdtree_knn(&t, q, k, r2, excl, ti, td);
        uint32_t tn2 = kdtree_knn(&t, q, k, r2, excl, ti2, NULL);
        int ok = tn == bn && tn2 == bn;
        for (uint32_t j = 0; ok && j < bn; ++j) ok = ti[j] == bi[j] && ti2[j] == bi[j] && same_bits(td[j], bd[j]);
        CHECK(ok, "large k=%u r2=%g excl=%u: %u/%u vs %u", k, (double)r2, excl, tn, tn2, bn);
    }
    free(scratch), free(ti), free(bi), free(ti2), free(td), free(bd);
    kdtree_free(&t);
    free(p);
}

static void timings(void) {
    uint32_t n = 1100000;
    float *p = alloc_pts(n);
    for (uint32_t i = 0; i < 3 * n; ++i) p[i] = rnd(-10, 10);
    KdTree t;
    double t0 = test_seconds();
    int rc = kdtree_build(&t, p, n);
    double t1 = test_seconds();
    CHECK(rc == 0, "1.1M build");
    if (rc) {
        free(p);
        return;
    }
    uint32_t nq = 100000, idx[20];
    float d[20];
    uint64_t sum = 0;
    double t2 = test_seconds();
    for (uint32_t i = 0; i < nq; ++i) {
        uint32_t pi = (uint32_t)(((uint64_t)i * 2654435761u) % n);
        sum += kdtree_knn(&t, &p[3 * (size_t)pi], 20, INFINITY, pi, idx, d);
    }
    double t3 = test_seconds();
    CHECK(sum == (uint64_t)nq * 20, "knn(20) counts");
    kdtree_free(&t);

    uint32_t n2 = 100000, nq2 = 500000;
    CHECK(kdtree_build(&t, p, n2) == 0, "100k build");
    double t4 = test_seconds();
    for (uint32_t i = 0; i < nq2; ++i) {
        float q[3] = {rnd(-10, 10), rnd(-10, 10), rnd(-10, 10)};
        sum += kdtree_nearest(&t, q, NULL);
    }
    double t5 = test_seconds();
    kdtree_free(&t);
    fprintf(stderr, "timing: build 1.1M points %.3f s; 100k knn(20) on 1.1M %.3f s (%.2f us/query); "
                    "1-NN on 100k points %.3f us/query (%llu)\n",
            t1 - t0, t3 - t2, (t3 - t2) / nq * 1e6, (t5 - t4) / nq2 * 1e6, (unsigned long long)(sum & 1));
    free(p);
}

int main(void) {
    sm_state = 0x4B44545245453031ull;
    test_sets();
    CHECK(shortcuts_taken > 100, "the clearance shortcut was exercised only %ld times", shortcuts_taken);
    test_large_k();
    timings();
    return test_exit();
}
