/* io/animation.c: io_scene_pose, the loaded scene re-placed at an animation time.
 *
 * Sampling follows glTF 2.0 Appendix C (interpolation): STEP holds a key until the next one,
 * LINEAR interpolates (rotations by slerp along the shorter arc), CUBICSPLINE is the cubic
 * Hermite spline whose stored tangents are per second, so they are scaled by the key interval.
 * Before the first key a channel gives its first value, after the last its last.
 * Transforms are composed in double exactly as gltf_loader.cpp composes the rest pose (same
 * formulas, same operation order, no FP contraction in ISO C), so a node without channels gets
 * the very floats the loader gave it. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "io.h"

/* The value of channel c at time t: out[0..ncomp). */
static void sample_channel(const IoAnimChannel *c, double t, int ncomp, double out[4]) {
    const float *times = c->times;
    const uint32_t n = c->num_keys;
    const int cubic = c->interpolation == IO_INTERP_CUBICSPLINE;
    const int stride = cubic ? 3 * ncomp : ncomp; /* floats per key */
    const int value_at = cubic ? ncomp : 0;       /* the value within a key (after the in-tangent) */
    if (n == 1 || t <= (double)times[0] || t >= (double)times[n - 1]) {
        uint32_t k = (n == 1 || t <= (double)times[0]) ? 0 : n - 1;
        for (int j = 0; j < ncomp; ++j) out[j] = c->values[(size_t)k * stride + value_at + j];
        return;
    }
    /* the last key at or before t (times strictly increase: validated at load) */
    uint32_t lo = 0, hi = n - 1;
    while (hi - lo > 1) {
        uint32_t mid = lo + (hi - lo) / 2;
        if ((double)times[mid] <= t) lo = mid;
        else hi = mid;
    }
    const float *a = c->values + (size_t)lo * stride, *b = c->values + (size_t)hi * stride;
    const double td = (double)times[hi] - (double)times[lo];
    const double u = (t - (double)times[lo]) / td;
    if (c->interpolation == IO_INTERP_STEP) {
        for (int j = 0; j < ncomp; ++j) out[j] = a[j];
    } else if (!cubic) {
        if (ncomp == 4) { /* slerp (Appendix C): the shorter arc, linear where the keys nearly coincide */
            double d = 0.0;
            for (int j = 0; j < 4; ++j) d += (double)a[j] * (double)b[j];
            const double sign = d < 0.0 ? -1.0 : 1.0, ad = fabs(d);
            double wa = 1.0 - u, wb = u;
            if (ad < 1.0 - 1e-9) {
                const double angle = acos(ad), s = sin(angle);
                wa = sin((1.0 - u) * angle) / s;
                wb = sin(u * angle) / s;
            }
            for (int j = 0; j < 4; ++j) out[j] = wa * (double)a[j] + sign * wb * (double)b[j];
        } else {
            for (int j = 0; j < ncomp; ++j) out[j] = (1.0 - u) * (double)a[j] + u * (double)b[j];
        }
    } else {
        /* key layout: in-tangent, value, out-tangent. p(u) = h00 v_k + h10 td b_k + h01 v_k+1 + h11 td a_k+1 */
        const double u2 = u * u, u3 = u2 * u;
        const double h00 = 2.0 * u3 - 3.0 * u2 + 1.0, h10 = u3 - 2.0 * u2 + u;
        const double h01 = -2.0 * u3 + 3.0 * u2, h11 = u3 - u2;
        for (int j = 0; j < ncomp; ++j)
            out[j] = h00 * (double)a[ncomp + j] + h10 * td * (double)a[2 * ncomp + j] + h01 * (double)b[ncomp + j] +
                     h11 * td * (double)b[j];
    }
    /* a rotation is normalised where it becomes a matrix (trs_matrix, as the loader does) */
}

/* Local matrix from TRS: the loader's formula (gltf_loader.cpp, trs_local). */
static void trs_matrix(const double t[3], const double q_in[4], const double s[3], double m[16]) {
    double q[4] = {q_in[0], q_in[1], q_in[2], q_in[3]};
    double qn = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (qn > 0.0 && isfinite(qn))
        for (int k = 0; k < 4; ++k) q[k] /= qn;
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    const double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w),
                         2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w),
                         2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)};
    memset(m, 0, 16 * sizeof *m);
    m[15] = 1.0;
    for (int c = 0; c < 3; ++c)
        for (int row = 0; row < 3; ++row) m[c * 4 + row] = r[c * 3 + row] * s[c];
    m[12] = t[0];
    m[13] = t[1];
    m[14] = t[2];
}

static void mat_mul(const double a[16], const double b[16], double r[16]) {
    for (int c = 0; c < 4; ++c)
        for (int row = 0; row < 4; ++row) {
            double s = 0.0;
            for (int k = 0; k < 4; ++k) s += a[k * 4 + row] * b[c * 4 + k];
            r[c * 4 + row] = s;
        }
}

static double mat_det3(const double *a) {
    return a[0] * (a[5] * a[10] - a[9] * a[6]) - a[4] * (a[1] * a[10] - a[9] * a[2]) + a[8] * (a[1] * a[6] - a[5] * a[2]);
}

/* What the loader refuses in a world transform (gltf_loader.cpp, flatten_nodes): an entry
 * beyond IO_MAX_COORDINATE or not finite; for a mesh or camera also a singular 3x3 part. */
static const char *transform_problem(const double w[16], int need_invertible) {
    double largest = 0.0;
    int finite = 1;
    for (int e = 0; e < 16; ++e) {
        finite = finite && isfinite(w[e]);
        largest = fmax(largest, fabs(w[e]));
    }
    if (!finite || largest > IO_MAX_COORDINATE) return "transform out of range";
    if (need_invertible && !(fabs(mat_det3(w)) > 1e-30 * fmax(largest * largest * largest, 1e-300)))
        return "singular transform (a zero scale)";
    return NULL;
}

