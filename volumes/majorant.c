/* volumes/majorant.c: the majorant grid of a VDB medium and the DDA over it.
 *
 * Null-collision tracking (the cache points paper §4.1, Eq. 7) needs sigma_maj >= sigma_t
 * along the ray; the tighter it is, the fewer null collisions. A coarse grid of
 * VOLUME_MAJORANT_CELL^3-voxel cells, each bounding its cell's trilinear field, gives a
 * piecewise-constant majorant; free flights restart at each cell boundary, which is exact for
 * exponential distances (memorylessness). Where the medium emits, the cell also carries the
 * emission term of §4.3 (Algorithm 1) as fixed in the spec (§7.4):
 *     sigma_maj = max(sigma_t,max, min(kappa lum(sigma_a L_e)_max, c_vox / voxel_size)),
 * kappa = c_vox = 1: emissive regions of low extinction get collisions (each gathers
 * emission), at most about one expected per voxel from the emission term.
 *
 * Cells are aligned with NanoVDB's 8^3 leaves (VOLUME_MAJORANT_CELL == 8), so a cell's
 * voxels are one leaf's value table or one tile value: the build reads every stored value
 * once, never a whole dense box. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

_Static_assert(VOLUME_MAJORANT_CELL == 8, "cells are NanoVDB leaves (8^3)");

static inline int32_t floor_div8(int32_t v) { return v >= 0 ? v / 8 : -((-v + 7) / 8); }

/* ---------------------------------------------------------------- block maxima */

/* Per 8^3 block of a grid (leaf-aligned): the max of its clean values, and of its six
 * two-voxel-thick faces (x lo = local x in {0, 1}, x hi = {6, 7}, then y, z). */
enum { BLK_ALL = 0, BLK_FACES = 7 };
typedef struct BlockTable {
    int32_t origin[3]; /* first voxel of block (0,0,0), a multiple of 8 */
    int32_t dims[3];
    int nvals;         /* 1 (block max only) or BLK_FACES */
    float *v;          /* nvals per block, x fastest */
} BlockTable;

static size_t block_index(const BlockTable *b, int32_t x, int32_t y, int32_t z) {
    return ((size_t)x + (size_t)b->dims[0] * ((size_t)y + (size_t)b->dims[1] * (size_t)z)) * (size_t)b->nvals;
}

static int block_table_alloc(BlockTable *b, const int32_t origin[3], const int32_t dims[3], int32_t layers, int nvals) {
    memcpy(b->origin, origin, sizeof b->origin);
    memcpy(b->dims, dims, sizeof b->dims);
    b->nvals = nvals;
    b->v = malloc((size_t)dims[0] * (size_t)dims[1] * (size_t)layers * (size_t)nvals * sizeof(float));
    return b->v ? 0 : -1;
}

/* Fills the z layer bz of blocks (voxels origin + 8 (x, y, bz) ...) into the table's layer
 * `slot`. A block is a leaf (512 values from its table) or lies in a tile / the background
 * (one value). */
static void block_layer_fill(BlockTable *b, GridReader *r, int32_t bz, int32_t slot, int take_min) {
    for (int32_t by = 0; by < b->dims[1]; ++by)
        for (int32_t bx = 0; bx < b->dims[0]; ++bx) {
            float *out = b->v + block_index(b, bx, by, slot);
            uint32_t level;
            float tile =
                grid_voxel_level(r, b->origin[0] + 8 * bx, b->origin[1] + 8 * by, b->origin[2] + 8 * bz, &level);
            if (level != 0) {
                for (int k = 0; k < b->nvals; ++k) out[k] = tile;
                continue;
            }
            pnanovdb_leaf_handle_t leaf = r->acc.leaf; /* the lookup above cached it */
            float mx[BLK_FACES];
            for (int k = 0; k < BLK_FACES; ++k) mx[k] = take_min ? FLT_MAX : 0.0f;
            for (uint32_t i = 0; i < 512; ++i) {
                float v = vol_clean(pnanovdb_read_float(
                    r->buf, pnanovdb_leaf_get_table_address(PNANOVDB_GRID_TYPE_FLOAT, r->buf, leaf, i)));
                if (take_min) {
                    mx[0] = vminf(mx[0], v);
                } else {
                    mx[0] = vmaxf(mx[0], v);
                }
                if (b->nvals == 1) continue;
                uint32_t l[3] = {i >> 6, (i >> 3) & 7, i & 7}; /* NanoVDB leaf order: x slowest */
                for (int a = 0; a < 3; ++a) {
                    float *lo = &mx[1 + 2 * a], *hi = &mx[2 + 2 * a];
                    if (take_min) {
                        if (l[a] <= 1) *lo = vminf(*lo, v);
                        if (l[a] >= 6) *hi = vminf(*hi, v);
                    } else {
                        if (l[a] <= 1) *lo = vmaxf(*lo, v);
                        if (l[a] >= 6) *hi = vmaxf(*hi, v);
                    }
                }
            }
            for (int k = 0; k < b->nvals; ++k) out[k] = mx[k];
        }
}

/* Max over the block table's blocks overlapping voxels [lo, hi] (inclusive); blocks outside
 * the table hold nothing (the field is 0 beyond the active box's margin, which the table
 * covers). */
static float block_table_max(const BlockTable *b, const int64_t lo[3], const int64_t hi[3]) {
    int32_t b0[3], b1[3];
    for (int k = 0; k < 3; ++k) {
        int64_t l = lo[k] - b->origin[k], h = hi[k] - b->origin[k];
        if (h < 0 || l >= 8 * (int64_t)b->dims[k]) return 0.0f;
        b0[k] = l < 0 ? 0 : (int32_t)(l / 8);
        b1[k] = h >= 8 * (int64_t)b->dims[k] ? b->dims[k] - 1 : (int32_t)(h / 8);
    }
    float mx = 0.0f;
    for (int32_t z = b0[2]; z <= b1[2]; ++z)
        for (int32_t y = b0[1]; y <= b1[1]; ++y)
            for (int32_t x = b0[0]; x <= b1[0]; ++x) mx = vmaxf(mx, b->v[block_index(b, x, y, z)]);
    return mx;
}

/* ---------------------------------------------------------------- build */

/* What a cell's emission term needs (emitting media). */
typedef struct EmitContext {
    const double *i2w;      /* the density grid's index to world (double) */
    const VolumeGrid *ag;   /* the emission (or temperature) grid */
    const BlockTable *aux;  /* its block maxima (the dense form), else: */
    struct AuxCache *cache; /* its block maxima found as asked (the sparse form) */
    float factor, cap;      /* lum(sigma_a L_e) per sigma_t and aux value; c_vox / voxel_size */
} EmitContext;

static float aux_cache_max(struct AuxCache *c, const int64_t lo[3], const int64_t hi[3], float *min_out);

/* The aux grid's voxels [vlo, vhi] whose blocks bound the aux field over the density-index box
 * [p0 - 2, p0 + size + 2] (a cell's box, size 8, with its slack; a brick's, size 64). */
static void aux_box(const EmitContext *ec, const double p0[3], double size, int64_t vlo[3], int64_t vhi[3]) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int corner = 0; corner < 8; ++corner) {
        double p[3], w[3];
        for (int k = 0; k < 3; ++k) p[k] = p0[k] + ((corner >> k & 1) ? size + 2.0 : -2.0);
        for (int r = 0; r < 3; ++r) w[r] = ec->i2w[r] * p[0] + ec->i2w[4 + r] * p[1] + ec->i2w[8 + r] * p[2] + ec->i2w[12 + r];
        for (int r = 0; r < 3; ++r) {
            const float *a = ec->ag->world_to_index;
            double q = a[r] * w[0] + a[4 + r] * w[1] + a[8 + r] * w[2] + a[12 + r];
            lo[r] = fmin(lo[r], q);
            hi[r] = fmax(hi[r], q);
        }
    }
    for (int k = 0; k < 3; ++k) {
        vlo[k] = (int64_t)fmax(floor(lo[k]) - 1.0, -4e9);
        vhi[k] = (int64_t)fmin(floor(hi[k]) + 2.0, 4e9);
    }
}

/* A cell's majorant, coarse majorant and (uncapped) emission term from its extinction bound st
 * and the aux grid's bound amax over its footprint (the header's formula). */
