/* tests/fuzz/fuzz_gltf.c: libFuzzer over the glTF / GLB loader (io_load_gltf): tinygltf's
 * parser, the GLB container checks, accessors, materials, lights, cameras, animations (and
 * posing at a few times) and Candela's extras; first the scene's references listing
 * (io_gltf_references).
 * Inputs starting with "glTF" are GLB, the others .gltf (JSON). */
#include "fuzz_common.h"
#include "io.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const char *path = fuzz_write_input(size >= 4 && memcmp(data, "glTF", 4) == 0 ? "in.glb" : "in.gltf", data, size);
    IoScene scene;
    char err[IO_ERR_LEN];
    IoPathList refs; /* the outputs rule's listing (simdjson, nlohmann when simdjson gives up) */
    if (io_gltf_references(path, &refs, err) == 0) io_path_list_free(&refs);
    if (io_load_gltf(path, &scene, err) == 0) {
        /* the animation sampler on whatever channels passed validation: before, inside, at
         * and after the keys */
        const double times[5] = {-1.0, scene.anim_start, 0.5 * (scene.anim_start + scene.anim_end), scene.anim_end, 1e9};
        for (int k = 0; k < 5; ++k) (void)io_scene_pose(&scene, times[k], err);
        io_scene_free(&scene);
    }
    return 0;
}
