/* guiding/sdtree.c: the guiding field of guiding.h, Practical Path Guiding's SD-tree
 * (Müller, Gross, Novák 2017, "Practical Path Guiding for Efficient Light-Transport
 * Simulation", §3), written from the paper's description.
 *
 * Layout.
 * - The S-tree: a binary tree over a cube around the scene bounds, stored as a flat array of
 *   SpatialNode. An interior node splits its box at the midpoint of axis depth % 3 (x, y, z
 *   cycling, §3: the cube keeps the leaves close to cubical) and stores the split position, so
 *   lookups reproduce exactly the boxes the update computed. Its two children are consecutive
 *   entries. A leaf names its GuideLeaf in the leaves array.
 * - The D-trees: per leaf a pair of quadtrees over the octahedral square (u, v) (dir_to_uv:
 *   algebraic, not equal-area; the paper's cylindrical equal-area map needs atan2 and sincos):
 *   a density over the square is a solid-angle density times the map's factor 4 / |p|^3,
 *   which sampling and pdf apply. Training adds L / pdf per direction, so a cell's sum estimates
 *   the flux through its solid angle whatever the map; a cell is sampled by its flux and then
 *   uniformly over its square. A tree is a
 *   flat array of QuadNode (four quadrant sums, four child indices, 0 meaning "the quadrant is
 *   a leaf"; the root is node 0 and never anybody's child), which copies with one memcpy.
 *   Quadrant q = qx + 2 qy, qx = (u >= 1/2) (columns), qy = (v >= 1/2) (rows), in the node's
 *   local coordinates. Every node of a tree is created after its parent, so child > parent.
 *   `sampling` is what the last update learned (no nodes: uniform); `building` accumulates
 *   the current iteration over the structure the last update chose.
 * - What lookups read: every update flattens each leaf's sampling tree into pdf nodes (each
 *   quadrant a child or its cell's stored density) and an alias table over its leaf cells
 *   (PdfNode, SampleCell, field_flatten): the pdf is a descent of loads and compares, sampling
 *   is O(1).
 *
 * Update (§3, "adaptive spatial binary tree" and "adaptive directional quadtree").
 *   1. Each leaf's building tree with samples and positive flux is rebuilt: a node's quadrant
 *      is subdivided when its share of the tree's total flux exceeds rho, up to the maximum
 *      depth; the rest stay leaves (what was finer is pruned). Where the old tree had no
 *      finer node, the quadrant's flux is split evenly among the new children (no finer
 *      information exists, and it keeps the density unchanged). The result, with flux, is the
 *      new sampling tree; the new building tree is the same structure with zero sums. A leaf
 *      without samples or flux keeps its trees (its building sums are zeroed).
 *   2. A leaf with more than c sqrt(spp of the iteration; PPG's 2^k) samples splits; children inherit the parent's
 *      D-trees with half the statistics, and split again while the halved count still exceeds
 *      the threshold, so the leaf becomes a complete subtree. Splitting stops at the memory
 *      cap, at SPATIAL_MAX_DEPTH and where float boxes would become degenerate. (The paper
 *      splits first and rebuilds the children's copies; the halves scale the sums by a power
 *      of two, which leaves every flux share bit-identical, so rebuilding once before copying
 *      is the same result for less work.)
 *   Everything the new state needs is allocated before anything is changed, so an
 *   allocation failure returns -1 with the field exactly as it was; the commit cannot fail.
 *   While an update runs the field holds both states (about twice its size).
 *
 * Deviations and choices (see also guiding.h):
 * - The first building tree is not a bare root but the structure rho gives a uniform flux
 *   (depth 4 at rho = 0.01): the first iteration already learns at 16 x 16 resolution
 *   instead of four quadrants.
 * - Training samples with non-finite position, direction, radiance or pdf, or pdf <= 0, or
 *   a zero direction, are skipped entirely. Zero and negative radiance count as samples
 *   (weight 1) but add no flux: a negative flux would make the quadrant sums unusable as
 *   probabilities.
 * - guide_distribution_sample returns the density of the cell it chose, the value
 *   guide_distribution_pdf reads for a direction in that cell (both store it). The float
 *   round trip (u, v) -> direction -> (u, v) can cross a cell boundary by a rounding error, so
 *   the two can differ for a point sampled that close to a cell's edge (below 1e-4 of samples
 *   in tests/test_sdtree.c; re-evaluating the pdf made them agree but was a third of guiding's
 *   render cost).
 * - Sampling picks the cell from an alias table rather than descending the tree level by level
 *   (the same distribution: each cell with its density times its area): 150 -> 42 ns per sample
 *   on a 512-leaf field trained on a narrow cone (one run, this machine); the flat copies
 *   roughly double the field's memory, which the memory cap counts.
 * - Spatial filtering (Müller 2019) is a parameter (spatial_filter); plain splats by default.
 *   Directional filtering (the same paper) is on by default (directional_filter). */
#include "guiding.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>


enum {
    SPATIAL_MAX_DEPTH = 48,       /* a box 2^-16 of the cube's side per axis */
    QUAD_MAX_DEPTH = 10,          /* cells of 2^-10 of the square's side (about 0.2 degrees), as a
                                   * sample's packed cell holds them; the trained fields of the
                                   * benchmark scenes put under 1e-3 of their mass below 2^-9 */
    QUAD_DEFAULT_DEPTH = 10,
};
#define LEAF_LIMIT (1u << 26)     /* keeps 8 * leaves (PLY vertex indices) within int */
#define DEFAULT_MAX_BYTES ((size_t)256 << 20)
#define DEFAULT_SPATIAL_THRESHOLD 3000.0f
#define DEFAULT_FLUX_THRESHOLD 0.01f

/* The learned BSDF share (guiding.h, GuideFieldParams.learn_bsdf_share): the candidates, and the
 * guided samples a leaf needs before it chooses among them. */
#define SHARE_CANDIDATES GUIDE_SHARE_CANDIDATES
const float guide_share_candidates[SHARE_CANDIDATES] = {0.25f, 0.375f, 0.5f, 0.625f, 0.75f, 0.875f, 1.0f};
#define SHARE_MIN_SAMPLES 64.0
#define SHARE_Z 2.0

/* ------------------------------------------------------------------ types */

typedef struct QuadNode {
    double sum[4];      /* flux through each quadrant (the sum of its subtree) */
    uint32_t child[4];  /* node index of the quadrant's subdivision; 0: the quadrant is a leaf */
} QuadNode;

typedef struct QuadTree {
    QuadNode *nodes;    /* owned; NULL when count is 0 */
    uint32_t count;     /* 0: no tree (a sampling tree without one is uniform) */
} QuadTree;

/* What lookups read: each leaf's sampling tree flattened for speed (field_flatten), in 16-byte
 * records (four to a cache line: at high resolution a guided vertex waits on these loads).
 * - pdf: a descent over PdfNode, each quadrant either a child or the density of its cell,
 *   stored: a level is one load and two compares, and the last one reads the answer.
 * - sampling: an alias table (Walker / Vose) over the tree's cells: one uniform picks a slot in
 *   O(1) and, rescaled, places the point across the cell the slot gives; the other places it
 *   down it. (The descent that divided each uniform by the quadrant shares level by level was
 *   most of guiding's per-vertex cost.)
 * The table's keep thresholds are 16-bit fractions; each cell's probability is then computed
 * from the table as built (its own slot's keep and its share of the slots it is the alias of),
 * and that probability over the cell's area is the density both the slots and the pdf tree
 * store: what a sample reports is what the pdf descent returns for a point of that cell, and
 * both are the density the table samples, to float rounding. The cells' nominal probabilities
 * (the learned flux shares) differ from those by the keeps' rounding, below 2^-16 of a slot. A
 * node without flux is one cell of its own, uniform, as in the double tree. */
typedef struct PdfNode {
    uint32_t q[4]; /* PDF_CHILD | the child's index in the field's node array, or the bits of the
                    * quadrant's cell density over the square (a float >= 0: top bit clear) */
} PdfNode;
#define PDF_CHILD 0x80000000u
_Static_assert(sizeof(PdfNode) == 16, "a pdf node is a quarter of a cache line");
/* An alias-table slot with both of its cells, so a sample reads one 16-byte slot (the cell and
 * its alias in separate entries were two cache misses per guided sample). A cell is packed in
 * 24 bits: its level L (side 2^-L, 1 <= L <= QUAD_MAX_DEPTH = 10) in bits 20-23 and its corner's
 * u and v in units of 2^-L in bits 10-19 and 0-9. */
typedef struct SampleCell {
    float pdf_uv[2];  /* the two cells' densities over the square */
    uint64_t packed;  /* bits 0-15: keep (cell 0 when the rescaled uniform is below keep / 2^16, else
                       * cell 1); bits 16-39 cell 0, bits 40-63 cell 1 */
} SampleCell;
_Static_assert(sizeof(SampleCell) == 16, "an alias slot is a quarter of a cache line");
#define NO_FLAT_TREE 0xFFFFFFFFu

/* A spatial leaf: what a lookup returns. Readers only touch the flat tree and the box. */
/* What a lookup returns and sampling reads: a leaf's flat trees, 32 bytes in an array of their
 * own (the leaf records' trees and counts around them had made a guided vertex miss the cache
 * on the record itself before it reached the trees). */
struct GuideDistribution {
    const PdfNode *pdf_nodes;   /* the field's flat pdf nodes */
    const SampleCell *cells;    /* this leaf's cells (NULL: uniform) */
    uint32_t pdf_root;          /* this leaf's root in pdf_nodes; NO_FLAT_TREE: uniform */
    uint32_t cell_count;
    const struct GuideLeaf *leaf; /* its record (bounds, sample counts) */
    float bsdf_share;             /* the leaf's learned BSDF share (GuideLeaf.bsdf_share) */
    float flux;                   /* the sampling tree's flux per sample learned: its estimate of the
                                   * incident radiance's integral (guide_distribution_flux) */
};

/* A spatial leaf's record: its quadtrees, counts and box. */
typedef struct GuideLeaf {
    QuadTree sampling;  /* learned at the last update (count 0: uniform) */
    QuadTree building;  /* accumulating now */
    double recorded;    /* samples recorded into `building` since the last update */
    double learned;     /* samples `sampling` was learned from (statistical weight) */
    float lo[3], hi[3]; /* the leaf's box */
    uint32_t node;      /* its spatial node */
    float bsdf_share;   /* the scattering function's share of guided MIS here (ch. 1 §3.2.1) */
    double share_count; /* guided samples in share_moment since the share was last chosen */
    double share_moment[SHARE_CANDIDATES]; /* per candidate share a, sum of F^2 / (p q_a): the
                                            * estimator's second moment had q_a sampled */
    double share_diff2[SHARE_CANDIDATES];  /* sum of the squared per-sample differences of those
                                            * terms from the floor candidate's (their spread) */
    double share_bsdf_mass, share_delta_mass; /* sums of p_f / p over the guided samples, and over
                                               * those whose ray reached a delta scatterer */
    double share_flux, share_delta_flux;      /* sums of L / p over the same */
} GuideLeaf;

