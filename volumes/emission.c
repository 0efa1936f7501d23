/* volumes/emission.c: volumetric emission sampling (the cache points paper §4.3, Algorithm 2,
 * Eq. 11; the spec's §7.5): the emission-energy grid of an emitting VDB medium, point sampling
 * from it, and the solid-angle pdf of a direction by a DDA over its cells.
 *
 * The grid reuses the majorant grid's cells (VOLUME_MAJORANT_CELL^3 voxels of the density
 * grid, boxes [origin + 8 c, origin + 8 (c + 1)] in its index space). A point is drawn with
 * the volume density p_x = P_v / V_v in cell v; seen from o, the direction density is the
 * Jacobian transform p_w(d) = integral_0^inf p_x(o + t d) t^2 dt (dA = t^2 dw dt), which is
 * piecewise sum P_v (t1^3 - t0^3) / 3 over the cells the ray crosses (Eq. 11). The transform
 * is affine, so t along the ray is the same in index space as in the world. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

/* The floor of E_v relative to the cell's bound (bound x the volume of one voxel): keeps every
 * cell where the emission can be non-zero sampleable (complete support) at a negligible cost
 * (cells whose voxel centres miss the emission: the trilinear fringe of the active box, a
 * hot spot between two centres). */
#define EMISSION_FLOOR 1e-2

/* The part of cell c (index space) inside the density's trilinear support, the open box
 * (index_min - 1, index_max + 1): where sigma_a, so sigma_a L_e, can be non-zero. Samples are
 * drawn there only; its volume in voxels, 0 when the cell lies outside. */
static double cell_box(const Medium *m, const int32_t c[3], double lo[3], double hi[3]) {
    const MajorantGrid *mg = &m->majorant;
    double vol = 1.0;
    for (int k = 0; k < 3; ++k) {
        double a = mg->origin[k] + 8.0 * c[k];
        lo[k] = fmax(a, m->density.index_min[k] - 1.0);
        hi[k] = fmin(a + 8.0, m->density.index_max[k] + 1.0);
        vol *= fmax(hi[k] - lo[k], 0.0);
    }
    return vol;
}

/* Cell index ci's cell coordinates: the dense form's x-fastest layout, or the sparse form's
 * slot x 512 + cell in the brick (x fastest). */
static inline void cell_of(const MajorantGrid *mg, size_t ci, int32_t c[3]) {
    if (mg->bricks.entries) {
        const int32_t *b = mg->brick_at + 3 * (ci / 512);
        size_t l = ci % 512;
        c[0] = 8 * b[0] + (int32_t)(l % 8);
        c[1] = 8 * b[1] + (int32_t)(l / 8 % 8);
        c[2] = 8 * b[2] + (int32_t)(l / 64);
    } else {
        c[0] = (int32_t)(ci % (size_t)mg->dims[0]);
        c[1] = (int32_t)(ci / (size_t)mg->dims[0] % (size_t)mg->dims[1]);
        c[2] = (int32_t)(ci / ((size_t)mg->dims[0] * (size_t)mg->dims[1]));
    }
}

/* L_e from an aux grid value (grid_emission's colour mapping). */
static void aux_emission(const Medium *m, float v, float le[3]) {
    if (m->emission.buffer) {
        for (int k = 0; k < 3; ++k) le[k] = m->emission_scale * v * m->emission_color[k];
    } else if (v >= BLACKBODY_MIN_KELVIN) {
        blackbody_lookup(v, le);
        for (int k = 0; k < 3; ++k) le[k] *= m->emission_scale;
    } else {
        le[0] = le[1] = le[2] = 0.0f;
    }
}

