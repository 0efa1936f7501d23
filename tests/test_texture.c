/* Texture lookups: bilinear filtering at texel centres and between them, the three glTF wrap
 * modes, and KHR_texture_transform (offset, rotation, scale) against hand-computed values; the
 * 8-bit form of a texture looks up bit for bit as its float form. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "png_raw.h"
#include "scene.h"

static IoTextureRef ref_default(void) {
    IoTextureRef r = {0};
    r.image = 0;
    r.scale[0] = r.scale[1] = 1.0f;
    return r;
}

/* An RGBA PNG holding every code value in every channel (texel i of 16 x 16: code i in R,
 * 255 - i in G, (37 i + 11) mod 256 in B, (91 i + 200) mod 256 in A) loaded as float (the
 * loader's old and only form) and as 8-bit, sRGB and linear: every lookup, at texel centres,
 * between texels, outside [0, 1] in each wrap mode and under a texture transform, must give
 * the same floats to the bit. (Renders are bit-identical because of this.) */
static void test_8bit_matches_float(void) {
    char dir[] = "/tmp/candela-test-texture-XXXXXX";
    if (!mkdtemp(dir)) {
        CHECK(0, "cannot create a temporary folder");
        return;
    }
    char path[64];
    snprintf(path, sizeof path, "%s/codes.png", dir);
    unsigned char raw[16 * 16 * 4];
    for (int i = 0; i < 256; ++i) {
        raw[4 * i] = (unsigned char)i;
        raw[4 * i + 1] = (unsigned char)(255 - i);
        raw[4 * i + 2] = (unsigned char)(37 * i + 11);
        raw[4 * i + 3] = (unsigned char)(91 * i + 200);
    }
    write_png_raw(path, 16, 16, 6, 8, raw, NULL, NULL);
    for (int srgb = 0; srgb < 2; ++srgb) {
        const int flags = srgb ? IO_IMAGE_SRGB : 0;
        char err[IO_ERR_LEN] = "";
        IoImage f, e;
        const int rf = io_load_image(path, flags, &f, err);
        CHECK(rf == 0, "float load: %s", err);
        const int re = io_load_image(path, flags | IO_IMAGE_KEEP_8BIT, &e, err);
        CHECK(re == 0, "8-bit load: %s", err);
        if (rf != 0 || re != 0) {
            if (rf == 0) io_image_free(&f);
            if (re == 0) io_image_free(&e);
            continue;
        }
        CHECK(f.rgba && e.rgba8 && e.srgb == srgb && e.width == 16 && e.height == 16, "forms (sRGB %d)", srgb);
        int centre_differs = 0, differs = 0, opaque_alpha = 0;
        IoTextureRef r = ref_default();
        for (int i = 0; i < 256 && e.rgba8; ++i) {
            const vec2 uv = {((float)(i % 16) + 0.5f) / 16.0f, ((float)(i / 16) + 0.5f) / 16.0f};
            float a[4], b[4];
            texture_lookup(&f, &r, uv, a);
            texture_lookup(&e, &r, uv, b);
            centre_differs += memcmp(a, b, sizeof a) != 0;
            opaque_alpha += b[3] == 1.0f;
        }
        CHECK(centre_differs == 0, "sRGB %d: %d texel centres differ between the forms", srgb, centre_differs);
        CHECK(opaque_alpha == 1, "sRGB %d: alpha is not the file's (%d texels opaque)", srgb, opaque_alpha);
        uint32_t state = 12345u;
        for (int j = 0; j < 3 * 4096 && e.rgba8; ++j) {
            r = ref_default();
            r.wrap_s = r.wrap_t = j / 4096;
            if (j % 3 == 0) {
                r.offset[0] = 0.3f;
                r.scale[1] = 1.7f;
                r.rotation = 0.4f;
            }
            state = state * 1664525u + 1013904223u;
            const float u = (float)(state >> 8) * (4.0f / 16777216.0f) - 1.5f;
            state = state * 1664525u + 1013904223u;
            const float v = (float)(state >> 8) * (4.0f / 16777216.0f) - 1.5f;
            float a[4], b[4];
            texture_lookup(&f, &r, (vec2){u, v}, a);
            texture_lookup(&e, &r, (vec2){u, v}, b);
            if (memcmp(a, b, sizeof a) != 0 && differs++ == 0)
                fprintf(stderr, "  sRGB %d at (%g, %g): float %.9g %.9g %.9g %.9g, 8-bit %.9g %.9g %.9g %.9g\n", srgb,
                        (double)u, (double)v, a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]);
        }
        CHECK(differs == 0, "sRGB %d: %d of %d bilinear lookups differ between the forms", srgb, differs, 3 * 4096);
        io_image_free(&f);
        io_image_free(&e);
    }
    remove(path);
    rmdir(dir);
}

