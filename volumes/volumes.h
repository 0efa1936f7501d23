/* volumes/volumes.h: participating media and the null-collision estimators over them.
 *
 * A Medium is a homogeneous medium (inside a closed mesh: constant coefficients, unbounded
 * here; the caller clips rays to the mesh) or a VDB volume (a density grid, optionally an
 * emission or a temperature grid, placed in the world by the glTF node and the grids' own
 * index-to-world transform). Several media may overlap along a ray (a fire volume inside a
 * mist volume inside a foggy room): a MediaView lists those of one ray segment and every
 * estimator works on their sum.
 *
 * Null-collision theory (the cache points paper §4.1, Eq. 7): a piecewise-constant majorant
 * sigma_maj >= sigma_t along the ray (the max over RGB, from a coarse majorant grid walked
 * with a DDA; free flights restart at each cell boundary, which is exact for exponential
 * distances) turns the heterogeneous medium into a homogeneous one plus null particles.
 *   - media_sample_event: spectral tracking (Kutz et al. 2017) of one free flight: returns a
 *     real scattering event (with the throughput factor to apply and the medium whose phase
 *     function scatters), or the end of the segment (passed through), or absorption. At every
 *     collision it also gathers the emission sigma_a L_e / sigma_maj times the current weight
 *     (an unbiased collision estimator of the emission integral), and the majorant grid holds
 *     max(sigma_t, min(sigma_a L_e, cap)) where media emit, so emissive regions of low
 *     extinction are sampled densely (the paper's §4.3, Algorithm 1; the cap keeps about one
 *     expected collision per voxel).
 *   - media_transmittance: residual ratio tracking (Novák et al. 2014 §5) for shadow rays,
 *     RGB: a per-cell control extinction (a lower bound of sigma_t, the majorant grid's
 *     sigma_min) is integrated exactly and only the residual is tracked; homogeneous media
 *     are exact (no collision).
 *   - media_emission_line: emission-optimised tracking (the paper's §4.3, Algorithm 1): one
 *     medium's emission integral along a segment, attenuated by all media of the view, with
 *     every collision gathering (P_a = P_n = 1); the other media's attenuation is residual
 *     ratio tracking as media_transmittance's (an emitting medium has no control).
 *   - medium_emission_sample / medium_emission_pdf: emissive media as lights (§4.3,
 *     Algorithm 2, Eq. 11): points from an emission-energy grid, and the solid-angle density
 *     of a direction by a DDA over its cells; medium_emission_power / _centroid for light
 *     selection.
 * Every walk is bounded: at most VOLUME_MAX_COLLISIONS collisions per call (counted in the
 * stats when hit, so a bad input can never hang a render).
 *
 * Random numbers come from the caller (VolumeRng), so the module holds no generator state
 * and results never depend on threads. Units: metres, 1/m, radiance in W/(m^2 sr). */
#ifndef CANDELA_VOLUMES_H
#define CANDELA_VOLUMES_H

#include <stdint.h>

#include "io.h"

#define VOLUME_MAX_OVERLAP 4          /* media one ray segment may be in at once */
#define VOLUME_MAX_COLLISIONS 100000  /* per tracker call (a walk never hangs) */
#define VOLUME_MAX_SIGMA_T 1e6f       /* extinction clamp (1/m): larger densities are clamped */

typedef struct VolumeRng {
    float (*next)(void *state);  /* uniform in [0, 1) */
    void *state;
} VolumeRng;

typedef enum { MEDIUM_HOMOGENEOUS = 0, MEDIUM_GRID = 1 } MediumKind;

/* A float grid placed in the world (a view of an IoVolumeGrid's NanoVDB buffer). */
typedef struct VolumeGrid {
    const void *buffer;          /* NanoVDB float grid (PNanoVDB reads it); NULL: no grid */
    uint64_t size;
    float world_to_index[16];    /* column-major; voxel centres at integer index coordinates */
    int32_t index_min[3], index_max[3];
} VolumeGrid;

