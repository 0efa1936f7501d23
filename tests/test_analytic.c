/* tests/test_analytic.c: end-to-end renders of scenes with known answers.
 *
 * Usage: test_analytic SCENES_DIR   (the scenes come from scenes/make_scenes.py)
 *
 * Every render is small (32x32 or less) and uses RAW light units (W/sr, W/m^2) unless noted.
 * A pixel of the film is the mean over its samples of radiance along rays jittered uniformly
 * over the pixel (box filter), so the exact value of a pixel is the average of the radiance
 * over the pixel's footprint; for the plane scenes that average is integrated numerically
 * (midpoint rule, 16x16 points per pixel, error < 1e-7 relative).
 *
 * Statistical checks, per channel, with image.variance = the variance of each pixel's mean:
 *   aggregate : |mean over pixels of (pixel - exact)| <= 5 sqrt(sum var) / Npix + floor
 *   per pixel : |pixel - exact| <= 6 sqrt(var) + floor for >= 99% of the pixels
 * floor = 1e-4 |exact| + 1e-6 absorbs float32 rounding where the estimator has no variance
 * (directional light, constant environment). Every value must be finite, variance >= 0.
 *
 * Scenes and exact values (rho = 0.5 Lambert, specularFactor 0, everywhere):
 *   furnace_sphere     closed sphere, Le = 1, albedo a = 0.5, camera at the centre:
 *                      L = Le / (1 - a) = 2. With max_depth D (1 = direct light only) the sum
 *                      is truncated to Le * sum_{k=0}^{D} a^k: 1.5 for D = 1, 1.75 for D = 2
 *                      (checked); max_depth 64 makes the truncation < 1e-19. Russian roulette
 *                      does not bias.
 *   schedule           40 spp with max_iteration_spp 1 (40 iterations) terminates, in a child.
 *   point_plane        point light I = 2 pi W/sr at h = 1 over the plane y = 0:
 *                      L(x) = rho/pi * I * h / r^3, r^2 = h^2 + |x|^2, so L(0) = 1.
 *                      Also rendered with Blender units: exactly 1/683 of that.
 *   spot_plane         the same light as a spot pointing down, every pixel in the inner cone.
 *   spot_blend_plane   a spot of outer 0.9, inner 0.45 rad: glTF's ramp, and with --light-model
 *                      blender3 Cycles 3.4's cos x smoothstep (test_spot_blend).
 *   directional_plane  E = 2 pi W/m^2 at 30 deg from the normal: L = rho/pi E cos 30 = 0.8660254.
 *   area_plane         one-sided square emitter (side 1, height 1, Le = 2, facing down):
 *                      L(x) = rho/pi * E(x) with Lambert's polygon formula
 *                      E = Le/2 * sum_i angle(a_i, a_i+1) * n.unit(a_i x a_i+1); a second emitter
 *                      facing away from the plane must add nothing.
 *   env_constant       camera sees only the constant environment: L = (0.5, 0.75, 1.0).
 *   env_plane          plane under it: irradiance pi Lenv, L = rho Lenv = (0.25, 0.375, 0.5).
 *   coat_plane         env_plane with a smooth clearcoat: (0.04 + 0.96 rho (1 - <Fc>)) Lenv.
 *   env_directions     orthographic cameras (parallel rays) aimed at texel centres of the 8x4
 *                      lat-long env_grid.exr: pixel = texel ((i+1)/8, (j+1)/4, .25 + .5((i+j)%2)).
 *                      Checks Cycles' equirectangular mapping in glTF axes (make_scenes.py
 *                      latlong_dir), unrotated and rotated 75 degrees (extras, --env-rotation).
 *   env_marked         one bright texel seen by a perspective camera where Cycles puts it,
 *                      with rotations 0, +20, -20 degrees (test_env_marked).
 *   normalmap_grazing  normal-mapped planes at grazing view: no black pixel, Lambert within
 *                      its tilted-lobe bounds (test_normalmap_grazing).
 *   two_lights         no exact value: the uniform vs the power and vs the tree light sampler (different seeds)
 *                      must agree: z = (a - b)/sqrt(va + vb) per pixel, mean z^2 within
 *                      1 +- 5 sqrt(2/N), and the mean difference within 5 standard errors.
 *   default            scenes/default.gltf (Blender units) smoke test: renders, finite, sane mean. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "candela.h"
#include "check.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static const char *g_dir = ".";


typedef struct RenderSpec {
    const char *file;        /* relative to g_dir (or absolute when it starts with '/') */
    const char *camera;      /* NULL: first camera */
    int width, height, spp, max_depth; /* max_depth 0: renderer default */
    CandelaLightSampler sampler;
    CandelaLightUnits units;
    uint64_t seed;
    int env_rotation_given;  /* 0: the scene's own rotation (CandelaOptions.env_rotation_deg NaN) */
    float env_rotation_deg;
    CandelaLightModel light_model;
    CandelaMaterialModel material_model;
    CandelaSampler sequence; /* --sampler (0: sobol, the default) */
} RenderSpec;

