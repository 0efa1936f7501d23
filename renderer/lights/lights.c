/* renderer/lights/lights.c: the light list (built from a loaded scene) and light sampling. */
#include "lights.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "media.h"
#include "rng.h"
#include "scene.h" /* (Embree: the shape lights' BVH) */

/* Luminous efficacy used by Blender's glTF importer in its default ("standard") lighting
 * mode: point/spot W/sr = cd / 683, sun W/m^2 = lux / 683. */
#define BLENDER_LM_PER_W 683.0f

static float finite_or_zero(float x) { return isfinite(x) ? x : 0.0f; }

static int push_light(Lights *ls, uint32_t *cap, const Light *l) {
    if (ls->count == *cap) {
        uint32_t nc = *cap ? *cap * 2 : 16;
        Light *nl = realloc(ls->lights, nc * sizeof *nl);
        if (!nl) return -1;
        ls->lights = nl;
        *cap = nc;
    }
    ls->lights[ls->count++] = *l;
    return 0;
}

/* topology: another instance's inner tree of the same primitive to refit (NULL: build one);
 * shared: the primitive's object-space tree in this instance's frame (NULL: none; then the
 * light gets no tree of its own). */
static int build_area_light(const Scene *scene, uint32_t instance, uint32_t local, const LightTree *topology,
                            const LightSharedTree *shared, Light *l) {
    const SceneInstance *inst = &scene->instances[instance];
    const IoMesh *mesh = &scene->io.meshes[inst->mesh];
    uint32_t global = mesh->first_primitive + local;
    const IoPrimitive *p = scene->prims[global].io;
    memset(l, 0, sizeof *l);
    l->type = LIGHT_AREA;
    l->instance = instance;
    l->local_prim = local;
    l->global_prim = global;
    l->world_vertices = malloc((size_t)p->num_triangles * 9 * sizeof(float) + 1);
    float *areas = malloc(((size_t)p->num_triangles + 1) * sizeof(float));
    if (!l->world_vertices || !areas) { free(l->world_vertices); free(areas); return -1; }
    double total = 0.0;
    for (uint32_t t = 0; t < p->num_triangles; ++t) {
        vec3 w[3];
        for (int k = 0; k < 3; ++k) {
            uint32_t vi = p->indices[3 * t + k];
            w[k] = xform_point(inst->xform, v3(p->positions[3 * vi], p->positions[3 * vi + 1], p->positions[3 * vi + 2]));
            l->world_vertices[9 * t + 3 * k] = w[k].x;
            l->world_vertices[9 * t + 3 * k + 1] = w[k].y;
            l->world_vertices[9 * t + 3 * k + 2] = w[k].z;
        }
        float a = 0.5f * v3_length(v3_cross(v3_sub(w[1], w[0]), v3_sub(w[2], w[0])));
        areas[t] = finite_or_zero(a);
        total += areas[t];
    }
    l->area = (float)total;
    int rc = dist1d_init(&l->triangles, areas, p->num_triangles);
    free(areas);
    if (rc != 0) { free(l->world_vertices); return -1; }
    const IoMaterial *mat = scene->prims[global].material;
    vec3 e = v3_scale(v3(mat->emissive[0], mat->emissive[1], mat->emissive[2]), mat->emissive_strength);
    l->emission = v3_max(e, v3s(0.0f));
    l->two_sided = mat->double_sided ? 1 : 0;
    l->power = PI_F * l->area * fmaxf(v3_luminance(e), 0.0f) * (mat->double_sided ? 2.0f : 1.0f);
    if (shared) {
        l->shared_tree = shared;
        return 0;
    }
    int tr = 1;
    if (topology && l->triangles.n > LIGHT_AREA_TREE_MAX_CDF)
        tr = light_tree_refit_triangles(&l->tri_tree, topology, l->world_vertices, l->triangles.n,
                                        v3_luminance(l->emission), l->two_sided);
    if (tr < 0 || (tr > 0 && light_area_tree_build(l) != 0)) { light_area_free(l); return -1; }
    return 0;
}

/* A rect or disk area light (io.h IoLight, README "Light shapes"): its plane, the dual basis of
 * its half-extent vectors, radiance power / (4 A) x colour over its world area A (Cycles 3.4's
 * convention, measured with Blender 3.4.1: its area light's eval_fac is invarea / 4, so a "watt"
 * of area light emits pi/4 W of flux; a 1 m^2 square of 2 pi W over a plane renders pi/4 of what
 * power / (pi A) would give), and the triangles the
 * estimates' fixed points lie on (2 for a rect, an inscribed fan of 16 for a disk), wound so that
 * their normals are the emission direction. 0 ok, -1 out of memory. */
#define DISK_ESTIMATE_FAN 16
static int build_shape_area(const IoLight *il, Light *l, vec3 color) {
    l->type = il->type == IO_LIGHT_RECT ? LIGHT_RECT : LIGHT_DISK;
    l->axis_u = v3(il->axis_u[0], il->axis_u[1], il->axis_u[2]);
    l->axis_v = v3(il->axis_v[0], il->axis_v[1], il->axis_v[2]);
    vec3 cr = v3_cross(l->axis_u, l->axis_v);
    float len = v3_length(cr);
    if (!(len > 0.0f) || !isfinite(len) || !v3_is_finite(l->axis_u) || !v3_is_finite(l->axis_v)) return 0; /* area 0 */
    vec3 ng = v3_scale(cr, 1.0f / len);
    /* the emitting side is the node's -Z side (its plane normal pointing there) */
    if (v3_dot(ng, l->direction) < 0.0f) ng = v3_neg(ng);
    l->direction = ng;
    /* dual basis: (y - c) . dual_u = a, (y - c) . dual_v = b for y = c + a u + b v in the plane */
    vec3 vn = v3_cross(l->axis_v, ng), nu = v3_cross(ng, l->axis_u);
    l->dual_u = v3_scale(vn, 1.0f / v3_dot(l->axis_u, vn));
    l->dual_v = v3_scale(nu, 1.0f / v3_dot(l->axis_v, nu));
    l->area = l->type == LIGHT_RECT ? 4.0f * len : PI_F * len;
    l->rect_ortho = l->type == LIGHT_RECT &&
                    fabsf(v3_dot(l->axis_u, l->axis_v)) <= 1e-6f * v3_length(l->axis_u) * v3_length(l->axis_v);
    float power = finite_or_zero(il->intensity);
    l->emission = v3_scale(color, power / (4.0f * l->area));
    if (!v3_is_finite(l->emission)) { l->area = 0.0f; return 0; }
    l->power = PI_F * l->area * v3_luminance(l->emission);
    uint32_t nt = l->type == LIGHT_RECT ? 2u : DISK_ESTIMATE_FAN;
    l->world_vertices = malloc((size_t)nt * 9 * sizeof(float));
    float areas[DISK_ESTIMATE_FAN];
    if (!l->world_vertices) return -1;
    vec3 c = l->position, u = l->axis_u, v = l->axis_v;
    for (uint32_t t = 0; t < nt; ++t) {
        vec3 w[3];
        if (l->type == LIGHT_RECT) {
            vec3 p00 = v3_sub(v3_sub(c, u), v), p10 = v3_sub(v3_add(c, u), v), p11 = v3_add(v3_add(c, u), v),
                 p01 = v3_add(v3_sub(c, u), v);
            w[0] = p00; w[1] = t ? p11 : p10; w[2] = t ? p01 : p11;
        } else {
            float a0 = 2.0f * PI_F * (float)t / (float)nt, a1 = 2.0f * PI_F * (float)(t + 1) / (float)nt;
            w[0] = c;
            w[1] = v3_add(c, v3_add(v3_scale(u, cosf(a0)), v3_scale(v, sinf(a0))));
            w[2] = v3_add(c, v3_add(v3_scale(u, cosf(a1)), v3_scale(v, sinf(a1))));
        }
        vec3 n = v3_cross(v3_sub(w[1], w[0]), v3_sub(w[2], w[0]));
        if (v3_dot(n, ng) < 0.0f) { vec3 tmp = w[1]; w[1] = w[2]; w[2] = tmp; }
        for (int k = 0; k < 3; ++k) {
            l->world_vertices[9 * t + 3 * k] = w[k].x;
            l->world_vertices[9 * t + 3 * k + 1] = w[k].y;
            l->world_vertices[9 * t + 3 * k + 2] = w[k].z;
        }
        areas[t] = 0.5f * v3_length(n);
    }
    if (dist1d_init(&l->triangles, areas, nt) != 0) { free(l->world_vertices); l->world_vertices = NULL; return -1; }
    return 0;
}

