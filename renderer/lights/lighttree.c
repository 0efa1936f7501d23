/* renderer/lights/lighttree.c: light BVH build, importance, single-path selection and its pmf.
 * See lighttree.h for the design. */
#include "lighttree.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

#include "light_sampler.h"

#define ONE_MINUS_EPS 0x1.fffffep-1f
#define NUM_BUCKETS 12
/* Importance is clamped to this so that the sum of two children stays finite. */
#define IMPORTANCE_MAX 1e30f
/* The importance's distance clamp, as a fraction of a node's squared bounding radius (see
 * light_tree_node_importance). */
#define LIGHT_TREE_D2_CLAMP 0.1f
/* Union cones are widened by this many radians against rounding in the rotation. */
#define CONE_SLACK 1e-5f

/* ---------------------------------------------------------------- bounds */

typedef struct LB {
    vec3 bmin, bmax, w;
    float cos_o, cos_e, phi;
    uint32_t two_sided;
} LB;

/* Angle between unit vectors, accurate near 0 and pi. */
static float angle_between(vec3 a, vec3 b) {
    if (v3_dot(a, b) < 0.0f) return PI_F - 2.0f * asinf(minf(0.5f * v3_length(v3_add(a, b)), 1.0f));
    return 2.0f * asinf(minf(0.5f * v3_length(v3_sub(b, a)), 1.0f));
}

/* Smallest-ish cone containing cones (wa, ca) and (wb, cb) (cos of the half-angle). */
static void cone_union(vec3 wa, float ca, vec3 wb, float cb, vec3 *w, float *c) {
    if (ca <= -1.0f || cb <= -1.0f) { *w = wa; *c = -1.0f; return; }
    if (wa.x == wb.x && wa.y == wb.y && wa.z == wb.z) { *w = wa; *c = minf(ca, cb); return; }
    /* (a single direction, cos 1, is the common case when unioning triangles: skip its acos) */
    float ta = ca >= 1.0f ? 0.0f : acosf(clampf(ca, -1.0f, 1.0f)), tb = cb >= 1.0f ? 0.0f : acosf(clampf(cb, -1.0f, 1.0f));
    float td = angle_between(wa, wb);
    if (minf(td + tb, PI_F) <= ta) { *w = wa; *c = ca; return; }
    if (minf(td + ta, PI_F) <= tb) { *w = wb; *c = cb; return; }
    float to = 0.5f * (ta + td + tb) + CONE_SLACK;
    vec3 k = v3_cross(wa, wb);
    float kl = v3_length(k);
    if (to >= PI_F || !(kl > 0.0f)) { *w = wa; *c = -1.0f; return; }
    k = v3_scale(k, 1.0f / kl);
    /* rotate wa towards wb by to - ta about k (k is perpendicular to wa) */
    float tr = to - ta;
    *w = v3_normalize(v3_add(v3_scale(wa, cosf(tr)), v3_scale(v3_cross(k, wa), sinf(tr))));
    *c = cosf(to);
}

static LB lb_union(const LB *a, const LB *b) {
    LB r;
    r.bmin = v3_min(a->bmin, b->bmin);
    r.bmax = v3_max(a->bmax, b->bmax);
    cone_union(a->w, a->cos_o, b->w, b->cos_o, &r.w, &r.cos_o);
    r.cos_e = minf(a->cos_e, b->cos_e);
    r.phi = a->phi + b->phi;
    /* a two-sided member mirrors the cone: the union's |cos| test covers both kinds */
    r.two_sided = a->two_sided | b->two_sided;
    return r;
}

/* Bounds of one light; 0 if it does not go in the BVH (infinite, no power, bad geometry).
 * phi is what the importance scales: the power of an isotropic emitter with the light's peak
 * intensity (pbrt-v4's LightBounds; Conty Estevez & Kulla 2018, §4.1), so a spot's cone
 * enters through the orientation bound only and two spots of equal intensity weigh the same
 * inside both cones, however narrow (Light.power, the power sampler's weight, is the flux
 * and would favour wide cones by their solid angle). */
