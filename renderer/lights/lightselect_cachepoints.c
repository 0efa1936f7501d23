/* renderer/lights/lightselect_cachepoints.c: cache points (Li et al. 2024, cachepoints/) as a
 * light-selection strategy. All the glue between the renderer and the cachepoints module is
 * here: candidate generation (§3.1.1: points in object bounding boxes in proportion to
 * volume, plus pilot path vertices), the light estimate callbacks (light_estimates.c), the
 * light tree the cut build's clusters descend, the build, and the protocol (light_sampler.h):
 * prepare = the vertex's cache point and its near lights' weights (§3.3), select / pmf,
 * record = the visibility counters (§3.2.1), barrier = Eqs. 5-6 and the visibility blur
 * (§3.2.2). The per-vertex token (LightVertex) is the point + 1 and the near lights' summed
 * weight, so the MIS pdf at the next wave costs one light's weight. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cachepoint_viz.h"
#include "cachepoints.h"
#include "clock.h"
#include "light_sampler.h"
#include "media.h"
#include "rng.h"
#include "sampling.h"
#include "scene.h"
#include "sort.h"
#include "threads.h"

/* Candidates (§3.1.1): the paper's 100,000 in object boxes at CANDIDATE_FULL_PIXELS or more,
 * in proportion to the pixels below, at least BBOX_CANDIDATES_MIN; and 65,536 stratified
 * pilot paths (§3.1.1 leaves their count open) at any size. The merge passes keep about one
 * point per pixel footprint (pass 1) and per 3 pixels (pass 2's floor, §3.1.4), so a smaller
 * image keeps fewer points from the same box candidates: the rest was build time spent on
 * points merged away. Measured at equal spp (variance of the mean, 2-3 seeds): a quarter of
 * the box and pilot candidates at 640x360 changed city, street, windows and emissive_mesh by
 * -1.1 % to +0.2 %; at 160x90, 4,096 pilot paths raised city's by 2 % (10,000 box candidates
 * with them: 7.6 %), so the pilots keep their count. */
#define BBOX_CANDIDATES 100000u
#define BBOX_CANDIDATES_MIN 25000u
#define PILOT_GRID 256u           /* 256 x 256 pilot paths */
#define CANDIDATE_FULL_PIXELS (1280.0 * 720.0)
#define PILOT_KEEP 0.5f
#define PILOT_CAP 1000000u
#define CANDIDATE_SEED_SALT 0xcac4e9017ull
#define CACHEPOINT_PROGRESSIVE_DEFAULT 0 /* --cachepoint-progressive's default (README: measured) */

/* The strategy's state: the built points and everything their callbacks read. */
typedef struct CachePointSampler {
    const Lights *lights;
    CachePoints *cp;
    CachePointLights view;       /* the lights as the cachepoints module sees them */
    float *centroid;
    uint8_t *infinite;
    CachePointStats stats;
    double build_seconds, build_cpu_seconds;
    LightEstimateTable estimates; /* the per-vertex near-light weights' precomputed part */
    /* the cut build: the light tree and its view (CachePointTree) */
    LightTree tree;
    CachePointTree tree_view;
    uint32_t *second, *leaf_light, *light_leaf;
    /* §4.2 scattering weights: the media and the camera they are computed for */
    const SceneMedia *media;
    int camera_ortho;
    vec3 camera_pos, camera_back; /* orthographic: the direction toward the camera */
    /* the summed weights on a grid over the scattering points' bounds (see build_scatter_grid) */
    float *scatter_grid;
    int grid_dims[3];
    vec3 grid_lo, grid_cell;
    float grid_step;
    const char *dump_path;       /* --dump-cachepoints (NULL: none), written by cp_finish */
    /* light linking: per link class c > 0, the lights that reach it (§3.3); NULL without */
    CachePointLink *links;
    /* progressive insertion (cachepoints_progress): the §4.2 weights to redo after an insertion
     * (their seed), and the time the barriers spent inserting */
    int inscatter;
    uint64_t seed;
    ThreadPool *grid_pool;
    double insert_seconds, insert_cpu_seconds;
    /* --cachepoint-bsdf: each light's bounding sphere (CachePointLights.bound); NULL: off */
    float *bound;
} CachePointSampler;

/* The vertex's light linking, or NULL (class 0: every light; the unlinked path, unchanged). */
static inline const CachePointLink *link_of(const CachePointSampler *s, const LightSampleContext *ctx) {
    return ctx->link_class ? &s->links[ctx->link_class] : NULL;
}

static void cp_estimate7(const void *user, uint32_t light, const float x[3], float out[7]) {
    const Lights *ls = ((const CachePointSampler *)user)->lights;
    light_contribution_estimate7(ls, &ls->lights[light], v3(x[0], x[1], x[2]), out);
}

static float cp_estimate(const void *user, uint32_t light, const float x[3], const float *n) {
    const CachePointSampler *s = user;
    vec3 nn = n ? v3(n[0], n[1], n[2]) : v3s(0.0f);
    return light_contribution_estimate_table(s->lights, &s->estimates, light, v3(x[0], x[1], x[2]), nn);
}

/* --- the light tree as the cut build sees it (CachePointTree) */

static void cp_node_bounds(const void *user, uint32_t node, float lo[3], float hi[3]) {
    const LightTreeNode *nd = &((const CachePointSampler *)user)->tree.nodes[node];
    lo[0] = nd->bmin.x; lo[1] = nd->bmin.y; lo[2] = nd->bmin.z;
    hi[0] = nd->bmax.x; hi[1] = nd->bmax.y; hi[2] = nd->bmax.z;
}

static void cp_node_estimate7(const void *user, uint32_t node, const float x[3], float out[7]) {
    light_tree_node_estimate7(&((const CachePointSampler *)user)->tree, node, v3(x[0], x[1], x[2]), out);
}

static LightSampleContext cp_context(const float x[3], const float *n) {
    LightSampleContext c = {v3(x[0], x[1], x[2]), n ? v3(n[0], n[1], n[2]) : v3s(0.0f)};
    return c;
}

static uint32_t cp_descend(const void *user, uint32_t node, const float x[3], const float *n, float u, float *pmf) {
    LightSampleContext c = cp_context(x, n);
    return light_tree_select_from(&((const CachePointSampler *)user)->tree, node, &c, u, pmf);
}

static float cp_descend_pmf(const void *user, uint32_t node, const float x[3], const float *n, uint32_t light) {
    LightSampleContext c = cp_context(x, n);
    return light_tree_pmf_from(&((const CachePointSampler *)user)->tree, node, &c, light);
}

