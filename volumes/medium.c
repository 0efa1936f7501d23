/* volumes/medium.c: media (homogeneous and VDB grids), their point evaluation and their
 * bounds. The trackers (trackers.c) evaluate grids through the same grid_trilinear with a
 * reader they keep for a whole walk; medium_eval is the one-off version. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

/* ---------------------------------------------------------------- trilinear lookup */

float grid_trilinear(GridReader *r, const float p[3]) {
    /* Outside (index_min - 1, index_max + 1) every corner is outside the active box, so the
     * field is 0 there by definition; the compare also sends a NaN p to 0. */
    if (!(p[0] > r->lo[0] && p[0] < r->hi[0] && p[1] > r->lo[1] && p[1] < r->hi[1] && p[2] > r->lo[2] &&
          p[2] < r->hi[2]))
        return 0.0f;
    float fx = floorf(p[0]), fy = floorf(p[1]), fz = floorf(p[2]);
    int32_t x = (int32_t)fx, y = (int32_t)fy, z = (int32_t)fz;
    float wx = p[0] - fx, wy = p[1] - fy, wz = p[2] - fz;
    float v[8]; /* v[dx*4 + dy*2 + dz] */
    if ((x & 7) != 7 && (y & 7) != 7 && (z & 7) != 7) {
        /* The 2x2x2 footprint lies inside one 8^3 leaf block (the common case, 343 of 512
         * positions): one accessor lookup, then the other 7 values sit at fixed offsets in
         * the leaf's value table (NanoVDB leaf layout: offset = x*64 + y*8 + z, 4-byte floats;
         * the grid type is checked to be FLOAT at init). A tile covers the whole block with
         * one value. */
        uint32_t level;
        pnanovdb_coord_t ijk = {x, y, z};
        pnanovdb_address_t a =
            pnanovdb_readaccessor_get_value_address_and_level(PNANOVDB_GRID_TYPE_FLOAT, r->buf, &r->acc, &ijk, &level);
        if (level != 0) return vol_clean(pnanovdb_read_float(r->buf, a));
        static const uint32_t off[8] = {0, 4, 32, 36, 256, 260, 288, 292};
        for (int k = 0; k < 8; ++k) v[k] = vol_clean(pnanovdb_read_float(r->buf, pnanovdb_address_offset(a, off[k])));
    } else {
        for (int k = 0; k < 8; ++k) v[k] = grid_voxel(r, x + (k >> 2), y + ((k >> 1) & 1), z + (k & 1));
    }
    /* a + w (b - a): never outside [min, max] of the corners by more than an ulp */
    float c00 = v[0] + wz * (v[1] - v[0]), c01 = v[2] + wz * (v[3] - v[2]);
    float c10 = v[4] + wz * (v[5] - v[4]), c11 = v[6] + wz * (v[7] - v[6]);
    float c0 = c00 + wy * (c01 - c00), c1 = c10 + wy * (c11 - c10);
    return c0 + wx * (c1 - c0);
}

void grid_emission(const Medium *m, GridReader *aux, const float p[3], float le[3]) {
    le[0] = le[1] = le[2] = 0.0f;
    if (!m->emissive) return;
    if (m->emission.buffer) {
        float pa[3];
        vol_xform_point(m->emission.world_to_index, p, pa);
        float e = m->emission_scale * grid_trilinear(aux, pa);
        for (int k = 0; k < 3; ++k) le[k] = e * m->emission_color[k];
    } else {
        float pa[3];
        vol_xform_point(m->temperature.world_to_index, p, pa);
        float kelvin = grid_trilinear(aux, pa);
        if (!(kelvin >= BLACKBODY_MIN_KELVIN)) return;
        blackbody_lookup(kelvin, le);
        for (int k = 0; k < 3; ++k) le[k] *= m->emission_scale;
    }
}

/* ---------------------------------------------------------------- evaluation and bounds */

void medium_eval(const Medium *m, const float p[3], MediumCoefficients *c) {
    if (m->kind == MEDIUM_HOMOGENEOUS) {
        for (int k = 0; k < 3; ++k) {
            c->sigma_a[k] = m->sigma_a[k];
            c->sigma_s[k] = m->sigma_s[k];
            c->emission[k] = 0.0f;
        }
        return;
    }
    GridReader density;
    grid_reader_init(&density, &m->density);
    float pi[3];
    vol_xform_point(m->world_to_index, p, pi);
    float st = grid_sigma_t(m, &density, pi);
    for (int k = 0; k < 3; ++k) {
        c->sigma_s[k] = m->albedo[k] * st;
        c->sigma_a[k] = st - c->sigma_s[k];
    }
    if (m->emissive) {
        GridReader aux;
        grid_reader_init(&aux, m->emission.buffer ? &m->emission : &m->temperature);
        grid_emission(m, &aux, p, c->emission);
    } else {
        c->emission[0] = c->emission[1] = c->emission[2] = 0.0f;
    }
}