static void emit_terms(const Medium *m, const EmitContext *ec, float st, float amax, float *maj, float *coarse,
                       float *term) {
    float e = m->emission.buffer ? amax : (amax >= BLACKBODY_MIN_KELVIN ? 1.0f : 0.0f);
    *term = st * ec->factor * e; /* kappa = 1 */
    *maj = vmaxf(st, vminf(*term, ec->cap));
    *coarse = vmaxf(st, vminf(*term, ec->cap * (1.0f / VOLUME_LINE_COARSE_VOXELS)));
}

/* One majorant cell c (cell indices; its blocks at bx, by in the block tables, whose z layers
 * below, at and above it are zs[0..2]): the majorant (before the slack), the coarse one, the
 * uncapped emission term (0 unless the medium emits) and the control (with its slack, 0 where
 * it would not lie below the majorant). dmin NULL: no control. */
static void cell_values(const Medium *m, const BlockTable *dens, const BlockTable *dmin, int32_t bx, int32_t by,
                        const int32_t zs[3], const EmitContext *ec, const int32_t c[3], float *maj_out,
                        float *coarse_out, float *term_out, float *ctl_out) {
    const MajorantGrid *mg = &m->majorant;
    float dmax = 0.0f;
    for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                int dd[3] = {dx, dy, dz};
                const float *nb = dens->v + block_index(dens, bx + dx, by + dy, zs[1 + dz]);
                float v = nb[BLK_ALL];
                /* a neighbour contributes its faces towards the cell; a diagonal
                 * one an edge or corner, bounded by the smallest of its faces */
                for (int a = 0; a < 3; ++a)
                    if (dd[a]) v = vminf(v, nb[1 + 2 * a + (dd[a] > 0 ? 0 : 1)]);
                dmax = vmaxf(dmax, v);
            }
    float st = vminf(m->density_scale * dmax, VOLUME_MAX_SIGMA_T);
    float maj = st, maj_coarse = st, term = 0.0f;
    if (m->emissive && st > 0.0f) {
        const double p0[3] = {mg->origin[0] + 8.0 * c[0], mg->origin[1] + 8.0 * c[1], mg->origin[2] + 8.0 * c[2]};
        int64_t vlo[3], vhi[3];
        aux_box(ec, p0, 8.0, vlo, vhi);
        float amax = ec->aux ? block_table_max(ec->aux, vlo, vhi) : aux_cache_max(ec->cache, vlo, vhi, NULL);
        emit_terms(m, ec, st, amax, &maj, &maj_coarse, &term);
    }
    *maj_out = maj;
    *coarse_out = maj_coarse;
    *term_out = term;
    *ctl_out = 0.0f;
    if (dmin) {
        /* the same footprint's minimum: a neighbour's two-voxel face towards the
         * cell; an edge or corner lies in each of its faces, so the largest of
         * their minima bounds it from below */
        float dmn = FLT_MAX;
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    int dd[3] = {dx, dy, dz};
                    const float *nb = dmin->v + block_index(dmin, bx + dx, by + dy, zs[1 + dz]);
                    float v = nb[BLK_ALL];
                    for (int a = 0; a < 3; ++a)
                        if (dd[a]) v = vmaxf(v, nb[1 + 2 * a + (dd[a] > 0 ? 0 : 1)]);
                    dmn = vminf(dmn, v);
                }
        float ctl = vminf(m->density_scale * dmn, VOLUME_MAX_SIGMA_T) * VOL_CONTROL_SLACK;
        *ctl_out = ctl < maj ? ctl : 0.0f;
    }
}

/* ---------------------------------------------------------------- sparse form */

static inline int32_t floor_div(int32_t v, int32_t d) { return v >= 0 ? v / d : -((-v + d - 1) / d); }

/* A brick without voxel data: every block its cells' footprints read (the brick's 64^3 voxels
 * and an 8-voxel ring) lies in a constant region of the tree (an upper node's tile or beyond:
 * level >= 2, 128^3 voxels or more). Found from at most 8 lookups, one per 128^3 region the
 * padded box touches; *hi and *lo are the largest and smallest of their values. With one value
 * the brick is what the dense form computes for each of its cells; with several (a brick on a
 * tile's border) hi and lo bound every cell's footprint, a majorant looser there by at most a
 * brick, where the dense form would hold 512 cells for a file that holds one tile. */
static int brick_tiles(GridReader *r, const int32_t vox0[3], float *hi_out, float *lo_out) {
    int32_t lo[3], hi[3];
    for (int k = 0; k < 3; ++k) {
        lo[k] = floor_div(vox0[k] - 8, 128);
        hi[k] = floor_div(vox0[k] + 64 + 8 - 1, 128);
    }
    float vmax = 0.0f, vmin = FLT_MAX;
    for (int32_t z = lo[2]; z <= hi[2]; ++z)
        for (int32_t y = lo[1]; y <= hi[1]; ++y)
            for (int32_t x = lo[0]; x <= hi[0]; ++x) {
                uint32_t level;
                float v = grid_voxel_level(r, 128 * x, 128 * y, 128 * z, &level);
                if (level < 2) return 0;
                vmax = vmaxf(vmax, v);
                vmin = vminf(vmin, v);
            }
    *hi_out = vmax;
    *lo_out = vmin;
    return 1;
}

/* ---- the sparse form's hash tables (MajorantTable, volumes.h) */

/* What the sparse tables may still take (the budget's share; 0: none) and what they hold. */
typedef struct SparseMem {
    uint64_t budget, used;
    int over;            /* the budget refused a growth */
} SparseMem;

/* The entry of key, inserted (slot -1, maj, ctl) when absent; NULL when the table could not
 * grow (memory or the budget). Doubles the table at half full. */
static MajorantEntry *sp_insert(MajorantTable *t, uint64_t key, float maj, float ctl, SparseMem *mem, int *added) {
    if (added) *added = 0;
    if (2 * (t->count + 1) > t->mask + 1) {
        uint64_t cap = 2 * (t->mask + 1);
        uint64_t bytes = cap * sizeof(MajorantEntry);
        if (mem->budget && mem->used + bytes > mem->budget) {
            mem->over = 1;
            return NULL;
        }
        MajorantEntry *e = calloc((size_t)cap, sizeof *e);
        if (!e) return NULL;
        MajorantTable nt = {e, cap - 1, t->count};
        for (uint64_t i = 0; i <= t->mask; ++i) {
            if (!t->entries[i].key) continue;
            uint64_t j = sp_slot(&nt, t->entries[i].key);
            while (e[j].key) j = (j + 1) & nt.mask;
            e[j] = t->entries[i];
        }
        mem->used += bytes - (t->mask + 1) * sizeof(MajorantEntry);
        free(t->entries);
        *t = nt;
    }
    uint64_t i = sp_slot(t, key);
    while (t->entries[i].key && t->entries[i].key != key) i = (i + 1) & t->mask;
    MajorantEntry *e = &t->entries[i];
    if (!e->key) {
        e->key = key;
        e->slot = -1;
        e->maj = maj;
        e->ctl = ctl;
        ++t->count;
        if (added) *added = 1;
    }
    return e;
}

static int sp_table_init(MajorantTable *t, SparseMem *mem) {
    t->mask = 63;
    t->count = 0;
    t->entries = calloc(64, sizeof *t->entries);
    mem->used += 64 * sizeof *t->entries;
    return t->entries ? 0 : -1;
}

/* The (majorant, control) pair of cells whose footprints hold values in [lo, hi]: what the
 * dense computation gives such a cell, slack included. */
static void sp_pair(const Medium *m, float hi, float lo, float *maj, float *ctl) {
    float st = vminf(m->density_scale * hi, VOLUME_MAX_SIGMA_T);
    float c = vminf(m->density_scale * lo, VOLUME_MAX_SIGMA_T) * VOL_CONTROL_SLACK;
    *maj = st * VOL_MAJORANT_SLACK;
    *ctl = c < st ? c : 0.0f;
}

/* An emitting medium's aux grid (emission or temperature) as the sparse form reads it: its 8^3
 * block maxima found as the cells ask for them and kept (the dense form's table over the aux
 * grid's box would be the box again), over the same block range as that table. */
struct AuxCache {
    GridReader reader;
    int32_t lo[3], hi[3]; /* blocks (voxels / 8) of the aux grid's box, as block tables cover it */
    MajorantTable table;
    SparseMem mem;        /* unbounded: it holds one entry per block read, in proportion to the data */
};