typedef struct SpatialNode {
    float lo[3], hi[3]; /* the node's box */
    float split;        /* interior: the split position on `axis` (points >= go right) */
    uint32_t child;     /* interior: the first of the two consecutive children; 0: a leaf */
    uint32_t leaf;      /* leaf: index into GuideField.leaves */
    uint8_t axis, depth;
} SpatialNode;

/* The descent's copy of a spatial node, 8 bytes: the split, and the first child with the axis in
 * the low two bits, or the leaf index with DESCENT_LEAF there. The lookups walk these (a
 * field's few thousand nodes fit the L1/L2 cache, where the 40-byte SpatialNodes, boxes
 * included, missed: the loads of the descent were a tenth of a guided render's time). */
typedef struct DescentNode {
    float split;
    uint32_t code;
} DescentNode;
#define DESCENT_LEAF 3u

/* The top of the spatial tree as a grid: splits are at midpoints on axis depth % 3 (§3), so the
 * nodes at depth 3 GRID_LEVELS tile the root box as a GRID_SIDE^3 grid, and a point's cell is
 * found per axis from the GRID_LEVELS midpoints above it (independent, cache-resident) instead
 * of 3 GRID_LEVELS dependent node loads. Each cell holds the deepest node at most that deep
 * holding it (a leaf, or where the descent continues). */
#define GRID_LEVELS 4
#define GRID_SIDE (1u << GRID_LEVELS)
#define GRID_CELLS (GRID_SIDE * GRID_SIDE * GRID_SIDE)

struct GuideField {
    GuideFieldParams params; /* sanitised */
    SpatialNode *nodes;
    DescentNode *descent; /* per node, what the lookups read */
    uint32_t *grid;       /* GRID_CELLS nodes, x major */
    float grid_split[3][GRID_SIDE]; /* per axis, the midpoints of the top GRID_LEVELS splits in heap order (from 1) */
    uint32_t node_count;
    GuideLeaf *leaves;
    GuideDistribution *dists; /* per leaf, what lookups return (filled by field_flatten) */
    uint32_t leaf_count;
    PdfNode *pdf_nodes;       /* every leaf's sampling tree as PdfNode (field_flatten) */
    SampleCell *cells;        /* every leaf's cells with their alias tables */
    int iterations;
    uint64_t recorded_total; /* samples ever given to guide_field_record: the spatial filter's hash key */
    int share_floor;         /* the smallest candidate BSDF share at or above params.min_bsdf_share */
    struct RecordScratch {   /* guide_field_record's, kept across calls */
        struct RecordItem *items;
        uint32_t *order, *start;
        size_t capacity, start_capacity;
    } record;
};
typedef struct RecordScratch RecordScratch;

/* Scratch arrays of a quadtree rebuild (grown as needed, reused across the leaves). */
typedef struct RebuildScratch {
    QuadNode *nodes;
    uint32_t *source;   /* the old tree's node behind each new node (NO_SOURCE: none) */
    uint8_t *depth;     /* 1 for the root */
    uint32_t capacity;
} RebuildScratch;
#define NO_SOURCE 0xFFFFFFFFu

/* ------------------------------------------------------------------ parameters */

void guide_field_params_default(GuideFieldParams *p) {
    if (!p) return;
    p->spatial_threshold = DEFAULT_SPATIAL_THRESHOLD;
    p->flux_threshold = DEFAULT_FLUX_THRESHOLD;
    p->max_quadtree_depth = QUAD_DEFAULT_DEPTH;
    p->max_bytes = DEFAULT_MAX_BYTES;
    p->accumulate = 1;
    p->spatial_filter = 0;
    p->directional_filter = 1;
    p->learn_bsdf_share = 0;
    p->min_bsdf_share = GUIDE_DEFAULT_MIN_BSDF_SHARE;
    p->bsdf_share = GUIDE_DEFAULT_BSDF_SHARE;
    p->caustic_threshold = GUIDE_DEFAULT_CAUSTIC_THRESHOLD;
    p->caustic_share = GUIDE_DEFAULT_CAUSTIC_SHARE;
    p->caustic_defense = GUIDE_DEFAULT_CAUSTIC_DEFENSE;
}

/* Out-of-range values fall back to the defaults rather than building absurd trees (rho <= 0
 * would subdivide every node to the maximum depth). */
static GuideFieldParams params_sanitize(const GuideFieldParams *in) {
    GuideFieldParams p;
    guide_field_params_default(&p);
    if (!in) return p;
    if (in->spatial_threshold > 0 && isfinite(in->spatial_threshold)) p.spatial_threshold = in->spatial_threshold;
    if (in->flux_threshold > 0 && isfinite(in->flux_threshold)) p.flux_threshold = in->flux_threshold;
    if (in->max_quadtree_depth > 0)
        p.max_quadtree_depth = in->max_quadtree_depth < QUAD_MAX_DEPTH ? in->max_quadtree_depth : QUAD_MAX_DEPTH;
    if (in->max_bytes > 0) p.max_bytes = in->max_bytes;
    p.accumulate = in->accumulate != 0;
    p.spatial_filter = in->spatial_filter != 0;
    p.directional_filter = in->directional_filter != 0;
    p.learn_bsdf_share = in->learn_bsdf_share != 0;
    if (in->min_bsdf_share >= 0 && in->min_bsdf_share <= 1) p.min_bsdf_share = in->min_bsdf_share;
    if (in->bsdf_share > 0 && in->bsdf_share <= 1) p.bsdf_share = in->bsdf_share;
    if (in->caustic_threshold >= 0 && in->caustic_threshold <= 1) p.caustic_threshold = in->caustic_threshold;
    if (in->caustic_share > 0 && in->caustic_share <= 1) p.caustic_share = in->caustic_share;
    if (in->caustic_defense >= 0 && in->caustic_defense <= 16) p.caustic_defense = in->caustic_defense;
    return p;
}

/* ------------------------------------------------------------------ directions */

static inline double clamp_unit_open(double x) { /* [0, 1): the sampling routines' domain */
    if (!(x > 0)) return 0;
    if (x >= 1) return 0x1.fffffffffffffp-1;
    return x;
}

/* The octahedral map between unit directions and the (u, v) square (Praun and Hoppe 2003;
 * Engelhardt and Dachsbacher 2008): p = dir / (|x| + |y| + |z|) lies on the octahedron; its
 * upper half (z >= 0) projects to the diamond |a| + |b| <= 1 with (a, b) = (p.x, p.y), the lower
 * half to the square's corners, folded across the diamond's edges; (u, v) = ((a + 1) / 2,
 * (b + 1) / 2). Algebraic both ways: no atan2, no sine or cosine on the hot path (the
 * cylindrical equal-area map's atan2 and sincos were 8% of a guided render's time). It is not
 * equal-area: a direction's solid angle per unit of (u, v) area is 4 / |p|^3 (the octahedron's
 * face is tilted by 1/sqrt 3 against the square and lies |p| from the origin), so a density over
 * the square turns into one over directions times |p|^3 / 4, between 1 / (12 sqrt 3) and 1 / 4
 * (*jacobian below). The quadtree adapts to the map's density like to any other. */
static int dir_to_uv(const float dir[3], double *u, double *v, double *jacobian) {
    double x = dir[0], y = dir[1], z = dir[2];
    double l1 = fabs(x) + fabs(y) + fabs(z);
    if (!(l1 > 0) || !isfinite(l1)) return 0;
    double a = x / l1, b = y / l1;
    if (z < 0) { /* the lower half, folded out to the corners */
        double fa = (1 - fabs(b)) * (a >= 0 ? 1 : -1), fb = (1 - fabs(a)) * (b >= 0 ? 1 : -1);
        a = fa;
        b = fb;
    }
    *u = clamp_unit_open(0.5 * (a + 1));
    *v = clamp_unit_open(0.5 * (b + 1));
    if (jacobian) {
        double p2 = (x * x + y * y + z * z) / (l1 * l1); /* |p|^2 */
        *jacobian = 0.25 * p2 * sqrt(p2);
    }
    return 1;
}

/* The direction of (u, v), and the density factor |p|^3 / 4 of dir_to_uv. */
static void uv_to_dir(double u, double v, float dir[3], double *jacobian) {
    double a = 2 * u - 1, b = 2 * v - 1;
    double z = 1 - fabs(a) - fabs(b);
    if (z < 0) {
        double fa = (1 - fabs(b)) * (a >= 0 ? 1 : -1), fb = (1 - fabs(a)) * (b >= 0 ? 1 : -1);
        a = fa;
        b = fb;
    }
    double p2 = a * a + b * b + z * z, len = sqrt(p2);
    dir[0] = (float)(a / len);
    dir[1] = (float)(b / len);
    dir[2] = (float)(z / len);
    *jacobian = 0.25 * p2 * len;
}

/* ------------------------------------------------------------------ quadtrees */

static inline double node_total(const QuadNode *n) { return (n->sum[0] + n->sum[1]) + (n->sum[2] + n->sum[3]); }

static void quadtree_free(QuadTree *t) {
    free(t->nodes);
    t->nodes = NULL;
    t->count = 0;
}

static size_t quadtree_bytes(const QuadTree *t) { return (size_t)t->count * sizeof(QuadNode); }

/* A copy with every sum multiplied by 2^exponent (exact: the shares stay bit-identical) or,
 * with zero_sums, set to 0. -1: out of memory. An empty tree copies to an empty tree. */
static int quadtree_copy(const QuadTree *src, int exponent, int zero_sums, QuadTree *out) {
    out->nodes = NULL;
    out->count = 0;
    if (src->count == 0) return 0;
    QuadNode *n = malloc((size_t)src->count * sizeof *n);
    if (!n) return -1;
    memcpy(n, src->nodes, (size_t)src->count * sizeof *n);
    for (uint32_t i = 0; i < src->count; ++i)
        for (int q = 0; q < 4; ++q) n[i].sum[q] = zero_sums ? 0.0 : ldexp(n[i].sum[q], exponent);
    out->nodes = n;
    out->count = src->count;
    return 0;
}

static void quadtree_scale(QuadTree *t, int exponent) {
    for (uint32_t i = 0; i < t->count; ++i)
        for (int q = 0; q < 4; ++q) t->nodes[i].sum[q] = ldexp(t->nodes[i].sum[q], exponent);
}

static void quadtree_zero(QuadTree *t) {
    for (uint32_t i = 0; i < t->count; ++i)
        for (int q = 0; q < 4; ++q) t->nodes[i].sum[q] = 0;
}

/* Adds `value` to every level's quadrant sum along the descent to (u, v), so a node's sum is
 * always its subtree's total and a rebuild can read the flux of any region at any level. */
static void quadtree_add(QuadTree *t, double u, double v, double value) {
    if (t->count == 0) return;
    uint32_t i = 0;
    for (;;) {
        QuadNode *n = &t->nodes[i];
        int qx = u >= 0.5, qy = v >= 0.5, q = qx + 2 * qy;
        n->sum[q] += value;
        if (!n->child[q]) return;
        u = 2 * u - qx; /* exact in binary floating point */
        v = 2 * v - qy;
        i = n->child[q];
    }
}

/* Müller et al. 2019 §4 (directional filtering): a sample's value is spread over a box of the
 * size of the building tree's cell that holds (u, v), centred on (u, v), each node receiving
 * the share of the box it overlaps. A sample near a cell's edge then trains both sides, so the
 * learned distribution has neither holes nor steps where few samples landed (the box at
 * 256x256: relMSE 1.57e-4 -> 1.38e-4, scenes/RESULTS.md). The box is clipped to the map's
 * square and its value renormalised over what remains: the total flux is the sample's. */
