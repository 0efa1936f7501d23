/* alphaMode MASK: an occluder whose alpha is below the cutoff is invisible to camera and
 * shadow rays (the image equals the unoccluded analytic answer); the same occluder above the
 * cutoff (the control) changes the image. argv[1]: tests/scenes. */
#include <math.h>
#include <stdio.h>

#include "candela.h"
#include "check.h"

/* point light I = 2 pi at height 1 over a Lambert plane (rho 0.5): L = rho/pi I h / r^3 */
static double exact(double x, double z) {
    double r2 = 1.0 + x * x + z * z;
    return 0.5 / M_PI * 2.0 * M_PI / (r2 * sqrt(r2));
}

/* mean of (pixel - exact) over the image and its standard error from the pixel variances */
static void render_diff(const char *dir, const char *name, double *diff, double *stderr_out) {
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = path;
    o.width = o.height = 16;
    o.spp = 64;
    o.quiet = 1;
    o.light_units = CANDELA_LIGHT_UNITS_RAW;
    CandelaImage img;
    char err[CANDELA_ERR_LEN];
    int rc = candela_render(&o, &img, NULL, NULL, err);
    CHECK(rc == 0, "%s", err);
    if (rc != 0) { *diff = NAN; *stderr_out = NAN; return; }
    double sum = 0.0, var = 0.0;
    int n = img.width * img.height;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            /* the camera covers x, z in [-1, 1]; image right = +x, image up = -z */
            double wx = -1.0 + 2.0 * (x + 0.5) / img.width, wz = -1.0 + 2.0 * (y + 0.5) / img.height;
            int i = y * img.width + x;
            sum += img.rgb[3 * i] - exact(wx, wz);
            var += img.variance[3 * i];
        }
    *diff = sum / n;
    *stderr_out = sqrt(var) / n;
    candela_image_free(&img);
}

int main(int argc, char **argv) {
    if (argc < 2) SKIP("usage: test_alpha SCENES_DIR");
    double d, se, dc, sec;
    render_diff(argv[1], "masked_plane.gltf", &d, &se);
    /* pixel-centre evaluation vs box-filtered pixels: the curvature error over a 1/8 m pixel
     * is below 2e-3 relative; allow 5 standard errors plus that */
    CHECK(fabs(d) < 5.0 * se + 2e-3, "masked occluder changed the image: mean diff %.5f (stderr %.5f)", d, se);
    render_diff(argv[1], "masked_plane_opaque.gltf", &dc, &sec);
    CHECK(fabs(dc) > 0.05, "control: an opaque occluder should change the image (diff %.5f)", dc);
    fprintf(stderr, "masked: diff %.5f (stderr %.5f); opaque control: diff %.5f\n", d, se, dc);
    return test_exit();
}