static int finite3(const float v[3]) { return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]); }

int medium_clip_ray(const Medium *m, const float o[3], const float d[3], float tmin, float tmax, float *t0,
                    float *t1) {
    if (!(tmin < tmax) || !finite3(o) || !finite3(d)) return 0; /* also NaN tmin / tmax */
    float lo = tmin, hi = tmax;
    if (m->kind == MEDIUM_GRID) {
        for (int k = 0; k < 3; ++k) {
            if (d[k] == 0.0f) {
                if (!(o[k] >= m->world_min[k] && o[k] <= m->world_max[k])) return 0;
                continue;
            }
            /* divisions, not a reciprocal: 0 / tiny is 0 where 0 * (1 / tiny) = 0 * inf is NaN */
            float ta = (m->world_min[k] - o[k]) / d[k], tb = (m->world_max[k] - o[k]) / d[k];
            if (ta > tb) {
                float s = ta;
                ta = tb;
                tb = s;
            }
            lo = vmaxf(lo, ta);
            hi = vminf(hi, tb);
        }
    }
    if (!(lo < hi)) return 0;
    *t0 = lo;
    *t1 = hi;
    return 1;
}

/* ---------------------------------------------------------------- construction */

static void set_err(char err[IO_ERR_LEN], const char *fmt, const char *name, const char *what, double value) {
    if (err) snprintf(err, IO_ERR_LEN, fmt, name, what, value);
}

/* A coefficient check: finite and >= 0 (and <= hi). */
static int check_range(const float *v, int n, float hi, const char *name, const char *what, char err[IO_ERR_LEN]) {
    for (int k = 0; k < n; ++k)
        if (!(v[k] >= 0.0f && v[k] <= hi)) {
            set_err(err, hi == FLT_MAX ? "%s: %s %g is negative or not finite" : "%s: %s %g is outside [0, 1]", name,
                    what, (double)v[k]);
            return -1;
        }
    return 0;
}

static int check_g(float g, const char *name, char err[IO_ERR_LEN]) {
    if (!(fabsf(g) < 1.0f)) {
        set_err(err, "%s: %s %g is outside (-1, 1)", name, "anisotropy", (double)g);
        return -1;
    }
    return 0;
}

int medium_init_homogeneous(Medium *m, const float sigma_a[3], const float sigma_s[3], float g, char err[IO_ERR_LEN]) {
    memset(m, 0, sizeof *m);
    const char *name = "homogeneous medium";
    if (check_range(sigma_a, 3, FLT_MAX, name, "sigma_a", err) || check_range(sigma_s, 3, FLT_MAX, name, "sigma_s", err) ||
        check_g(g, name, err))
        return -1;
    m->kind = MEDIUM_HOMOGENEOUS;
    m->g = g;
    for (int k = 0; k < 3; ++k) {
        /* the same extinction clamp as grids (a walk never hangs): scale both coefficients */
        float st = sigma_a[k] + sigma_s[k];
        float s = st > VOLUME_MAX_SIGMA_T ? VOLUME_MAX_SIGMA_T / st : 1.0f;
        m->sigma_a[k] = sigma_a[k] * s;
        m->sigma_s[k] = sigma_s[k] * s;
        m->world_min[k] = -INFINITY;
        m->world_max[k] = INFINITY;
    }
    return 0;
}

/* world = node x grid: column-major products in double, then the inverse. -1 when not affine,
 * not finite or singular. */