int emission_build(Medium *m, const double i2w[16], const float *bound, char err[IO_ERR_LEN], const char *name) {
    EmissionEnergyGrid *e = &m->emission_energy;
    memset(e, 0, sizeof *e);
    if (!m->emissive || !bound) return 0;
    const MajorantGrid *mg = &m->majorant;
    size_t ncells = mg->bricks.entries ? (size_t)mg->nslots * 512u
                                       : (size_t)mg->dims[0] * (size_t)mg->dims[1] * (size_t)mg->dims[2];
    const double *a = i2w;
    double det = a[0] * (a[5] * a[10] - a[6] * a[9]) - a[4] * (a[1] * a[10] - a[2] * a[9]) +
                 a[8] * (a[1] * a[6] - a[2] * a[5]);
    double vvox = fabs(det);
    for (int i = 0; i < 16; ++i) e->index_to_world[i] = (float)i2w[i];

    /* the sparse form's uniform emitting bricks (volumes.h) follow the cells, one entry each */
    const size_t nuni = mg->bricks.entries ? (size_t)mg->nubricks : 0, nentries = ncells + nuni;
    double *energy = malloc((nentries ? nentries : 1) * sizeof(double));
    e->density = calloc(ncells ? ncells : 1, sizeof(float));
    if (!energy || !e->density) goto oom;

    GridReader dens, aux;
    const VolumeGrid *ag = m->emission.buffer ? &m->emission : &m->temperature;
    grid_reader_init(&dens, &m->density);
    grid_reader_init(&aux, ag);
    /* the aux grid in the density grid's index space (the usual VDB layout): its voxels are
     * read directly instead of through the world and a trilinear lookup */
    int same_space = memcmp(ag->world_to_index, m->density.world_to_index, sizeof ag->world_to_index) == 0;
    double total = 0.0, cen[3] = {0.0, 0.0, 0.0};
    size_t count = 0;
    for (size_t ci = 0; ci < ncells; ++ci) {
        {
            {
                energy[ci] = 0.0;
                if (!(bound[ci] > 0.0f)) continue;
                int32_t c[3];
                cell_of(mg, ci, c);
                int32_t base[3] = {mg->origin[0] + 8 * c[0], mg->origin[1] + 8 * c[1], mg->origin[2] + 8 * c[2]};
                double blo[3], bhi[3], vcell = cell_box(m, c, blo, bhi) * vvox;
                if (!(vcell > 0.0)) continue;
                double sum = 0.0, vc[3] = {0.0, 0.0, 0.0};
                /* the cell's voxels inside the active box (the field is 0 at the centres of the
                 * others); at a voxel centre the trilinear field is the voxel's value */
                int32_t v0[3], v1[3];
                for (int k = 0; k < 3; ++k) {
                    v0[k] = base[k] > m->density.index_min[k] ? base[k] : m->density.index_min[k];
                    v1[k] = base[k] + 7 < m->density.index_max[k] ? base[k] + 7 : m->density.index_max[k];
                }
                /* the sparse form: a cell inside a tile of density and of the aux grid (same
                 * space) is one value at every centre, summed at once (an emitting tile's border
                 * bricks: 25 M cells of 512 voxels) */
                int tiled = 0;
                if (mg->bricks.entries && same_space && v0[0] <= v1[0] && v0[1] <= v1[1] && v0[2] <= v1[2]) {
                    int in_aux = 1;
                    for (int k = 0; k < 3; ++k) in_aux = in_aux && v0[k] >= ag->index_min[k] && v1[k] <= ag->index_max[k];
                    uint32_t ld = 0, la = 0;
                    float dval = grid_voxel_level(&dens, base[0], base[1], base[2], &ld);
                    float aval = in_aux ? grid_voxel_level(&aux, base[0], base[1], base[2], &la) : 0.0f;
                    if (in_aux && ld >= 1 && la >= 1) {
                        tiled = 1;
                        float st = vminf(m->density_scale * dval, VOLUME_MAX_SIGMA_T), le[3], src[3];
                        if (st > 0.0f) {
                            aux_emission(m, aval, le);
                            for (int k = 0; k < 3; ++k) src[k] = (1.0f - m->albedo[k]) * st * le[k];
                            double n = (double)(v1[0] - v0[0] + 1) * (v1[1] - v0[1] + 1) * (v1[2] - v0[2] + 1);
                            double lv = vlum(src), q[3];
                            sum = n * lv;
                            for (int k = 0; k < 3; ++k) q[k] = 0.5 * (v0[k] + v1[k]);
                            for (int r = 0; r < 3; ++r) vc[r] = sum * (a[r] * q[0] + a[4 + r] * q[1] + a[8 + r] * q[2] + a[12 + r]);
                        }
                    }
                }
                for (int32_t z = v0[2]; z <= v1[2] && !tiled; ++z)
                    for (int32_t y = v0[1]; y <= v1[1]; ++y)
                        for (int32_t x = v0[0]; x <= v1[0]; ++x) {
                            float st = vminf(m->density_scale * grid_voxel(&dens, x, y, z), VOLUME_MAX_SIGMA_T);
                            if (!(st > 0.0f)) continue;
                            float pi[3] = {(float)x, (float)y, (float)z}, p[3], le[3], src[3];
                            for (int r = 0; r < 3; ++r)
                                p[r] = (float)(a[r] * pi[0] + a[4 + r] * pi[1] + a[8 + r] * pi[2] + a[12 + r]);
                            if (same_space) { /* the aux voxel at the same centre */
                                float av = x >= ag->index_min[0] && x <= ag->index_max[0] && y >= ag->index_min[1] &&
                                                   y <= ag->index_max[1] && z >= ag->index_min[2] &&
                                                   z <= ag->index_max[2]
                                               ? grid_voxel(&aux, x, y, z)
                                               : 0.0f;
                                aux_emission(m, av, le);
                            } else {
                                grid_emission(m, &aux, p, le);
                            }
                            for (int k = 0; k < 3; ++k) src[k] = (1.0f - m->albedo[k]) * st * le[k];
                            double lv = vlum(src);
                            sum += lv;
                            for (int r = 0; r < 3; ++r) vc[r] += lv * p[r];
                        }
                double ev = sum * vvox, floor_e = EMISSION_FLOOR * (double)bound[ci] * vvox;
                if (!(ev >= floor_e)) {
                    /* the floor, centred on the sampled box */
                    ev = floor_e;
                    double q[3];
                    for (int k = 0; k < 3; ++k) q[k] = 0.5 * (blo[k] + bhi[k]);
                    for (int r = 0; r < 3; ++r) vc[r] = a[r] * q[0] + a[4 + r] * q[1] + a[8 + r] * q[2] + a[12 + r];
                } else {
                    for (int r = 0; r < 3; ++r) vc[r] /= sum;
                }
                if (!(ev > 0.0) || !isfinite(ev)) continue;
                energy[ci] = ev;
                total += ev;
                for (int r = 0; r < 3; ++r) cen[r] += ev * vc[r];
                ++count;
            }
        }
    }
    for (size_t j = 0; j < nuni; ++j) { /* a uniform emitting brick: every voxel as its first */
        const int32_t *b = mg->ubrick_at + 3 * j;
        const MajorantEntry *be = sp_find(&mg->bricks, sp_key(b[0], b[1], b[2]));
        size_t ci = ncells + j;
        energy[ci] = 0.0;
        const int32_t v0[3] = {mg->origin[0] + 64 * b[0], mg->origin[1] + 64 * b[1], mg->origin[2] + 64 * b[2]};
        float st = vminf(m->density_scale * grid_voxel(&dens, v0[0], v0[1], v0[2]), VOLUME_MAX_SIGMA_T);
        float pi[3] = {(float)v0[0], (float)v0[1], (float)v0[2]}, p[3], le[3], src[3];
        for (int r = 0; r < 3; ++r) p[r] = (float)(a[r] * pi[0] + a[4 + r] * pi[1] + a[8 + r] * pi[2] + a[12 + r]);
        if (same_space) {
            float av = v0[0] >= ag->index_min[0] && v0[0] <= ag->index_max[0] && v0[1] >= ag->index_min[1] &&
                               v0[1] <= ag->index_max[1] && v0[2] >= ag->index_min[2] && v0[2] <= ag->index_max[2]
                           ? grid_voxel(&aux, v0[0], v0[1], v0[2])
                           : 0.0f;
            aux_emission(m, av, le);
        } else {
            grid_emission(m, &aux, p, le);
        }
        for (int k = 0; k < 3; ++k) src[k] = (1.0f - m->albedo[k]) * st * le[k];
        double ev = (double)vlum(src) * 262144.0 * vvox, floor_e = EMISSION_FLOOR * (double)be->emit * 512.0 * vvox;
        /* the voxel centres' mean (v0 + 31.5), or the sampled box's centre (v0 + 32) when floored */
        double off = ev >= floor_e ? 31.5 : 32.0, vc[3];
        if (!(ev >= floor_e)) ev = floor_e;
        for (int r = 0; r < 3; ++r)
            vc[r] = a[r] * (v0[0] + off) + a[4 + r] * (v0[1] + off) + a[8 + r] * (v0[2] + off) + a[12 + r];
        if (!(ev > 0.0) || !isfinite(ev)) continue;
        energy[ci] = ev;
        total += ev;
        for (int r = 0; r < 3; ++r) cen[r] += ev * vc[r];
        ++count;
    }
    if (count == 0 || !(total > 0.0) || !isfinite(total)) { /* emits nothing */
        free(energy);
        free(e->density);
        e->density = NULL;
        return 0;
    }
    e->cells = malloc(count * sizeof(int32_t));
    e->cdf = malloc(count * sizeof(double));
    if (!e->cells || !e->cdf) goto oom;
    double run = 0.0;
    size_t j = 0;
    for (size_t ci = 0; ci < nentries; ++ci) {
        if (!(energy[ci] > 0.0)) {
            if (ci >= ncells) { /* a uniform brick that does not emit after all */
                const int32_t *b = mg->ubrick_at + 3 * (ci - ncells);
                ((MajorantEntry *)sp_find(&mg->bricks, sp_key(b[0], b[1], b[2])))->emit = 0.0f;
            }
            continue;
        }
        double pv = energy[ci] / total, lo[3], hi[3];
        run += pv;
        e->cells[j] = (int32_t)ci;
        e->cdf[j] = run;
        if (ci < ncells) {
            int32_t c[3];
            cell_of(mg, ci, c);
            e->density[ci] = (float)(pv / (cell_box(m, c, lo, hi) * vvox));
        } else { /* the brick's entry holds its density from now on (its bound until here) */
            const int32_t *b = mg->ubrick_at + 3 * (ci - ncells);
            ((MajorantEntry *)sp_find(&mg->bricks, sp_key(b[0], b[1], b[2])))->emit =
                (float)(pv / (262144.0 * vvox));
        }
        ++j;
    }
    e->cdf[count - 1] = 1.0;
    e->count = (int32_t)count;
    e->power = (float)total;
    for (int r = 0; r < 3; ++r) e->centroid[r] = (float)(cen[r] / total);
    free(energy);
    return 0;
oom:
    free(energy);
    free(e->density);
    free(e->cells);
    free(e->cdf);
    memset(e, 0, sizeof *e);
    if (err) snprintf(err, IO_ERR_LEN, "%s: out of memory building the emission-energy grid", name);
    return -1;
}