/* Builds the light tree and the SoA view of it for the cut build. */
static int setup_tree_view(CachePointSampler *s) {
    const Lights *ls = s->lights;
    if (light_tree_build(&s->tree, ls->lights, ls->count) != 0) return -1;
    const LightTree *t = &s->tree;
    float *peak = malloc(((size_t)ls->count + 1) * sizeof(float));
    s->second = malloc(((size_t)t->node_count + 1) * sizeof(uint32_t));
    s->leaf_light = malloc(((size_t)t->node_count + 1) * sizeof(uint32_t));
    s->light_leaf = malloc(((size_t)ls->count + 1) * sizeof(uint32_t));
    if (!peak || !s->second || !s->leaf_light || !s->light_leaf) { free(peak); return -1; }
    for (uint32_t i = 0; i < ls->count; ++i) {
        peak[i] = light_peak_intensity(&ls->lights[i]);
        s->light_leaf[i] = UINT32_MAX;
    }
    int rc = light_tree_set_intensities(&s->tree, peak);
    free(peak);
    if (rc != 0) return -1;
    for (uint32_t k = 0; k < t->node_count; ++k) {
        const LightTreeNode *nd = &t->nodes[k];
        int leaf = nd->light != LIGHT_TREE_INTERIOR;
        s->second[k] = leaf ? 0 : nd->child;
        s->leaf_light[k] = leaf ? nd->light : UINT32_MAX;
        if (leaf) s->light_leaf[nd->light] = k;
    }
    s->tree_view = (CachePointTree){.node_count = t->node_count, .second_child = s->second,
                                    .leaf_light = s->leaf_light, .light_leaf = s->light_leaf,
                                    .node_bounds = cp_node_bounds, .node_estimate7 = cp_node_estimate7,
                                    .descend = cp_descend, .descend_pmf = cp_descend_pmf};
    s->view.tree = &s->tree_view;
    return 0;
}

static void pool_parallel_for(void *pool, size_t n, size_t grain, void (*fn)(void *, size_t, size_t, int), void *ctx) {
    threadpool_parallel_for((ThreadPool *)pool, n, grain, fn, ctx);
}

/* Instances whose every primitive has zero base colour never do light sampling (§3.1.1). */
static int instance_reflects(const Scene *scene, uint32_t inst) {
    const IoMesh *mesh = &scene->io.meshes[scene->instances[inst].mesh];
    for (uint32_t k = 0; k < mesh->num_primitives; ++k) {
        const IoMaterial *m = scene->prims[mesh->first_primitive + k].material;
        if (m->base_color[0] > 0.0f || m->base_color[1] > 0.0f || m->base_color[2] > 0.0f) return 1;
    }
    return 0;
}

static void instance_bounds(const Scene *scene, uint32_t inst, vec3 *lo, vec3 *hi) {
    const SceneInstance *si = &scene->instances[inst];
    const IoMesh *mesh = &scene->io.meshes[si->mesh];
    *lo = v3s(INFINITY);
    *hi = v3s(-INFINITY);
    for (uint32_t k = 0; k < mesh->num_primitives; ++k) {
        const IoPrimitive *p = scene->prims[mesh->first_primitive + k].io;
        for (uint32_t v = 0; v < p->num_vertices; ++v) {
            vec3 w = xform_point(si->xform, v3(p->positions[3 * v], p->positions[3 * v + 1], p->positions[3 * v + 2]));
            *lo = v3_min(*lo, w);
            *hi = v3_max(*hi, w);
        }
    }
}

typedef struct Candidates { float *xyz; uint32_t count, capacity; } Candidates;

static int push(Candidates *c, vec3 p) {
    if (c->count == c->capacity) {
        uint32_t nc = c->capacity ? 2 * c->capacity : 1024;
        float *n = realloc(c->xyz, (size_t)nc * 3 * sizeof(float));
        if (!n) return -1;
        c->xyz = n;
        c->capacity = nc;
    }
    c->xyz[3 * c->count] = p.x; c->xyz[3 * c->count + 1] = p.y; c->xyz[3 * c->count + 2] = p.z;
    ++c->count;
    return 0;
}

/* The candidate counts for this render: the options', else scaled with the image (above): the
 * full image with --crop too, whose pixel footprint the merge passes keep (the pilots go to the
 * crop: pilot_candidates). */
static void candidate_counts(const Scene *scene, const CandelaOptions *o, uint32_t *bbox, uint32_t *pilot_grid) {
    double f = (double)scene->camera.width * (double)scene->camera.height / CANDIDATE_FULL_PIXELS;
    if (!(f < 1.0)) f = 1.0;
    double b = o->cachepoint_candidates ? (double)o->cachepoint_candidates : fmax(BBOX_CANDIDATES * f, BBOX_CANDIDATES_MIN);
    double paths = o->cachepoint_pilots ? (double)o->cachepoint_pilots : (double)PILOT_GRID * PILOT_GRID;
    *bbox = (uint32_t)lrint(b);
    *pilot_grid = (uint32_t)lrint(ceil(sqrt(paths))); /* a square grid of strata over the image */
    if (*pilot_grid < 1) *pilot_grid = 1;
}

/* `budget` points in the instances' world boxes in proportion to (padded) volume; budget split
 * by largest remainder in instance order; positions from the counter-based RNG keyed by
 * (seed, instance, k), so they never depend on threads (§3.1.1). */
