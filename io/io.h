/* io/io.h: Candela's only door to files.
 *
 * Plain C17 view of what the C++17 adapters (tinygltf, OpenImageIO, OpenVDB; the last two in
 * modules loaded on first use, io_module.h), libpng and the OpenEXR C API
 * read and write. No C++ type crosses this header. Every function that can fail returns 0 on
 * success and non-zero on failure, with a one-line message "FILE: problem" in err.
 * Ownership: a loaded IoScene / IoImage owns all its arrays; free with io_scene_free /
 * io_image_free. Every writer writes through io_atomic_begin / io_atomic_commit (PATH.tmp-PID,
 * synced, then renamed), so a crash or a full disk never leaves a half-written file under the
 * final name. */
#ifndef CANDELA_IO_H
#define CANDELA_IO_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

#define IO_ERR_LEN 512

/* ---------------------------------------------------------------- atomic files (io/atomic_file.c)
 * Every output file is written by this protocol, by every writer (EXR, PNG, statistics JSON,
 * checkpoints and films, the comparison report's files, cache point and guiding dumps, VDB
 * files; io/README.md "Writing an output"): io_atomic_begin resolves PATH (io_output_path),
 * removes PATH's stale temporaries (io_remove_stale_temps), registers PATH.tmp-PID for the signal
 * handler (io_remove_active_temps) and, given a stdio mode ("wb", or "w+b" for a writer that
 * reads back what it wrote), opens it as the stream af->f; the writer writes af->f (or, mode
 * NULL, the descriptor af->fd, keeping the first write's errno in af->error, or has a library
 * write the file named af->tmp, which then exists, empty); io_atomic_commit then checks every
 * write, flush and close, syncs the file and renames it to PATH. Any failure removes the temporary and leaves
 * PATH as it was, with one line "PATH: cannot write: REASON" (e.g. "No space left on device")
 * in err; io_atomic_abort gives up a write the writer found wrong itself. 0 ok. */
#define IO_PATH_MAX 4096
#define IO_TEMP_PATH_MAX (IO_PATH_MAX + 32)
typedef struct IoAtomicFile {
    FILE *f;                     /* the temporary as a stream (NULL for a write by name) */
    char path[IO_PATH_MAX];      /* the final name, a symbolic link followed to its target */
    char tmp[IO_TEMP_PATH_MAX];  /* PATH.tmp-PID */
    int fd;                      /* the temporary's descriptor (writes without a stream) */
    int error;                   /* the errno of the first failed write (0: none) */
    int slot;                    /* internal: its place in the signal handler's registry */
} IoAtomicFile;
int io_atomic_begin(IoAtomicFile *af, const char *path, const char *mode, char err[IO_ERR_LEN]);
int io_atomic_commit(IoAtomicFile *af, char err[IO_ERR_LEN]);
void io_atomic_abort(IoAtomicFile *af);
/* The whole file at once: size bytes of data written to path by the protocol above. */
int io_atomic_write(const char *path, const void *data, size_t size, char err[IO_ERR_LEN]);
/* Removes the temporaries of the writes in progress: for a signal handler (async-signal-safe:
 * no lock, no allocation), so that an interrupted write leaves no file behind. */
void io_remove_active_temps(void);
/* Removes the files named exactly PATH.tmp-PID beside PATH whose PID is no live process
 * (kill(PID, 0) fails with ESRCH): what a SIGKILL, crash or power loss during a write left, which
 * no signal handler could remove. A live writer's file (another process writing PATH) stays, and
 * so does one whose PID has since been reused by a live process. (A writer in another PID
 * namespace, e.g. another container sharing the folder, looks dead: its rename would then fail.) */
void io_remove_stale_temps(const char *path);
/* Where a writer puts PATH: a symbolic link is followed to its target (so a link into a shared
 * render folder gets the image, not replaced by a regular file), an existing directory, device
 * or FIFO is refused with a one-line error. 0 ok. */
int io_output_path(const char *path, char resolved[IO_PATH_MAX], char err[IO_ERR_LEN]);

/* ---------------------------------------------------------------- files (io/files.c)
 * Inputs: every file the program reads (a scene and its buffers, images, VDBs, variant lists,
 * checkpoints, shard films, a comparison's reference and key) is opened by io_open_input, once: a
 * symbolic link is followed, and anything but a regular file (a FIFO, which would block in
 * open(), a device such as /dev/zero, which never ends, a directory) is refused before it is
 * opened (stat) and again by what was opened (fstat), as is a file larger than max_bytes (0: no
 * limit), from its size before reading.
 * `what` names the input in that message ("a scene", ...). 0 ok, -1 with "PATH: problem". */
int io_open_input(const char *path, uint64_t max_bytes, const char *what, int *fd, uint64_t *size,
                  char err[IO_ERR_LEN]);
