/* tests/test_animation.c: io_scene_pose, the glTF animation sampler (io/animation.c).
 *
 * Channels built by hand on a two-node hierarchy, checked against values derived here
 * independently: STEP holds keys (and switches exactly at a key), LINEAR interpolates, slerp
 * gives the half angle at the midpoint, CUBICSPLINE reproduces a cubic exactly only when its
 * tangents are scaled by the key interval (so t^3 on keys 0 and 2 s catches an unscaled
 * spline), clamping before the first and after the last key, parents compose, lights follow
 * their node, a zero scale hides a mesh and fails a camera's pose naming the node. And posing a loaded scene without
 * animation changes no bit of any transform (the loader's formulas, repeated exactly). */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "check.h"
#include "io.h"

#define NEAR(a, b) (fabs((double)(a) - (double)(b)) < 1e-5)

typedef struct Fixture {
    IoScene scene;
    IoNode nodes[2];
    IoInstance instance;
    IoLight light;
    IoAnimChannel channels[4];
} Fixture;

/* node 0: root, translated by channels; node 1: its child at +1 in z, rotated and scaled by
 * channels; one instance and one light on node 1 */
static void fixture(Fixture *f) {
    memset(f, 0, sizeof *f);
    for (int i = 0; i < 2; ++i) {
        snprintf(f->nodes[i].name, sizeof f->nodes[i].name, "n%d", i);
        f->nodes[i].gltf_node = i;
        f->nodes[i].parent = i - 1;
        f->nodes[i].rotation[3] = 1.0;
        f->nodes[i].scale[0] = f->nodes[i].scale[1] = f->nodes[i].scale[2] = 1.0;
    }
    f->nodes[1].translation[2] = 1.0;
    f->instance.node = 1;
    f->light.node = 1;
    f->scene.nodes = f->nodes;
    f->scene.num_nodes = 2;
    f->scene.instances = &f->instance;
    f->scene.num_instances = 1;
    f->scene.lights = &f->light;
    f->scene.num_lights = 1;
    f->scene.channels = f->channels;
    snprintf(f->scene.path, sizeof f->scene.path, "fixture.gltf");
}

static void pose(Fixture *f, double t) {
    char err[IO_ERR_LEN];
    int rc = io_scene_pose(&f->scene, t, err);
    CHECK(rc == 0, "pose at %g failed: %s", t, err);
}