void emission_free(Medium *m) {
    EmissionEnergyGrid *e = &m->emission_energy;
    free(e->density);
    free(e->cells);
    free(e->cdf);
    memset(e, 0, sizeof *e);
}

float medium_emission_power(const Medium *m) {
    return m && m->kind == MEDIUM_GRID && m->emission_energy.count > 0 ? m->emission_energy.power : 0.0f;
}

void medium_emission_centroid(const Medium *m, float c[3]) {
    int on = medium_emission_power(m) > 0.0f;
    for (int k = 0; k < 3; ++k) c[k] = on ? m->emission_energy.centroid[k] : 0.0f;
}

static inline float unit_clamp(float u) { return u >= 0.0f ? (u < 1.0f ? u : 0x1.fffffep-1f) : 0.0f; }

float medium_emission_sample(const Medium *m, float u0, float u1, float u2, float u3, float p[3]) {
    if (!(medium_emission_power(m) > 0.0f)) {
        p[0] = p[1] = p[2] = 0.0f;
        return 0.0f;
    }
    const EmissionEnergyGrid *e = &m->emission_energy;
    const MajorantGrid *mg = &m->majorant;
    /* the first cell whose cdf exceeds u0: its probability step is positive */
    double u = (double)unit_clamp(u0);
    int32_t a = 0, b = e->count - 1;
    while (a < b) {
        int32_t mid = a + (b - a) / 2;
        if (e->cdf[mid] > u) b = mid;
        else a = mid + 1;
    }
    int32_t ci = e->cells[a];
    float uu[3] = {unit_clamp(u1), unit_clamp(u2), unit_clamp(u3)}, pi[3];
    double lo[3], hi[3];
    const size_t ncells = mg->bricks.entries ? (size_t)mg->nslots * 512u : (size_t)-1;
    float dv;
    if ((size_t)ci >= ncells) { /* a uniform emitting brick: its box, inside the support */
        const int32_t *b = mg->ubrick_at + 3 * ((size_t)ci - ncells);
        for (int k = 0; k < 3; ++k) {
            lo[k] = mg->origin[k] + 64.0 * b[k];
            hi[k] = lo[k] + 64.0;
        }
        dv = sp_find(&mg->bricks, sp_key(b[0], b[1], b[2]))->emit;
    } else {
        int32_t c[3];
        cell_of(mg, (size_t)ci, c);
        cell_box(m, c, lo, hi);
        dv = e->density[ci];
    }
    for (int k = 0; k < 3; ++k) pi[k] = (float)(lo[k] + (hi[k] - lo[k]) * (double)uu[k]);
    vol_xform_point(e->index_to_world, pi, p);
    return dv;
}