/* The same as a stdio stream (NULL on failure). */
FILE *io_open_input_file(const char *path, uint64_t max_bytes, const char *what, uint64_t *size, char err[IO_ERR_LEN]);
/* The whole file into *data (malloc'd, with a zero byte after the *size bytes), read no further
 * than max_bytes even if it grows meanwhile. */
int io_read_input(const char *path, uint64_t max_bytes, const char *what, void **data, size_t *size,
                  char err[IO_ERR_LEN]);
/* The largest scene file (glTF JSON or GLB) and the largest buffer file a scene references. */
#define IO_MAX_SCENE_BYTES ((uint64_t)0xFFFFFFF0u)
/* The largest image file (a texture, an environment map, a frame's PNG read back): 2^28 pixels
 * (the decoder's limit) of four float channels. */
#define IO_MAX_IMAGE_BYTES ((uint64_t)4 << 30)

/* Which file a path names, to tell whether two paths are one file (an output must never be an
 * input or another output of the same run): an existing file by device and inode (after
 * symbolic links), one that does not exist yet by its folder's real path and its name (a
 * dangling link by its target's). io_file_id returns -1 when the folder does not exist (the
 * id then holds the path as given). */
typedef struct IoFileId {
    int exists;
    uint64_t dev, ino;
    char path[IO_PATH_MAX];
} IoFileId;
int io_file_id(const char *path, IoFileId *id);
int io_same_file(const IoFileId *a, const IoFileId *b);
/* 1 when path resolves (symbolic links and .. followed) inside folder ("/" holds every path). */
int io_path_inside(const char *path, const char *folder);

/* One writer per output: io_lock_output takes an exclusive lock (flock) on OUTPUT.lock beside
 * the output's resolved path, and fails with "OUTPUT: another candela (pid P) is writing it"
 * when another process holds it. A dead process's lock is free (the kernel drops it), so a
 * lock file a SIGKILL left is simply taken over; io_unlock_output removes the file. On a file
 * system without locks, writing goes on unlocked (fd -1). */
typedef struct IoLock {
    int fd;
    char path[IO_PATH_MAX + 8];
} IoLock;
int io_lock_output(const char *output, IoLock *lock, char err[IO_ERR_LEN]);
void io_unlock_output(IoLock *lock);
/* The name of output's lock file (OUTPUT.lock beside its resolved path), as io_lock_output takes
 * it: the lock is truncated and removed when done, so the outputs rule counts it as an output
 * (renderer/app/runfiles.c) and an input of that name is refused, not destroyed. 0 ok. */
int io_lock_path(const char *output, char lock[IO_PATH_MAX + 8], char err[IO_ERR_LEN]);
/* The largest magnitude of a node's world transform entry (and so of a coordinate it places):
 * beyond it float rays lose all precision. Documented in README.md. */
#define IO_MAX_COORDINATE 1e12
/* The largest emitted radiance (emissiveFactor x emissiveStrength, W/(m^2 sr)) and light
 * intensity a scene may give: products with it stay finite in float. */
#define IO_MAX_EMISSION 1e20

/* One image, RGBA per texel, rows top to bottom (row 0 is the top of the picture), held in one
 * of two forms: exactly one of rgba / rgba8 is non-NULL (both NULL only in an empty image).
 *  - rgba: linear float, 16 bytes per texel: HDR, EXR, 16-bit and other files that are not
 *    8 bits per channel, every image loaded without IO_IMAGE_KEEP_8BIT (the environment map).
 *  - rgba8: the file's own 8-bit code values, 4 bytes per texel (PNG, JPEG, 8-bit TGA / BMP /
 *    WebP ... loaded with IO_IMAGE_KEEP_8BIT, as glTF textures are): a 16k x 16k PNG is 1 GiB
 *    rather than 4. Code k of R, G, B stands for io_texel8_tables()->srgb[k] when srgb != 0
 *    and for ->linear[k] otherwise; alpha always for ->linear[k]. Those are exactly the floats
 *    the float form of the same file holds, so the two forms render identically.
 * Grey files are expanded to RGB and a missing alpha is opaque (1.0 / code 255) in both forms. */
typedef struct IoImage {
    int width, height;
    float *rgba;     /* width*height*4, or NULL */
    uint8_t *rgba8;  /* width*height*4, or NULL */
    int32_t srgb;    /* rgba8 only: R, G, B are sRGB-encoded (base colour, emissive) */
} IoImage;

/* What an 8-bit code value k stands for: linear[k] is the float OpenImageIO converts k to
 * (k * (1/255) in single precision), srgb[k] the exact sRGB EOTF of k/255 rounded to float.
 * Computed once, then read-only and shared by every thread. */