/* The majorant grid: per coarse cell (VOLUME_MAJORANT_CELL^3 voxels of the density grid) the
 * max of sigma_t over RGB in the cell and its trilinear footprint, with the emission term
 * folded in (see above). Cells are addressed in the density grid's index space. */
#define VOLUME_MAJORANT_CELL 8
/* media_emission_line_at's VOLUME_LINE_COARSE caps the emission term at one expected
 * collision per this many voxels (VOLUME_LINE_STANDARD, media_emission_line: one per voxel) */
#define VOLUME_LINE_COARSE_VOXELS 8
/* An open-addressing hash table of the sparse majorant: key 0 is an empty slot; an entry is a
 * uniform brick or region (slot -1: majorant, control) or a brick's cells (slot: their offset /
 * 512 in brick_maj / brick_min). */
typedef struct MajorantEntry {
    uint64_t key;
    int32_t slot;
    float maj, ctl;
    float emit;  /* a uniform brick of an emitting medium: its cells' emission-energy density
                  * P_v / V_v (1/m^3; 0: it does not emit); its emission bound during the build */
} MajorantEntry;
typedef struct MajorantTable {
    MajorantEntry *entries;      /* capacity a power of 2, at most half full */
    uint64_t mask, count;        /* capacity - 1, entries held */
} MajorantTable;
typedef struct MajorantGrid {
    int32_t origin[3];           /* index of cell (0,0,0)'s first voxel */
    int32_t dims[3];             /* cells per axis */
    float *sigma_maj;            /* dims[0] * dims[1] * dims[2], x fastest */
    /* per cell a lower bound of sigma_t over the same footprint (the control extinction of
     * residual ratio tracking, Novak et al. 2014 §5); NULL for an emitting medium (0) */
    float *sigma_min;
    /* emitting media: the same majorant with the emission term capped at one expected
     * collision per VOLUME_LINE_COARSE_VOXELS voxels (media_emission_line_at's COARSE
     * density); NULL for media that do not emit */
    float *sigma_maj_coarse;
    /* Sparse form (sigma_maj NULL, bricks.entries non-NULL): a grid whose dense form would be
     * large and mostly empty or constant (two small clouds far apart, a constant tile filling a
     * huge box) is held in bricks of VOLUME_MAJORANT_BRICK^3 cells, found through two hash tables
     * (majorant.c): regions (VOLUME_MAJORANT_REGION^3 cells, the 4096^3 voxels of a NanoVDB root
     * entry) hold the majorant and control of a brick nobody stored there, and bricks hold either
     * two numbers (a brick whose padded box holds no voxel data: the largest and smallest tile
     * value it touches, exact inside a tile, looser by at most a brick along a tile's border) or
     * their 8^3 cells, computed as the dense form does. Only the bricks the tree's leaves and
     * tiles reach (with the trilinear footprint's ring) and the regions of the root's entries and
     * their neighbours are stored: memory follows the nodes the file holds, not its bounding box,
     * and the DDA crosses an absent region or a uniform brick in one step. In an emitting medium
     * regions are empty (the background's extinction must be 0) and a brick that can emit holds
     * its cells, unless it is a uniform emitting brick (one density tile value inside the active
     * box, one aux value over its footprint: MajorantEntry.emit, listed in ubrick_at); the
     * emission-energy grid follows the slots (cell index slot x 512 + cell in the brick, then
     * one index per uniform emitting brick). origin is a multiple of 4096. */
    MajorantTable bricks, regions;
    float outside_maj, outside_ctl; /* majorant and control of an absent region (the background) */
    float *brick_maj, *brick_min;/* 512 cells per non-uniform brick, x fastest; an emitting
                                  * medium's brick_min holds the coarse majorant, not a control */
    int32_t *brick_at;           /* per non-uniform brick (slot): its brick coordinates (3) */
    int32_t nslots;              /* non-uniform bricks */
    int32_t *ubrick_at;          /* an emitting medium's uniform emitting bricks: coordinates (3) */
    int32_t nubricks;
    uint64_t bytes;              /* memory held by the grid (either form) */
} MajorantGrid;
#define VOLUME_MAJORANT_BRICK 8
#define VOLUME_MAJORANT_REGION 512 /* cells: 4096 voxels, a NanoVDB root entry */
/* Below this many cells the majorant grid is always dense (the form every scene so far uses,
 * and the faster one to walk); above it the sparse form is used when it needs less than half
 * the memory (VolumeDesc.dense_cells_max overrides it, for tests). */