/* medium_emission_pdf over the sparse form: the same sum over the cells the ray crosses, an
 * empty block (a uniform brick or an absent region: no emitting cell) crossed at once, the
 * planes' distances computed from the cell index (no drift over long gaps). */
static float sparse_pdf(const Medium *m, const double oi[3], const double di[3], double t0, double t1) {
    enum { B = VOLUME_MAJORANT_BRICK, R = VOLUME_MAJORANT_REGION };
    const MajorantGrid *mg = &m->majorant;
    const float *dens = m->emission_energy.density;
    int32_t cell[3], step[3];
    double tn[3];
    for (int k = 0; k < 3; ++k) {
        double c = floor((oi[k] + t0 * di[k] - mg->origin[k]) * 0.125);
        cell[k] = c < 0.0 ? 0 : c >= mg->dims[k] ? mg->dims[k] - 1 : (int32_t)c;
        step[k] = di[k] > 0.0 ? 1 : di[k] < 0.0 ? -1 : 0;
        tn[k] = step[k] ? (mg->origin[k] + 8.0 * (cell[k] + (step[k] > 0)) - oi[k]) / di[k] : INFINITY;
    }
    double sum = 0.0, t = t0;
    for (;;) {
        /* the cell's block: an emitting cell's density, or an empty block of blk^3 cells */
        int32_t blk = R, slot = -1;
        float uniform_dv = 0.0f; /* a uniform emitting brick's density */
        if (sp_find(&mg->regions, sp_key(cell[0] / R, cell[1] / R, cell[2] / R))) {
            const MajorantEntry *e = sp_find(&mg->bricks, sp_key(cell[0] / B, cell[1] / B, cell[2] / B));
            blk = e && e->slot >= 0 ? 1 : B;
            if (blk == 1) slot = e->slot;
            else if (e) uniform_dv = e->emit;
        }
        if (blk > 1) { /* to the last cell before the block's exit plane along each axis */
            int32_t n[3];
            double exit = INFINITY;
            int ax = 0;
            for (int k = 0; k < 3; ++k) {
                n[k] = 0;
                if (!step[k]) continue;
                int32_t left = step[k] > 0 ? blk - 1 - cell[k] % blk : cell[k] % blk;
                int32_t to_edge = step[k] > 0 ? mg->dims[k] - 1 - cell[k] : cell[k];
                n[k] = left < to_edge ? left : to_edge;
                double ek = (mg->origin[k] + 8.0 * (cell[k] + step[k] * n[k] + (step[k] > 0)) - oi[k]) / di[k];
                if (ek < exit) {
                    exit = ek;
                    ax = k;
                }
            }
            if (!(exit < t1)) { /* the segment ends in this block */
                if (uniform_dv > 0.0f) sum += (double)uniform_dv * (t1 - t) * (t1 * t1 + t1 * t + t * t) * (1.0 / 3.0);
                break;
            }
            for (int k = 0; k < 3; ++k) {
                if (!step[k]) continue;
                int32_t j = n[k];
                if (k != ax) { /* the planes of axis k before the exit */
                    double td = 8.0 / fabs(di[k]);
                    double q = ceil((exit - tn[k]) / td);
                    j = q > 0.0 ? (q < (double)n[k] ? (int32_t)q : n[k]) : 0;
                }
                cell[k] += step[k] * j;
                tn[k] = (mg->origin[k] + 8.0 * (cell[k] + (step[k] > 0)) - oi[k]) / di[k];
            }
        }
        int a = tn[0] < tn[1] ? (tn[0] < tn[2] ? 0 : 2) : (tn[1] < tn[2] ? 1 : 2);
        double te = fmin(fmax(tn[a], t), t1);
        if (slot >= 0 || uniform_dv > 0.0f) {
            float dv = uniform_dv;
            if (slot >= 0)
                dv = dens[(size_t)slot * 512u + (size_t)(cell[0] % B) + B * ((size_t)(cell[1] % B) + B * (size_t)(cell[2] % B))];
            /* t1^3 - t0^3 without cancellation */
            if (dv > 0.0f) sum += (double)dv * (te - t) * (te * te + te * t + t * t) * (1.0 / 3.0);
        }
        if (!(te < t1)) break;
        t = te;
        cell[a] += step[a];
        if ((uint32_t)cell[a] >= (uint32_t)mg->dims[a]) break;
        tn[a] = (mg->origin[a] + 8.0 * (cell[a] + (step[a] > 0)) - oi[a]) / di[a];
    }
    return (float)sum;
}