typedef struct IoTexel8Tables {
    float linear[256];
    float srgb[256];
} IoTexel8Tables;
const IoTexel8Tables *io_texel8_tables(void);

/* Texel `index` (y * width + x) of a non-empty image as linear float RGBA, whichever form it
 * is held in. */
static inline void io_image_texel(const IoImage *image, size_t index, float out[4]) {
    if (image->rgba8) {
        const IoTexel8Tables *tables = io_texel8_tables();
        const float *rgb = image->srgb ? tables->srgb : tables->linear;
        const uint8_t *c = image->rgba8 + 4 * index;
        out[0] = rgb[c[0]];
        out[1] = rgb[c[1]];
        out[2] = rgb[c[2]];
        out[3] = tables->linear[c[3]];
    } else {
        const float *f = image->rgba + 4 * index;
        for (int k = 0; k < 4; ++k) out[k] = f[k];
    }
}

/* The bytes an image's texels occupy (16 or 4 per texel; 0 when empty). */
uint64_t io_image_bytes(const IoImage *image);

/* A texture reference as a material uses it. image < 0: no texture.
 * KHR_texture_transform is already folded into offset/rotation/scale:
 * uv' = T(offset) * R(rotation) * S(scale) * uv, as the extension defines. */
typedef struct IoTextureRef {
    int32_t image;      /* index into IoScene.images, or -1 */
    int32_t texcoord;   /* which UV set (only 0 is loaded; others fall back to 0) */
    float offset[2];
    float scale[2];
    float rotation;     /* radians */
    int32_t wrap_s, wrap_t; /* 0 repeat, 1 clamp-to-edge, 2 mirrored-repeat */
} IoTextureRef;

enum { IO_ALPHA_OPAQUE = 0, IO_ALPHA_MASK = 1, IO_ALPHA_BLEND = 2 };

/* glTF metallic-roughness material plus the extensions Candela honours. Images referenced
 * as base colour or emissive are sRGB-encoded (8-bit ones are kept as code values with
 * IoImage.srgb set, others are decoded to linear float at load); metallic-roughness and
 * normal maps are linear. (An image used both ways is loaded twice, once per colour space.) */
typedef struct IoMaterial {
    char name[64];
    float base_color[4];            /* baseColorFactor, linear RGBA */
    IoTextureRef base_color_tex;
    float metallic, roughness;      /* factors */
    IoTextureRef metallic_roughness_tex; /* B = metallic, G = roughness */
    IoTextureRef normal_tex;
    float normal_scale;
    float emissive[3];              /* emissiveFactor */
    float emissive_strength;        /* KHR_materials_emissive_strength, default 1 */
    IoTextureRef emissive_tex;
    float specular;                 /* KHR_materials_specular specularFactor, default 1 */
    float specular_color[3];        /* specularColorFactor, default 1,1,1 */
    int32_t has_specular_ext;       /* 1 when KHR_materials_specular is present (--material-model
                                     * blender3 converts it as Blender 3.4's importer does) */
    float transmission;             /* KHR_materials_transmission transmissionFactor, default 0 */
    float ior;                      /* KHR_materials_ior, default 1.5 */
    /* KHR_materials_clearcoat: clearcoatFactor x clearcoatTexture.R (default 0: no coat),
     * clearcoatRoughnessFactor x clearcoatRoughnessTexture.G (default 0); a clearcoatNormalTexture
     * is not read (warning): the coat shares the base's shading normal */
    float clearcoat, clearcoat_roughness;
    IoTextureRef clearcoat_tex, clearcoat_roughness_tex;
    int32_t double_sided;
    int32_t alpha_mode;             /* IO_ALPHA_* (BLEND is treated as MASK by the renderer) */
    float alpha_cutoff;             /* default 0.5 */
    /* A homogeneous participating medium filling the inside of every closed mesh with this
     * material (units 1/m; linear RGB). From the material's
     *   "extras": {"candela_medium": {"sigma_a": [r, g, b], "sigma_s": [r, g, b], "anisotropy": g}}
     * (each key optional: defaults 0,0,0 / 0,0,0 / 0); has_medium = 1 whenever candela_medium
     * is an object, even an empty one or with all coefficients 0 ("candela_medium": null is
     * absent; an optional key that is null or [] reads as its default). Otherwise from KHR_materials_volume:
     * attenuationDistance d (default +inf) and attenuationColor c (default 1,1,1) give
     * sigma_a = -ln(c) / d per channel (0 when d is infinite), sigma_s = 0, anisotropy 0, and
     * has_medium = 1 only when some sigma_a > 0 (an infinite distance is a thin-walled no-op);
     * thicknessFactor / thicknessTexture are ignored. candela_medium wins when both are there
     * (KHR_materials_volume is then not read at all). Without either: has_medium = 0 and all
     * zero. Load fails (one line naming the file and the material) for a candela_medium that is
     * not an object, coefficients that are not 3 finite numbers >= 0, an anisotropy that is not
     * a finite number in (-1, 1), an attenuationDistance that is not a number > 0, or an
     * attenuationColor that is not 3 numbers in (0, 1]; unknown candela_medium keys give a
     * warning. The medium mesh is an invisible
     * boundary unless the material is transmissive (transmission > 0), then a dielectric one
     * (README.md, "Participating media"). */
    int32_t has_medium;
    float medium_sigma_a[3];        /* absorption coefficient, 1/m */
    float medium_sigma_s[3];        /* scattering coefficient, 1/m */
    float medium_anisotropy;        /* Henyey-Greenstein g, in (-1, 1) */
} IoMaterial;

