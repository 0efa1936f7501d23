/* tests/fuzz/fuzz_gltf.c: libFuzzer over the glTF / GLB loader (io_load_gltf): tinygltf's
 * parser, the GLB container checks, accessors, materials, lights, cameras, animations (and
 * posing at a few times) and Candela's extras; first the scene's references listing
 * (io_gltf_references), and every input loaded twice: with the bulk pass forced on and off.
 * Inputs starting with "glTF" are GLB, the others .gltf (JSON). */
#include "fuzz_common.h"
#include "io.h"

/* The bulk pass (io/gltf_bulk.cpp: simdjson's, nlohmann's when it gives up) forced on, against
 * tinygltf alone: the same answer (loaded or not, the same message, the same lights and nodes),
 * or the input is a finding. */
static void same_with_bulk_pass(const char *path, const IoScene *plain, int plain_rc, const char *plain_err) {
    IoLoadOptions on;
    memset(&on, 0, sizeof on);
    on.bulk_min_lights = 1;
    on.no_warnings = 1;
    IoScene bulk;
    char err[IO_ERR_LEN];
    int rc = io_load_gltf_opts(path, &on, &bulk, err);
    if ((rc == 0) != (plain_rc == 0)) abort();
    if (rc != 0) {
        if (strcmp(err, plain_err) != 0) abort();
        return;
    }
    if (bulk.num_lights != plain->num_lights || bulk.num_nodes != plain->num_nodes ||
        (bulk.num_lights && memcmp(bulk.lights, plain->lights, bulk.num_lights * sizeof *bulk.lights) != 0))
        abort();
    io_scene_free(&bulk);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    const char *path = fuzz_write_input(size >= 4 && memcmp(data, "glTF", 4) == 0 ? "in.glb" : "in.gltf", data, size);
    IoScene scene;
    char err[IO_ERR_LEN];
    IoPathList refs; /* the outputs rule's listing (simdjson, nlohmann when simdjson gives up) */
    if (io_gltf_references(path, &refs, err) == 0) io_path_list_free(&refs);
    IoLoadOptions off;
    memset(&off, 0, sizeof off);
    off.bulk_min_lights = UINT32_MAX;
    off.no_warnings = 1;
    int rc = io_load_gltf_opts(path, &off, &scene, err);
    same_with_bulk_pass(path, &scene, rc, err);
    if (rc == 0) {
        /* the animation sampler on whatever channels passed validation: before, inside, at
         * and after the keys */
        const double times[5] = {-1.0, scene.anim_start, 0.5 * (scene.anim_start + scene.anim_end), scene.anim_end, 1e9};
        for (int k = 0; k < 5; ++k) (void)io_scene_pose(&scene, times[k], err);
        io_scene_free(&scene);
    }
    return 0;
}