static int bbox_candidates(const Scene *scene, const SceneMedia *media, uint64_t seed, uint32_t budget, Candidates *c) {
    /* the boxes: instances, then VDB volumes (a medium's vertices need points inside it) */
    uint32_t ni = scene->io.num_instances, n = ni + (media ? media->num_vdb : 0);
    if (n == 0) return 0;
    vec3 *lo = malloc(n * sizeof *lo), *hi = malloc(n * sizeof *hi);
    double *vol = calloc(n, sizeof *vol);
    uint32_t *quota = calloc(n, sizeof *quota);
    double *rem = calloc(n, sizeof *rem);
    if (!lo || !hi || !vol || !quota || !rem) { free(lo); free(hi); free(vol); free(quota); free(rem); return -1; }
    float pad = 1e-3f * 2.0f * scene->radius;
    double total = 0.0;
    for (uint32_t i = 0; i < n; ++i) {
        if (i < ni) {
            if (!instance_reflects(scene, i) || scene->instances[i].hidden) continue;
            instance_bounds(scene, i, &lo[i], &hi[i]);
        } else {
            const Medium *m = &media->vdb[i - ni];
            lo[i] = v3(m->world_min[0], m->world_min[1], m->world_min[2]);
            hi[i] = v3(m->world_max[0], m->world_max[1], m->world_max[2]);
        }
        if (!(lo[i].x <= hi[i].x) || !v3_is_finite(lo[i]) || !v3_is_finite(hi[i])) continue;
        vec3 ext = v3_sub(hi[i], lo[i]);
        /* flat objects get a minimum thickness so they receive points */
        vol[i] = (double)maxf(ext.x, pad) * maxf(ext.y, pad) * maxf(ext.z, pad);
        total += vol[i];
    }
    uint32_t assigned = 0;
    for (uint32_t i = 0; i < n && total > 0.0; ++i) {
        double share = budget * vol[i] / total;
        quota[i] = (uint32_t)share;
        rem[i] = share - quota[i];
        assigned += quota[i];
    }
    while (total > 0.0 && assigned < budget) { /* largest remainder, lowest index wins ties */
        uint32_t best = 0;
        for (uint32_t i = 1; i < n; ++i) if (rem[i] > rem[best]) best = i;
        if (!(rem[best] > 0.0)) break;
        quota[best]++;
        rem[best] = -1.0;
        ++assigned;
    }
    int rc = 0;
    for (uint32_t i = 0; i < n && rc == 0; ++i) {
        vec3 ext = v3_sub(hi[i], lo[i]);
        vec3 mid = v3_scale(v3_add(lo[i], hi[i]), 0.5f);
        vec3 half = v3_scale(v3(maxf(ext.x, pad), maxf(ext.y, pad), maxf(ext.z, pad)), 0.5f);
        for (uint32_t k = 0; k < quota[i] && rc == 0; ++k) {
            uint64_t key = rng_path_key(seed ^ CANDIDATE_SEED_SALT, i, k);
            vec3 u = v3(rng_uniform(key, 0), rng_uniform(key, 1), rng_uniform(key, 2));
            rc = push(c, v3(mid.x + (2.0f * u.x - 1.0f) * half.x, mid.y + (2.0f * u.y - 1.0f) * half.y,
                            mid.z + (2.0f * u.z - 1.0f) * half.z));
        }
    }
    free(lo); free(hi); free(vol); free(quota); free(rem);
    return rc;
}

/* Pilot paths (§3.1.1): a stratified grid of camera rays over the image (over the crop with
 * --crop, so the pilots' density there rises by the crop's share of the image), their first hit and one cosine
 * bounce, and where the camera ray crosses a VDB volume a point in it; each vertex kept with
 * probability 1/2 (fewer paths than §3.1.1 uses, half kept: the merge passes thin them anyway). */
static int pilot_candidates(const Scene *scene, const SceneMedia *media, uint64_t seed, uint32_t grid, Candidates *c) {
    const Camera *cam = &scene->camera;
    uint32_t kept = 0;
    for (uint32_t j = 0; j < grid; ++j) {
        for (uint32_t i = 0; i < grid; ++i) {
            uint64_t key = rng_path_key(seed ^ (CANDIDATE_SEED_SALT + 1), j * grid + i, 0);
            /* over the crop with --crop: the points go where the render looks */
            float fx = (float)cam->crop_x + ((float)i + rng_uniform(key, 0)) / (float)grid * (float)cam->crop_width;
            float fy = (float)cam->crop_y + ((float)j + rng_uniform(key, 1)) / (float)grid * (float)cam->crop_height;
            vec3 o, d;
            camera_generate_ray(cam, fx, fy, &o, &d);
            for (int bounce = 0; bounce < 2; ++bounce) {
                SceneHit sh;
                int hit = scene_intersect1(scene, (SceneRay){o, 0.0f, d, INFINITY}, &sh);
                /* the camera ray's stretch through VDB media: a vertex uniformly in it (kept
                 * with the same probability), so media get points along what the camera sees */
                if (bounce == 0 && media && media->num_vdb > 0 && kept < PILOT_CAP &&
                    rng_uniform(key, 10) < PILOT_KEEP) {
                    MediaView view;
                    media_view(media, 0, o, d, hit ? sh.t : INFINITY, &view);
                    const float of[3] = {o.x, o.y, o.z}, df[3] = {d.x, d.y, d.z};
                    float t0, t1;
                    if (view.count > 0 &&
                        medium_clip_ray(view.media[0], of, df, 0.0f, hit ? sh.t : INFINITY, &t0, &t1) && isfinite(t1)) {
                        if (push(c, v3_madd(o, d, t0 + (t1 - t0) * rng_uniform(key, 11))) != 0) return -1;
                        ++kept;
                    }
                }
                if (!hit) break;
                SurfaceHit h;
                scene_surface_hit(scene, sh.instance, sh.local_prim, sh.triangle, sh.u, sh.v, &h);
                if (rng_uniform(key, 2 + 4 * (uint32_t)bounce) < PILOT_KEEP && kept < PILOT_CAP) {
                    if (push(c, h.p) != 0) return -1;
                    ++kept;
                }
                vec3 ng = v3_dot(h.ng, d) < 0.0f ? h.ng : v3_neg(h.ng);
                Frame f = frame_from_normal(ng);
                vec3 wl = sample_cosine_hemisphere(rng_uniform(key, 3 + 4 * (uint32_t)bounce), rng_uniform(key, 4 + 4 * (uint32_t)bounce));
                o = offset_ray_origin(h.p, ng);
                d = v3_normalize(frame_to_world(&f, wl));
            }
        }
    }
    return 0;
}

/* §3.1.1: candidates in the order of a 63-bit Morton code over the bounds of the finite ones,
 * ties in generation order (a stable sort), so the merge passes walk them coherently. */
static int sort_candidates(Candidates *c) {
    uint32_t n = c->count;
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < n; ++i) {
        const float *p = c->xyz + 3 * (size_t)i;
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2])) continue; /* dropped by the build */
        for (int k = 0; k < 3; ++k) { lo[k] = fminf(lo[k], p[k]); hi[k] = fmaxf(hi[k], p[k]); }
    }
    uint64_t *keys = malloc(((size_t)n + 1) * sizeof *keys), *keys_tmp = malloc(((size_t)n + 1) * sizeof *keys_tmp);
    uint32_t *order = malloc(((size_t)n + 1) * sizeof *order), *order_tmp = malloc(((size_t)n + 1) * sizeof *order_tmp);
    float *sorted = malloc(((size_t)n + 1) * 3 * sizeof *sorted);
    int rc = keys && keys_tmp && order && order_tmp && sorted ? 0 : -1;
    if (rc == 0) {
        for (uint32_t i = 0; i < n; ++i) {
            uint64_t code = 0;
            for (int k = 0; k < 3; ++k) {
                float ext = hi[k] - lo[k];
                float t = ext > 0.0f ? (c->xyz[3 * (size_t)i + k] - lo[k]) / ext : 0.0f;
                code |= morton_spread21((uint64_t)(fminf(fmaxf(t, 0.0f), 1.0f) * 2097151.0f)) << k;
            }
            keys[i] = code;
            order[i] = i;
        }
        radix_sort_pairs(order, keys, n, keys_tmp, order_tmp);
        for (uint32_t i = 0; i < n; ++i) memcpy(sorted + 3 * (size_t)i, c->xyz + 3 * (size_t)order[i], 3 * sizeof(float));
        free(c->xyz);
        c->xyz = sorted;
        c->capacity = n;
        sorted = NULL;
    }
    free(keys); free(keys_tmp); free(order); free(order_tmp); free(sorted);
    return rc;
}

