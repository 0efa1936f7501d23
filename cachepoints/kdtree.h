/* cachepoints/kdtree.h (private): a static 3-D kd-tree over points for the cache point
 * build (k nearest neighbours within a radius) and render-time lookup (1 nearest).
 *
 * Deterministic: distance ties are broken by point index (lower index first), so results
 * never depend on build or query order. The tree stores indices into the caller's point
 * array; the caller keeps the array alive and unchanged while the tree is used.
 *
 * Distances are squared Euclidean distances computed in float, exactly as
 *     float dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
 *     float d2 = dx * dx + dy * dy + dz * dz;      (left to right, no FMA contraction)
 * so results are bit-identical to a brute-force sort of all points by (d2, index) with that
 * formula (GCC/Clang in ISO C mode do not contract; x86-64 baseline has no FMA anyway).
 * Points with NaN coordinates are never returned. */
#ifndef CANDELA_KDTREE_H
#define CANDELA_KDTREE_H

#include <stddef.h>
#include <stdint.h>

typedef struct KdTree {
    const float *points;   /* 3 floats per point (caller-owned) */
    uint32_t count;
    /* private: implicit median-split layout over positions [0, count); a range [lo, hi)
     * larger than a leaf has its splitting point at mid = lo + (hi - lo) / 2 and children
     * [lo, mid), [mid + 1, hi). */
    void *nodes;           /* count x {x, y, z, index}: point copies in tree order */
    uint8_t *axes;         /* count: split axis of the range whose mid is this position */
    size_t num_nodes;      /* == count */
    float *clear2;         /* optional (kdtree_build_clearance): per point, a squared radius
                            * inside which it is certainly the nearest point */
} KdTree;

/* Build over points[0 .. count) (3 floats each). 0 ok, -1 out of memory. count may be 0. */
int kdtree_build(KdTree *tree, const float *points, uint32_t count);
void kdtree_free(KdTree *tree);

/* Up to k nearest points to q with squared distance <= radius2 (INFINITY: no limit),
 * sorted by (distance, index) ascending. `exclude` (or UINT32_MAX) is skipped, so a point
 * can ask for its neighbours without itself. Writes indices (and squared distances if
 * dist2 != NULL); returns how many were found. Thread-safe (read-only). */
uint32_t kdtree_knn(const KdTree *tree, const float q[3], uint32_t k, float radius2, uint32_t exclude,
                    uint32_t *indices, float *dist2);

/* Optional, after kdtree_build: per point the squared radius c^2 nn^2 (nn: distance to its
 * nearest other point, c = 0.49) inside which no other point can be nearer, so that
 * kdtree_nearest_hint answers without a traversal when q lies that close to the hint (the
 * triangle inequality leaves a 2% margin, far above float rounding). 0 ok, -1 out of memory. */
int kdtree_build_clearance(KdTree *tree);

/* The nearest point (ties: lowest index); UINT32_MAX when the tree is empty. */
uint32_t kdtree_nearest(const KdTree *tree, const float q[3], float *dist2);
/* The same with a guess (any point index, e.g. the previous query's answer for a coherent
 * stream of queries): its distance bounds the search, the result is identical. */
uint32_t kdtree_nearest_hint(const KdTree *tree, const float q[3], uint32_t hint, float *dist2);

#endif