static int light_bounds(const Light *l, LB *b) {
    if (!(l->power > 0.0f) || !isfinite(l->power)) return 0;
    b->phi = l->power;
    b->w = v3(0.0f, 0.0f, 1.0f);
    b->cos_e = 0.0f; /* theta_e = pi/2 */
    b->two_sided = 0;
    switch (l->type) {
    case LIGHT_POINT:
        /* a sphere light: its box (the importance's distance and horizon bounds then cover
         * every point of it) */
        b->bmin = v3_sub(l->position, v3s(l->radius));
        b->bmax = v3_add(l->position, v3s(l->radius));
        b->cos_o = -1.0f; /* theta_o = pi */
        break;
    case LIGHT_RECT:
    case LIGHT_DISK: {
        /* one-sided and flat: its exact box, the normal cone of its plane, theta_e = pi/2 */
        vec3 ext = v3(sqrtf(l->axis_u.x * l->axis_u.x + l->axis_v.x * l->axis_v.x),
                      sqrtf(l->axis_u.y * l->axis_u.y + l->axis_v.y * l->axis_v.y),
                      sqrtf(l->axis_u.z * l->axis_u.z + l->axis_v.z * l->axis_v.z));
        if (l->type == LIGHT_RECT) /* the corners' extent: |u_i| + |v_i| */
            ext = v3(fabsf(l->axis_u.x) + fabsf(l->axis_v.x), fabsf(l->axis_u.y) + fabsf(l->axis_v.y),
                     fabsf(l->axis_u.z) + fabsf(l->axis_v.z));
        b->bmin = v3_sub(l->position, ext);
        b->bmax = v3_add(l->position, ext);
        b->w = l->direction;
        b->cos_o = 1.0f;
        break;
    }
    case LIGHT_VOLUME: /* emits in every direction from anywhere in its box */
        b->bmin = l->bounds_min;
        b->bmax = l->bounds_max;
        b->cos_o = -1.0f;
        break;
    case LIGHT_SPOT: {
        /* full intensity within the inner cone (theta_o), falling to zero at the outer cone:
         * theta_e = theta_outer - theta_inner beyond it */
        b->phi = 4.0f * PI_F * v3_luminance(l->intensity);
        if (!(b->phi > 0.0f) || !isfinite(b->phi)) return 0;
        b->bmin = v3_sub(l->position, v3s(l->radius)); /* a sphere spot: its box (the cone is */
        b->bmax = v3_add(l->position, v3s(l->radius)); /* evaluated from the centre, inside it) */
        b->w = v3_normalize(l->direction);
        float ci = clampf(l->cos_inner, -1.0f, 1.0f), co = clampf(l->cos_outer, -1.0f, 1.0f);
        if (ci < co) ci = co;
        b->cos_o = ci;
        b->cos_e = cosf(acosf(co) - acosf(ci));
        /* the importance keeps cos theta' > cos_e, and inside the inner cone cos theta' is
         * exactly 1: a hard cone (theta_e = 0, or a few ulps) must not reject its own axis */
        if (!(b->cos_e < 0x1.fffffcp-1f)) b->cos_e = 0x1.fffffcp-1f;
        break;
    }
    case LIGHT_AREA: {
        uint32_t nt = l->triangles.n;
        if (nt == 0 || !l->world_vertices) return 0;
        b->bmin = v3s(INFINITY);
        b->bmax = v3s(-INFINITY);
        int have_cone = 0;
        b->cos_o = 1.0f;
        for (uint32_t t = 0; t < nt; ++t) {
            const float *v = l->world_vertices + 9 * (size_t)t;
            vec3 a = v3(v[0], v[1], v[2]), bb = v3(v[3], v[4], v[5]), c = v3(v[6], v[7], v[8]);
            b->bmin = v3_min(b->bmin, v3_min(a, v3_min(bb, c)));
            b->bmax = v3_max(b->bmax, v3_max(a, v3_max(bb, c)));
            vec3 n = v3_cross(v3_sub(bb, a), v3_sub(c, a));
            float len = v3_length(n);
            if (!(len > 0.0f) || !isfinite(len)) continue; /* degenerate: emits nothing */
            n = v3_scale(n, 1.0f / len);
            if (!have_cone) { b->w = n; b->cos_o = 1.0f; have_cone = 1; }
            else cone_union(b->w, b->cos_o, n, 1.0f, &b->w, &b->cos_o);
        }
        if (!have_cone) b->cos_o = -1.0f;
        /* a two-sided emitter keeps its normal cone and mirrors it (|cos theta_w|): a flat
         * two-sided panel is still dark edge-on */
        b->two_sided = l->two_sided ? 1u : 0u;
        break;
    }
    default:
        return 0;
    }
    return v3_is_finite(b->bmin) && v3_is_finite(b->bmax) && v3_is_finite(b->w);
}

/* ---------------------------------------------------------------- importance */

/* cos(max(0, a - b)) and sin(max(0, a - b)) from the sines and cosines of a, b in [0, pi] */
static inline float cos_sub_clamped(float sin_a, float cos_a, float sin_b, float cos_b) {
    if (cos_a > cos_b) return 1.0f;
    return cos_a * cos_b + sin_a * sin_b;
}
static inline float sin_sub_clamped(float sin_a, float cos_a, float sin_b, float cos_b) {
    if (cos_a > cos_b) return 0.0f;
    return sin_a * cos_b - cos_a * sin_b;
}

/* A node as seen from p: the squared distance to its box's centre (dist2) and the squared
 * radius of its bounding sphere (r2), the sphere's half-angle theta_b (cos_b, sin_b; every
 * direction when p is inside), the unit direction from the centre to p (wi), and the emitter
 * bound cos(theta') = cos(max(0, theta_w - theta_o - theta_b)) (below cos_e: no emission
 * towards p; theta_w measured from |cos| for two-sided emitters). Shared by the importance
 * and the cluster estimate. */
typedef struct NodeView { float dist2, r2, cos_b, sin_b, cos_p; vec3 wi; } NodeView;

static inline NodeView node_view(const LightTreeNode *nd, vec3 p) {
    NodeView v;
    vec3 pc = v3_scale(v3_add(nd->bmin, nd->bmax), 0.5f);
    vec3 diag = v3_sub(nd->bmax, nd->bmin);
    v.r2 = 0.25f * v3_dot(diag, diag);
    vec3 d = v3_sub(p, pc);
    v.dist2 = v3_dot(d, d);
    if (v.dist2 <= v.r2) { /* inside the bounding sphere: every direction */
        v.cos_b = -1.0f;
        v.sin_b = 0.0f;
    } else {
        float s2 = v.r2 / v.dist2;
        v.cos_b = safe_sqrtf(1.0f - s2);
        v.sin_b = sqrtf(s2);
    }
    v.wi = v.dist2 > 0.0f ? v3_scale(d, 1.0f / sqrtf(v.dist2)) : v3(0.0f, 0.0f, 1.0f);
    float cos_w = v3_dot(nd->w, v.wi);
    if (nd->two_sided) cos_w = fabsf(cos_w);
    float sin_w = safe_sqrtf(1.0f - cos_w * cos_w);
    /* (cos_o = 1, a single direction, or -1, every direction: sin_o is 0 without a sqrt) */
    float sin_o = nd->cos_o >= 1.0f || nd->cos_o <= -1.0f ? 0.0f : safe_sqrtf(1.0f - nd->cos_o * nd->cos_o);
    float cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, nd->cos_o);
    float sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, nd->cos_o);
    v.cos_p = cos_sub_clamped(sin_x, cos_x, v.sin_b, v.cos_b);
    return v;
}