static int grid_transform(const float node[16], const float grid[16], double i2w[16], float w2i[16]) {
    for (int i = 0; i < 16; ++i)
        if (!isfinite(node[i]) || !isfinite(grid[i])) return -1;
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r) {
            double s = 0.0;
            for (int k = 0; k < 4; ++k) s += (double)node[k * 4 + r] * (double)grid[c * 4 + k];
            i2w[c * 4 + r] = s;
        }
    if (fabs(i2w[3]) > 1e-9 || fabs(i2w[7]) > 1e-9 || fabs(i2w[11]) > 1e-9 || fabs(i2w[15] - 1.0) > 1e-9) return -1;
    const double *a = i2w;  /* columns a[0..2], a[4..6], a[8..10] */
    double inv[9];          /* rows of the inverse = cross products of the columns / det */
    inv[0] = a[5] * a[10] - a[6] * a[9];
    inv[1] = a[6] * a[8] - a[4] * a[10];
    inv[2] = a[4] * a[9] - a[5] * a[8];
    inv[3] = a[9] * a[2] - a[10] * a[1];
    inv[4] = a[10] * a[0] - a[8] * a[2];
    inv[5] = a[8] * a[1] - a[9] * a[0];
    inv[6] = a[1] * a[6] - a[2] * a[5];
    inv[7] = a[2] * a[4] - a[0] * a[6];
    inv[8] = a[0] * a[5] - a[1] * a[4];
    double det = a[0] * inv[0] + a[1] * inv[1] + a[2] * inv[2];
    double n0 = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]), n1 = sqrt(a[4] * a[4] + a[5] * a[5] + a[6] * a[6]),
           n2 = sqrt(a[8] * a[8] + a[9] * a[9] + a[10] * a[10]);
    /* singular relative to the columns' lengths (a scale-free test: a 1 um voxel is fine) */
    if (!(fabs(det) > 1e-9 * n0 * n1 * n2) || !isfinite(det)) return -1;
    /* inverse of L is inv (rows) / det; w2i = [L^-1, -L^-1 t] */
    double L[9];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) L[r * 3 + c] = inv[r * 3 + c] / det; /* row r of L^-1 */
    /* rows of L^-1 as computed: row 0 = (c1 x c2) / det, and so on */
    for (int r = 0; r < 3; ++r) {
        double t = -(L[r * 3 + 0] * a[12] + L[r * 3 + 1] * a[13] + L[r * 3 + 2] * a[14]);
        for (int c = 0; c < 3; ++c) w2i[c * 4 + r] = (float)L[r * 3 + c];
        w2i[12 + r] = (float)t;
        w2i[r * 4 + 3] = 0.0f;
    }
    w2i[15] = 1.0f;
    for (int i = 0; i < 16; ++i)
        if (!isfinite(w2i[i])) return -1;
    return 0;
}

/* A grid of the description: a float NanoVDB grid placed in the world. */
static int place_grid(const IoVolumeGrid *g, const float node[16], VolumeGrid *out, double i2w[16],
                      char err[IO_ERR_LEN]) {
    const char *name = g->name[0] ? g->name : "(unnamed)";
    if (!g->buffer || g->size < PNANOVDB_GRID_SIZE) {
        if (err) snprintf(err, IO_ERR_LEN, "volume grid '%s': no NanoVDB buffer", name);
        return -1;
    }
    pnanovdb_buf_t buf = pnanovdb_make_buf((uint32_t *)g->buffer, g->size / 4);
    pnanovdb_grid_handle_t grid = {pnanovdb_address_null()};
    if (pnanovdb_grid_get_grid_type(buf, grid) != PNANOVDB_GRID_TYPE_FLOAT) {
        if (err) snprintf(err, IO_ERR_LEN, "volume grid '%s': not a NanoVDB float grid", name);
        return -1;
    }
    for (int k = 0; k < 3; ++k)
        if (g->index_min[k] > g->index_max[k] || g->index_min[k] < -(1 << 21) || g->index_max[k] > (1 << 21)) {
            if (err) snprintf(err, IO_ERR_LEN, "volume grid '%s': empty or absurd index bounds", name);
            return -1;
        }
    if (grid_transform(node, g->index_to_world, i2w, out->world_to_index)) {
        if (err) snprintf(err, IO_ERR_LEN, "volume grid '%s': singular, non-affine or non-finite transform", name);
        return -1;
    }
    out->buffer = g->buffer;
    out->size = g->size;
    memcpy(out->index_min, g->index_min, sizeof out->index_min);
    memcpy(out->index_max, g->index_max, sizeof out->index_max);
    return 0;
}