static float aux_block(struct AuxCache *c, int32_t bx, int32_t by, int32_t bz, float *min_out) {
    uint64_t key = sp_key(bx - c->lo[0], by - c->lo[1], bz - c->lo[2]);
    if (c->table.entries) {
        const MajorantEntry *e = sp_find(&c->table, key);
        if (e) {
            *min_out = e->ctl;
            return e->maj;
        }
    }
    uint32_t level;
    float v = grid_voxel_level(&c->reader, 8 * bx, 8 * by, 8 * bz, &level), mn = v;
    if (level == 0) { /* a leaf: the max of its clean values, as block_layer_fill takes it */
        pnanovdb_leaf_handle_t leaf = c->reader.acc.leaf;
        v = 0.0f;
        mn = FLT_MAX;
        for (uint32_t i = 0; i < 512; ++i) {
            float x = vol_clean(pnanovdb_read_float(
                c->reader.buf, pnanovdb_leaf_get_table_address(PNANOVDB_GRID_TYPE_FLOAT, c->reader.buf, leaf, i)));
            v = vmaxf(v, x);
            mn = vminf(mn, x);
        }
    }
    if (c->table.entries) sp_insert(&c->table, key, v, mn, &c->mem, NULL); /* NULL (memory): read again next time */
    *min_out = mn;
    return v;
}

/* block_table_max over the cache: the max over the blocks overlapping voxels [lo, hi] within
 * the aux grid's box (0 beyond it). */
static float aux_cache_max(struct AuxCache *c, const int64_t lo[3], const int64_t hi[3], float *min_out) {
    /* min_out: the smallest value over the blocks, or -1 when the range leaves the aux box
     * (where the field is 0 whatever the blocks hold) */
    int32_t b0[3], b1[3];
    int clipped = 0;
    for (int k = 0; k < 3; ++k) {
        int64_t a = lo[k] >= 0 ? lo[k] / 8 : -((-lo[k] + 7) / 8), b = hi[k] >= 0 ? hi[k] / 8 : -((-hi[k] + 7) / 8);
        if (b < c->lo[k] || a > c->hi[k]) {
            if (min_out) *min_out = -1.0f;
            return 0.0f;
        }
        clipped |= a < c->lo[k] || b > c->hi[k];
        b0[k] = a < c->lo[k] ? c->lo[k] : (int32_t)a;
        b1[k] = b > c->hi[k] ? c->hi[k] : (int32_t)b;
    }
    /* by 128^3 regions (16^3 blocks): one that an upper node's tile or the root holds (level
     * >= 2) is one value, read once (an emitting tile's box would be 134 M blocks); the others
     * block by block */
    float mx = 0.0f, mn = FLT_MAX, bm;
    int32_t r0[3], r1[3];
    for (int k = 0; k < 3; ++k) {
        r0[k] = floor_div(b0[k], 16);
        r1[k] = floor_div(b1[k], 16);
    }
    for (int32_t rz = r0[2]; rz <= r1[2]; ++rz)
        for (int32_t ry = r0[1]; ry <= r1[1]; ++ry)
            for (int32_t rx = r0[0]; rx <= r1[0]; ++rx) {
                uint32_t level;
                float v = grid_voxel_level(&c->reader, 128 * rx, 128 * ry, 128 * rz, &level);
                if (level >= 2) {
                    mx = vmaxf(mx, v);
                    mn = vminf(mn, v);
                    continue;
                }
                const int32_t rr[3] = {rx, ry, rz};
                int32_t q0[3], q1[3];
                for (int k = 0; k < 3; ++k) {
                    q0[k] = b0[k] > 16 * rr[k] ? b0[k] : 16 * rr[k];
                    q1[k] = b1[k] < 16 * rr[k] + 15 ? b1[k] : 16 * rr[k] + 15;
                }
                for (int32_t z = q0[2]; z <= q1[2]; ++z)
                    for (int32_t y = q0[1]; y <= q1[1]; ++y)
                        for (int32_t x = q0[0]; x <= q1[0]; ++x) {
                            mx = vmaxf(mx, aux_block(c, x, y, z, &bm));
                            mn = vminf(mn, bm);
                        }
            }
    if (min_out) *min_out = clipped ? -1.0f : mn;
    return mx;
}

/* What the tree walk collects: the bricks the data reaches and the regions of the root. */
typedef struct SparseWalk {
    MajorantGrid *mg;
    SparseMem *mem;
    float bg_maj, bg_ctl; /* the background's pair */
    int fail;
} SparseWalk;

/* Every brick whose padded box (8 voxels around its 64^3: the cells' trilinear footprints)
 * meets the voxel box [lo, lo + size)^3; shell: only those that are not inside it with their
 * pad (a root tile's interior is its region's default). */
static void sp_mark_box(SparseWalk *w, const int32_t lo[3], int32_t size, int shell) {
    if (w->fail) return;
    MajorantGrid *mg = w->mg;
    int32_t b0[3], b1[3];
    for (int k = 0; k < 3; ++k) {
        b0[k] = floor_div(lo[k] - 8 - mg->origin[k], 64);
        b1[k] = floor_div(lo[k] + size + 8 - 1 - mg->origin[k], 64);
        if (b0[k] < 0) b0[k] = 0;
        int32_t bmax = (mg->dims[k] - 1) / VOLUME_MAJORANT_BRICK;
        if (b1[k] > bmax) b1[k] = bmax;
    }
    for (int32_t z = b0[2]; z <= b1[2]; ++z)
        for (int32_t y = b0[1]; y <= b1[1]; ++y)
            for (int32_t x = b0[0]; x <= b1[0]; ++x) {
                if (shell) {
                    const int32_t bb[3] = {x, y, z};
                    int inside = 1;
                    for (int k = 0; k < 3; ++k) {
                        int64_t v0 = (int64_t)mg->origin[k] + 64 * (int64_t)bb[k];
                        if (v0 - 8 < lo[k] || v0 + 64 + 8 > (int64_t)lo[k] + size) inside = 0;
                    }
                    if (inside) continue;
                }
                if (!sp_insert(&mg->bricks, sp_key(x, y, z), 0.0f, 0.0f, w->mem, NULL)) {
                    w->fail = 1;
                    return;
                }
            }
}

/* A node's origin from its tree position (NanoVDB internal nodes: x slowest). */
static void child_origin(const int32_t parent[3], uint32_t n, int log2dim, int child_size, int32_t out[3]) {
    uint32_t mask = (1u << log2dim) - 1;
    out[0] = parent[0] + (int32_t)((n >> (2 * log2dim)) & mask) * child_size;
    out[1] = parent[1] + (int32_t)((n >> log2dim) & mask) * child_size;
    out[2] = parent[2] + (int32_t)(n & mask) * child_size;
}

/* A tile of value v and size voxels at lo: marked when its pair differs from its region's
 * default (ref_maj, ref_ctl; tiles of that value are what an absent brick is). */
static void sp_tile(SparseWalk *w, const Medium *m, const int32_t lo[3], int32_t size, float v, float ref_maj,
                    float ref_ctl) {
    float maj, ctl;
    sp_pair(m, vol_clean(v), vol_clean(v), &maj, &ctl);
    if (maj != ref_maj || ctl != ref_ctl) sp_mark_box(w, lo, size, 0);
}

/* The default of a root child's region: the pair most of its upper node's tiles share (a fill
 * with some detail: the bricks the detail and the region's border reach are stored, not every
 * tile's). Any default is correct (tiles of another pair are marked, and a region whose default
 * is not the background's has its border marked); the majority (Boyer-Moore's vote, one pass)
 * stores the fewest bricks. */
static void sp_child_default(const SparseWalk *w, const Medium *m, pnanovdb_buf_t buf, pnanovdb_upper_handle_t upper,
                             float *maj, float *ctl) {
    const pnanovdb_grid_type_t F = PNANOVDB_GRID_TYPE_FLOAT;
    uint32_t votes = 0;
    float m0 = w->bg_maj, c0 = w->bg_ctl;
    for (uint32_t n = 0; n < PNANOVDB_UPPER_TABLE_COUNT; ++n) {
        if (pnanovdb_upper_get_child_mask(buf, upper, n)) continue;
        float v = vol_clean(pnanovdb_read_float(buf, pnanovdb_upper_get_table_address(F, buf, upper, n))), a, c;
        sp_pair(m, v, v, &a, &c);
        if (votes == 0) {
            m0 = a;
            c0 = c;
            votes = 1;
        } else if (a == m0 && c == c0) {
            ++votes;
        } else {
            --votes;
        }
    }
    *maj = m0;
    *ctl = c0;
}