int main(void) {
    Fixture f;
    char err[IO_ERR_LEN];

    /* STEP and LINEAR translations on the root; the child's offset composes */
    {
        float times[3] = {0.0f, 1.0f, 2.0f};
        float values[9] = {0, 0, 0, 4, 0, 0, 4, 8, 0};
        fixture(&f);
        f.channels[0] = (IoAnimChannel){0, IO_ANIM_TRANSLATION, IO_INTERP_STEP, 3, times, values};
        f.scene.num_channels = 1;
        const double t[5] = {-1.0, 0.999, 1.0, 1.5, 7.0};
        const double x[5] = {0, 0, 4, 4, 4}, y[5] = {0, 0, 0, 0, 8};
        for (int k = 0; k < 5; ++k) {
            pose(&f, t[k]);
            CHECK(NEAR(f.instance.xform[12], x[k]) && NEAR(f.instance.xform[13], y[k]) && NEAR(f.instance.xform[14], 1.0),
                  "STEP at %g: (%g %g %g), expected (%g %g 1)", t[k], f.instance.xform[12], f.instance.xform[13],
                  f.instance.xform[14], x[k], y[k]);
            CHECK(NEAR(f.light.position[0], x[k]) && NEAR(f.light.position[1], y[k]), "the light does not follow at %g", t[k]);
        }
        f.channels[0].interpolation = IO_INTERP_LINEAR;
        const double xl[5] = {0, 4 * 0.999, 4, 4, 4}, yl[5] = {0, 0, 0, 4, 8};
        for (int k = 0; k < 5; ++k) {
            pose(&f, t[k]);
            CHECK(NEAR(f.instance.xform[12], xl[k]) && NEAR(f.instance.xform[13], yl[k]), "LINEAR at %g: (%g %g), expected (%g %g)",
                  t[k], f.instance.xform[12], f.instance.xform[13], xl[k], yl[k]);
        }
    }

    /* slerp: identity to 90 degrees about +Y (keys on opposite hemispheres: the shorter arc);
     * at the midpoint the child is turned 45 degrees, so its local -Z (the light's direction)
     * is (-sin 45, 0, -cos 45) */
    {
        const double h = sqrt(0.5);
        float times[2] = {0.0f, 1.0f};
        float values[8] = {0, 0, 0, 1, 0, -(float)h, 0, -(float)h};
        fixture(&f);
        f.channels[0] = (IoAnimChannel){1, IO_ANIM_ROTATION, IO_INTERP_LINEAR, 2, times, values};
        f.scene.num_channels = 1;
        pose(&f, 0.5);
        const double a = 3.14159265358979 / 4;
        CHECK(NEAR(f.light.direction[0], -sin(a)) && NEAR(f.light.direction[1], 0) && NEAR(f.light.direction[2], -cos(a)),
              "slerp midpoint direction (%g %g %g)", f.light.direction[0], f.light.direction[1], f.light.direction[2]);
        /* a quarter of the way: 22.5 degrees (a normalised lerp would give 18.4) */
        pose(&f, 0.25);
        const double b = 3.14159265358979 / 8;
        CHECK(NEAR(f.light.direction[0], -sin(b)) && NEAR(f.light.direction[2], -cos(b)),
              "slerp quarter direction (%g %g %g)", f.light.direction[0], f.light.direction[1], f.light.direction[2]);
    }

    /* CUBICSPLINE: x(t) = t^3 on keys 0 and 2 s (values 0, 8; derivatives 0, 12 per second).
     * Keys hold (in-tangent, value, out-tangent); the glTF spline scales tangents by the 2 s
     * interval and then reproduces the cubic exactly. y holds a second check: constant 1 with
     * zero tangents. */
    {
        float times[2] = {0.0f, 2.0f};
        float values[18] = {0, 0, 0, 0, 1, 0, 0, 0, 0, /* key 0 */ 12, 0, 0, 8, 1, 0, 12, 0, 0 /* key 1 */};
        fixture(&f);
        f.channels[0] = (IoAnimChannel){0, IO_ANIM_TRANSLATION, IO_INTERP_CUBICSPLINE, 2, times, values};
        f.scene.num_channels = 1;
        const double t[5] = {0.5, 1.0, 1.5, 1.9, 3.0};
        for (int k = 0; k < 5; ++k) {
            double tc = t[k] < 2.0 ? t[k] : 2.0;
            pose(&f, t[k]);
            CHECK(NEAR(f.instance.xform[12], tc * tc * tc) && NEAR(f.instance.xform[13], 1.0),
                  "CUBICSPLINE at %g: x %g, expected %g", t[k], f.instance.xform[12], tc * tc * tc);
        }
    }

    /* scale to zero at 1 s (STEP) on the child: the mesh is hidden there (keeping its last
     * invertible transform) and back at 2 s; a camera on that node cannot be placed, so with
     * one the pose fails naming the node */
    {
        float times[3] = {0.0f, 1.0f, 2.0f};
        float values[9] = {2, 2, 2, 0, 0, 0, 1, 1, 1};
        fixture(&f);
        f.channels[0] = (IoAnimChannel){1, IO_ANIM_SCALE, IO_INTERP_STEP, 3, times, values};
        f.scene.num_channels = 1;
        pose(&f, 0.5);
        CHECK(NEAR(f.instance.xform[0], 2.0) && !f.instance.hidden, "scale 2 at 0.5 s gives %g", f.instance.xform[0]);
        pose(&f, 1.0);
        CHECK(f.instance.hidden && NEAR(f.instance.xform[0], 2.0), "zero scale: hidden %d, xform %g", f.instance.hidden,
              f.instance.xform[0]);
        pose(&f, 2.0);
        CHECK(NEAR(f.instance.xform[0], 1.0) && !f.instance.hidden, "scale 1 at 2 s gives %g", f.instance.xform[0]);
        IoCamera cam;
        memset(&cam, 0, sizeof cam);
        cam.node = 1;
        f.scene.cameras = &cam;
        f.scene.num_cameras = 1;
        int rc = io_scene_pose(&f.scene, 1.0, err);
        CHECK(rc != 0 && strstr(err, "fixture.gltf") && strstr(err, "'n1'") && strstr(err, "singular"),
              "camera with zero scale: rc %d, '%s'", rc, err);
    }

    /* a loaded scene without animation: posing changes no bit */
    {
        IoScene s;
        const char *path = CANDELA_SOURCE_ROOT "/scenes/default.gltf";
        if (io_load_gltf(path, &s, err) != 0) {
            CHECK(0, "load %s: %s", path, err);
        } else {
            CHECK(s.num_channels == 0 && s.num_nodes >= s.num_instances, "default.gltf: %u channels, %u nodes",
                  s.num_channels, s.num_nodes);
            IoInstance *inst = malloc(s.num_instances * sizeof *inst);
            IoLight *lights = malloc(s.num_lights * sizeof *lights);
            IoCamera *cams = malloc(s.num_cameras * sizeof *cams);
            memcpy(inst, s.instances, s.num_instances * sizeof *inst);
            memcpy(lights, s.lights, s.num_lights * sizeof *lights);
            memcpy(cams, s.cameras, s.num_cameras * sizeof *cams);
            CHECK(io_scene_pose(&s, 0.37, err) == 0, "pose: %s", err);
            CHECK(memcmp(inst, s.instances, s.num_instances * sizeof *inst) == 0, "instances changed");
            CHECK(memcmp(lights, s.lights, s.num_lights * sizeof *lights) == 0, "lights changed");
            CHECK(memcmp(cams, s.cameras, s.num_cameras * sizeof *cams) == 0, "cameras changed");
            free(inst);
            free(lights);
            free(cams);
            io_scene_free(&s);
        }
    }

    /* the animated demo loads with its five channels over 0..2 s */
    {
        IoScene s;
        const char *path = CANDELA_SOURCE_ROOT "/scenes/animation.gltf";
        if (io_load_gltf(path, &s, err) != 0) {
            CHECK(0, "load %s: %s", path, err);
        } else {
            CHECK(s.num_channels == 5 && s.anim_start == 0.0 && NEAR(s.anim_end, 2.0), "animation.gltf: %u channels, %g..%g s",
                  s.num_channels, s.anim_start, s.anim_end);
            int interp[3] = {0, 0, 0};
            for (uint32_t k = 0; k < s.num_channels; ++k) ++interp[s.channels[k].interpolation];
            CHECK(interp[IO_INTERP_STEP] == 1 && interp[IO_INTERP_LINEAR] == 3 && interp[IO_INTERP_CUBICSPLINE] == 1,
                  "interpolations %d %d %d", interp[0], interp[1], interp[2]);
            io_scene_free(&s);
        }
    }
    return test_exit();
}