static double quadtree_cell_size(const QuadTree *t, double u, double v) {
    uint32_t i = 0;
    double size = 1.0;
    for (;;) {
        const QuadNode *n = &t->nodes[i];
        int qx = u >= 0.5, qy = v >= 0.5, q = qx + 2 * qy;
        size *= 0.5;
        if (!n->child[q]) return size;
        u = 2 * u - qx; /* exact in binary floating point */
        v = 2 * v - qy;
        i = n->child[q];
    }
}

/* Node i covers [x, x + size) x [y, y + size); box = {x0, y0, x1, y1}; density per unit area. */
static void quadtree_splat(QuadTree *t, uint32_t i, double x, double y, double size, const double box[4],
                           double density) {
    QuadNode *n = &t->nodes[i];
    double h = 0.5 * size;
    for (int q = 0; q < 4; ++q) {
        double qx = x + (q & 1) * h, qy = y + (q >> 1) * h;
        /* the overlap; plain compares, not fmin/fmax (libm calls in this inner loop; no NaN here) */
        double x1 = qx + h < box[2] ? qx + h : box[2], x0 = qx > box[0] ? qx : box[0];
        double y1 = qy + h < box[3] ? qy + h : box[3], y0 = qy > box[1] ? qy : box[1];
        double ox = x1 - x0, oy = y1 - y0;
        if (!(ox > 0) || !(oy > 0)) continue;
        n->sum[q] += density * ox * oy;
        if (n->child[q]) quadtree_splat(t, n->child[q], qx, qy, h, box, density);
    }
}

static void quadtree_add_filtered(QuadTree *t, double u, double v, double value) {
    if (t->count == 0) return;
    double r = 0.5 * quadtree_cell_size(t, u, v);
    double box[4] = {fmax(u - r, 0.0), fmax(v - r, 0.0), fmin(u + r, 1.0), fmin(v + r, 1.0)};
    double area = (box[2] - box[0]) * (box[3] - box[1]);
    if (!(area > 0)) {
        quadtree_add(t, u, v, value);
        return;
    }
    quadtree_splat(t, 0, 0.0, 0.0, 1.0, box, value / area);
}

/* ------------------------------------------------------------------ flat sampling trees */

/* Cells of a tree: every node's quadrants without a child (4 n - (n - 1)). */
static size_t tree_cells(const QuadTree *t) { return t->count ? 3 * (size_t)t->count + 1 : 0; }

static size_t tree_flat_bytes(const QuadTree *t) {
    return (size_t)t->count * sizeof(PdfNode) + tree_cells(t) * sizeof(SampleCell);
}

/* Scratch of the alias table builds (sized for the largest tree): each cell's probability, the
 * two work lists, and the cells before they are paired into slots. */
typedef struct AliasCell {
    uint32_t node;   /* the PdfNode whose quadrant it is */
    uint32_t packed; /* level, u, v (SampleCell) */
    uint8_t quad;
} AliasCell;
typedef struct AliasScratch {
    double *prob;    /* nominal, then the table's (per cell) */
    uint32_t *small, *large;
    AliasCell *cell;
    uint16_t *keep;  /* per slot */
    uint32_t *alias; /* per slot: cell 1 */
} AliasScratch;

static void alias_scratch_free(AliasScratch *a) {
    free(a->prob); free(a->small); free(a->large); free(a->cell); free(a->keep); free(a->alias);
    memset(a, 0, sizeof *a);
}

static int alias_scratch_alloc(AliasScratch *a, size_t cells) {
    if (cells < 1) cells = 1;
    a->prob = malloc(cells * sizeof *a->prob);
    a->small = malloc(cells * sizeof *a->small);
    a->large = malloc(cells * sizeof *a->large);
    a->cell = malloc(cells * sizeof *a->cell);
    a->keep = malloc(cells * sizeof *a->keep);
    a->alias = malloc(cells * sizeof *a->alias);
    if (!a->prob || !a->small || !a->large || !a->cell || !a->keep || !a->alias) { alias_scratch_free(a); return -1; }
    return 0;
}

/* The flat arrays that lookups read at random, on cache-line boundaries (a slot never straddles
 * two lines). Freed with free(). (2 MiB pages asked for by madvise measured no gain on the box
 * at 256x256.) */
static void *flat_alloc(size_t bytes) { return aligned_alloc(64, ((bytes ? bytes : 1) + 63) & ~(size_t)63); }

static SampleCell *slots_alloc(size_t n) { return flat_alloc((n ? n : 1) * sizeof(SampleCell)); }

static double cell_area(uint32_t packed) { return ldexp(1.0, -2 * (int)(packed >> 20)); }

static uint32_t float_bits(float x) {
    uint32_t b;
    memcpy(&b, &x, sizeof b);
    return b;
}

/* One leaf: its PdfNodes at nodes[base ...], its cells at cells[0 ...] with their alias table
 * (Vose's construction, deterministic). A tree without positive total weight stays uniform. */
static void flatten_leaf(const GuideLeaf *leaf, GuideDistribution *l, PdfNode *nodes, uint32_t base, SampleCell *cells,
                         AliasScratch *a) {
    const QuadTree *t = &leaf->sampling;
    l->leaf = leaf;
    l->bsdf_share = leaf->bsdf_share;
    l->pdf_nodes = nodes;
    l->pdf_root = NO_FLAT_TREE;
    l->cells = NULL;
    l->cell_count = 0;
    l->flux = 0.0f;
    if (t->count == 0) return;
    double flux = leaf->learned > 0 ? node_total(&t->nodes[0]) / leaf->learned : 0.0;
    if (flux > 0 && flux < 1e30) l->flux = (float)flux;
    memset(&nodes[base], 0, (size_t)t->count * sizeof *nodes); /* nodes under a cell stay unread */
    /* The cells, depth first, each with its nominal probability: the product of the flux shares
     * down to it (double). A quadrant without flux, or at the depth a packed cell holds, is a
     * cell even where the tree goes deeper (a tree loaded from an older checkpoint). */
    typedef struct CellVisit { uint32_t node; uint32_t ui, vi; double prob; int level; } CellVisit;
    CellVisit stack[4 * (QUAD_MAX_DEPTH + 2)]; /* at most 3 siblings per level wait */
    int top = 0;
    uint32_t nc = 0;
    double weight = 0;
    stack[top++] = (CellVisit){0, 0, 0, 1.0, 0};
    while (top > 0) {
        CellVisit e = stack[--top];
        const QuadNode *n = &t->nodes[e.node];
        double total = node_total(n);
        for (int q = 0; q < 4; ++q) {
            uint32_t ui = 2 * e.ui + (q & 1), vi = 2 * e.vi + (q >> 1);
            double prob = total > 0 ? e.prob * (n->sum[q] / total) : 0.25 * e.prob;
            if (!(prob > 0) || !isfinite(prob)) prob = 0;
            if (total > 0 && n->child[q] && prob > 0 && e.level + 1 < QUAD_MAX_DEPTH &&
                top < (int)(sizeof stack / sizeof stack[0])) {
                nodes[base + e.node].q[q] = PDF_CHILD | (base + n->child[q]);
                stack[top++] = (CellVisit){n->child[q], ui, vi, prob, e.level + 1};
                continue;
            }
            AliasCell *c = &a->cell[nc];
            c->node = base + e.node;
            c->quad = (uint8_t)q;
            c->packed = (uint32_t)(e.level + 1) << 20 | ui << 10 | vi;
            a->prob[nc] = prob;
            weight += prob;
            ++nc;
        }
    }
    if (!(weight > 0) || !isfinite(weight)) return; /* uniform */
    /* Vose: slot i's own cell is cell i; keep rounded to 16 bits as it is built */
    uint32_t ns = 0, nl = 0;
    for (uint32_t i = 0; i < nc; ++i) {
        a->prob[i] *= (double)nc / weight;
        a->keep[i] = 0xFFFF;
        a->alias[i] = i;
        if (a->prob[i] < 1.0) a->small[ns++] = i;
        else a->large[nl++] = i;
    }
    while (ns > 0 && nl > 0) {
        uint32_t sm = a->small[--ns], lg = a->large[--nl];
        double k = floor(a->prob[sm] * 65536.0 + 0.5);
        a->keep[sm] = (uint16_t)(k > 65535.0 ? 65535.0 : k);
        a->alias[sm] = lg;
        a->prob[lg] = (a->prob[lg] + a->prob[sm]) - 1.0;
        if (a->prob[lg] < 1.0) a->small[ns++] = lg;
        else a->large[nl++] = lg;
    }
    /* the rest keep their own cell (the large ones, and rounding leftovers among the small):
     * alias = self, keep irrelevant. Each cell's probability from the table as built: */
    for (uint32_t i = 0; i < nc; ++i) a->prob[i] = 0.0;
    for (uint32_t i = 0; i < nc; ++i) {
        double keep = a->alias[i] == i ? 1.0 : a->keep[i] * 0x1p-16;
        a->prob[i] += keep;
        a->prob[a->alias[i]] += 1.0 - keep;
    }
    for (uint32_t i = 0; i < nc; ++i) {
        const AliasCell *c = &a->cell[i];
        float pdf = (float)(a->prob[i] / ((double)nc * cell_area(c->packed)));
        nodes[c->node].q[c->quad] = float_bits(pdf);
        a->prob[i] = pdf; /* the slots' copy */
    }
    for (uint32_t i = 0; i < nc; ++i) {
        uint32_t j = a->alias[i];
        cells[i].pdf_uv[0] = (float)a->prob[i];
        cells[i].pdf_uv[1] = (float)a->prob[j];
        cells[i].packed = (uint64_t)a->keep[i] | (uint64_t)a->cell[i].packed << 16 | (uint64_t)a->cell[j].packed << 40;
    }
    l->pdf_root = base;
    l->cells = cells;
    l->cell_count = nc;
}

/* Every leaf flattened into nodes / cells (sized by the leaves' tree_cells and counts). */
static void field_flatten(const GuideLeaf *leaves, GuideDistribution *dists, uint32_t leaf_count, PdfNode *nodes,
                          SampleCell *cells, AliasScratch *a) {
    uint32_t base = 0;
    size_t cell_base = 0;
    for (uint32_t i = 0; i < leaf_count; ++i) {
        flatten_leaf(&leaves[i], &dists[i], nodes, base, cells + cell_base, a);
        base += leaves[i].sampling.count;
        cell_base += tree_cells(&leaves[i].sampling);
    }
}

static int scratch_reserve(RebuildScratch *s, uint32_t need) {
    if (need <= s->capacity) return 0;
    uint32_t cap = s->capacity ? s->capacity : 256;
    while (cap < need) cap = cap > UINT32_MAX / 2 ? UINT32_MAX : cap * 2;
    QuadNode *n = realloc(s->nodes, (size_t)cap * sizeof *n);
    if (!n) return -1;
    s->nodes = n;
    uint32_t *src = realloc(s->source, (size_t)cap * sizeof *src);
    if (!src) return -1;
    s->source = src;
    uint8_t *d = realloc(s->depth, (size_t)cap);
    if (!d) return -1;
    s->depth = d;
    s->capacity = cap;
    return 0;
}