/* Walks the NanoVDB tree (root entries, upper and lower nodes, leaves): time and memory in
 * proportion to its nodes. */
static void sp_walk_tree(SparseWalk *w, const Medium *m, pnanovdb_buf_t buf) {
    const pnanovdb_grid_type_t F = PNANOVDB_GRID_TYPE_FLOAT;
    pnanovdb_grid_handle_t grid = {pnanovdb_address_null()};
    pnanovdb_root_handle_t root = pnanovdb_tree_get_root(buf, pnanovdb_grid_get_tree(buf, grid));
    uint32_t ntiles = pnanovdb_root_get_tile_count(buf, root);
    MajorantGrid *mg = w->mg;
    /* pass 0: the regions of the root's entries (a tile's value, a child's background), pass
     * 1: their 26 neighbours (the background, unless an entry), pass 2: the bricks */
    for (int pass = 0; pass < 3 && !w->fail; ++pass)
        for (uint32_t i = 0; i < ntiles && !w->fail; ++i) {
            pnanovdb_root_tile_handle_t tile = pnanovdb_root_get_tile(F, root, i);
            uint64_t key = pnanovdb_root_tile_get_key(buf, tile);
            int32_t o[3] = {(int32_t)(uint32_t)(((key >> 42) & 0x1FFFFF) << 12),
                            (int32_t)(uint32_t)(((key >> 21) & 0x1FFFFF) << 12), (int32_t)(uint32_t)((key & 0x1FFFFF) << 12)};
            int child = pnanovdb_root_tile_get_child(buf, tile) != 0;
            float maj = w->bg_maj, ctl = w->bg_ctl;
            float tile_maj = w->bg_maj, tile_ctl = w->bg_ctl;
            if (!child) {
                float v = pnanovdb_read_float(buf, pnanovdb_root_tile_get_value_address(F, buf, tile));
                sp_pair(m, vol_clean(v), vol_clean(v), &tile_maj, &tile_ctl);
                if (tile_maj == w->bg_maj && tile_ctl == w->bg_ctl) continue; /* the background's value */
                maj = tile_maj;
                ctl = tile_ctl;
            } else if (pass != 1) {
                sp_child_default(w, m, buf, pnanovdb_root_get_child(F, buf, root, tile), &maj, &ctl);
            }
            /* an emitting medium: every region defaults to the background (absent bricks must
             * not emit: their extinction is the background's 0) */
            if (m->emissive) {
                maj = w->bg_maj;
                ctl = w->bg_ctl;
            }
            int32_t r[3];
            int out = 0;
            for (int k = 0; k < 3; ++k) {
                r[k] = floor_div(o[k] - mg->origin[k], 4096);
                /* an entry beyond the active box (inactive tiles): its ring may still reach it */
                if (o[k] + 4096 + 8 <= mg->origin[k] || o[k] - 8 > mg->origin[k] + 8 * (mg->dims[k] - 1) + 7) out = 1;
            }
            if (out) continue;
            if (pass == 0) {
                if (r[0] >= 0 && r[1] >= 0 && r[2] >= 0 &&
                    !sp_insert(&mg->regions, sp_key(r[0], r[1], r[2]), maj, ctl, w->mem, NULL))
                    w->fail = 1;
                continue;
            }
            if (pass == 1) {
                for (int dz = -1; dz <= 1; ++dz)
                    for (int dy = -1; dy <= 1; ++dy)
                        for (int dx = -1; dx <= 1; ++dx) {
                            int32_t q[3] = {r[0] + dx, r[1] + dy, r[2] + dz};
                            if (q[0] < 0 || q[1] < 0 || q[2] < 0 || w->fail) continue;
                            if (!sp_insert(&mg->regions, sp_key(q[0], q[1], q[2]), w->bg_maj, w->bg_ctl, w->mem, NULL))
                                w->fail = 1;
                        }
                continue;
            }
            /* a region of another value than the background: its shell (inside and out, where
             * the neighbours' values meet its own) */
            if (maj != w->bg_maj || ctl != w->bg_ctl) sp_mark_box(w, o, 4096, 1);
            if (!child) {
                if (m->emissive) sp_mark_box(w, o, 4096, 0); /* an emitting tile: every brick */
                continue;
            }
            pnanovdb_upper_handle_t upper = pnanovdb_root_get_child(F, buf, root, tile);
            for (uint32_t n = 0; n < PNANOVDB_UPPER_TABLE_COUNT && !w->fail; ++n) {
                int32_t uo[3];
                child_origin(o, n, 5, 128, uo);
                if (!pnanovdb_upper_get_child_mask(buf, upper, n)) {
                    sp_tile(w, m, uo, 128, pnanovdb_read_float(buf, pnanovdb_upper_get_table_address(F, buf, upper, n)), maj, ctl);
                    continue;
                }
                pnanovdb_lower_handle_t lower = pnanovdb_upper_get_child(F, buf, upper, n);
                for (uint32_t l = 0; l < PNANOVDB_LOWER_TABLE_COUNT && !w->fail; ++l) {
                    int32_t lo[3];
                    child_origin(uo, l, 4, 8, lo);
                    if (!pnanovdb_lower_get_child_mask(buf, lower, l))
                        sp_tile(w, m, lo, 8, pnanovdb_read_float(buf, pnanovdb_lower_get_table_address(F, buf, lower, l)), maj,
                                ctl);
                    else
                        sp_mark_box(w, lo, 8, 0); /* a leaf */
                }
            }
        }
}

/* The sparse form (MajorantGrid, volumes.h). Returns 1 without building it when it would take
 * at least half of dense_bytes (the dense form is then as good and faster to walk) unless
 * forced (a test's dense_cells_max), or when an emitting medium's background has extinction;
 * 0 when built (an emitting medium's per-cell emission bound in *bound, slot layout), -1 with
 * err (the budget, memory). ec: the emission context (factor, cap, grids) of an emitting
 * medium. */
