/* renderer/scene/scene.c: IoScene -> Embree scene, camera, materials, textures, environment. */
#include "scene.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MIN_SCENE_RADIUS 1e-3f

/* ---------------------------------------------------------------- textures */

static int wrap_coord(int i, int n, int mode) {
    switch (mode) {
    case 1: /* clamp to edge */
        return i < 0 ? 0 : (i >= n ? n - 1 : i);
    case 2: { /* mirrored repeat */
        int period = 2 * n;
        int m = i % period;
        if (m < 0) m += period;
        return m < n ? m : period - 1 - m;
    }
    default: {
        int m = i % n;
        return m < 0 ? m + n : m;
    }
    }
}

void texture_lookup(const IoImage *image, const IoTextureRef *ref, vec2 uv, float out[4]) {
    /* KHR_texture_transform: uv' = T * R * S * uv */
    float su = uv.x * ref->scale[0], sv = uv.y * ref->scale[1];
    float c = cosf(ref->rotation), s = sinf(ref->rotation);
    float tu = c * su + s * sv + ref->offset[0];
    float tv = -s * su + c * sv + ref->offset[1];
    if (!isfinite(tu) || !isfinite(tv)) { tu = 0.0f; tv = 0.0f; }
    /* glTF: (0,0) is the top-left of the image; texel centres at half-integers. */
    float x = tu * (float)image->width - 0.5f;
    float y = tv * (float)image->height - 0.5f;
    /* keep floorf's argument bounded so the int conversion cannot overflow */
    x = clampf(x, -1e6f, 1e6f);
    y = clampf(y, -1e6f, 1e6f);
    float fx = floorf(x), fy = floorf(y);
    int x0 = (int)fx, y0 = (int)fy;
    float ax = x - fx, ay = y - fy;
    int xs[2] = {wrap_coord(x0, image->width, ref->wrap_s), wrap_coord(x0 + 1, image->width, ref->wrap_s)};
    int ys[2] = {wrap_coord(y0, image->height, ref->wrap_t), wrap_coord(y0 + 1, image->height, ref->wrap_t)};
    float w[4] = {(1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay};
    for (int k = 0; k < 4; ++k) out[k] = 0.0f;
    if (image->rgba8) {
        /* 8-bit texels (4 bytes each instead of 16) become the very floats a float decode of
         * the file holds (io.h, io_texel8_tables) before they are weighted, so the result is
         * bit for bit the float form's */
        const IoTexel8Tables *tables = io_texel8_tables();
        const float *rgb = image->srgb ? tables->srgb : tables->linear;
        for (int j = 0; j < 4; ++j) {
            const uint8_t *c = image->rgba8 + 4 * ((size_t)ys[j >> 1] * (size_t)image->width + (size_t)xs[j & 1]);
            const float t[4] = {rgb[c[0]], rgb[c[1]], rgb[c[2]], tables->linear[c[3]]};
            for (int k = 0; k < 4; ++k) out[k] += w[j] * t[k];
        }
        return;
    }
    for (int j = 0; j < 4; ++j) {
        const float *t = image->rgba + 4 * ((size_t)ys[j >> 1] * (size_t)image->width + (size_t)xs[j & 1]);
        for (int k = 0; k < 4; ++k) out[k] += w[j] * t[k];
    }
}

static int texture_present(const Scene *scene, const IoTextureRef *ref) {
    return ref->image >= 0 && (uint32_t)ref->image < scene->io.num_images &&
           scene->io.images[ref->image].width > 0;
}

/* ---------------------------------------------------------------- geometry */

static vec3 prim_position(const IoPrimitive *p, uint32_t v) {
    return v3(p->positions[3 * v], p->positions[3 * v + 1], p->positions[3 * v + 2]);
}

static vec2 prim_uv(const IoPrimitive *p, uint32_t i0, uint32_t i1, uint32_t i2, float b1, float b2) {
    if (!p->uvs) return (vec2){0.0f, 0.0f};
    float b0 = 1.0f - b1 - b2;
    vec2 r = {b0 * p->uvs[2 * i0] + b1 * p->uvs[2 * i1] + b2 * p->uvs[2 * i2],
              b0 * p->uvs[2 * i0 + 1] + b1 * p->uvs[2 * i1 + 1] + b2 * p->uvs[2 * i2 + 1]};
    return r;
}

static vec3 normal_to_world(const SceneInstance *inst, vec3 n) {
    const float *m = inst->normal_xform;
    return v3(m[0] * n.x + m[1] * n.y + m[2] * n.z, m[3] * n.x + m[4] * n.y + m[5] * n.z,
              m[6] * n.x + m[7] * n.y + m[8] * n.z);
}

void scene_surface_hit(const Scene *scene, uint32_t instance, uint32_t local_prim,
                       uint32_t triangle, float b1, float b2, SurfaceHit *hit) {
    const SceneInstance *inst = &scene->instances[instance];
    const IoMesh *mesh = &scene->io.meshes[inst->mesh];
    uint32_t global = mesh->first_primitive + local_prim;
    const ScenePrimitive *sp = &scene->prims[global];
    const IoPrimitive *p = sp->io;
    uint32_t i0 = p->indices[3 * triangle], i1 = p->indices[3 * triangle + 1], i2 = p->indices[3 * triangle + 2];
    float b0 = 1.0f - b1 - b2;
    vec3 p0 = prim_position(p, i0), p1 = prim_position(p, i1), p2 = prim_position(p, i2);
    vec3 po = v3_add(v3_add(v3_scale(p0, b0), v3_scale(p1, b1)), v3_scale(p2, b2));
    const int moved = !inst->linear_identity; /* else the matrix products below are the identity */
    hit->p = moved ? xform_point(inst->xform, po) : v3_add(po, v3(inst->xform[12], inst->xform[13], inst->xform[14]));
    vec3 e1 = v3_sub(p1, p0), e2 = v3_sub(p2, p0);
    /* world-space winding: glTF flips the front face of mirrored instances (negative
     * determinant), which the cross product of transformed edges gets right */
    vec3 ng = v3_normalize(moved ? v3_cross(xform_vector(inst->xform, e1), xform_vector(inst->xform, e2)) : v3_cross(e1, e2));
    hit->ng = ng;
    vec3 ns = ng;
    if (p->normals) {
        vec3 n0 = v3(p->normals[3 * i0], p->normals[3 * i0 + 1], p->normals[3 * i0 + 2]);
        vec3 n1 = v3(p->normals[3 * i1], p->normals[3 * i1 + 1], p->normals[3 * i1 + 2]);
        vec3 n2 = v3(p->normals[3 * i2], p->normals[3 * i2 + 1], p->normals[3 * i2 + 2]);
        vec3 n = v3_add(v3_add(v3_scale(n0, b0), v3_scale(n1, b1)), v3_scale(n2, b2));
        if (moved) n = normal_to_world(inst, n);
        float len = v3_length(n);
        if (len > 1e-12f && isfinite(len)) {
            ns = v3_scale(n, 1.0f / len);
            if (v3_dot(ns, ng) < 0.0f) ns = v3_neg(ns); /* keep on the winding's side */
        }
    }
    hit->uv = prim_uv(p, i0, i1, i2, b1, b2);
    hit->ns = ns;
    const IoMaterial *mat = sp->material;
    if (!texture_present(scene, &mat->normal_tex)) {
        /* the BSDF is isotropic: any tangent will do, and a branchless basis is cheapest */
        vec3 b;
        onb_from_normal(ns, &hit->dpdu, &b);
    } else {
        /* tangent: from TANGENT if present, else from the UV parameterisation */
        vec3 t = v3(0, 0, 0);
        if (p->tangents) {
            const float *tg = p->tangents;
            vec3 t0 = v3(tg[4 * i0], tg[4 * i0 + 1], tg[4 * i0 + 2]);
            vec3 t1 = v3(tg[4 * i1], tg[4 * i1 + 1], tg[4 * i1 + 2]);
            vec3 t2 = v3(tg[4 * i2], tg[4 * i2 + 1], tg[4 * i2 + 2]);
            t = xform_vector(inst->xform, v3_add(v3_add(v3_scale(t0, b0), v3_scale(t1, b1)), v3_scale(t2, b2)));
        } else if (p->uvs) {
            float du1 = p->uvs[2 * i1] - p->uvs[2 * i0], dv1 = p->uvs[2 * i1 + 1] - p->uvs[2 * i0 + 1];
            float du2 = p->uvs[2 * i2] - p->uvs[2 * i0], dv2 = p->uvs[2 * i2 + 1] - p->uvs[2 * i0 + 1];
            float det = du1 * dv2 - dv1 * du2;
            if (fabsf(det) > 1e-20f)
                t = xform_vector(inst->xform, v3_scale(v3_sub(v3_scale(e1, dv2), v3_scale(e2, dv1)), 1.0f / det));
        }
        t = v3_sub(t, v3_scale(ns, v3_dot(ns, t)));
        float tl = v3_length(t);
        if (!(tl > 1e-12f) || !isfinite(tl)) {
            vec3 b;
            onb_from_normal(ns, &t, &b);
        } else {
            t = v3_scale(t, 1.0f / tl);
        }
        /* bitangent per glTF: cross(normal, tangent) * w, w the tangent's handedness */
        vec3 bt = v3_cross(ns, t);
        if (p->tangents && p->tangents[4 * i0 + 3] < 0.0f) bt = v3_neg(bt);
        hit->dpdu = t;
        /* normal map (tangent space, glTF: +Y of the texture = bitangent) */
        float texel[4];
        texture_lookup(&scene->io.images[mat->normal_tex.image], &mat->normal_tex, hit->uv, texel);
        vec3 tn = v3((2.0f * texel[0] - 1.0f) * mat->normal_scale,
                     (2.0f * texel[1] - 1.0f) * mat->normal_scale, 2.0f * texel[2] - 1.0f);
        vec3 n = v3_add(v3_add(v3_scale(t, tn.x), v3_scale(bt, tn.y)), v3_scale(ns, tn.z));
        float len = v3_length(n);
        if (len > 1e-12f && isfinite(len) && v3_dot(n, ng) > 0.0f) {
            hit->ns = v3_scale(n, 1.0f / len);
            vec3 tt = v3_sub(t, v3_scale(hit->ns, v3_dot(hit->ns, t)));
            float ttl = v3_length(tt);
            if (ttl > 1e-12f) hit->dpdu = v3_scale(tt, 1.0f / ttl);
            else { vec3 b; onb_from_normal(hit->ns, &hit->dpdu, &b); }
        }
    }
    hit->material = sp->material;
    hit->instance = instance;
    hit->local_prim = local_prim;
    hit->global_prim = global;
    hit->triangle = triangle;
}

void scene_material_at(const Scene *scene, const SurfaceHit *hit, MaterialSample *m) {
    const IoMaterial *mat = hit->material;
    vec3 base = v3(mat->base_color[0], mat->base_color[1], mat->base_color[2]);
    float metallic = mat->metallic, roughness = mat->roughness;
    if (texture_present(scene, &mat->base_color_tex)) {
        float t[4];
        texture_lookup(&scene->io.images[mat->base_color_tex.image], &mat->base_color_tex, hit->uv, t);
        base = v3_mul(base, v3(t[0], t[1], t[2]));
    }
    if (texture_present(scene, &mat->metallic_roughness_tex)) {
        float t[4];
        texture_lookup(&scene->io.images[mat->metallic_roughness_tex.image], &mat->metallic_roughness_tex, hit->uv, t);
        roughness *= t[1];
        metallic *= t[2];
    }
    m->bsdf.base_color = v3_min(v3_max(base, v3s(0.0f)), v3s(1.0f));
    m->bsdf.metallic = clampf(metallic, 0.0f, 1.0f);
    m->bsdf.roughness = clampf(roughness, 0.0f, 1.0f);
    m->bsdf.specular = clampf(mat->specular, 0.0f, 1.0f);
    m->bsdf.specular_color = v3(mat->specular_color[0], mat->specular_color[1], mat->specular_color[2]);
    m->bsdf.transmission = clampf(mat->transmission, 0.0f, 1.0f);
    m->bsdf.ior = mat->ior >= 1.0f && isfinite(mat->ior) ? mat->ior : 1.5f;
    float coat = mat->clearcoat, coat_roughness = mat->clearcoat_roughness;
    if (coat > 0.0f && texture_present(scene, &mat->clearcoat_tex)) {
        float t[4];
        texture_lookup(&scene->io.images[mat->clearcoat_tex.image], &mat->clearcoat_tex, hit->uv, t);
        coat *= t[0];
    }
    if (coat > 0.0f && texture_present(scene, &mat->clearcoat_roughness_tex)) {
        float t[4];
        texture_lookup(&scene->io.images[mat->clearcoat_roughness_tex.image], &mat->clearcoat_roughness_tex, hit->uv, t);
        coat_roughness *= t[1];
    }
    m->bsdf.clearcoat = clampf(coat, 0.0f, 1.0f);
    m->bsdf.clearcoat_roughness = clampf(coat_roughness, 0.0f, 1.0f);
    m->bsdf.model = scene->material_model == CANDELA_MATERIAL_MODEL_BLENDER3 ? BSDF_MODEL_BLENDER3 : BSDF_MODEL_GLTF;
    m->bsdf.specular_ext = mat->has_specular_ext != 0;
    m->double_sided = mat->double_sided;
}

const BsdfPrepared *scene_material_prepared(const Scene *scene, const SurfaceHit *hit, MaterialSample *m) {
    const MaterialFixed *f = scene->prims[hit->global_prim].material_fixed;
    if (f) {
        *m = f->sample;
        return &f->prepared;
    }
    scene_material_at(scene, hit, m);
    return NULL;
}

/* Whether a texture read by scene_material_at varies the material over its surface. */
static int material_textured(const Scene *scene, const IoMaterial *mat) {
    return texture_present(scene, &mat->base_color_tex) || texture_present(scene, &mat->metallic_roughness_tex) ||
           (mat->clearcoat > 0.0f && (texture_present(scene, &mat->clearcoat_tex) ||
                                      texture_present(scene, &mat->clearcoat_roughness_tex)));
}

/* The fixed materials' answers (after material_model is set: the BSDF depends on it). */
static int fix_materials(Scene *scene) {
    const IoScene *io = &scene->io;
    free(scene->material_fixed);
    scene->material_fixed = calloc((size_t)io->num_materials + 1, sizeof *scene->material_fixed);
    if (!scene->material_fixed) return -1;
    for (uint32_t i = 0; i < io->num_primitives; ++i) {
        ScenePrimitive *sp = &scene->prims[i];
        sp->material_fixed = NULL;
        if (material_textured(scene, sp->material)) continue;
        size_t k = sp->material == &scene->default_material ? io->num_materials : (size_t)(sp->material - io->materials);
        MaterialFixed *f = &scene->material_fixed[k];
        SurfaceHit h = {.material = sp->material};
        scene_material_at(scene, &h, &f->sample);
        bsdf_prepare(&f->sample.bsdf, &f->prepared);
        sp->material_fixed = f;
    }
    return 0;
}

vec3 scene_emitted_radiance(const Scene *scene, const SurfaceHit *hit, vec3 w) {
    const IoMaterial *mat = hit->material;
    if (mat->emissive[0] <= 0.0f && mat->emissive[1] <= 0.0f && mat->emissive[2] <= 0.0f) return v3s(0.0f);
    if (!mat->double_sided && v3_dot(w, hit->ng) <= 0.0f) return v3s(0.0f);
    vec3 e = v3_scale(v3(mat->emissive[0], mat->emissive[1], mat->emissive[2]), mat->emissive_strength);
    if (texture_present(scene, &mat->emissive_tex)) {
        float t[4];
        texture_lookup(&scene->io.images[mat->emissive_tex.image], &mat->emissive_tex, hit->uv, t);
        e = v3_mul(e, v3(t[0], t[1], t[2]));
    }
    return v3_max(e, v3s(0.0f));
}

/* ---------------------------------------------------------------- environment */

/* Cycles' equirectangular map (direction_to_equirectangular: u = 0.5 - atan2(y, x) / 2pi,
 * v = 1 - acos(z) / pi with v = 1 the top row, in Blender's Z-up axes) written in glTF's axes
 * (x_b = x, y_b = -z, z_b = y): u = 0.5 + atan2(z, x) / 2pi, the image's row from the top
 * acos(y) / pi. +X looks at the image's centre column, -Z (Blender's +Y) at u = 0.25. The
 * rotation is that of Blender's Mapping node (type Point) before the Environment Texture: the
 * lookup direction is Rz(rotation) d, i.e. phi = atan2(z, x) becomes phi - rotation, a shift of
 * u by -rotation / 2pi. */
vec2 scene_env_dir_to_uv(const Scene *scene, vec3 d) {
    float u = atan2f(d.z, d.x) * INV_2PI_F + 0.5f - scene->env_rotation_turns;
    float v = 0.5f - atan2f(d.y, sqrtf(d.x * d.x + d.z * d.z)) * INV_PI_F;
    u -= floorf(u);
    if (u >= 1.0f) u = 0.0f; /* -tiny - floor(-tiny) rounds to 1 */
    return (vec2){u, clampf(v, 0.0f, 1.0f)};
}

vec3 scene_env_uv_to_dir(const Scene *scene, vec2 uv) {
    float phi = (uv.x - 0.5f + scene->env_rotation_turns) * 2.0f * PI_F; /* = atan2(z, x) */
    float elev = (0.5f - uv.y) * PI_F;
    float c = cosf(elev);
    return v3(c * cosf(phi), sinf(elev), c * sinf(phi));
}

vec3 scene_env_radiance(const Scene *scene, vec3 d) {
    if (scene->env.width <= 0) return v3s(0.0f);
    vec2 uv = scene_env_dir_to_uv(scene, d);
    /* piecewise constant, matching the sampling distribution's cells */
    int x = (int)(uv.x * (float)scene->env.width), y = (int)(uv.y * (float)scene->env.height);
    if (x >= scene->env.width) x = scene->env.width - 1;
    if (y >= scene->env.height) y = scene->env.height - 1;
    const float *t = scene->env.rgba + 4 * ((size_t)y * (size_t)scene->env.width + (size_t)x);
    return v3_scale(v3(t[0], t[1], t[2]), scene->env_strength);
}

/* ---------------------------------------------------------------- camera */

void camera_generate_ray(const Camera *c, float fx, float fy, vec3 *org, vec3 *dir) {
    float aspect = (float)c->width / (float)c->height;
    float sx = 2.0f * fx / (float)c->width - 1.0f;   /* -1 left, +1 right */
    float sy = 1.0f - 2.0f * fy / (float)c->height;  /* +1 top */
    if (c->type == IO_CAMERA_ORTHOGRAPHIC) {
        vec3 lo = v3(sx * c->ymag * aspect, sy * c->ymag, 0.0f);
        *org = xform_point(c->xform, lo);
        *dir = v3_normalize(xform_vector(c->xform, v3(0.0f, 0.0f, -1.0f)));
    } else {
        vec3 ld = v3(sx * c->tan_half_fov_y * aspect, sy * c->tan_half_fov_y, -1.0f);
        *org = xform_point(c->xform, v3(0.0f, 0.0f, 0.0f));
        *dir = v3_normalize(xform_vector(c->xform, ld));
    }
}

/* ---------------------------------------------------------------- build */

static void alpha_filter(const struct RTCFilterFunctionNArguments *args) {
    const ScenePrimitive *sp = (const ScenePrimitive *)args->geometryUserPtr;
    const Scene *scene = sp->scene;
    const IoMaterial *mat = sp->material;
    unsigned N = args->N;
    float *hit = (float *)args->hit;
    for (unsigned i = 0; i < N; ++i) {
        if (args->valid[i] != -1) continue;
        float b1 = hit[3 * N + i], b2 = hit[4 * N + i];
        unsigned prim = ((unsigned *)args->hit)[5 * N + i];
        const IoPrimitive *p = sp->io;
        float alpha = mat->base_color[3];
        if (texture_present(scene, &mat->base_color_tex) && p->uvs) {
            uint32_t i0 = p->indices[3 * prim], i1 = p->indices[3 * prim + 1], i2 = p->indices[3 * prim + 2];
            float t[4];
            texture_lookup(&scene->io.images[mat->base_color_tex.image], &mat->base_color_tex,
                           prim_uv(p, i0, i1, i2, b1, b2), t);
            alpha *= t[3];
        }
        if (alpha < mat->alpha_cutoff) args->valid[i] = 0;
    }
}

static void set_error(char err[CANDELA_ERR_LEN], const char *fmt, const char *a, const char *b) {
    snprintf(err, CANDELA_ERR_LEN, fmt, a, b);
}

static void invert_transpose3(const float m[16], float out[9]) {
    /* 3x3 part, column-major in m: a[r][c] = m[c*4 + r] */
    float a00 = m[0], a01 = m[4], a02 = m[8];
    float a10 = m[1], a11 = m[5], a12 = m[9];
    float a20 = m[2], a21 = m[6], a22 = m[10];
    float c00 = a11 * a22 - a12 * a21, c01 = a12 * a20 - a10 * a22, c02 = a10 * a21 - a11 * a20;
    float c10 = a02 * a21 - a01 * a22, c11 = a00 * a22 - a02 * a20, c12 = a01 * a20 - a00 * a21;
    float c20 = a01 * a12 - a02 * a11, c21 = a02 * a10 - a00 * a12, c22 = a00 * a11 - a01 * a10;
    float det = a00 * c00 + a01 * c01 + a02 * c02;
    float inv = fabsf(det) > 1e-30f ? 1.0f / det : 0.0f;
    /* inverse transpose = cofactor matrix / det, row-major */
    float r[9] = {c00, c01, c02, c10, c11, c12, c20, c21, c22};
    for (int i = 0; i < 9; ++i) out[i] = r[i] * inv;
}

/* The instance's object-to-world matrix and what follows from it. */
static void instance_set_xform(SceneInstance *si, const float xform[16]) {
    memcpy(si->xform, xform, sizeof si->xform);
    invert_transpose3(si->xform, si->normal_xform);
    static const float identity3[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}; /* columns 0-2, column-major */
    si->linear_identity = memcmp(si->xform, identity3, sizeof identity3) == 0;
}

static void default_camera(Scene *scene, Camera *cam) {
    /* Frame the bounding sphere from +Z (glTF's "front"), 40 degree vertical field of view. */
    float fov = 40.0f * PI_F / 180.0f;
    float dist = scene->radius / sinf(0.5f * fov) * 1.1f;
    memset(cam->xform, 0, sizeof cam->xform);
    cam->xform[0] = 1.0f; cam->xform[5] = 1.0f; cam->xform[10] = 1.0f; cam->xform[15] = 1.0f;
    cam->xform[12] = scene->center.x;
    cam->xform[13] = scene->center.y;
    cam->xform[14] = scene->center.z + dist;
    cam->type = IO_CAMERA_PERSPECTIVE;
    cam->tan_half_fov_y = tanf(0.5f * fov);
    cam->ymag = cam->xmag = 1.0f;
}

static int setup_camera(Scene *scene, const CandelaOptions *o, char err[CANDELA_ERR_LEN]) {
    Camera *cam = &scene->camera;
    const IoCamera *ic = NULL;
    if (o->camera_name) {
        for (uint32_t i = 0; i < scene->io.num_cameras; ++i)
            if (strcmp(scene->io.cameras[i].name, o->camera_name) == 0) { ic = &scene->io.cameras[i]; break; }
        if (!ic) {
            /* the names it could have been, so a typo is fixed without opening the file */
            char names[256] = "";
            size_t used = 0;
            for (uint32_t i = 0; i < scene->io.num_cameras && used + 1 < sizeof names; ++i) {
                int w = snprintf(names + used, sizeof names - used, "%s'%s'", i ? ", " : "", scene->io.cameras[i].name);
                used = w < 0 ? used : used + (size_t)w;
            }
            if (used >= sizeof names) memcpy(names + sizeof names - 5, "...", 4); /* cut: say so */
            snprintf(err, CANDELA_ERR_LEN, "%.200s: no camera named '%.60s' (%s%s)", o->scene_path, o->camera_name,
                     scene->io.num_cameras ? "the scene's cameras: " : "the scene has no cameras", names);
            return -1;
        }
    } else if (scene->io.num_cameras > 0) {
        ic = &scene->io.cameras[0];
    }
    float aspect = 4.0f / 3.0f;
    if (ic) {
        cam->type = ic->type;
        memcpy(cam->xform, ic->xform, sizeof cam->xform);
        /* remove scale from the camera matrix so directions stay unit and orthographic
         * extents stay as written */
        for (int c = 0; c < 3; ++c) {
            vec3 axis = v3(cam->xform[4 * c], cam->xform[4 * c + 1], cam->xform[4 * c + 2]);
            float l = v3_length(axis);
            if (l > 0.0f) for (int r = 0; r < 3; ++r) cam->xform[4 * c + r] /= l;
        }
        float yfov = ic->yfov > 1e-4f && ic->yfov < PI_F - 1e-4f ? ic->yfov : 0.8f;
        cam->tan_half_fov_y = tanf(0.5f * yfov);
        cam->xmag = ic->xmag > 0.0f ? ic->xmag : 1.0f;
        cam->ymag = ic->ymag > 0.0f ? ic->ymag : 1.0f;
        if (ic->type == IO_CAMERA_PERSPECTIVE && ic->aspect > 0.0f) aspect = ic->aspect;
        if (ic->type == IO_CAMERA_ORTHOGRAPHIC) aspect = cam->xmag / cam->ymag;
    } else {
        default_camera(scene, cam);
    }
    cam->width = o->width;
    cam->height = o->height;
    if (cam->width <= 0 || cam->height <= 0) {
        cam->width = 640;
        int h = (int)lrintf(640.0f / aspect);
        cam->height = h < 1 ? 1 : (h > 16384 ? 16384 : h);
    }
    cam->crop_x = cam->crop_y = 0;
    cam->crop_width = cam->width;
    cam->crop_height = cam->height;
    if (o->crop[2] > 0) {
        if (o->crop[2] > cam->width || o->crop[3] > cam->height || o->crop[0] >= o->crop[2] || o->crop[1] >= o->crop[3] ||
            o->crop[0] < 0 || o->crop[1] < 0) {
            snprintf(err, CANDELA_ERR_LEN, "%.300s: --crop %d,%d,%d,%d reaches outside the %dx%d image (X1 <= %d and Y1 <= %d)",
                     o->scene_path, o->crop[0], o->crop[1], o->crop[2], o->crop[3], cam->width, cam->height, cam->width,
                     cam->height);
            return -1;
        }
        cam->crop_x = o->crop[0];
        cam->crop_y = o->crop[1];
        cam->crop_width = o->crop[2] - o->crop[0];
        cam->crop_height = o->crop[3] - o->crop[1];
    }
    return 0;
}

/* The bounds of the committed top-level scene, its centre and bounding sphere. */
static void scene_bounds(Scene *scene) {
    struct RTCBounds b;
    rtcGetSceneBounds(scene->top, &b);
    if (scene->io.num_instances == 0 || !(b.lower_x <= b.upper_x)) {
        scene->bounds_min = v3s(-1.0f);
        scene->bounds_max = v3s(1.0f);
    } else {
        scene->bounds_min = v3(b.lower_x, b.lower_y, b.lower_z);
        scene->bounds_max = v3(b.upper_x, b.upper_y, b.upper_z);
    }
    scene->center = v3_scale(v3_add(scene->bounds_min, scene->bounds_max), 0.5f);
    scene->radius = fmaxf(0.5f * v3_length(v3_sub(scene->bounds_max, scene->bounds_min)), MIN_SCENE_RADIUS);
}

/* Shadow linking (extras.candela_light_linking.blockers): every distinct blockers list is a
 * mask bit (2..31); an instance a list names lacks its bit, and the shadow rays of the lights
 * of that list carry only that bit (scene_rays.c), so they pass through exactly those
 * instances. *instance_mask stays NULL (every mask at Embree's default) without blockers. */
static int shadow_link_masks(Scene *scene, uint32_t **instance_mask, char err[CANDELA_ERR_LEN]) {
    const IoScene *io = &scene->io;
    uint32_t any = 0;
    for (uint32_t k = 0; k < io->num_light_links; ++k) any |= io->light_links[k].num_blockers;
    if (!any) return 0;
    scene->link_shadow_mask = malloc(io->num_light_links * sizeof *scene->link_shadow_mask);
    *instance_mask = malloc(((size_t)io->num_instances + 1) * sizeof **instance_mask);
    uint32_t *first_of_bit = malloc(30 * sizeof *first_of_bit); /* the link that defined each bit */
    if (!scene->link_shadow_mask || !*instance_mask || !first_of_bit) {
        free(first_of_bit);
        set_error(err, "%.400s: out of memory%s", io->path, "");
        return -1;
    }
    for (uint32_t i = 0; i < io->num_instances; ++i) (*instance_mask)[i] = 0xffffffffu;
    uint32_t bits = 0;
    for (uint32_t k = 0; k < io->num_light_links; ++k) {
        const IoLightLink *l = &io->light_links[k];
        scene->link_shadow_mask[k] = SCENE_MASK_SURFACES;
        if (!l->num_blockers) continue;
        uint32_t bit = bits;
        for (uint32_t b = 0; b < bits && bit == bits; ++b) { /* the same list as an earlier link's */
            const IoLightLink *o = &io->light_links[first_of_bit[b]];
            if (o->num_blockers == l->num_blockers &&
                !memcmp(io->link_instances + o->first_blocker, io->link_instances + l->first_blocker,
                        l->num_blockers * sizeof(uint32_t)))
                bit = b;
        }
        if (bit == bits) {
            if (bits == 30) {
                free(first_of_bit);
                set_error(err, "%.400s: more than 30 distinct blockers lists in extras.candela_light_linking%s",
                          io->path, "");
                return -1;
            }
            first_of_bit[bits++] = k;
            for (uint32_t j = 0; j < l->num_blockers; ++j)
                (*instance_mask)[io->link_instances[l->first_blocker + j]] &= ~(1u << (2 + bit));
        }
        scene->link_shadow_mask[k] = 1u << (2 + bit);
    }
    free(first_of_bit);
    return 0;
}

static void io_phase_done(void *user, int io_phase) {
    phase_mark(user, io_phase == IO_PHASE_PARSED ? CANDELA_PHASE_PARSE : CANDELA_PHASE_FLATTEN);
}

int scene_load(Scene *scene, const CandelaOptions *o, char err[CANDELA_ERR_LEN]) {
    return scene_load_phased(scene, o, NULL, err);
}

int scene_load_phased(Scene *scene, const CandelaOptions *o, ScenePhases *phases, char err[CANDELA_ERR_LEN]) {
    memset(scene, 0, sizeof *scene);
    char ioerr[IO_ERR_LEN];
    IoLoadOptions lo = {.confine_dir = o->confine_dir,
                        .texture_budget_bytes = (uint64_t)o->texture_budget_mb << 20,
                        .volume_budget_bytes = (uint64_t)o->volume_budget_mb << 20,
                        .no_warnings = o->no_warnings,
                        .phase_done = phases ? io_phase_done : NULL,
                        .phase_user = phases};
    if (io_load_gltf_opts(o->scene_path, &lo, &scene->io, ioerr) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
        return -1;
    }
    IoMaterial *dm = &scene->default_material;
    snprintf(dm->name, sizeof dm->name, "default");
    for (int k = 0; k < 4; ++k) dm->base_color[k] = 1.0f;
    dm->metallic = 1.0f; dm->roughness = 1.0f;
    dm->base_color_tex.image = dm->metallic_roughness_tex.image = dm->normal_tex.image = dm->emissive_tex.image = -1;
    dm->clearcoat_tex.image = dm->clearcoat_roughness_tex.image = -1;
    dm->normal_scale = 1.0f; dm->emissive_strength = 1.0f; dm->specular = 1.0f;
    dm->specular_color[0] = dm->specular_color[1] = dm->specular_color[2] = 1.0f;
    dm->ior = 1.5f; dm->alpha_cutoff = 0.5f;

    const IoScene *io = &scene->io;
    /* primitives x instances index the per-instance light and medium tables in 32 bits:
     * refuse a scene that would overflow them (README "Limits") */
    uint64_t instance_primitives = 0;
    for (uint32_t i = 0; i < io->num_instances; ++i)
        instance_primitives += io->meshes[io->instances[i].mesh].num_primitives;
    if (instance_primitives > SCENE_MAX_INSTANCE_PRIMITIVES) {
        char what[64];
        snprintf(what, sizeof what, "%llu", (unsigned long long)instance_primitives);
        set_error(err, "%s: too many instanced primitives (%s; the limit is 2^31 - 1)", o->scene_path, what);
        scene_free(scene);
        return -1;
    }
    scene->prims = calloc(io->num_primitives ? io->num_primitives : 1, sizeof *scene->prims);
    scene->instances = calloc(io->num_instances ? io->num_instances : 1, sizeof *scene->instances);
    scene->mesh_scenes = calloc(io->num_meshes ? io->num_meshes : 1, sizeof *scene->mesh_scenes);
    if (!scene->prims || !scene->instances || !scene->mesh_scenes) {
        set_error(err, "%s: out of memory%s", o->scene_path, "");
        scene_free(scene);
        return -1;
    }
    for (uint32_t i = 0; i < io->num_primitives; ++i) {
        ScenePrimitive *sp = &scene->prims[i];
        sp->io = &io->primitives[i];
        int32_t mi = io->primitives[i].material;
        sp->material = (mi >= 0 && (uint32_t)mi < io->num_materials) ? &io->materials[mi] : dm;
        sp->scene = scene;
        sp->alpha_masked = sp->material->alpha_mode != IO_ALPHA_OPAQUE;
        sp->medium_boundary = sp->material->has_medium && !(sp->material->transmission > 0.0f);
    }

    char config[64];
    int threads = o->threads > 0 ? o->threads : 0;
    if (threads > 0) snprintf(config, sizeof config, "threads=%d", threads);
    else config[0] = 0;
    scene->device = rtcNewDevice(config);
    if (!scene->device) {
        set_error(err, "%s: cannot create the Embree device%s", o->scene_path, "");
        scene_free(scene);
        return -1;
    }
    for (uint32_t m = 0; m < io->num_meshes; ++m) {
        RTCScene ms = rtcNewScene(scene->device);
        scene->mesh_scenes[m] = ms;
        const IoMesh *mesh = &io->meshes[m];
        for (uint32_t k = 0; k < mesh->num_primitives; ++k) {
            ScenePrimitive *sp = &scene->prims[mesh->first_primitive + k];
            const IoPrimitive *p = sp->io;
            RTCGeometry g = rtcNewGeometry(scene->device, RTC_GEOMETRY_TYPE_TRIANGLE);
            float *vb = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                3 * sizeof(float), p->num_vertices ? p->num_vertices : 1);
            unsigned *ib = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                   3 * sizeof(unsigned), p->num_triangles);
            if (!vb || (!ib && p->num_triangles)) {
                rtcReleaseGeometry(g);
                set_error(err, "%s: Embree could not allocate geometry buffers%s", o->scene_path, "");
                scene_free(scene);
                return -1;
            }
            memcpy(vb, p->positions, (size_t)p->num_vertices * 3 * sizeof(float));
            if (p->num_triangles) memcpy(ib, p->indices, (size_t)p->num_triangles * 3 * sizeof(unsigned));
            rtcSetGeometryUserData(g, sp);
            rtcSetGeometryMask(g, sp->medium_boundary ? 2u : ~2u); /* scene_rays.c (bits 2..31: shadow linking) */
            if (sp->alpha_masked) {
                rtcSetGeometryIntersectFilterFunction(g, alpha_filter);
                rtcSetGeometryOccludedFilterFunction(g, alpha_filter);
            }
            rtcCommitGeometry(g);
            unsigned id = rtcAttachGeometry(ms, g);
            (void)id; /* == k: geometries are attached in order */
            rtcReleaseGeometry(g);
        }
        rtcCommitScene(ms);
    }
    uint32_t *instance_mask = NULL;
    if (shadow_link_masks(scene, &instance_mask, err) != 0) { scene_free(scene); return -1; }
    scene->top = rtcNewScene(scene->device);
    for (uint32_t i = 0; i < io->num_instances; ++i) {
        SceneInstance *si = &scene->instances[i];
        instance_set_xform(si, io->instances[i].xform);
        si->mesh = io->instances[i].mesh;
        si->primitive_base = scene->num_instance_primitives;
        scene->num_instance_primitives += io->meshes[si->mesh].num_primitives;
        for (uint32_t k = 0; k < io->meshes[si->mesh].num_primitives; ++k)
            scene->num_triangles_total += io->primitives[io->meshes[si->mesh].first_primitive + k].num_triangles;
        RTCGeometry g = rtcNewGeometry(scene->device, RTC_GEOMETRY_TYPE_INSTANCE);
        rtcSetGeometryInstancedScene(g, scene->mesh_scenes[si->mesh]);
        /* a hidden instance (an animated zero scale) is disabled: Embree never sees its
         * singular transform */
        si->hidden = io->instances[i].hidden;
        static const float identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
        rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, si->hidden ? identity : si->xform);
        if (si->hidden) rtcDisableGeometry(g);
        if (instance_mask) rtcSetGeometryMask(g, instance_mask[i]);
        rtcCommitGeometry(g);
        rtcAttachGeometryByID(scene->top, g, i);
        rtcReleaseGeometry(g);
    }
    free(instance_mask);
    rtcCommitScene(scene->top);
    if (rtcGetDeviceError(scene->device) != RTC_ERROR_NONE) {
        set_error(err, "%s: Embree failed to build the scene%s", o->scene_path, "");
        scene_free(scene);
        return -1;
    }
    scene_bounds(scene);

    if (setup_camera(scene, o, err) != 0) { scene_free(scene); return -1; }

    /* --env is read like the scene's own files: inside --confine-to when given (a variant list,
     * which may come with an uploaded scene, must not read elsewhere) */
    if (o->env_path && o->confine_dir && !io_path_inside(o->env_path, o->confine_dir)) {
        set_error(err, "%.300s: --env is outside %.150s (--confine-to)", o->env_path, o->confine_dir);
        scene_free(scene);
        return -1;
    }
    const char *env_path = o->env_path ? o->env_path : (io->env_path[0] ? io->env_path : NULL);
    scene->env_strength = o->env_path ? o->env_strength : io->env_strength;
    scene->light_model = o->light_model;
    scene->material_model = o->material_model;
    if (fix_materials(scene) != 0) {
        set_error(err, "%s: out of memory%s", o->scene_path, "");
        scene_free(scene);
        return -1;
    }
    /* --env-rotation (NaN when not given) wins over the extras' rotation, with or without --env */
    double rotation_deg = isnan(o->env_rotation_deg) ? (double)io->env_rotation_deg : (double)o->env_rotation_deg;
    double turns = rotation_deg / 360.0;
    turns -= floor(turns);
    scene->env_rotation_turns = turns < 1.0 ? (float)turns : 0.0f;
    if (env_path) {
        /* float whatever the file: the environment is summed into the light's sampling
         * distribution and read as float there (lights.c, light_estimates.c) */
        if (io_load_image(env_path, IO_IMAGE_SRGB, &scene->env, ioerr) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
            scene_free(scene);
            return -1;
        }
        if (!(scene->env_strength >= 0.0f) || !isfinite(scene->env_strength)) {
            set_error(err, "%.400s: environment strength must be a finite number >= 0%s", env_path, "");
            scene_free(scene);
            return -1;
        }
        size_t n = (size_t)scene->env.width * (size_t)scene->env.height * 4, bad = 0;
        float largest = 0.0f;
        for (size_t i = 0; i < n; ++i) {
            if (!isfinite(scene->env.rgba[i]) || scene->env.rgba[i] < 0.0f) {
                scene->env.rgba[i] = 0.0f;
                ++bad;
            }
            if (i % 4 != 3) largest = fmaxf(largest, scene->env.rgba[i]);
        }
        /* radiance beyond IO_MAX_EMISSION overflows products in float (a black image, exit 0) */
        if ((double)largest * scene->env_strength > IO_MAX_EMISSION) {
            snprintf(err, CANDELA_ERR_LEN, "%.400s: environment radiance out of range (%g x strength %g; the limit is %g)",
                     env_path, (double)largest, (double)scene->env_strength, IO_MAX_EMISSION);
            scene_free(scene);
            return -1;
        }
        if (bad && !o->quiet && !o->no_warnings)
            fprintf(stderr, "%s: warning: %zu non-finite or negative environment values set to 0\n", env_path, bad);
    }
    if (phases) phase_mark(phases, CANDELA_PHASE_EMBREE);
    return 0;
}