#define VOLUME_MAJORANT_DENSE_CELLS ((uint64_t)1 << 21)

/* The emission-energy grid of an emitting VDB medium (the cache points paper §4.3, "an
 * emission-energy-distribution grid, which is just a coarser version of the volume", after
 * Villemin & Hery 2013; the spec's §7.5): the majorant grid's cells (VOLUME_MAJORANT_CELL^3
 * voxels of the density grid, the index-space boxes [origin + 8 c, origin + 8 (c + 1)]) with
 * per cell the energy E_v = sum over the cell's voxel centres of lum(sigma_a L_e) x the world
 * volume of a voxel, raised to at least 1e-2 x (an upper bound of lum(sigma_a L_e) over the
 * cell's trilinear footprint) x the volume of a voxel, so every cell where the emission can be
 * non-zero has E_v > 0 (complete support). A cell is picked with P_v = E_v / sum E, then a
 * point uniformly in its sampled box: the cell's box clipped to the density's trilinear
 * support (index_min - 1, index_max + 1), outside which sigma_a = 0 (a parallelepiped in the
 * world, of volume V_v; the cells' full boxes reach up to 9 voxels beyond the active box).
 * Built by medium_init_vdb when the medium emits; all zero (count 0) otherwise and for
 * homogeneous media. Fields are the module's. */
typedef struct EmissionEnergyGrid {
    float *density;              /* per majorant cell (majorant layout; the sparse form: slot x 512 +
                                  * cell in the brick): P_v / V_v (1/m^3) */
    int32_t *cells;              /* linear indices of the cells with E_v > 0, ascending */
    double *cdf;                 /* cdf[i] = sum of P over cells[0..i]; cdf[count - 1] = 1 */
    int32_t count;
    float index_to_world[16];    /* of the density grid (column-major) */
    float power;                 /* sum of E_v; 0: the medium does not emit */
    float centroid[3];           /* the energy centroid: the lum(sigma_a L_e)-weighted mean of the
                                  * voxel centres (a floored cell counts at its box's centre) */
} EmissionEnergyGrid;

typedef struct Medium {
    MediumKind kind;
    float g;                     /* Henyey-Greenstein anisotropy, (-1, 1) */
    /* homogeneous */
    float sigma_a[3], sigma_s[3];
    /* grid: sigma_t = density_scale x density, sigma_s = albedo x sigma_t, sigma_a = the rest;
     * emitted radiance = emission_scale x emission x emission_color, or the blackbody of the
     * temperature grid (kelvin) times emission_scale when only a temperature grid is given */
    float density_scale, albedo[3];
    float emission_scale, emission_color[3];
    VolumeGrid density, emission, temperature;
    uint64_t memory_bytes;             /* held by the majorant and emission-energy grids */
    float world_min[3], world_max[3];  /* world bounds of the active density (homogeneous: infinite) */
    float world_to_index[16];          /* of the density grid (for the majorant DDA) */
    MajorantGrid majorant;
    int emissive;
    EmissionEnergyGrid emission_energy;
} Medium;

/* A homogeneous medium. 0 ok; -1 with a one-line message (negative or non-finite
 * coefficients, |g| >= 1). */
int medium_init_homogeneous(Medium *m, const float sigma_a[3], const float sigma_s[3], float g, char err[IO_ERR_LEN]);
/* What a VDB volume is made of (the glTF node's candela_volume extras, loaded by io/). */
typedef struct VolumeDesc {
    const IoVolumeGrid *density;                 /* required */
    const IoVolumeGrid *emission, *temperature;  /* optional (NULL) */
    float node_to_world[16];                     /* column-major; world = node x grid index_to_world */
    float density_scale, albedo[3], anisotropy;
    float emission_scale, emission_color[3];
    /* bytes the medium's own grids (majorant, emission energy) may take, checked before they are
     * allocated (0: no limit): the caller's share of a per-scene volume budget */
    uint64_t memory_budget;
    uint64_t dense_cells_max;    /* 0: VOLUME_MAJORANT_DENSE_CELLS; else above it always sparse (tests) */
} VolumeDesc;