/* Conty Estevez & Kulla 2018 §4.1 / pbrt-v4's LightBounds::Importance: phi cos(theta') / d^2
 * times the receiver's bound cos(theta_i'), theta_i' = max(0, theta_i - theta_b). The
 * receiver is one-sided (ctx.n faces the side light is gathered from: opaque surfaces turn
 * it towards wo, transmissive ones and media pass 0), so a node whose bounding sphere lies
 * wholly below the horizon gets 0: every light in it would contribute 0 (pbrt-v4 and the
 * paper use |cos theta_i| and keep sampling them).
 *
 * d^2, the squared distance to the box's centre, is clamped below at LIGHT_TREE_D2_CLAMP
 * times the squared radius of the bounding sphere: only near a cluster's centre, where the
 * true sum of phi_i / d_i^2 is dominated by the members nearest p (lights on facades or a
 * mesh: a 2D spread, whose mean 1/d^2 grows without bound towards the surface). The old
 * clamp at the full radius (d >= r) made every cluster around p look as dim as if p stood
 * on its sphere, so the descent spread samples over the far side of the scene; pbrt-v4's
 * |diagonal|/2 (a length compared with a squared length: r in scene units) behaves like a
 * small ratio at metre scales. Measured on the make_manylights.py scenes (scenes/tree_mse.py,
 * 16 spp): ratios 0.01 and 0.1 are equal within noise, 0.25 is worse on city_10k, 1 (the
 * old clamp) 2.4x worse on city_10k and 1.36x on emissive_mesh; 0.1 keeps a cluster whose
 * centre p happens to touch from taking every sample. */
float light_tree_node_importance(const LightTreeNode *nd, vec3 p, vec3 n) {
    NodeView v = node_view(nd, p);
    if (v.cos_p <= nd->cos_e) return 0.0f;
    float imp = nd->phi * v.cos_p / maxf(v.dist2, LIGHT_TREE_D2_CLAMP * v.r2);
    if (n.x != 0.0f || n.y != 0.0f || n.z != 0.0f) {
        float cos_i = -v3_dot(v.wi, n); /* towards the node's centre */
        float sin_i = safe_sqrtf(1.0f - cos_i * cos_i);
        float c = cos_sub_clamped(sin_i, cos_i, v.sin_b, v.cos_b);
        if (!(c > 0.0f)) return 0.0f;
        imp *= c;
    }
    return imp > 0.0f ? minf(imp, IMPORTANCE_MAX) : 0.0f; /* NaN -> 0 */
}

/* Starts the loads of an interior node's two children (a node spans at most two lines). */
static inline void prefetch_children(const LightTree *t, const LightTreeNode *nd) {
    if (nd->light != LIGHT_TREE_INTERIOR) return;
    const LightTreeNode *first = nd + 1, *second = &t->nodes[nd->child];
    __builtin_prefetch(first);
    __builtin_prefetch((const char *)(first + 1) - 1);
    __builtin_prefetch(second);
    __builtin_prefetch((const char *)(second + 1) - 1);
}

/* Branch probabilities at interior node `node`. Not inlined: select and pmf must run the
 * very same instructions so that their products agree bit for bit. */
__attribute__((noinline)) static void child_probs(const LightTree *t, uint32_t node, vec3 p, vec3 n,
                                                  float *p0, float *p1) {
    const LightTreeNode *c0 = &t->nodes[node + 1], *c1 = &t->nodes[t->nodes[node].child];
    /* The descent is a chain of dependent loads (each level's nodes miss the cache on large
     * trees): start the next level's loads, both children's children, before this level's
     * arithmetic. */
    prefetch_children(t, c0);
    prefetch_children(t, c1);
    float i0 = light_tree_node_importance(c0, p, n);
    float i1 = light_tree_node_importance(c1, p, n);
    if (!(i0 + i1 > 0.0f)) { /* neither child visible by its bounds: split by power */
        i0 = c0->phi;
        i1 = c1->phi;
        if (!(i0 + i1 > 0.0f) || !isfinite(i0 + i1)) i0 = i1 = 1.0f;
    }
    float s = i0 + i1;
    *p0 = i0 / s;
    *p1 = i1 / s;
}

static void node_set(LightTreeNode *nd, const LB *b) {
    nd->bmin = b->bmin;
    nd->bmax = b->bmax;
    nd->w = b->w;
    nd->cos_o = b->cos_o;
    nd->cos_e = b->cos_e;
    nd->phi = b->phi;
    nd->two_sided = b->two_sided;
}

static LB node_bounds(const LightTreeNode *nd) {
    LB b = {nd->bmin, nd->bmax, nd->w, nd->cos_o, nd->cos_e, nd->phi, nd->two_sided};
    return b;
}

/* ---------------------------------------------------------------- build */

typedef struct Item {
    LB b;
    vec3 c; /* centroid */
    uint32_t light;
} Item;

typedef struct KeyPos { float key; uint32_t pos; } KeyPos;