int scene_pose(Scene *scene, const CandelaOptions *o, double seconds, uint32_t *changed_instances,
               char err[CANDELA_ERR_LEN]) {
    char ioerr[IO_ERR_LEN];
    *changed_instances = 0;
    if (io_scene_pose(&scene->io, seconds, ioerr) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
        return -1;
    }
    /* meshes never change (one Embree scene each, built once); only the transforms of the
     * instances that moved are set, and the top-level scene (one entry per instance) rebuilt */
    for (uint32_t i = 0; i < scene->io.num_instances; ++i) {
        SceneInstance *si = &scene->instances[i];
        const IoInstance *ii = &scene->io.instances[i];
        const int moved = !ii->hidden && memcmp(si->xform, ii->xform, sizeof si->xform) != 0;
        if (!moved && si->hidden == ii->hidden) continue;
        RTCGeometry g = rtcGetGeometry(scene->top, i);
        if (moved) {
            instance_set_xform(si, ii->xform);
            rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, si->xform);
            rtcCommitGeometry(g);
        }
        if (si->hidden != ii->hidden) {
            if (ii->hidden) rtcDisableGeometry(g);
            else rtcEnableGeometry(g);
            si->hidden = ii->hidden;
        }
        ++*changed_instances;
    }
    if (*changed_instances) {
        rtcCommitScene(scene->top);
        if (rtcGetDeviceError(scene->device) != RTC_ERROR_NONE) {
            set_error(err, "%s: Embree failed to update the scene%s", o->scene_path, "");
            return -1;
        }
        scene_bounds(scene);
    }
    return setup_camera(scene, o, err);
}

void scene_free(Scene *scene) {
    if (scene->top) rtcReleaseScene(scene->top);
    if (scene->mesh_scenes)
        for (uint32_t m = 0; m < scene->io.num_meshes; ++m)
            if (scene->mesh_scenes[m]) rtcReleaseScene(scene->mesh_scenes[m]);
    if (scene->device) rtcReleaseDevice(scene->device);
    free(scene->mesh_scenes);
    free(scene->prims);
    free(scene->instances);
    free(scene->link_shadow_mask);
    free(scene->material_fixed);
    io_image_free(&scene->env);
    io_scene_free(&scene->io);
    memset(scene, 0, sizeof *scene);
}