/* ---------------------------------------------------------------- §4.2 scattering weights */

/* mu_s at y (luminance) over the VDB media whose bounds hold y and the mesh medium around it,
 * and the anisotropy of the one that scatters most. */
static float cp_scatter_medium(const void *user, const float y[3], float *g) {
    const CachePointSampler *s = user;
    const SceneMedia *media = s->media;
    float total = 0.0f, best = 0.0f;
    *g = 0.0f;
    for (uint32_t i = 0; i < media->num_vdb; ++i) {
        const Medium *m = &media->vdb[i];
        if (y[0] < m->world_min[0] || y[1] < m->world_min[1] || y[2] < m->world_min[2] || y[0] > m->world_max[0] ||
            y[1] > m->world_max[1] || y[2] > m->world_max[2])
            continue;
        MediumCoefficients c;
        medium_eval(m, y, &c);
        float l = v3_luminance(v3(c.sigma_s[0], c.sigma_s[1], c.sigma_s[2]));
        total += l;
        if (l > best) { best = l; *g = m->g; }
    }
    if (media->num_homogeneous > 0) {
        uint32_t mm = media_at_point(media, v3(y[0], y[1], y[2]));
        if (mm > 0) {
            const Medium *m = &media->homogeneous[mm - 1];
            float l = v3_luminance(v3(m->sigma_s[0], m->sigma_s[1], m->sigma_s[2]));
            total += l;
            if (l > best) *g = m->g;
        }
    }
    return total;
}

/* One light sample at y: phase x radiance / pdf toward the camera, unoccluded (luminance). */
static float cp_scatter_light(const void *user, uint32_t light, const float y[3], float g, const float u[4]) {
    const CachePointSampler *s = user;
    vec3 p = v3(y[0], y[1], y[2]);
    LightSampleContext ctx = {p, v3s(0.0f), {0, 0.0f}, NULL};
    LightLiSample ls;
    if (!light_sample_li(s->lights, &s->lights->lights[light], &ctx, u[0], u[1], u[2], u[3], &ls) || !(ls.pdf > 0.0f))
        return 0.0f;
    vec3 wo = s->camera_ortho ? s->camera_back : v3_normalize(v3_sub(s->camera_pos, p));
    const float wof[3] = {wo.x, wo.y, wo.z}, wif[3] = {ls.wi.x, ls.wi.y, ls.wi.z};
    return hg_phase(g, wof, wif) * v3_luminance(ls.radiance) / ls.pdf;
}

/* The summed weights S_p looked up along every camera ray (up to 65 stations per ray, each a
 * nearest-point query) cost more than the rest of the technique, so they are tabulated once:
 * a grid of SCATTER_GRID^3 cells over the bounds of the points with S_p > 0 (padded by their
 * radii) holding S of the point nearest each cell's centre. A station reads its cell (0
 * outside the grid); the table along a ray is then a deterministic function of the ray, as
 * the technique needs, at a few nanoseconds per station. */
#define SCATTER_GRID 64

typedef struct GridCtx { CachePointSampler *s; } GridCtx;

static void scatter_grid_range(void *vctx, size_t b, size_t e, int thread) {
    (void)thread;
    CachePointSampler *s = ((GridCtx *)vctx)->s;
    const int *dims = s->grid_dims;
    uint32_t hint = UINT32_MAX;
    for (size_t i = b; i < e; ++i) {
        int x = (int)(i % (size_t)dims[0]), y = (int)(i / (size_t)dims[0] % (size_t)dims[1]),
            z = (int)(i / ((size_t)dims[0] * dims[1]));
        const float c[3] = {s->grid_lo.x + (x + 0.5f) * s->grid_cell.x, s->grid_lo.y + (y + 0.5f) * s->grid_cell.y,
                            s->grid_lo.z + (z + 0.5f) * s->grid_cell.z};
        hint = cachepoints_nearest_hint(s->cp, c, hint, NULL);
        s->scatter_grid[i] = cachepoints_scatter_total(s->cp, hint);
    }
}

static int build_scatter_grid(CachePointSampler *s, ThreadPool *pool) {
    vec3 lo = v3s(INFINITY), hi = v3s(-INFINITY);
    uint32_t n = cachepoints_count(s->cp);
    for (uint32_t i = 0; i < n; ++i) {
        if (!(cachepoints_scatter_total(s->cp, i) > 0.0f)) continue;
        float p[3], r;
        cachepoints_point(s->cp, i, p, &r);
        lo = v3_min(lo, v3(p[0] - r, p[1] - r, p[2] - r));
        hi = v3_max(hi, v3(p[0] + r, p[1] + r, p[2] + r));
    }
    if (!(lo.x <= hi.x) || !v3_is_finite(lo) || !v3_is_finite(hi)) return 0; /* nothing scatters: S = 0 */
    vec3 ext = v3_max(v3_sub(hi, lo), v3s(1e-6f));
    for (int k = 0; k < 3; ++k) s->grid_dims[k] = SCATTER_GRID;
    s->grid_lo = lo;
    s->grid_cell = v3_scale(ext, 1.0f / SCATTER_GRID);
    s->grid_step = fminf(s->grid_cell.x, fminf(s->grid_cell.y, s->grid_cell.z));
    size_t cells = (size_t)SCATTER_GRID * SCATTER_GRID * SCATTER_GRID;
    s->scatter_grid = malloc(cells * sizeof(float));
    if (!s->scatter_grid) return -1;
    GridCtx ctx = {s};
    threadpool_parallel_for(pool, cells, 4096, scatter_grid_range, &ctx);
    return 0;
}