static void scratch_free(RebuildScratch *s) {
    free(s->nodes);
    free(s->source);
    free(s->depth);
    memset(s, 0, sizeof *s);
}

/* The adaptive directional quadtree (§3): a new tree whose quadrants are subdivided where
 * their share of the total flux of `src` exceeds rho (and the depth allows), with the flux of
 * `src` as sums. Nodes are created breadth first (the scratch array is the queue), so a node
 * limit cuts the finest levels first. -1: out of memory (out untouched). */
static int quadtree_rebuild(const QuadTree *src, double rho, int max_depth, uint32_t max_nodes,
                            RebuildScratch *s, QuadTree *out) {
    if (src->count == 0) return -1;
    if (scratch_reserve(s, 1)) return -1;
    s->nodes[0] = (QuadNode){{src->nodes[0].sum[0], src->nodes[0].sum[1], src->nodes[0].sum[2], src->nodes[0].sum[3]},
                             {0, 0, 0, 0}};
    s->source[0] = 0;
    s->depth[0] = 1;
    uint32_t count = 1;
    double limit = rho * node_total(&src->nodes[0]);
    for (uint32_t i = 0; i < count; ++i) {
        for (int q = 0; q < 4; ++q) {
            double flux = s->nodes[i].sum[q];
            if (!(flux > limit) || s->depth[i] >= max_depth || count >= max_nodes) continue;
            if (scratch_reserve(s, count + 1)) return -1;
            uint32_t from = s->source[i] == NO_SOURCE ? 0 : src->nodes[s->source[i]].child[q];
            QuadNode *c = &s->nodes[count];
            if (from) {
                *c = src->nodes[from];
                c->child[0] = c->child[1] = c->child[2] = c->child[3] = 0;
                s->source[count] = from;
            } else {
                double quarter = 0.25 * flux; /* no finer information: keep the density */
                *c = (QuadNode){{quarter, quarter, quarter, quarter}, {0, 0, 0, 0}};
                s->source[count] = NO_SOURCE;
            }
            s->depth[count] = (uint8_t)(s->depth[i] + 1);
            s->nodes[i].child[q] = count;
            ++count;
        }
    }
    QuadNode *n = malloc((size_t)count * sizeof *n);
    if (!n) return -1;
    memcpy(n, s->nodes, (size_t)count * sizeof *n);
    out->nodes = n;
    out->count = count;
    return 0;
}

/* The building structure a uniform flux gives: where an untrained leaf starts. */
static int quadtree_initial(const GuideFieldParams *p, uint32_t max_nodes, RebuildScratch *s, QuadTree *out) {
    QuadNode root = {{1, 1, 1, 1}, {0, 0, 0, 0}};
    QuadTree uniform = {&root, 1};
    if (quadtree_rebuild(&uniform, p->flux_threshold, p->max_quadtree_depth, max_nodes, s, out)) return -1;
    quadtree_zero(out);
    return 0;
}

/* The most nodes one tree may have: a sampling and a building copy within the memory cap. */
static uint32_t quadtree_node_limit(const GuideFieldParams *p) {
    size_t n = p->max_bytes / (2 * sizeof(QuadNode));
    if (n < 1) n = 1;
    if (n > UINT32_MAX / 2) n = UINT32_MAX / 2;
    return (uint32_t)n;
}

/* ------------------------------------------------------------------ field */

static size_t leaf_tree_bytes(const GuideLeaf *l) {
    return quadtree_bytes(&l->sampling) + quadtree_bytes(&l->building) + tree_flat_bytes(&l->sampling);
}

/* A leaf whose trees are a rebuilt tree: it as the sampling and the building tree, and flat. */
static size_t rebuilt_tree_bytes(const QuadTree *t) { return 2 * quadtree_bytes(t) + tree_flat_bytes(t); }

/* A spatial node with its descent copy; the field's struct with its lookup grid. */
#define NODE_BYTES (sizeof(SpatialNode) + sizeof(DescentNode))
#define FIELD_FIXED_BYTES (sizeof(GuideField) + GRID_CELLS * sizeof(uint32_t))

size_t guide_field_bytes(const GuideField *f) {
    if (!f) return 0;
    size_t b = FIELD_FIXED_BYTES + (size_t)f->node_count * NODE_BYTES + (size_t)f->leaf_count * sizeof(GuideLeaf);
    for (uint32_t i = 0; i < f->leaf_count; ++i) b += leaf_tree_bytes(&f->leaves[i]);
    return b;
}

uint32_t guide_field_num_leaves(const GuideField *f) { return f ? f->leaf_count : 0; }
int guide_field_iterations(const GuideField *f) { return f ? f->iterations : 0; }

/* A spatial split's position: the midpoint of [lo, hi), one expression for the splits and the
 * lookup grid's copies of them. */
static inline float split_mid(float lo, float hi) { return lo + 0.5f * (hi - lo); }

/* pos clamped into the root box (NaN coordinates go to its low corner). */
static void field_clamp(const GuideField *f, const float pos[3], float p[3]) {
    const SpatialNode *root = &f->nodes[0];
    for (int k = 0; k < 3; ++k) {
        float x = pos[k];
        p[k] = x > root->lo[k] ? (x < root->hi[k] ? x : root->hi[k]) : root->lo[k];
    }
}

/* The leaf holding the clamped point p: a node's points >= split go to its second child. */
static uint32_t field_descend(const GuideField *f, const float p[3]) {
    uint32_t c[3];
    for (int k = 0; k < 3; ++k) {
        const float *m = f->grid_split[k];
        uint32_t i = 1;
        for (int j = 0; j < GRID_LEVELS; ++j) i = 2 * i + (p[k] >= m[i]);
        c[k] = i - GRID_SIDE;
    }
    const DescentNode *d = f->descent, *n = &d[f->grid[(c[0] * GRID_SIDE + c[1]) * GRID_SIDE + c[2]]];
    while ((n->code & 3u) != DESCENT_LEAF) n = &d[(n->code >> 2) + (p[n->code & 3u] >= n->split)];
    return n->code >> 2;
}

/* The leaf containing pos, clamped into the root box. */
static uint32_t field_find_leaf(const GuideField *f, const float pos[3]) {
    float p[3];
    field_clamp(f, pos, p);
    return field_descend(f, p);
}

/* Cells [c0, c1) per axis of the grid take node i, or its children's halves above depth
 * 3 GRID_LEVELS. */
static void grid_fill_node(uint32_t *grid, const SpatialNode *nodes, uint32_t i, const uint32_t c0[3], const uint32_t c1[3]) {
    const SpatialNode *n = &nodes[i];
    if (n->child && n->depth < 3 * GRID_LEVELS && c1[n->axis] - c0[n->axis] >= 2) { /* always, for a sound tree */
        int a = n->axis;
        uint32_t mid = (c0[a] + c1[a]) / 2, lo[3] = {c0[0], c0[1], c0[2]}, hi[3] = {c1[0], c1[1], c1[2]};
        hi[a] = mid;
        grid_fill_node(grid, nodes, n->child, lo, hi);
        lo[a] = mid;
        hi[a] = c1[a];
        grid_fill_node(grid, nodes, n->child + 1, lo, hi);
        return;
    }
    for (uint32_t x = c0[0]; x < c1[0]; ++x)
        for (uint32_t y = c0[1]; y < c1[1]; ++y)
            for (uint32_t z = c0[2]; z < c1[2]; ++z) grid[(x * GRID_SIDE + y) * GRID_SIDE + z] = i;
}

/* The descent's nodes and grid from the spatial nodes. The grid's midpoints are the splits'
 * own (split_mid from the root box, as spatial_split computes them level by level). */
static void descent_fill(DescentNode *d, uint32_t *grid, float split[3][GRID_SIDE], const SpatialNode *n, uint32_t count) {
    for (uint32_t i = 0; i < count; ++i)
        d[i] = n[i].child ? (DescentNode){n[i].split, n[i].child << 2 | n[i].axis} : (DescentNode){0.0f, n[i].leaf << 2 | DESCENT_LEAF};
    for (int k = 0; k < 3; ++k) {
        float lo[GRID_SIDE], hi[GRID_SIDE]; /* heap order: node j's interval */
        lo[1] = n[0].lo[k];
        hi[1] = n[0].hi[k];
        for (uint32_t j = 1; j < GRID_SIDE; ++j) {
            split[k][j] = split_mid(lo[j], hi[j]);
            if (2 * j + 1 < GRID_SIDE) {
                lo[2 * j] = lo[j];
                hi[2 * j] = split[k][j];
                lo[2 * j + 1] = split[k][j];
                hi[2 * j + 1] = hi[j];
            }
        }
        split[k][0] = 0.0f;
    }
    const uint32_t c0[3] = {0, 0, 0}, c1[3] = {GRID_SIDE, GRID_SIDE, GRID_SIDE};
    grid_fill_node(grid, n, 0, c0, c1);
}

GuideField *guide_field_create(const float lo[3], const float hi[3], const GuideFieldParams *p) {
    GuideField *f = calloc(1, sizeof *f);
    if (!f) return NULL;
    f->params = params_sanitize(p);
    f->share_floor = SHARE_CANDIDATES - 1;
    for (int k = SHARE_CANDIDATES - 1; k >= 0; --k)
        if (guide_share_candidates[k] >= f->params.min_bsdf_share) f->share_floor = k;
    /* The cube around the bounds (§3: the S-tree partitions a cube), enlarged by 1e-3 of its
     * side so points on the bounds are strictly inside after float rounding. Bounds that are
     * not finite or empty fall back to [-1, 1] on that axis rather than poisoning the tree. */
    double a[3], b[3], side = 0, mag = 0;
    for (int k = 0; k < 3; ++k) {
        a[k] = lo ? lo[k] : -1;
        b[k] = hi ? hi[k] : 1;
        if (!isfinite(a[k]) || !isfinite(b[k])) {
            a[k] = -1;
            b[k] = 1;
        }
        if (a[k] > b[k]) {
            double t = a[k];
            a[k] = b[k];
            b[k] = t;
        }
        side = fmax(side, b[k] - a[k]);
        mag = fmax(mag, fmax(fabs(a[k]), fabs(b[k])));
    }
    side = fmax(side * (1 + 1e-3), fmax(mag, 1.0) * 1e-3); /* never a point-sized cube */
    f->nodes = calloc(1, sizeof *f->nodes);
    f->descent = calloc(1, sizeof *f->descent);
    f->grid = malloc(GRID_CELLS * sizeof *f->grid);
    f->leaves = calloc(1, sizeof *f->leaves);
    f->dists = calloc(1, sizeof *f->dists);
    if (!f->nodes || !f->descent || !f->grid || !f->leaves || !f->dists) {
        guide_field_free(f);
        return NULL;
    }
    SpatialNode *root = &f->nodes[0];
    for (int k = 0; k < 3; ++k) {
        double c = 0.5 * (a[k] + b[k]);
        root->lo[k] = (float)(c - 0.5 * side);
        root->hi[k] = (float)(c + 0.5 * side);
    }
    f->node_count = 1;
    descent_fill(f->descent, f->grid, f->grid_split, f->nodes, 1); /* the root is leaf 0 */
    f->leaf_count = 1;
    GuideLeaf *leaf = &f->leaves[0];
    memcpy(leaf->lo, root->lo, sizeof leaf->lo);
    memcpy(leaf->hi, root->hi, sizeof leaf->hi);
    RebuildScratch s = {0};
    leaf->bsdf_share = f->params.bsdf_share;
    f->dists[0] = (GuideDistribution){NULL, NULL, NO_FLAT_TREE, 0, leaf, leaf->bsdf_share, 0.0f}; /* nothing learned: uniform */
    int rc = quadtree_initial(&f->params, quadtree_node_limit(&f->params), &s, &leaf->building);
    scratch_free(&s);
    if (rc) {
        guide_field_free(f);
        return NULL;
    }
    return f;
}