/* Renders; on failure records a CHECK failure and returns non-zero (image left empty). */
static int render(const RenderSpec *s, CandelaImage *img) {
    CandelaOptions o;
    candela_options_default(&o);
    char path[4096];
    if (s->file[0] == '/')
        snprintf(path, sizeof path, "%s", s->file);
    else
        snprintf(path, sizeof path, "%s/%s", g_dir, s->file);
    o.scene_path = path;
    o.camera_name = s->camera;
    o.width = s->width;
    o.height = s->height;
    o.spp = s->spp;
    if (s->max_depth > 0) o.max_depth = s->max_depth;
    o.light_sampler = s->sampler;
    o.light_units = s->units;
    o.seed = s->seed;
    if (s->env_rotation_given) o.env_rotation_deg = s->env_rotation_deg;
    o.light_model = s->light_model;
    o.material_model = s->material_model;
    o.sampler = s->sequence;
    o.threads = 2;
    o.quiet = 1;

    memset(img, 0, sizeof *img);
    CandelaStats st;
    memset(&st, 0, sizeof st);
    char err[CANDELA_ERR_LEN];
    err[0] = 0;
    double t0 = test_seconds();
    int rc = candela_render(&o, img, &st, NULL, err);
    double t = test_seconds() - t0;
    CHECK(rc == 0, "%s: candela_render failed: %s", s->file, err);
    if (rc != 0) return rc;
    CHECK(img->width == s->width && img->height == s->height, "%s: got %dx%d, asked %dx%d",
          s->file, img->width, img->height, s->width, s->height);
    CHECK(img->rgb != NULL && img->variance != NULL, "%s: missing rgb/variance", s->file);
    if (img->width != s->width || img->height != s->height || !img->rgb || !img->variance) return 1;
    fprintf(stderr, "  render %-22s %-10s %dx%d %4d spp depth %2d %s %s: %.2f s, %u tris, %u lights\n",
            s->file, s->camera ? s->camera : "-", s->width, s->height, s->spp, o.max_depth,
            candela_light_sampler_name(s->sampler),
            s->units == CANDELA_LIGHT_UNITS_RAW ? "raw" : "blender", t, st.num_triangles,
            st.num_lights);
    CHECK(t < 30.0, "%s: render took %.1f s", s->file, t);
    return 0;
}

static int all_finite(const char *name, const CandelaImage *img) {
    size_t n = (size_t)img->width * (size_t)img->height * 3;
    size_t bad = 0;
    for (size_t i = 0; i < n; ++i)
        if (!isfinite(img->rgb[i]) || !isfinite(img->variance[i]) || img->variance[i] < 0.0f) ++bad;
    CHECK(bad == 0, "%s: %zu non-finite values or negative variances", name, bad);
    return bad == 0;
}

/* Compares the film with per-pixel exact values (3 per pixel). */
static void compare(const char *name, const CandelaImage *img, const double *exact) {
    const double rel_floor = 1e-4, abs_floor = 1e-6;
    if (!all_finite(name, img)) return;
    int n = img->width * img->height;
    int ok_pixels = 0;
    double worst_excess = 0.0;
    int worst_pixel = -1;
    for (int p = 0; p < n; ++p) {
        int ok = 1;
        for (int c = 0; c < 3; ++c) {
            double v = img->rgb[3 * p + c], e = exact[3 * p + c];
            double tol = 6.0 * sqrt((double)img->variance[3 * p + c]) + rel_floor * fabs(e) + abs_floor;
            double excess = fabs(v - e) / tol;
            if (excess > 1.0) ok = 0;
            if (excess > 1.0 && getenv("ANALYTIC_VERBOSE"))
                fprintf(stderr, "    %s: pixel (%d,%d) ch%d value %.6g exact %.6g sigma %.3g z %.1f\n", name,
                        p % img->width, p / img->width, c, v, e, sqrt((double)img->variance[3 * p + c]),
                        (v - e) / sqrt((double)img->variance[3 * p + c]));
            if (excess > worst_excess) { worst_excess = excess; worst_pixel = p; }
        }
        ok_pixels += ok;
    }
    CHECK(ok_pixels >= (int)ceil(0.99 * n),
          "%s: only %d of %d pixels within 6 sigma (worst: pixel (%d,%d) rgb %g %g %g exact %g %g %g)",
          name, ok_pixels, n, worst_pixel % img->width, worst_pixel / img->width,
          img->rgb[3 * worst_pixel], img->rgb[3 * worst_pixel + 1], img->rgb[3 * worst_pixel + 2],
          exact[3 * worst_pixel], exact[3 * worst_pixel + 1], exact[3 * worst_pixel + 2]);
    for (int c = 0; c < 3; ++c) {
        double sd = 0, sv = 0, se = 0, sr = 0;
        for (int p = 0; p < n; ++p) {
            sd += img->rgb[3 * p + c] - exact[3 * p + c];
            sv += img->variance[3 * p + c];
            se += fabs(exact[3 * p + c]);
            sr += img->rgb[3 * p + c];
        }
        double mean_d = sd / n, se_mean = sqrt(sv) / n;
        double tol = 5.0 * se_mean + rel_floor * se / n + abs_floor;
        CHECK(fabs(mean_d) <= tol, "%s: channel %d mean %.7g, exact %.7g: bias %.3g > tol %.3g",
              name, c, sr / n, se / n, mean_d, tol);
        fprintf(stderr, "  %-28s ch%d mean %.6f exact %.6f (diff %+.2e, stderr %.2e)\n", name, c,
                sr / n, se / n, mean_d, se_mean);
    }
    fprintf(stderr, "  %-28s %d/%d pixels within 6 sigma\n", name, ok_pixels, n);
}

static double *constant_exact(int n, double r, double g, double b) {
    double *e = malloc(sizeof(double) * 3 * (size_t)n);
    for (int p = 0; p < n; ++p) { e[3 * p] = r; e[3 * p + 1] = g; e[3 * p + 2] = b; }
    return e;
}