static int sparse_build(Medium *m, uint64_t dense_bytes, uint64_t budget, int forced, char err[IO_ERR_LEN],
                        const char *name, const EmitContext *ec_in, float **bound) {
    MajorantGrid *mg = &m->majorant;
    const VolumeGrid *g = &m->density;
    enum { B = VOLUME_MAJORANT_BRICK, BV = 8 * VOLUME_MAJORANT_BRICK, BC = B * B * B };
    const int emissive = m->emissive;
    if (bound) *bound = NULL;
    for (int k = 0; k < 3; ++k) {
        int32_t v0 = 4096 * floor_div(g->index_min[k] - 2, 4096); /* regions aligned to the root's */
        mg->origin[k] = v0;
        mg->dims[k] = floor_div8(g->index_max[k] + 2) - v0 / 8 + 1;
    }
    GridReader reader;
    grid_reader_init(&reader, g);
    SparseMem mem = {budget, 0, 0};
    SparseWalk w = {mg, &mem, 0.0f, 0.0f, 0};
    float bg = vol_clean(pnanovdb_read_float(
        reader.buf, pnanovdb_address_offset(reader.acc.root.address,
                                            PNANOVDB_GRID_TYPE_GET(PNANOVDB_GRID_TYPE_FLOAT, root_off_background))));
    sp_pair(m, bg, bg, &w.bg_maj, &w.bg_ctl);
    if (emissive && w.bg_maj > 0.0f) { /* the background would emit everywhere: the dense form */
        memset(mg, 0, sizeof *mg);
        return 1;
    }
    mg->outside_maj = w.bg_maj;
    mg->outside_ctl = w.bg_ctl;
    struct AuxCache cache = {0};
    float *bnd = NULL;
    EmitContext ec = {0};
    if (emissive) { /* the aux grid's blocks, read as the cells ask for them */
        ec = *ec_in;
        ec.aux = NULL;
        ec.cache = &cache;
        const VolumeGrid *ag = ec_in->ag;
        grid_reader_init(&cache.reader, ag);
        for (int k = 0; k < 3; ++k) {
            cache.lo[k] = floor_div8(ag->index_min[k] - 2);
            cache.hi[k] = floor_div8(ag->index_max[k] + 2);
        }
        if (sp_table_init(&cache.table, &cache.mem)) goto fail;
    }
    if (sp_table_init(&mg->bricks, &mem) || sp_table_init(&mg->regions, &mem)) goto fail;
    sp_walk_tree(&w, m, reader.buf);
    if (w.fail) goto fail;
    /* every brick the data reaches: two numbers when its padded box holds no voxel data (and
     * then its region's default when equal; in an emitting medium only an empty one), else its
     * cells */
    uint64_t dense = 0, nuni = 0;
    for (uint64_t i = 0; i <= mg->bricks.mask; ++i) {
        MajorantEntry *e = &mg->bricks.entries[i];
        if (!e->key) continue;
        uint64_t k = e->key - 1;
        const int32_t bb[3] = {(int32_t)(k & 0x1FFFFF), (int32_t)(k >> 21 & 0x1FFFFF), (int32_t)(k >> 42 & 0x1FFFFF)};
        const int32_t vox0[3] = {mg->origin[0] + BV * bb[0], mg->origin[1] + BV * bb[1], mg->origin[2] + BV * bb[2]};
        float vhi, vlo;
        int uniform = brick_tiles(&reader, vox0, &vhi, &vlo);
        if (uniform) sp_pair(m, vhi, vlo, &e->maj, &e->ctl);
        e->emit = 0.0f;
        if (uniform && emissive && e->maj > 0.0f) {
            /* an emitting brick is uniform when its density is one tile value, all its voxel
             * centres lie in the active box (no cell clipped, every centre counted) and the aux
             * grid is one value over its footprint: then every cell has the same majorant,
             * coarse majorant, emission bound and energy, and the brick is one entry of the
             * emission-energy CDF (a 4096^3 emitting tile: 262,144 entries, not 134 M cells) */
            int inside = vhi == vlo;
            for (int a = 0; a < 3; ++a)
                inside = inside && vox0[a] >= g->index_min[a] && vox0[a] + BV - 1 <= g->index_max[a];
            float amin = -1.0f, amax = 0.0f;
            if (inside) {
                const double p0[3] = {vox0[0], vox0[1], vox0[2]};
                int64_t alo[3], ahi[3];
                aux_box(&ec, p0, (double)BV, alo, ahi);
                amax = aux_cache_max(&cache, alo, ahi, &amin);
            }
            if (inside && amin == amax) {
                float st = vminf(m->density_scale * vhi, VOLUME_MAX_SIGMA_T), mj, coarse, term;
                emit_terms(m, &ec, st, amax, &mj, &coarse, &term);
                e->maj = mj * VOL_MAJORANT_SLACK;
                e->ctl = coarse * VOL_MAJORANT_SLACK;
                e->emit = term;
                e->slot = -1;
                nuni += term > 0.0f;
            } else {
                e->slot = (int32_t)dense++;
            }
        } else if (uniform) {
            if (emissive) e->ctl = e->maj; /* the coarse majorant: an empty brick's */
            e->slot = -1;
        } else {
            e->slot = (int32_t)dense++;
        }
        /* its region must be stored (a brick lies within a ring of an entry's region) */
        if (!sp_insert(&mg->regions, sp_key(bb[0] / B / B, bb[1] / B / B, bb[2] / B / B), w.bg_maj, w.bg_ctl, &mem, NULL))
            goto fail;
    }
    /* per non-uniform brick: its cells' majorant and control (or coarse majorant), its
     * coordinates; an emitting medium's emission bound and emission-energy grid on top */
    const uint64_t cells_bytes =
        dense * (BC * (emissive ? 3 * sizeof(float) + EMISSION_BYTES_PER_CELL : 2 * sizeof(float)) + 3 * sizeof(int32_t)) +
        nuni * (3 * sizeof(int32_t) + EMISSION_BYTES_PER_CELL);
    const uint64_t bytes = mem.used + cells_bytes;
    if (2 * bytes >= dense_bytes && !forced) {
        free(mg->bricks.entries);
        free(mg->regions.entries);
        free(cache.table.entries);
        memset(mg, 0, sizeof *mg);
        return 1;
    }
    if (budget && bytes > budget) {
        mem.over = 1;
        mem.used = bytes;
        goto fail;
    }
    if (dense * BC >= ((uint64_t)1 << 31)) goto fail; /* cell indices are int32 (emission.c) */
    mg->brick_maj = malloc((size_t)(dense ? dense : 1) * BC * sizeof(float));
    mg->brick_min = malloc((size_t)(dense ? dense : 1) * BC * sizeof(float));
    mg->brick_at = malloc((size_t)(dense ? dense : 1) * 3 * sizeof(int32_t));
    mg->ubrick_at = malloc((size_t)(nuni ? nuni : 1) * 3 * sizeof(int32_t));
    if (emissive) bnd = malloc((size_t)(dense ? dense : 1) * BC * sizeof(float));
    /* a non-uniform brick's cells from the block maxima (and minima) of its 64^3 voxels and
     * their ring, exactly as the dense form computes a cell */
    BlockTable dens = {0}, dmin = {0};
    const int32_t zero[3] = {0, 0, 0}, tdims[3] = {B + 2, B + 2, B + 2};
    if (!mg->brick_maj || !mg->brick_min || !mg->brick_at || !mg->ubrick_at || (emissive && !bnd) ||
        block_table_alloc(&dens, zero, tdims, B + 2, BLK_FACES) ||
        (!emissive && block_table_alloc(&dmin, zero, tdims, B + 2, BLK_FACES))) {
        free(dens.v);
        free(dmin.v);
        goto fail;
    }
    size_t ui = 0;
    for (uint64_t i = 0; i <= mg->bricks.mask; ++i) {
        const MajorantEntry *e = &mg->bricks.entries[i];
        if (!e->key) continue;
        uint64_t k = e->key - 1;
        const int32_t bb[3] = {(int32_t)(k & 0x1FFFFF), (int32_t)(k >> 21 & 0x1FFFFF), (int32_t)(k >> 42 & 0x1FFFFF)};
        if (e->slot < 0) {
            if (e->emit > 0.0f) memcpy(mg->ubrick_at + 3 * ui++, bb, sizeof bb);
            continue;
        }
        memcpy(mg->brick_at + 3 * (size_t)e->slot, bb, sizeof bb);
        for (int a = 0; a < 3; ++a) dens.origin[a] = dmin.origin[a] = mg->origin[a] + BV * bb[a] - 8;
        for (int32_t lz = 0; lz < B + 2; ++lz) {
            block_layer_fill(&dens, &reader, lz, lz, 0);
            if (!emissive) block_layer_fill(&dmin, &reader, lz, lz, 1);
        }
        float *maj = mg->brick_maj + (size_t)e->slot * BC, *mn = mg->brick_min + (size_t)e->slot * BC;
        for (int32_t lz = 0; lz < B; ++lz) {
            const int32_t zs[3] = {lz, lz + 1, lz + 2};
            for (int32_t ly = 0; ly < B; ++ly)
                for (int32_t lx = 0; lx < B; ++lx) {
                    const int32_t c[3] = {B * bb[0] + lx, B * bb[1] + ly, B * bb[2] + lz};
                    const size_t l = (size_t)(lx + B * (ly + B * lz));
                    float mj, coarse, term, ctl;
                    cell_values(m, &dens, emissive ? NULL : &dmin, lx + 1, ly + 1, zs, &ec, c, &mj, &coarse, &term, &ctl);
                    maj[l] = mj * VOL_MAJORANT_SLACK;
                    mn[l] = emissive ? coarse * VOL_MAJORANT_SLACK : ctl;
                    if (bnd) bnd[(size_t)e->slot * BC + l] = term;
                }
        }
    }
    free(dens.v);
    free(dmin.v);
    free(cache.table.entries);
    mg->nslots = (int32_t)dense;
    mg->nubricks = (int32_t)nuni;
    mg->bytes = mem.used + dense * (BC * 2 * sizeof(float) + 3 * sizeof(int32_t)) + nuni * 3 * sizeof(int32_t);
    if (bound) *bound = bnd;
    else free(bnd);
    return 0;
fail:
    /* the budget's message, or out of memory: either way nothing is kept */
    free(mg->bricks.entries);
    free(mg->regions.entries);
    free(mg->brick_maj);
    free(mg->brick_min);
    free(mg->brick_at);
    free(mg->ubrick_at);
    free(cache.table.entries);
    free(bnd);
    memset(mg, 0, sizeof *mg);
    if (mem.over) {
        if (err)
            snprintf(err, IO_ERR_LEN, "%s: its majorant grid needs %s%.1f MiB, over the %.1f MiB of volume memory left",
                     name, mem.used > budget ? "" : "more than ", (double)(mem.used > budget ? mem.used : budget) / 1048576.0,
                     (double)budget / 1048576.0);
        return -1;
    }
    if (err) snprintf(err, IO_ERR_LEN, "%s: out of memory building the majorant grid", name);
    return -1;
}

