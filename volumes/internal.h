/* volumes/internal.h (private): what the module's files share. Tiny inline math (the module
 * does not depend on renderer/), the cached NanoVDB reader and the point evaluation of a
 * grid medium in its density grid's index space. */
#ifndef CANDELA_VOLUMES_INTERNAL_H
#define CANDELA_VOLUMES_INTERNAL_H

#include <float.h>
#include <math.h>
#include <stdint.h>

#include "volumes.h"

/* PNanoVDB is written for warning-free GPU compilers, not for -Wextra. */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-parameter"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#define PNANOVDB_C
#include <nanovdb/PNanoVDB.h>
#pragma GCC diagnostic pop

#define VOL_PI 3.14159265358979323846f

/* Luminance weights of linear Rec.709 (the renderer's v3_luminance). */
#define VOL_LUM_R 0.2126f
#define VOL_LUM_G 0.7152f
#define VOL_LUM_B 0.0722f

/* Relative slack on every majorant: trilinear weights and the index-space position of a
 * collision are rounded, so an interpolated value can exceed the max of its corners by an
 * ulp or two. 1e-4 costs 0.01 % more null collisions and makes sigma_t <= sigma_maj exact. */
#define VOL_MAJORANT_SLACK 1.0001f
/* The same on the control (minorant) grid, downwards: sigma_c <= sigma_t stays exact. */
#define VOL_CONTROL_SLACK 0.9999f

/* min/max as compares: with a NaN in a they return b (so vmaxf(x, 0) maps NaN to 0). */
static inline float vmaxf(float a, float b) { return a > b ? a : b; }
static inline float vminf(float a, float b) { return a < b ? a : b; }
static inline float vmax3(const float v[3]) { return vmaxf(v[0], vmaxf(v[1], v[2])); }
static inline float vlum(const float v[3]) { return VOL_LUM_R * v[0] + VOL_LUM_G * v[1] + VOL_LUM_B * v[2]; }

/* A voxel value as the media read it: negative, NaN and infinite values count as 0
 * (documented clamping; header, medium_init_vdb). */
static inline float vol_clean(float v) { return v > 0.0f && v <= FLT_MAX ? v : 0.0f; }

/* Affine 4x4, column-major (m[col*4 + row]). */
static inline void vol_xform_point(const float m[16], const float p[3], float r[3]) {
    for (int k = 0; k < 3; ++k) r[k] = m[k] * p[0] + m[4 + k] * p[1] + m[8 + k] * p[2] + m[12 + k];
}
static inline void vol_xform_vector(const float m[16], const float v[3], float r[3]) {
    for (int k = 0; k < 3; ++k) r[k] = m[k] * v[0] + m[4 + k] * v[1] + m[8 + k] * v[2];
}

/* ---------------------------------------------------------------- grid reading */

/* A NanoVDB float grid with a read accessor. The accessor caches the path to the last leaf,
 * so lookups near the previous one (the 8 corners of a trilinear footprint, the next
 * collision of a walk) skip the tree descent: a tracker keeps one per grid for a whole call. */
typedef struct GridReader {
    pnanovdb_buf_t buf;
    pnanovdb_readaccessor_t acc;
    float lo[3], hi[3];  /* the open box (index_min - 1, index_max + 1): outside, the field is 0 */
} GridReader;

static inline void grid_reader_init(GridReader *r, const VolumeGrid *g) {
    r->buf = pnanovdb_make_buf((uint32_t *)g->buffer, g->size / 4);
    pnanovdb_grid_handle_t grid = {pnanovdb_address_null()};
    pnanovdb_root_handle_t root = pnanovdb_tree_get_root(r->buf, pnanovdb_grid_get_tree(r->buf, grid));
    pnanovdb_readaccessor_init(&r->acc, root);
    for (int k = 0; k < 3; ++k) {
        r->lo[k] = (float)g->index_min[k] - 1.0f;
        r->hi[k] = (float)g->index_max[k] + 1.0f;
    }
}

/* The clean value of voxel (x, y, z) and the tree level it came from (0: a leaf voxel; above:
 * a tile or the background, constant over at least the voxel's 8^3 leaf block). */
