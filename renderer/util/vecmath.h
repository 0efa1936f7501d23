/* renderer/util/vecmath.h (private): small value types and inline math shared by the renderer.
 * Plain structs and static inline functions (yocto-gl style); no allocation. */
#ifndef CANDELA_VECMATH_H
#define CANDELA_VECMATH_H

#include <math.h>
#include <stdint.h>

#define PI_F 3.14159265358979323846f
#define INV_PI_F 0.31830988618379067154f
#define INV_2PI_F 0.15915494309189533577f
#define INV_4PI_F 0.07957747154594766788f

typedef struct { float x, y, z; } vec3;
typedef struct { float x, y; } vec2;

/* min/max as compares: libm's fminf/fmaxf are calls unless -ffinite-math-only. With a NaN
 * in a, both return b, so maxf(x, 0.0f) also maps NaN to 0. */
static inline float maxf(float a, float b) { return a > b ? a : b; }
static inline float minf(float a, float b) { return a < b ? a : b; }
static inline vec3 v3(float x, float y, float z) { vec3 r = {x, y, z}; return r; }
static inline vec3 v3s(float s) { vec3 r = {s, s, s}; return r; }
static inline vec3 v3_add(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline vec3 v3_sub(vec3 a, vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline vec3 v3_mul(vec3 a, vec3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static inline vec3 v3_scale(vec3 a, float s) { return v3(a.x * s, a.y * s, a.z * s); }
static inline vec3 v3_neg(vec3 a) { return v3(-a.x, -a.y, -a.z); }
static inline vec3 v3_madd(vec3 a, vec3 b, float s) { return v3(a.x + b.x * s, a.y + b.y * s, a.z + b.z * s); }
static inline float v3_dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline vec3 v3_cross(vec3 a, vec3 b) {
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline float v3_length(vec3 a) { return sqrtf(v3_dot(a, a)); }
static inline vec3 v3_normalize(vec3 a) {
    float l = v3_length(a);
    return l > 0.0f ? v3_scale(a, 1.0f / l) : v3(0.0f, 0.0f, 1.0f);
}
/* A vector already unit up to rounding (a unit vector through an orthonormal frame) made unit
 * again by one Newton step of 1/sqrt(d) about 1, (3 - d) / 2: its error is (d - 1)^2, far below
 * a float's, with no square root or division on a bounce's critical path; anything further
 * from unit length takes v3_normalize. */
static inline vec3 v3_renormalize(vec3 a) {
    float d = v3_dot(a, a);
    if (!(fabsf(d - 1.0f) < 1e-3f)) return v3_normalize(a);
    return v3_scale(a, 1.5f - 0.5f * d);
}
static inline vec3 v3_lerp(vec3 a, vec3 b, float t) { return v3_add(v3_scale(a, 1.0f - t), v3_scale(b, t)); }
static inline float v3_max_component(vec3 a) { return maxf(a.x, maxf(a.y, a.z)); }
static inline vec3 v3_min(vec3 a, vec3 b) { return v3(minf(a.x, b.x), minf(a.y, b.y), minf(a.z, b.z)); }
static inline vec3 v3_max(vec3 a, vec3 b) { return v3(maxf(a.x, b.x), maxf(a.y, b.y), maxf(a.z, b.z)); }
static inline int v3_is_black(vec3 a) { return a.x == 0.0f && a.y == 0.0f && a.z == 0.0f; }
static inline int v3_is_finite(vec3 a) { return isfinite(a.x) && isfinite(a.y) && isfinite(a.z); }
/* Rec.709 luminance, used for light power and Russian roulette. */
static inline float v3_luminance(vec3 a) { return 0.2126f * a.x + 0.7152f * a.y + 0.0722f * a.z; }
static inline float v3_average(vec3 a) { return (a.x + a.y + a.z) * (1.0f / 3.0f); }
static inline float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }
static inline float sqr(float x) { return x * x; }
static inline float safe_sqrtf(float x) { return sqrtf(maxf(x, 0.0f)); }

/* Orthonormal basis around unit n (Duff et al. 2017, branchless). */
static inline void onb_from_normal(vec3 n, vec3 *t, vec3 *b) {
    float sign = copysignf(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float bb = n.x * n.y * a;
    *t = v3(1.0f + sign * n.x * n.x * a, sign * bb, -sign * n.x);
    *b = v3(bb, sign + n.y * n.y * a, -n.y);
}

/* A local shading frame: columns t, b, n. */
typedef struct { vec3 t, b, n; } Frame;

static inline Frame frame_from_normal(vec3 n) {
    Frame f; f.n = n; onb_from_normal(n, &f.t, &f.b); return f;
}
static inline vec3 frame_to_local(const Frame *f, vec3 v) {
    return v3(v3_dot(v, f->t), v3_dot(v, f->b), v3_dot(v, f->n));
}
static inline vec3 frame_to_world(const Frame *f, vec3 v) {
    return v3_add(v3_add(v3_scale(f->t, v.x), v3_scale(f->b, v.y)), v3_scale(f->n, v.z));
}

/* 4x4 column-major affine transforms (glTF layout m[col*4 + row]). */
static inline vec3 xform_point(const float m[16], vec3 p) {
    return v3(m[0] * p.x + m[4] * p.y + m[8] * p.z + m[12],
              m[1] * p.x + m[5] * p.y + m[9] * p.z + m[13],
              m[2] * p.x + m[6] * p.y + m[10] * p.z + m[14]);
}
static inline vec3 xform_vector(const float m[16], vec3 v) {
    return v3(m[0] * v.x + m[4] * v.y + m[8] * v.z,
              m[1] * v.x + m[5] * v.y + m[9] * v.z,
              m[2] * v.x + m[6] * v.y + m[10] * v.z);
}

#endif