int light_area_tree_build(Light *l) {
    memset(&l->tri_tree, 0, sizeof l->tri_tree);
    if (l->type != LIGHT_AREA || l->triangles.n <= LIGHT_AREA_TREE_MAX_CDF || !l->world_vertices) return 0;
    return light_tree_build_triangles(&l->tri_tree, l->world_vertices, l->triangles.n, v3_luminance(l->emission),
                                      l->two_sided);
}

void light_area_free(Light *l) {
    dist1d_free(&l->triangles);
    free(l->world_vertices);
    l->world_vertices = NULL;
    light_tree_free(&l->tri_tree);
}

static float env_average_luminance(const Scene *scene) {
    const IoImage *im = &scene->env;
    double sum = 0.0, wsum = 0.0;
    for (int y = 0; y < im->height; ++y) {
        double w = sin(PI_F * ((double)y + 0.5) / (double)im->height);
        for (int x = 0; x < im->width; ++x) {
            const float *t = im->rgba + 4 * ((size_t)y * (size_t)im->width + (size_t)x);
            sum += w * v3_luminance(v3(t[0], t[1], t[2]));
            wsum += w;
        }
    }
    return wsum > 0.0 ? (float)(sum / wsum) * scene->env_strength : 0.0f;
}

/* ---------------------------------------------------------------- the shape lights' BVH */

typedef struct ShapeBvh {
    RTCScene scene;
    const Light *lights;
    uint32_t *prim_light; /* primitive -> light index */
} ShapeBvh;

/* A query: Embree's context first (the intersection callback gets it back), then the ray as the
 * caller gave it (light_shape_hit sees exactly the floats the linear path would) and the crossings
 * found, up to SHAPE_QUERY_MAX (more: the caller falls back to the list). */
#define SHAPE_QUERY_MAX 64
typedef struct ShapeQuery {
    struct RTCIntersectContext ctx;
    const ShapeBvh *bvh;
    vec3 o, d, receiver;
    float tmin, tmax;
    uint32_t n, overflow;
    uint32_t light[SHAPE_QUERY_MAX];
    float t[SHAPE_QUERY_MAX];
    vec3 radiance[SHAPE_QUERY_MAX];
} ShapeQuery;

static void shape_box(const Light *l, vec3 *lo, vec3 *hi) {
    vec3 ext = v3s(l->radius);
    if (l->type == LIGHT_RECT || l->type == LIGHT_DISK) /* |u_i| + |v_i| covers both */
        ext = v3(fabsf(l->axis_u.x) + fabsf(l->axis_v.x), fabsf(l->axis_u.y) + fabsf(l->axis_v.y),
                 fabsf(l->axis_u.z) + fabsf(l->axis_v.z));
    /* a little wider: the box is only a filter, light_shape_hit decides */
    ext = v3_add(v3_scale(ext, 1.0f + 1e-4f), v3s(1e-6f * (fabsf(l->position.x) + fabsf(l->position.y) + fabsf(l->position.z))));
    *lo = v3_sub(l->position, ext);
    *hi = v3_add(l->position, ext);
}

static void shape_bounds_fn(const struct RTCBoundsFunctionArguments *args) {
    const ShapeBvh *b = args->geometryUserPtr;
    vec3 lo, hi;
    shape_box(&b->lights[b->prim_light[args->primID]], &lo, &hi);
    args->bounds_o->lower_x = lo.x; args->bounds_o->lower_y = lo.y; args->bounds_o->lower_z = lo.z;
    args->bounds_o->upper_x = hi.x; args->bounds_o->upper_y = hi.y; args->bounds_o->upper_z = hi.z;
}

static void shape_intersect_fn(const struct RTCIntersectFunctionNArguments *args) {
    if (!args->valid[0]) return;
    ShapeQuery *q = (ShapeQuery *)args->context;
    uint32_t light = q->bvh->prim_light[args->primID];
    float t;
    vec3 le;
    if (!light_shape_hit(&q->bvh->lights[light], q->o, q->d, q->tmin, q->tmax, q->receiver, &t, &le)) return;
    if (q->n == SHAPE_QUERY_MAX) { q->overflow = 1; return; }
    q->light[q->n] = light;
    q->t[q->n] = t;
    q->radiance[q->n] = le;
    ++q->n;
    /* no hit reported: the traversal goes on to every other crossing */
}

static void shape_occluded_fn(const struct RTCOccludedFunctionNArguments *args) { (void)args; }

static void shape_bvh_free(void *p) {
    ShapeBvh *b = p;
    if (!b) return;
    if (b->scene) rtcReleaseScene(b->scene);
    free(b->prim_light);
    free(b);
}