/* A VDB volume (the grids keep owning their buffers and must outlive the medium). Negative
 * and non-finite densities count as 0 and extinctions above VOLUME_MAX_SIGMA_T are clamped
 * (documented clamping, never an error); builds the majorant grid. 0 ok; -1 with a one-line
 * message (out of memory, a singular transform, invalid parameters, world bounds beyond
 * VOLUME_MAX_COORDINATE (a voxel size of 1e30), grids larger than memory_budget). */
#define VOLUME_MAX_COORDINATE 1e12 /* IO_MAX_COORDINATE: the world bounds of a grid */
int medium_init_vdb(Medium *m, const VolumeDesc *desc, char err[IO_ERR_LEN]);
void medium_free(Medium *m);

/* Coefficients at a point: absorption, scattering (1/m) and emitted radiance L_e (the
 * source term of Eq. 7 is sigma_a L_e). */
typedef struct MediumCoefficients {
    float sigma_a[3], sigma_s[3];
    float emission[3];
} MediumCoefficients;

void medium_eval(const Medium *m, const float p[3], MediumCoefficients *c);

/* The media of one ray segment. */
typedef struct MediaView {
    const Medium *media[VOLUME_MAX_OVERLAP];
    int count;
    /* media_sample_event: 1 = decomposition tracking where homogeneous and grid media overlap
     * (Kutz et al. 2017 §4: a collision of the homogeneous control component needs no grid
     * lookup); 0 = spectral tracking of the sum (the same estimate in expectation) */
    int decomposition;
} MediaView;

/* The interval [*t0, *t1] of o + t d (d need not be unit) inside the medium's bounds, clipped
 * to [tmin, tmax]; 0 when empty. Homogeneous media return [tmin, tmax]. */
int medium_clip_ray(const Medium *m, const float o[3], const float d[3], float tmin, float tmax, float *t0, float *t1);

/* The majorant segments of one medium along o + t d: contiguous intervals [t0, t1] covering
 * exactly medium_clip_ray's interval, each with a constant sigma_maj >= sigma_t (max over RGB)
 * at every point of it (0 where the ray crosses empty cells or misses the grid's box).
 * Homogeneous media: one segment with sigma_maj = max over RGB of sigma_a + sigma_s. Grids: a
 * 3-D DDA (Amanatides & Woo 1987) over the majorant cells in the density grid's index space
 * (the transform is affine, so t is the same there); neighbouring cells of equal majorant
 * are merged into one segment. d need not be unit; a NaN or infinite o or d, a NaN tmin or
 * tmax and an empty interval give no segment. The struct lives on the caller's stack; its
 * fields are the module's. */
typedef struct MajorantIterator {
    const float *cells;              /* MajorantGrid.sigma_maj (grid media) */
    const float *cells_min;          /* MajorantGrid.sigma_min when the walk asked for controls, else NULL */
    int32_t dims[3], cell[3], step[3];
    int32_t index;                   /* linear index of the current cell */
    int32_t index_step[3];           /* what a step along each axis adds to index */
    int32_t phase;                   /* what the next piece is (majorant.c) */
    float t, t_end;                  /* the next segment starts at t; the clipped interval ends at t_end */
    float t_grid0, t_grid1;          /* the part of [t, t_end] inside the majorant grid's box */
    float t_next[3], t_delta[3];     /* DDA: t of the current cell's exit plane, t per cell, per axis */
    float sigma;                     /* homogeneous: the constant majorant */
    float t_base;                    /* the ray in the density grid's index space is */
    float o_index[3], d_index[3];    /* o_index + (t - t_base) d_index (re-based at the clip entry) */
    const MajorantGrid *sparse;      /* the sparse form's grid (cells NULL), else NULL */
    int32_t control;                 /* sparse: controls asked for */
    float cur_maj, cur_min;          /* sparse: the current cell's majorant and control */
} MajorantIterator;