/* Frees the leaves' quadtrees and the array (leaves may be NULL). */
static void leaves_free(GuideLeaf *leaves, uint32_t count) {
    if (leaves)
        for (uint32_t i = 0; i < count; ++i) {
            quadtree_free(&leaves[i].sampling);
            quadtree_free(&leaves[i].building);
        }
    free(leaves);
}

void guide_field_free(GuideField *f) {
    if (!f) return;
    free(f->record.items);
    free(f->record.order);
    free(f->record.start);
    leaves_free(f->leaves, f->leaf_count);
    free(f->dists);
    free(f->nodes);
    free(f->descent);
    free(f->grid);
    free(f->pdf_nodes);
    free(f->cells);
    free(f);
}

static int point_in_leaf(const GuideLeaf *l, const float p[3]) {
    return p[0] >= l->lo[0] && p[0] < l->hi[0] && p[1] >= l->lo[1] && p[1] < l->hi[1] && p[2] >= l->lo[2] && p[2] < l->hi[2];
}

/* One valid sample's place in a batch: its leaf, where it lands on the square, its value. */
typedef struct RecordItem {
    double u, v, value; /* value: L / pdf (added only when positive) */
    uint32_t leaf;
    float share_value, bsdf_pdf, guide_pdf; /* GuideTrainingSample's (share_value < 0: none) */
    float pdf;
    int delta_child;
    float defense; /* GuideTrainingSample's */
} RecordItem;

static int record_scratch_reserve(GuideField *f, size_t n) {
    RecordScratch *r = &f->record;
    if (n > r->capacity) {
        RecordItem *items = realloc(r->items, n * sizeof *items);
        if (!items) return -1;
        r->items = items;
        uint32_t *order = realloc(r->order, n * sizeof *order);
        if (!order) return -1;
        r->order = order;
        r->capacity = n;
    }
    if ((size_t)f->leaf_count + 1 > r->start_capacity) {
        uint32_t *start = realloc(r->start, ((size_t)f->leaf_count + 1) * sizeof *start);
        if (!start) return -1;
        r->start = start;
        r->start_capacity = (size_t)f->leaf_count + 1;
    }
    return 0;
}

static void record_item(GuideField *f, const RecordItem *it) {
    GuideLeaf *leaf = &f->leaves[it->leaf];
    /* The caustic defense: a sample whose ray reached a delta scatterer also trains its direction
     * with c F p_f / p, F the leaf's mean flux per sample so far. Over the samples these add up to
     * c F N P_f(R) in a region R, P_f(R) the probability that the function's sampling goes there:
     * the guide's density toward glass and mirrors becomes about c p_f wherever training found
     * no light beyond them, so the mixture's pdf there is about the function's own and a caustic
     * only the function finds keeps about its unguided weight (not 1 / share of it), while the
     * guide loses only about P_f of the delta scatterers to this. */
    double defense = 0;
    if (it->defense > 0 && f->params.caustic_defense > 0 && leaf->recorded > 0 && leaf->building.count > 0) {
        double mean = node_total(&leaf->building.nodes[0]) / leaf->recorded;
        if (mean > 0 && isfinite(mean)) defense = f->params.caustic_defense * mean * (double)it->defense;
    }
    /* §3: the statistical weight counts every sample, zero radiance included (C1 §8.1:
     * dropping them biases the learned distribution). */
    leaf->recorded += 1;
    /* The incident radiance estimate L / p over the sphere: its sum per cell estimates the
     * cell's flux (§3, "collecting estimates"). */
    double added = (it->value > 0 ? it->value : 0) + (isfinite(defense) ? defense : 0);
    if (added > 0) {
        if (f->params.directional_filter) quadtree_add_filtered(&leaf->building, it->u, it->v, added);
        else quadtree_add(&leaf->building, it->u, it->v, added);
    }
    if (it->share_value < 0) return;
    leaf->share_count += 1;
    /* the caustic guard's sums (leaf_choose_share): E_p[p_f / p] over the directions that reach a
     * delta scatterer is the probability that the function's sampling goes there, E_p[L / p]
     * their flux */
    double w = (double)it->bsdf_pdf / (double)it->pdf, v = it->value > 0 ? it->value : 0;
    leaf->share_bsdf_mass += w;
    leaf->share_flux += v;
    if (it->delta_child) {
        leaf->share_delta_mass += w;
        leaf->share_delta_flux += v;
    }
    if (!f->params.learn_bsdf_share) return;
    /* ch. 1 §3.2.1: the second moment of the one-sample estimator F / q_a for each candidate share
     * a, from this sample drawn with pdf p: E_p[F^2 / (p q_a)] = integral of F^2 / q_a */
    double term[SHARE_CANDIDATES];
    for (int k = 0; k < SHARE_CANDIDATES; ++k) {
        double a = guide_share_candidates[k];
        double q = a * (double)it->bsdf_pdf + (1 - a) * (double)it->guide_pdf;
        term[k] = q > 0 ? (double)it->share_value / q : HUGE_VAL;
        leaf->share_moment[k] += term[k];
    }
    int r = f->share_floor;
    for (int k = 0; k < SHARE_CANDIDATES; ++k) {
        double d = term[k] - term[r];
        leaf->share_diff2[k] += isfinite(d) ? d * d : HUGE_VAL;
    }
}

/* The candidate share with the least second moment at or above the floor; a share above the
 * floor only where its second moment is lower by more than SHARE_Z standard errors of the paired
 * difference: the sums are heavy-tailed, and a noisy choice above the floor costs where the guide
 * is good. */
static float leaf_learned_share(const GuideField *f, const GuideLeaf *l) {
    int r = f->share_floor, best = r;
    double n = l->share_count;
    for (int k = r + 1; k < SHARE_CANDIDATES; ++k) {
        double diff = l->share_moment[k] - l->share_moment[r];
        double var = l->share_diff2[k] - diff * diff / n; /* n - 1 times the differences' variance */
        double se = sqrt(fmax(var, 0.0) / (n - 1)) * sqrt(n); /* of the sum */
        if (!isfinite(diff) || !isfinite(se) || !(diff < -SHARE_Z * se)) continue;
        if (l->share_moment[k] < l->share_moment[best]) best = k;
    }
    return guide_share_candidates[best];
}

/* The leaf's share from SHARE_MIN_SAMPLES guided samples or more (fewer: it keeps its share and
 * its sums): learning, the candidate with the least second moment at or above the floor; else
 * params.bsdf_share. Then the caustic guard: 1 where the function's sampling reaches delta
 * scatterers with probability above params.caustic_threshold while the light found beyond them is
 * a smaller share of the leaf's flux than that probability (dimmer than the leaf's average: the
 * guide has not learned what lies there, and one-sample MIS would weight what the function alone
 * finds there, caustics, by 1 / share). Light through glass that training did find bright (a
 * window) keeps the guide. */
static void leaf_choose_share(const GuideField *f, GuideLeaf *l) {
    if (!(l->share_count >= SHARE_MIN_SAMPLES)) return;
    l->bsdf_share = f->params.learn_bsdf_share ? leaf_learned_share(f, l) : f->params.bsdf_share;
    double mass = l->share_bsdf_mass > 0 ? l->share_delta_mass / l->share_bsdf_mass : 0;
    double flux = l->share_flux > 0 ? l->share_delta_flux / l->share_flux : 0;
    if (f->params.caustic_threshold > 0 && mass > f->params.caustic_threshold && flux < mass)
        l->bsdf_share = fmaxf(l->bsdf_share, f->params.caustic_share);
    l->share_bsdf_mass = l->share_delta_mass = 0;
    l->share_flux = l->share_delta_flux = 0;
    l->share_count = 0;
    memset(l->share_moment, 0, sizeof l->share_moment);
    memset(l->share_diff2, 0, sizeof l->share_diff2);
}

/* Samples are located first, then added leaf by leaf, each leaf's in the order given: a leaf's
 * sums see the same additions in the same order as one pass in sample order would make (the
 * result is bit for bit that pass's), while a leaf's building tree stays in the cache across
 * its samples instead of being fetched again for each (the samples come in path order, all
 * over the scene: the descents' misses were most of the training's time). */
void guide_field_record(GuideField *f, const GuideTrainingSample *s, size_t n) {
    if (!f || !s || n == 0) return;
    int grouped = n <= UINT32_MAX && record_scratch_reserve(f, n) == 0;
    RecordItem *items = f->record.items, one;
    size_t m = 0;
    for (size_t i = 0; i < n; ++i) {
        const GuideTrainingSample *x = &s[i];
        if (!isfinite(x->pos[0]) || !isfinite(x->pos[1]) || !isfinite(x->pos[2])) continue;
        if (!isfinite(x->radiance) || !(x->pdf > 0) || !isfinite(x->pdf)) continue;
        RecordItem *it = grouped ? &items[m] : &one;
        if (!dir_to_uv(x->dir, &it->u, &it->v, NULL)) continue;
        uint64_t index = f->recorded_total++;
        uint32_t leaf = x->leaf;
        /* the hint holds where pos is in its leaf's box [lo, hi), the cells the descent's >= rule
         * gives the leaf; else (a stale or foreign hint, a point on the root's far faces or
         * outside, which the descent clamps) the descent decides */
        if (leaf >= f->leaf_count || !point_in_leaf(&f->leaves[leaf], x->pos)) leaf = field_find_leaf(f, x->pos);
        if (f->params.spatial_filter) {
            /* Müller 2019 §4 (spatial filtering): splat into the leaf at a point drawn uniformly
             * in a box of the sample's leaf's size around it, so neighbouring leaves share
             * their data and the learned field has no seams at leaf boundaries */
            const GuideLeaf *l = &f->leaves[leaf];
            float q[3];
            for (int k = 0; k < 3; ++k) {
                uint64_t h = index * 0x9E3779B97F4A7C15ull + (uint64_t)(k + 1) * 0xD1B54A32D192ED03ull;
                h ^= h >> 31;
                h *= 0xBF58476D1CE4E5B9ull;
                h ^= h >> 29;
                float u = (float)(h >> 40) * 0x1.0p-24f - 0.5f;
                q[k] = x->pos[k] + u * (l->hi[k] - l->lo[k]);
            }
            leaf = field_find_leaf(f, q);
        }
        it->leaf = leaf;
        it->value = (double)x->radiance / (double)x->pdf; /* in double: finite for any float input */
        int share = x->share_value >= 0 && isfinite(x->share_value) && x->bsdf_pdf > 0 && isfinite(x->bsdf_pdf) &&
                    x->guide_pdf >= 0 && isfinite(x->guide_pdf);
        it->share_value = share ? x->share_value : -1.0f;
        it->bsdf_pdf = x->bsdf_pdf;
        it->guide_pdf = x->guide_pdf;
        it->pdf = x->pdf;
        it->delta_child = x->delta_child;
        it->defense = x->delta_child && x->defense > 0 && isfinite(x->defense) ? x->defense : 0.0f;
        if (grouped) ++m;
        else record_item(f, it); /* no scratch: one pass in sample order (the same result) */
    }
    if (!grouped || m == 0) return;
    /* a counting sort by leaf, stable */
    uint32_t *start = f->record.start, *order = f->record.order;
    memset(start, 0, ((size_t)f->leaf_count + 1) * sizeof *start);
    for (size_t i = 0; i < m; ++i) start[items[i].leaf + 1]++;
    for (uint32_t l = 0; l < f->leaf_count; ++l) start[l + 1] += start[l];
    for (size_t i = 0; i < m; ++i) order[start[items[i].leaf]++] = (uint32_t)i;
    for (size_t i = 0; i < m; ++i) record_item(f, &items[order[i]]);
}

