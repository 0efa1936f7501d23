// io/gltf_internal.hpp: private to the glTF loader's files (io/gltf_*.cpp); not part of io's API
// (io.h), never included from C nor from outside io/. The loader converts a glTF file into the
// plain-C IoScene of io.h; no C++ type crosses that header.
//
// The files, by concern (io/README.md, "The glTF loader's files"):
//   gltf_loader.cpp          the core walk: parse (GLB checks, JSON depth), the node walk and its
//                            transforms, the environment, the hand-over to C, the extern "C" API
//                            (io_load_gltf, io_load_gltf_opts, io_scene_free, io_gltf_references)
//   gltf_values.cpp          reading and checking JSON values, file paths and the confinement,
//                            the message helpers (strf, fail)
//   gltf_meshes.cpp          accessors (bounds, sparse) and mesh primitives
//   gltf_materials.cpp       materials, textures and their images, material media
//   gltf_lights_cameras.cpp  KHR_lights_punctual, light shapes, area lights, light linking, cameras
//   gltf_animation.cpp       animation channels and their validation
//   gltf_bulk.cpp            the bulk pass for files with many light nodes (io/README.md, "Memory")
//   gltf_volumes.cpp         extras.candela_volume and its VDB grids
// A helper one file uses is static there; what several share is declared here (small ones inline).
#ifndef CANDELA_IO_GLTF_INTERNAL_HPP
#define CANDELA_IO_GLTF_INTERNAL_HPP

#include "io.h"
#include "io_internal.hpp"

#include <tiny_gltf.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace candela_io::gltf {

// Thrown (only inside the loader's files) to abandon a load; caught in io_load_gltf_opts.
struct LoadError {
    std::string problem;
};

// ---- messages, names and paths (gltf_values.cpp) ----

// printf into a string (a message line; at most 1023 characters)
#if defined(__GNUC__)
__attribute__((format(printf, 1, 2)))
#endif
std::string strf(const char *fmt, ...);

// Abandons the load with a one-line problem (io_load_gltf_opts puts the file's path before it).
[[noreturn]] void fail(const std::string &problem);

inline void copy_name(char dst[64], const std::string &src) { std::snprintf(dst, 64, "%s", src.c_str()); }

std::string join_path(const std::string &dir, const std::string &rel);
std::string dir_of(const std::string &path);
std::string url_decode(const std::string &s);
bool is_regular_file(const std::string &p);
// The file-reference policy (--confine-to): file resolves inside folder_real ("": anywhere).
bool inside_folder(const std::string &file, const std::string &folder_real);

// The scene-references listing's fast path (gltf_references.cpp): simdjson over json[0, len),
// readable up to capacity (len + JSON_FAST_PADDING at least); false: it gave up (the nlohmann
// listing decides), found untouched.
constexpr size_t JSON_FAST_PADDING = 64;
bool references_fast(unsigned char *json, size_t len, size_t capacity, const std::string &dir,
                     std::vector<std::string> *found);

struct FsUser {
    std::string dir, confine;
};

// ---- JSON values (tinygltf::Value asserts on wrong types, so check first) ----

inline const tinygltf::Value *member(const tinygltf::Value &o, const char *key) {
    if (!o.IsObject() || !o.Has(key)) return nullptr;
    return &o.Get(key);
}

inline double number_or(const tinygltf::Value &o, const char *key, double def) {
    const tinygltf::Value *v = member(o, key);
    return (v && v->IsNumber()) ? v->GetNumberAsDouble() : def;
}

// An index from a JSON number: -1 unless it is a whole number in [0, 2^31) (a cast of 1e10 to
// int is undefined behaviour).
inline int index_value(const tinygltf::Value &v) {
    if (!v.IsNumber()) return -1;
    const double d = v.GetNumberAsDouble();
    return d >= 0.0 && d < 2147483648.0 && d == std::floor(d) ? int(d) : -1;
}

inline const tinygltf::Value *extension(const tinygltf::ExtensionMap &ext, const char *name) {
    auto it = ext.find(name);
    return it == ext.end() ? nullptr : &it->second;
}