static int build_scatter_weights(CachePointSampler *s, const Scene *scene, const SceneMedia *media, ThreadPool *pool,
                                 uint64_t seed) {
    const Camera *cam = &scene->camera;
    s->media = media;
    s->camera_ortho = cam->type != IO_CAMERA_PERSPECTIVE;
    s->camera_pos = xform_point(cam->xform, v3s(0.0f));
    vec3 o, d;
    camera_generate_ray(cam, 0.5f * (float)cam->width, 0.5f * (float)cam->height, &o, &d);
    s->camera_back = v3_neg(d);
    CachePointScatter sc = {.medium = cp_scatter_medium, .light_sample = cp_scatter_light, .user = s,
                            .seed = seed ^ (CANDIDATE_SEED_SALT + 2)};
    int rc = cachepoints_build_scatter(s->cp, &s->view, &sc);
    return rc != 0 ? rc : build_scatter_grid(s, pool);
}

static float cp_inscatter_weight(const void *state, const float x[3], uint32_t *hint, float *radius) {
    (void)hint;
    const CachePointSampler *s = state;
    *radius = s->grid_step;
    if (!s->scatter_grid) return 0.0f;
    int c[3];
    const float lo[3] = {s->grid_lo.x, s->grid_lo.y, s->grid_lo.z}, cell[3] = {s->grid_cell.x, s->grid_cell.y, s->grid_cell.z};
    for (int k = 0; k < 3; ++k) {
        float f = (x[k] - lo[k]) / cell[k];
        if (!(f >= 0.0f && f < (float)s->grid_dims[k])) return 0.0f;
        c[k] = (int)f;
    }
    return s->scatter_grid[(size_t)c[0] + (size_t)s->grid_dims[0] * ((size_t)c[1] + (size_t)s->grid_dims[1] * c[2])];
}

static const LightSamplerOps CACHEPOINT_INSCATTER_OPS;

/* ---------------------------------------------------------------- the protocol */

/* --cachepoint-bsdf: the lobe's axis travels in the token octahedrally encoded in 2 x 16 bits
 * (a step of ~1e-4 rad, below the sharpest lobe's width); prepare weighs the entries with the
 * decoded axis, so the next wave's pmf, which decodes the same bits, sees the same lobe. */
static uint32_t oct_encode(vec3 d) {
    float l1 = fabsf(d.x) + fabsf(d.y) + fabsf(d.z);
    float u = d.x / l1, v = d.y / l1;
    if (d.z < 0.0f) {
        float tu = (1.0f - fabsf(v)) * (u >= 0.0f ? 1.0f : -1.0f), tv = (1.0f - fabsf(u)) * (v >= 0.0f ? 1.0f : -1.0f);
        u = tu;
        v = tv;
    }
    uint32_t qu = (uint32_t)lrintf(clampf(u * 0.5f + 0.5f, 0.0f, 1.0f) * 65535.0f);
    uint32_t qv = (uint32_t)lrintf(clampf(v * 0.5f + 0.5f, 0.0f, 1.0f) * 65535.0f);
    return qu | qv << 16;
}

static void oct_decode(uint32_t e, float a[3]) {
    float u = (float)(e & 0xffffu) / 65535.0f * 2.0f - 1.0f, v = (float)(e >> 16) / 65535.0f * 2.0f - 1.0f;
    float z = 1.0f - fabsf(u) - fabsf(v);
    if (z < 0.0f) {
        float tu = (1.0f - fabsf(v)) * (u >= 0.0f ? 1.0f : -1.0f), tv = (1.0f - fabsf(u)) * (v >= 0.0f ? 1.0f : -1.0f);
        u = tu;
        v = tv;
    }
    float inv = 1.0f / sqrtf(u * u + v * v + z * z);
    a[0] = u * inv; a[1] = v * inv; a[2] = z * inv;
}

/* The lobe of an unlinked vertex with a normal (v prepared for x, n; near_w its near weights or
 * NULL): sets v's lobe fields and returns the axis's code (0 and no lobe when it has none). */
static uint32_t vertex_lobe(const CachePointSampler *s, const LightSampleContext *ctx, const float x[3],
                            const float *np, const float *near_w, CachePointVertex *v) {
    if (!s->bound || !np || ctx->link_class || !(ctx->lobe.weight > 0.0f)) return 0;
    uint32_t code = oct_encode(ctx->lobe.axis);
    float axis[3];
    oct_decode(code, axis);
    cachepoints_vertex_lobe(s->cp, &s->view, x, np, near_w, axis, ctx->lobe.sharpness, ctx->lobe.weight, v);
    return v->lobe_mix > 0.0f ? code : 0;
}

/* The cache point vertex of a context: from its token when prepared, else looked up. */
static void vertex_of(const CachePointSampler *s, const LightSampleContext *ctx, float x[3], float n[3],
                      const float **np, CachePointVertex *v) {
    x[0] = ctx->p.x; x[1] = ctx->p.y; x[2] = ctx->p.z;
    n[0] = ctx->n.x; n[1] = ctx->n.y; n[2] = ctx->n.z;
    *np = v3_is_black(ctx->n) ? NULL : n;
    if (ctx->vertex.word) {
        *v = (CachePointVertex){.point = ctx->vertex.word - 1u, .near_total = ctx->vertex.value};
        if (ctx->vertex.lobe_mix > 0.0f) { /* the lobe prepare followed */
            oct_decode(ctx->vertex.lobe_axis, v->lobe_axis);
            v->lobe_sharpness = ctx->vertex.lobe_sharpness;
            v->lobe_mix = ctx->vertex.lobe_mix;
            v->lobe_total = ctx->vertex.lobe_total;
        }
    } else if (ctx->link_class) cachepoints_vertex_linked(s->cp, &s->view, x, *np, UINT32_MAX, link_of(s, ctx), v, NULL);
    else {
        cachepoints_vertex(s->cp, &s->view, x, *np, UINT32_MAX, v, NULL);
        vertex_lobe(s, ctx, x, *np, NULL, v);
    }
}

