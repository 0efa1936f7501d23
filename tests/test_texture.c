/* Texture lookups: bilinear filtering at texel centres and between them, the three glTF wrap
 * modes, and KHR_texture_transform (offset, rotation, scale) against hand-computed values. */
#include <math.h>

#include "check.h"
#include "scene.h"

static IoTextureRef ref_default(void) {
    IoTextureRef r = {0};
    r.image = 0;
    r.scale[0] = r.scale[1] = 1.0f;
    return r;
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
    return test_exit();
}