/* One glTF mesh primitive, triangulated (TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN), in the
 * mesh's object space. Non-indexed primitives get indices 0..n-1. Optional arrays are NULL
 * when absent. */
typedef struct IoPrimitive {
    uint32_t num_vertices, num_triangles;
    float *positions;   /* 3 * num_vertices */
    float *normals;     /* 3 * num_vertices or NULL */
    float *uvs;         /* 2 * num_vertices (TEXCOORD_0) or NULL */
    float *tangents;    /* 4 * num_vertices or NULL (xyz + handedness w) */
    uint32_t *indices;  /* 3 * num_triangles, each < num_vertices (validated) */
    int32_t material;   /* index into IoScene.materials, or -1 for the glTF default material */
} IoPrimitive;

/* A glTF mesh: a run of primitives [first_primitive, first_primitive + num_primitives). */
typedef struct IoMesh {
    char name[64];
    uint32_t first_primitive, num_primitives;
} IoMesh;

/* A node that references a mesh, flattened: object-to-world matrix, column-major 4x4
 * (glTF's layout: m[col*4 + row]). A mesh referenced by several nodes appears in several
 * instances. */
typedef struct IoInstance {
    uint32_t mesh;
    float xform[16];
    int32_t node;       /* index into IoScene.nodes (io_scene_pose places it) */
    /* 1 while its world transform is singular (a zero scale: how animations hide objects):
     * not rendered, xform is then the last invertible one (or singular, at rest). Only
     * animated nodes (or their descendants) give hidden instances; a static singular mesh is
     * dropped at load with a warning. */
    int32_t hidden;
} IoInstance;

enum { IO_LIGHT_POINT = 0, IO_LIGHT_SPOT = 1, IO_LIGHT_DIRECTIONAL = 2, IO_LIGHT_RECT = 3, IO_LIGHT_DISK = 4 };

/* KHR_lights_punctual light placed by its node, in world space. Intensity is as written in
 * the file (candela for point/spot, lux for directional); unit conversion is the renderer's.
 * Light shapes (README "Light shapes"): extras.candela_light {"radius": r} makes a point or spot
 * light a sphere of radius r (world units, 0: a point), {"angle": deg} a directional light a
 * sun of that angular diameter (radians here, 0: a delta direction). A node with
 * extras.candela_area_light is an IO_LIGHT_RECT / IO_LIGHT_DISK: intensity is its power (W,
 * Blender's), size its full extents along the node's local X and Y (before the node's scale),
 * axis_u / axis_v the world half-extent vectors (node X and Y scaled by size / 2), direction
 * the node's -Z (it emits along it, one-sided). */
typedef struct IoLight {
    char name[64];
    int32_t type;
    float color[3];
    float intensity;
    float range;            /* 0 = infinite */
    float inner_cone_angle; /* spot only, radians */
    float outer_cone_angle;
    float position[3];      /* world */
    float direction[3];     /* world, unit: the direction light travels (node's -Z) */
    int32_t node;           /* index into IoScene.nodes */
    float radius;           /* point, spot: sphere radius (0: a point) */
    float angle;            /* directional: angular diameter, radians (0: delta) */
    float size[2];          /* rect, disk: full extents along local X, Y */
    float axis_u[3], axis_v[3]; /* rect, disk: world half-extent vectors (io_scene_pose updates them) */
} IoLight;

enum { IO_CAMERA_PERSPECTIVE = 0, IO_CAMERA_ORTHOGRAPHIC = 1 };

typedef struct IoCamera {
    char name[64];
    int32_t type;
    float yfov;         /* perspective, radians */
    float aspect;       /* perspective aspectRatio, 0 when absent */
    float xmag, ymag;   /* orthographic half extents */
    float znear, zfar;
    float xform[16];    /* camera-to-world, column-major; camera looks down its local -Z, +Y up */
    int32_t node;       /* index into IoScene.nodes */
} IoCamera;

