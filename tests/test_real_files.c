/* Real files: every .gltf/.glb under the shared assets (generated Cornell scenes and the
 * tinygltf project's own models) renders at tiny resolution without error, with finite pixels
 * and (for the lit Cornell scenes) some light. argv[1]: ../shared/assets. */
#define _XOPEN_SOURCE 700
#include <ftw.h>
#include <math.h>
#include <string.h>

#include "candela.h"
#include "check.h"

static int rendered = 0;

static int visit(const char *path, const struct stat *sb, int type, struct FTW *ftw) {
    (void)sb; (void)ftw;
    if (type != FTW_F) return 0;
    size_t n = strlen(path);
    if (!(n > 5 && strcmp(path + n - 5, ".gltf") == 0) && !(n > 4 && strcmp(path + n - 4, ".glb") == 0)) return 0;
    CandelaOptions o;
    candela_options_default(&o);
    o.scene_path = path;
    o.width = 16; o.height = 12;
    o.spp = 2;
    o.quiet = 1;
    o.threads = 2;
    CandelaImage img;
    char err[CANDELA_ERR_LEN];
    int rc = candela_render(&o, &img, NULL, NULL, err);
    CHECK(rc == 0, "%s: %s", path, err);
    if (rc != 0) return 0;
    double sum = 0.0;
    int finite = 1;
    for (int i = 0; i < img.width * img.height * 3; ++i) {
        if (!isfinite(img.rgb[i])) finite = 0;
        sum += img.rgb[i];
    }
    CHECK(finite, "%s: non-finite pixels", path);
    if (strstr(path, "cornell")) CHECK(sum > 0.0, "%s: black image", path);
    fprintf(stderr, "rendered %s: mean %.4f\n", path, sum / (img.width * img.height * 3));
    candela_image_free(&img);
    ++rendered;
    return 0;
}

int main(int argc, char **argv) {
    if (argc < 2) SKIP("usage: test_real_files ASSETS_DIR");
    struct stat st;
    if (stat(argv[1], &st) != 0) SKIP("%s absent", argv[1]);
    nftw(argv[1], visit, 16, FTW_PHYS);
    CHECK(rendered >= 8, "only %d files rendered", rendered);
    return test_exit();
}