int majorant_build(Medium *m, const double i2w[16], float voxel_size, float **emit_bound, char err[IO_ERR_LEN],
                   const char *name, uint64_t budget, uint64_t dense_cells_max) {
    MajorantGrid *mg = &m->majorant;
    float *bound = NULL;
    if (emit_bound) *emit_bound = NULL;
    const VolumeGrid *g = &m->density;
    /* Cells cover voxels index_min - 2 .. index_max + 2: the trilinear field is 0 beyond
     * index_min - 1 .. index_max + 1, and the extra voxel keeps rounding on the safe side. */
    int64_t ncells = 1;
    for (int k = 0; k < 3; ++k) {
        int32_t c0 = floor_div8(g->index_min[k] - 2), c1 = floor_div8(g->index_max[k] + 2);
        mg->origin[k] = 8 * c0;
        mg->dims[k] = c1 - c0 + 1;
        ncells *= mg->dims[k];
    }
    /* the dense form's bytes: the majorant (and control or coarse majorant), the emission bound
     * and the emission-energy grid it becomes */
    const uint64_t dense_bytes =
        (uint64_t)ncells * (m->emissive ? 2 * sizeof(float) + sizeof(float) + EMISSION_BYTES_PER_CELL : 2 * sizeof(float));
    /* lum(sigma_a L_e) <= sigma_t x emission_scale x (this) x aux value: the emission grid's
     * lum((1 - albedo) colour); for a blackbody (luminance 1, non-negative RGB) the largest
     * 1 - albedo. */
    const VolumeGrid *ag = m->emission.buffer ? &m->emission : &m->temperature;
    EmitContext ec = {i2w, ag, NULL, NULL, 0.0f, 0.0f};
    if (m->emissive) {
        float absorb[3];
        for (int k = 0; k < 3; ++k) absorb[k] = (1.0f - m->albedo[k]) * (m->emission.buffer ? m->emission_color[k] : 1.0f);
        ec.factor = m->emission_scale * (m->emission.buffer ? vlum(absorb) : vmax3(absorb));
    }
    ec.cap = voxel_size > 0.0f ? 1.0f / voxel_size : 0.0f; /* c_vox / voxel_size, c_vox = 1 */
    if ((uint64_t)ncells > (dense_cells_max ? dense_cells_max : VOLUME_MAJORANT_DENSE_CELLS)) {
        int rc = sparse_build(m, dense_bytes, budget, dense_cells_max != 0, err, name, &ec, emit_bound);
        if (rc <= 0) return rc; /* built (0) or failed (-1); 1: the dense form is no larger */
        for (int k = 0; k < 3; ++k) { /* back to the dense form's cells */
            int32_t c0 = floor_div8(g->index_min[k] - 2), c1 = floor_div8(g->index_max[k] + 2);
            mg->origin[k] = 8 * c0;
            mg->dims[k] = c1 - c0 + 1;
        }
    }
    /* the dense form's limit (the sparse form has none: it follows the tree's nodes) */
    if (ncells > ((int64_t)1 << 28)) {
        if (err) snprintf(err, IO_ERR_LEN, "%s: too large for a majorant grid (%lld cells)", name, (long long)ncells);
        return -1;
    }
    if (budget && dense_bytes > budget) {
        if (err)
            snprintf(err, IO_ERR_LEN, "%s: its majorant grid needs %.1f MiB, over the %.1f MiB of volume memory left", name,
                     (double)dense_bytes / 1048576.0, (double)budget / 1048576.0);
        return -1;
    }
    mg->bytes = (uint64_t)ncells * 2 * sizeof(float); /* the majorant, and the control or the coarse majorant */
    mg->sigma_maj = malloc((size_t)ncells * sizeof(float));
    /* the control grid (residual ratio tracking): only for media that do not emit (an
     * emitting medium's walks gather its emission at collisions, which need its whole
     * majorant) */
    mg->sigma_min = m->emissive ? NULL : malloc((size_t)ncells * sizeof(float));
    mg->sigma_maj_coarse = m->emissive ? malloc((size_t)ncells * sizeof(float)) : NULL;

    /* Density block maxima with a ring of one block around the cells: a cell's majorant
     * bounds its voxels and the two-voxel shell around them, i.e. the trilinear footprint of
     * the cell (its voxels and the next one up) with a voxel of slack on both sides. */
    BlockTable dens = {0}, aux = {0}, dmin_table = {0};
    int32_t ring_origin[3], ring_dims[3];
    for (int k = 0; k < 3; ++k) {
        ring_origin[k] = mg->origin[k] - 8;
        ring_dims[k] = mg->dims[k] + 2;
    }
    /* only three z layers of density blocks are alive at a time (a layer of cells needs the
     * layers below, at and above it): the temporary memory is a slab, not the volume */
    int fail = !mg->sigma_maj || (m->emissive && !mg->sigma_maj_coarse) || block_table_alloc(&dens, ring_origin, ring_dims, 3, BLK_FACES) ||
               (!m->emissive && (!mg->sigma_min || block_table_alloc(&dmin_table, ring_origin, ring_dims, 3, BLK_FACES)));
    if (!fail && m->emissive && emit_bound) fail = !(bound = calloc((size_t)ncells, sizeof(float)));

    /* The emission (or temperature) grid's block maxima over its own index space. */
    if (!fail && m->emissive) {
        int32_t o[3], d[3];
        for (int k = 0; k < 3; ++k) {
            int32_t c0 = floor_div8(ag->index_min[k] - 2), c1 = floor_div8(ag->index_max[k] + 2);
            o[k] = 8 * c0;
            d[k] = c1 - c0 + 1;
        }
        fail = (int64_t)d[0] * d[1] * d[2] > ((int64_t)1 << 28) || block_table_alloc(&aux, o, d, d[2], 1);
        if (!fail) {
            GridReader r;
            grid_reader_init(&r, ag);
            for (int32_t bz = 0; bz < d[2]; ++bz) block_layer_fill(&aux, &r, bz, bz, 0);
        }
    }
    if (fail) {
        free(dens.v);
        free(aux.v);
        free(dmin_table.v);
        free(bound);
        free(mg->sigma_maj);
        free(mg->sigma_min);
        free(mg->sigma_maj_coarse);
        mg->sigma_maj = NULL;
        mg->sigma_min = NULL;
        mg->sigma_maj_coarse = NULL;
        if (err) snprintf(err, IO_ERR_LEN, "%s: out of memory building the majorant grid", name);
        return -1;
    }

    ec.aux = &aux;

    GridReader reader;
    grid_reader_init(&reader, g);
    for (int32_t bz = 0; bz < 2; ++bz) {
        block_layer_fill(&dens, &reader, bz, bz, 0);
        if (dmin_table.v) block_layer_fill(&dmin_table, &reader, bz, bz, 1);
    }
    for (int32_t cz = 0; cz < mg->dims[2]; ++cz) {
        block_layer_fill(&dens, &reader, cz + 2, (cz + 2) % 3, 0);
        if (dmin_table.v) block_layer_fill(&dmin_table, &reader, cz + 2, (cz + 2) % 3, 1);
        const int32_t zs[3] = {cz % 3, (cz + 1) % 3, (cz + 2) % 3}; /* the block layers below, at, above */
        for (int32_t cy = 0; cy < mg->dims[1]; ++cy)
            for (int32_t cx = 0; cx < mg->dims[0]; ++cx) {
                const size_t ci = (size_t)cx + (size_t)mg->dims[0] * ((size_t)cy + (size_t)mg->dims[1] * (size_t)cz);
                const int32_t c[3] = {cx, cy, cz};
                float maj, maj_coarse, term, ctl;
                cell_values(m, &dens, dmin_table.v ? &dmin_table : NULL, cx + 1, cy + 1, zs, &ec, c, &maj, &maj_coarse,
                            &term, &ctl);
                if (bound) bound[ci] = term;
                mg->sigma_maj[ci] = maj * VOL_MAJORANT_SLACK;
                if (mg->sigma_maj_coarse) mg->sigma_maj_coarse[ci] = maj_coarse * VOL_MAJORANT_SLACK;
                if (mg->sigma_min) mg->sigma_min[ci] = ctl;
            }
    }
    free(dens.v);
    free(dmin_table.v);
    free(aux.v);
    if (emit_bound) *emit_bound = bound;
    return 0;
}