/* One float grid of a VDB file, converted to NanoVDB so that C reads it with PNanoVDB.h
 * (`#define PNANOVDB_C`, `#include <nanovdb/PNanoVDB.h>`): buffer holds exactly one NanoVDB
 * float grid. Index space has voxel centres at integer coordinates; index_to_world is the
 * VDB's own (affine) transform. */
typedef struct IoVolumeGrid {
    char name[64];
    void *buffer;                /* NanoVDB grid buffer, 32-byte aligned; owned */
    uint64_t size;               /* bytes */
    float index_to_world[16];    /* column-major 4x4 (glTF layout m[col*4 + row]) */
    int32_t index_min[3], index_max[3]; /* bounding box of the active voxels, inclusive */
    float value_min, value_max;  /* range of the finite active values */
    uint64_t active_voxels;
    uint64_t nonfinite_voxels;   /* active voxels that are NaN or infinite */
} IoVolumeGrid;

/* A VDB volume placed by a glTF node: the node's
 *   "extras": {"candela_volume": {"uri": "cloud.vdb", "density_grid": "density",
 *       "density_scale": 4.0, "albedo": [0.8, 0.8, 0.8], "anisotropy": 0.0,
 *       "emission_grid": "none", "emission_scale": 1.0, "emission_color": [1, 1, 1],
 *       "temperature_grid": "none"}}
 * uri is required (resolved relative to the glTF file's folder, percent-decoded like image
 * URIs; an absolute path is kept). Every other key is optional with the default shown.
 * A grid name "none" loads no grid (the default of emission_grid and temperature_grid);
 * density_grid cannot be "none". A node may carry both a mesh and a volume (both load);
 * volumes are listed in the order of the node walk (depth first, scene roots in order), and
 * only nodes of the loaded scene count. "candela_volume": null is no volume; an optional key
 * that is null or [] reads as its default.
 * Load fails with one line naming the glTF file (and the VDB file when it is the problem:
 * io_load_vdb_grid's message is passed through) for: candela_volume not an object, a missing
 * or empty uri, a grid name that is not a non-empty string, a missing or unreadable VDB file,
 * a missing grid, a value that is not a number (finite as a float) or an array of 3 of them,
 * density_scale < 0, emission_scale < 0, an emission_color component < 0, an albedo component
 * outside [0, 1], an anisotropy outside the open interval (-1, 1) (|g| = 1 is a degenerate
 * phase function). Unknown keys give a warning. The grid's values are NOT checked here:
 * negative or non-finite voxels are the renderer's business (each grid reports value_min and
 * nonfinite_voxels). What the renderer makes of it: README.md, "Participating media". */
typedef struct IoVolume {
    char name[64];               /* the node's name */
    float xform[16];             /* the node's world matrix (parents included), column-major
                                  * like IoInstance.xform; world = xform x grid.index_to_world */
    char path[1024];             /* the resolved uri */
    float density_scale;         /* default 4 */
    float albedo[3];             /* default 0.8, 0.8, 0.8; each in [0, 1] */
    float anisotropy;            /* Henyey-Greenstein g, default 0, in (-1, 1) */
    float emission_scale;        /* default 1 */
    float emission_color[3];     /* default 1, 1, 1 */
    IoVolumeGrid density;        /* always loaded */
    IoVolumeGrid emission;       /* buffer NULL unless emission_grid names a grid */
    IoVolumeGrid temperature;    /* buffer NULL unless temperature_grid names a grid (kelvin) */
    int32_t node;                /* index into IoScene.nodes */
} IoVolume;

/* ---------------------------------------------------------------- animation
 * The node walk of the loaded scene, kept so that io_scene_pose can re-place everything at an
 * animation time: nodes[] lists the visited glTF nodes parents first (depth first, scene roots
 * in order, as the instances, cameras, lights and volumes are listed), each with its rest
 * (static) local transform. */
typedef struct IoNode {
    char name[64];
    int32_t gltf_node;      /* index in the file's "nodes" */
    int32_t parent;         /* index into IoScene.nodes (always earlier), or -1 for a root */
    int32_t has_matrix;     /* local transform given as a matrix (not animatable: glTF forbids
                             * animating such a node; its channels are refused at load) */
    double matrix[16];      /* has_matrix: the local matrix, column-major */
    double translation[3], rotation[4], scale[3]; /* !has_matrix: the rest TRS (rotation x y z w) */
} IoNode;

enum { IO_ANIM_TRANSLATION = 0, IO_ANIM_ROTATION = 1, IO_ANIM_SCALE = 2 };
enum { IO_INTERP_STEP = 0, IO_INTERP_LINEAR = 1, IO_INTERP_CUBICSPLINE = 2 };