static inline float grid_voxel_level(GridReader *r, int32_t x, int32_t y, int32_t z, uint32_t *level) {
    pnanovdb_coord_t ijk = {x, y, z};
    pnanovdb_address_t a =
        pnanovdb_readaccessor_get_value_address_and_level(PNANOVDB_GRID_TYPE_FLOAT, r->buf, &r->acc, &ijk, level);
    return vol_clean(pnanovdb_read_float(r->buf, a));
}

static inline float grid_voxel(GridReader *r, int32_t x, int32_t y, int32_t z) {
    uint32_t level;
    return grid_voxel_level(r, x, y, z, &level);
}

/* Trilinear interpolation of the clean voxel values at index-space p (voxel centres at
 * integer coordinates); 0 outside the active box's one-voxel margin (and for a NaN p). */
float grid_trilinear(GridReader *r, const float p[3]);

/* ---------------------------------------------------------------- grid media */

/* What a tracker evaluates at a collision of a grid medium, with its readers (initialised
 * on the first collision: most rays through a view never collide in most media). */
typedef struct GridMediumCache {
    GridReader density, aux;  /* aux: the emission grid, else the temperature grid */
    int ready;
} GridMediumCache;

/* sigma_t (grey) of a grid medium at the density grid's index-space point pi. */
static inline float grid_sigma_t(const Medium *m, GridReader *density, const float pi[3]) {
    return vminf(m->density_scale * grid_trilinear(density, pi), VOLUME_MAX_SIGMA_T);
}

/* Emitted radiance L_e of a grid medium at world point p (its own grid's index space). */
void grid_emission(const Medium *m, GridReader *aux, const float p[3], float le[3]);

/* Blackbody colour without the temperature check, for a temperature known to be >= 500 K. */
void blackbody_lookup(float kelvin, float rgb[3]);
#define BLACKBODY_MIN_KELVIN 500.0f

/* ---------------------------------------------------------------- the sparse majorant's tables */

/* Brick and region coordinates are cells / 8 and cells / 512 from the grid's origin: below
 * 2^19 (index bounds within 2^21, medium.c), packed 21 bits per axis; +1 keeps 0 for empty. */
static inline uint64_t sp_key(int32_t x, int32_t y, int32_t z) {
    return ((uint64_t)(uint32_t)x | (uint64_t)(uint32_t)y << 21 | (uint64_t)(uint32_t)z << 42) + 1;
}
static inline uint64_t sp_slot(const MajorantTable *t, uint64_t key) {
    uint64_t h = key * 0x9E3779B97F4A7C15ull;
    return (h ^ (h >> 31)) & t->mask;
}
static inline const MajorantEntry *sp_find(const MajorantTable *t, uint64_t key) {
    for (uint64_t i = sp_slot(t, key);; i = (i + 1) & t->mask) {
        const MajorantEntry *e = &t->entries[i];
        if (e->key == key) return e;
        if (!e->key) return NULL;
    }
}

/* Builds m->majorant (majorant.c) from the density grid's index-to-world transform i2w
 * (node x grid, double); 0 ok, -1 out of memory or an absurd size (err). When the medium
 * emits and emit_bound is not NULL, *emit_bound gets a malloc'd array (the caller frees it)
 * with, per majorant cell, an upper bound of lum(sigma_a L_e) over the cell's trilinear
 * footprint (the uncapped emission term; 0 where the cell cannot emit). */
int majorant_build(Medium *m, const double i2w[16], float voxel_size, float **emit_bound, char err[IO_ERR_LEN],
                   const char *name, uint64_t budget, uint64_t dense_cells_max);
/* Bytes an emitting medium's emission-energy grid may take per majorant cell (emission.c, with
 * its temporaries), for the budget check before anything is allocated. */
#define EMISSION_BYTES_PER_CELL 24

/* Builds m->emission_energy (emission.c) from the bound of majorant_build; 0 ok, -1 out of
 * memory (err). */
int emission_build(Medium *m, const double i2w[16], const float *bound, char err[IO_ERR_LEN], const char *name);
void emission_free(Medium *m);

#endif