int main(void) {
    /* 2x2 image, red channel: top row 0, 1; bottom row 2, 3 */
    float px[16] = {0, 0, 0, 1, 1, 0, 0, 1, 2, 0, 0, 1, 3, 0, 0, 1};
    IoImage im = {2, 2, px};
    IoTextureRef r = ref_default();
    float t[4];
    /* texel centres are at (0.25, 0.25), (0.75, 0.25), ... (v = 0 is the top row) */
    texture_lookup(&im, &r, (vec2){0.25f, 0.25f}, t);
    CHECK(fabsf(t[0] - 0.0f) < 1e-6f, "top-left centre %g", t[0]);
    texture_lookup(&im, &r, (vec2){0.75f, 0.75f}, t);
    CHECK(fabsf(t[0] - 3.0f) < 1e-6f, "bottom-right centre %g", t[0]);
    texture_lookup(&im, &r, (vec2){0.5f, 0.5f}, t);
    CHECK(fabsf(t[0] - 1.5f) < 1e-6f, "bilinear middle %g", t[0]);
    CHECK(fabsf(t[3] - 1.0f) < 1e-6f, "alpha %g", t[3]);
    /* repeat: u = 1.25 is u = 0.25 */
    texture_lookup(&im, &r, (vec2){1.25f, 0.25f}, t);
    CHECK(fabsf(t[0] - 0.0f) < 1e-6f, "repeat %g", t[0]);
    /* repeat across the edge at u = 0: halfway between texel 1 (wrapped) and texel 0 */
    texture_lookup(&im, &r, (vec2){0.0f, 0.25f}, t);
    CHECK(fabsf(t[0] - 0.5f) < 1e-6f, "repeat edge %g", t[0]);
    /* clamp to edge: u = 0 and u = -3 give texel 0 */
    r.wrap_s = 1;
    texture_lookup(&im, &r, (vec2){-3.0f, 0.25f}, t);
    CHECK(fabsf(t[0] - 0.0f) < 1e-6f, "clamp %g", t[0]);
    texture_lookup(&im, &r, (vec2){0.0f, 0.25f}, t);
    CHECK(fabsf(t[0] - 0.0f) < 1e-6f, "clamp edge %g", t[0]);
    /* mirrored repeat: u = 1.25 mirrors to 0.75 */
    r.wrap_s = 2;
    texture_lookup(&im, &r, (vec2){1.25f, 0.25f}, t);
    CHECK(fabsf(t[0] - 1.0f) < 1e-6f, "mirror %g", t[0]);
    /* KHR_texture_transform: uv' = offset + R(rotation) * (scale * uv) */
    r = ref_default();
    r.offset[0] = 0.5f;
    texture_lookup(&im, &r, (vec2){0.25f, 0.25f}, t);
    CHECK(fabsf(t[0] - 1.0f) < 1e-6f, "offset %g", t[0]);
    r = ref_default();
    r.scale[0] = 3.0f;
    texture_lookup(&im, &r, (vec2){0.25f, 0.25f}, t); /* u' = 0.75 */
    CHECK(fabsf(t[0] - 1.0f) < 1e-6f, "scale %g", t[0]);
    r = ref_default();
    r.rotation = (float)(M_PI / 2); /* rotates (u, v) = (0.25, 0) to (0, -0.25)... per the extension's matrix */
    /* the extension's rotation matrix is [[cos, sin], [-sin, cos]]: (0.75, 0.25) -> (0.25, -0.75) = (0.25, 0.25) after repeat */
    texture_lookup(&im, &r, (vec2){0.75f, 0.25f}, t);
    CHECK(fabsf(t[0] - 0.0f) < 1e-5f, "rotation %g", t[0]);
    test_8bit_matches_float();
    return test_exit();
}