int io_scene_pose(IoScene *scene, double seconds, char err[IO_ERR_LEN]) {
    if (err) err[0] = 0;
    const uint32_t n = scene->num_nodes;
    if (n == 0) return 0;
    /* per node: T, R, S (rest values, overridden by channels) and the world matrix */
    double *trs = malloc((size_t)n * 10 * sizeof *trs);
    double *world = malloc((size_t)n * 16 * sizeof *world);
    if (!trs || !world) {
        free(trs);
        free(world);
        snprintf(err, IO_ERR_LEN, "%.400s: out of memory posing the scene", scene->path);
        return -1;
    }
    for (uint32_t i = 0; i < n; ++i) {
        const IoNode *nd = &scene->nodes[i];
        memcpy(trs + 10 * i, nd->translation, 3 * sizeof(double));
        memcpy(trs + 10 * i + 3, nd->rotation, 4 * sizeof(double));
        memcpy(trs + 10 * i + 7, nd->scale, 3 * sizeof(double));
    }
    for (uint32_t k = 0; k < scene->num_channels; ++k) {
        const IoAnimChannel *c = &scene->channels[k];
        if (c->node < 0 || (uint32_t)c->node >= n) continue;
        double v[4];
        const int ncomp = c->path == IO_ANIM_ROTATION ? 4 : 3;
        sample_channel(c, seconds, ncomp, v);
        const int at = c->path == IO_ANIM_TRANSLATION ? 0 : c->path == IO_ANIM_ROTATION ? 3 : 7;
        for (int j = 0; j < ncomp; ++j) trs[10 * (size_t)c->node + at + j] = v[j];
    }
    for (uint32_t i = 0; i < n; ++i) {
        const IoNode *nd = &scene->nodes[i];
        double local[16];
        if (nd->has_matrix) memcpy(local, nd->matrix, sizeof local);
        else trs_matrix(trs + 10 * i, trs + 10 * i + 3, trs + 10 * i + 7, local);
        if (nd->parent >= 0) {
            mat_mul(world + 16 * (size_t)nd->parent, local, world + 16 * (size_t)i);
        } else {
            static const double identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
            mat_mul(identity, local, world + 16 * (size_t)i);
        }
    }
    free(trs);

    /* the loader's checks, at this time: what a renderer cannot take fails the frame */
    const char *problem = NULL;
    int32_t bad_node = -1;
    for (uint32_t i = 0; i < scene->num_instances && !problem; ++i) {
        IoInstance *inst = &scene->instances[i];
        if (inst->node < 0) continue;
        const double *w = world + 16 * (size_t)inst->node;
        if ((problem = transform_problem(w, 0))) {
            bad_node = inst->node;
        } else if (transform_problem(w, 1)) {
            inst->hidden = 1; /* a zero scale: hidden now, xform keeps the last invertible one */
        } else {
            inst->hidden = 0;
            for (int k = 0; k < 16; ++k) inst->xform[k] = (float)w[k];
        }
    }
    for (uint32_t i = 0; i < scene->num_cameras && !problem; ++i) {
        IoCamera *cam = &scene->cameras[i];
        if (cam->node < 0) continue;
        const double *w = world + 16 * (size_t)cam->node;
        if ((problem = transform_problem(w, 1))) bad_node = cam->node;
        else for (int k = 0; k < 16; ++k) cam->xform[k] = (float)w[k];
    }
    for (uint32_t i = 0; i < scene->num_lights && !problem; ++i) {
        IoLight *l = &scene->lights[i];
        if (l->node < 0) continue;
        const double *w = world + 16 * (size_t)l->node;
        if ((problem = transform_problem(w, 0))) {
            bad_node = l->node;
            break;
        }
        l->position[0] = (float)w[12];
        l->position[1] = (float)w[13];
        l->position[2] = (float)w[14];
        if (l->type == IO_LIGHT_RECT || l->type == IO_LIGHT_DISK) {
            /* an area light's extents follow the node's X and Y axes (io.h, IoLight) */
            for (int c = 0; c < 3; ++c) {
                l->axis_u[c] = (float)(w[c] * 0.5 * l->size[0]);
                l->axis_v[c] = (float)(w[4 + c] * 0.5 * l->size[1]);
            }
        }
        double dir[3] = {-w[8], -w[9], -w[10]};
        double len = sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
        if (len > 0.0 && isfinite(len)) {
            for (int c = 0; c < 3; ++c) l->direction[c] = (float)(dir[c] / len);
        } else {
            l->direction[0] = l->direction[1] = 0.0f;
            l->direction[2] = -1.0f;
        }
    }
    for (uint32_t i = 0; i < scene->num_volumes && !problem; ++i) {
        IoVolume *v = &scene->volumes[i];
        if (v->node < 0) continue;
        const double *w = world + 16 * (size_t)v->node;
        if ((problem = transform_problem(w, 0))) bad_node = v->node;
        else for (int k = 0; k < 16; ++k) v->xform[k] = (float)w[k];
    }
    int rc = 0;
    if (problem) {
        const IoNode *nd = &scene->nodes[bad_node];
        if (snprintf(err, IO_ERR_LEN, "%.380s: at %.6g s: node %d ('%.60s'): %s", scene->path, seconds, nd->gltf_node,
                     nd->name, problem) >= IO_ERR_LEN)
            err[IO_ERR_LEN - 1] = 0; /* cut, still one line */
        rc = -1;
    }
    free(world);
    return rc;
}