static void cp_prepare(const void *state, LightSampleContext *ctx, uint32_t *hint) {
    const CachePointSampler *s = state;
    float x[3] = {ctx->p.x, ctx->p.y, ctx->p.z}, n[3] = {ctx->n.x, ctx->n.y, ctx->n.z};
    CachePointVertex v;
    const CachePointLink *lk = link_of(s, ctx);
    if (lk && ctx->previous.word)
        cachepoints_vertex_reuse_linked(s->cp, &s->view, x, v3_is_black(ctx->n) ? NULL : n, ctx->previous.word - 1u, lk,
                                        &v, ctx->scratch);
    else if (lk)
        cachepoints_vertex_linked(s->cp, &s->view, x, v3_is_black(ctx->n) ? NULL : n, hint ? *hint : UINT32_MAX, lk, &v,
                                  ctx->scratch);
    else if (ctx->previous.word) /* a medium walk's next vertex: keep its point while inside it (§3.3) */
        cachepoints_vertex_reuse(s->cp, &s->view, x, v3_is_black(ctx->n) ? NULL : n, ctx->previous.word - 1u, &v,
                                 ctx->scratch);
    else
        cachepoints_vertex(s->cp, &s->view, x, v3_is_black(ctx->n) ? NULL : n, hint ? *hint : UINT32_MAX, &v,
                           ctx->scratch);
    if (hint) *hint = v.point;
    uint32_t code = vertex_lobe(s, ctx, x, v3_is_black(ctx->n) ? NULL : n, ctx->scratch, &v);
    ctx->vertex = (LightVertex){v.point + 1u, v.near_total};
    if (v.lobe_mix > 0.0f) {
        ctx->vertex.lobe_axis = code;
        ctx->vertex.lobe_sharpness = v.lobe_sharpness;
        ctx->vertex.lobe_mix = v.lobe_mix;
        ctx->vertex.lobe_total = v.lobe_total;
    }
}

static uint32_t cp_select(const void *state, const LightSampleContext *ctx, float u, float u_descend, float *pmf,
                          uint32_t *outcome) {
    const CachePointSampler *s = state;
    float x[3], n[3];
    const float *np;
    CachePointVertex v;
    vertex_of(s, ctx, x, n, &np, &v);
    /* the near weights in the scratch are valid only for the vertex prepare filled them for */
    const float *near_w = ctx->vertex.word ? ctx->scratch : NULL;
    if (ctx->link_class)
        return cachepoints_select_linked(s->cp, &s->view, x, np, &v, near_w, link_of(s, ctx), u, u_descend, pmf, outcome);
    return cachepoints_select(s->cp, &s->view, x, np, &v, near_w, u, u_descend, pmf, outcome);
}

static float cp_pmf(const void *state, const LightSampleContext *ctx, uint32_t light) {
    const CachePointSampler *s = state;
    float x[3], n[3];
    const float *np;
    CachePointVertex v;
    vertex_of(s, ctx, x, n, &np, &v);
    if (ctx->link_class) return cachepoints_pmf_linked(s->cp, &s->view, x, np, &v, link_of(s, ctx), light);
    return cachepoints_pmf(s->cp, &s->view, x, np, &v, light);
}

static void cp_record(void *state, uint32_t outcome, float visibility) {
    cachepoints_record(((CachePointSampler *)state)->cp, outcome, visibility);
}

static void cp_prefetch_outcome(const void *state, uint32_t outcome) {
    cachepoints_prefetch_counters(((const CachePointSampler *)state)->cp, outcome);
}

static int build_scatter_weights(CachePointSampler *s, const Scene *scene, const SceneMedia *media, ThreadPool *pool,
                                 uint64_t seed);

/* After points were inserted: the §4.2 weights and their grid again, over every point. */
static int redo_scatter(CachePointSampler *s) {
    if (!s->inscatter) return 0;
    free(s->scatter_grid);
    s->scatter_grid = NULL;
    CachePointScatter sc = {.medium = cp_scatter_medium, .light_sample = cp_scatter_light, .user = s,
                            .seed = s->seed ^ (CANDIDATE_SEED_SALT + 2)};
    int rc = cachepoints_build_scatter(s->cp, &s->view, &sc);
    return rc != 0 ? rc : build_scatter_grid(s, s->grid_pool);
}

/* Progressive insertion (cachepoints_progress: its rounds' barriers insert points, the others
 * only count), then Eqs. 5-6 and the visibility blur over the (new) points. */
static void cp_barrier(void *state) {
    CachePointSampler *s = state;
    double t0 = clock_seconds(), c0 = clock_cpu_seconds();
    uint32_t inserted = 0;
    if (cachepoints_progress(s->cp, &s->view, &inserted) != 0)
        fprintf(stderr, "candela: warning: out of memory inserting cache points; the render continues without them\n");
    if (inserted && redo_scatter(s) != 0) {
        /* the weights are per point: without them for the new points in-scattering sampling
         * would read missing values, so stop inserting is not enough; S_p = 0 for all is valid */
        fprintf(stderr, "candela: warning: out of memory rebuilding the cache points' scattering weights\n");
    }
    s->insert_seconds += clock_seconds() - t0;
    s->insert_cpu_seconds += clock_cpu_seconds() - c0;
    cachepoints_update_visibility(s->cp);
}

static int cp_save_learned(const void *state, FILE *out) {
    const CachePointSampler *s = state;
    return cachepoints_save_inserted(s->cp, out) | cachepoints_save_learned(s->cp, out);
}
static int cp_load_learned(void *state, FILE *in) {
    CachePointSampler *s = state;
    int rc = cachepoints_load_inserted(s->cp, &s->view, in);
    if (rc == 0 && cachepoints_inserted(s->cp) && redo_scatter(s) != 0) rc = -1;
    return rc != 0 ? rc : cachepoints_load_learned(s->cp, in);
}

/* --aov cachepoint: the colour of the vertex's point, and of the entry it weighs most (a
 * light, or a light-tree cluster in a palette of its own). */
static void cp_aov(const void *state, const LightSampleContext *ctx, vec3 *point_rgb, vec3 *light_rgb) {
    const CachePointSampler *s = state;
    float x[3], n[3];
    const float *np;
    CachePointVertex v;
    vertex_of(s, ctx, x, n, &np, &v);
    *point_rgb = cachepoint_false_colour(v.point, CACHEPOINT_COLOUR_POINT);
    int cluster;
    uint32_t top = cachepoints_top_entry(s->cp, &s->view, x, np, &v, ctx->scratch, &cluster);
    *light_rgb = top == UINT32_MAX ? v3s(0.0f)
                                   : cachepoint_false_colour(top, cluster ? CACHEPOINT_COLOUR_CLUSTER : CACHEPOINT_COLOUR_LIGHT);
}

static int cp_finish(const void *state, char err[CANDELA_ERR_LEN]) {
    const CachePointSampler *s = state;
    return s->dump_path ? cachepoint_write_ply(s->cp, s->dump_path, err) : 0;
}

static void cp_report(const void *state, CandelaStats *st) {
    const CachePointSampler *s = state;
    st->time_cachepoints = s->build_seconds;
    st->cpu_cachepoints = s->build_cpu_seconds;
    st->num_cachepoints = cachepoints_count(s->cp);
    st->cachepoint_candidates = s->stats.candidates;
    st->cachepoint_bytes = s->stats.bytes;
    st->cachepoint_mean_near = s->stats.mean_near;
    st->cachepoint_mean_far = s->stats.mean_far;
    st->cachepoint_mean_clusters = s->stats.mean_far_clusters;
    st->cachepoints_inserted = cachepoints_inserted(s->cp);
    st->time_cachepoint_insertion = s->insert_seconds;
    st->cpu_cachepoint_insertion = s->insert_cpu_seconds;
}

