/* End-to-end renders of VDB media against closed forms (the volume walk, its NEE and the
 * shadow rays' transmittance through the whole renderer). Each scene is written at test time
 * into a temporary folder: a .vdb (io_write_vdb_dense), a constant environment (EXR) and a
 * glTF with an orthographic camera looking down -Z through a box of medium centred at the
 * origin. Tolerances are 5 standard errors of the image mean (from the film's per-pixel
 * variance) plus the quadrature error where a reference is integrated numerically.
 *   (a) transmittance: an absorbing box (albedo 0) in front of a constant environment:
 *       L = exp(-tau), tau = sigma_t x thickness;
 *   (b) emission: an emitting absorber against black: L = Le (1 - exp(-tau));
 *   (c) single scattering of a point light inside a scattering box (--max-volume-bounces 1) against a
 *       quadrature of the trilinear density field along the camera ray and the light rays;
 *   (d) furnace: a non-absorbing box (albedo 1) under a constant environment: L = the
 *       environment's radiance, whatever the scattering (every bounce, NEE through media, MIS);
 *   (e) 1 and 2 threads give bit-identical images;
 *   (f)-(h) media inside meshes (candela_medium, invisible boundaries): looking through an
 *       absorbing cube, the camera inside it (found at the start), and a sun's shadow rays
 *       through an absorbing slab onto a Lambert floor;
 *   (i) a floor lit by an emitting volume: emission sampling on and off agree, and on is less
 *       noisy; (j) the same on a heterogeneous, scattering emitter, and 1 vs 2 threads;
 *   (n) volume path guiding (phase sampling guided, |g| < 0.95): the furnace stays exactly
 *       the environment with one-sample MIS and with RIS, bit-identical for 1 and 2 threads;
 *   (o) the radiance recorder on a deep medium (optical thickness 300, albedo 1: hundreds of
 *       scattering events per path) stays under its bound (--recorder-mb 4), and its debug AOV
 *       still converges to the image.
 * CANDELA_KEEP_TEST_SCENES=1 keeps the written scenes (their folder is printed) for rendering
 * them by hand. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "candela.h"
#include "check.h"
#include "io.h"

static char g_dir[256];

enum { N = 16 };              /* voxels per axis of the box */
static const float H = 1.0f / N; /* voxel size: the box's optical thickness is that of 1 m (trilinear ramps included) */

static void index_to_world(float m[16]) {
    memset(m, 0, 16 * sizeof(float));
    m[0] = m[5] = m[10] = H;
    float t = -0.5f * (float)(N - 1) * H; /* voxel centres symmetric about the origin */
    m[12] = m[13] = m[14] = t;
    m[15] = 1.0f;
}

/* A constant environment image of radiance `value`. */
static void write_env(const char *name, float value) {
    char path[512];
    snprintf(path, sizeof path, "%s/%s", g_dir, name);
    float px[8];
    for (int i = 0; i < 8; ++i) px[i] = value;
    float alpha[8] = {1, 1, 1, 1, 1, 1, 1, 1};
    IoExrChannel ch[4] = {{"R", px}, {"G", px}, {"B", px}, {"A", alpha}};
    char err[IO_ERR_LEN];
    CHECK(io_write_exr(path, 4, 2, ch, 4, NULL, 0, err) == 0, "%s", err);
}

/* density (and optionally emission: a grid two voxels wider, so Le is constant wherever the
 * density is not 0) into NAME.vdb */
static void write_box_vdb(const char *name, int emissive) {
    enum { M = N + 4 };
    static float dens[M * M * M], emit[M * M * M];
    for (int z = 0; z < M; ++z)
        for (int y = 0; y < M; ++y)
            for (int x = 0; x < M; ++x) {
                int inside = x >= 2 && x < N + 2 && y >= 2 && y < N + 2 && z >= 2 && z < N + 2;
                dens[x + M * (y + M * z)] = inside ? 1.0f : 0.0f;
                emit[x + M * (y + M * z)] = 1.0f;
            }
    float m[16];
    index_to_world(m);
    m[12] -= 2.0f * H; m[13] -= 2.0f * H; m[14] -= 2.0f * H; /* the grid starts two voxels earlier */
    const char *names[2] = {"density", "emission"};
    const float *values[2] = {dens, emit};
    char path[512], err[IO_ERR_LEN];
    snprintf(path, sizeof path, "%s/%s", g_dir, name);
    CHECK(io_write_vdb_dense(path, names, values, emissive ? 2 : 1, M, M, M, m, err) == 0, "%s", err);
}

/* A glTF: orthographic camera at z = 3 looking down -Z (half extent `mag`), the volume node,
 * optionally a point light (KHR_lights_punctual, raw units) and an environment. */