typedef struct Builder {
    LightTree *t;
    Item *items;
    Item *scratch;    /* for the median fallback's sort */
    struct KeyPos *keys;
} Builder;

static inline float v3_get(vec3 v, int a) { return a == 0 ? v.x : (a == 1 ? v.y : v.z); }

static inline int bucket_of(float c, float cmin, float cmax) {
    int b = (int)((float)NUM_BUCKETS * ((c - cmin) / (cmax - cmin)));
    return b < 0 ? 0 : (b >= NUM_BUCKETS ? NUM_BUCKETS - 1 : b);
}

/* pbrt-v4's orientation measure M_Omega of a cone (theta_o, theta_e) times power times the
 * box's surface area; extents are padded by `pad` so that collinear / coplanar emitters
 * still rank splits by their extent instead of all costing 0. */
static double saoh_cost(const LB *b, float pad) {
    double m;
    if (b->cos_o <= -1.0f) {
        m = 4.0 * PI_F; /* theta_o = pi: the whole sphere, whatever theta_e */
    } else {
        double to = acos(clampf(b->cos_o, -1.0f, 1.0f)), te = acos(clampf(b->cos_e, -1.0f, 1.0f));
        double tw = fmin(to + te, (double)PI_F);
        double so = sqrt(fmax(0.0, 1.0 - (double)b->cos_o * b->cos_o));
        m = 2.0 * PI_F * (1.0 - b->cos_o) +
            0.5 * PI_F * (2.0 * tw * so - cos(to - 2.0 * tw) - 2.0 * to * so + b->cos_o);
    }
    vec3 e = v3_sub(b->bmax, b->bmin);
    double ex = (double)e.x + pad, ey = (double)e.y + pad, ez = (double)e.z + pad;
    double area = 2.0 * (ex * ey + ey * ez + ez * ex);
    return (double)b->phi * m * area;
}

static int cmp_key(const void *a, const void *b) {
    const KeyPos *x = a, *y = b;
    if (x->key != y->key) return x->key < y->key ? -1 : 1;
    return x->pos < y->pos ? -1 : (x->pos > y->pos ? 1 : 0);
}

/* Sorts items[start, end) by centroid along the widest centroid axis (ties: current order). */
static void sort_range(Builder *B, uint32_t start, uint32_t end) {
    vec3 cmin = v3s(INFINITY), cmax = v3s(-INFINITY);
    for (uint32_t i = start; i < end; ++i) {
        cmin = v3_min(cmin, B->items[i].c);
        cmax = v3_max(cmax, B->items[i].c);
    }
    vec3 ext = v3_sub(cmax, cmin);
    int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    uint32_t n = end - start;
    for (uint32_t i = 0; i < n; ++i) {
        B->keys[i].key = v3_get(B->items[start + i].c, axis);
        B->keys[i].pos = i;
    }
    qsort(B->keys, n, sizeof *B->keys, cmp_key);
    for (uint32_t i = 0; i < n; ++i) B->scratch[i] = B->items[start + B->keys[i].pos];
    memcpy(B->items + start, B->scratch, n * sizeof(Item));
}

/* SAOH split (pbrt-v4 / Conty & Kulla): 12 buckets along each axis, cost
 * Kr * (cost(left) + cost(right)) with Kr = longest extent / extent along the axis.
 * Returns the split position, or start + n/2 when no split separates anything. */
static uint32_t saoh_split(Builder *B, uint32_t start, uint32_t end) {
    Item *it = B->items;
    vec3 cmin = v3s(INFINITY), cmax = v3s(-INFINITY), bmin = v3s(INFINITY), bmax = v3s(-INFINITY);
    for (uint32_t i = start; i < end; ++i) {
        cmin = v3_min(cmin, it[i].c);
        cmax = v3_max(cmax, it[i].c);
        bmin = v3_min(bmin, it[i].b.bmin);
        bmax = v3_max(bmax, it[i].b.bmax);
    }
    vec3 diag = v3_sub(bmax, bmin);
    float maxext = v3_max_component(diag);
    float pad = 1e-4f * maxext;
    LB bk[3][NUM_BUCKETS];
    uint32_t cnt[3][NUM_BUCKETS];
    memset(cnt, 0, sizeof cnt);
    int use[3];
    for (int a = 0; a < 3; ++a) use[a] = v3_get(cmax, a) > v3_get(cmin, a) && v3_get(diag, a) > 0.0f;
    if (!use[0] && !use[1] && !use[2]) return start + (end - start) / 2;
    for (uint32_t i = start; i < end; ++i) {
        for (int a = 0; a < 3; ++a) {
            if (!use[a]) continue;
            int b = bucket_of(v3_get(it[i].c, a), v3_get(cmin, a), v3_get(cmax, a));
            if (cnt[a][b]++ == 0) bk[a][b] = it[i].b;
            else bk[a][b] = lb_union(&bk[a][b], &it[i].b);
        }
    }
    double best = INFINITY;
    int best_axis = -1, best_bucket = -1;
    for (int a = 0; a < 3; ++a) {
        if (!use[a]) continue;
        double kr = (double)maxext / (double)v3_get(diag, a);
        /* suffix unions: right[i] = buckets i..11 */
        LB right[NUM_BUCKETS];
        uint32_t rc[NUM_BUCKETS];
        rc[NUM_BUCKETS - 1] = cnt[a][NUM_BUCKETS - 1];
        right[NUM_BUCKETS - 1] = bk[a][NUM_BUCKETS - 1];
        for (int i = NUM_BUCKETS - 2; i >= 0; --i) {
            rc[i] = rc[i + 1] + cnt[a][i];
            if (cnt[a][i] == 0) right[i] = right[i + 1];
            else if (rc[i + 1] == 0) right[i] = bk[a][i];
            else right[i] = lb_union(&bk[a][i], &right[i + 1]);
        }
        LB left;
        uint32_t lc = 0;
        for (int i = 0; i < NUM_BUCKETS - 1; ++i) {
            if (cnt[a][i]) {
                left = lc ? lb_union(&left, &bk[a][i]) : bk[a][i];
                lc += cnt[a][i];
            }
            if (lc == 0 || rc[i + 1] == 0) continue;
            double cost = kr * (saoh_cost(&left, pad) + saoh_cost(&right[i + 1], pad));
            if (cost < best) { best = cost; best_axis = a; best_bucket = i; }
        }
    }
    if (best_axis < 0) return start + (end - start) / 2;
    float lo = v3_get(cmin, best_axis), hi = v3_get(cmax, best_axis);
    uint32_t i = start, j = end;
    while (i < j) {
        if (bucket_of(v3_get(it[i].c, best_axis), lo, hi) <= best_bucket) { ++i; continue; }
        --j;
        Item tmp = it[i];
        it[i] = it[j];
        it[j] = tmp;
    }
    if (i == start || i == end) return start + (end - start) / 2; /* cannot happen */
    return i;
}