/* Level `level` of the complete subtree replacing a leaf at depth `depth` splits its boxes on
 * axis (depth + level) % 3; the two halves must stay non-degenerate in float, so the half
 * width must be well above the precision of the coordinates. */
static int split_is_sound(const float lo[3], const float hi[3], int depth, int level) {
    int axis = (depth + level) % 3, earlier = 0; /* earlier levels of the subtree on this axis */
    for (int l = 0; l < level; ++l) earlier += (depth + l) % 3 == axis;
    double width = ldexp((double)hi[axis] - (double)lo[axis], -earlier);
    double mag = fmax(fabs((double)lo[axis]), fabs((double)hi[axis]));
    return 0.5 * width > 64.0 * FLT_EPSILON * fmax(mag, width);
}

/* Appends the two children of node idx (a leaf) and turns it into their parent. */
static void spatial_split(SpatialNode *nodes, uint32_t idx, uint32_t *count) {
    SpatialNode *n = &nodes[idx];
    int axis = n->depth % 3;
    float mid = split_mid(n->lo[axis], n->hi[axis]);
    uint32_t c = *count;
    *count += 2;
    SpatialNode child = *n;
    child.child = 0;
    child.leaf = 0;
    child.split = 0;
    child.axis = 0;
    child.depth = (uint8_t)(n->depth + 1);
    nodes[c] = child;
    nodes[c + 1] = child;
    nodes[c].hi[axis] = mid;
    nodes[c + 1].lo[axis] = mid;
    n->child = c;
    n->axis = (uint8_t)axis;
    n->split = mid;
}

int guide_field_update(GuideField *f, float iteration_spp) {
    if (!f) return -1;
    const GuideFieldParams *p = &f->params;
    const uint32_t old_leaves = f->leaf_count;
    /* §3: the split threshold grows with the iteration, c sqrt(2^k). Each iteration takes
     * twice the samples of the last; a threshold growing by sqrt 2 lets the number of leaves
     * and the samples per leaf both grow by sqrt 2, so the spatial and the directional
     * resolution refine together. */
    /* 2^k is the samples per pixel of PPG's iteration k; a schedule of other sizes (the
     * guided schedule repeats 1 spp) gives its own */
    double spp = isfinite(iteration_spp) && iteration_spp >= 1.0f ? (double)iteration_spp : 1.0;
    double threshold = (double)p->spatial_threshold * sqrt(spp);
    uint32_t node_limit = quadtree_node_limit(p);

    QuadTree *rebuilt = calloc(old_leaves, sizeof *rebuilt);
    uint8_t *levels = calloc(old_leaves, 1);
    RebuildScratch scratch = {0};
    SpatialNode *new_nodes = NULL;
    DescentNode *new_descent = NULL;
    GuideLeaf *new_leaves = NULL;
    GuideDistribution *new_dists = NULL;
    PdfNode *flat_nodes = NULL;
    SampleCell *flat_cells = NULL;
    AliasScratch alias = {0};
    uint32_t new_leaf_count = 0;
    if (!rebuilt || !levels) goto fail;

    /* 1. The directional rebuild of every leaf that saw flux. */
    for (uint32_t i = 0; i < old_leaves; ++i) {
        const GuideLeaf *l = &f->leaves[i];
        if (!(l->recorded > 0) || l->building.count == 0) continue;
        double total = node_total(&l->building.nodes[0]);
        if (!(total > 0) || !isfinite(total)) continue; /* keep the previous sampling tree */
        if (quadtree_rebuild(&l->building, p->flux_threshold, p->max_quadtree_depth, node_limit, &scratch, &rebuilt[i]))
            goto fail;
    }
    scratch_free(&scratch);

    /* 2. The spatial splits, within the memory cap: each extra leaf costs its two D-trees,
     * its leaf record and two spatial nodes. Leaves are visited in index order, so the cap
     * cuts deterministically. */
    size_t projected = FIELD_FIXED_BYTES + (size_t)f->node_count * NODE_BYTES + (size_t)old_leaves * sizeof(GuideLeaf);
    for (uint32_t i = 0; i < old_leaves; ++i)
        projected += rebuilt[i].count ? rebuilt_tree_bytes(&rebuilt[i]) : leaf_tree_bytes(&f->leaves[i]);
    uint64_t total_leaves = old_leaves, total_nodes = f->node_count;
    for (uint32_t i = 0; i < old_leaves; ++i) {
        const GuideLeaf *l = &f->leaves[i];
        const SpatialNode *node = &f->nodes[l->node];
        size_t trees = rebuilt[i].count ? rebuilt_tree_bytes(&rebuilt[i]) : leaf_tree_bytes(l);
        size_t per_leaf = trees + sizeof(GuideLeaf) + 2 * NODE_BYTES;
        double count = l->recorded;
        int s = 0;
        while (count > threshold && node->depth + s < SPATIAL_MAX_DEPTH &&
               split_is_sound(node->lo, node->hi, node->depth, s)) {
            uint64_t added = (uint64_t)1 << s; /* doubling the subtree's leaves */
            if (total_leaves + added > LEAF_LIMIT) break;
            if (projected > p->max_bytes || per_leaf > (p->max_bytes - projected) / added) break;
            projected += per_leaf * (size_t)added;
            total_leaves += added;
            total_nodes += 2 * added;
            count *= 0.5;
            ++s;
        }
        levels[i] = (uint8_t)s;
    }

    /* 3. Allocate the new state. Entries [0, old_leaves) of new_leaves take over the old
     * leaves (only their new building trees are allocated here); the extra leaves of each
     * split follow in leaf order, each with its own copies. */
    new_leaf_count = (uint32_t)total_leaves;
    new_nodes = malloc((size_t)total_nodes * sizeof *new_nodes);
    new_descent = malloc((size_t)total_nodes * sizeof *new_descent);
    new_leaves = calloc(new_leaf_count, sizeof *new_leaves);
    new_dists = malloc(new_leaf_count * sizeof *new_dists);
    if (!new_nodes || !new_descent || !new_leaves || !new_dists) goto fail;
    uint32_t extra = old_leaves;
    for (uint32_t i = 0; i < old_leaves; ++i) {
        const GuideLeaf *l = &f->leaves[i];
        int s = levels[i];
        /* accumulating: the flux learned so far stays in the building tree (L / pdf is an unbiased
         * estimate of a cell's flux whatever pdf sampled it, so earlier iterations' samples
         * remain valid), and a guided schedule of 1-spp iterations no longer rebuilds every
         * leaf from a handful of non-zero samples (which collapsed the pdf onto the few
         * directions that happened to find light) */
        const int acc = p->accumulate;
        if (rebuilt[i].count && quadtree_copy(&rebuilt[i], acc ? -s : 0, !acc, &new_leaves[i].building)) goto fail;
        const QuadTree *sampling = rebuilt[i].count ? &rebuilt[i] : &l->sampling;
        const QuadTree *building = rebuilt[i].count ? &rebuilt[i] : &l->building;
        int exponent = rebuilt[i].count ? -s : 0; /* half the statistics per split */
        for (uint32_t j = 1; j < ((uint32_t)1 << s); ++j, ++extra) {
            if (quadtree_copy(sampling, exponent, 0, &new_leaves[extra].sampling)) goto fail;
            if (quadtree_copy(building, acc && rebuilt[i].count ? -s : 0, !acc, &new_leaves[extra].building)) goto fail;
        }
    }

    /* The flat sampling trees of the new state (filled after the commit). */
    size_t flat_count = 0, cell_count = 0, max_cells = 0;
    for (uint32_t i = 0; i < new_leaf_count; ++i) {
        const QuadTree *t = i < old_leaves ? (rebuilt[i].count ? &rebuilt[i] : &f->leaves[i].sampling) : &new_leaves[i].sampling;
        flat_count += t->count;
        cell_count += tree_cells(t);
        if (tree_cells(t) > max_cells) max_cells = tree_cells(t);
    }
    if (flat_count > UINT32_MAX - 1) goto fail; /* node indices stay below NO_FLAT_TREE */
    flat_nodes = flat_alloc((flat_count ? flat_count : 1) * sizeof *flat_nodes);
    flat_cells = slots_alloc(cell_count);
    if (!flat_nodes || !flat_cells || alias_scratch_alloc(&alias, max_cells)) goto fail;

    /* 4. Commit: nothing below allocates or fails. */
    memcpy(new_nodes, f->nodes, (size_t)f->node_count * sizeof *new_nodes);
    uint32_t node_count = f->node_count;
    extra = old_leaves;
    for (uint32_t i = 0; i < old_leaves; ++i) {
        GuideLeaf *old = &f->leaves[i], *nl = &new_leaves[i];
        int s = levels[i];
        if (rebuilt[i].count) {
            quadtree_scale(&rebuilt[i], -s);
            nl->sampling = rebuilt[i];
            rebuilt[i] = (QuadTree){NULL, 0};
            quadtree_free(&old->sampling);
            quadtree_free(&old->building);
            nl->learned = ldexp(old->recorded, -s);
        } else {
            nl->sampling = old->sampling;
            nl->building = old->building;
            if (!p->accumulate) quadtree_zero(&nl->building);
            nl->learned = ldexp(old->learned, -s);
        }
        nl->recorded = p->accumulate ? ldexp(old->recorded, -s) : 0;
        nl->node = old->node;
        leaf_choose_share(f, old);
        nl->bsdf_share = old->bsdf_share;
        if (s == 0) { /* an unsplit leaf keeps sums too few to choose from; split ones start again */
            nl->share_count = old->share_count;
            memcpy(nl->share_moment, old->share_moment, sizeof nl->share_moment);
            memcpy(nl->share_diff2, old->share_diff2, sizeof nl->share_diff2);
            nl->share_bsdf_mass = old->share_bsdf_mass;
            nl->share_delta_mass = old->share_delta_mass;
            nl->share_flux = old->share_flux;
            nl->share_delta_flux = old->share_delta_flux;
        }
        if (s > 0) {
            /* The complete subtree, level by level; each level's nodes are contiguous. */
            spatial_split(new_nodes, old->node, &node_count);
            uint32_t first = node_count - 2, end = node_count;
            for (int level = 1; level < s; ++level) {
                for (uint32_t j = first; j < end; ++j) spatial_split(new_nodes, j, &node_count);
                first = end;
                end = node_count;
            }
            for (uint32_t j = first; j < end; ++j) {
                uint32_t li = j == first ? i : extra++;
                GuideLeaf *dst = &new_leaves[li];
                if (li != i) {
                    dst->learned = nl->learned;
                    dst->recorded = nl->recorded;
                    dst->bsdf_share = nl->bsdf_share;
                }
                dst->node = j;
                new_nodes[j].leaf = li;
            }
        }
        new_nodes[nl->node].leaf = i;
    }
    for (uint32_t i = 0; i < new_leaf_count; ++i) {
        const SpatialNode *n = &new_nodes[new_leaves[i].node];
        memcpy(new_leaves[i].lo, n->lo, sizeof n->lo);
        memcpy(new_leaves[i].hi, n->hi, sizeof n->hi);
    }
    free(f->nodes);
    free(f->descent);
    free(f->leaves);
    free(f->dists);
    f->nodes = new_nodes;
    f->node_count = node_count;
    descent_fill(new_descent, f->grid, f->grid_split, new_nodes, node_count);
    f->descent = new_descent;
    f->leaves = new_leaves;
    f->dists = new_dists;
    f->leaf_count = new_leaf_count;
    field_flatten(f->leaves, f->dists, f->leaf_count, flat_nodes, flat_cells, &alias);
    alias_scratch_free(&alias);
    free(f->pdf_nodes);
    free(f->cells);
    f->pdf_nodes = flat_nodes;
    f->cells = flat_cells;
    f->iterations += 1;
    free(rebuilt);
    free(levels);
    return 0;

fail:
    scratch_free(&scratch);
    if (rebuilt)
        for (uint32_t i = 0; i < old_leaves; ++i) quadtree_free(&rebuilt[i]);
    leaves_free(new_leaves, new_leaf_count);
    free(new_dists);
    free(rebuilt);
    free(levels);
    free(new_nodes);
    free(new_descent);
    free(flat_nodes);
    free(flat_cells);
    alias_scratch_free(&alias);
    return -1;
}