void medium_majorant_begin(const Medium *m, const float o[3], const float d[3], float tmin, float tmax,
                           MajorantIterator *it);
/* The next segment; 0 when there is none left. */
int medium_majorant_next(MajorantIterator *it, float *t0, float *t1, float *sigma_maj);
/* The same segments split further where the control grid changes: each also carries
 * *sigma_min, a lower bound of sigma_t (grey) on it (0 for emitting media, empty space and
 * homogeneous media, whose trackers use their exact coefficients). */
void medium_majorant_begin_control(const Medium *m, const float o[3], const float d[3], float tmin, float tmax,
                                   MajorantIterator *it);
/* The control segments over an emitting medium's coarse majorant (MajorantGrid.
 * sigma_maj_coarse), else as medium_majorant_begin_control. */
void medium_majorant_begin_coarse(const Medium *m, const float o[3], const float d[3], float tmin, float tmax,
                                  MajorantIterator *it);
int medium_majorant_next_control(MajorantIterator *it, float *t0, float *t1, float *sigma_maj, float *sigma_min);

/* Statistics a tracker adds to (the renderer reports them). */
typedef struct VolumeStats {
    uint64_t collisions;         /* majorant collisions evaluated */
    uint64_t capped_walks;       /* calls stopped at VOLUME_MAX_COLLISIONS */
    uint64_t grid_collisions;    /* media_sample_event: collisions that looked up a grid medium
                                  * (decomposition tracking's control collisions do not) */
} VolumeStats;

enum { VOLUME_EVENT_PASSED = 0, VOLUME_EVENT_SCATTER = 1, VOLUME_EVENT_ABSORBED = 2 };

typedef struct VolumeEvent {
    int type;
    float t;             /* scatter: the distance along the ray (passed: tmax) */
    int medium;          /* scatter: index in the view of the medium whose phase function applies
                          * (otherwise -1) */
    float weight[3];     /* throughput factor to apply (scatter: up to and including the
                          * scattering coefficient's; passed: over the whole segment;
                          * absorbed: 0) */
    float emitted[3];    /* emission gathered on the way, already weighted (add beta x this);
                          * valid for every outcome, absorption included */
    float emitted_by[VOLUME_MAX_OVERLAP][3]; /* emitted split by the view's medium it came from
                          * (index in the view; 0 beyond the view's count): the same collision
                          * estimates, one medium's sigma_a L_e each, so their sum is emitted up
                          * to float rounding (emitted itself is summed as before). For MIS,
                          * where each emissive medium is a light. */
    /* scatter: for MIS against distance sampling along the ray (the cache points paper §4.2,
     * Eq. 10): null_mis is the product over the null collisions before the event of the mean
     * over RGB of sigma_n / sigma_maj, sigma_s_mean the mean over RGB of the summed sigma_s at
     * the event (1 and 0 for the other outcomes). media_ratio_track returns the same product
     * over its collisions, so both techniques weigh a path with one function of its vertices. */
    float null_mis, sigma_s_mean;
} VolumeEvent;

/* One free flight along o + t d (d unit) over [tmin, tmax] through the view's media
 * (spectral tracking, Kutz et al. 2017, with the throughput-weighted probabilities that make
 * chromatic media unbiased; `beta` is the path throughput the probabilities weigh with, NULL
 * for (1, 1, 1)). stats may be NULL (also for media_transmittance). */
void media_sample_event(const MediaView *v, const float o[3], const float d[3], float tmin, float tmax,
                        const float beta[3], VolumeRng *rng, VolumeEvent *ev, VolumeStats *stats);

/* Transmittance (RGB) of o + t d (d unit) over [tmin, tmax] by residual ratio tracking; the
 * estimate is unbiased. */