float medium_emission_pdf(const Medium *m, const float o[3], const float d[3]) {
    if (!(medium_emission_power(m) > 0.0f)) return 0.0f;
    for (int k = 0; k < 3; ++k)
        if (!isfinite(o[k]) || !isfinite(d[k])) return 0.0f;
    const EmissionEnergyGrid *e = &m->emission_energy;
    const MajorantGrid *mg = &m->majorant;
    const float *w = m->world_to_index;
    double oi[3], di[3];
    for (int r = 0; r < 3; ++r) {
        oi[r] = (double)w[r] * o[0] + (double)w[4 + r] * o[1] + (double)w[8 + r] * o[2] + (double)w[12 + r];
        di[r] = (double)w[r] * d[0] + (double)w[4 + r] * d[1] + (double)w[8 + r] * d[2];
    }
    /* the density's trilinear support (inside the cells' box: the cells cover index_min - 2 ..
     * index_max + 2), where the samples lie, in index space */
    double t0 = 0.0, t1 = INFINITY;
    for (int k = 0; k < 3; ++k) {
        double lo = m->density.index_min[k] - 1.0, hi = m->density.index_max[k] + 1.0;
        if (di[k] == 0.0) {
            if (!(oi[k] >= lo && oi[k] <= hi)) return 0.0f;
            continue;
        }
        double ta = (lo - oi[k]) / di[k], tb = (hi - oi[k]) / di[k];
        if (ta > tb) {
            double s = ta;
            ta = tb;
            tb = s;
        }
        t0 = fmax(t0, ta);
        t1 = fmin(t1, tb);
    }
    if (!(t0 < t1)) return 0.0f;
    if (mg->bricks.entries) return sparse_pdf(m, oi, di, t0, t1);
    /* Amanatides & Woo over the cells from the entry point (the entry cell clamped: the entry
     * lies on the box's surface up to rounding) */
    int32_t cell[3], step[3], stride[3] = {1, mg->dims[0], mg->dims[0] * mg->dims[1]};
    double tn[3], td[3];
    int64_t index = 0;
    for (int k = 0; k < 3; ++k) {
        double pk = oi[k] + t0 * di[k];
        double c = floor((pk - mg->origin[k]) * 0.125);
        int32_t ck = c < 0.0 ? 0 : c >= mg->dims[k] ? mg->dims[k] - 1 : (int32_t)c;
        cell[k] = ck;
        index += (int64_t)ck * stride[k];
        if (di[k] > 0.0) {
            step[k] = 1;
            tn[k] = (mg->origin[k] + 8.0 * (ck + 1) - oi[k]) / di[k];
            td[k] = 8.0 / di[k];
        } else if (di[k] < 0.0) {
            step[k] = -1;
            tn[k] = (mg->origin[k] + 8.0 * ck - oi[k]) / di[k];
            td[k] = -8.0 / di[k];
        } else {
            step[k] = 0;
            tn[k] = INFINITY;
            td[k] = INFINITY;
        }
    }
    const float *dens = e->density;
    double sum = 0.0, t = t0;
    for (;;) {
        int a = tn[0] < tn[1] ? (tn[0] < tn[2] ? 0 : 2) : (tn[1] < tn[2] ? 1 : 2);
        double te = fmin(fmax(tn[a], t), t1);
        float dv = dens[index];
        /* t1^3 - t0^3 without cancellation */
        if (dv > 0.0f) sum += (double)dv * (te - t) * (te * te + te * t + t * t) * (1.0 / 3.0);
        if (!(te < t1)) break;
        t = te;
        cell[a] += step[a];
        if ((uint32_t)cell[a] >= (uint32_t)mg->dims[a]) break;
        index += (int64_t)step[a] * stride[a];
        tn[a] += td[a];
    }
    return (float)sum;
}