/* ------------------------------------------------------------------ distributions */

const GuideDistribution *guide_field_lookup(const GuideField *f, const float pos[3]) {
    if (!f) return NULL;
    static const float origin[3] = {0, 0, 0};
    return &f->dists[field_find_leaf(f, pos ? pos : origin)];
}

uint32_t guide_field_leaf_of(const GuideField *f, const GuideDistribution *d) {
    if (!f || !d || d < f->dists || d >= f->dists + f->leaf_count) return GUIDE_NO_LEAF;
    return (uint32_t)(d - f->dists);
}

/* Density over the (u, v) square: the descent to the cell holding (u, v), which stores it. */
static float flat_pdf_uv(const GuideDistribution *d, double u, double v) {
    if (d->pdf_root == NO_FLAT_TREE) return 1.0f;
    const PdfNode *nodes = d->pdf_nodes;
    uint32_t i = d->pdf_root;
    for (;;) {
        int qx = u >= 0.5, qy = v >= 0.5;
        uint32_t e = nodes[i].q[qx + 2 * qy];
        if (!(e & PDF_CHILD)) {
            float pdf;
            memcpy(&pdf, &e, sizeof pdf);
            return pdf;
        }
        i = e & ~PDF_CHILD;
        u = 2 * u - qx; /* exact in binary floating point */
        v = 2 * v - qy;
    }
}

/* A point of the (u, v) square: the slot from the alias table with u1 (the rescaled
 * remainder of u1 places it across the cell: u1 is a float and a leaf has at most a few
 * thousand cells, so a dozen bits or more are left), u2 places it down the cell. */
/* The alias slot u1 picks (of a leaf with cells) and u1 scaled to the slots in *x: what
 * flat_sample reads and guide_distribution_prefetch_sample fetches. */
static uint32_t slot_index(const GuideDistribution *d, double u1, double *x) {
    *x = u1 * d->cell_count;
    uint32_t i = (uint32_t)*x;
    return i < d->cell_count ? i : d->cell_count - 1;
}

static void flat_sample(const GuideDistribution *d, double u1, double u2, double *u, double *v, float *pdf_uv) {
    if (!d || !d->cells) {
        *u = u1;
        *v = u2;
        *pdf_uv = 1.0f;
        return;
    }
    double x;
    uint32_t i = slot_index(d, u1, &x);
    double frac = x - i;
    const SampleCell *c = &d->cells[i];
    uint64_t b = c->packed;
    double keep = (double)(b & 0xFFFFu) * 0x1p-16;
    int k = !(frac < keep);
    frac = k ? (frac - keep) / (1.0 - keep) : frac / keep; /* keep < 1; keep > 0 when frac < keep */
    uint32_t cell = (uint32_t)(b >> (16 + 24 * k)) & 0xFFFFFFu;
    uint64_t size_bits = (uint64_t)(1023u - (cell >> 20)) << 52; /* 2^-level, exactly (no libm call) */
    double size;
    memcpy(&size, &size_bits, sizeof size);
    *u = clamp_unit_open(size * ((double)((cell >> 10) & 1023u) + clamp_unit_open(frac)));
    *v = clamp_unit_open(size * ((double)(cell & 1023u) + u2));
    *pdf_uv = c->pdf_uv[k];
}

/* The slot flat_sample reads for u1. */
void guide_distribution_prefetch_sample(const GuideDistribution *d, float u1) {
    if (!d || !d->cells) return;
    double x;
    __builtin_prefetch(&d->cells[slot_index(d, clamp_unit_open(u1), &x)]);
}

void guide_distribution_prefetch_pdf(const GuideDistribution *d) {
    if (d && d->pdf_root != NO_FLAT_TREE) __builtin_prefetch(&d->pdf_nodes[d->pdf_root]);
}

float guide_distribution_pdf(const GuideDistribution *d, const float dir[3]) {
    double u, v, jacobian;
    if (!d || !dir || !dir_to_uv(dir, &u, &v, &jacobian)) return 0;
    return flat_pdf_uv(d, u, v) * (float)jacobian;
}

void guide_distribution_sample(const GuideDistribution *d, float u1, float u2, float dir[3], float *pdf) {
    double u, v, jacobian;
    float pdf_uv;
    flat_sample(d, clamp_unit_open(u1), clamp_unit_open(u2), &u, &v, &pdf_uv);
    uv_to_dir(u, v, dir, &jacobian);
    /* The density of the cell the descent chose: the product guide_distribution_pdf forms for
     * the direction, level by level (they can differ only where the float direction rounds
     * across a cell boundary, a measure-zero set; evaluating the pdf again was a third of
     * guiding's cost). */
    if (pdf) *pdf = pdf_uv * (float)jacobian;
}

int guide_direction_uv(const float dir[3], float *u, float *v) {
    double a, b;
    if (!dir || !dir_to_uv(dir, &a, &b, NULL)) return 0;
    *u = (float)a;
    *v = (float)b;
    return 1;
}

double guide_distribution_samples(const GuideDistribution *d) { return d ? d->leaf->learned : 0.0; }

float guide_distribution_flux(const GuideDistribution *d) { return d ? d->flux : 0.0f; }

float guide_distribution_bsdf_share(const GuideDistribution *d) { return d ? d->bsdf_share : GUIDE_DEFAULT_BSDF_SHARE; }

void guide_field_share_leaves(const GuideField *f, uint32_t counts[GUIDE_SHARE_CANDIDATES]) {
    for (int k = 0; k < SHARE_CANDIDATES; ++k) counts[k] = 0;
    if (!f) return;
    for (uint32_t i = 0; i < f->leaf_count; ++i)
        for (int k = 0; k < SHARE_CANDIDATES; ++k) counts[k] += f->leaves[i].bsdf_share == guide_share_candidates[k];
}

void guide_distribution_bounds(const GuideDistribution *dist, float lo[3], float hi[3]) {
    const GuideLeaf *d = dist ? dist->leaf : NULL;
    if (!d) return;
    for (int k = 0; k < 3; ++k) {
        if (lo) lo[k] = d->lo[k];
        if (hi) hi[k] = d->hi[k];
    }
}

void guide_distribution_image(const GuideDistribution *d, int w, int h, float *out) {
    if (!d || !out || w <= 0 || h <= 0) return;
    for (int row = 0; row < h; ++row)
        for (int col = 0; col < w; ++col) {
            double u = (col + 0.5) / w, v = (row + 0.5) / h, jacobian;
            float dir[3];
            uv_to_dir(u, v, dir, &jacobian);
            out[(size_t)row * (size_t)w + (size_t)col] = flat_pdf_uv(d, u, v) * (float)jacobian;
        }
}

/* ------------------------------------------------------------------ PLY */

int guide_field_write_ply(const GuideField *f, FILE *fp) {
    if (!f || !fp) {
        errno = EINVAL;
        return -1;
    }
    int bad = 0;
    uint32_t n = f->leaf_count;
    /* Per vertex (repeated on a box's 8 corners): the samples the leaf's sampling tree was
     * learned from, the samples recorded since the last update, and the size of its sampling
     * quadtree in nodes, so a viewer can colour the boxes by any of them. */
    bad |= fprintf(fp,
                   "ply\nformat ascii 1.0\ncomment candela guiding field (PPG SD-tree), %d updates\n"
                   "element vertex %lu\nproperty float x\nproperty float y\nproperty float z\n"
                   "property float samples\nproperty float recorded\nproperty float quadtree_nodes\n"
                   "element face %lu\nproperty list uchar int vertex_indices\nend_header\n",
                   f->iterations, 8ul * n, 6ul * n) < 0;
    for (uint32_t i = 0; i < n && !bad; ++i) {
        const GuideLeaf *l = &f->leaves[i];
        for (int c = 0; c < 8 && !bad; ++c) {
            float x = (c & 1) ? l->hi[0] : l->lo[0];
            float y = (c & 2) ? l->hi[1] : l->lo[1];
            float z = (c & 4) ? l->hi[2] : l->lo[2];
            bad |= fprintf(fp, "%.9g %.9g %.9g %.9g %.9g %lu\n", x, y, z, l->learned, l->recorded,
                           (unsigned long)l->sampling.count) < 0;
        }
    }
    /* Corner c = bx + 2 by + 4 bz; each face counter-clockwise seen from outside. */
    static const unsigned long faces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
    for (uint32_t i = 0; i < n && !bad; ++i) {
        unsigned long base = 8ul * i;
        for (int k = 0; k < 6 && !bad; ++k)
            bad |= fprintf(fp, "4 %lu %lu %lu %lu\n", base + faces[k][0], base + faces[k][1], base + faces[k][2],
                           base + faces[k][3]) < 0;
    }
    /* what the stream still buffers is written now, so that a full disk is this call's failure */
    if (!bad && (fflush(fp) != 0 || ferror(fp))) {
        if (!errno) errno = EIO;
        return -1;
    }
    return bad ? -1 : 0;
}

/* ------------------------------------------------------------------ checkpoint (save / load) */

/* The field's whole state (the spatial tree, every leaf's sampling and building quadtrees and
 * counts, the update count and the spatial filter's sample counter) in native byte order, so a
 * resumed render trains and samples bit-identically. Structs are written member by member:
 * their padding never reaches the file. */