static void write_gltf(const char *name, const char *volume_extras, const char *env, const float *light_pos,
                       float light_intensity, float mag) {
    char path[512];
    snprintf(path, sizeof path, "%s/%s", g_dir, name);
    FILE *f = fopen(path, "w");
    if (!f) { CHECK(0, "cannot write %s", path); return; }
    fprintf(f, "{\"asset\": {\"version\": \"2.0\"}, \"scene\": 0,\n");
    if (light_pos) fprintf(f, "\"extensionsUsed\": [\"KHR_lights_punctual\"],\n"
                              "\"extensions\": {\"KHR_lights_punctual\": {\"lights\": [{\"type\": \"point\", "
                              "\"color\": [1, 1, 1], \"intensity\": %.9g}]}},\n", light_intensity);
    fprintf(f, "\"scenes\": [{\"nodes\": [0, 1%s]", light_pos ? ", 2" : "");
    if (env) fprintf(f, ", \"extras\": {\"candela_environment\": {\"uri\": \"%s\", \"strength\": 1.0}}", env);
    fprintf(f, "}],\n\"nodes\": [{\"name\": \"camera\", \"translation\": [0, 0, 3], \"camera\": 0},\n"
               "{\"name\": \"box\", \"extras\": {\"candela_volume\": %s}}", volume_extras);
    if (light_pos)
        fprintf(f, ",\n{\"name\": \"light\", \"translation\": [%.9g, %.9g, %.9g], "
                   "\"extensions\": {\"KHR_lights_punctual\": {\"light\": 0}}}", light_pos[0], light_pos[1], light_pos[2]);
    fprintf(f, "],\n\"cameras\": [{\"type\": \"orthographic\", \"orthographic\": {\"xmag\": %.9g, \"ymag\": %.9g, "
               "\"znear\": 0.01, \"zfar\": 100}}]}\n", mag, mag);
    fclose(f);
}

typedef struct Result { double mean, se; CandelaImage img; } Result;

static int g_max_depth = 8;
static int g_emission_sampling = 1;
static CandelaLightSampler g_sampler = CANDELA_LIGHT_SAMPLER_POWER;
static int g_inscatter = 0;
static CandelaGuiding g_guiding = CANDELA_GUIDING_OFF;
static int g_aov = 0;              /* --aov recorder-debug */
static uint32_t g_recorder_mb = 0;
static CandelaStats g_stats;       /* the last render's */

static Result render(const char *name, int spp, int max_volume_bounces, int threads) {
    char path[512];
    snprintf(path, sizeof path, "%s/%s", g_dir, name);
    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = path;
    o.width = o.height = 16;
    o.spp = spp;
    o.max_volume_bounces = max_volume_bounces;
    o.max_depth = g_max_depth;
    o.volume_emission_sampling = g_emission_sampling;
    o.threads = threads;
    o.quiet = 1;
    o.seed = 11;
    o.light_units = CANDELA_LIGHT_UNITS_RAW;
    o.light_sampler = g_sampler;
    o.volume_inscatter_sampling = g_inscatter;
    o.guiding = g_guiding;
    o.aov_recorder_debug = g_aov;
    o.recorder_mb = g_recorder_mb;
    Result r = {0};
    char err[CANDELA_ERR_LEN];
    int rc = candela_render(&o, &r.img, &g_stats, NULL, err);
    CHECK(rc == 0, "%s: %s", name, err);
    if (rc != 0) return r;
    size_t n = (size_t)r.img.width * r.img.height;
    double sum = 0.0, var = 0.0;
    for (size_t i = 0; i < n; ++i) {
        sum += (r.img.rgb[3 * i] + r.img.rgb[3 * i + 1] + r.img.rgb[3 * i + 2]) / 3.0;
        var += (r.img.variance[3 * i] + r.img.variance[3 * i + 1] + r.img.variance[3 * i + 2]) / 9.0;
    }
    r.mean = sum / (double)n;
    r.se = sqrt(var) / (double)n;
    return r;
}

/* render with --max-depth (surface bounces) instead */
static Result render_depth(const char *name, int spp, int max_depth) {
    g_max_depth = max_depth;
    Result r = render(name, spp, 256, 2);
    g_max_depth = 8;
    return r;
}

static void expect(const char *what, Result r, double expected, double extra_tol) {
    double tol = 5.0 * r.se + extra_tol;
    fprintf(stderr, "  %-28s mean %.5f expected %.5f (tolerance %.5f)\n", what, r.mean, expected, tol);
    CHECK(fabs(r.mean - expected) <= tol, "%s: mean %.5f, expected %.5f +- %.5f", what, r.mean, expected, tol);
}

/* The density field the renderer sees: trilinear over voxel centres of the N^3 box of 1s. */
static double box_density(double x, double y, double z) {
    double c[3] = {x, y, z}, w = 1.0;
    for (int k = 0; k < 3; ++k) {
        double i = c[k] / H + 0.5 * (N - 1); /* continuous index */
        /* 1 inside [0, N-1], a linear ramp to 0 over one voxel outside */
        double d = i < 0.0 ? -i : (i > N - 1 ? i - (N - 1) : 0.0);
        w *= d >= 1.0 ? 0.0 : 1.0 - d;
    }
    return w;
}