/* One animation channel with its sampler, validated at load: times finite, >= 0 and strictly
 * increasing; values finite; counts matching (CUBICSPLINE: 3 values per key, in-tangent,
 * value, out-tangent). Every glTF animation of the file plays at once (channels of all
 * animations are listed together); channels that target a node outside the loaded scene, and
 * "weights" channels (morph targets, not rendered: a warning), are dropped. */
typedef struct IoAnimChannel {
    int32_t node;           /* index into IoScene.nodes */
    int32_t path;           /* IO_ANIM_* */
    int32_t interpolation;  /* IO_INTERP_* */
    uint32_t num_keys;
    float *times;           /* num_keys seconds */
    float *values;          /* num_keys x (3 or 4) floats, x 3 again for CUBICSPLINE */
} IoAnimChannel;



/* ---------------------------------------------------------------- light linking
 * A node's "extras": {"candela_light_linking": {"receivers": {"include": [NAMES]} or
 * {"exclude": [NAMES]}, "blockers": {"exclude": [NAMES]}}} on a node that carries a punctual
 * light or an emissive mesh (the links apply to those lights). NAMES are node names of the
 * loaded scene (every node of that name; a node stands for its whole subtree), resolved here
 * to sorted, duplicate-free lists of instance indices. Load fails with one line naming the
 * file, the node and the problem for: a value that is not an object, a receivers object with
 * both or neither of include / exclude, a list that is not an array of strings, a name no
 * node of the scene has. Unknown keys give a warning, as does the key on a node without a
 * light. What the renderer does with it: README.md, "Light linking". */
enum { IO_LINK_ALL = 0, IO_LINK_INCLUDE = 1, IO_LINK_EXCLUDE = 2 };

typedef struct IoLightLink {
    int32_t node;                 /* index into IoScene.nodes: the node carrying the extras */
    int32_t receivers;            /* IO_LINK_ALL (no "receivers"), IO_LINK_INCLUDE, IO_LINK_EXCLUDE */
    uint32_t first_receiver, num_receivers; /* into IoScene.link_instances */
    uint32_t first_blocker, num_blockers;   /* blockers.exclude, into IoScene.link_instances */
} IoLightLink;

typedef struct IoScene {
    IoPrimitive *primitives; uint32_t num_primitives;
    IoMesh *meshes;          uint32_t num_meshes;
    IoInstance *instances;   uint32_t num_instances;
    IoMaterial *materials;   uint32_t num_materials;
    IoImage *images;         uint32_t num_images;
    IoLight *lights;         uint32_t num_lights;
    IoCamera *cameras;       uint32_t num_cameras;
    /* scene.extras.candela_environment {"uri": "...", "strength": S, "rotation": DEG}: path
     * resolved relative to the glTF file; env_path[0] == 0 when absent. rotation: degrees about
     * the vertical (+Y), the sign of Blender's Z rotation of the world's Mapping node (0 when absent). */
    char env_path[1024];
    float env_strength;
    float env_rotation_deg;
    IoVolume *volumes;       uint32_t num_volumes; /* nodes with extras.candela_volume */
    uint32_t num_warnings;   /* warnings printed to stderr while loading (e.g. morph targets ignored) */
    IoNode *nodes;           uint32_t num_nodes;    /* the node walk (io_scene_pose) */
    IoAnimChannel *channels; uint32_t num_channels; /* all animations' channels */
    IoLightLink *light_links; uint32_t num_light_links; /* extras.candela_light_linking, by node */
    uint32_t *link_instances; uint32_t num_link_instances; /* the links' instance lists */
    double anim_start, anim_end; /* first and last key time of all channels, seconds (0, 0 without) */
    char path[1024];         /* the file it was loaded from (for io_scene_pose's messages) */
} IoScene;

/* Evaluates every channel at time `seconds` (before the first key: the first value, after the
 * last: the last; STEP, LINEAR with slerp for rotations, CUBICSPLINE Hermite with tangents
 * scaled by the key interval, glTF 2.0 Appendix C) and writes the world transforms of the
 * instances, cameras, lights (position, direction) and volumes. A node no channel animates keeps
 * its rest transform, computed exactly as the loader computed it (so posing a scene without
 * animation changes no bit). A mesh instance whose transform is singular at this time (a zero
 * scale) is hidden (IoInstance.hidden), as at load. Fails with a one-line error naming the
 * node when a transform at this time is out of range (IO_MAX_COORDINATE, non-finite) or a
 * camera's is singular (the scene is then partly posed: pose it again before use). */
int io_scene_pose(IoScene *scene, double seconds, char err[IO_ERR_LEN]);

/* Load a .gltf or .glb (decided by content, not extension). Validates everything the renderer
 * relies on: accessor bounds and types, index ranges, finite positions, image sizes. */