void media_transmittance(const MediaView *v, const float o[3], const float d[3], float tmin, float tmax,
                         VolumeRng *rng, float T[3], VolumeStats *stats);

/* Plain ratio tracking over the view's majorant (no control: the null vertices must be those
 * of the free flights' majorant process), also returning in
 * *null_mis the product over its collisions of the mean over RGB of sigma_n / sigma_maj (see
 * VolumeEvent.null_mis): the null-collision path's density ratio of Eq. 10 for a point sampled
 * at tmax by another technique. */
void media_ratio_track(const MediaView *v, const float o[3], const float d[3], float tmin, float tmax,
                       VolumeRng *rng, float T[3], float *null_mis, VolumeStats *stats);

/* ---------------------------------------------------------------- distance sampling (§4.2) */

/* A density over distance t in [t0, t1] along a ray: the cache points paper's §4.2
 * "piecewise-linear 1-D CDF over distance" from importance values S_i at stations t_i
 * (ascending, the first at t0 and the last at t1; linear in between), mixed with a defensive
 * uniform term so every point of the interval can be drawn (the spec's §7.2 proposal):
 *   p(t) = (1 - delta) lin(t) / integral(lin) + delta / (t1 - t0).
 * With no importance anywhere (all S_i = 0) p is uniform. At most VOLUME_DISTANCE_STATIONS. */
#define VOLUME_DISTANCE_STATIONS 66
typedef struct VolumeDistanceTable {
    float t[VOLUME_DISTANCE_STATIONS], s[VOLUME_DISTANCE_STATIONS];
    double cdf[VOLUME_DISTANCE_STATIONS]; /* cdf[i]: integral of lin over [t0, t_i] */
    int n;
    float delta;
} VolumeDistanceTable;

/* 0 ok; -1 for fewer than 2 stations, more than VOLUME_DISTANCE_STATIONS, a non-finite or
 * decreasing t, t0 == t1, or a negative or non-finite S (then p is undefined: do not use). */
int volume_distance_table_init(VolumeDistanceTable *tab, const float *t, const float *s, int n, float delta);
/* A distance from two uniforms (u0 picks the component, u1 the point); returns it and its
 * density in *pdf (1/m), exactly volume_distance_pdf at the returned t. */
float volume_distance_sample(const VolumeDistanceTable *tab, float u0, float u1, float *pdf);
/* The density at t (0 outside [t0, t1]). */
float volume_distance_pdf(const VolumeDistanceTable *tab, float t);

/* ---------------------------------------------------------------- volumetric emission (§4.3) */

/* The emitted power of the medium as the emission-energy grid holds it: the sum of E_v, i.e.
 * the integral of lum(sigma_a L_e) over the volume (W/sr per unit of the emission scale:
 * radiance x 1/m x m^3 = W/sr) estimated at voxel centres; 0 if it does not emit
 * (homogeneous media never do). A light's power for light selection. */
float medium_emission_power(const Medium *m);
/* The energy centroid (world, m): the mean of the voxel centres weighted by lum(sigma_a L_e)
 * x voxel volume (a cell raised to its floor counts at its sampled box's centre, with E_v);
 * (0, 0, 0) if the medium does not emit. */
void medium_emission_centroid(const Medium *m, float c[3]);

/* A point p (world) of the medium's emission-energy grid (the paper's §4.3 / spec §7.5): u0
 * picks a cell with probability P_v = E_v / sum E, u1..u3 (in [0, 1)) a uniform point in the
 * cell's sampled box (world-space parallelepiped: the cell clipped to the density's support,
 * see EmissionEnergyGrid).
 * Returns the pdf per unit world volume, P_v / V_v (1/m^3); 0 (and p = 0) when the medium
 * does not emit. Deterministic, no allocation. */
float medium_emission_sample(const Medium *m, float u0, float u1, float u2, float u3, float p[3]);