// gltf_values.cpp: checked readers (a value of the wrong kind fails the load, naming `what`)
void numbers(const tinygltf::Value &o, const char *key, float *dst, size_t n);
double finite_number(const tinygltf::Value &o, const char *key, double def, const std::string &what);
void finite_vec3(const tinygltf::Value &o, const char *key, float dst[3], const std::string &what);
char raw_member_start(const std::string &json, const char *key);

// ---- 4x4 column-major double matrices (m[col*4 + row]) ----

struct Mat4 {
    double m[16];
};

inline Mat4 identity() {
    Mat4 r{};
    r.m[0] = r.m[5] = r.m[10] = r.m[15] = 1.0;
    return r;
}

inline Mat4 mul(const Mat4 &a, const Mat4 &b) {
    Mat4 r{};
    for (int c = 0; c < 4; ++c)
        for (int row = 0; row < 4; ++row) {
            double s = 0.0;
            for (int k = 0; k < 4; ++k) s += a.m[k * 4 + row] * b.m[c * 4 + k];
            r.m[c * 4 + row] = s;
        }
    return r;
}

// A node's local matrix from its TRS, also kept in its walk record (gltf_loader.cpp).
Mat4 trs_local(const double t[3], const double q0[4], const double s[3], IoNode *walk);

// ---- accessor views ----

inline constexpr unsigned char kZeros[64] = {};

struct AccView {
    const unsigned char *base = nullptr;  // nullptr: all zeros (no bufferView)
    size_t stride = 0, count = 0, elem = 0;
    int ct = 0, ncomp = 0;
    bool normalized = false;
    const unsigned char *sp_vals = nullptr;  // sparse substitution values (tightly packed)
    std::vector<int32_t> sp_map;             // element -> sparse slot, or -1

    const unsigned char *at(size_t i) const {
        if (!sp_map.empty() && sp_map[i] >= 0) return sp_vals + size_t(sp_map[i]) * elem;
        return base ? base + i * stride : kZeros;
    }
};

// A bulk record's node name for a message, made only when a message needs it (place_light's
// What; a million light nodes must not each format one).
struct BulkWhat {
    int gi;
    const std::string *name;
    std::string operator()() const { return strf("node %d ('%s')", gi, name->c_str()); }
};

// ---- the loader (its member functions are defined in the files named in the class) ----

class Loader {
  public:
    Loader(const std::string &path, const std::string &confine, uint64_t texture_budget, uint64_t volume_budget,
           bool print_warnings)
        : path_(path), dir_(dir_of(path)), fs_user_{dir_of(path), confine}, texture_budget_(texture_budget),
          volume_budget_(volume_budget), print_warnings_(print_warnings) {}
    ~Loader() { release_all(); }
    Loader(const Loader &) = delete;
    Loader &operator=(const Loader &) = delete;

    void run(IoScene *out);
    size_t bulk_min_lights_ = 0;                // IoLoadOptions.bulk_min_lights (0: BULK_MIN_LIGHTS)
    void (*phase_done_)(void *, int) = nullptr; // IoLoadOptions.phase_done
    void *phase_user_ = nullptr;

  private:
    std::string path_, dir_;
    FsUser fs_user_;
    uint64_t texture_budget_ = 0, texture_used_ = 0; // decoded texel bytes (budget 0: none)
    uint64_t volume_budget_ = 0, volume_used_ = 0;   // NanoVDB grid bytes (budget 0: none)
    // What the texture budget has left for the next image (0 means no limit, so an exhausted
    // budget reports 1 byte).
    uint64_t texture_left() const {
        if (!texture_budget_) return 0;
        return texture_used_ < texture_budget_ ? texture_budget_ - texture_used_ : 1;
    }
    tinygltf::Model m_;
    // A file the scene references, relative to its folder; refused outside the confinement.
    std::string referenced(const std::string &uri, const std::string &what) {
        const std::string file = join_path(dir_, uri);
        if (!fs_user_.confine.empty() && is_regular_file(file) && !inside_folder(file, fs_user_.confine))
            fail(what + ": '" + uri + "' is outside " + fs_user_.confine + " (--confine-to)");
        return file;
    }
    uint32_t warnings_ = 0;
    bool print_warnings_ = true; // IoLoadOptions.no_warnings: counted, not printed
    bool warned_morph_ = false;
    bool warned_texcoord_ = false;
    bool warned_color_ = false;
    int scene_ = -1;