int io_load_gltf(const char *path, IoScene *scene, char err[IO_ERR_LEN]);
/* The same with options (NULL: the defaults, as io_load_gltf). */
typedef struct IoLoadOptions {
    /* every file the scene references (buffers, images, VDBs, its environment) and the scene
     * itself must resolve (realpath) inside this folder (NULL: no confinement; the default
     * policy lets a scene reference files anywhere relative to its folder) */
    const char *confine_dir;
    /* the decoded textures' total size in bytes as held (io_image_bytes: 4 per texel for
     * 8-bit files, 16 for the others), checked from each image's header before it is decoded
     * (0: no limit) */
    uint64_t texture_budget_bytes;
    /* the volume grids' NanoVDB buffers in total, checked after each grid is read (0: no limit;
     * the renderer's --volume-budget-mb, which also counts what the media build from them) */
    uint64_t volume_budget_bytes;
    /* non-zero: warnings are counted (IoScene.num_warnings) but not printed (--no-warnings) */
    int no_warnings;
    /* optional: called when the file is parsed (IO_PHASE_PARSED: JSON and buffers read) and when
     * the scene is flattened (IO_PHASE_FLATTENED: meshes, materials, textures, nodes, lights), so
     * the caller can time and measure each (the renderer's phases, candela.h) */
    void (*phase_done)(void *user, int phase);
    void *phase_user;
    /* the bulk pass (io/README.md, "Memory") reads plain light nodes itself when the file names
     * KHR_lights_punctual at least this often (0: the default, 4096; UINT32_MAX: never). Both
     * ways load the same scene; tests compare them. */
    uint32_t bulk_min_lights;
} IoLoadOptions;
enum { IO_PHASE_PARSED = 0, IO_PHASE_FLATTENED = 1 };
int io_load_gltf_opts(const char *path, const IoLoadOptions *opts, IoScene *scene, char err[IO_ERR_LEN]);
void io_scene_free(IoScene *scene);
/* The files a glTF / GLB references (buffers, images, VDBs, environments; not data: URIs),
 * resolved as the loader resolves them, from the JSON alone (nothing is loaded): what an output
 * of the same run must not replace. A superset of what io_load_gltf reads (every node's volume,
 * every scene's environment). 0 ok (list->count may be 0), -1 with a message (a file the loader
 * would refuse too). Free with io_path_list_free. */
typedef struct IoPathList {
    char **paths;
    int count;
} IoPathList;
int io_gltf_references(const char *path, IoPathList *list, char err[IO_ERR_LEN]);
void io_path_list_free(IoPathList *list);

/* io_load_image flags. IO_IMAGE_SRGB: the file's R, G, B are sRGB-encoded (8/16-bit integer
 * files; float files are linear whatever the flag says). IO_IMAGE_KEEP_8BIT: a file of 8 bits
 * per channel is held as rgba8 (with IoImage.srgb = the IO_IMAGE_SRGB flag) instead of float. */
enum { IO_IMAGE_SRGB = 1, IO_IMAGE_KEEP_8BIT = 2 };
/* Read any image OpenImageIO reads (EXR, HDR, PNG, ...) into an IoImage: linear float RGBA,
 * or with IO_IMAGE_KEEP_8BIT 8-bit RGBA for 8-bit files. Loads candela_io_image.so on first use. */
int io_load_image(const char *path, int flags, IoImage *image, char err[IO_ERR_LEN]);
void io_image_free(IoImage *image);

/* One string attribute of an EXR header or a PNG text chunk (provenance: "software",
 * "candela:commandLine", ...). */
typedef struct IoExrAttribute {
    const char *name;
    const char *value;
} IoExrAttribute;

/* Write an 8-bit sRGB PNG through libpng (io/png.c). rgb: width*height*3 display values in [0,1]
 * (already tone-mapped and sRGB-encoded by the caller), top row first. attributes (NULL, 0:
 * none) become text chunks before the pixels: tEXt, zTXt for a value over 1024 bytes, iTXt
 * (compressed when long) for a value that is not plain ASCII (UTF-8). "software" is written as
 * the registered keyword "Software", "capDate" as "Creation Time"; any other name is the
 * keyword as is. A keyword that is not 1-79 printable Latin-1 characters without leading,
 * trailing or double spaces, one given twice, or a NULL value is refused. */
int io_write_png(const char *path, int width, int height, const float *rgb, const IoExrAttribute *attributes,
                 int num_attributes, char err[IO_ERR_LEN]);

/* One named channel of a multi-channel EXR, e.g. "R", "albedo.G", "variance.B", "Z". */
typedef struct IoExrChannel {
    const char *name;
    const float *data; /* width*height floats, top row first */
} IoExrChannel;

/* Write a single-part scanline EXR (FLOAT channels, ZIP compression) with the OpenEXR C API.
 * attributes (num_attributes of them; NULL, 0: none) are written into the header as string
 * attributes; a name the header already has (the required ones) or given twice is refused. */