/* ---------------------------------------------------------------- DDA */

/* What the iterator's next piece is: before the grid's box (majorant 0), a cell, after the
 * box (0), the homogeneous medium's one segment, or nothing. */
enum { PH_DONE = 0, PH_LEAD, PH_GRID, PH_TAIL, PH_HOMOG };

static int finite3(const float v[3]) { return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]); }

/* The sparse form's cell c (inside dims): majorant and, when asked, control (else 0). Returns
 * the edge in cells of the uniform block around c that holds them: VOLUME_MAJORANT_REGION (an
 * absent region), VOLUME_MAJORANT_BRICK (a uniform or absent brick) or 1 (a brick's cell). */
static inline int32_t sparse_cell(const MajorantGrid *mg, const int32_t c[3], int mode, float *maj, float *ctl) {
    enum { B = VOLUME_MAJORANT_BRICK, R = VOLUME_MAJORANT_REGION };
    /* mode (MajorantIterator.control): 0 the majorant, 1 with the control, 2 the coarse
     * majorant (an emitting medium: the second numbers) */
    float first, second;
    int32_t blk;
    const MajorantEntry *r = sp_find(&mg->regions, sp_key(c[0] / R, c[1] / R, c[2] / R));
    if (!r) {
        first = mg->outside_maj;
        second = mg->outside_ctl;
        blk = R;
    } else {
        const MajorantEntry *e = sp_find(&mg->bricks, sp_key(c[0] / B, c[1] / B, c[2] / B));
        if (!e || e->slot < 0) {
            if (!e) e = r;
            first = e->maj;
            second = e->ctl;
            blk = B;
        } else {
            size_t i = (size_t)e->slot * (B * B * B) + (size_t)(c[0] % B) + B * ((size_t)(c[1] % B) + B * (size_t)(c[2] % B));
            first = mg->brick_maj[i];
            second = mg->brick_min[i];
            blk = 1;
        }
    }
    *maj = mode == 2 ? second : first;
    *ctl = mode == 1 ? second : 0.0f;
    return blk;
}

void medium_majorant_begin(const Medium *m, const float o[3], const float d[3], float tmin, float tmax,
                           MajorantIterator *it) {
    it->phase = PH_DONE;
    it->cells_min = NULL;
    it->sparse = NULL;
    it->control = 0;
    float t0, t1;
    if (!medium_clip_ray(m, o, d, tmin, tmax, &t0, &t1)) return;
    it->t = t0;
    it->t_end = t1;
    if (m->kind == MEDIUM_HOMOGENEOUS) {
        float st[3] = {m->sigma_a[0] + m->sigma_s[0], m->sigma_a[1] + m->sigma_s[1], m->sigma_a[2] + m->sigma_s[2]};
        it->sigma = vmax3(st);
        it->phase = PH_HOMOG;
        return;
    }
    const MajorantGrid *mg = &m->majorant;
    /* The ray in index space, re-based at the clip entry in double: far origins and huge t
     * keep their precision where it matters (near the grid). */
    const float *w = m->world_to_index;
    double e[3];
    for (int k = 0; k < 3; ++k) e[k] = (double)o[k] + (double)t0 * (double)d[k];
    for (int r = 0; r < 3; ++r) {
        it->o_index[r] = (float)(w[r] * e[0] + w[4 + r] * e[1] + w[8 + r] * e[2] + w[12 + r]);
        it->d_index[r] = (float)((double)w[r] * d[0] + (double)w[4 + r] * d[1] + (double)w[8 + r] * d[2]);
    }
    it->t_base = t0;
    it->cells = mg->sigma_maj;
    it->cells_min = NULL;
    memcpy(it->dims, mg->dims, sizeof it->dims);
    it->phase = PH_TAIL; /* until the ray is known to cross the box: one empty segment */
    if (!finite3(it->o_index) || !finite3(it->d_index)) return;

    /* The part of [t0, t1] where the field can be non-zero: the open box (index_min - 1,
     * index_max + 1) of the trilinear support, inside the cells' box; outside it the majorant
     * is 0. The world bounds (half a voxel looser, and axis-aligned in the world) would
     * otherwise lend the border cells' majorant to empty space. The box is widened by 1/64
     * voxel plus ~32 ulps of the coordinates involved (the index box, and the world origin in
     * index units, which measures how far from the world origin the grid sits), so that a
     * point evaluated from its world position (rounded differently) is never inside the
     * support but in a 0 segment. */
    float g0 = t0, g1 = t1;
    float far = vmaxf(fabsf(w[12]), vmaxf(fabsf(w[13]), fabsf(w[14])));
    for (int k = 0; k < 3; ++k) {
        float imin = (float)m->density.index_min[k], imax = (float)m->density.index_max[k];
        float slack = 1.0f / 64.0f + 4e-6f * (vmaxf(fabsf(imin), fabsf(imax)) + far);
        float lo = imin - 1.0f - slack, hi = imax + 1.0f + slack;
        if (it->d_index[k] == 0.0f) {
            if (!(it->o_index[k] >= lo && it->o_index[k] <= hi)) return;
            continue;
        }
        float ta = t0 + (lo - it->o_index[k]) / it->d_index[k], tb = t0 + (hi - it->o_index[k]) / it->d_index[k];
        if (ta > tb) {
            float s = ta;
            ta = tb;
            tb = s;
        }
        g0 = vmaxf(g0, ta);
        g1 = vminf(g1, tb);
    }
    if (!(g0 < g1)) return;
    it->t_grid0 = g0;
    it->t_grid1 = g1;
    /* The entry cell (clamped: the entry point lies on the box's surface up to rounding; a
     * cell off by one there is left at once through a zero-length piece). */
    /* the linear index is the dense form's (the sparse form's cells may number past 2^31) */
    const int dense_form = mg->bricks.entries == NULL;
    int32_t stride[3] = {1, dense_form ? mg->dims[0] : 0, dense_form ? mg->dims[0] * mg->dims[1] : 0};
    it->index = 0;
    for (int k = 0; k < 3; ++k) {
        float p = it->o_index[k] + (g0 - t0) * it->d_index[k];
        float c = floorf((p - (float)mg->origin[k]) * (1.0f / 8.0f));
        int32_t ci = c < 0.0f ? 0 : c >= (float)mg->dims[k] ? mg->dims[k] - 1 : (int32_t)c;
        it->cell[k] = ci;
        it->index += ci * stride[k];
        it->index_step[k] = 0;
        float dk = it->d_index[k];
        if (dk > 0.0f) {
            it->step[k] = 1;
            it->index_step[k] = stride[k];
            it->t_next[k] = t0 + ((float)(mg->origin[k] + 8 * (ci + 1)) - it->o_index[k]) / dk;
            it->t_delta[k] = 8.0f / dk;
        } else if (dk < 0.0f) {
            it->step[k] = -1;
            it->index_step[k] = -stride[k];
            it->t_next[k] = t0 + ((float)(mg->origin[k] + 8 * ci) - it->o_index[k]) / dk;
            it->t_delta[k] = -8.0f / dk;
        } else {
            it->step[k] = 0;
            it->t_next[k] = INFINITY;
            it->t_delta[k] = INFINITY;
        }
    }
    it->phase = t0 < g0 ? PH_LEAD : PH_GRID;
    if (mg->bricks.entries) {
        it->sparse = mg;
        sparse_cell(mg, it->cell, 0, &it->cur_maj, &it->cur_min);
    }
}

static inline float piece_majorant(const MajorantIterator *it) {
    if (it->phase == PH_GRID) return it->sparse ? it->cur_maj : it->cells[it->index];
    return it->phase == PH_HOMOG ? it->sigma : 0.0f;
}