int medium_init_vdb(Medium *m, const VolumeDesc *desc, char err[IO_ERR_LEN]) {
    memset(m, 0, sizeof *m);
    if (!desc || !desc->density) {
        if (err) snprintf(err, IO_ERR_LEN, "volume: no density grid");
        return -1;
    }
    char name[96];
    snprintf(name, sizeof name, "volume '%s'", desc->density->name);
    float scale = desc->density_scale, escale = desc->emission_scale;
    if (check_range(&scale, 1, FLT_MAX, name, "density_scale", err) ||
        check_range(desc->albedo, 3, 1.0f, name, "albedo", err) ||
        check_g(desc->anisotropy, name, err) || check_range(&escale, 1, FLT_MAX, name, "emission_scale", err) ||
        check_range(desc->emission_color, 3, FLT_MAX, name, "emission_color", err))
        return -1;
    double i2w[16], aux_i2w[16];
    if (place_grid(desc->density, desc->node_to_world, &m->density, i2w, err)) return -1;
    if (desc->emission && place_grid(desc->emission, desc->node_to_world, &m->emission, aux_i2w, err)) return -1;
    if (desc->temperature && place_grid(desc->temperature, desc->node_to_world, &m->temperature, aux_i2w, err))
        return -1;
    m->kind = MEDIUM_GRID;
    m->g = desc->anisotropy;
    m->density_scale = scale;
    m->emission_scale = escale;
    for (int k = 0; k < 3; ++k) {
        m->albedo[k] = desc->albedo[k];
        m->emission_color[k] = desc->emission_color[k];
    }
    memcpy(m->world_to_index, m->density.world_to_index, sizeof m->world_to_index);
    /* The emission grid wins over the temperature grid (header); an emission grid whose
     * colour is black emits nothing. */
    if (escale > 0.0f) {
        if (m->emission.buffer) m->emissive = vlum(m->emission_color) > 0.0f;
        else m->emissive = m->temperature.buffer != NULL;
    }

    /* World bounds: the active box's voxels (index_min - 0.5 .. index_max + 0.5) padded by
     * one voxel for the trilinear footprint, all 8 corners through the transform. */
    for (int k = 0; k < 3; ++k) {
        m->world_min[k] = INFINITY;
        m->world_max[k] = -INFINITY;
    }
    for (int c = 0; c < 8; ++c) {
        double p[3];
        for (int k = 0; k < 3; ++k) p[k] = (c >> k & 1) ? m->density.index_max[k] + 1.5 : m->density.index_min[k] - 1.5;
        for (int r = 0; r < 3; ++r) {
            double w = i2w[r] * p[0] + i2w[4 + r] * p[1] + i2w[8 + r] * p[2] + i2w[12 + r];
            m->world_min[r] = vminf(m->world_min[r], (float)w);
            m->world_max[r] = vmaxf(m->world_max[r], (float)w);
        }
    }
    /* a voxel size of 1e30 (or a node scaling a grid so) puts the volume where float rays lose
     * all precision, and every consumer of its bounds (cache point candidates, the guiding
     * field) works in vain: refused, like node transforms beyond the same limit */
    for (int k = 0; k < 3; ++k)
        if (!(m->world_min[k] >= -VOLUME_MAX_COORDINATE && m->world_max[k] <= VOLUME_MAX_COORDINATE)) {
            if (err)
                snprintf(err, IO_ERR_LEN, "%s: world bounds [%g %g %g] - [%g %g %g] beyond %g (voxel size or placement out of range)",
                         name, (double)m->world_min[0], (double)m->world_min[1], (double)m->world_min[2],
                         (double)m->world_max[0], (double)m->world_max[1], (double)m->world_max[2], VOLUME_MAX_COORDINATE);
            medium_free(m);
            return -1;
        }
    /* the smallest world voxel edge: the emission term's cap c_vox / voxel_size (spec §7.4) */
    double vs = INFINITY;
    for (int c = 0; c < 3; ++c)
        vs = fmin(vs, sqrt(i2w[c * 4] * i2w[c * 4] + i2w[c * 4 + 1] * i2w[c * 4 + 1] + i2w[c * 4 + 2] * i2w[c * 4 + 2]));
    float *bound = NULL;
    if (majorant_build(m, i2w, (float)vs, &bound, err, name, desc->memory_budget, desc->dense_cells_max)) {
        medium_free(m);
        return -1;
    }
    /* the emission-energy grid (§4.3) from the majorant's per-cell emission bound */
    int rc = emission_build(m, i2w, bound, err, name);
    free(bound);
    if (rc) {
        medium_free(m);
        return -1;
    }
    const EmissionEnergyGrid *e = &m->emission_energy;
    m->memory_bytes = m->majorant.bytes;
    if (e->density)
        m->memory_bytes += (m->majorant.bricks.entries ? (uint64_t)m->majorant.nslots * 512u
                                                       : (uint64_t)m->majorant.dims[0] * (uint64_t)m->majorant.dims[1] *
                                                             (uint64_t)m->majorant.dims[2]) *
                               sizeof(float) +
                           (uint64_t)e->count * (sizeof(int32_t) + sizeof(double));
    return 0;
}

void medium_free(Medium *m) {
    if (!m) return;
    free(m->majorant.sigma_maj);
    free(m->majorant.sigma_min);
    free(m->majorant.sigma_maj_coarse);
    free(m->majorant.bricks.entries);
    free(m->majorant.regions.entries);
    free(m->majorant.brick_maj);
    free(m->majorant.brick_min);
    free(m->majorant.brick_at);
    free(m->majorant.ubrick_at);
    emission_free(m);
    memset(m, 0, sizeof *m);
}