    std::vector<IoPrimitive> prims_;
    std::vector<IoMesh> meshes_;
    std::vector<IoInstance> instances_;
    std::vector<IoMaterial> materials_;
    std::vector<IoImage> images_;
    std::vector<IoLight> lights_;
    std::vector<IoCamera> cameras_;
    std::vector<IoVolume> volumes_;
    std::vector<IoNode> nodes_;             // the node walk, parents first (io.h, IoNode)
    std::vector<int32_t> node_of_gltf_;     // glTF node -> index in nodes_, or -1 (not in the scene)
    std::vector<IoAnimChannel> channels_;
    double anim_start_ = 0.0, anim_end_ = 0.0;
    std::map<std::pair<std::string, int>, int32_t> image_cache_;

    // Warnings are held until the load succeeds: a failed load prints only its one error line.
    std::vector<std::string> pending_warnings_;
    void warn(const std::string &msg) {
        pending_warnings_.push_back(msg);
        ++warnings_;
    }
    void release_all() {
        for (IoPrimitive &p : prims_) free_prim(&p);
        prims_.clear();
        for (IoImage &im : images_) io_image_free(&im);
        images_.clear();
        for (IoVolume &v : volumes_) free_volume(&v);
        volumes_.clear();
        for (IoAnimChannel &c : channels_) {
            std::free(c.times);
            std::free(c.values);
        }
        channels_.clear();
    }
    static void free_volume(IoVolume *v) {
        io_volume_grid_free(&v->density);
        io_volume_grid_free(&v->emission);
        io_volume_grid_free(&v->temperature);
    }
    static void free_prim(IoPrimitive *p) {
        std::free(p->positions);
        std::free(p->normals);
        std::free(p->uvs);
        std::free(p->tangents);
        std::free(p->indices);
        std::memset(p, 0, sizeof *p);
    }

    // Light records of the file, in its order (KHR_lights_punctual "lights"): every light the
    // nodes may place, whether tinygltf or the bulk pass (below) read it.
    struct LightDef {
        uint32_t name_at = 0, name_len = 0; // in names_
        int32_t type = -1;                  // IO_LIGHT_*, or -1: type_name_ holds what the file says
        bool has_color = false;
        double color[3] = {1, 1, 1}, intensity = 1.0, range = 0.0, inner = 0.0, outer = 0.7853981634;
    };
    std::vector<LightDef> light_defs_;
    std::map<size_t, std::string> type_name_; // light index -> an unknown "type" (for its error)
    // The bulk pass (io/README.md, "Memory"): a file with many lights has its plain light nodes
    // (a name, TRS, a KHR_lights_punctual light and nothing else) and plain light records read
    // into these compact records while nlohmann parses it, and the rest handed to tinygltf, whose
    // Model would hold ~1.1 KB per light node and record plus their JSON tree.
    struct BulkNode {
        uint32_t name_at = 0, name_len = 0; // in names_
        int32_t light = -1;
        uint8_t has_t = 0, has_r = 0, has_s = 0;
        double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
    };
    bool bulk_ = false;
    std::vector<BulkNode> bulk_nodes_;
    std::vector<int32_t> kept_of_gltf_; // bulk_: glTF node -> index in m_.nodes, or -1 - its bulk record
    std::vector<int32_t> light_kept_;   // bulk_: glTF light -> index in m_.lights, or -1 (read by the pass)
    std::string names_;                 // the bulk records' names, back to back
    std::string name_of(uint32_t at, uint32_t len) const { return names_.substr(at, len); }
    size_t gltf_node_count() const { return bulk_ ? kept_of_gltf_.size() : m_.nodes.size(); }
    // The tinygltf node of a glTF node index, or null for a bulk record.
    const tinygltf::Node *gltf_node(size_t i) const {
        if (!bulk_) return &m_.nodes[i];
        const int32_t k = kept_of_gltf_[i];
        return k >= 0 ? &m_.nodes[size_t(k)] : nullptr;
    }
    std::string gltf_node_name(size_t i) const {
        if (const tinygltf::Node *n = gltf_node(i)) return n->name;
        const BulkNode &b = bulk_nodes_[size_t(-1 - kept_of_gltf_[i])];
        return name_of(b.name_at, b.name_len);
    }
    std::vector<IoLightLink> light_links_;
    std::vector<uint32_t> link_instances_;