static LB build_node(Builder *B, uint32_t start, uint32_t end, uint64_t trail, int depth, int sorted) {
    LightTree *t = B->t;
    uint32_t idx = t->node_count++;
    LightTreeNode *nd;
    t->depth[idx] = (uint8_t)depth;
    if (end - start == 1) {
        const Item *it = &B->items[start];
        nd = &t->nodes[idx];
        node_set(nd, &it->b);
        nd->child = 0;
        nd->light = it->light;
        t->trail[it->light] = trail;
        return it->b;
    }
    uint32_t mid;
    if (!sorted && depth >= LIGHT_TREE_SAH_DEPTH) {
        sort_range(B, start, end); /* from here on: balanced median splits */
        sorted = 1;
    }
    mid = sorted || end - start == 2 ? start + (end - start) / 2 : saoh_split(B, start, end);
    LB l = build_node(B, start, mid, trail, depth + 1, sorted);
    uint32_t second = t->node_count;
    LB r = build_node(B, mid, end, trail | ((uint64_t)1 << depth), depth + 1, sorted);
    LB u = lb_union(&l, &r);
    nd = &t->nodes[idx];
    node_set(nd, &u);
    nd->child = second;
    nd->light = LIGHT_TREE_INTERIOR;
    return u;
}

/* Builds the nodes over B->items[0..m) (their bounds, centroids and indices filled in) and
 * fills t->trail for those indices. 0 ok, -1 out of memory (the caller frees t). */
static int build_items(LightTree *t, Builder *B, uint32_t m) {
    if (!m) return 0;
    t->nodes = malloc((2 * (size_t)m - 1) * sizeof *t->nodes);
    t->depth = malloc(2 * (size_t)m - 1);
    if (!t->depth) return -1;
    B->scratch = malloc(m * sizeof(Item));
    B->keys = malloc(m * sizeof *B->keys);
    if (!t->nodes || !B->scratch || !B->keys) return -1;
    build_node(B, 0, m, 0, 0, 0);
    return 0;
}

static void builder_free(Builder *B) {
    free(B->items);
    free(B->scratch);
    free(B->keys);
}

/* The start of both builds: the per-light arrays and the item buffer. 0 ok, -1 out of memory. */
static int builder_begin(LightTree *t, Builder *B, uint32_t count) {
    t->light_count = count;
    t->trail = calloc(count, sizeof *t->trail);
    t->kind = calloc(count, sizeof *t->kind);
    B->items = malloc(count * sizeof(Item));
    return t->trail && t->kind && B->items ? 0 : -1;
}

int light_tree_build(LightTree *t, const Light *lights, uint32_t count) {
    return light_tree_build_enabled(t, lights, count, NULL);
}

int light_tree_build_enabled(LightTree *t, const Light *lights, uint32_t count, const uint8_t *enabled) {
    memset(t, 0, sizeof *t);
    if (count == 0) return 0;
    Builder B = {t, NULL, NULL, NULL};
    if (builder_begin(t, &B, count) != 0) goto oom;
    uint32_t m = 0, ninf = 0;
    for (uint32_t i = 0; i < count; ++i) {
        const Light *l = &lights[i];
        if (enabled && !enabled[i]) continue; /* light linking: not in this class's tree */
        if (l->type == LIGHT_DIRECTIONAL || l->type == LIGHT_ENVIRONMENT) {
            t->kind[i] = LIGHT_TREE_INFINITE;
            ++ninf;
            continue;
        }
        Item *it = &B.items[m];
        if (!light_bounds(l, &it->b)) continue;
        it->c = v3_scale(v3_add(it->b.bmin, it->b.bmax), 0.5f);
        it->light = i;
        t->kind[i] = LIGHT_TREE_BVH;
        ++m;
    }
    if (ninf) {
        t->infinite = malloc(ninf * sizeof *t->infinite);
        t->inf_dir = malloc(ninf * sizeof *t->inf_dir);
        t->inf_sin = malloc(ninf * sizeof *t->inf_sin);
        if (!t->infinite || !t->inf_dir || !t->inf_sin) goto oom;
        for (uint32_t i = 0; i < count; ++i) {
            if (t->kind[i] != LIGHT_TREE_INFINITE) continue;
            vec3 d = lights[i].type == LIGHT_DIRECTIONAL ? lights[i].direction : v3s(0.0f);
            t->inf_dir[t->num_infinite] = v3_is_finite(d) ? d : v3s(0.0f);
            float omc = lights[i].type == LIGHT_DIRECTIONAL ? lights[i].sun_omc : 0.0f; /* a sun's cone */
            t->inf_sin[t->num_infinite] = sqrtf(fmaxf(omc * (2.0f - omc), 0.0f));
            t->infinite[t->num_infinite++] = i;
        }
    }
    if (build_items(t, &B, m) != 0) goto oom;
    t->p_inf = (float)ninf / (float)(ninf + (m ? 1u : 0u));
    if (ninf + m == 0) t->p_inf = 0.0f;
    t->p_bvh = 1.0f - t->p_inf;
    t->pmf_inf = ninf ? t->p_inf / (float)ninf : 0.0f;
    builder_free(&B);
    return 0;
oom:
    builder_free(&B);
    light_tree_free(t);
    return -1;
}