/* 0 ok, -1 out of memory. */
static int shape_bvh_build(Lights *ls, const Scene *scene) {
    ShapeBvh *b = calloc(1, sizeof *b);
    if (!b) return -1;
    uint32_t n = ls->num_shapes - ls->num_suns, k = 0;
    b->prim_light = malloc(n * sizeof *b->prim_light);
    if (!b->prim_light) { free(b); return -1; }
    for (uint32_t i = 0; i < ls->num_shapes; ++i)
        if (ls->lights[ls->shapes[i]].type != LIGHT_DIRECTIONAL) b->prim_light[k++] = ls->shapes[i];
    b->lights = ls->lights;
    b->scene = rtcNewScene(scene->device);
    RTCGeometry g = rtcNewGeometry(scene->device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(g, n);
    rtcSetGeometryUserData(g, b);
    rtcSetGeometryBoundsFunction(g, shape_bounds_fn, NULL);
    rtcSetGeometryIntersectFunction(g, shape_intersect_fn);
    rtcSetGeometryOccludedFunction(g, shape_occluded_fn);
    rtcCommitGeometry(g);
    rtcAttachGeometry(b->scene, g);
    rtcReleaseGeometry(g);
    rtcCommitScene(b->scene);
    ls->shape_bvh = b;
    return 0;
}

void lights_shape_crossings(const Lights *ls, vec3 o, vec3 d, float tmin, float tmax, vec3 receiver,
                            void (*fn)(void *user, uint32_t light, float t, vec3 radiance), void *user) {
    const ShapeBvh *b = ls->shape_bvh;
    float t;
    vec3 le;
    if (b) {
        ShapeQuery q;
        rtcInitIntersectContext(&q.ctx);
        q.bvh = b;
        q.o = o; q.d = d; q.receiver = receiver;
        q.tmin = tmin; q.tmax = tmax;
        q.n = q.overflow = 0;
        struct RTCRayHit rh;
        rh.ray.org_x = o.x; rh.ray.org_y = o.y; rh.ray.org_z = o.z;
        rh.ray.dir_x = d.x; rh.ray.dir_y = d.y; rh.ray.dir_z = d.z;
        rh.ray.tnear = fmaxf(tmin, 0.0f);
        rh.ray.tfar = isinf(tmax) ? INFINITY : tmax * (1.0f + 1e-5f) + 1e-6f;
        rh.ray.time = 0.0f;
        rh.ray.mask = 0xFFFFFFFFu;
        rh.ray.id = 0;
        rh.ray.flags = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(b->scene, &q.ctx, &rh);
        if (!q.overflow) {
            /* the suns (escaping rays), then everything in light order */
            for (uint32_t k = 0; k < ls->num_suns && isinf(tmax); ++k)
                if (light_shape_hit(&ls->lights[ls->suns[k]], o, d, tmin, tmax, receiver, &t, &le)) {
                    if (q.n == SHAPE_QUERY_MAX) { q.overflow = 1; break; }
                    q.light[q.n] = ls->suns[k]; q.t[q.n] = t; q.radiance[q.n] = le; ++q.n;
                }
        }
        if (!q.overflow) {
            for (uint32_t i = 1; i < q.n; ++i) /* insertion sort by light index */
                for (uint32_t j = i; j > 0 && q.light[j - 1] > q.light[j]; --j) {
                    uint32_t tl = q.light[j]; q.light[j] = q.light[j - 1]; q.light[j - 1] = tl;
                    float tt = q.t[j]; q.t[j] = q.t[j - 1]; q.t[j - 1] = tt;
                    vec3 tr = q.radiance[j]; q.radiance[j] = q.radiance[j - 1]; q.radiance[j - 1] = tr;
                }
            for (uint32_t k = 0; k < q.n; ++k) fn(user, q.light[k], q.t[k], q.radiance[k]);
            return;
        }
    }
    /* the list, in light order (few shapes, or more crossings than a query holds) */
    for (uint32_t k = 0; k < ls->num_shapes; ++k)
        if (light_shape_hit(&ls->lights[ls->shapes[k]], o, d, tmin, tmax, receiver, &t, &le)) fn(user, ls->shapes[k], t, le);
}

int light_shared_tree_frame(const float m[16], LightSharedTree *f) {
    vec3 c[3] = {v3(m[0], m[1], m[2]), v3(m[4], m[5], m[6]), v3(m[8], m[9], m[10])};
    float l2[3] = {v3_dot(c[0], c[0]), v3_dot(c[1], c[1]), v3_dot(c[2], c[2])};
    float lo = minf(l2[0], minf(l2[1], l2[2])), hi = maxf(l2[0], maxf(l2[1], l2[2]));
    /* a rotation times a scale: orthogonal columns (to rounding: a glTF TRS in floats), a
     * positive determinant, and lengths within LIGHT_SHARED_TREE_MAX_STRETCH of each other */
    const float tol = 1e-5f;
    if (!(lo > 0.0f) || !isfinite(hi) || hi > LIGHT_SHARED_TREE_MAX_STRETCH * LIGHT_SHARED_TREE_MAX_STRETCH * lo ||
        fabsf(v3_dot(c[0], c[1])) > tol * sqrtf(l2[0] * l2[1]) || fabsf(v3_dot(c[0], c[2])) > tol * sqrtf(l2[0] * l2[2]) ||
        fabsf(v3_dot(c[1], c[2])) > tol * sqrtf(l2[1] * l2[2]) || !(v3_dot(c[0], v3_cross(c[1], c[2])) > 0.0f))
        return 0;
    f->tree = NULL;
    f->origin = v3(m[12], m[13], m[14]);
    for (int k = 0; k < 3; ++k) {
        f->row[k] = v3_scale(c[k], 1.0f / l2[k]); /* M^-1 = diag(1 / s) R^T */
        f->col[k] = c[k];                         /* M^T takes the normals */
    }
    return v3_is_finite(f->origin) && v3_is_finite(f->row[0]) && v3_is_finite(f->row[1]) && v3_is_finite(f->row[2]);
}

/* The object-space inner tree of an emissive primitive, built on its first instance that may
 * share it (light_shared_tree_frame).
 * 0 ok (also when it already exists, or when no triangle emits: node_count 0), -1 out of
 * memory. */
static int object_tree_build(LightTree *t, const ScenePrimitive *sp) {
    if (t->node_count || t->light_count) return 0; /* built (light_count: tried, nothing emits) */
    const IoPrimitive *p = sp->io;
    float *v = malloc((size_t)p->num_triangles * 9 * sizeof(float));
    if (!v) return -1;
    for (uint32_t k = 0; k < 3 * p->num_triangles; ++k)
        memcpy(v + 3 * (size_t)k, p->positions + 3 * (size_t)p->indices[k], 3 * sizeof(float));
    const IoMaterial *mat = sp->material;
    vec3 e = v3_scale(v3(mat->emissive[0], mat->emissive[1], mat->emissive[2]), mat->emissive_strength);
    int rc = light_tree_build_triangles(t, v, p->num_triangles, v3_luminance(v3_max(e, v3s(0.0f))),
                                        mat->double_sided ? 1 : 0);
    free(v);
    if (rc == 0 && !t->node_count) t->light_count = p->num_triangles;
    return rc;
}

int lights_build(Lights *ls, const Scene *scene, const SceneMedia *media, CandelaLightUnits units, char *err,
                 size_t err_len) {
    memset(ls, 0, sizeof *ls);
    int32_t *link_of_node = NULL;
    ls->environment = -1;
    ls->scene = scene;
    ls->media = media;
    uint32_t cap = 0;
    ls->of_primitive = malloc(((size_t)scene->num_instance_primitives + 1) * sizeof *ls->of_primitive);
    if (!ls->of_primitive) goto oom;
    for (uint32_t i = 0; i < scene->num_instance_primitives; ++i) ls->of_primitive[i] = -1;
    /* light linking: the link of each node (extras.candela_light_linking) */
    if (scene->io.num_light_links) {
        link_of_node = malloc(scene->io.num_nodes * sizeof *link_of_node);
        if (!link_of_node) goto oom;
        for (uint32_t k = 0; k < scene->io.num_nodes; ++k) link_of_node[k] = -1;
        for (uint32_t k = 0; k < scene->io.num_light_links; ++k) link_of_node[scene->io.light_links[k].node] = (int32_t)k;
    }
    float scale = units == CANDELA_LIGHT_UNITS_BLENDER ? 1.0f / BLENDER_LM_PER_W : 1.0f;
    float r = scene->radius;
    for (uint32_t i = 0; i < scene->io.num_lights; ++i) {
        const IoLight *il = &scene->io.lights[i];
        Light l;
        memset(&l, 0, sizeof l);
        vec3 color = v3(finite_or_zero(il->color[0]), finite_or_zero(il->color[1]), finite_or_zero(il->color[2]));
        float intensity = finite_or_zero(il->intensity) * scale;
        l.intensity = v3_max(v3_scale(color, intensity), v3s(0.0f));
        l.position = v3(il->position[0], il->position[1], il->position[2]);
        l.direction = v3_normalize(v3(il->direction[0], il->direction[1], il->direction[2]));
        if (!v3_is_finite(l.position) || !v3_is_finite(l.direction)) {
            fprintf(stderr, "candela: warning: light '%s' has a non-finite position or direction; ignored\n",
                    il->name);
            continue;
        }
        float lum = v3_luminance(l.intensity);
        l.link = link_of_node && il->node >= 0 ? link_of_node[il->node] : -1;
        if (il->type == IO_LIGHT_RECT || il->type == IO_LIGHT_DISK) {
            /* an area light: power in Blender's watts, whatever the light units */
            vec3 c = v3_max(color, v3s(0.0f));
            if (build_shape_area(il, &l, c) != 0) goto oom;
            if (!(l.area > 0.0f) || !isfinite(l.area)) {
                light_area_free(&l);
                fprintf(stderr, "candela: warning: area light '%s' has no area; ignored\n", il->name);
                continue;
            }
            if (push_light(ls, &cap, &l) != 0) { light_area_free(&l); goto oom; }
            continue;
        }
        /* a sphere of radius r with the point light's intensity I in every direction (far field):
         * radiance I / (pi r^2), the same power (Cycles' point light radius keeps the power) */
        float radius = il->type != IO_LIGHT_DIRECTIONAL ? finite_or_zero(il->radius) : 0.0f;
        if (radius > 0.0f) {
            l.radius = radius;
            /* Cycles 3.4 (point_light_sample, ray_aligned_disk_intersect): a disk facing the
             * shading point; Blender 4 made it the sphere that is the default here */
            l.sphere_disk = scene->light_model == CANDELA_LIGHT_MODEL_BLENDER3;
            l.emission = v3_scale(l.intensity, 1.0f / (PI_F * radius * radius));
            if (!v3_is_finite(l.emission)) { l.radius = 0.0f; l.emission = v3s(0.0f); }
        }
        float angle = il->type == IO_LIGHT_DIRECTIONAL ? finite_or_zero(il->angle) : 0.0f;
        if (angle > 0.0f && angle < PI_F) {
            /* a sun of angular diameter `angle`: uniform radiance over the cone of half-angle h,
             * E = L * pi sin^2 h on a perpendicular plane (solid angle 2 pi (1 - cos h) times the
             * mean cosine (1 + cos h) / 2), E the glTF irradiance */
            double h = 0.5 * (double)angle, sh = sin(0.5 * h);
            l.sun_omc = (float)(2.0 * sh * sh); /* 1 - cos h without cancellation */
            double s2 = sin(h) * sin(h);
            l.emission = v3_scale(l.intensity, (float)(1.0 / (PI_F * s2)));
            /* Cycles 3.4 samples a sun as a disk of radius tan h at unit distance with eval_fac =
             * pdf, so its perpendicular irradiance is the strength times the mean cosine of that
             * disk's directions, 2 cos h / (1 + cos h) (measured with Blender 3.4.1: 0.99233 at
             * 20 degrees); --light-model blender3 keeps that (uniform radiance: the same irradiance
             * on any plane that sees the whole cone) */
            if (scene->light_model == CANDELA_LIGHT_MODEL_BLENDER3) {
                double ch = cos(h);
                l.emission = v3_scale(l.emission, (float)(2.0 * ch / (1.0 + ch)));
            }
        }
        switch (il->type) {
        case IO_LIGHT_POINT:
            l.type = LIGHT_POINT;
            l.power = 4.0f * PI_F * lum;
            break;
        case IO_LIGHT_SPOT: {
            l.type = LIGHT_SPOT;
            float outer = clampf(finite_or_zero(il->outer_cone_angle), 0.0f, 0.5f * PI_F);
            float inner = clampf(finite_or_zero(il->inner_cone_angle), 0.0f, outer);
            l.cos_outer = cosf(outer);
            l.cos_inner = cosf(inner);
            l.power = 2.0f * PI_F * (1.0f - 0.5f * (l.cos_inner + l.cos_outer)) * lum;
            if (scene->light_model == CANDELA_LIGHT_MODEL_BLENDER3) {
                /* Blender's glTF exporter writes outer = spot_size / 2 and inner = outer (1 -
                 * spot_blend) (its importer inverts that), so blend = 1 - inner / outer; Cycles 3.4
                 * smooths over (1 - cos_outer) blend in cos and keeps a cos factor (light_spot_falloff) */
                float blend = outer > 0.0f ? 1.0f - inner / outer : 0.0f;
                float w = (1.0f - l.cos_outer) * blend, co = l.cos_outer;
                l.spot_cycles = 1;
                l.spot_smooth = w;
                /* 2 pi int_co^1 falloff dc: c over [co + w, 1]; (co + t) smoothstep(t / w) over [0, w],
                 * whose integral is w (co / 2 + 0.35 w) */
                l.power = 2.0f * PI_F * (0.5f * (1.0f - (co + w) * (co + w)) + w * (0.5f * co + 0.35f * w)) * lum;
            }
            break;
        }
        default:
            l.type = LIGHT_DIRECTIONAL;
            l.power = PI_F * r * r * lum;
            break;
        }
        if (push_light(ls, &cap, &l) != 0) goto oom;
    }
    /* Per primitive: the light whose inner tree later instances of it refit (UINT32_MAX: none
     * yet). The split search runs once per distinct emissive primitive, not once per instance:
     * in object space, for the instances placed by a rotation and a mild scale, which share
     * that tree (LightSharedTree); the others refit its splits, or the first of them builds. */
    uint32_t *tree_of_prim = NULL;
    if (scene->io.num_primitives) {
        tree_of_prim = malloc(scene->io.num_primitives * sizeof *tree_of_prim);
        ls->object_trees = calloc(scene->io.num_primitives, sizeof *ls->object_trees);
        ls->shared_trees = calloc((size_t)scene->num_instance_primitives + 1, sizeof *ls->shared_trees);
        if (!tree_of_prim || !ls->object_trees || !ls->shared_trees) { free(tree_of_prim); goto oom; }
        for (uint32_t k = 0; k < scene->io.num_primitives; ++k) tree_of_prim[k] = UINT32_MAX;
    }
    for (uint32_t i = 0; i < scene->io.num_instances; ++i) {
        const SceneInstance *inst = &scene->instances[i];
        const IoMesh *mesh = &scene->io.meshes[inst->mesh];
        if (inst->hidden) continue; /* a zero scale in this frame of an animation */
        for (uint32_t k = 0; k < mesh->num_primitives; ++k) {
            const ScenePrimitive *sp = &scene->prims[mesh->first_primitive + k];
            const float *e = sp->material->emissive;
            if (!(e[0] > 0.0f || e[1] > 0.0f || e[2] > 0.0f) || !(sp->material->emissive_strength > 0.0f) ||
                sp->io->num_triangles == 0)
                continue;
            Light l;
            uint32_t g = mesh->first_primitive + k, from = tree_of_prim[g];
            LightSharedTree *shared = &ls->shared_trees[inst->primitive_base + k];
            if (sp->io->num_triangles > LIGHT_AREA_TREE_MAX_CDF && light_shared_tree_frame(inst->xform, shared)) {
                if (object_tree_build(&ls->object_trees[g], sp) != 0) { free(tree_of_prim); goto oom; }
                shared->tree = ls->object_trees[g].node_count ? &ls->object_trees[g] : NULL;
            }
            const LightTree *topology = ls->object_trees[g].node_count ? &ls->object_trees[g]
                                        : from != UINT32_MAX       ? &ls->lights[from].tri_tree
                                                                   : NULL;
            if (build_area_light(scene, i, k, topology, shared->tree ? shared : NULL, &l) != 0) {
                free(tree_of_prim);
                goto oom;
            }
            if (!(l.area > 0.0f)) { light_area_free(&l); continue; }
            if (from == UINT32_MAX && l.tri_tree.node_count) tree_of_prim[g] = ls->count;
            l.link = link_of_node && scene->io.instances[i].node >= 0 ? link_of_node[scene->io.instances[i].node] : -1;
            ls->of_primitive[inst->primitive_base + k] = (int32_t)ls->count;
            if (push_light(ls, &cap, &l) != 0) { light_area_free(&l); free(tree_of_prim); goto oom; }
        }
    }
    free(tree_of_prim);
    /* emissive volumes (§4.3): one light each, sampled in proportion to their emission energy */
    if (media && media->num_vdb > 0) {
        ls->of_medium = malloc(media->num_vdb * sizeof *ls->of_medium);
        if (!ls->of_medium) goto oom;
        for (uint32_t i = 0; i < media->num_vdb; ++i) {
            ls->of_medium[i] = -1;
            const Medium *m = &media->vdb[i];
            float intensity = medium_emission_power(m); /* integral of lum(sigma_a L_e): W/sr */
            if (!m->emissive || !(intensity > 0.0f) || !isfinite(intensity)) continue;
            Light l;
            memset(&l, 0, sizeof l);
            l.type = LIGHT_VOLUME;
            l.link = -1;
            l.medium = i;
            float c[3];
            medium_emission_centroid(m, c);
            l.position = v3(c[0], c[1], c[2]);
            l.intensity = v3s(intensity);
            l.power = 4.0f * PI_F * intensity;
            l.medium_mesh = media_at_point(media, l.position);
            l.bounds_min = v3(m->world_min[0], m->world_min[1], m->world_min[2]);
            l.bounds_max = v3(m->world_max[0], m->world_max[1], m->world_max[2]);
            ls->of_medium[i] = (int32_t)ls->count;
            if (push_light(ls, &cap, &l) != 0) goto oom;
        }
    }
    if (scene->env.width > 0) {
        const IoImage *im = &scene->env;
        float *f = malloc((size_t)im->width * (size_t)im->height * sizeof(float));
        if (!f) goto oom;
        for (int y = 0; y < im->height; ++y) {
            float s = sinf(PI_F * ((float)y + 0.5f) / (float)im->height);
            for (int x = 0; x < im->width; ++x) {
                const float *t = im->rgba + 4 * ((size_t)y * (size_t)im->width + (size_t)x);
                /* max component rather than luminance: no colour is ever left unsampled */
                f[(size_t)y * (size_t)im->width + (size_t)x] = v3_max_component(v3(t[0], t[1], t[2])) * s;
            }
        }
        int rc = dist2d_init(&ls->env_distribution, f, (uint32_t)im->width, (uint32_t)im->height);
        free(f);
        if (rc != 0) goto oom;
        Light l;
        memset(&l, 0, sizeof l);
        l.type = LIGHT_ENVIRONMENT;
        l.link = -1;
        l.power = 4.0f * PI_F * PI_F * r * r * env_average_luminance(scene);
        ls->environment = (int32_t)ls->count;
        if (push_light(ls, &cap, &l) != 0) goto oom;
    }
    if (ls->environment >= 0) light_env_estimates(scene, ls->env_estimate);
    for (uint32_t i = 0; i < ls->count; ++i) ls->num_shapes += light_is_shape(&ls->lights[i]) ? 1u : 0u;
    if (ls->num_shapes) {
        ls->shapes = malloc(ls->num_shapes * sizeof *ls->shapes);
        ls->suns = malloc(ls->num_shapes * sizeof *ls->suns);
        if (!ls->shapes || !ls->suns) goto oom;
        uint32_t k = 0;
        for (uint32_t i = 0; i < ls->count; ++i) {
            if (!light_is_shape(&ls->lights[i])) continue;
            ls->shapes[k++] = i;
            if (ls->lights[i].type == LIGHT_DIRECTIONAL) ls->suns[ls->num_suns++] = i;
        }
        if (ls->num_shapes - ls->num_suns > LIGHT_SHAPE_BVH_MIN && shape_bvh_build(ls, scene) != 0) goto oom;
    }
    free(link_of_node);
    if (lights_build_linking(ls, scene, err, err_len) != 0) { lights_free(ls); return -1; }
    return 0;
oom:
    free(link_of_node);
    snprintf(err, err_len, "out of memory while building the light list");
    lights_free(ls);
    return -1;
}

void lights_free(Lights *ls) {
    for (uint32_t i = 0; i < ls->count; ++i) {
        if (light_is_areal(&ls->lights[i])) light_area_free(&ls->lights[i]);
    }
    free(ls->lights);
    free(ls->shapes);
    free(ls->suns);
    shape_bvh_free(ls->shape_bvh);
    if (ls->environment >= 0) dist2d_free(&ls->env_distribution);
    free(ls->of_primitive);
    free(ls->of_medium);
    if (ls->object_trees && ls->scene)
        for (uint32_t k = 0; k < ls->scene->io.num_primitives; ++k) light_tree_free(&ls->object_trees[k]);
    free(ls->object_trees);
    free(ls->shared_trees);
    lights_free_linking(ls);
    memset(ls, 0, sizeof *ls);
    ls->environment = -1;
}

int32_t lights_of_primitive(const Lights *ls, uint32_t instance, uint32_t local_prim) {
    return ls->of_primitive[ls->scene->instances[instance].primitive_base + local_prim];
}

float light_spot_falloff(const Light *l, vec3 w) {
    float c = v3_dot(w, l->direction);
    if (l->spot_cycles) {
        /* Cycles 3.4 (kernel light spot_light_attenuation, checked against Blender 3.4.1's
         * render of tests/scenes/spot_blend_plane.gltf): 0 outside the cone, then smoothstep
         * over spot_smooth in cos, and the cosine itself throughout */
        float t = c - l->cos_outer;
        if (!(t > 0.0f)) return 0.0f;
        if (t < l->spot_smooth) {
            float x = t / l->spot_smooth;
            return c * x * x * (3.0f - 2.0f * x);
        }
        return c;
    }
    float t = l->cos_inner > l->cos_outer ? (c - l->cos_outer) / (l->cos_inner - l->cos_outer)
                                          : (c >= l->cos_outer ? 1.0f : 0.0f);
    t = clampf(t, 0.0f, 1.0f);
    return t * t;
}

/* ---------------------------------------------------------------- sampling */

/* Not inlined: sampling and the pdfs must take the same branch, with the same frame, for the
 * same context. */
__attribute__((noinline)) const LightTree *light_area_tree(const Light *l, const LightSampleContext *ctx,
                                                           LightSampleContext *local) {
    const LightTree *t = &l->tri_tree;
    const LightSharedTree *f = l->shared_tree;
    if (f) { /* into the shared tree's object space */
        vec3 d = v3_sub(ctx->p, f->origin), n = ctx->n;
        vec3 po = v3(v3_dot(f->row[0], d), v3_dot(f->row[1], d), v3_dot(f->row[2], d));
        vec3 no = v3(v3_dot(f->col[0], n), v3_dot(f->col[1], n), v3_dot(f->col[2], n));
        float nl = v3_length(no);
        no = nl > 0.0f ? v3_scale(no, 1.0f / nl) : v3s(0.0f); /* (a medium point keeps n = 0) */
        *local = light_sample_context(po, no, NULL, NULL, 0u);
        t = f->tree;
    } else {
        *local = light_sample_context(ctx->p, ctx->n, NULL, NULL, 0u);
    }
    return t->node_count > 0 && light_tree_node_importance(&t->nodes[0], local->p, local->n) > 0.0f ? t : NULL;
}

/* Area density of a point on triangle t picked with probability tri_pmf (tree) or by area. */
static inline float area_density(const Light *l, int tree, uint32_t t, float tri_pmf) {
    if (!tree) return 1.0f / l->area; /* area CDF then uniform on the triangle: 1/A overall */
    float a = l->triangles.func[t];   /* the triangle's area */
    return a > 0.0f ? tri_pmf / a : 0.0f;
}

/* Solid angle from area density at y (normal ny) seen from p. */
static inline float area_to_solid_angle(float pdf_area, vec3 p, vec3 y, vec3 ny) {
    vec3 d = v3_sub(y, p);
    float d2 = v3_dot(d, d);
    float cos_l = fabsf(v3_dot(ny, d)) / sqrtf(d2);
    if (!(cos_l > 0.0f) || !(pdf_area > 0.0f)) return 0.0f;
    return pdf_area * d2 / cos_l;
}

float light_area_triangle_pmf(const Light *l, const LightSampleContext *ctx, uint32_t triangle) {
    if (l->type != LIGHT_AREA || triangle >= l->triangles.n || !(l->area > 0.0f)) return 0.0f;
    LightSampleContext local;
    const LightTree *tree = light_area_tree(l, ctx, &local);
    return tree ? light_tree_pmf(tree, &local, triangle) : dist1d_pmf(&l->triangles, triangle);
}

float light_area_pdf_li(const Light *l, const LightSampleContext *ctx, uint32_t triangle, vec3 y, vec3 ny) {
    if (l->type != LIGHT_AREA || triangle >= l->triangles.n || !(l->area > 0.0f)) return 0.0f;
    LightSampleContext local;
    const LightTree *tree = light_area_tree(l, ctx, &local);
    float tri_pmf = tree ? light_tree_pmf(tree, &local, triangle) : 0.0f;
    return area_to_solid_angle(area_density(l, tree != NULL, triangle, tri_pmf), ctx->p, y, ny);
}

float light_volume_pdf_li(const Lights *ls, const Light *l, vec3 p, vec3 d) {
    if (l->type != LIGHT_VOLUME || !ls->media) return 0.0f;
    const float o[3] = {p.x, p.y, p.z}, w[3] = {d.x, d.y, d.z};
    return medium_emission_pdf(&ls->media->vdb[l->medium], o, w);
}

float light_env_pdf_li(const Lights *ls, vec3 d) {
    if (ls->environment < 0) return 0.0f;
    vec2 uv = scene_env_dir_to_uv(ls->scene, d);
    float sin_theta = sqrtf(fmaxf(0.0f, 1.0f - d.y * d.y));
    if (!(sin_theta > 0.0f)) return 0.0f;
    return dist2d_pdf(&ls->env_distribution, uv) / (2.0f * PI_F * PI_F * sin_theta);
}

/* ---------------------------------------------------------------- light shapes */

/* The cone a sphere subtends from p (pbrt-v4 Sphere::Sample(ctx), "Sampling Spheres"): sin^2 and
 * 1 - cos of its half-angle, the latter from sin^2 / 2 below 1.5 degrees where 1 - cos loses its
 * digits (sampling and light_shape_pdf_li both use this). 0 when p is inside the sphere. */
static int sphere_cone(const Light *l, vec3 p, float *sin2_max, float *omc_max) {
    vec3 d = v3_sub(l->position, p);
    float dc2 = v3_dot(d, d), r2 = l->radius * l->radius;
    if (!(dc2 > r2)) return 0;
    float s2 = r2 / dc2;
    *sin2_max = s2;
    *omc_max = s2 < 0.00068523f ? 0.5f * s2 : 1.0f - safe_sqrtf(1.0f - s2);
    return 1;
}

/* A sphere light's radiance towards receiver p: a spot's falloff on the direction from the
 * centre (Cycles evaluates the cone from the light's centre). */
static vec3 sphere_radiance(const Light *l, vec3 p) {
    if (l->type != LIGHT_SPOT) return l->emission;
    vec3 w = v3_sub(p, l->position);
    float len = v3_length(w);
    if (!(len > 0.0f)) return v3s(0.0f);
    return v3_scale(l->emission, light_spot_falloff(l, v3_scale(w, 1.0f / len)));
}

/* A unit vector at angle theta from axis z (cos_t, sin_t given), azimuth 2 pi u. */
static vec3 cone_dir(vec3 z, float cos_t, float sin_t, float u) {
    vec3 t, b;
    onb_from_normal(z, &t, &b);
    float phi = 2.0f * PI_F * u;
    return v3_add(v3_scale(z, cos_t), v3_add(v3_scale(t, sin_t * cosf(phi)), v3_scale(b, sin_t * sinf(phi))));
}

/* --light-model blender3's point radius: a disk of radius r centred at the light, facing the
 * receiver p, sampled by area with the concentric map (Cycles 3.4's disk_light_sample). */
/* The direction and distance from p to the light point y into s (wi, distance); returns the
 * squared distance, 0 (nothing written that matters) when y is p. */
static inline float li_toward(vec3 p, vec3 y, LightLiSample *s) {
    vec3 d = v3_sub(y, p);
    float d2 = v3_dot(d, d);
    if (!(d2 > 0.0f)) return 0.0f;
    float dist = sqrtf(d2);
    s->wi = v3_scale(d, 1.0f / dist);
    s->distance = dist;
    return d2;
}

static int sample_facing_disk(const Light *l, vec3 p, float u0, float u1, LightLiSample *s) {
    vec3 to = v3_sub(p, l->position);
    float dc = v3_length(to);
    if (!(dc > 0.0f)) return 0;
    vec3 nd = v3_scale(to, 1.0f / dc), t, b;
    onb_from_normal(nd, &t, &b);
    vec2 q = sample_concentric_disk(u0, u1);
    vec3 y = v3_add(l->position, v3_scale(v3_add(v3_scale(t, q.x), v3_scale(b, q.y)), l->radius));
    float d2 = li_toward(p, y, s);
    if (!(d2 > 0.0f)) return 0;
    float cos_l = -v3_dot(s->wi, nd);
    if (!(cos_l > 0.0f)) return 0;
    s->pdf = d2 / (cos_l * PI_F * l->radius * l->radius);
    s->radiance = sphere_radiance(l, p);
    s->is_delta = 0;
    return s->pdf > 0.0f && isfinite(s->pdf) && !v3_is_black(s->radiance);
}

static int sample_sphere(const Light *l, vec3 p, float u0, float u1, LightLiSample *s) {
    if (l->sphere_disk) return sample_facing_disk(l, p, u0, u1, s);
    vec3 c = l->position;
    float r = l->radius;
    float sin2_max, omc_max;
    vec3 y, ny;
    if (!sphere_cone(l, p, &sin2_max, &omc_max)) {
        /* p inside the sphere: area sampling (the sphere is seen all around, every direction
         * reaching exactly one point: where a ray from p leaves it) */
        ny = sample_uniform_sphere(u0, u1);
        y = v3_madd(c, ny, r);
        float d2 = li_toward(p, y, s);
        if (!(d2 > 0.0f)) return 0;
        float cos_l = fabsf(v3_dot(ny, s->wi));
        s->pdf = cos_l > 0.0f ? d2 / (cos_l * 4.0f * PI_F * r * r) : 0.0f;
    } else {
        /* uniform in the cone of the visible cap; the point on the sphere from the angle alpha
         * at the centre (pbrt-v4: accurate for small cones, where ray-sphere intersection is not) */
        float dc = v3_length(v3_sub(c, p));
        float sin_max = safe_sqrtf(sin2_max);
        float sin2_t, cos_t;
        if (sin2_max < 0.00068523f) {
            sin2_t = sin2_max * u0;
            cos_t = safe_sqrtf(1.0f - sin2_t);
        } else {
            cos_t = 1.0f - u0 * omc_max;
            sin2_t = fmaxf(0.0f, 1.0f - cos_t * cos_t);
        }
        float cos_a = sin2_t / sin_max + cos_t * safe_sqrtf(1.0f - sin2_t / sin2_max);
        float sin_a = safe_sqrtf(1.0f - cos_a * cos_a);
        vec3 z = v3_scale(v3_sub(c, p), 1.0f / dc);
        /* the normal at the point: angle alpha from -z */
        ny = cone_dir(v3_neg(z), cos_a, sin_a, u1);
        y = v3_madd(c, ny, r);
        vec3 d = v3_sub(y, p);
        float dist = v3_length(d);
        if (!(dist > 0.0f)) return 0;
        s->wi = v3_scale(d, 1.0f / dist);
        s->distance = dist;
        s->pdf = 1.0f / (2.0f * PI_F * omc_max);
    }
    s->radiance = sphere_radiance(l, p);
    s->is_delta = 0;
    return s->pdf > 0.0f && isfinite(s->pdf) && !v3_is_black(s->radiance);
}

static int sample_sun(const Light *l, float u0, float u1, LightLiSample *s) {
    /* uniform in the cone: 1 - cos theta = u omc, sin theta from it without cancellation */
    float omc = u0 * l->sun_omc;
    float sin_t = safe_sqrtf(omc * (2.0f - omc));
    s->wi = v3_normalize(cone_dir(v3_neg(l->direction), 1.0f - omc, sin_t, u1));
    s->distance = INFINITY;
    s->radiance = l->emission;
    s->pdf = 1.0f / (2.0f * PI_F * l->sun_omc);
    s->is_delta = 0;
    return isfinite(s->pdf) && !v3_is_black(s->radiance);
}

/* Spherical rectangle sampling (Ureña, Fajardo and King 2013, "An Area-Preserving
 * Parametrization for Spherical Rectangles", §4; as pbrt-v4's SampleSphericalRectangle): the
 * rectangle's frame seen from p, its solid angle, and the point for (u0, u1), uniform in solid
 * angle. Set up in double (the solid angle is a difference of angles near 2 pi). */
typedef struct SphRect {
    double ex[3], ey[3], ez[3]; /* the local frame (x along axis_u, y along axis_v, z towards p's side flipped) */
    double x0, y0, z0, x1, y1;  /* the rectangle's extent in it, relative to p */
    double n0z, n2z, g0, g1, g2, g3;
    double omega;               /* solid angle */
} SphRect;

static double d3dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static void d3cross_unit(const double a[3], const double b[3], double out[3]) {
    double c[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    double len = sqrt(d3dot(c, c));
    for (int k = 0; k < 3; ++k) out[k] = len > 0.0 ? c[k] / len : 0.0;
}
static double angle_between(const double a[3], const double b[3]) { /* of unit vectors, -a and b */
    double dt = -d3dot(a, b);
    return acos(dt < -1.0 ? -1.0 : dt > 1.0 ? 1.0 : dt);
}

static double sph_rect_setup(const Light *l, vec3 p, SphRect *r) {
    double ul = v3_length(l->axis_u), vl = v3_length(l->axis_v);
    for (int k = 0; k < 3; ++k) {
        r->ex[k] = (double)(k == 0 ? l->axis_u.x : k == 1 ? l->axis_u.y : l->axis_u.z) / ul;
        r->ey[k] = (double)(k == 0 ? l->axis_v.x : k == 1 ? l->axis_v.y : l->axis_v.z) / vl;
    }
    r->ez[0] = r->ex[1] * r->ey[2] - r->ex[2] * r->ey[1];
    r->ez[1] = r->ex[2] * r->ey[0] - r->ex[0] * r->ey[2];
    r->ez[2] = r->ex[0] * r->ey[1] - r->ex[1] * r->ey[0];
    /* the corner c - u - v relative to p, in the frame */
    double s[3] = {(double)l->position.x - l->axis_u.x - l->axis_v.x - p.x, (double)l->position.y - l->axis_u.y - l->axis_v.y - p.y,
                   (double)l->position.z - l->axis_u.z - l->axis_v.z - p.z};
    r->x0 = d3dot(s, r->ex);
    r->y0 = d3dot(s, r->ey);
    r->z0 = d3dot(s, r->ez);
    if (r->z0 > 0.0) { for (int k = 0; k < 3; ++k) r->ez[k] = -r->ez[k]; r->z0 = -r->z0; }
    r->x1 = r->x0 + 2.0 * ul;
    r->y1 = r->y0 + 2.0 * vl;
    double v00[3] = {r->x0, r->y0, r->z0}, v01[3] = {r->x0, r->y1, r->z0}, v10[3] = {r->x1, r->y0, r->z0},
           v11[3] = {r->x1, r->y1, r->z0};
    double n0[3], n1[3], n2[3], n3[3];
    d3cross_unit(v00, v10, n0);
    d3cross_unit(v10, v11, n1);
    d3cross_unit(v11, v01, n2);
    d3cross_unit(v01, v00, n3);
    r->g0 = angle_between(n0, n1);
    r->g1 = angle_between(n1, n2);
    r->g2 = angle_between(n2, n3);
    r->g3 = angle_between(n3, n0);
    r->n0z = n0[2];
    r->n2z = n2[2];
    r->omega = r->g0 + r->g1 + r->g2 + r->g3 - 2.0 * 3.14159265358979323846;
    return r->omega;
}

/* Whether the rect is sampled by solid angle from p (pbrt-v4's window: above 3e-4 sr, where
 * the angles still resolve it, below 6.22 sr, where it is nearly a hemisphere and area sampling
 * does as well); sampling and the pdf of a BSDF hit decide with this same function. */
#define SPH_RECT_MIN 3e-4
#define SPH_RECT_MAX 6.22
__attribute__((noinline)) static int rect_spherical(const Light *l, vec3 p, SphRect *r) {
    if (!l->rect_ortho) return 0;
    double omega = sph_rect_setup(l, p, r);
    return omega > SPH_RECT_MIN && omega < SPH_RECT_MAX && r->z0 < 0.0;
}

static vec3 sph_rect_sample(const SphRect *r, vec3 p, float u0, float u1) {
    const double pi = 3.14159265358979323846;
    double au = u0 * (r->g0 + r->g1 - 2.0 * pi) + (u0 - 1.0) * (r->g2 + r->g3);
    double fu = (cos(au) * r->n0z - r->n2z) / sin(au);
    double cu = copysign(1.0 / sqrt(fu * fu + r->n0z * r->n0z), fu);
    cu = cu < -(1.0 - 1e-12) ? -(1.0 - 1e-12) : cu > 1.0 - 1e-12 ? 1.0 - 1e-12 : cu;
    double xu = -(cu * r->z0) / sqrt(fmax(0.0, 1.0 - cu * cu));
    xu = xu < r->x0 ? r->x0 : xu > r->x1 ? r->x1 : xu;
    double dd = sqrt(xu * xu + r->z0 * r->z0);
    double h0 = r->y0 / sqrt(dd * dd + r->y0 * r->y0), h1 = r->y1 / sqrt(dd * dd + r->y1 * r->y1);
    double hv = h0 + u1 * (h1 - h0), hv2 = hv * hv;
    double yv = hv2 < 1.0 - 1e-12 ? hv * dd / sqrt(1.0 - hv2) : r->y1;
    yv = yv < r->y0 ? r->y0 : yv > r->y1 ? r->y1 : yv;
    double q[3];
    for (int k = 0; k < 3; ++k) q[k] = xu * r->ex[k] + yv * r->ey[k] + r->z0 * r->ez[k];
    return v3((float)(p.x + q[0]), (float)(p.y + q[1]), (float)(p.z + q[2]));
}

/* Rects by solid angle where it pays (rect_spherical), else uniformly by area (any parallelogram
 * a sheared node makes); disks by area with the concentric map (an ellipse for x != y); area
 * densities converted to solid angle. */
static int sample_planar(const Light *l, vec3 p, float u0, float u1, LightLiSample *s) {
    float a, b;
    SphRect sr;
    if (l->type == LIGHT_RECT && rect_spherical(l, p, &sr)) {
        vec3 y = sph_rect_sample(&sr, p, u0, u1);
        vec3 d = v3_sub(y, p);
        float dist = v3_length(d);
        if (!(dist > 0.0f)) return 0;
        s->wi = v3_scale(d, 1.0f / dist);
        s->distance = dist;
        if (!(v3_dot(s->wi, l->direction) < 0.0f)) return 0; /* one-sided */
        s->pdf = (float)(1.0 / sr.omega);
        s->radiance = l->emission;
        s->is_delta = 0;
        return s->pdf > 0.0f && isfinite(s->pdf) && !v3_is_black(s->radiance);
    }
    if (l->type == LIGHT_RECT) {
        a = 2.0f * u0 - 1.0f;
        b = 2.0f * u1 - 1.0f;
    } else {
        vec2 q = sample_concentric_disk(u0, u1);
        a = q.x;
        b = q.y;
    }
    vec3 y = v3_add(l->position, v3_add(v3_scale(l->axis_u, a), v3_scale(l->axis_v, b)));
    float d2 = li_toward(p, y, s);
    if (!(d2 > 0.0f)) return 0;
    float cos_l = -v3_dot(s->wi, l->direction); /* one-sided: it emits along direction */
    if (!(cos_l > 0.0f)) return 0;
    s->pdf = d2 / (cos_l * l->area);
    s->radiance = l->emission;
    s->is_delta = 0;
    return s->pdf > 0.0f && isfinite(s->pdf) && !v3_is_black(s->radiance);
}

int light_shape_hit(const Light *l, vec3 o, vec3 d, float tmin, float tmax, vec3 receiver, float *t, vec3 *radiance) {
    switch (l->type) {
    case LIGHT_DIRECTIONAL: {
        if (!isinf(tmax) || isinf(tmin) || !(l->sun_omc > 0.0f)) return 0; /* (tmin infinite: counted) */
        /* inside the cone: sin^2 of the angle to the axis below sin^2 h (no 1 - cos cancellation) */
        vec3 axis = v3_neg(l->direction);
        float c = v3_dot(d, axis);
        if (!(c > 0.0f)) return 0;
        vec3 x = v3_cross(d, axis);
        float s2 = v3_dot(x, x), omc = l->sun_omc;
        if (!(s2 <= omc * (2.0f - omc))) return 0;
        *t = INFINITY;
        *radiance = l->emission;
        return 1;
    }
    case LIGHT_POINT:
    case LIGHT_SPOT: {
        if (!(l->radius > 0.0f)) return 0;
        if (l->sphere_disk) {
            /* the disk facing the receiver (the vertex whose NEE would have sampled it) */
            vec3 nd = v3_sub(receiver, l->position);
            float len = v3_length(nd);
            if (!(len > 0.0f)) return 0;
            nd = v3_scale(nd, 1.0f / len);
            float dn = v3_dot(d, nd);
            if (!(dn < 0.0f)) return 0;
            float th = v3_dot(v3_sub(l->position, o), nd) / dn;
            if (!(th > tmin && th < tmax)) return 0;
            vec3 r = v3_sub(v3_madd(o, d, th), l->position);
            if (!(v3_dot(r, r) <= l->radius * l->radius)) return 0;
            *t = th;
            *radiance = sphere_radiance(l, receiver);
            return !v3_is_black(*radiance);
        }
        /* |o + t d - c|^2 = r^2 with the half-b form on f = o - c, and the far root from the near
         * one's product, as pbrt does to keep digits for small spheres far away */
        vec3 f = v3_sub(o, l->position);
        float b = v3_dot(f, d);
        vec3 perp = v3_sub(f, v3_scale(d, b));
        float r2 = l->radius * l->radius;
        float disc = r2 - v3_dot(perp, perp);
        if (!(disc >= 0.0f)) return 0;
        float sq = sqrtf(disc);
        float q = b > 0.0f ? -(b + sq) : -(b - sq);
        float c0 = v3_dot(f, f) - r2;
        float t0 = q, t1 = q != 0.0f ? c0 / q : 0.0f;
        if (t0 > t1) { float tmp = t0; t0 = t1; t1 = tmp; }
        /* an origin outside sees the entry point, one inside the exit point */
        float th = c0 > 0.0f ? t0 : t1;
        if (!(th > tmin && th < tmax)) return 0;
        *t = th;
        *radiance = sphere_radiance(l, receiver);
        return !v3_is_black(*radiance);
    }
    case LIGHT_RECT:
    case LIGHT_DISK: {
        float dn = v3_dot(d, l->direction);
        if (!(dn < 0.0f)) return 0; /* one-sided: seen only against its emission direction */
        float th = v3_dot(v3_sub(l->position, o), l->direction) / dn;
        if (!(th > tmin && th < tmax)) return 0;
        vec3 r = v3_sub(v3_madd(o, d, th), l->position);
        float a = v3_dot(r, l->dual_u), b = v3_dot(r, l->dual_v);
        int inside = l->type == LIGHT_RECT ? (fabsf(a) <= 1.0f && fabsf(b) <= 1.0f) : (a * a + b * b <= 1.0f);
        if (!inside) return 0;
        *t = th;
        *radiance = l->emission;
        return 1;
    }
    default:
        return 0;
    }
}

float light_shape_pdf_li(const Light *l, vec3 p, vec3 d, float t) {
    switch (l->type) {
    case LIGHT_DIRECTIONAL:
        return l->sun_omc > 0.0f ? 1.0f / (2.0f * PI_F * l->sun_omc) : 0.0f;
    case LIGHT_POINT:
    case LIGHT_SPOT: {
        if (!(l->radius > 0.0f)) return 0.0f;
        if (l->sphere_disk) {
            vec3 nd = v3_normalize(v3_sub(p, l->position));
            float cos_l = -v3_dot(d, nd);
            return cos_l > 0.0f ? t * t / (cos_l * PI_F * l->radius * l->radius) : 0.0f;
        }
        float sin2_max, omc_max;
        if (sphere_cone(l, p, &sin2_max, &omc_max)) return 1.0f / (2.0f * PI_F * omc_max);
        /* inside: area sampling at the exit point */
        vec3 y = v3_madd(p, d, t);
        vec3 ny = v3_normalize(v3_sub(y, l->position));
        float cos_l = fabsf(v3_dot(ny, d));
        return cos_l > 0.0f ? t * t / (cos_l * 4.0f * PI_F * l->radius * l->radius) : 0.0f;
    }
    case LIGHT_RECT:
    case LIGHT_DISK: {
        float cos_l = -v3_dot(d, l->direction);
        if (!(cos_l > 0.0f)) return 0.0f;
        SphRect sr;
        if (l->type == LIGHT_RECT && rect_spherical(l, p, &sr)) return (float)(1.0 / sr.omega);
        return t * t / (cos_l * l->area);
    }
    default:
        return 0.0f;
    }
}

int light_sample_li(const Lights *ls, const Light *l, const LightSampleContext *ctx, float u0, float u1, float u2,
                    float u3, LightLiSample *s) {
    const Scene *scene = ls->scene;
    vec3 p = ctx->p;
    s->triangle = 0;
    if (light_is_shape(l)) {
        if (l->type == LIGHT_DIRECTIONAL) return sample_sun(l, u0, u1, s);
        if (l->type == LIGHT_RECT || l->type == LIGHT_DISK) return sample_planar(l, p, u0, u1, s);
        return sample_sphere(l, p, u0, u1, s);
    }
    switch (l->type) {
    case LIGHT_RECT:
    case LIGHT_DISK:
        return 0; /* no area (not built) */
    case LIGHT_POINT:
    case LIGHT_SPOT: {
        float d2 = li_toward(p, l->position, s);
        if (!(d2 > 0.0f)) return 0;
        vec3 I = l->intensity;
        if (l->type == LIGHT_SPOT) I = v3_scale(I, light_spot_falloff(l, v3_neg(s->wi)));
        s->radiance = v3_scale(I, 1.0f / d2);
        s->pdf = 1.0f;
        s->is_delta = 1;
        return !v3_is_black(s->radiance);
    }
    case LIGHT_DIRECTIONAL:
        s->wi = v3_neg(l->direction);
        s->distance = INFINITY;
        s->radiance = l->intensity;
        s->pdf = 1.0f;
        s->is_delta = 1;
        return !v3_is_black(s->radiance);
    case LIGHT_AREA: {
        if (!(l->area > 0.0f)) return 0;
        float tri_pmf;
        LightSampleContext local;
        const LightTree *tree = light_area_tree(l, ctx, &local);
        uint32_t t = tree ? light_tree_select(tree, &local, u0, &tri_pmf)
                          : dist1d_sample_discrete(&l->triangles, u0, &tri_pmf, NULL);
        if (!(tri_pmf > 0.0f)) return 0;
        float pdf_area = area_density(l, tree != NULL, t, tri_pmf);
        s->triangle = t;
        const float *w = l->world_vertices + 9 * (size_t)t;
        vec3 a = v3(w[0], w[1], w[2]), b = v3(w[3], w[4], w[5]), c = v3(w[6], w[7], w[8]);
        vec2 bc = sample_uniform_triangle(u1, u2);
        vec3 y = v3_add(v3_add(v3_scale(a, 1.0f - bc.x - bc.y), v3_scale(b, bc.x)), v3_scale(c, bc.y));
        float d2 = li_toward(p, y, s);
        if (!(d2 > 0.0f)) return 0;
        /* radiance leaving y towards p */
        const IoMaterial *mat = scene->prims[l->global_prim].material;
        if (mat->emissive_tex.image >= 0) {
            SurfaceHit hit; /* textured emission: evaluate the material at the sampled point */
            scene_surface_hit(scene, l->instance, l->local_prim, t, bc.x, bc.y, &hit);
            s->radiance = scene_emitted_radiance(scene, &hit, v3_neg(s->wi));
            s->pdf = area_to_solid_angle(pdf_area, p, y, hit.ng);
        } else {
            vec3 ng = v3_normalize(v3_cross(v3_sub(b, a), v3_sub(c, a)));
            int front = v3_dot(s->wi, ng) < 0.0f;
            s->radiance = front || mat->double_sided ? l->emission : v3s(0.0f);
            s->pdf = area_to_solid_angle(pdf_area, p, y, ng);
        }
        s->is_delta = 0;
        return s->pdf > 0.0f && isfinite(s->pdf) && !v3_is_black(s->radiance);
    }
    case LIGHT_VOLUME: {
        const SceneMedia *media = ls->media;
        const Medium *m = &media->vdb[l->medium];
        float y[3];
        float pdf_volume = medium_emission_sample(m, u0, u1, u2, u3, y);
        vec3 d = v3_sub(v3(y[0], y[1], y[2]), p);
        float len = v3_length(d);
        if (!(pdf_volume > 0.0f) || !(len > 0.0f)) return 0;
        vec3 wi = v3_scale(d, 1.0f / len);
        const float o[3] = {p.x, p.y, p.z}, w[3] = {wi.x, wi.y, wi.z};
        float t0, t1;
        if (!medium_clip_ray(m, o, w, 0.0f, INFINITY, &t0, &t1)) return 0;
        /* the line ends at the first surface inside the volume's span */
        SceneHit hit;
        if (scene_intersect1(scene, (SceneRay){p, t0, wi, t1}, &hit)) t1 = hit.t;
        /* the line's tracker draws from a sub-stream keyed by this sample's own numbers, which
         * are the path's: deterministic, and independent of them through the hash */
        uint32_t b0, b1, b2, b3;
        memcpy(&b0, &u0, 4); memcpy(&b1, &u1, 4); memcpy(&b2, &u2, 4); memcpy(&b3, &u3, 4);
        RngStream stream = rng_stream(((uint64_t)b0 << 32 | b1) ^ ((uint64_t)b2 << 16 | (uint64_t)b3 << 40), 0,
                                      RNG_STREAM_LIGHT_LINE);
        VolumeRng rng = {rng_stream_next_cb, &stream};
        MediaView view;
        media_view(media, l->medium_mesh, p, wi, t1, &view);
        int emitter = -1;
        for (int k = 0; k < view.count; ++k) if (view.media[k] == m) emitter = k;
        if (emitter < 0) return 0;
        float L[3];
        media_emission_line_at(&view, emitter, o, w, t0, t1, VOLUME_LINE_COARSE, &rng, L, ctx->stats);
        s->wi = wi;
        s->distance = t0; /* the shadow ray: occlusion and other media up to the volume */
        s->radiance = v3(L[0], L[1], L[2]);
        s->pdf = medium_emission_pdf(m, o, w);
        s->is_delta = 0;
        return s->pdf > 0.0f && isfinite(s->pdf) && !v3_is_black(s->radiance) && v3_is_finite(s->radiance);
    }
    case LIGHT_ENVIRONMENT: {
        float pdf_uv;
        vec2 uv = dist2d_sample(&ls->env_distribution, u0, u1, &pdf_uv);
        (void)u2;
        vec3 d = scene_env_uv_to_dir(scene, uv);
        float sin_theta = sinf(uv.y * PI_F);
        if (!(pdf_uv > 0.0f) || !(sin_theta > 0.0f)) return 0;
        s->wi = d;
        s->distance = INFINITY;
        s->radiance = scene_env_radiance(scene, d);
        s->pdf = pdf_uv / (2.0f * PI_F * PI_F * sin_theta);
        s->is_delta = 0;
        return isfinite(s->pdf) && !v3_is_black(s->radiance);
    }
    }
    return 0;
}