    // gltf_loader.cpp: the core walk
    void parse();
    void parse_again_slow();
    void check_required_extensions();
    void warn_unrendered();
    void flatten_nodes();
    void environment(IoScene *out);
    void transfer(IoScene *out);
    // gltf_bulk.cpp: the bulk pass
    bool bulk_pass(const unsigned char *json, size_t len, std::string *kept);
    bool use_bulk_pass(const unsigned char *json, size_t len, std::string *kept);
    // the same with simdjson (false: it gave up; bulk_pass then runs); bulk_fast_: it was used,
    // bulk_slow_: a load read again after tinygltf refused the fast pass's JSON, so that a
    // malformed file fails with the message it gets without it
    using ElementParserRef = void *;
    bool bulk_pass_fast(const unsigned char *json, size_t len, std::string *kept);
    bool fast_plain_node(ElementParserRef ep, std::string_view raw);
    bool fast_plain_light(ElementParserRef ep, std::string_view raw);
    void reset_bulk();
    void store_name(std::string_view name, uint32_t *at, uint32_t *len);
    bool refuse_bulk(); // bulk_refused_: neither pass may read this file (a key given twice)
    bool bulk_fast_ = false, bulk_slow_ = false, bulk_refused_ = false;
    void place_bulk(int gi, const Mat4 &parent, int32_t parent_walk);
    // gltf_meshes.cpp: accessors and meshes
    const unsigned char *view_span(int bvi, long long offset, size_t need, const std::string &what,
                                   size_t *stride);
    AccView accessor(int ai, const std::string &what, int want_type);
    float *read_floats(const AccView &v, const std::string &what, bool check_finite);
    void convert_meshes();
    void convert_primitive(const tinygltf::Mesh &mesh, size_t pi);
    // gltf_materials.cpp: materials, textures and their images
    int32_t image_for(int gltf_image, bool srgb, const std::string &what);
    template <class Info>
    IoTextureRef texture_ref(const Info &info, bool srgb, const std::string &what);
    void convert_materials();
    void material_medium(const tinygltf::Material &src, const std::string &what, IoMaterial *d);
    // gltf_lights_cameras.cpp: KHR_lights_punctual, light shapes, area lights, light linking, cameras
    void convert_light_defs();
    // What: the node's name for a message, a std::string or a BulkWhat (instantiated for both there)
    template <class What>
    void place_light(size_t l, const std::string &node_name, const What &what, const double *world_m,
                     int32_t walk_index, const tinygltf::Node *node);
    void light_shape_extras(const tinygltf::Node &node, const std::string &what, IoLight &d);
    void load_area_light(const tinygltf::Node &node, const std::string &what, const Mat4 &world, int32_t walk_index);
    void place_camera(const tinygltf::Node &node, const std::string &what, const Mat4 &world, double det,
                      int32_t walk_index);
    void convert_light_links();
    // gltf_animation.cpp: animation channels
    void check_animation_indices(const unsigned char *json, size_t len);
    void convert_animations();
    void convert_channel(const tinygltf::Animation &anim, size_t ai, size_t ci);
    // gltf_volumes.cpp: extras.candela_volume
    void load_volume(const tinygltf::Node &node, const std::string &what, const Mat4 &world);
    void load_grid(const std::string &vdb, const std::string &grid, const std::string &what, IoVolumeGrid *out);
};

}  // namespace candela_io::gltf

#endif