/* One triangle's leaf bounds (an emitter of luminance x area, x2 when two-sided; its normal
 * cone a single direction, a cosine emitter). 0: it emits nothing (zero or non-finite area or
 * bounds) and is left out of the tree. */
static int triangle_bounds(const float *v, float scale, int two_sided, LB *out) {
    vec3 a = v3(v[0], v[1], v[2]), b = v3(v[3], v[4], v[5]), c = v3(v[6], v[7], v[8]);
    vec3 n = v3_cross(v3_sub(b, a), v3_sub(c, a));
    float len = v3_length(n);
    float phi = 0.5f * len * scale;
    if (!(len > 0.0f) || !isfinite(len) || !(phi > 0.0f) || !isfinite(phi)) return 0; /* emits nothing */
    out->bmin = v3_min(a, v3_min(b, c));
    out->bmax = v3_max(a, v3_max(b, c));
    if (!v3_is_finite(out->bmin) || !v3_is_finite(out->bmax)) return 0;
    out->w = v3_scale(n, 1.0f / len);
    out->cos_o = 1.0f;
    out->two_sided = two_sided ? 1u : 0u;
    out->cos_e = 0.0f; /* theta_e = pi/2: a cosine emitter */
    out->phi = phi;
    return 1;
}

/* relative powers are all that matter; a black (or odd) luminance falls back to area */
static float triangle_power_scale(float luminance, int two_sided) {
    return (luminance > 0.0f && isfinite(luminance) ? luminance : 1.0f) * (two_sided ? 2.0f : 1.0f);
}

int light_tree_build_triangles(LightTree *t, const float *world_vertices, uint32_t count, float luminance,
                               int two_sided) {
    memset(t, 0, sizeof *t);
    if (count == 0) return 0;
    Builder B = {t, NULL, NULL, NULL};
    if (builder_begin(t, &B, count) != 0) goto oom;
    float scale = triangle_power_scale(luminance, two_sided);
    uint32_t m = 0;
    for (uint32_t i = 0; i < count; ++i) {
        Item *it = &B.items[m];
        if (!triangle_bounds(world_vertices + 9 * (size_t)i, scale, two_sided, &it->b)) continue;
        it->c = v3_scale(v3_add(it->b.bmin, it->b.bmax), 0.5f);
        it->light = i;
        t->kind[i] = LIGHT_TREE_BVH;
        ++m;
    }
    if (build_items(t, &B, m) != 0) goto oom;
    t->p_inf = 0.0f;
    t->p_bvh = m ? 1.0f : 0.0f;
    t->pmf_inf = 0.0f;
    builder_free(&B);
    return 0;
oom:
    builder_free(&B);
    light_tree_free(t);
    return -1;
}

int light_tree_refit_triangles(LightTree *t, const LightTree *topology, const float *world_vertices, uint32_t count,
                               float luminance, int two_sided) {
    memset(t, 0, sizeof *t);
    if (topology->light_count != count || topology->num_infinite) return 1;
    if (count == 0) return 0;
    float scale = triangle_power_scale(luminance, two_sided);
    /* the triangles the topology left out must still emit nothing (those it holds are checked
     * as their leaves are refitted): a leaf set that differs needs a build of its own */
    for (uint32_t i = 0; i < count; ++i) {
        LB b;
        if (topology->kind[i] != LIGHT_TREE_BVH && triangle_bounds(world_vertices + 9 * (size_t)i, scale, two_sided, &b))
            return 1;
    }
    size_t nn = topology->node_count;
    t->light_count = count;
    t->node_count = topology->node_count;
    t->nodes = malloc((nn ? nn : 1) * sizeof *t->nodes);
    t->depth = malloc(nn ? nn : 1);
    t->trail = malloc(count * sizeof *t->trail);
    t->kind = malloc(count);
    if (!t->nodes || !t->depth || !t->trail || !t->kind) { light_tree_free(t); return -1; }
    memcpy(t->nodes, topology->nodes, nn * sizeof *t->nodes);
    memcpy(t->depth, topology->depth, nn);
    memcpy(t->trail, topology->trail, count * sizeof *t->trail);
    memcpy(t->kind, topology->kind, count);
    /* children follow their parent in the depth-first array, so one backward pass sees both
     * children of a node before the node: the same lb_union as the build, bottom-up */
    for (size_t k = nn; k-- > 0;) {
        LightTreeNode *nd = &t->nodes[k];
        LB b;
        memset(&b, 0, sizeof b);
        if (nd->light != LIGHT_TREE_INTERIOR) {
            if (!triangle_bounds(world_vertices + 9 * (size_t)nd->light, scale, two_sided, &b)) {
                light_tree_free(t); /* a leaf's triangle emits nothing here */
                return 1;
            }
        } else {
            LB l = node_bounds(&t->nodes[k + 1]), r = node_bounds(&t->nodes[nd->child]);
            b = lb_union(&l, &r);
        }
        node_set(nd, &b);
    }
    t->p_inf = 0.0f;
    t->p_bvh = topology->p_bvh;
    t->pmf_inf = 0.0f;
    return 0;
}