static double optical_depth(double sigma, const double a[3], const double b[3]) {
    enum { STEPS = 200 };
    double len = sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
    double tau = 0.0;
    for (int i = 0; i < STEPS; ++i) {
        double t = (i + 0.5) / STEPS;
        tau += box_density(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2]));
    }
    return sigma * tau * len / STEPS;
}

/* ---------------------------------------------------------------- media inside meshes */

static void base64(const unsigned char *in, size_t n, char *out) {
    static const char tbl[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    size_t o = 0;
    for (size_t i = 0; i < n; i += 3) {
        uint32_t v = (uint32_t)in[i] << 16 | (i + 1 < n ? (uint32_t)in[i + 1] << 8 : 0) | (i + 2 < n ? in[i + 2] : 0);
        out[o++] = tbl[v >> 18 & 63];
        out[o++] = tbl[v >> 12 & 63];
        out[o++] = i + 1 < n ? tbl[v >> 6 & 63] : '=';
        out[o++] = i + 2 < n ? tbl[v & 63] : '=';
    }
    out[o] = 0;
}

/* glTF with mesh 0 = a unit cube (outward winding), mesh 1 = a white Lambert floor square;
 * `nodes` is the JSON of the node list (the camera is node 0), materials: 0 = the medium
 * (candela_medium `medium`), 1 = white Lambert. */
static void write_mesh_gltf(const char *name, const char *nodes, const char *scene_nodes, const char *medium,
                            const char *env, const char *extensions) {
    static const float cube[8][3] = {{-.5f, -.5f, -.5f}, {.5f, -.5f, -.5f}, {.5f, .5f, -.5f}, {-.5f, .5f, -.5f},
                                     {-.5f, -.5f, .5f},  {.5f, -.5f, .5f},  {.5f, .5f, .5f},  {-.5f, .5f, .5f}};
    static const uint16_t cube_idx[36] = {0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4,
                                          3, 7, 6, 3, 6, 2, 0, 4, 7, 0, 7, 3, 1, 2, 6, 1, 6, 5};
    static const float floor_v[4][3] = {{-4, 0, -4}, {4, 0, -4}, {4, 0, 4}, {-4, 0, 4}};
    static const uint16_t floor_idx[6] = {0, 2, 1, 0, 3, 2};
    unsigned char buf[96 + 72 + 48 + 12];
    memcpy(buf, cube, 96);
    memcpy(buf + 96, cube_idx, 72);
    memcpy(buf + 168, floor_v, 48);
    memcpy(buf + 216, floor_idx, 12);
    char b64[400];
    base64(buf, sizeof buf, b64);
    char path[512];
    snprintf(path, sizeof path, "%s/%s", g_dir, name);
    FILE *f = fopen(path, "w");
    if (!f) { CHECK(0, "cannot write %s", path); return; }
    fprintf(f, "{\"asset\": {\"version\": \"2.0\"}, \"scene\": 0,%s\n", extensions ? extensions : "");
    fprintf(f, "\"scenes\": [{\"nodes\": %s", scene_nodes);
    if (env) fprintf(f, ", \"extras\": {\"candela_environment\": {\"uri\": \"%s\", \"strength\": 1.0}}", env);
    fprintf(f, "}],\n\"nodes\": %s,\n", nodes);
    fprintf(f, "\"cameras\": [{\"type\": \"orthographic\", \"orthographic\": {\"xmag\": 0.2, \"ymag\": 0.2, "
               "\"znear\": 0.01, \"zfar\": 100}}],\n");
    fprintf(f, "\"materials\": [{\"name\": \"medium\", \"extras\": {\"candela_medium\": %s}},\n"
               "  {\"name\": \"white\", \"pbrMetallicRoughness\": {\"baseColorFactor\": [0.5, 0.5, 0.5, 1], "
               "\"metallicFactor\": 0, \"roughnessFactor\": 1}, \"extensions\": {\"KHR_materials_specular\": "
               "{\"specularFactor\": 0}}}],\n", medium);
    fprintf(f, "\"extensionsUsed\": [\"KHR_materials_specular\", \"KHR_lights_punctual\"],\n");
    fprintf(f, "\"meshes\": [{\"primitives\": [{\"attributes\": {\"POSITION\": 0}, \"indices\": 1, \"material\": 0}]},\n"
               "  {\"primitives\": [{\"attributes\": {\"POSITION\": 2}, \"indices\": 3, \"material\": 1}]}],\n");
    fprintf(f, "\"accessors\": [{\"bufferView\": 0, \"componentType\": 5126, \"count\": 8, \"type\": \"VEC3\", "
               "\"min\": [-0.5, -0.5, -0.5], \"max\": [0.5, 0.5, 0.5]},\n"
               "  {\"bufferView\": 1, \"componentType\": 5123, \"count\": 36, \"type\": \"SCALAR\"},\n"
               "  {\"bufferView\": 2, \"componentType\": 5126, \"count\": 4, \"type\": \"VEC3\", "
               "\"min\": [-4, 0, -4], \"max\": [4, 0, 4]},\n"
               "  {\"bufferView\": 3, \"componentType\": 5123, \"count\": 6, \"type\": \"SCALAR\"}],\n");
    fprintf(f, "\"bufferViews\": [{\"buffer\": 0, \"byteOffset\": 0, \"byteLength\": 96}, "
               "{\"buffer\": 0, \"byteOffset\": 96, \"byteLength\": 72}, "
               "{\"buffer\": 0, \"byteOffset\": 168, \"byteLength\": 48}, "
               "{\"buffer\": 0, \"byteOffset\": 216, \"byteLength\": 12}],\n");
    fprintf(f, "\"buffers\": [{\"byteLength\": %zu, \"uri\": \"data:application/octet-stream;base64,%s\"}]}\n",
            sizeof buf, b64);
    fclose(f);
}

/* (i) an emitting absorber lights a Lambert floor (--max-depth 1): with emission sampling
 * (the volume is a light: NEE with line integration, MIS with the walk's gathering) and without
 * (only phase/BSDF rays find it) the images agree within their noise, and sampling has the
 * lower variance. The orthographic camera looks straight down at the floor beside the box. */
static void test_emission_sampling(void) {
    write_mesh_gltf("glow_floor.gltf",
                    "[{\"name\": \"camera\", \"translation\": [1.6, 3, 0], \"rotation\": [-0.70710678, 0, 0, 0.70710678], "
                    "\"camera\": 0}, {\"name\": \"floor\", \"mesh\": 1}, {\"name\": \"glow\", \"translation\": [0, 1.2, 0], "
                    "\"extras\": {\"candela_volume\": {\"uri\": \"glow.vdb\", \"density_scale\": 1.5, \"albedo\": [0, 0, 0], "
                    "\"emission_grid\": \"emission\", \"emission_scale\": 4.0}}}]",
                    "[0, 1, 2]", "{}", "black.exr", NULL);
    g_max_depth = 1;
    g_emission_sampling = 1;
    Result on = render("glow_floor.gltf", 256, 8, 2);
    g_emission_sampling = 0;
    Result off = render("glow_floor.gltf", 256, 8, 2);
    g_emission_sampling = 1;
    g_max_depth = 8;
    double tol = 5.0 * sqrt(on.se * on.se + off.se * off.se);
    fprintf(stderr, "  (i) emission sampling on %.5f (SE %.5f), off %.5f (SE %.5f)\n", on.mean, on.se, off.mean, off.se);
    CHECK(on.mean > 0.01, "the floor is not lit by the volume: %g", on.mean);
    CHECK(fabs(on.mean - off.mean) <= tol, "emission sampling changes the mean: %.5f vs %.5f (tolerance %.5f)", on.mean,
          off.mean, tol);
    CHECK(on.se < off.se, "emission sampling is not less noisy: SE %.5f vs %.5f", on.se, off.se);
    candela_image_free(&on.img);
    candela_image_free(&off.img);
}

/* (j) the same on a heterogeneous emitter (a lumpy density with an emission field that does not
 * follow it, albedo 0.6 so the volume also scatters its own light), and 1 vs 2 threads. */
static void test_emission_sampling_heterogeneous(void) {
    enum { M = 24 };
    static float dens[M * M * M], emit[M * M * M];
    for (int z = 0; z < M; ++z)
        for (int y = 0; y < M; ++y)
            for (int x = 0; x < M; ++x) {
                float fx = (x + 0.5f) / M - 0.5f, fy = (y + 0.5f) / M - 0.5f, fz = (z + 0.5f) / M - 0.5f;
                float r2 = fx * fx + fy * fy + fz * fz;
                float lumps = 0.5f + 0.5f * sinf(17.0f * fx) * cosf(13.0f * fy + 2.0f * fz);
                dens[x + M * (y + M * z)] = r2 < 0.2f ? lumps : 0.0f;
                emit[x + M * (y + M * z)] = r2 < 0.05f ? 1.0f + 0.8f * sinf(23.0f * fz) : 0.0f; /* a hot core */
            }
    float m[16];
    memset(m, 0, sizeof m);
    m[0] = m[5] = m[10] = 1.0f / M;
    m[12] = m[13] = m[14] = -0.5f + 0.5f / M;
    m[15] = 1.0f;
    const char *names[2] = {"density", "emission"};
    const float *values[2] = {dens, emit};
    char path[512], err[IO_ERR_LEN];
    snprintf(path, sizeof path, "%s/lumpy.vdb", g_dir);
    CHECK(io_write_vdb_dense(path, names, values, 2, M, M, M, m, err) == 0, "%s", err);
    write_mesh_gltf("lumpy_floor.gltf",
                    "[{\"name\": \"camera\", \"translation\": [0.9, 2.6, 0], \"rotation\": [-0.70710678, 0, 0, 0.70710678], "
                    "\"camera\": 0}, {\"name\": \"floor\", \"mesh\": 1}, {\"name\": \"glow\", \"translation\": [0, 1.0, 0], "
                    "\"extras\": {\"candela_volume\": {\"uri\": \"lumpy.vdb\", \"density_scale\": 6.0, \"albedo\": [0.6, 0.6, 0.6], "
                    "\"anisotropy\": 0.3, \"emission_grid\": \"emission\", \"emission_scale\": 3.0}}}]",
                    "[0, 1, 2]", "{}", "black.exr", NULL);
    Result on = render("lumpy_floor.gltf", 256, 64, 2);
    g_emission_sampling = 0;
    Result off = render("lumpy_floor.gltf", 256, 64, 2);
    g_emission_sampling = 1;
    Result on1 = render("lumpy_floor.gltf", 256, 64, 1);
    double tol = 5.0 * sqrt(on.se * on.se + off.se * off.se);
    fprintf(stderr, "  (j) heterogeneous emitter: sampling on %.5f (SE %.5f), off %.5f (SE %.5f)\n", on.mean, on.se,
            off.mean, off.se);
    CHECK(on.mean > 0.005, "the floor is not lit by the volume: %g", on.mean);
    CHECK(fabs(on.mean - off.mean) <= tol, "emission sampling changes the mean: %.5f vs %.5f (tolerance %.5f)", on.mean,
          off.mean, tol);
    CHECK(on.img.rgb && on1.img.rgb && memcmp(on.img.rgb, on1.img.rgb, 16 * 16 * 3 * sizeof(float)) == 0,
          "1 and 2 threads differ");
    candela_image_free(&on.img);
    candela_image_free(&off.img);
    candela_image_free(&on1.img);

    /* (l) every estimator combination on this heterogeneous, scattering, emitting volume with
     * cache points: in-scattering sampling off / on, emission sampling off / on, all agree
     * with the power sampler's image (the volume lights itself and the floor; multiple
     * scattering) */
    write_mesh_gltf("lumpy_through.gltf",
                    "[{\"name\": \"camera\", \"translation\": [0.1, 2.6, 0], \"rotation\": [-0.70710678, 0, 0, 0.70710678], "
                    "\"camera\": 0}, {\"name\": \"floor\", \"mesh\": 1}, {\"name\": \"glow\", \"translation\": [0, 1.0, 0], "
                    "\"extras\": {\"candela_volume\": {\"uri\": \"lumpy.vdb\", \"density_scale\": 2.0, \"albedo\": [0.9, 0.8, 0.7], "
                    "\"anisotropy\": 0.5, \"emission_grid\": \"emission\", \"emission_scale\": 3.0}}}]",
                    "[0, 1, 2]", "{}", "white.exr", NULL);
    g_sampler = CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
    Result combo[4];
    for (int c = 0; c < 4; ++c) {
        g_inscatter = c & 1;
        g_emission_sampling = c >> 1;
        combo[c] = render("lumpy_through.gltf", 256, 64, 2);
    }
    g_inscatter = 1;
    Result combo1 = render("lumpy_through.gltf", 256, 64, 1);
    CHECK(combo[3].img.rgb && combo1.img.rgb && memcmp(combo[3].img.rgb, combo1.img.rgb, 16 * 16 * 3 * sizeof(float)) == 0,
          "in-scattering sampling on a heterogeneous volume: 1 and 2 threads differ");
    candela_image_free(&combo1.img);
    /* both auto choices: the same image in expectation, and bit-identical for 1 and 2 threads
     * (the choices are made from counts in path order, never from clocks) */
    g_inscatter = 2;
    g_emission_sampling = 2;
    Result au2 = render("lumpy_through.gltf", 256, 64, 2), au1 = render("lumpy_through.gltf", 256, 64, 1);
    CHECK(au2.img.rgb && au1.img.rgb && memcmp(au2.img.rgb, au1.img.rgb, 16 * 16 * 3 * sizeof(float)) == 0,
          "auto choices: 1 and 2 threads differ");
    candela_image_free(&au1.img);
    g_inscatter = 0;
    g_emission_sampling = 1;
    g_sampler = CANDELA_LIGHT_SAMPLER_POWER;
    Result ref = render("lumpy_through.gltf", 1024, 64, 2);
    {
        double ta = 5.0 * sqrt(au2.se * au2.se + ref.se * ref.se);
        fprintf(stderr, "  (l) cache points, both auto: %.5f (SE %.5f) vs %.5f\n", au2.mean, au2.se, ref.mean);
        CHECK(fabs(au2.mean - ref.mean) <= ta, "auto choices: %.5f vs %.5f (tolerance %.5f)", au2.mean, ref.mean, ta);
        candela_image_free(&au2.img);
    }
    for (int c = 0; c < 4; ++c) {
        double tc = 5.0 * sqrt(combo[c].se * combo[c].se + ref.se * ref.se);
        fprintf(stderr, "  (l) cache points, in-scattering %s, emission sampling %s: %.5f (SE %.5f) vs %.5f\n",
                c & 1 ? "on" : "off", c >> 1 ? "on" : "off", combo[c].mean, combo[c].se, ref.mean);
        CHECK(fabs(combo[c].mean - ref.mean) <= tc, "combination %d: %.5f vs %.5f (tolerance %.5f)", c, combo[c].mean,
              ref.mean, tc);
        candela_image_free(&combo[c].img);
    }
    candela_image_free(&ref.img);
}

static void test_mesh_media(void) {
    const double sa = 1.2;
    /* (f) looking through an absorbing fog cube (an invisible boundary) at a white sky: the
     * camera at z = 3, orthographic rays down -Z cross 1 m of medium */
    write_mesh_gltf("fog_cube.gltf",
                    "[{\"name\": \"camera\", \"translation\": [0, 0, 3], \"camera\": 0}, {\"name\": \"cube\", \"mesh\": 0}]",
                    "[0, 1]", "{\"sigma_a\": [1.2, 1.2, 1.2]}", "white.exr", NULL);
    Result f = render("fog_cube.gltf", 256, 8, 2);
    expect("(f) through a mesh medium", f, exp(-sa), 0.0);
    candela_image_free(&f.img);
    /* (g) the camera inside the cube, at z = 0.2: 0.7 m to the far face */
    write_mesh_gltf("fog_inside.gltf",
                    "[{\"name\": \"camera\", \"translation\": [0, 0, 0.2], \"camera\": 0}, {\"name\": \"cube\", \"mesh\": 0}]",
                    "[0, 1]", "{\"sigma_a\": [1.2, 1.2, 1.2]}", "white.exr", NULL);
    Result g = render("fog_inside.gltf", 256, 8, 2);
    expect("(g) camera inside the medium", g, exp(-sa * 0.7), 0.0);
    candela_image_free(&g.img);
    /* (h) shadow rays through a mesh medium: a Lambert floor (albedo 0.5) under a sun shining
     * straight down through a fog slab (the cube scaled to 6 x 1 x 6 m) and seen from straight
     * above through it: L = albedo / pi x E x T_sun x T_view, T = exp(-sigma_a x 1 m) each way
     * (--max-depth 1 keeps indirect light out) */
    write_mesh_gltf("fog_sun.gltf",
                    "[{\"name\": \"camera\", \"translation\": [0, 3, 0], \"rotation\": [-0.70710678, 0, 0, 0.70710678], "
                    "\"camera\": 0}, {\"name\": \"cube\", \"mesh\": 0, \"translation\": [0, 1, 0], \"scale\": [6, 1, 6]}, "
                    "{\"name\": \"floor\", \"mesh\": 1}, {\"name\": \"sun\", \"rotation\": [-0.70710678, 0, 0, 0.70710678], "
                    "\"extensions\": {\"KHR_lights_punctual\": {\"light\": 0}}}]",
                    "[0, 1, 2, 3]", "{\"sigma_a\": [0.7, 0.7, 0.7]}", "black.exr",
                    "\n\"extensions\": {\"KHR_lights_punctual\": {\"lights\": [{\"type\": \"directional\", "
                    "\"color\": [1, 1, 1], \"intensity\": 3.0}]}},");
    Result h = render_depth("fog_sun.gltf", 256, 1);
    expect("(h) shadow rays through a medium", h, 0.5 / M_PI * 3.0 * exp(-0.7) * exp(-0.7), 0.0);
    candela_image_free(&h.img);
}

int main(void) {
    snprintf(g_dir, sizeof g_dir, "/tmp/candela-test-volumes-XXXXXX");
    if (!mkdtemp(g_dir)) { perror("mkdtemp"); return 1; }
    write_env("white.exr", 1.0f);
    write_env("black.exr", 0.0f);
    write_box_vdb("box.vdb", 0);
    write_box_vdb("glow.vdb", 1);

    /* (a) transmittance, xmag 0.3: every camera ray crosses the full 1 m box */
    const float sigma = 1.5f;
    write_gltf("absorb.gltf", "{\"uri\": \"box.vdb\", \"density_scale\": 1.5, \"albedo\": [0, 0, 0]}", "white.exr",
               NULL, 0.0f, 0.3f);
    Result a = render("absorb.gltf", 512, 8, 2);
    expect("(a) transmittance", a, exp(-sigma), 0.0);
    candela_image_free(&a.img);

    /* (b) emission of an absorber: L = Le (1 - exp(-tau)) */
    write_gltf("glow.gltf",
               "{\"uri\": \"glow.vdb\", \"density_scale\": 1.5, \"albedo\": [0, 0, 0], \"emission_grid\": \"emission\", "
               "\"emission_scale\": 2.0, \"emission_color\": [1, 1, 1]}",
               "black.exr", NULL, 0.0f, 0.3f);
    Result b = render("glow.gltf", 512, 8, 2);
    expect("(b) emission", b, 2.0 * (1.0 - exp(-sigma)), 0.0);
    candela_image_free(&b.img);

    /* (c) single scattering of a point light inside the box, black environment: along the
     * central camera rays (xmag 0.05), L = int T(cam, x) sigma_s p_iso I / r^2 T(x, light) dt */
    const float lp[3] = {0.2f, 0.1f, 0.0f};
    const float I = 1.0f;
    const double sigma_s = 0.8;
    write_gltf("single.gltf", "{\"uri\": \"box.vdb\", \"density_scale\": 0.8, \"albedo\": [1, 1, 1]}", "black.exr", lp,
               I, 0.05f);
    Result c = render("single.gltf", 1024, 1, 2);
    {
        /* the image mean is the average over the 0.1 m square the 16x16 pixels cover: the
         * quadrature averages 16x16 rays over the same square (the integrand is smooth there) */
        double acc = 0.0;
        int rays = 0;
        enum { RAYS = 16, STEPS = 800 };
        for (int py = 0; py < RAYS; ++py)
            for (int px = 0; px < RAYS; ++px) {
                double x = -0.05 + 0.1 * (px + 0.5) / RAYS, y = 0.05 - 0.1 * (py + 0.5) / RAYS;
                double z0 = 0.5 + 2 * H, z1 = -0.5 - 2 * H, dz = (z0 - z1) / STEPS;
                double sum = 0.0, tau_cam = 0.0; /* nothing but the box is in the medium */
                for (int i = 0; i < STEPS; ++i) {
                    double z = z0 - (i + 0.5) * dz;
                    double dens = box_density(x, y, z);
                    double tau_here = tau_cam + 0.5 * sigma_s * dens * dz; /* up to the step's midpoint */
                    tau_cam += sigma_s * dens * dz;
                    if (dens <= 0.0) continue;
                    double p[3] = {x, y, z}, l[3] = {lp[0], lp[1], lp[2]};
                    double r2 = (p[0] - l[0]) * (p[0] - l[0]) + (p[1] - l[1]) * (p[1] - l[1]) + (p[2] - l[2]) * (p[2] - l[2]);
                    double tr = exp(-tau_here - optical_depth(sigma_s, p, l));
                    sum += tr * sigma_s * dens * (1.0 / (4.0 * M_PI)) * I / r2 * dz;
                }
                acc += sum;
                ++rays;
            }
        expect("(c) single scattering", c, acc / rays, 0.01 * acc / rays);
        /* (k) the same with cache points, without and with cache-point in-scattering sampling
         * (§4.2): both converge to the quadrature, and in-scattering sampling is less noisy
         * in this thin medium at equal samples */
        g_sampler = CANDELA_LIGHT_SAMPLER_CACHEPOINTS;
        Result k0 = render("single.gltf", 1024, 1, 2);
        g_inscatter = 1;
        Result k1 = render("single.gltf", 1024, 1, 2);
        Result k2 = render("single.gltf", 1024, 1, 1);
        g_inscatter = 0;
        g_sampler = CANDELA_LIGHT_SAMPLER_POWER;
        expect("(k) cache points, tracking", k0, acc / rays, 0.01 * acc / rays);
        expect("(k) in-scattering sampling", k1, acc / rays, 0.01 * acc / rays);
        fprintf(stderr, "  (k) SE tracking %.6f, with in-scattering sampling %.6f\n", k0.se, k1.se);
        CHECK(k1.se < k0.se, "in-scattering sampling is not less noisy: SE %.6f vs %.6f", k1.se, k0.se);
        CHECK(k1.img.rgb && k2.img.rgb && memcmp(k1.img.rgb, k2.img.rgb, 16 * 16 * 3 * sizeof(float)) == 0,
              "in-scattering sampling: 1 and 2 threads differ");
        /* (l) one light (no environment): power with in-scattering sampling from the light's own
         * estimate (what auto picks for a one-light scene with media, without a cache point
         * build): the quadrature, less noisy than tracking alone, 1 and 2 threads alike */
        write_gltf("single1.gltf", "{\"uri\": \"box.vdb\", \"density_scale\": 0.8, \"albedo\": [1, 1, 1]}", NULL,
                   lp, I, 0.05f);
        g_inscatter = 1;
        Result l1 = render("single1.gltf", 1024, 1, 2);
        Result l2 = render("single1.gltf", 1024, 1, 1);
        g_inscatter = 0;
        Result l0 = render("single1.gltf", 1024, 1, 2);
        expect("(l) power, in-scattering sampling", l1, acc / rays, 0.01 * acc / rays);
        fprintf(stderr, "  (l) SE power tracking %.6f, with in-scattering sampling %.6f\n", l0.se, l1.se);
        CHECK(l1.se < l0.se, "power's in-scattering sampling is not less noisy: SE %.6f vs %.6f", l1.se, l0.se);
        CHECK(l1.img.rgb && l2.img.rgb && memcmp(l1.img.rgb, l2.img.rgb, 16 * 16 * 3 * sizeof(float)) == 0,
              "power's in-scattering sampling: 1 and 2 threads differ");
        candela_image_free(&l0.img);
        candela_image_free(&l1.img);
        candela_image_free(&l2.img);
        candela_image_free(&k0.img);
        candela_image_free(&k1.img);
        candela_image_free(&k2.img);
    }
    candela_image_free(&c.img);

    /* (d) furnace: albedo 1 under a white environment */
    write_gltf("furnace.gltf", "{\"uri\": \"box.vdb\", \"density_scale\": 3.0, \"albedo\": [1, 1, 1], \"anisotropy\": 0.6}",
               "white.exr", NULL, 0.0f, 0.6f);
    Result d = render("furnace.gltf", 256, 256, 2);
    expect("(d) furnace", d, 1.0, 0.0);

    /* (e) determinism across thread counts */
    Result d1 = render("furnace.gltf", 256, 256, 1);
    CHECK(d.img.rgb && d1.img.rgb && memcmp(d.img.rgb, d1.img.rgb, 16 * 16 * 3 * sizeof(float)) == 0,
          "1 and 2 threads differ");
    candela_image_free(&d.img);
    candela_image_free(&d1.img);

    /* (n) volume guiding in the furnace: guided phase sampling keeps L = 1 */
    for (int g = CANDELA_GUIDING_MIS; g <= CANDELA_GUIDING_RIS; ++g) {
        g_guiding = (CandelaGuiding)g;
        Result l = render("furnace.gltf", 128, 256, 2);
        expect(g == CANDELA_GUIDING_MIS ? "(n) furnace, guided MIS" : "(n) furnace, guided RIS", l, 1.0, 0.0);
        CHECK(g_stats.guide_updates > 8 && g_stats.guide_samples > 0, "(n) the volume field trained (%d updates)",
              g_stats.guide_updates);
        Result l1 = render("furnace.gltf", 128, 256, 1);
        CHECK(l.img.rgb && l1.img.rgb && memcmp(l.img.rgb, l1.img.rgb, 16 * 16 * 3 * sizeof(float)) == 0,
              "(n) guided (%d): 1 and 2 threads differ", g);
        candela_image_free(&l.img);
        candela_image_free(&l1.img);
    }
    g_guiding = CANDELA_GUIDING_OFF;

    /* (o) a deep medium: hundreds of bounces per path, the recorder bounded */
    write_gltf("deep.gltf", "{\"uri\": \"box.vdb\", \"density_scale\": 300.0, \"albedo\": [1, 1, 1], \"anisotropy\": 0.3}",
               "white.exr", NULL, 0.0f, 0.6f);
    g_aov = 1;
    g_recorder_mb = 4;
    g_guiding = CANDELA_GUIDING_MIS;
    Result m = render("deep.gltf", 32, 100000, 2);
    expect("(o) deep furnace, recorded", m, 1.0, 0.0);
    double mean_bounces = (double)g_stats.rays_bounce / (double)g_stats.paths;
    fprintf(stderr, "  (o) %.0f bounce rays per path, recorder peak %.2f MiB of a %.2f MiB bound (%u live vertices), "
                    "%llu children refused, path skip %.3f\n",
            mean_bounces, g_stats.recorder_peak_bytes / 1048576.0, g_stats.recorder_bound_bytes / 1048576.0,
            g_stats.recorder_peak_vertices, (unsigned long long)g_stats.recorder_refused, g_stats.recorder_path_skip);
    CHECK(mean_bounces > 100.0, "(o) the medium is deep (%.0f bounces per path)", mean_bounces);
    CHECK(g_stats.recorder_peak_bytes <= g_stats.recorder_bound_bytes && g_stats.recorder_bound_bytes <= (size_t)5 << 20,
          "(o) recorder memory %zu over its bound %zu", g_stats.recorder_peak_bytes, g_stats.recorder_bound_bytes);
    if (m.img.recorder_debug) {
        double dbg = 0.0;
        for (int i = 0; i < 16 * 16 * 3; ++i) dbg += m.img.recorder_debug[i];
        dbg /= 16 * 16 * 3;
        /* the AOV divides by the path recording probability: noisier than the image */
        double tol = 5.0 * m.se / sqrt(fmax(1e-3, 1.0 - g_stats.recorder_path_skip)) + 0.02;
        fprintf(stderr, "  (o) recorder-debug mean %.4f vs image %.4f (tolerance %.4f)\n", dbg, m.mean, tol);
        CHECK(fabs(dbg - m.mean) <= tol, "(o) the recorder-debug AOV %.4f vs the image %.4f", dbg, m.mean);
    } else CHECK(0, "(o) no recorder-debug AOV");
    candela_image_free(&m.img);
    g_aov = 0;
    g_recorder_mb = 0;
    g_guiding = CANDELA_GUIDING_OFF;

    test_mesh_media();
    test_emission_sampling();
    test_emission_sampling_heterogeneous();

    char cmd[600];
    if (getenv("CANDELA_KEEP_TEST_SCENES")) { fprintf(stderr, "scenes kept in %s\n", g_dir); return test_exit(); }
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", g_dir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", g_dir);
    return test_exit();
}
