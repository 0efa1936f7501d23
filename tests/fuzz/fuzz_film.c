/* tests/fuzz/fuzz_film.c: libFuzzer over the readers of candela's own binary files (renderer/
 * checkpoint.c): shard films (`candela merge`: header, identity, sample ranges, the film section
 * and its validation) and checkpoints (`--resume-from`: every module's section, read into a
 * render of the scene they name).
 *
 * Every file ends in an FNV-1a checksum of what precedes it, which a mutation breaks almost
 * always; the harness writes the checksum of the mutated bytes in its place, so that the input
 * reaches the parsers behind it (the checksum itself is tested in tests/test_checkpoint.sh).
 * Then: a merge of the file alone (a film of one shard), and, when the header says checkpoint,
 * a resumed render of tests/scenes/point_plane.gltf at 8x8, 8 spp, guided (recorder and guiding
 * sections), one thread: the seed checkpoints are of that render (corpus/film, README there). */
#include <string.h>

#include "candela.h"
#include "fuzz_common.h"

#ifndef CANDELA_SOURCE_ROOT
#error "CANDELA_SOURCE_ROOT: the source tree (for the scene the checkpoints belong to)"
#endif

static uint64_t fnv1a(const uint8_t *p, size_t n) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 0x100000001b3ull;
    return h;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size < 8 + 24 + 8 || size > (1u << 20)) return 0;
    uint8_t *fixed = malloc(size);
    if (!fixed) return 0;
    memcpy(fixed, data, size);
    const uint64_t sum = fnv1a(fixed, size - 8);
    memcpy(fixed + size - 8, &sum, 8); /* native byte order, as checkpoint.c writes it */
    const char *path = fuzz_write_input("in.film", fixed, size);
    uint32_t kind = 0;
    memcpy(&kind, fixed + 8 + 8, 4); /* after "CANDCKPT", the byte-order mark and the version */
    free(fixed);

    char err[CANDELA_ERR_LEN], out[256];
    snprintf(out, sizeof out, "%.200s.exr", path);
    const char *files[1] = {path};
    (void)candela_merge(out, NULL, files, 1, err);

    if (kind == 1) {
        CandelaOptions o;
        candela_options_default(&o);
        o.scene_path = CANDELA_SOURCE_ROOT "/tests/scenes/point_plane.gltf";
        o.width = o.height = 8;
        o.spp = 8;
        o.threads = 1;
        o.quiet = 1;
        o.no_warnings = 1;
        o.guiding = CANDELA_GUIDING_MIS;
        o.light_sampler = CANDELA_LIGHT_SAMPLER_POWER;
        o.resume_from = path;
        CandelaImage image;
        CandelaStats stats;
        if (candela_render(&o, &image, &stats, NULL, err) == 0) candela_image_free(&image);
    }
    return 0;
}