void light_tree_free(LightTree *t) {
    free(t->nodes);
    free(t->depth);
    free(t->intensity);
    free(t->trail);
    free(t->kind);
    free(t->infinite);
    free(t->inf_dir);
    free(t->inf_sin);
    memset(t, 0, sizeof *t);
}

/* ---------------------------------------------------------------- selection */

/* The split between the infinite lights and the BVH at ctx (pbrt-v4: one share per infinite
 * light and one for the BVH), minus what cannot contribute there: a directional light below
 * the receiver's horizon, and the whole BVH when its root has importance 0 (every light
 * below the horizon or facing away). Those shares go to the rest; when nothing is left the
 * context-free split applies (the pmf still sums to 1). *alive: how many infinite lights
 * share p_inf. Not inlined: select and pmf must get the same floats. */
typedef struct InfSplit { float p_inf, p_bvh, pmf_inf; uint32_t alive; } InfSplit;

static inline int infinite_reaches(const LightTree *t, uint32_t k, vec3 n) {
    vec3 d = t->inf_dir[k]; /* zero: the environment, which may light every direction */
    if (v3_is_black(n) || v3_is_black(d)) return 1;
    /* a sun reaches while any of its cone is above the horizon: the axis above -sin h */
    return -v3_dot(d, n) > -t->inf_sin[k];
}

__attribute__((noinline)) static InfSplit infinite_split(const LightTree *t, const LightSampleContext *ctx) {
    InfSplit r = {t->p_inf, t->p_bvh, t->pmf_inf, t->num_infinite};
    if (!t->num_infinite) return r;
    uint32_t alive = 0;
    for (uint32_t k = 0; k < t->num_infinite; ++k) alive += (uint32_t)infinite_reaches(t, k, ctx->n);
    uint32_t bvh = t->node_count && light_tree_node_importance(&t->nodes[0], ctx->p, ctx->n) > 0.0f ? 1u : 0u;
    if (alive + bvh == 0) return r;
    r.alive = alive;
    r.p_inf = (float)alive / (float)(alive + bvh);
    r.p_bvh = 1.0f - r.p_inf;
    r.pmf_inf = alive ? r.p_inf / (float)alive : 0.0f;
    return r;
}

uint32_t light_tree_select(const LightTree *t, const LightSampleContext *ctx, float u, float *pmf) {
    InfSplit sp = infinite_split(t, ctx);
    if (u < sp.p_inf) {
        uint32_t k = (uint32_t)(minf(u / sp.p_inf, ONE_MINUS_EPS) * (float)sp.alive);
        if (k >= sp.alive) k = sp.alive - 1;
        *pmf = sp.pmf_inf;
        if (sp.alive == t->num_infinite) return t->infinite[k];
        for (uint32_t j = 0;; ++j) /* the k-th infinite light that reaches ctx */
            if (infinite_reaches(t, j, ctx->n) && k-- == 0) return t->infinite[j];
    }
    if (t->node_count == 0) { *pmf = 0.0f; return 0; }
    float pr;
    uint32_t light = light_tree_select_from(t, 0, ctx, (u - sp.p_inf) / sp.p_bvh, &pr);
    *pmf = sp.p_bvh * pr;
    return light;
}

float light_tree_pmf(const LightTree *t, const LightSampleContext *ctx, uint32_t light) {
    if (light >= t->light_count) return 0.0f;
    if (t->kind[light] == LIGHT_TREE_INFINITE) {
        InfSplit sp = infinite_split(t, ctx);
        if (sp.alive == t->num_infinite) return sp.pmf_inf;
        for (uint32_t k = 0; k < t->num_infinite; ++k)
            if (t->infinite[k] == light) return infinite_reaches(t, k, ctx->n) ? sp.pmf_inf : 0.0f;
        return 0.0f;
    }
    if (t->kind[light] != LIGHT_TREE_BVH) return 0.0f;
    InfSplit sp = infinite_split(t, ctx);
    if (!(sp.p_bvh > 0.0f)) return 0.0f;
    return sp.p_bvh * light_tree_pmf_from(t, 0, ctx, light);
}

/* ---------------------------------------------------------------- descent below a node */

/* The single-path descent: the whole tree from node 0 (light_tree_select/pmf), a cache point
 * cluster from its node. */
uint32_t light_tree_select_from(const LightTree *t, uint32_t node, const LightSampleContext *ctx, float u, float *pmf) {
    u = clampf(u, 0.0f, ONE_MINUS_EPS);
    float pr = 1.0f;
    while (t->nodes[node].light == LIGHT_TREE_INTERIOR) {
        float p0, p1;
        child_probs(t, node, ctx->p, ctx->n, &p0, &p1);
        if (u < p0) {
            pr *= p0;
            u = minf(u / p0, ONE_MINUS_EPS);
            node = node + 1;
        } else {
            pr *= p1;
            u = clampf((u - p0) / p1, 0.0f, ONE_MINUS_EPS);
            node = t->nodes[node].child;
        }
    }
    *pmf = pr;
    return t->nodes[node].light;
}