#define FIELD_MAGIC 0x44544453u /* "SDTD" */
#define FIELD_VERSION 2u /* 2: each leaf's BSDF share and its sums (learned, caustic guard) */

static int put(FILE *out, const void *p, size_t n) { return fwrite(p, 1, n, out) == n ? 0 : -1; }
/* A load reads through this: `left` is what the file still holds, so that no count it declares
 * (a damaged or forged checkpoint's) allocates or walks more records than the bytes could hold
 * (a 16M-leaf count in a 33 KB file took fuzz_film 9 s to allocate and free). */
typedef struct FieldReader {
    FILE *in;
    uint64_t left;
} FieldReader;

static int get(FieldReader *r, void *p, size_t n) {
    if (n > r->left || fread(p, 1, n, r->in) != n) return -1;
    r->left -= n;
    return 0;
}

/* What the file holds after the current position (UINT64_MAX: not a seekable file). */
static uint64_t bytes_left(FILE *in) {
    long at = ftell(in), end = -1;
    if (at >= 0 && fseek(in, 0, SEEK_END) == 0) end = ftell(in);
    if (at < 0 || fseek(in, at, SEEK_SET) != 0) return UINT64_MAX;
    return end >= at ? (uint64_t)(end - at) : UINT64_MAX;
}

/* The bytes a record takes in the file (member by member, as written below). */
#define QUAD_NODE_BYTES (sizeof(((QuadNode *)0)->sum) + sizeof(((QuadNode *)0)->child))
#define SPATIAL_NODE_BYTES (6 * sizeof(float) + sizeof(((SpatialNode *)0)->split) + sizeof(((SpatialNode *)0)->child) + \
                            sizeof(((SpatialNode *)0)->leaf) + 2)
#define LEAF_MIN_BYTES (sizeof(((GuideLeaf *)0)->recorded) + sizeof(((GuideLeaf *)0)->learned) + 6 * sizeof(float) + \
                        sizeof(uint32_t) + 2 * sizeof(uint32_t) + sizeof(float) + (2 * SHARE_CANDIDATES + 5) * sizeof(double))

static int quadtree_save(const QuadTree *t, FILE *out) {
    int rc = put(out, &t->count, sizeof t->count);
    for (uint32_t i = 0; i < t->count && rc == 0; ++i)
        rc = put(out, t->nodes[i].sum, sizeof t->nodes[i].sum) | put(out, t->nodes[i].child, sizeof t->nodes[i].child);
    return rc;
}

static int quadtree_load(QuadTree *t, uint32_t max_nodes, FieldReader *in) {
    uint32_t count;
    if (get(in, &count, sizeof count) || count > max_nodes || (uint64_t)count * QUAD_NODE_BYTES > in->left) return -1;
    t->count = 0;
    t->nodes = NULL;
    if (count == 0) return 0;
    t->nodes = calloc(count, sizeof *t->nodes);
    if (!t->nodes) return -1;
    t->count = count;
    for (uint32_t i = 0; i < count; ++i) {
        if (get(in, t->nodes[i].sum, sizeof t->nodes[i].sum) || get(in, t->nodes[i].child, sizeof t->nodes[i].child))
            return -1;
        for (int q = 0; q < 4; ++q) /* a child is created after its parent (see Layout) */
            if (t->nodes[i].child[q] != 0 && (t->nodes[i].child[q] <= i || t->nodes[i].child[q] >= count)) return -1;
    }
    return 0;
}

int guide_field_save(const GuideField *f, FILE *out) {
    uint32_t head[4] = {FIELD_MAGIC, FIELD_VERSION, f->node_count, f->leaf_count};
    int32_t iterations = f->iterations;
    int rc = put(out, head, sizeof head) | put(out, &iterations, sizeof iterations) |
             put(out, &f->recorded_total, sizeof f->recorded_total);
    for (uint32_t i = 0; i < f->node_count && rc == 0; ++i) {
        const SpatialNode *n = &f->nodes[i];
        rc = put(out, n->lo, sizeof n->lo) | put(out, n->hi, sizeof n->hi) | put(out, &n->split, sizeof n->split) |
             put(out, &n->child, sizeof n->child) | put(out, &n->leaf, sizeof n->leaf) | put(out, &n->axis, 1) |
             put(out, &n->depth, 1);
    }
    for (uint32_t i = 0; i < f->leaf_count && rc == 0; ++i) {
        const GuideLeaf *l = &f->leaves[i];
        rc = put(out, &l->recorded, sizeof l->recorded) | put(out, &l->learned, sizeof l->learned) |
             put(out, l->lo, sizeof l->lo) | put(out, l->hi, sizeof l->hi) | put(out, &l->node, sizeof l->node);
        if (rc == 0)
            rc = put(out, &l->bsdf_share, sizeof l->bsdf_share) | put(out, &l->share_count, sizeof l->share_count) |
                 put(out, l->share_moment, sizeof l->share_moment) | put(out, l->share_diff2, sizeof l->share_diff2) |
                 put(out, &l->share_bsdf_mass, sizeof l->share_bsdf_mass) |
                 put(out, &l->share_delta_mass, sizeof l->share_delta_mass) |
                 put(out, &l->share_flux, sizeof l->share_flux) | put(out, &l->share_delta_flux, sizeof l->share_delta_flux);
        if (rc == 0) rc = quadtree_save(&l->sampling, out);
        if (rc == 0) rc = quadtree_save(&l->building, out);
    }
    return rc;
}

int guide_field_load(GuideField *f, FILE *file) {
    FieldReader reader = {file, bytes_left(file)}, *in = &reader;
    uint32_t head[4];
    int32_t iterations;
    uint64_t recorded_total;
    if (get(in, head, sizeof head) || head[0] != FIELD_MAGIC || head[1] != FIELD_VERSION) return -1;
    uint32_t node_count = head[2], leaf_count = head[3];
    /* the memory cap bounds what a valid field can hold */
    if (node_count == 0 || leaf_count == 0 || leaf_count > LEAF_LIMIT || node_count > 2 * leaf_count ||
        (size_t)node_count * sizeof(SpatialNode) > f->params.max_bytes ||
        (uint64_t)node_count * SPATIAL_NODE_BYTES + (uint64_t)leaf_count * LEAF_MIN_BYTES > in->left)
        return -1;
    if (get(in, &iterations, sizeof iterations) || get(in, &recorded_total, sizeof recorded_total) || iterations < 0)
        return -1;
    GuideField g = *f; /* the loaded state, committed only when complete */
    g.nodes = calloc(node_count, sizeof *g.nodes);
    g.descent = malloc(node_count * sizeof *g.descent);
    g.leaves = calloc(leaf_count, sizeof *g.leaves);
    g.dists = malloc(leaf_count * sizeof *g.dists);
    g.node_count = node_count;
    g.leaf_count = leaf_count;
    int rc = g.nodes && g.descent && g.leaves && g.dists ? 0 : -1;
    for (uint32_t i = 0; i < node_count && rc == 0; ++i) {
        SpatialNode *n = &g.nodes[i];
        rc = get(in, n->lo, sizeof n->lo) | get(in, n->hi, sizeof n->hi) | get(in, &n->split, sizeof n->split) |
             get(in, &n->child, sizeof n->child) | get(in, &n->leaf, sizeof n->leaf) | get(in, &n->axis, 1) |
             get(in, &n->depth, 1);
        if (rc == 0 && (n->child != 0 ? (n->child <= i || n->child >= node_count - 1 || n->axis > 2)
                                      : n->leaf >= leaf_count))
            rc = -1;
    }
    /* the tree the splits make: the root at depth 0, children one deeper, each node split on
     * axis depth % 3 (the lookup grid takes the top levels' cells from that rule) */
    if (rc == 0 && g.nodes[0].depth != 0) rc = -1;
    for (uint32_t i = 0; i < node_count && rc == 0; ++i) {
        const SpatialNode *n = &g.nodes[i];
        if (n->child != 0 && (n->axis != n->depth % 3 || g.nodes[n->child].depth != n->depth + 1 ||
                              g.nodes[n->child + 1].depth != n->depth + 1))
            rc = -1;
    }
    uint32_t max_nodes = quadtree_node_limit(&f->params);
    for (uint32_t i = 0; i < leaf_count && rc == 0; ++i) {
        GuideLeaf *l = &g.leaves[i];
        rc = get(in, &l->recorded, sizeof l->recorded) | get(in, &l->learned, sizeof l->learned) |
             get(in, l->lo, sizeof l->lo) | get(in, l->hi, sizeof l->hi) | get(in, &l->node, sizeof l->node);
        if (rc == 0 && l->node >= node_count) rc = -1;
        if (rc == 0)
            rc = get(in, &l->bsdf_share, sizeof l->bsdf_share) | get(in, &l->share_count, sizeof l->share_count) |
                 get(in, l->share_moment, sizeof l->share_moment) | get(in, l->share_diff2, sizeof l->share_diff2) |
                 get(in, &l->share_bsdf_mass, sizeof l->share_bsdf_mass) |
                 get(in, &l->share_delta_mass, sizeof l->share_delta_mass) |
                 get(in, &l->share_flux, sizeof l->share_flux) | get(in, &l->share_delta_flux, sizeof l->share_delta_flux);
        if (rc == 0 && !(l->bsdf_share > 0 && l->bsdf_share <= 1)) rc = -1; /* a share the sampling can use */
        if (rc == 0) rc = quadtree_load(&l->sampling, max_nodes, in);
        if (rc == 0) rc = quadtree_load(&l->building, max_nodes, in);
    }
    if (rc != 0) {
        leaves_free(g.leaves, leaf_count);
        free(g.dists);
        free(g.nodes);
        free(g.descent);
        return -1;
    }
    /* the lookups' flat trees and alias tables, built from the sampling trees as an update does */
    size_t flat_count = 0, cell_count = 0, max_cells = 0;
    for (uint32_t i = 0; i < leaf_count; ++i) {
        flat_count += g.leaves[i].sampling.count;
        cell_count += tree_cells(&g.leaves[i].sampling);
        if (tree_cells(&g.leaves[i].sampling) > max_cells) max_cells = tree_cells(&g.leaves[i].sampling);
    }
    PdfNode *flat_nodes = flat_alloc((flat_count ? flat_count : 1) * sizeof *flat_nodes);
    SampleCell *flat_cells = slots_alloc(cell_count);
    AliasScratch alias = {0};
    if (!flat_nodes || !flat_cells || alias_scratch_alloc(&alias, max_cells)) {
        free(flat_nodes);
        free(flat_cells);
        leaves_free(g.leaves, leaf_count);
        free(g.dists);
        free(g.nodes);
        free(g.descent);
        return -1;
    }
    descent_fill(g.descent, g.grid, g.grid_split, g.nodes, node_count);
    field_flatten(g.leaves, g.dists, leaf_count, flat_nodes, flat_cells, &alias);
    alias_scratch_free(&alias);
    leaves_free(f->leaves, f->leaf_count);
    free(f->dists);
    free(f->nodes);
    free(f->descent);
    free(f->pdf_nodes);
    free(f->cells);
    g.pdf_nodes = flat_nodes;
    g.cells = flat_cells;
    g.iterations = iterations;
    g.recorded_total = recorded_total;
    *f = g;
    return 0;
}