static inline float piece_control(const MajorantIterator *it) {
    if (it->phase != PH_GRID) return 0.0f;
    if (it->sparse) return it->cur_min; /* 0 unless controls were asked for */
    return it->cells_min ? it->cells_min[it->index] : 0.0f;
}

/* The axis of the smallest t_next without branches (Amanatides & Woo's comparison table):
 * which plane comes next is what a branch predictor cannot guess. */
static inline int next_axis(const float tn[3]) {
    static const uint8_t axis[8] = {2, 1, 2, 1, 2, 2, 0, 0};
    return axis[((tn[0] < tn[1]) << 2) | ((tn[0] < tn[2]) << 1) | (tn[1] < tn[2])];
}

/* In PH_GRID: steps through the cells while their majorant equals the current one, then
 * leaves it->t at the end of the run. Every step moves to a neighbouring cell along one axis
 * (monotonically per axis) or leaves the grid, so a walk takes at most dims[0] + dims[1] +
 * dims[2] steps. */
static inline void grid_run(MajorantIterator *it, float maj, float ctl) {
    /* the state in locals: cells (float *) may alias the iterator's floats as far as the
     * compiler knows, which would keep every field in memory across the loop */
    const float *cells = it->cells, *cells_min = it->cells_min;
    float tn[3] = {it->t_next[0], it->t_next[1], it->t_next[2]};
    int32_t cell[3] = {it->cell[0], it->cell[1], it->cell[2]}, index = it->index;
    float t = it->t, t_grid1 = it->t_grid1;
    for (;;) {
        int a = next_axis(tn);
        float e = tn[a];
        if (!(e < t_grid1)) {
            t = t_grid1;
            it->phase = t < it->t_end ? PH_TAIL : PH_DONE;
            break;
        }
        t = vmaxf(e, t);
        cell[a] += it->step[a];
        if ((uint32_t)cell[a] >= (uint32_t)it->dims[a]) { /* left the box early (rounding) */
            it->phase = t < it->t_end ? PH_TAIL : PH_DONE;
            break;
        }
        index += it->index_step[a];
        tn[a] += it->t_delta[a];
        if (cells[index] != maj || (cells_min && cells_min[index] != ctl)) break;
    }
    it->t = t;
    it->index = index;
    for (int k = 0; k < 3; ++k) {
        it->t_next[k] = tn[k];
        it->cell[k] = cell[k];
    }
}

/* grid_run over the sparse form: the same steps, the cell's values from its brick, and a
 * uniform brick or absent region of the run's values crossed at once. Inside such a block the
 * ray is moved to the last cell before the block's exit plane: along each axis, the cell planes it crosses before
 * the earliest exit, counted from their distances (t_next + j t_delta; a tie at a plane can put
 * the ray a cell off for an instant, as rounding does in the cell-by-cell walk). */
static void sparse_run(MajorantIterator *it, float maj, float ctl) {
    const MajorantGrid *mg = it->sparse;
    float tn[3] = {it->t_next[0], it->t_next[1], it->t_next[2]};
    int32_t cell[3] = {it->cell[0], it->cell[1], it->cell[2]};
    float t = it->t, t_grid1 = it->t_grid1;
    float m2 = maj, c2 = ctl;
    int32_t blk = sparse_cell(mg, cell, it->control, &m2, &c2);
    for (;;) {
        if (blk > 1) {
            int32_t n[3];
            float exit = INFINITY;
            int ax = 0;
            for (int k = 0; k < 3; ++k) {
                n[k] = 0;
                if (it->step[k] == 0) continue;
                int32_t left = it->step[k] > 0 ? blk - 1 - cell[k] % blk : cell[k] % blk;
                int32_t to_edge = it->step[k] > 0 ? mg->dims[k] - 1 - cell[k] : cell[k];
                n[k] = left < to_edge ? left : to_edge;
                float e = tn[k] + (float)n[k] * it->t_delta[k];
                if (e < exit) {
                    exit = e;
                    ax = k;
                }
            }
            if (!(exit < t_grid1)) { /* the run ends inside this brick */
                t = t_grid1;
                it->phase = t < it->t_end ? PH_TAIL : PH_DONE;
                break;
            }
            for (int k = 0; k < 3; ++k) {
                if (it->step[k] == 0) continue;
                int32_t j = n[k];
                if (k != ax) { /* the planes of axis k before the exit */
                    float q = ceilf((exit - tn[k]) / it->t_delta[k]);
                    j = q > 0.0f ? (q < (float)n[k] ? (int32_t)q : n[k]) : 0;
                }
                if (j == 0) continue;
                cell[k] += it->step[k] * j;
                /* the plane's distance from the cell index, not accumulated: a skip crosses up
                 * to 512 cells, and sums of t_delta over a 600 m gap of 1 mm voxels drifted by
                 * voxels (the blob behind it lost its majorant) */
                tn[k] = it->t_base +
                        ((float)(mg->origin[k] + 8 * (cell[k] + (it->step[k] > 0))) - it->o_index[k]) / it->d_index[k];
            }
        }
        int a = next_axis(tn);
        float e = tn[a];
        if (!(e < t_grid1)) {
            t = t_grid1;
            it->phase = t < it->t_end ? PH_TAIL : PH_DONE;
            break;
        }
        t = vmaxf(e, t);
        cell[a] += it->step[a];
        if ((uint32_t)cell[a] >= (uint32_t)it->dims[a]) { /* left the box early (rounding) */
            it->phase = t < it->t_end ? PH_TAIL : PH_DONE;
            break;
        }
        tn[a] += it->t_delta[a];
        blk = sparse_cell(mg, cell, it->control, &m2, &c2);
        if (m2 != maj || c2 != ctl) break;
    }
    it->t = t;
    it->cur_maj = m2;
    it->cur_min = c2;
    for (int k = 0; k < 3; ++k) {
        it->t_next[k] = tn[k];
        it->cell[k] = cell[k];
    }
}

int medium_majorant_next_control(MajorantIterator *it, float *t0, float *t1, float *sigma_maj, float *sigma_min) {
    while (it->phase != PH_DONE) {
        float a = it->t, maj = piece_majorant(it), ctl = piece_control(it);
        /* neighbouring pieces of equal majorant (and control) are one segment (empty space,
         * uniform media) */
        for (;;) {
            switch (it->phase) {
            case PH_LEAD:
                it->t = it->t_grid0;
                it->phase = PH_GRID;
                break;
            case PH_GRID:
                if (it->sparse) sparse_run(it, maj, ctl);
                else grid_run(it, maj, ctl);
                break;
            default: /* PH_TAIL, PH_HOMOG */
                it->t = it->t_end;
                it->phase = PH_DONE;
                break;
            }
            if (it->phase == PH_DONE || piece_majorant(it) != maj || piece_control(it) != ctl) break;
        }
        if (it->t > a) {
            *t0 = a;
            *t1 = it->t;
            *sigma_maj = maj;
            *sigma_min = ctl;
            return 1;
        }
    }
    return 0;
}

int medium_majorant_next(MajorantIterator *it, float *t0, float *t1, float *sigma_maj) {
    float ctl; /* cells_min is NULL: always 0, and runs split on the majorant alone */
    return medium_majorant_next_control(it, t0, t1, sigma_maj, &ctl);
}

void medium_majorant_begin_control(const Medium *m, const float o[3], const float d[3], float tmin, float tmax,
                                   MajorantIterator *it) {
    medium_majorant_begin(m, o, d, tmin, tmax, it);
    if (m->kind != MEDIUM_HOMOGENEOUS) it->cells_min = m->majorant.sigma_min;
    if (it->sparse && !m->emissive) { /* an emitting medium has no control (sigma_min NULL) */
        it->control = 1;
        sparse_cell(it->sparse, it->cell, 1, &it->cur_maj, &it->cur_min);
    }
}

void medium_majorant_begin_coarse(const Medium *m, const float o[3], const float d[3], float tmin, float tmax,
                                  MajorantIterator *it) {
    medium_majorant_begin_control(m, o, d, tmin, tmax, it);
    if (m->kind != MEDIUM_HOMOGENEOUS && m->majorant.sigma_maj_coarse) it->cells = m->majorant.sigma_maj_coarse;
    if (it->sparse && m->emissive) { /* the bricks' second numbers */
        it->control = 2;
        sparse_cell(it->sparse, it->cell, 2, &it->cur_maj, &it->cur_min);
    }
}