/* Exact pixel values for the top orthographic camera (x, z in [-mag, mag], image right = +x,
 * image up = -z) over the plane y = 0: footprint average of f(x, z), 16x16 midpoint rule. */
typedef double (*PlaneFn)(double x, double z);
static double *plane_exact(int w, int h, double mag, PlaneFn f, double scale_) {
    double *e = malloc(sizeof(double) * 3 * (size_t)w * (size_t)h);
    const int sub = 16;
    for (int py = 0; py < h; ++py)
        for (int px = 0; px < w; ++px) {
            double sum = 0;
            for (int j = 0; j < sub; ++j)
                for (int i = 0; i < sub; ++i) {
                    double sx = (px + (i + 0.5) / sub) / w, sy = (py + (j + 0.5) / sub) / h;
                    double x = mag * (2 * sx - 1), z = mag * (2 * sy - 1); /* z: top row is -z */
                    sum += f(x, z);
                }
            double v = scale_ * sum / (sub * sub);
            for (int c = 0; c < 3; ++c) e[3 * (py * w + px) + c] = v;
        }
    return e;
}

static double point_light_L(double x, double z) {
    const double rho = 0.5, I = 2 * M_PI, h = 1.0;
    double r2 = h * h + x * x + z * z;
    return rho / M_PI * I * h / (r2 * sqrt(r2));
}

/* Irradiance at (x, 0, z), normal +y, from the square [-.5,.5]^2 at y = 1 with radiance Le. */
static double square_irradiance(double x, double z, double Le) {
    const double v[4][3] = {{-0.5, 1, -0.5}, {0.5, 1, -0.5}, {0.5, 1, 0.5}, {-0.5, 1, 0.5}};
    double a[4][3];
    for (int i = 0; i < 4; ++i) {
        double d[3] = {v[i][0] - x, v[i][1], v[i][2] - z};
        double l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        for (int k = 0; k < 3; ++k) a[i][k] = d[k] / l;
    }
    double sum = 0;
    for (int i = 0; i < 4; ++i) {
        const double *p = a[i], *q = a[(i + 1) % 4];
        double cr[3] = {p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]};
        double cl = sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        double ang = acos(fmax(-1.0, fmin(1.0, p[0] * q[0] + p[1] * q[1] + p[2] * q[2])));
        sum += ang * cr[1] / cl; /* n = +y */
    }
    return Le * 0.5 * fabs(sum);
}

static double area_light_L(double x, double z) { return 0.5 / M_PI * square_irradiance(x, z, 2.0); }

/* 256 spp: path lengths are geometric, so with few samples the pixels that drew no long path
 * under-estimate their own variance (64 spp puts ~1% of the pixels beyond 6 sigma). */
static void test_furnace(void) {
    RenderSpec s = {"furnace_sphere.gltf", NULL, 32, 32, 256, 64, CANDELA_LIGHT_SAMPLER_POWER,
                    CANDELA_LIGHT_UNITS_RAW, 1};
    CandelaImage img;
    if (render(&s, &img) == 0) {
        double *e = constant_exact(32 * 32, 2.0, 2.0, 2.0);
        compare("furnace_sphere", &img, e);
        free(e);
    }
    candela_image_free(&img);

    /* max_depth 2: emission + 2 bounces = Le (1 + a + a^2) = 1.75 (pins the depth convention:
     * 1.5 or 1.875 would be off by hundreds of standard errors) */
    RenderSpec s2 = {"furnace_sphere.gltf", NULL, 32, 32, 64, 2, CANDELA_LIGHT_SAMPLER_POWER,
                     CANDELA_LIGHT_UNITS_RAW, 2};
    if (render(&s2, &img) == 0) {
        double *e = constant_exact(32 * 32, 1.75, 1.75, 1.75);
        compare("furnace_sphere (max_depth 2)", &img, e);
        free(e);
    }
    candela_image_free(&img);
}

/* The spp schedule 1, 1, 2, 4, ... capped by max_iteration_spp must sum to spp however many
 * iterations it takes (more than 32 iterations once overflowed "1 << (iteration - 1)" and never
 * finished). Runs in a child process with an alarm so a hang fails instead of stalling. */