static void cp_destroy(void *state) {
    CachePointSampler *s = state;
    if (!s) return;
    cachepoints_free(s->cp);
    free(s->centroid);
    free(s->infinite);
    light_tree_free(&s->tree);
    free(s->second);
    free(s->leaf_light);
    free(s->light_leaf);
    free(s->scatter_grid);
    light_estimate_table_free(&s->estimates);
    free(s->links);
    free(s->bound);
    free(s);
}

static const LightSamplerOps CACHEPOINT_OPS = {
    .name = "cachepoints", .prepare = cp_prepare, .select = cp_select, .pmf = cp_pmf, .record = cp_record,
    .prefetch_outcome = cp_prefetch_outcome, .barrier = cp_barrier, .save_learned = cp_save_learned,
    .load_learned = cp_load_learned, .report = cp_report, .destroy = cp_destroy, .aov = cp_aov, .finish = cp_finish};
/* with the §4.2 scattering weights (scenes with media, in-scattering sampling not off) */
static const LightSamplerOps CACHEPOINT_INSCATTER_OPS = {
    .name = "cachepoints", .prepare = cp_prepare, .select = cp_select, .pmf = cp_pmf, .record = cp_record,
    .prefetch_outcome = cp_prefetch_outcome, .barrier = cp_barrier, .save_learned = cp_save_learned,
    .load_learned = cp_load_learned, .report = cp_report, .destroy = cp_destroy,
    .inscatter_weight = cp_inscatter_weight, .aov = cp_aov, .finish = cp_finish};

/* ---------------------------------------------------------------- build */

/* --cachepoint-bsdf: every light's bounding sphere around its centroid (CachePointLights.bound):
 * a point or spot light its position (a sphere light its radius); an area light the farthest
 * triangle vertex; a rect or disk its farthest corner; a volume the farthest corner of its
 * bounds; a directional light its direction (toward the light), angular radius 0 (a sun its
 * half-angle); the environment all around. 0 ok, -1 out of memory. */
static int build_bounds(CachePointSampler *s) {
    const Lights *ls = s->lights;
    s->bound = malloc(((size_t)ls->count + 1) * 4 * sizeof(float));
    if (!s->bound) return -1;
    for (uint32_t i = 0; i < ls->count; ++i) {
        const Light *l = &ls->lights[i];
        float *b = s->bound + 4 * (size_t)i;
        vec3 c = v3(s->centroid[3 * i], s->centroid[3 * i + 1], s->centroid[3 * i + 2]);
        float r2 = 0.0f;
        if (l->type == LIGHT_DIRECTIONAL || l->type == LIGHT_ENVIRONMENT) {
            vec3 d = l->type == LIGHT_DIRECTIONAL ? v3_normalize(v3_neg(l->direction)) : v3(0.0f, 0.0f, 1.0f);
            b[0] = d.x; b[1] = d.y; b[2] = d.z;
            b[3] = l->type == LIGHT_DIRECTIONAL ? acosf(clampf(1.0f - l->sun_omc, -1.0f, 1.0f)) /* a sun's half-angle */
                                                : 4.0f; /* >= pi: every direction */
            continue;
        }
        if (l->type == LIGHT_RECT || l->type == LIGHT_DISK) { /* corners (the ellipse lies inside them) */
            r2 = fmaxf(v3_dot(v3_add(l->axis_u, l->axis_v), v3_add(l->axis_u, l->axis_v)),
                       v3_dot(v3_sub(l->axis_u, l->axis_v), v3_sub(l->axis_u, l->axis_v)));
        } else if (l->type == LIGHT_POINT || l->type == LIGHT_SPOT) {
            r2 = l->radius * l->radius; /* a sphere light (0: a point) */
        }
        if (l->type == LIGHT_AREA) {
            for (size_t k = 0; k < 3 * (size_t)l->triangles.n; ++k) {
                const float *v = l->world_vertices + 3 * k;
                { vec3 e = v3_sub(v3(v[0], v[1], v[2]), c); r2 = fmaxf(r2, v3_dot(e, e)); }
            }
        } else if (l->type == LIGHT_VOLUME) {
            for (int k = 0; k < 8; ++k) {
                vec3 q = v3(k & 1 ? l->bounds_max.x : l->bounds_min.x, k & 2 ? l->bounds_max.y : l->bounds_min.y,
                            k & 4 ? l->bounds_max.z : l->bounds_min.z);
                { vec3 e = v3_sub(q, c); r2 = fmaxf(r2, v3_dot(e, e)); }
            }
        }
        b[0] = c.x; b[1] = c.y; b[2] = c.z;
        b[3] = sqrtf(r2);
    }
    return 0;
}

/* Fills s->cp (NULL when fewer than 10 points exist). 0 ok, -1 out of memory, -2 invalid
 * cache point parameters. */