float light_tree_pmf_from(const LightTree *t, uint32_t node, const LightSampleContext *ctx, uint32_t light) {
    if (light >= t->light_count || t->kind[light] != LIGHT_TREE_BVH) return 0.0f;
    uint64_t trail = t->trail[light] >> t->depth[node];
    float pr = 1.0f;
    while (t->nodes[node].light == LIGHT_TREE_INTERIOR) {
        float p0, p1;
        child_probs(t, node, ctx->p, ctx->n, &p0, &p1);
        if (trail & 1u) {
            pr *= p1;
            node = t->nodes[node].child;
        } else {
            pr *= p0;
            node = node + 1;
        }
        trail >>= 1;
    }
    return t->nodes[node].light == light ? pr : 0.0f;
}

/* ---------------------------------------------------------------- cluster estimates */

int light_tree_set_intensities(LightTree *t, const float *light_intensity) {
    free(t->intensity);
    t->intensity = malloc((t->node_count + 1) * sizeof(float));
    if (!t->intensity) return -1;
    /* children have higher indices than their parent: one reverse sweep sums them */
    for (uint32_t k = t->node_count; k-- > 0;) {
        const LightTreeNode *nd = &t->nodes[k];
        float v = nd->light == LIGHT_TREE_INTERIOR ? t->intensity[k + 1] + t->intensity[nd->child]
                                                    : light_intensity[nd->light];
        t->intensity[k] = v > 0.0f && isfinite(v) ? minf(v, IMPORTANCE_MAX) : 0.0f;
    }
    return 0;
}

/* The cluster's summed radiant intensity towards p, I cos(theta') (theta' as in the
 * importance: the emitter cone widened by the node's angular size), over the squared
 * distance to its centre clamped to its bounding sphere: the fluence. Irradiance on the axis
 * planes bounds the receiver cosine the same way, cos(max(0, theta_i - theta_b)). Exact for a
 * single point light; an approximation for clusters, which only ever sets sampling weights. */
void light_tree_node_estimate7(const LightTree *t, uint32_t node, vec3 p, float out[7]) {
    const LightTreeNode *nd = &t->nodes[node];
    for (int i = 0; i < 7; ++i) out[i] = 0.0f;
    float I = t->intensity ? t->intensity[node] : 0.0f;
    if (!(I > 0.0f)) return;
    NodeView v = node_view(nd, p);
    if (v.cos_p <= nd->cos_e) return;
    float fluence = I * maxf(v.cos_p, 0.0f) / maxf(v.dist2, v.r2);
    if (!(fluence > 0.0f) || !isfinite(fluence)) return;
    out[6] = fluence;
    /* receiver cosine bound per axis: the direction from p to the cluster is -wi; the two
     * planes of an axis share the sine */
    const float c[3] = {-v.wi.x, -v.wi.y, -v.wi.z};
    for (int k = 0; k < 3; ++k) {
        float sin_i = safe_sqrtf(1.0f - c[k] * c[k]);
        out[2 * k] = fluence * maxf(cos_sub_clamped(sin_i, c[k], v.sin_b, v.cos_b), 0.0f);
        out[2 * k + 1] = fluence * maxf(cos_sub_clamped(sin_i, -c[k], v.sin_b, v.cos_b), 0.0f);
    }
}

/* ---------------------------------------------------------------- as a strategy */

/* The light BVH as a light-selection strategy (light_sampler.h): one descent per selection.
 * With light linking, one tree per link class over the class's lights (light_tree_build_enabled),
 * so a descent never ends on a light that cannot reach the vertex; class 0 is the whole tree. */
typedef struct TreeSampler {
    LightTree *trees;     /* [num_classes] (1 without linking) */
    uint32_t num_classes;
} TreeSampler;

static uint32_t tree_select(const void *state, const LightSampleContext *ctx, float u, float u1, float *pmf,
                            uint32_t *outcome) {
    (void)u1; (void)outcome;
    const TreeSampler *ts = state;
    return light_tree_select(&ts->trees[ctx->link_class], ctx, u, pmf);
}

static float tree_pmf(const void *state, const LightSampleContext *ctx, uint32_t light) {
    const TreeSampler *ts = state;
    return light_tree_pmf(&ts->trees[ctx->link_class], ctx, light);
}

static void tree_destroy(void *state) {
    TreeSampler *ts = state;
    for (uint32_t c = 0; c < ts->num_classes; ++c) light_tree_free(&ts->trees[c]);
    free(ts->trees);
    free(ts);
}

static const LightSamplerOps TREE_OPS = {
    .name = "tree", .select = tree_select, .pmf = tree_pmf, .destroy = tree_destroy};

int light_sampler_tree_create(LightSampler *s, const Lights *lights) {
    TreeSampler *ts = calloc(1, sizeof *ts);
    uint32_t classes = lights->link ? lights->link->num_classes : 1;
    if (!ts || !(ts->trees = calloc(classes, sizeof *ts->trees))) { free(ts); return -1; }
    for (uint32_t c = 0; c < classes; ++c) {
        const uint8_t *enabled = c ? lights->link->enabled + (size_t)c * lights->count : NULL;
        if (light_tree_build_enabled(&ts->trees[c], lights->lights, lights->count, enabled) != 0) {
            tree_destroy(ts);
            return -1;
        }
        ts->num_classes = c + 1;
    }
    *s = (LightSampler){&TREE_OPS, ts, lights->count};
    return 0;
}