/* The solid-angle density (1/sr) of the direction d (unit) from o for the points of
 * medium_emission_sample (d = normalize(p - o)): the paper's Algorithm 2 / Eq. 11, the
 * Jacobian-transformed volume density p_w(d) = integral over t > 0 of p_x(o + t d) t^2 dt,
 * i.e. a DDA (in double) over the emission-energy cells the ray o + t d crosses inside the
 * density's support box, summing (P_v / V_v) (t1^3 - t0^3) / 3 over each cell's entry / exit
 * [t0, t1]. Integrates to 1 over the sphere for any o (inside or outside the volume). 0 when
 * the medium does not emit, for a non-finite o or d and for a ray that misses every emitting
 * cell. */
float medium_emission_pdf(const Medium *m, const float o[3], const float d[3]);

/* The emission of one medium of the view, v->media[emitter], along o + t d (d unit) over
 * [tmin, tmax], attenuated from o by ALL media of the view: L = integral over [tmin, tmax] of
 * T(tmin, t) sigma_a,e(t) L_e,e(t) dt per channel (the radiance arriving at o + tmin d from
 * the direction d, travelling along -d). Emission-optimised tracking (the paper's §4.3,
 * Algorithm 1, with the spec's §7.4 fix: the collision is placed, and a walk past tmax
 * stops, before anything is gathered) over the view's merged majorants (as
 * media_sample_event, which carry the emission term): at every collision
 * L += w sigma_a,e L_e,e / sigma_maj, then w *= 1 - sigma_t,all / sigma_maj per channel
 * (sigma_maj and sigma_t,all here the residual ones of the non-emitting media: see
 * media_transmittance)
 * (P_a = P_n = 1: no absorption or scattering event is chosen, the walk always goes on); below
 * max(w) = 0.1 Russian roulette (survive with probability max(w), divide by it), as ratio
 * tracking. Unbiased. At most VOLUME_MAX_COLLISIONS collisions (stats->capped_walks; the
 * gathered L is kept). L = 0 for an emitter outside the view or not emissive. stats may be
 * NULL. No allocation. */
void media_emission_line(const MediaView *v, int emitter, const float o[3], const float d[3], float tmin, float tmax,
                         VolumeRng *rng, float L[3], VolumeStats *stats);
/* The same estimate from the majorant process of another collision density: COARSE caps the
 * emitter's emission term at one expected collision per VOLUME_LINE_COARSE_VOXELS voxels
 * instead of one per voxel (STANDARD); its extinction still bounds the majorant from below,
 * so the ratio-tracking weights stay in [0, 1]. A collision estimator is unbiased for any
 * majorant > 0 where the medium emits: the density only trades noise per line against
 * collisions, and where a line's noise matters differs by orders of magnitude (torch_mist,
 * 160x90, 6 x 8 spp): a line the camera sees IS the pixel (the renderer averages
 * several there), while a line found by next-event estimation from a scattering vertex is one
 * factor of a contribution whose noise comes from where the vertex and the direction fall
 * (averaging 8 STANDARD lines per estimate changed the image's variance by under 5% for 8x
 * the collisions; COARSE raised it by 5% with 3.5x fewer collisions in the whole render). */
typedef enum { VOLUME_LINE_STANDARD, VOLUME_LINE_COARSE } VolumeLineDensity;
void media_emission_line_at(const MediaView *v, int emitter, const float o[3], const float d[3], float tmin,
                            float tmax, VolumeLineDensity density, VolumeRng *rng, float L[3], VolumeStats *stats);

/* ---------------------------------------------------------------- phase function */

/* Henyey-Greenstein phase function; wo and wi both point away from the scattering point,
 * so forward scattering (g > 0) favours wi = -wo. Its pdf is the function itself. */
float hg_phase(float g, const float wo[3], const float wi[3]);
/* Samples wi (unit) with pdf = hg_phase(g, wo, wi); returns the pdf. */
float hg_sample(float g, const float wo[3], float u1, float u2, float wi[3]);

/* Blackbody radiance of a temperature (kelvin) as linear Rec.709 RGB, normalised so that the
 * luminance is 1 at every temperature (emission_scale sets the brightness); 0 below 500 K.
 * Documented in README.md. */
void blackbody_rgb(float kelvin, float rgb[3]);

#endif