static void test_schedule(void) {
    pid_t pid = fork();
    if (pid < 0) {
        CHECK(pid >= 0, "fork failed");
        return;
    }
    if (pid == 0) {
        alarm(30);
        CandelaOptions o;
        candela_options_default(&o);
        char path[4096];
        snprintf(path, sizeof path, "%s/directional_plane.gltf", g_dir);
        o.scene_path = path;
        o.width = 2;
        o.height = 2;
        o.spp = 40;
        o.max_iteration_spp = 1;
        o.light_units = CANDELA_LIGHT_UNITS_RAW;
        o.threads = 2;
        o.quiet = 1;
        CandelaImage img;
        CandelaStats st;
        memset(&st, 0, sizeof st);
        char err[CANDELA_ERR_LEN];
        err[0] = 0;
        if (candela_render(&o, &img, &st, NULL, err) != 0) {
            fprintf(stderr, "FAIL schedule: %s\n", err);
            _exit(1);
        }
        int ok = st.iterations == 40 && fabs(img.rgb[0] - cos(M_PI / 6)) < 1e-4;
        if (!ok) fprintf(stderr, "FAIL schedule: %d iterations (expected 40), pixel %g\n", st.iterations, img.rgb[0]);
        candela_image_free(&img);
        _exit(ok ? 0 : 1);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    CHECK(WIFEXITED(status) && WEXITSTATUS(status) == 0,
          "schedule: 40 spp with max_iteration_spp 1 %s", WIFSIGNALED(status) ? "hung (killed by alarm)" : "failed");
    fprintf(stderr, "  schedule: 40 spp in 40 iterations of 1 spp %s\n",
            WIFEXITED(status) && WEXITSTATUS(status) == 0 ? "ok" : "FAILED");
}

static void check_top_aovs(const char *name, const CandelaImage *img, double depth) {
    int n = img->width * img->height, bad_depth = 0, bad_normal = 0, bad_albedo = 0;
    for (int p = 0; p < n; ++p) {
        if (img->depth && !(fabs(img->depth[p] - depth) <= 1e-3 * depth)) ++bad_depth;
        if (img->normal && !(fabs(img->normal[3 * p + 1] - 1.0) <= 1e-3)) ++bad_normal;
        if (img->albedo)
            for (int c = 0; c < 3; ++c)
                if (!(fabs(img->albedo[3 * p + c] - 0.5) <= 1e-3)) { ++bad_albedo; break; }
    }
    CHECK(bad_depth == 0, "%s: %d pixels with depth != %g", name, bad_depth, depth);
    CHECK(bad_normal == 0, "%s: %d pixels with normal != +y", name, bad_normal);
    CHECK(bad_albedo == 0, "%s: %d pixels with albedo != 0.5", name, bad_albedo);
}

static void test_plane(const char *file, const char *name, PlaneFn f, double scale_,
                       CandelaLightUnits units, double cam_height) {
    RenderSpec s = {file, NULL, 32, 32, 64, 0, CANDELA_LIGHT_SAMPLER_POWER, units, 7};
    CandelaImage img;
    if (render(&s, &img) == 0) {
        double *e = plane_exact(32, 32, 1.0, f, scale_);
        compare(name, &img, e);
        check_top_aovs(name, &img, cam_height);
        free(e);
    }
    candela_image_free(&img);
}

/* spot_blend_plane: the spot of point_plane (1 m up, 2 pi W/sr, Lambert 0.5 below) with outer
 * cone 0.9 rad and inner 0.45 rad, as Blender's glTF exporter writes spot size 1.8 rad, blend
 * 0.5. L = rho/pi I falloff(c) c / r^2 with c = h / r. glTF: falloff = t^2, t the linear ramp
 * in cos from the outer to the inner cone. Blender 3.4 (--light-model blender3): Cycles' spot
 * is c smoothstep((c - cos outer) / w), w = (1 - cos outer) blend, blend = 1 - inner / outer
 * (the exporter's inverse); Blender 3.4.1's Cycles renders this scene to these values within
 * 0.1% (README). */
static double spot_blend_falloff_gltf(double c) {
    double co = cos(0.9), ci = cos(0.45);
    double t = (c - co) / (ci - co);
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    return t * t;
}
static double spot_blend_falloff_blender3(double c) {
    double co = cos(0.9), w = (1.0 - co) * (1.0 - 0.45 / 0.9), t = c - co;
    if (t <= 0) return 0.0;
    if (t >= w) return c;
    double x = t / w;
    return c * x * x * (3.0 - 2.0 * x);
}
static double spot_blend_L(double x, double z, double (*falloff)(double)) {
    const double rho = 0.5, I = 2 * M_PI, h = 1.0;
    double r2 = h * h + x * x + z * z, c = h / sqrt(r2);
    return rho / M_PI * I * falloff(c) * c / r2;
}
static double spot_blend_L_gltf(double x, double z) { return spot_blend_L(x, z, spot_blend_falloff_gltf); }
static double spot_blend_L_blender3(double x, double z) { return spot_blend_L(x, z, spot_blend_falloff_blender3); }

static void test_spot_blend(void) {
    for (int k = 0; k < 2; ++k) {
        RenderSpec s = {"spot_blend_plane.gltf", NULL, 32, 32, 64, 0, CANDELA_LIGHT_SAMPLER_POWER,
                        CANDELA_LIGHT_UNITS_RAW, 7, 0, 0.0f,
                        k ? CANDELA_LIGHT_MODEL_BLENDER3 : CANDELA_LIGHT_MODEL_GLTF};
        CandelaImage img;
        if (render(&s, &img) == 0) {
            double *e = plane_exact(32, 32, 1.5, k ? spot_blend_L_blender3 : spot_blend_L_gltf, 1.0);
            compare(k ? "spot_blend_plane (blender3)" : "spot_blend_plane (gltf)", &img, e);
            free(e);
            /* the models differ where the test can see it, in the blend ring: the other model's
             * values must be far (6 sigma) from many pixels */
            double *other = plane_exact(32, 32, 1.5, k ? spot_blend_L_gltf : spot_blend_L_blender3, 1.0);
            int far = 0;
            for (int p = 0; p < 32 * 32; ++p)
                far += fabs(img.rgb[3 * p] - other[3 * p]) > 6.0 * sqrt((double)img.variance[3 * p]) + 1e-4;
            fprintf(stderr, "  spot_blend_plane: %d of 1024 pixels reject the other model\n", far);
            CHECK(far >= 100, "spot_blend_plane: only %d pixels tell the models apart", far);
            free(other);
        }
        candela_image_free(&img);
    }
}

static double directional_L(double x, double z) {
    (void)x; (void)z;
    return 0.5 / M_PI * 2 * M_PI * cos(M_PI / 6);
}

/* env_marked: a 64x32 environment, black but texel (18, 14) of radiance 1, seen by a 90-degree
 * perspective camera at the origin looking down -Z (32x32 pixels, top row first). The texel's
 * centre direction is derived here from Cycles' equirectangular_to_direction in Blender's axes
 * (phi = pi - 2 pi u, theta = pi v_top, d_b = (sin theta cos phi, sin theta sin phi, cos theta)),
 * a world Mapping node's Z rotation rho (lookup Rz(rho) d: the world direction turns by -rho),
 * glTF = (x_b, z_b, -y_b), and the pinhole projection. The image's brightness centroid must
 * lie within 1 pixel of that projection (the texel spans ~2 pixels; its footprint's centroid
 * is not exactly its centre's projection), and the image must hold the texel's radiance
 * times its solid angle (energy, with the rotation too: 5 standard errors). The old mapping, 180 degrees off, put
 * the texel behind the camera. */
static void test_env_marked(void) {
    const int W = 64, H = 32, mi = 18, mj = 14, R = 32;
    const float rotations[] = {0.0f, 20.0f, -20.0f};
    for (size_t q = 0; q < sizeof rotations / sizeof rotations[0]; ++q) {
        double u = (mi + 0.5) / W, v = (mj + 0.5) / H;
        double phi = M_PI - 2.0 * M_PI * u - rotations[q] * M_PI / 180.0, theta = M_PI * v;
        double xb = sin(theta) * cos(phi), yb = sin(theta) * sin(phi), zb = cos(theta);
        double x = xb, y = zb, z = -yb; /* glTF */
        /* pinhole looking down -Z, tan(45 deg) = 1, aspect 1: film x right, y down */
        double px = (x / -z + 1.0) * 0.5 * R, py = (1.0 - y / -z) * 0.5 * R;
        CHECK(z < 0 && px > 2 && px < R - 2 && py > 2 && py < R - 2, "marked texel outside the view (%g, %g)", px, py);
        RenderSpec s = {"env_marked.gltf", NULL, R, R, 16, 0, CANDELA_LIGHT_SAMPLER_POWER, CANDELA_LIGHT_UNITS_RAW, 7,
                        1, rotations[q]};
        CandelaImage img;
        if (render(&s, &img) != 0) { candela_image_free(&img); continue; }
        double sum = 0, cx = 0, cy = 0, energy = 0, energy_var = 0;
        for (int j = 0; j < R; ++j)
            for (int i = 0; i < R; ++i) {
                double L = img.rgb[3 * (j * R + i)];
                sum += L;
                cx += L * (i + 0.5);
                cy += L * (j + 0.5);
                /* a pixel's solid angle: (2/R)^2 over |film point|^3 on the plane at distance 1 */
                double fx = (i + 0.5) * 2.0 / R - 1.0, fy = (j + 0.5) * 2.0 / R - 1.0;
                double sr = (4.0 / (R * R)) / pow(1.0 + fx * fx + fy * fy, 1.5);
                energy += L * sr;
                energy_var += sr * sr * img.variance[3 * (j * R + i)];
            }
        double texel_sr = (2.0 * M_PI / W) * (cos(M_PI * mj / H) - cos(M_PI * (mj + 1) / H));
        CHECK(sum > 0, "env_marked rotation %g: black image", (double)rotations[q]);
        if (sum > 0) {
            cx /= sum;
            cy /= sum;
            fprintf(stderr, "  env_marked rotation %+g: centroid (%.2f, %.2f), Cycles' direction at (%.2f, %.2f); "
                    "energy %.5f +- %.5f sr, texel %.5f sr\n", (double)rotations[q], cx, cy, px, py, energy,
                    sqrt(energy_var), texel_sr);
            CHECK(fabs(cx - px) <= 1.0 && fabs(cy - py) <= 1.0,
                  "env_marked rotation %g: marked texel at (%.2f, %.2f), Cycles puts it at (%.2f, %.2f)",
                  (double)rotations[q], cx, cy, px, py);
            /* 5 standard errors of the pixel sums, plus 1% for the pixel-centre solid angles */
            CHECK(fabs(energy - texel_sr) <= 5.0 * sqrt(energy_var) + 0.01 * texel_sr, "env_marked rotation %g: %.5f sr of radiance 1, texel %.5f sr",
                  (double)rotations[q], energy, texel_sr);
        }
        candela_image_free(&img);
    }
}

/* plastic_plane (scenes/make_scenes.py): a smooth plastic plane (rho 0.5, F0 0.04) under the
 * constant environment, seen orthographically from straight above (wo = n at every pixel), in
 * both material models (renderer/materials/bsdf.h):
 *   gltf      L = (F(1) + rho Dg) Lenv, Dg = int (1 - F(h.n)) cos / pi = 2 int_0^1 (1 - F(sqrt((1+u)/2))) u du
 *             (h.n = cos(theta_i / 2)), F Schlick of F0 0.04; the smooth mirror reflects F(1) Lenv;
 *   blender3  L = (Fr(1, 1.5) + rho (1 - 1/42)) Lenv: Principled v1's Specular 0.5 mirror (Cycles'
 *             blend is the exact Fresnel, 0.04 at normal incidence) added on top of the Disney
 *             diffuse, whose albedo at roughness 0 and wo = n is 1 - 1/42.
 * Principled v1 is the brighter, by the ratio of the two closed forms (checked through both
 * images against their exact values, with the renderer's variance-derived tolerances). */
static void test_material_models(void) {
    double dg = 0.0;
    for (int k = 0; k < 4096; ++k) { /* midpoint rule, error ~1e-8 */
        double u = (k + 0.5) / 4096.0, c = sqrt(0.5 * (1.0 + u));
        dg += 2.0 * (1.0 - (0.04 + 0.96 * pow(1.0 - c, 5.0))) * u / 4096.0;
    }
    const double rho = 0.5, lenv[3] = {0.5, 0.75, 1.0};
    const double k_gltf = 0.04 + rho * dg, k_b3 = 0.04 + rho * (41.0 / 42.0);
    fprintf(stderr, "  plastic_plane: gltf %.6f, blender3 %.6f x Lenv (ratio %.5f)\n", k_gltf, k_b3, k_b3 / k_gltf);
    double mean[2] = {0.0, 0.0};
    for (int model = 0; model < 2; ++model) {
        RenderSpec s = {"plastic_plane.gltf", NULL, 16, 16, 256, 0, CANDELA_LIGHT_SAMPLER_POWER, CANDELA_LIGHT_UNITS_RAW, 6};
        s.material_model = model ? CANDELA_MATERIAL_MODEL_BLENDER3 : CANDELA_MATERIAL_MODEL_GLTF;
        CandelaImage img;
        if (render(&s, &img) == 0) {
            double k = model ? k_b3 : k_gltf;
            double *e = constant_exact(16 * 16, k * lenv[0], k * lenv[1], k * lenv[2]);
            compare(model ? "plastic_plane --material-model blender3" : "plastic_plane --material-model gltf", &img, e);
            for (int p = 0; p < 16 * 16; ++p) mean[model] += img.rgb[3 * p + 2] / (16.0 * 16.0);
            free(e);
        }
        candela_image_free(&img);
    }
    CHECK(mean[1] > mean[0], "plastic_plane: blender3 mean %.6f not above gltf %.6f", mean[1], mean[0]);
}

static void test_env(void) {
    RenderSpec s = {"env_constant.gltf", NULL, 32, 32, 16, 0, CANDELA_LIGHT_SAMPLER_POWER,
                    CANDELA_LIGHT_UNITS_RAW, 3};
    CandelaImage img;
    if (render(&s, &img) == 0) {
        double *e = constant_exact(32 * 32, 0.5, 0.75, 1.0);
        compare("env_constant", &img, e);
        free(e);
        int finite_depth = 0;
        for (int p = 0; p < 32 * 32; ++p)
            if (img.depth && isfinite(img.depth[p])) ++finite_depth;
        CHECK(finite_depth == 0, "env_constant: %d pixels hit something", finite_depth);
    }
    candela_image_free(&img);

    RenderSpec s2 = {"env_plane.gltf", NULL, 32, 32, 64, 0, CANDELA_LIGHT_SAMPLER_POWER,
                     CANDELA_LIGHT_UNITS_RAW, 4};
    if (render(&s2, &img) == 0) {
        double *e = constant_exact(32 * 32, 0.25, 0.375, 0.5);
        compare("env_plane", &img, e);
        check_top_aovs("env_plane", &img, 3.0);
        free(e);
    }
    candela_image_free(&img);
    /* coat_plane: the same with a smooth clearcoat (the BSDF's closed form, tests/test_bsdf.c):
     * KHR_materials_clearcoat's fresnel_coat at wo = n: L = (0.04 + 0.96 rho) Lenv */
    RenderSpec s3 = {"coat_plane.gltf", NULL, 32, 32, 64, 0, CANDELA_LIGHT_SAMPLER_POWER, CANDELA_LIGHT_UNITS_RAW, 4};
    if (render(&s3, &img) == 0) {
        double k = 0.04 + 0.96 * 0.5;
        double *e = constant_exact(32 * 32, 0.5 * k, 0.75 * k, 1.0 * k);
        compare("coat_plane", &img, e);
        free(e);
    }
    candela_image_free(&img);

    /* Each camera looks at a texel centre of the 8x4 grid along the direction Cycles maps it
     * to (scenes/make_scenes.py latlong_dir); "rot_" cameras for the environment turned by 75
     * degrees (Blender's Mapping node Z rotation), from the extras or from --env-rotation. */
    static const int texels[][2] = {{0, 1}, {1, 2}, {2, 1}, {3, 0}, {4, 2}, {5, 3}, {6, 1}, {7, 2}};
    static const struct {
        const char *file, *prefix;
        int given;
        float deg;
    } cases[] = {
        {"env_directions.gltf", "texel", 0, 0.0f},           /* no rotation */
        {"env_directions_rot.gltf", "rot_texel", 0, 0.0f},   /* extras rotation 75 */
        {"env_directions.gltf", "rot_texel", 1, 75.0f},      /* --env-rotation 75 */
        {"env_directions.gltf", "rot_texel", 1, 75.0f - 720.0f}, /* whole turns do nothing */
        {"env_directions_rot.gltf", "texel", 1, 0.0f},       /* --env-rotation 0 overrides the extras */
    };
    for (size_t q = 0; q < sizeof cases / sizeof cases[0]; ++q) {
        for (size_t k = 0; k < sizeof texels / sizeof texels[0]; ++k) {
            int i = texels[k][0], j = texels[k][1];
            char cam[32], name[128];
            snprintf(cam, sizeof cam, "%s_%d_%d", cases[q].prefix, i, j);
            snprintf(name, sizeof name, "env_directions %s %s (--env-rotation %s%g)", cases[q].file, cam,
                     cases[q].given ? "" : "none, ", cases[q].given ? (double)cases[q].deg : 0.0);
            RenderSpec sd = {cases[q].file, cam, 4, 4, 4, 0, CANDELA_LIGHT_SAMPLER_POWER,
                             CANDELA_LIGHT_UNITS_RAW, 5, cases[q].given, cases[q].deg};
            if (render(&sd, &img) == 0) {
                double *e = constant_exact(16, (i + 1) / 8.0, (j + 1) / 4.0, 0.25 + 0.5 * ((i + j) % 2));
                /* bilinear lookups at a texel centre are exact to float rounding of the direction */
                int bad = 0;
                for (int p = 0; p < 16; ++p)
                    for (int c = 0; c < 3; ++c)
                        if (!(fabs(img.rgb[3 * p + c] - e[3 * p + c]) <= 1e-3)) ++bad;
                CHECK(bad == 0, "%s: expected texel (%d,%d) = %g %g %g, pixel 0 = %g %g %g", name, i, j,
                      e[0], e[1], e[2], img.rgb[0], img.rgb[1], img.rgb[2]);
                free(e);
            }
            candela_image_free(&img);
        }
    }
    test_env_marked();
    test_material_models();
}

/* Compares two renders of the same scene made with different light samplers (uniform as
 * the reference, seed-independent): per-pixel z^2 and the mean difference. With independent
 * samples the variance layer is the error's variance, so the mean z^2 is 1; with Sobol' points
 * it overestimates the error (stratified samples vary less than their sample variance says), so
 * the mean z^2 is at most 1 (one-sided: `stratified`). */
static void compare_samplers(const CandelaImage *a, const CandelaImage *b, const char *bname, int stratified) {
    const int n = a->width * a->height;
    for (int c = 0; c < 3; ++c) {
        double z2 = 0, sd = 0, sv = 0, sa = 0, sb = 0, va_sum = 0, vb_sum = 0;
        int m = 0, exact_mismatch = 0;
        for (int p = 0; p < n; ++p) {
            double x = a->rgb[3 * p + c], y = b->rgb[3 * p + c];
            double va = a->variance[3 * p + c], vb = b->variance[3 * p + c];
            sa += x; sb += y; sd += x - y; sv += va + vb; va_sum += va; vb_sum += vb;
            if (va + vb > 0) {
                z2 += (x - y) * (x - y) / (va + vb);
                ++m;
            } else if (fabs(x - y) > 1e-5 * fmax(fabs(x), fabs(y)) + 1e-7) {
                ++exact_mismatch; /* both noiseless (e.g. the emitter seen directly) */
            }
        }
        CHECK(exact_mismatch == 0, "two_lights %s ch%d: %d noiseless pixels differ", bname, c, exact_mismatch);
        CHECK(m > n / 2, "two_lights %s ch%d: only %d noisy pixels", bname, c, m);
        double mz2 = m ? z2 / m : 0, tol = 5.0 * sqrt(2.0 / (m ? m : 1));
        if (stratified)
            CHECK(mz2 - 1.0 <= tol, "two_lights %s (sobol) ch%d: mean z^2 = %.4f, expected at most 1 + %.3f", bname, c,
                  mz2, tol);
        else
            CHECK(fabs(mz2 - 1.0) <= tol, "two_lights %s ch%d: mean z^2 = %.4f, expected 1 +- %.3f", bname, c, mz2, tol);
        double se = sqrt(sv) / n;
        CHECK(fabs(sd / n) <= 5.0 * se, "two_lights %s ch%d: mean difference %.3g > 5 x stderr %.3g",
              bname, c, sd / n, se);
        fprintf(stderr,
                "  two_lights ch%d: uniform mean %.5f %s mean %.5f diff %+.2e (stderr %.2e), "
                "mean z^2 %.4f over %d px, sum var uniform %.3g %s %.3g\n",
                c, sa / n, bname, sb / n, sd / n, se, mz2, m, va_sum, bname, vb_sum);
    }
}

/* normalmap_grazing (scenes/make_scenes.py): normal-mapped planes under the constant environment
 * (0.5, 0.75, 1) seen 85 degrees from their normal, half their stripes tilted 10 degrees away
 * from the view (the view below their shading hemisphere: black pixels before the shading
 * normal was bent, issue 14). Every pixel sees the plane (depth finite) and must be non-zero.
 * Lambert rho = 0.5: the cosine lobe about a normal tilted by at most 10 degrees, cut by the
 * geometric plane, holds between (1 + cos 10) / 2 and all of rho Lenv: each pixel within those
 * bounds (6 sigma), and the image mean too (5 standard errors): the flat plane's value to 0.8%.
 * White GGX metal: non-zero and at most Lenv (single scattering loses, never gains). */
static void test_normalmap_grazing(void) {
    const double env[3] = {0.5, 0.75, 1.0}, rho = 0.5, tilt = 10.0 * M_PI / 180.0;
    for (int k = 0; k < 2; ++k) {
        const char *cam = k == 0 ? "lambert" : "metal";
        RenderSpec s = {"normalmap_grazing.gltf", cam, 16, 16, 64, 0, CANDELA_LIGHT_SAMPLER_POWER,
                        CANDELA_LIGHT_UNITS_RAW, 11};
        CandelaImage img;
        if (render(&s, &img) != 0) { candela_image_free(&img); continue; }
        const int n = 16 * 16;
        int zeros = 0, missed = 0, out_of_bounds = 0;
        for (int c = 0; c < 3; ++c) {
            double lo = k == 0 ? rho * env[c] * 0.5 * (1.0 + cos(tilt)) : 0.0, hi = k == 0 ? rho * env[c] : env[c];
            double sum = 0, var = 0;
            for (int p = 0; p < n; ++p) {
                double v = img.rgb[3 * p + c], sd = sqrt((double)img.variance[3 * p + c]);
                zeros += v == 0.0;
                if (c == 0) missed += !isfinite(img.depth[p]);
                out_of_bounds += !(v >= lo - 6.0 * sd - 1e-6 && v <= hi + 6.0 * sd + 1e-6);
                sum += v;
                var += img.variance[3 * p + c];
            }
            double mean = sum / n, se = sqrt(var) / n;
            fprintf(stderr, "  normalmap_grazing %-7s ch%d mean %.5f (+- %.5f), bounds [%.5f, %.5f]\n", cam, c, mean,
                    se, lo, hi);
            CHECK(mean >= lo - 5.0 * se && mean <= hi + 5.0 * se, "normalmap_grazing %s ch%d: mean %.5f outside [%.5f, %.5f]",
                  cam, c, mean, lo, hi);
        }
        CHECK(missed == 0, "normalmap_grazing %s: %d pixels miss the plane", cam, missed);
        CHECK(zeros == 0, "normalmap_grazing %s: %d pixel channels are exactly 0 (paths killed at grazing view)", cam,
              zeros);
        CHECK(out_of_bounds == 0, "normalmap_grazing %s: %d pixel channels outside the bounds", cam, out_of_bounds);
        candela_image_free(&img);
    }
}

static void test_samplers(CandelaSampler sequence) {
    const int w = 32, h = 32;
    RenderSpec su = {"two_lights.gltf", NULL, w, h, 256, 0, CANDELA_LIGHT_SAMPLER_UNIFORM,
                     CANDELA_LIGHT_UNITS_RAW, 11};
    su.sequence = sequence;
    int strat = sequence == CANDELA_SAMPLER_SOBOL;
    RenderSpec sp = su;
    sp.sampler = CANDELA_LIGHT_SAMPLER_POWER;
    sp.seed = 12; /* independent samples: same seeds would correlate the two images */
    RenderSpec st = su;
    st.sampler = CANDELA_LIGHT_SAMPLER_TREE;
    st.seed = 13;
    RenderSpec so = su;
    so.sampler = CANDELA_LIGHT_SAMPLER_OPTIMAL;
    so.seed = 14;
    CandelaImage a, b, t, op;
    int ra = render(&su, &a), rb = render(&sp, &b), rt = render(&st, &t), ro = render(&so, &op);
    int fa = ra == 0 && all_finite("two_lights uniform", &a);
    if (fa && rb == 0 && all_finite("two_lights power", &b)) compare_samplers(&a, &b, "power", strat);
    if (fa && rt == 0 && all_finite("two_lights tree", &t)) compare_samplers(&a, &t, "tree", strat);
    if (fa && ro == 0 && all_finite("two_lights optimal", &op)) compare_samplers(&a, &op, "optimal", strat);
    candela_image_free(&op);
    candela_image_free(&a);
    candela_image_free(&b);
    candela_image_free(&t);
}

static void test_default_scene(void) {
    const char *rel = "../../scenes/default.gltf";
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", g_dir, rel);
    FILE *fh = fopen(path, "rb");
    if (!fh) {
        fprintf(stderr, "  (no %s, default-scene smoke test skipped)\n", path);
        return;
    }
    fclose(fh);
    RenderSpec s = {rel, NULL, 48, 36, 16, 0, CANDELA_LIGHT_SAMPLER_POWER,
                    CANDELA_LIGHT_UNITS_BLENDER, 1};
    CandelaImage img;
    if (render(&s, &img) == 0 && all_finite("default", &img)) {
        double sum = 0;
        int n = img.width * img.height;
        for (int i = 0; i < 3 * n; ++i) sum += img.rgb[i];
        double mean = sum / (3.0 * n);
        fprintf(stderr, "  default: mean pixel value %.4f\n", mean);
        CHECK(mean > 0.02 && mean < 5.0, "default: mean pixel value %g is not a sane exposure", mean);
    }
    candela_image_free(&img);
}

int main(int argc, char **argv) {
    if (argc > 1) g_dir = argv[1];
    test_schedule(); /* first: forks before this process has started any threads */
    test_furnace();
    test_plane("point_plane.gltf", "point_plane", point_light_L, 1.0, CANDELA_LIGHT_UNITS_RAW, 3.0);
    test_plane("point_plane.gltf", "point_plane (blender units)", point_light_L, 1.0 / 683.0,
               CANDELA_LIGHT_UNITS_BLENDER, 3.0);
    test_plane("spot_plane.gltf", "spot_plane", point_light_L, 1.0, CANDELA_LIGHT_UNITS_RAW, 3.0);
    test_spot_blend();
    test_plane("directional_plane.gltf", "directional_plane", directional_L, 1.0,
               CANDELA_LIGHT_UNITS_RAW, 3.0);
    test_plane("area_plane.gltf", "area_plane", area_light_L, 1.0, CANDELA_LIGHT_UNITS_RAW, 0.5);
    test_env();
    test_normalmap_grazing();
    test_samplers(CANDELA_SAMPLER_INDEPENDENT); /* the variance layer is exact */
    test_samplers(CANDELA_SAMPLER_SOBOL);
    test_default_scene();
    return test_exit();
}