int io_write_exr(const char *path, int width, int height, const IoExrChannel *channels,
                 int num_channels, const IoExrAttribute *attributes, int num_attributes,
                 char err[IO_ERR_LEN]);

/* Read one channel by name from an EXR (any pixel type, converted to float). The caller
 * frees *data with free(). Used by tests and comparison tools. Images larger than the
 * renderer's largest (IO_EXR_MAX_SIDE per side, IO_EXR_MAX_PIXELS in all) are refused. */
#define IO_EXR_MAX_SIDE 16384
#define IO_EXR_MAX_PIXELS ((int64_t)64 << 20)
int io_read_exr_channel(const char *path, const char *channel, int *width, int *height,
                        float **data, char err[IO_ERR_LEN]);
/* 0 when path is a whole scanline EXR (header, every chunk's table entry and header read, its
 * bytes inside the file) of at most the renderer's largest size, with its size; nothing is
 * decompressed (`--frames --resume` asks this of every existing frame). */
int io_exr_complete(const char *path, int *width, int *height, char err[IO_ERR_LEN]);
/* io_exr_complete that also reads the string attribute `name` of the header into value (""
 * when the header has none or it is no string). */
int io_exr_complete_attribute(const char *path, int *width, int *height, const char *name, char *value, size_t size,
                              char err[IO_ERR_LEN]);

/* ---------------------------------------------------------------- volumes (OpenVDB)
 * Every function here but io_volume_grid_free loads candela_io_vdb.so on first use. */
/* IoVolumeGrid is defined above, with IoVolume. */

/* Reads the float grid `grid_name` of a .vdb file. Fails with a one-line "FILE: problem" for
 * a missing, unreadable, corrupt or truncated file, a missing grid (the message lists the
 * grids there are), a grid that is not a float grid, a non-affine transform, an empty grid
 * or absurd bounds. */
int io_load_vdb_grid(const char *path, const char *grid_name, IoVolumeGrid *grid, char err[IO_ERR_LEN]);
/* A grid from dense values (tests and generators): values[x + nx * (y + ny * z)] for index
 * (x, y, z) in [0, n), zero values inactive; index_to_world as in IoVolumeGrid. */
int io_volume_grid_from_dense(const float *values, int nx, int ny, int nz, const float index_to_world[16],
                              const char *name, IoVolumeGrid *grid, char err[IO_ERR_LEN]);
/* A grid from sparse data (tests and generators): num_boxes boxes (6 ints each, inclusive
 * min x y z, max x y z) filled with box_values (OpenVDB's fill: tiles where a box covers whole
 * nodes), then count single voxels (3 ints each in ijk) set to values over them. */
int io_volume_grid_from_voxels(const int32_t *ijk, const float *values, size_t count, const int32_t *boxes,
                               const float *box_values, size_t num_boxes, const float index_to_world[16],
                               const char *name, IoVolumeGrid *grid, char err[IO_ERR_LEN]);
void io_volume_grid_free(IoVolumeGrid *grid);
/* Writes a .vdb file of num_grids float grids (names[g], dense values[g] laid out as above,
 * zero values inactive, one shared index_to_world), through a temporary name and a rename
 * (tests and generators). */
int io_write_vdb_dense(const char *path, const char *const *names, const float *const *values, int num_grids,
                       int nx, int ny, int nz, const float index_to_world[16], char err[IO_ERR_LEN]);

/* ---------------------------------------------------------------- comparison variants */
/* `candela compare --variants FILE.toml|FILE.json` (io/variants.cpp): an ordered list of
 * (name, render flags) read from a TOML file of [[variant]] tables or a JSON object
 * {"variant": [{"name": ..., "flags": ...}, ...]}; any other key is an error. The flags are
 * not interpreted here. Free with io_variants_free. */
#define IO_MAX_VARIANTS 16
#define IO_MAX_VARIANTS_BYTES ((uint64_t)1 << 20) /* a variant file's size limit */
typedef struct IoVariant {
    char *name;
    char *flags;
} IoVariant;
int io_read_variants(const char *path, IoVariant **variants, int *count, char err[IO_ERR_LEN]);
void io_variants_free(IoVariant *variants, int count);

/* ---------------------------------------------------------------- JSON strings */
/* s as a JSON string literal, quotes included, escaped by nlohmann/json (io/variants.cpp):
 * quotes, backslashes and control characters escaped, other UTF-8 as it is, bytes that are no
 * UTF-8 replaced by U+FFFD (the result is always valid JSON). malloc'd; NULL when out of memory.
 * Every JSON string Candela writes (statistics, options, the frame log) goes through it. */
char *io_json_quote(const char *s);

#ifdef __cplusplus
}
#endif

#endif