static int build(CachePointSampler *s, const Scene *scene, const SceneMedia *media, ThreadPool *pool,
                 const CandelaOptions *o) {
    const Lights *ls = s->lights;
    s->centroid = malloc((size_t)ls->count * 3 * sizeof(float));
    s->infinite = malloc(ls->count);
    if (!s->centroid || !s->infinite || light_estimate_table_build(&s->estimates, ls) != 0) return -1;
    for (uint32_t i = 0; i < ls->count; ++i) {
        const Light *l = &ls->lights[i];
        vec3 c = l->position;
        if (l->type == LIGHT_AREA) {
            double sum[3] = {0, 0, 0}, wsum = 0.0;
            for (uint32_t t = 0; t < l->triangles.n; ++t) {
                const float *v = l->world_vertices + 9 * (size_t)t;
                double a = l->triangles.func[t];
                for (int k = 0; k < 3; ++k) sum[k] += a * (v[k] + v[3 + k] + v[6 + k]) / 3.0;
                wsum += a;
            }
            c = wsum > 0 ? v3((float)(sum[0] / wsum), (float)(sum[1] / wsum), (float)(sum[2] / wsum))
                         : v3(l->world_vertices[0], l->world_vertices[1], l->world_vertices[2]);
        }
        s->centroid[3 * i] = c.x; s->centroid[3 * i + 1] = c.y; s->centroid[3 * i + 2] = c.z;
        s->infinite[i] = l->type == LIGHT_DIRECTIONAL || l->type == LIGHT_ENVIRONMENT;
    }
    s->view = (CachePointLights){.count = ls->count, .centroid = s->centroid, .infinite = s->infinite,
                                 .estimate7 = cp_estimate7, .estimate = cp_estimate, .user = s, .tree = NULL};
    if (o->cachepoint_bsdf) {
        if (build_bounds(s) != 0) return -1;
        s->view.bound = s->bound;
    }
    if (!o->cachepoint_build_linear && setup_tree_view(s) != 0) return -1;

    Candidates cand = {0};
    uint32_t bbox_count, pilot_grid;
    candidate_counts(scene, o, &bbox_count, &pilot_grid);
    if (bbox_candidates(scene, media, o->seed, bbox_count, &cand) != 0 ||
        pilot_candidates(scene, media, o->seed, pilot_grid, &cand) != 0 ||
        sort_candidates(&cand) != 0) {
        free(cand.xyz);
        return -1;
    }
    const Camera *cam = &scene->camera;
    CachePointCamera cc;
    vec3 cpos = xform_point(cam->xform, v3s(0.0f));
    cc.position[0] = cpos.x; cc.position[1] = cpos.y; cc.position[2] = cpos.z;
    cc.pixel_angle = cam->type == IO_CAMERA_PERSPECTIVE ? 2.0f * cam->tan_half_fov_y / (float)cam->height : 0.0f;
    cc.pixel_size = 2.0f * cam->ymag / (float)cam->height;
    CachePointParams params;
    cachepoints_default_params(&params);
    params.visibility = !o->cachepoint_no_visibility;
    params.retruncate = o->cachepoint_retruncate;
    params.pool_visibility = o->cachepoint_pooling;
    params.build_cut = !o->cachepoint_build_linear;
    if (o->cachepoint_cut_size) params.cut_size = o->cachepoint_cut_size;
    if (o->cachepoint_max_near) params.max_near = o->cachepoint_max_near;
    /* progressive insertion: one round, after the third iteration (4 spp of counters: the
     * visibility rates are reliable enough, most of the render is still to come). Two rounds,
     * after 2 and 4 spp with half the budget each, gave the same MSE on windows at 16 spp
     * (1.001x the one-shot build's either way) for twice the rebuild time. */
    if (o->cachepoint_progressive == 1 || (o->cachepoint_progressive == 0 && CACHEPOINT_PROGRESSIVE_DEFAULT)) {
        params.progressive_rounds = 1;
        params.progressive_first = 3;
        params.progressive_budget = o->cachepoint_progressive_budget > 0.0f ? o->cachepoint_progressive_budget : 0.15f;
    }
    params.parallel_for = pool_parallel_for;
    params.pool = pool;
    if (!o->quiet)
        fprintf(stderr, "candela: building cache points from %u candidates over %u lights (%s build)%s\n", cand.count,
                ls->count, params.build_cut ? "cut" : "linear",
                !params.build_cut && ls->count > 20000 ? "; the linear build visits every light for every point: this will be slow" : "");
    int rc = cachepoints_build(&s->cp, cand.xyz, cand.count, &s->view, &cc, &params, &s->stats);
    free(cand.xyz);
    return rc < 0 ? rc : 0; /* -1 out of memory, -2 invalid parameters */
}

int light_sampler_cachepoints_create(LightSampler *ls, const Lights *lights, const Scene *scene,
                                     const SceneMedia *media, ThreadPool *pool, const CandelaOptions *o,
                                     char err[CANDELA_ERR_LEN]) {
    int rc = 0;
    if (lights->count > 0) {
        double t0 = clock_seconds(), c0 = clock_cpu_seconds();
        CachePointSampler *s = calloc(1, sizeof *s);
        if (!s) goto oom;
        s->lights = lights;
        s->dump_path = o->cachepoint_dump_path;
        const LightLinking *k = lights->link;
        if (k && k->num_classes > 1) { /* light linking: each class's lights (§3.3) */
            s->links = calloc(k->num_classes, sizeof *s->links);
            if (!s->links) { cp_destroy(s); goto oom; }
            for (uint32_t c = 1; c < k->num_classes; ++c)
                s->links[c] = (CachePointLink){k->enabled + (size_t)c * lights->count, k->enabled_lights + k->enabled_off[c],
                                               k->enabled_off[c + 1] - k->enabled_off[c],
                                               k->exclusive_lights + k->exclusive_off[c],
                                               k->exclusive_off[c + 1] - k->exclusive_off[c],
                                               k->disabled_lights + k->disabled_off[c],
                                               k->disabled_off[c + 1] - k->disabled_off[c]};
        }
        int rc_build = build(s, scene, media, pool, o);
        if (rc_build != 0) {
            cp_destroy(s);
            if (rc_build == -1) goto oom;
            snprintf(err, CANDELA_ERR_LEN, "%s: invalid cache point parameters", o->scene_path);
            return -1;
        }
        int inscatter = s->cp && media && media_any(media) && o->volume_inscatter_sampling != 0;
        s->inscatter = inscatter;
        s->seed = o->seed;
        s->grid_pool = pool;
        if (inscatter) {
            int rc_scatter = build_scatter_weights(s, scene, media, pool, o->seed);
            if (rc_scatter != 0) { cp_destroy(s); goto oom; }
        }
        s->build_seconds = clock_seconds() - t0;
        s->build_cpu_seconds = clock_cpu_seconds() - c0;
        if (s->cp && s->bound && cachepoints_prepare_lobes(s->cp, &s->view) != 0) { cp_destroy(s); goto oom; }
        if (s->cp) {
            *ls = (LightSampler){inscatter ? &CACHEPOINT_INSCATTER_OPS : &CACHEPOINT_OPS, s, lights->count};
            ls->uses_lobe = s->bound != NULL; /* --cachepoint-bsdf */
            ls->uses_descend = 1;             /* the far bins' descent */
            return 0;
        }
        cp_destroy(s);
        /* fewer than 10 points: per-vertex optimal selection instead (§3.1.1) */
        fprintf(stderr, "%s: warning: fewer than 10 cache points; using optimal light selection\n", o->scene_path);
    }
    rc = light_sampler_optimal_create(ls, lights, scene, o->optimal_occlusion);
    if (rc == 0) {
        /* no points (no lights, or the fallback): the dump says so with an empty file, now */
        if (o->cachepoint_dump_path && cachepoint_write_ply(NULL, o->cachepoint_dump_path, err) != 0) {
            light_sampler_free(ls);
            return -1;
        }
        return 0;
    }
oom:
    snprintf(err, CANDELA_ERR_LEN, "%s: out of memory building cache points", o->scene_path);
    return -1;
}
