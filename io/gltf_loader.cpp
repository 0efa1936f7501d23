// io/gltf_loader.cpp: thin extern "C" adapter over tinygltf (C++17).
//
// tinygltf parses the JSON / GLB container and loads buffers; images are NOT decoded by it
// (a no-op image loader keeps uri / bufferView, and stashes the bytes of data: URIs, which
// tinygltf does not keep otherwise). Everything the renderer relies on is validated here
// (accessor and buffer bounds, index ranges, finite positions, node graph shape) and
// converted to the plain C arrays of io.h. Images are decoded with OpenImageIO
// (image_module.cpp, in candela_io_image.so: io_module.h) once per (image, colour space).
#include "io.h"
#include "io_internal.hpp"

#include <tiny_gltf.h>
#include <nlohmann/json.hpp>

#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <map>
#include <new>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace {

using candela_io::set_err;

// Thrown (only inside this file) to abandon a load; caught in io_load_gltf.
struct LoadError {
    std::string problem;
};

#if defined(__GNUC__)
__attribute__((format(printf, 1, 2)))
#endif
std::string strf(const char *fmt, ...) {
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    return buf;
}

[[noreturn]] void fail(const std::string &problem) { throw LoadError{problem}; }

// A GLB's magic, or JSON's first character '{' after an optional UTF-8 BOM and white space: an
// OBJ, USD or PNG given as the scene is named as such in one line, not by the JSON parser's
// "[json.exception.parse_error.101] ..." about its first byte.
bool looks_like_gltf(const std::vector<unsigned char> &bytes) {
    if (bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0) return true;
    size_t i = 0;
    if (bytes.size() >= 3 && bytes[0] == 0xEF && bytes[1] == 0xBB && bytes[2] == 0xBF) i = 3;
    while (i < bytes.size() && (bytes[i] == ' ' || bytes[i] == '\t' || bytes[i] == '\n' || bytes[i] == '\r')) ++i;
    return i < bytes.size() && bytes[i] == '{';
}

// Largest accessor element count accepted (also bounds accessors that have no bufferView).
constexpr size_t kMaxCount = size_t(1) << 28;

void copy_name(char dst[64], const std::string &src) { std::snprintf(dst, 64, "%s", src.c_str()); }

std::string join_path(const std::string &dir, const std::string &rel) {
    if (!rel.empty() && rel[0] == '/') return rel;
    if (dir.empty()) return rel;
    if (dir.back() == '/') return dir + rel;
    return dir + "/" + rel;
}

std::string dir_of(const std::string &path) {
    size_t p = path.find_last_of('/');
    if (p == std::string::npos) return "";
    if (p == 0) return "/";
    return path.substr(0, p);
}

std::string url_decode(const std::string &s) {
    std::string out;
    out.reserve(s.size());
    for (size_t i = 0; i < s.size(); ++i) {
        if (s[i] == '%' && i + 2 < s.size() && std::isxdigit((unsigned char)s[i + 1]) &&
            std::isxdigit((unsigned char)s[i + 2])) {
            out += char(std::stoi(s.substr(i + 1, 2), nullptr, 16));
            i += 2;
        } else {
            out += s[i];
        }
    }
    return out;
}

bool is_regular_file(const std::string &p) {
    struct stat st;
    return ::stat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

// The scene file through the one input door (io_open_input: regular files only, never a
// FIFO's blocking open or /dev/zero's endless bytes; the size checked before reading).
bool read_whole_file(const std::string &path, std::vector<unsigned char> *out, std::string *problem) {
    void *data = nullptr;
    size_t n = 0;
    char err[IO_ERR_LEN];
    if (io_read_input(path.c_str(), IO_MAX_SCENE_BYTES, "a scene (4 GiB)", &data, &n, err) != 0) {
        // io's message starts with the path, which the caller adds again
        const std::string m(err);
        *problem = m.compare(0, path.size() + 2, path + ": ") == 0 ? m.substr(path.size() + 2) : m;
        return false;
    }
    const unsigned char *p = static_cast<const unsigned char *>(data);
    out->assign(p, p + n);
    std::free(data);
    return true;
}

// tinygltf ReadWholeFile callback (buffer files): the same door, so a buffer URI naming a FIFO
// or a device is refused even if it changed after the FileExists check.
bool fs_read_whole_file(std::vector<unsigned char> *out, std::string *err, const std::string &path, void *) {
    std::string problem;
    if (read_whole_file(path, out, &problem)) return true;
    if (err) *err = path + ": " + problem;
    return false;
}

// The file-reference policy (README "Scene input"): a scene may reference files anywhere,
// relative to its own folder (production scenes use ../textures/), unless a confinement
// folder is given (`--confine-to DIR`, for farms rendering uploaded scenes): then every file
// it references must resolve (symbolic links and .. followed, by realpath) inside DIR.
bool inside_folder(const std::string &file, const std::string &folder_real) {
    if (folder_real.empty()) return true;
    char *r = ::realpath(file.c_str(), nullptr);
    if (!r) return false;
    const std::string real(r);
    std::free(r);
    // "/" holds every path ("/" + "/" is the prefix of none)
    return folder_real == "/" || real.compare(0, folder_real.size() + 1, folder_real + "/") == 0;
}

struct FsUser {
    std::string dir, confine;
};

// tinygltf FileExists callback: a buffer file is looked up only under the glTF's own folder
// path (tinygltf would otherwise also search the current working directory) and, with a
// confinement folder, only when it resolves inside it.
bool fs_file_exists(const std::string &abs_filename, void *user) {
    const FsUser &fs = *static_cast<const FsUser *>(user);
    if (!fs.dir.empty()) {
        std::string prefix = fs.dir.back() == '/' ? fs.dir : fs.dir + "/";
        if (abs_filename.compare(0, prefix.size(), prefix) != 0) return false;
    }
    return is_regular_file(abs_filename) && inside_folder(abs_filename, fs.confine);
}

// tinygltf image callback: decode nothing. Keep the bytes of data: URI images (tinygltf
// keeps neither the URI nor the bytes for those); file and bufferView images are read later.
bool keep_image_bytes(tinygltf::Image *image, const int, std::string *, std::string *, int, int,
                      const unsigned char *bytes, int size, void *) {
    if (image->uri.empty() && image->bufferView < 0 && bytes && size > 0)
        image->image.assign(bytes, bytes + size);
    return true;
}

// ---- small JSON-value helpers (tinygltf::Value asserts on wrong types, so check first) ----

const tinygltf::Value *member(const tinygltf::Value &o, const char *key) {
    if (!o.IsObject() || !o.Has(key)) return nullptr;
    return &o.Get(key);
}

double number_or(const tinygltf::Value &o, const char *key, double def) {
    const tinygltf::Value *v = member(o, key);
    return (v && v->IsNumber()) ? v->GetNumberAsDouble() : def;
}

// An index from a JSON number: -1 unless it is a whole number in [0, 2^31) (a cast of 1e10 to
// int is undefined behaviour).
static int index_value(const tinygltf::Value &v) {
    if (!v.IsNumber()) return -1;
    const double d = v.GetNumberAsDouble();
    return d >= 0.0 && d < 2147483648.0 && d == std::floor(d) ? int(d) : -1;
}

// The deepest nesting of arrays and objects in a JSON text (strings skipped): tinygltf's
// parser recurses once per level, so a file nesting hundreds of thousands of levels
// overflowed the stack. Documented limit: JSON_MAX_DEPTH.
static constexpr int JSON_MAX_DEPTH = 512;
static int json_depth(const unsigned char *p, size_t n) {
    int depth = 0, deepest = 0;
    bool in_string = false;
    for (size_t i = 0; i < n; ++i) {
        const unsigned char c = p[i];
        if (in_string) {
            if (c == '\\') ++i;
            else if (c == '"') in_string = false;
        } else if (c == '"') {
            in_string = true;
        } else if (c == '[' || c == '{') {
            if (++depth > deepest) deepest = depth;
        } else if (c == ']' || c == '}') {
            --depth;
        }
    }
    return deepest;
}

// Fill n numbers from array member key, if present and well-formed.
void numbers(const tinygltf::Value &o, const char *key, float *dst, size_t n) {
    const tinygltf::Value *v = member(o, key);
    if (!v || !v->IsArray() || v->ArrayLen() != n) return;
    for (size_t i = 0; i < n; ++i) {
        const tinygltf::Value &e = v->Get(int(i));
        if (!e.IsNumber()) return;
    }
    for (size_t i = 0; i < n; ++i) dst[i] = float(v->Get(int(i)).GetNumberAsDouble());
}

// A finite (in float) number at o[key], or def when the key is absent; fails otherwise.
double finite_number(const tinygltf::Value &o, const char *key, double def, const std::string &what) {
    const tinygltf::Value *v = member(o, key);
    if (!v) return def;
    if (!v->IsNumber()) fail(what + "." + key + " must be a number");
    const double d = v->GetNumberAsDouble();
    if (!std::isfinite(d) || !std::isfinite(float(d))) fail(what + "." + key + " must be a finite number");
    return d;
}

// Three finite (in float) numbers at o[key] into dst; dst untouched when the key is absent.
void finite_vec3(const tinygltf::Value &o, const char *key, float dst[3], const std::string &what) {
    const tinygltf::Value *v = member(o, key);
    if (!v) return;
    bool ok = v->IsArray() && v->ArrayLen() == 3;
    for (int i = 0; ok && i < 3; ++i) {
        const tinygltf::Value &e = v->Get(i);
        ok = e.IsNumber() && std::isfinite(e.GetNumberAsDouble()) && std::isfinite(float(e.GetNumberAsDouble()));
    }
    if (!ok) fail(what + "." + key + " must be an array of 3 finite numbers");
    for (int i = 0; i < 3; ++i) dst[i] = float(v->Get(i).GetNumberAsDouble());
}

// tinygltf drops empty objects, empty arrays and nulls from extras. For the keys whose mere
// presence matters (candela_medium: {} is a medium with the defaults; candela_volume: {}
// lacks its uri), look at the original JSON text of the extras object (stored by tinygltf,
// compact, as nlohmann dumps it): the first character of the value of top-level member
// `key`, or 0 when there is no such member.
char raw_member_start(const std::string &json, const char *key) {
    const std::string quoted = std::string("\"") + key + "\"";
    int depth = 0;
    for (size_t i = 0; i < json.size(); ++i) {
        const char c = json[i];
        if (c == '"') {
            size_t j = i + 1;
            while (j < json.size() && json[j] != '"') j += json[j] == '\\' ? 2 : 1;
            if (j >= json.size()) return 0;
            if (depth == 1 && json.compare(i, j + 1 - i, quoted) == 0 && j + 1 < json.size() && json[j + 1] == ':')
                return j + 2 < json.size() ? json[j + 2] : 0;
            i = j;
        } else if (c == '{' || c == '[') {
            ++depth;
        } else if (c == '}' || c == ']') {
            --depth;
        }
    }
    return 0;
}

const tinygltf::Value *extension(const tinygltf::ExtensionMap &ext, const char *name) {
    auto it = ext.find(name);
    return it == ext.end() ? nullptr : &it->second;
}

// ---- 4x4 column-major double matrices (m[col*4 + row]) ----

struct Mat4 {
    double m[16];
};

Mat4 identity() {
    Mat4 r{};
    r.m[0] = r.m[5] = r.m[10] = r.m[15] = 1.0;
    return r;
}

Mat4 mul(const Mat4 &a, const Mat4 &b) {
    Mat4 r{};
    for (int c = 0; c < 4; ++c)
        for (int row = 0; row < 4; ++row) {
            double s = 0.0;
            for (int k = 0; k < 4; ++k) s += a.m[k * 4 + row] * b.m[c * 4 + k];
            r.m[c * 4 + row] = s;
        }
    return r;
}

// ---- accessor views ----

const unsigned char kZeros[64] = {};

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

float comp_to_float(const unsigned char *p, int ct, bool normalized) {
    switch (ct) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
        float v;
        std::memcpy(&v, p, 4);
        return v;
    }
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
        int8_t v;
        std::memcpy(&v, p, 1);
        return normalized ? std::max(float(v) / 127.0f, -1.0f) : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return normalized ? float(p[0]) / 255.0f : float(p[0]);
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
        int16_t v;
        std::memcpy(&v, p, 2);
        return normalized ? std::max(float(v) / 32767.0f, -1.0f) : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t v;
        std::memcpy(&v, p, 2);
        return normalized ? float(v) / 65535.0f : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
        uint32_t v;
        std::memcpy(&v, p, 4);
        return normalized ? float(double(v) / 4294967295.0) : float(v);
    }
    default:
        return 0.0f;
    }
}

uint32_t comp_to_uint(const unsigned char *p, int ct) {
    switch (ct) {
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return p[0];
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t v;
        std::memcpy(&v, p, 2);
        return v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
        uint32_t v;
        std::memcpy(&v, p, 4);
        return v;
    }
    default:
        return UINT32_MAX;
    }
}

bool is_index_type(int ct) {
    return ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
           ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ||
           ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
}

const char *type_name(int t) {
    switch (t) {
    case TINYGLTF_TYPE_SCALAR: return "SCALAR";
    case TINYGLTF_TYPE_VEC2: return "VEC2";
    case TINYGLTF_TYPE_VEC3: return "VEC3";
    case TINYGLTF_TYPE_VEC4: return "VEC4";
    case TINYGLTF_TYPE_MAT2: return "MAT2";
    case TINYGLTF_TYPE_MAT3: return "MAT3";
    case TINYGLTF_TYPE_MAT4: return "MAT4";
    default: return "invalid";
    }
}

// ---- the loader ----

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
    bool bulk_pass(const unsigned char *json, size_t len, std::string *kept);
    bool use_bulk_pass(const unsigned char *json, size_t len, std::string *kept);
    void convert_light_defs();
    void place_bulk(int gi, const Mat4 &parent, int32_t parent_walk);
    template <class What>
    void place_light(size_t l, const std::string &node_name, const What &what, const double *world_m,
                     int32_t walk_index, const tinygltf::Node *node);

    void parse();
    void check_animation_indices(const unsigned char *json, size_t len);
    void check_required_extensions();
    void warn_unrendered();
    const unsigned char *view_span(int bvi, long long offset, size_t need, const std::string &what,
                                   size_t *stride);
    AccView accessor(int ai, const std::string &what, int want_type);
    float *read_floats(const AccView &v, const std::string &what, bool check_finite);
    void convert_meshes();
    void convert_primitive(const tinygltf::Mesh &mesh, size_t pi);
    int32_t image_for(int gltf_image, bool srgb, const std::string &what);
    template <class Info>
    IoTextureRef texture_ref(const Info &info, bool srgb, const std::string &what);
    void convert_materials();
    void material_medium(const tinygltf::Material &src, const std::string &what, IoMaterial *d);
    void flatten_nodes();
    void convert_animations();
    void convert_channel(const tinygltf::Animation &anim, size_t ai, size_t ci);
    void load_volume(const tinygltf::Node &node, const std::string &what, const Mat4 &world);
    void light_shape_extras(const tinygltf::Node &node, const std::string &what, IoLight &d);
    void load_area_light(const tinygltf::Node &node, const std::string &what, const Mat4 &world, int32_t walk_index);
    void convert_light_links();
    std::vector<IoLightLink> light_links_;
    std::vector<uint32_t> link_instances_;
    void load_grid(const std::string &vdb, const std::string &grid, const std::string &what, IoVolumeGrid *out);
    void environment(IoScene *out);
    void transfer(IoScene *out);
};

// How many light nodes make the bulk pass worth its second parse: below this the file goes to
// tinygltf whole, as it always did (its JSON tree and Model cost ~5 KB per light node, 5 GB for
// issue 28's street of 1M lights; 20 MB at this count).
static constexpr size_t BULK_MIN_LIGHTS = 4096;

static size_t count_occurrences(const unsigned char *p, size_t n, const char *what) {
    const size_t w = std::strlen(what);
    size_t count = 0;
    for (const unsigned char *at = p, *end = p + n;
         (at = std::search(at, end, what, what + w)) != end; at += w)
        ++count;
    return count;
}

static bool number_array(const nlohmann::json &v, size_t n, double *out) {
    if (!v.is_array() || v.size() != n) return false;
    for (size_t k = 0; k < n; ++k) {
        if (!v[k].is_number()) return false;
        out[k] = v[k].get<double>();
    }
    return true;
}

// The bulk pass: nlohmann parses the JSON with a callback that takes each plain light node
// ({"name", "translation", "rotation", "scale", "extensions": {"KHR_lights_punctual":
// {"light": i}}} and nothing else) and each plain light record ("name", "type", "color",
// "intensity", "range", "spot" with its two angles) as it completes, stores it compactly and
// drops it from the tree, so the tree never holds them; what is left (every other node, kept in
// its place by kept_of_gltf_, and the rest of the file) is written back as JSON for tinygltf.
// Values are read as tinygltf reads them (nlohmann's doubles, tinygltf's defaults), so a light
// comes out the same either way. False: the file is not one the pass handles (malformed JSON,
// duplicate top-level keys); tinygltf then parses it whole and reports what it finds.
bool Loader::bulk_pass(const unsigned char *json, size_t len, std::string *kept) {
    std::string key_at[4];
    size_t n_nodes_arrays = 0, n_light_arrays = 0;
    int32_t kept_nodes = 0, kept_lights = 0;
    auto in_nodes = [&]() { return key_at[1] == "nodes"; };
    auto in_lights = [&]() {
        return key_at[1] == "extensions" && key_at[2] == "KHR_lights_punctual" && key_at[3] == "lights";
    };
    auto add_name = [&](const nlohmann::json &o, uint32_t *at, uint32_t *n) {
        auto it = o.find("name");
        if (it == o.end()) return;
        const std::string &name = it->get_ref<const std::string &>();
        *at = uint32_t(names_.size());
        *n = uint32_t(name.size());
        names_ += name;
    };
    auto plain_node = [&](const nlohmann::json &o) {
        if (!o.is_object() || names_.size() > UINT32_MAX / 2) return false;
        BulkNode b;
        bool light = false;
        for (auto it = o.begin(); it != o.end(); ++it) {
            const std::string &k = it.key();
            const nlohmann::json &v = it.value();
            if (k == "name") {
                if (!v.is_string()) return false;
            } else if (k == "translation") {
                if (!number_array(v, 3, b.t)) return false;
                b.has_t = 1;
            } else if (k == "rotation") {
                if (!number_array(v, 4, b.q)) return false;
                b.has_r = 1;
            } else if (k == "scale") {
                if (!number_array(v, 3, b.s)) return false;
                b.has_s = 1;
            } else if (k == "extensions") {
                if (!v.is_object() || v.size() != 1) return false;
                auto lp = v.find("KHR_lights_punctual");
                if (lp == v.end() || !lp->is_object() || lp->size() != 1) return false;
                auto li = lp->find("light");
                if (li == lp->end() || !li->is_number_unsigned() || li->get<uint64_t>() >= 2147483648u) return false;
                b.light = int32_t(li->get<uint64_t>());
                light = true;
            } else {
                return false;
            }
        }
        if (!light) return false;
        add_name(o, &b.name_at, &b.name_len);
        bulk_nodes_.push_back(b);
        return true;
    };
    auto plain_light = [&](const nlohmann::json &o) {
        if (!o.is_object() || names_.size() > UINT32_MAX / 2) return false;
        LightDef d;
        std::string type;
        bool spot_seen = false;
        for (auto it = o.begin(); it != o.end(); ++it) {
            const std::string &k = it.key();
            const nlohmann::json &v = it.value();
            if (k == "name" || k == "type") {
                if (!v.is_string()) return false;
                if (k == "type") type = v.get<std::string>();
            } else if (k == "color") {
                if (!number_array(v, 3, d.color)) return false;
                d.has_color = true;
            } else if (k == "intensity" || k == "range") {
                if (!v.is_number()) return false;
                (k == "intensity" ? d.intensity : d.range) = v.get<double>();
            } else if (k == "spot") {
                if (!v.is_object()) return false;
                for (auto a = v.begin(); a != v.end(); ++a) {
                    if (!a.value().is_number()) return false;
                    if (a.key() == "innerConeAngle") d.inner = a.value().get<double>();
                    else if (a.key() == "outerConeAngle") d.outer = a.value().get<double>();
                    else return false;
                }
                spot_seen = true;
            } else {
                return false;
            }
        }
        if (type == "point" || type == "directional") {
            if (spot_seen) return false; // tinygltf ignores it; leave that to tinygltf
            d.type = type == "point" ? IO_LIGHT_POINT : IO_LIGHT_DIRECTIONAL;
        } else if (type == "spot" && spot_seen) {
            d.type = IO_LIGHT_SPOT;
        } else {
            return false;
        }
        add_name(o, &d.name_at, &d.name_len);
        light_defs_.push_back(d);
        return true;
    };
    nlohmann::json d;
    try {
        d = nlohmann::json::parse(json, json + len, [&](int depth, nlohmann::json::parse_event_t e, nlohmann::json &v) {
            using E = nlohmann::json::parse_event_t;
            if (e == E::key && depth >= 1 && depth <= 3) {
                key_at[depth] = v.get<std::string>();
                for (int k = depth + 1; k <= 3; ++k) key_at[k].clear();
                if (depth == 1 && key_at[1] == "nodes") ++n_nodes_arrays;
                if (depth == 3 && in_lights()) ++n_light_arrays;
                return true;
            }
            const bool done = e == E::value || e == E::object_end || e == E::array_end;
            if (done && depth == 2 && in_nodes()) { // an element of "nodes" completed
                if (plain_node(v)) {
                    kept_of_gltf_.push_back(-int32_t(bulk_nodes_.size()));
                    return false;
                }
                kept_of_gltf_.push_back(kept_nodes++);
            } else if (done && depth == 4 && in_lights()) { // an element of the lights completed
                if (plain_light(v)) {
                    light_kept_.push_back(-1);
                    return false;
                }
                light_defs_.emplace_back();
                light_kept_.push_back(kept_lights++);
            }
            return true;
        });
    } catch (const std::bad_alloc &) {
        throw;
    } catch (const std::exception &) {
        d = nlohmann::json();
        n_nodes_arrays = 2; // malformed: tinygltf reports it
    }
    if (n_nodes_arrays > 1 || n_light_arrays > 1 || kept_of_gltf_.size() > size_t(INT32_MAX) ||
        light_defs_.size() > size_t(INT32_MAX)) {
        bulk_nodes_ = std::vector<BulkNode>();
        kept_of_gltf_ = std::vector<int32_t>();
        light_kept_ = std::vector<int32_t>();
        light_defs_ = std::vector<LightDef>();
        names_ = std::string();
        return false;
    }
    kept_of_gltf_.shrink_to_fit();
    light_kept_.shrink_to_fit();
    *kept = d.dump();
    return true;
}

// Every light record as place_light reads it, in the file's order: tinygltf's, and the bulk
// pass's where it read them.
void Loader::convert_light_defs() {
    if (!bulk_) light_defs_.assign(m_.lights.size(), LightDef{});
    for (size_t i = 0; i < light_defs_.size(); ++i) {
        if (bulk_ && light_kept_[i] < 0) continue;
        const tinygltf::Light &src = m_.lights[bulk_ ? size_t(light_kept_[i]) : i];
        LightDef &d = light_defs_[i];
        if (!src.name.empty()) {
            d.name_at = uint32_t(names_.size());
            d.name_len = uint32_t(src.name.size());
            names_ += src.name;
        }
        if (src.type == "point")
            d.type = IO_LIGHT_POINT;
        else if (src.type == "spot")
            d.type = IO_LIGHT_SPOT;
        else if (src.type == "directional")
            d.type = IO_LIGHT_DIRECTIONAL;
        else
            type_name_[i] = src.type;
        d.has_color = src.color.size() == 3;
        for (int c = 0; c < 3; ++c) d.color[c] = d.has_color ? src.color[size_t(c)] : 1.0;
        d.intensity = src.intensity;
        d.range = src.range;
        d.inner = src.spot.innerConeAngle;
        d.outer = src.spot.outerConeAngle;
    }
}

// The bulk pass when the file has many light nodes (BULK_MIN_LIGHTS); false: tinygltf reads it whole.
bool Loader::use_bulk_pass(const unsigned char *json, size_t len, std::string *kept) {
    const size_t lights = count_occurrences(json, len, "\"KHR_lights_punctual\"");
    if (lights < (bulk_min_lights_ ? bulk_min_lights_ : BULK_MIN_LIGHTS)) return false;
    // reserved from counts of the text (upper bounds), so the records never grow by doubling
    bulk_nodes_.reserve(lights);
    light_defs_.reserve(std::min(lights, count_occurrences(json, len, "\"type\"")));
    bulk_ = bulk_pass(json, len, kept);
    return bulk_;
}

void Loader::parse() {
    std::vector<unsigned char> bytes;
    std::string problem;
    if (!read_whole_file(path_, &bytes, &problem)) fail(problem);
    if (bytes.empty()) fail("file is empty");
    if (!looks_like_gltf(bytes)) fail("not a glTF 2.0 file (.gltf or .glb expected)");

    tinygltf::TinyGLTF tg;
    tg.SetImageLoader(&keep_image_bytes, nullptr);
    tg.SetStoreOriginalJSONForExtrasAndExtensions(true);  // for raw_member_start
    tinygltf::FsCallbacks fs = {&fs_file_exists, &tinygltf::ExpandFilePath,
                                &fs_read_whole_file, &tinygltf::WriteWholeFile, &fs_user_};
    tg.SetFsCallbacks(fs);

    std::string err, warn_s;
    bool ok = false;
    std::string kept; // the bulk pass's JSON (a .gltf file's whole text; a GLB's JSON chunk)
    try {
        if (bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0) {
            // Validate the GLB container ourselves first: tinygltf 2.7.0's BIN-chunk bound
            // check omits the 8-byte chunk header and can read past the end of the file.
            const size_t n = bytes.size();
            auto u32 = [&](size_t off) {
                uint32_t v;
                std::memcpy(&v, bytes.data() + off, 4);
                return v;  // GLB is little-endian; so is every platform we build for
            };
            if (n < 20) fail(strf("truncated GLB (%zu bytes, header needs 20)", n));
            const uint32_t version = u32(4), length = u32(8), json_len = u32(12);
            if (version != 2) fail(strf("unsupported GLB version %u", version));
            if (length > n) fail(strf("truncated GLB: header says %u bytes, file has %zu", length, n));
            if (length < 20 || uint64_t(json_len) + 20 > length || u32(16) != 0x4E4F534Au)
                fail("invalid GLB: bad JSON chunk");
            const uint64_t bin_at = 20ull + json_len;
            if (bin_at < length) {
                if (bin_at + 8 > length) fail("invalid GLB: truncated BIN chunk header");
                if (bin_at + 8 + uint64_t(u32(size_t(bin_at))) > length)
                    fail("invalid GLB: BIN chunk exceeds the file");
            }
            if (json_depth(bytes.data() + 20, json_len) > JSON_MAX_DEPTH)
                fail(strf("JSON nests deeper than %d levels", JSON_MAX_DEPTH));
            uint32_t glb_length = length;
            if (use_bulk_pass(bytes.data() + 20, json_len, &kept)) {
                // the GLB again, its JSON chunk the pass's (padded with spaces, as GLB pads it)
                while (kept.size() % 4) kept += ' ';
                const size_t bin = bin_at < length ? length - size_t(bin_at) : 0;
                if (kept.size() + bin + 20 > UINT32_MAX) fail("GLB too large after the bulk pass");
                std::vector<unsigned char> glb(20 + kept.size() + bin);
                auto put = [&](size_t off, uint32_t v) { std::memcpy(glb.data() + off, &v, 4); };
                std::memcpy(glb.data(), bytes.data(), 8);
                put(8, uint32_t(glb.size()));
                put(12, uint32_t(kept.size()));
                put(16, 0x4E4F534Au);
                std::memcpy(glb.data() + 20, kept.data(), kept.size());
                if (bin) std::memcpy(glb.data() + 20 + kept.size(), bytes.data() + bin_at, bin);
                bytes.swap(glb);
                glb_length = uint32_t(bytes.size());
            }
            ok = tg.LoadBinaryFromMemory(&m_, &err, &warn_s, bytes.data(), glb_length, dir_);
        } else {
            if (json_depth(bytes.data(), bytes.size()) > JSON_MAX_DEPTH)
                fail(strf("JSON nests deeper than %d levels", JSON_MAX_DEPTH));
            if (use_bulk_pass(bytes.data(), bytes.size(), &kept)) {
                if (kept.size() > UINT32_MAX) fail("JSON too large after the bulk pass");
                std::vector<unsigned char>().swap(bytes); // the file's text: no longer needed
                bytes.assign(kept.begin(), kept.end());
                std::string().swap(kept);
            }
            ok = tg.LoadASCIIFromString(&m_, &err, &warn_s, reinterpret_cast<const char *>(bytes.data()),
                                        static_cast<unsigned int>(bytes.size()), dir_);
        }
    } catch (const LoadError &) {
        throw;
    } catch (const std::bad_alloc &) {
        throw;
    } catch (const std::exception &e) {
        fail(std::string("malformed glTF: ") + e.what());
    }
    // tinygltf's warnings, one per line
    size_t start = 0;
    while (start < warn_s.size()) {
        size_t end = warn_s.find('\n', start);
        if (end == std::string::npos) end = warn_s.size();
        std::string line = warn_s.substr(start, end - start);
        if (!line.empty() && ok) warn(line);
        start = end + 1;
    }
    if (!ok) {
        std::string msg = candela_io::one_line(err);
        if (msg.empty()) msg = candela_io::one_line(warn_s);
        if (msg.empty()) msg = "tinygltf could not parse the file";
        if (!fs_user_.confine.empty() && msg.find("File not found") != std::string::npos)
            msg += " (or outside " + fs_user_.confine + ": --confine-to)";
        fail(msg);
    }
    // tinygltf drops an animation channel whose "sampler" or "node" is not an integer without
    // failing the load, so "node": 1.5 used to animate nothing, silently: the indices are read
    // again from the JSON (only when the file has animations)
    const unsigned char *json = bytes.data();
    size_t json_len = bytes.size();
    if (json_len >= 20 && std::memcmp(json, "glTF", 4) == 0) {
        uint32_t len;
        std::memcpy(&len, json + 12, 4);
        json += 20;
        json_len = len; // checked above
    }
    static const char key[] = "\"animations\"";
    if (std::search(json, json + json_len, key, key + sizeof key - 1) != json + json_len) check_animation_indices(json, json_len);
}

// Every animation channel's "sampler" and "target.node" must be JSON integers (README "Limits":
// indices are whole numbers; a sampler's "input" or "output" that is not fails tinygltf's own
// parse); a channel without a node is the glTF spec's "ignore this channel".
void Loader::check_animation_indices(const unsigned char *json, size_t len) {
    nlohmann::json d;
    try {
        d = nlohmann::json::parse(json, json + len);
    } catch (const std::exception &e) {
        fail(std::string("malformed glTF: ") + e.what());
    }
    const auto anims = d.find("animations");
    if (anims == d.end() || !anims->is_array()) return;
    auto whole = [](const nlohmann::json &v) { return v.is_number_integer() || v.is_number_unsigned(); };
    for (size_t ai = 0; ai < anims->size(); ++ai) {
        const nlohmann::json &a = (*anims)[ai];
        if (!a.is_object()) continue;
        const auto check = [&](const nlohmann::json &o, const char *field, const std::string &where) {
            auto it = o.find(field);
            if (it != o.end() && !whole(*it))
                fail(strf("animation %zu %s: \"%s\" must be a whole number (an integer index), not %s", ai, where.c_str(), field,
                          it->dump().substr(0, 40).c_str()));
        };
        if (auto chans = a.find("channels"); chans != a.end() && chans->is_array())
            for (size_t ci = 0; ci < chans->size(); ++ci) {
                const nlohmann::json &c = (*chans)[ci];
                if (!c.is_object()) continue;
                check(c, "sampler", strf("channel %zu", ci));
                if (auto t = c.find("target"); t != c.end() && t->is_object()) check(*t, "node", strf("channel %zu target", ci));
            }
    }
}

// The extensions the renderer renders (a required one outside this list refuses the file, a
// used one is warned about).
static bool extension_supported(const std::string &e) {
    static const char *supported[] = {
        "KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_materials_specular",
        "KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume", "KHR_texture_transform",
        "KHR_materials_clearcoat"};
    for (const char *s : supported)
        if (e == s) return true;
    return false;
}

void Loader::check_required_extensions() {
    for (const std::string &e : m_.extensionsRequired)
        if (!extension_supported(e)) fail("requires unsupported extension '" + e + "'");
}

// One warning per feature the file has and the renderer reads past (issue 14): an exporter
// (Blender's writes KHR_materials_clearcoat, animations, BLEND) gets exit 0 and an image that
// differs from its own renderer's, so say what was left out. After the file parsed; the
// animations' warning is the renderer's (a frame batch renders them).
void Loader::warn_unrendered() {
    for (const std::string &e : m_.extensionsUsed)
        if (!extension_supported(e) && std::find(m_.extensionsRequired.begin(), m_.extensionsRequired.end(), e) ==
                                           m_.extensionsRequired.end())
            warn("extension '" + e + "' is not supported; it is ignored (extensionsUsed)");
    std::vector<std::string> blend;
    for (const tinygltf::Material &m : m_.materials)
        if (m.alphaMode == "BLEND") blend.push_back("'" + m.name + "'");
    if (!blend.empty()) {
        std::string names;
        for (size_t i = 0; i < blend.size() && i < 3; ++i) names += (i ? ", " : "") + blend[i];
        if (blend.size() > 3) names += strf(" and %zu more", blend.size() - 3);
        warn(strf("alphaMode BLEND is rendered as MASK (cut out below alphaCutoff, default 0.5; opaque above) in %zu "
                  "material%s: ",
                  blend.size(), blend.size() == 1 ? "" : "s") +
             names);
    }
    if (!m_.skins.empty())
        warn(strf("%zu skin%s ignored: skinned meshes render in their node's rest transform", m_.skins.size(),
                  m_.skins.size() == 1 ? "" : "s"));
}

// Pointer to [offset, offset+need) inside bufferView bvi, after checking the view lies inside
// its buffer. *stride receives the view's byteStride (0 = tightly packed).
const unsigned char *Loader::view_span(int bvi, long long offset, size_t need,
                                       const std::string &what, size_t *stride) {
    if (bvi < 0 || size_t(bvi) >= m_.bufferViews.size())
        fail(strf("%s: bufferView %d out of range", what.c_str(), bvi));
    const tinygltf::BufferView &bv = m_.bufferViews[size_t(bvi)];
    if (bv.buffer < 0 || size_t(bv.buffer) >= m_.buffers.size())
        fail(strf("%s: bufferView %d references missing buffer %d", what.c_str(), bvi, bv.buffer));
    const tinygltf::Buffer &buf = m_.buffers[size_t(bv.buffer)];
    const size_t bsize = buf.data.size();
    if (bv.byteOffset > bsize || bv.byteLength > bsize - bv.byteOffset)
        fail(strf("%s: bufferView %d (offset %zu, length %zu) exceeds buffer %d (%zu bytes)",
                  what.c_str(), bvi, bv.byteOffset, bv.byteLength, bv.buffer, bsize));
    if (offset < 0 || uint64_t(offset) > bv.byteLength || need > bv.byteLength - uint64_t(offset))
        fail(strf("%s: data (offset %lld, %zu bytes) exceeds bufferView %d (%zu bytes)", what.c_str(),
                  offset, need, bvi, bv.byteLength));
    if (stride) *stride = bv.byteStride;
    return buf.data.data() + bv.byteOffset + size_t(offset);
}

AccView Loader::accessor(int ai, const std::string &what, int want_type) {
    if (ai < 0 || size_t(ai) >= m_.accessors.size())
        fail(strf("%s: accessor %d out of range", what.c_str(), ai));
    const tinygltf::Accessor &a = m_.accessors[size_t(ai)];
    const std::string w = what + strf(" (accessor %d)", ai);
    const int nc = tinygltf::GetNumComponentsInType(uint32_t(a.type));
    const int cs = tinygltf::GetComponentSizeInBytes(uint32_t(a.componentType));
    if (nc <= 0 || cs <= 0 || a.componentType == TINYGLTF_COMPONENT_TYPE_INT ||
        a.componentType == TINYGLTF_COMPONENT_TYPE_DOUBLE)
        fail(w + ": invalid type or componentType");
    if (a.type != want_type)
        fail(strf("%s: type %s, expected %s", w.c_str(), type_name(a.type), type_name(want_type)));
    if (a.count == 0) fail(w + ": count is 0");
    if (a.count > kMaxCount) fail(strf("%s: count %zu too large", w.c_str(), a.count));

    AccView v;
    v.count = a.count;
    v.ct = a.componentType;
    v.ncomp = nc;
    v.normalized = a.normalized;
    v.elem = size_t(nc) * size_t(cs);
    if (a.bufferView >= 0) {
        size_t bstride = 0;
        view_span(a.bufferView, 0, 0, w, &bstride);  // validates the view itself
        v.stride = bstride ? bstride : v.elem;
        if (v.stride < v.elem || v.stride > 4096)
            fail(strf("%s: byteStride %zu invalid for %zu-byte elements", w.c_str(), v.stride, v.elem));
        if (a.byteOffset > (size_t(1) << 40)) fail(w + ": byteOffset too large");
        // byteOffset + stride*(count-1) + elemsize <= bufferView length (no overflow: count
        // <= 2^28, stride <= 4096, offset <= 2^40)
        const size_t need = v.stride * (v.count - 1) + v.elem;
        v.base = view_span(a.bufferView, (long long)a.byteOffset, need, w, nullptr);
    }
    if (a.sparse.isSparse) {
        const int sc = a.sparse.count;
        if (sc <= 0 || size_t(sc) > a.count)
            fail(strf("%s: sparse count %d invalid (accessor count %zu)", w.c_str(), sc, a.count));
        const int ict = a.sparse.indices.componentType;
        if (!is_index_type(ict)) fail(w + ": sparse indices have an invalid componentType");
        const size_t ics = size_t(tinygltf::GetComponentSizeInBytes(uint32_t(ict)));
        const unsigned char *ip = view_span(a.sparse.indices.bufferView, a.sparse.indices.byteOffset,
                                            ics * size_t(sc), w + " sparse indices", nullptr);
        v.sp_vals = view_span(a.sparse.values.bufferView, a.sparse.values.byteOffset,
                              v.elem * size_t(sc), w + " sparse values", nullptr);
        v.sp_map.assign(v.count, -1);
        for (int k = 0; k < sc; ++k) {
            uint32_t idx = comp_to_uint(ip + size_t(k) * ics, ict);
            if (idx >= v.count)
                fail(strf("%s: sparse index %u out of range (count %zu)", w.c_str(), idx, v.count));
            v.sp_map[idx] = k;
        }
    }
    return v;
}

float *Loader::read_floats(const AccView &v, const std::string &what, bool check_finite) {
    const size_t n = v.count * size_t(v.ncomp);
    float *out = static_cast<float *>(std::malloc(n * sizeof(float)));
    if (!out) throw std::bad_alloc();
    const size_t cs = v.elem / size_t(v.ncomp);
    for (size_t i = 0; i < v.count; ++i) {
        const unsigned char *p = v.at(i);
        for (int c = 0; c < v.ncomp; ++c) {
            float f = comp_to_float(p + size_t(c) * cs, v.ct, v.normalized);
            if (check_finite && !std::isfinite(f)) {
                std::free(out);
                fail(what);
            }
            out[i * size_t(v.ncomp) + size_t(c)] = f;
        }
    }
    return out;
}

void Loader::convert_primitive(const tinygltf::Mesh &mesh, size_t pi) {
    const tinygltf::Primitive &p = mesh.primitives[pi];
    const std::string where = strf("mesh '%s' primitive %zu", mesh.name.c_str(), pi);
    const int mode = p.mode < 0 ? TINYGLTF_MODE_TRIANGLES : p.mode;
    if (mode >= TINYGLTF_MODE_POINTS && mode <= TINYGLTF_MODE_LINE_STRIP) {
        warn(where + strf(": mode %d (points/lines) skipped", mode));
        return;
    }
    if (mode > TINYGLTF_MODE_TRIANGLE_FAN) fail(strf("%s: invalid mode %d", where.c_str(), mode));
    if (!p.targets.empty() && !warned_morph_) {
        warned_morph_ = true;
        warn("morph targets ignored");
    }
    if (p.material < -1 || (p.material >= 0 && size_t(p.material) >= m_.materials.size()))
        fail(strf("%s: material %d out of range", where.c_str(), p.material));

    auto attr = [&](const char *name) {
        auto it = p.attributes.find(name);
        return it == p.attributes.end() ? -1 : it->second;
    };
    const int pos_ai = attr("POSITION");
    if (pos_ai < 0) fail(where + ": no POSITION attribute");
    if (attr("COLOR_0") >= 0 && !warned_color_) {
        warned_color_ = true;
        warn(where + ": vertex colours (COLOR_0) are ignored (the base colour does not include them)");
    }

    prims_.push_back(IoPrimitive{});
    IoPrimitive &out = prims_.back();
    out.material = p.material;

    // POSITION: VEC3 float, finite
    AccView pv = accessor(pos_ai, where + " POSITION", TINYGLTF_TYPE_VEC3);
    if (pv.ct != TINYGLTF_COMPONENT_TYPE_FLOAT) fail(where + " POSITION: componentType must be FLOAT");
    const size_t nv = pv.count;
    out.num_vertices = uint32_t(nv);
    out.positions = read_floats(pv, strf("mesh '%s' has non-finite vertex positions", mesh.name.c_str()), true);

    auto same_count = [&](const AccView &v, const char *name) {
        if (v.count != nv)
            fail(strf("%s: %s count %zu differs from POSITION count %zu", where.c_str(), name, v.count, nv));
    };
    if (int ai = attr("NORMAL"); ai >= 0) {
        AccView v = accessor(ai, where + " NORMAL", TINYGLTF_TYPE_VEC3);
        if (v.ct != TINYGLTF_COMPONENT_TYPE_FLOAT) fail(where + " NORMAL: componentType must be FLOAT");
        same_count(v, "NORMAL");
        out.normals = read_floats(v, "", false);
    }
    if (int ai = attr("TEXCOORD_0"); ai >= 0) {
        AccView v = accessor(ai, where + " TEXCOORD_0", TINYGLTF_TYPE_VEC2);
        const bool ok = v.ct == TINYGLTF_COMPONENT_TYPE_FLOAT ||
                        (v.normalized && (v.ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                                          v.ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT));
        if (!ok) fail(where + " TEXCOORD_0: must be FLOAT or normalized UNSIGNED_BYTE/SHORT");
        same_count(v, "TEXCOORD_0");
        out.uvs = read_floats(v, "", false);
    }
    if (int ai = attr("TANGENT"); ai >= 0) {
        AccView v = accessor(ai, where + " TANGENT", TINYGLTF_TYPE_VEC4);
        if (v.ct != TINYGLTF_COMPONENT_TYPE_FLOAT) fail(where + " TANGENT: componentType must be FLOAT");
        same_count(v, "TANGENT");
        out.tangents = read_floats(v, "", false);
    }

    // indices (validated against the vertex count)
    std::vector<uint32_t> idx;
    if (p.indices >= 0) {
        AccView iv = accessor(p.indices, where + " indices", TINYGLTF_TYPE_SCALAR);
        if (!is_index_type(iv.ct) || iv.normalized)
            fail(where + " indices: componentType must be UNSIGNED_BYTE/SHORT/INT");
        idx.resize(iv.count);
        for (size_t i = 0; i < iv.count; ++i) {
            uint32_t k = comp_to_uint(iv.at(i), iv.ct);
            if (k >= nv)
                fail(strf("%s: index %u out of range (%zu vertices)", where.c_str(), k, nv));
            idx[i] = k;
        }
    } else {
        idx.resize(nv);
        for (size_t i = 0; i < nv; ++i) idx[i] = uint32_t(i);
    }

    const size_t ni = idx.size();
    size_t nt = 0;
    if (mode == TINYGLTF_MODE_TRIANGLES)
        nt = ni / 3;
    else
        nt = ni >= 3 ? ni - 2 : 0;
    if (nt == 0) {
        warn(where + ": no triangles; skipped");
        free_prim(&out);
        prims_.pop_back();
        return;
    }
    out.indices = static_cast<uint32_t *>(std::malloc(nt * 3 * sizeof(uint32_t)));
    if (!out.indices) throw std::bad_alloc();
    for (size_t t = 0; t < nt; ++t) {
        uint32_t *d = out.indices + t * 3;
        if (mode == TINYGLTF_MODE_TRIANGLES) {
            d[0] = idx[3 * t]; d[1] = idx[3 * t + 1]; d[2] = idx[3 * t + 2];
        } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
            // glTF: {i, i + (1 + i%2), i + (2 - i%2)} keeps a consistent winding
            d[0] = idx[t]; d[1] = idx[t + 1 + (t & 1)]; d[2] = idx[t + 2 - (t & 1)];
        } else {  // fan: {i+1, i+2, 0}
            d[0] = idx[t + 1]; d[1] = idx[t + 2]; d[2] = idx[0];
        }
    }
    out.num_triangles = uint32_t(nt);
}

void Loader::convert_meshes() {
    meshes_.reserve(m_.meshes.size());
    for (const tinygltf::Mesh &mesh : m_.meshes) {
        IoMesh om{};
        copy_name(om.name, mesh.name);
        om.first_primitive = uint32_t(prims_.size());
        for (size_t pi = 0; pi < mesh.primitives.size(); ++pi) convert_primitive(mesh, pi);
        om.num_primitives = uint32_t(prims_.size()) - om.first_primitive;
        meshes_.push_back(om);
    }
}

int32_t Loader::image_for(int gi, bool srgb, const std::string &what) {
    if (gi < 0 || size_t(gi) >= m_.images.size())
        fail(strf("%s: image %d out of range", what.c_str(), gi));
    const tinygltf::Image &im = m_.images[size_t(gi)];
    const bool from_file = im.bufferView < 0 && !im.uri.empty();
    const std::string file = from_file ? referenced(url_decode(im.uri), what) : std::string();
    const std::string key = from_file ? file : strf("#%d", gi);
    auto it = image_cache_.find({key, srgb ? 1 : 0});
    if (it != image_cache_.end()) return it->second;

    const std::string label = from_file ? "image '" + im.uri + "'" : strf("embedded image %d", gi);
    IoImage img{};
    std::string problem;
    bool ok;
    if (from_file) {
        if (!is_regular_file(file)) fail(label + " not found (" + file + ")");
        ok = candela_io::decode_image(file, nullptr, 0, srgb, true, texture_left(), &img, &problem);
        if (!ok) problem = file + ": " + problem;
    } else if (im.bufferView >= 0) {
        size_t len = m_.bufferViews.size() > size_t(im.bufferView)
                         ? m_.bufferViews[size_t(im.bufferView)].byteLength : 0;
        const unsigned char *p = view_span(im.bufferView, 0, len, label, nullptr);
        ok = candela_io::decode_image(label, p, len, srgb, true, texture_left(), &img, &problem);
    } else {
        if (im.image.empty()) fail(label + " has no data");
        ok = candela_io::decode_image(label, im.image.data(), im.image.size(), srgb, true, texture_left(), &img, &problem);
    }
    if (!ok) fail(label + ": " + problem);
    texture_used_ += io_image_bytes(&img);
    images_.push_back(img);
    const int32_t index = int32_t(images_.size() - 1);
    image_cache_[{key, srgb ? 1 : 0}] = index;
    return index;
}

// A textureInfo inside an extension's JSON (KHR_materials_clearcoat's textures) as tinygltf's
// TextureInfo, for texture_ref: index (-1 when the key is absent), texCoord, extensions.
tinygltf::TextureInfo texture_info(const tinygltf::Value &ext, const char *key, const std::string &what) {
    tinygltf::TextureInfo ti;
    const tinygltf::Value *v = member(ext, key);
    if (!v) return ti;
    const tinygltf::Value *index = member(*v, "index");
    if (!index || index_value(*index) < 0) fail(what + "." + key + ": needs a texture \"index\"");
    ti.index = index_value(*index);
    if (const tinygltf::Value *tc = member(*v, "texCoord"); tc && index_value(*tc) >= 0) ti.texCoord = index_value(*tc);
    if (const tinygltf::Value *x = member(*v, "extensions"); x && x->IsObject())
        for (const std::string &k : x->Keys()) ti.extensions[k] = x->Get(k);
    return ti;
}

template <class Info>
IoTextureRef Loader::texture_ref(const Info &info, bool srgb, const std::string &what) {
    IoTextureRef r{};
    r.image = -1;
    r.scale[0] = r.scale[1] = 1.0f;
    if (info.index < 0) return r;
    if (size_t(info.index) >= m_.textures.size())
        fail(strf("%s: texture %d out of range", what.c_str(), info.index));
    const tinygltf::Texture &tex = m_.textures[size_t(info.index)];
    r.texcoord = info.texCoord;
    if (const tinygltf::Value *tt = extension(info.extensions, "KHR_texture_transform")) {
        numbers(*tt, "offset", r.offset, 2);
        numbers(*tt, "scale", r.scale, 2);
        r.rotation = float(number_or(*tt, "rotation", 0.0));
        if (const tinygltf::Value *tc = member(*tt, "texCoord"); tc && tc->IsNumber())
            r.texcoord = index_value(*tc) >= 0 ? index_value(*tc) : 0;
    }
    if (r.texcoord != 0 && !warned_texcoord_) {
        warned_texcoord_ = true;
        warn(what + strf(": uses TEXCOORD_%d; only TEXCOORD_0 is loaded", r.texcoord));
    }
    if (tex.sampler >= 0) {
        if (size_t(tex.sampler) >= m_.samplers.size())
            fail(strf("%s: sampler %d out of range", what.c_str(), tex.sampler));
        auto wrap = [](int w) {
            switch (w) {
            case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE: return 1;
            case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT: return 2;
            default: return 0;
            }
        };
        r.wrap_s = wrap(m_.samplers[size_t(tex.sampler)].wrapS);
        r.wrap_t = wrap(m_.samplers[size_t(tex.sampler)].wrapT);
    }
    int source = tex.source;
    if (source < 0) {
        if (const tinygltf::Value *webp = extension(tex.extensions, "EXT_texture_webp")) {
            if (const tinygltf::Value *s = member(*webp, "source"); s && s->IsNumber())
                source = index_value(*s);
        }
    }
    if (source < 0) {
        warn(what + strf(": texture %d has no image source; ignored", info.index));
        return r;
    }
    r.image = image_for(source, srgb, what);
    return r;
}

void Loader::convert_materials() {
    materials_.reserve(m_.materials.size());
    for (size_t i = 0; i < m_.materials.size(); ++i) {
        const tinygltf::Material &src = m_.materials[i];
        const std::string what = strf("material '%s'", src.name.c_str());
        IoMaterial d{};
        copy_name(d.name, src.name);
        const auto &pbr = src.pbrMetallicRoughness;
        for (int c = 0; c < 4; ++c)
            d.base_color[c] = pbr.baseColorFactor.size() == 4 ? float(pbr.baseColorFactor[size_t(c)]) : 1.0f;
        d.metallic = float(pbr.metallicFactor);
        d.roughness = float(pbr.roughnessFactor);
        for (int c = 0; c < 3; ++c)
            d.emissive[c] = src.emissiveFactor.size() == 3 ? float(src.emissiveFactor[size_t(c)]) : 0.0f;
        d.emissive_strength = 1.0f;
        d.normal_scale = float(src.normalTexture.scale);
        d.specular = 1.0f;
        d.specular_color[0] = d.specular_color[1] = d.specular_color[2] = 1.0f;
        d.transmission = 0.0f;
        d.ior = 1.5f;
        d.double_sided = src.doubleSided ? 1 : 0;
        if (src.alphaMode == "MASK")
            d.alpha_mode = IO_ALPHA_MASK;
        else if (src.alphaMode == "BLEND")
            d.alpha_mode = IO_ALPHA_BLEND;
        else
            d.alpha_mode = IO_ALPHA_OPAQUE;
        d.alpha_cutoff = float(src.alphaCutoff);

        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_emissive_strength"))
            d.emissive_strength = float(number_or(*e, "emissiveStrength", 1.0));
        /* an emission beyond IO_MAX_EMISSION overflowed to infinity in float and rendered a
         * black image with exit 0: refuse it, naming the material */
        for (int c = 0; c < 3; ++c) {
            const double e = double(d.emissive[c]) * double(d.emissive_strength);
            if (!std::isfinite(e) || std::fabs(e) > IO_MAX_EMISSION || !std::isfinite(d.emissive_strength))
                fail(strf("%s: emission out of range (emissiveFactor x emissiveStrength = %g; the limit is %g)",
                          what.c_str(), e, IO_MAX_EMISSION));
        }
        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_specular")) {
            d.has_specular_ext = 1;
            d.specular = float(number_or(*e, "specularFactor", 1.0));
            numbers(*e, "specularColorFactor", d.specular_color, 3);
        }
        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_transmission"))
            d.transmission = float(number_or(*e, "transmissionFactor", 0.0));
        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_ior"))
            d.ior = float(number_or(*e, "ior", 1.5));
        d.clearcoat_tex.image = d.clearcoat_roughness_tex.image = -1;
        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_clearcoat")) {
            const std::string w = what + " KHR_materials_clearcoat";
            d.clearcoat = float(finite_number(*e, "clearcoatFactor", 0.0, w));
            d.clearcoat_roughness = float(finite_number(*e, "clearcoatRoughnessFactor", 0.0, w));
            if (!(d.clearcoat >= 0.0f && d.clearcoat <= 1.0f) ||
                !(d.clearcoat_roughness >= 0.0f && d.clearcoat_roughness <= 1.0f))
                fail(w + ": clearcoatFactor and clearcoatRoughnessFactor must be in [0, 1]");
            d.clearcoat_tex = texture_ref(texture_info(*e, "clearcoatTexture", w), false, w + " clearcoatTexture");
            d.clearcoat_roughness_tex =
                texture_ref(texture_info(*e, "clearcoatRoughnessTexture", w), false, w + " clearcoatRoughnessTexture");
            if (member(*e, "clearcoatNormalTexture"))
                warn(w + ": clearcoatNormalTexture is ignored (the coat uses the base's shading normal)");
        }

        d.base_color_tex = texture_ref(pbr.baseColorTexture, true, what + " baseColorTexture");
        d.metallic_roughness_tex =
            texture_ref(pbr.metallicRoughnessTexture, false, what + " metallicRoughnessTexture");
        d.normal_tex = texture_ref(src.normalTexture, false, what + " normalTexture");
        d.emissive_tex = texture_ref(src.emissiveTexture, true, what + " emissiveTexture");
        material_medium(src, what, &d);
        materials_.push_back(d);
    }
}

// The material's homogeneous medium: extras.candela_medium, else KHR_materials_volume (io.h).
void Loader::material_medium(const tinygltf::Material &src, const std::string &what, IoMaterial *d) {
    d->has_medium = 0;
    for (int c = 0; c < 3; ++c) d->medium_sigma_a[c] = d->medium_sigma_s[c] = 0.0f;
    d->medium_anisotropy = 0.0f;
    const char raw = member(src.extras, "candela_medium") ? 0 : raw_member_start(src.extras_json_string, "candela_medium");
    if (raw == '{') {  // an empty object: a medium with the defaults
        d->has_medium = 1;
        return;
    }
    if (raw == '[') fail(what + ": extras.candela_medium must be an object");
    if (const tinygltf::Value *cm = member(src.extras, "candela_medium")) {
        const std::string w = what + ": extras.candela_medium";
        if (!cm->IsObject()) fail(w + " must be an object");
        finite_vec3(*cm, "sigma_a", d->medium_sigma_a, w);
        finite_vec3(*cm, "sigma_s", d->medium_sigma_s, w);
        for (int c = 0; c < 3; ++c) {
            if (d->medium_sigma_a[c] < 0.0f) fail(w + ".sigma_a must not be negative");
            if (d->medium_sigma_s[c] < 0.0f) fail(w + ".sigma_s must not be negative");
        }
        const double g = finite_number(*cm, "anisotropy", 0.0, w);
        if (!(g > -1.0 && g < 1.0)) fail(w + strf(".anisotropy %g is outside (-1, 1)", g));
        d->medium_anisotropy = float(g);
        for (const std::string &k : cm->Keys())
            if (k != "sigma_a" && k != "sigma_s" && k != "anisotropy") warn(w + ": unknown key '" + k + "' ignored");
        d->has_medium = 1;
        return;
    }
    const tinygltf::Value *kv = extension(src.extensions, "KHR_materials_volume");
    if (!kv) return;
    const std::string w = what + ": KHR_materials_volume";
    if (!kv->IsObject()) fail(w + " must be an object");
    double dist = INFINITY;
    if (const tinygltf::Value *v = member(*kv, "attenuationDistance")) {
        if (!v->IsNumber() || !(v->GetNumberAsDouble() > 0.0))
            fail(w + ".attenuationDistance must be a number > 0");
        dist = v->GetNumberAsDouble();
    }
    float color[3] = {1.0f, 1.0f, 1.0f};
    finite_vec3(*kv, "attenuationColor", color, w);
    for (int c = 0; c < 3; ++c)
        if (!(color[c] > 0.0f && color[c] <= 1.0f)) fail(w + ".attenuationColor components must be in (0, 1]");
    if (!std::isfinite(dist) || !std::isfinite(float(dist))) return;  // thin-walled: no medium
    for (int c = 0; c < 3; ++c) {
        const double sa = -std::log(double(color[c])) / dist;
        if (!std::isfinite(float(sa))) fail(w + ": attenuation gives a non-finite absorption coefficient");
        d->medium_sigma_a[c] = float(sa);
        if (d->medium_sigma_a[c] > 0.0f) d->has_medium = 1;
    }
}

static Mat4 trs_local(const double t[3], const double q0[4], const double s[3], IoNode *walk);

void Loader::flatten_nodes() {
    const size_t n = gltf_node_count();
    // A valid glTF node graph is a forest: every node has at most one parent. Checking that
    // up front makes the traversal below finite (no cycles, no shared subtrees).
    std::vector<int> parent(n, -1);
    for (size_t i = 0; i < n; ++i)
        for (int c : gltf_node(i) ? gltf_node(i)->children : std::vector<int>()) {
            if (c < 0 || size_t(c) >= n) fail(strf("node %zu: child %d out of range", i, c));
            if (parent[size_t(c)] != -1 || size_t(c) == i)
                fail(strf("node %d has more than one parent (node graph is not a tree)", c));
            parent[size_t(c)] = int(i);
        }

    std::vector<int> roots;
    if (!m_.scenes.empty()) {
        scene_ = m_.defaultScene >= 0 ? m_.defaultScene : 0;
        if (size_t(scene_) >= m_.scenes.size())
            fail(strf("default scene %d out of range", m_.defaultScene));
        std::vector<char> seen(n, 0);
        for (int r : m_.scenes[size_t(scene_)].nodes) {
            if (r < 0 || size_t(r) >= n) fail(strf("scene %d: node %d out of range", scene_, r));
            if (parent[size_t(r)] != -1) fail(strf("scene %d: node %d is not a root node", scene_, r));
            if (seen[size_t(r)]) continue;
            seen[size_t(r)] = 1;
            roots.push_back(r);
        }
    } else {
        for (size_t i = 0; i < n; ++i)
            if (parent[i] == -1) roots.push_back(int(i));
    }

    // nodes an animation channel moves (weights aside): with their descendants, a zero scale
    // there may be a moment of an animation, not a mesh to drop
    std::vector<char> channel_target(n, 0);
    for (const tinygltf::Animation &anim : m_.animations)
        for (const tinygltf::AnimationChannel &ch : anim.channels)
            if (ch.target_node >= 0 && size_t(ch.target_node) < n && ch.target_path != "weights")
                channel_target[size_t(ch.target_node)] = 1;
    struct Item {
        int node;
        Mat4 parent;
        int32_t parent_walk; // the parent's index in nodes_, or -1
        bool animated;       // a channel moves this node or an ancestor
    };
    node_of_gltf_.assign(n, -1);
    if (bulk_) { // sized once: growing by doubling would hold old and new arrays at once
        nodes_.reserve(n);
        lights_.reserve(bulk_nodes_.size());
    }
    std::vector<Item> stack;
    for (size_t k = roots.size(); k-- > 0;) stack.push_back({roots[k], identity(), -1, false});
    while (!stack.empty()) {
        Item it = stack.back();
        stack.pop_back();
        if (!gltf_node(size_t(it.node))) { // a bulk record: a plain light node
            place_bulk(it.node, it.parent, it.parent_walk);
            continue;
        }
        const tinygltf::Node &node = *gltf_node(size_t(it.node));
        const std::string what = strf("node %d ('%s')", it.node, node.name.c_str());
        const bool animated = it.animated || channel_target[size_t(it.node)];
        // the node as io_scene_pose re-places it (io.h, IoNode): the same local transform as below
        IoNode walk{};
        copy_name(walk.name, node.name);
        walk.gltf_node = it.node;
        walk.parent = it.parent_walk;
        walk.rotation[3] = 1.0;
        walk.scale[0] = walk.scale[1] = walk.scale[2] = 1.0;
        const int32_t walk_index = int32_t(nodes_.size());
        node_of_gltf_[size_t(it.node)] = walk_index;
        Mat4 local = identity();
        if (!node.matrix.empty()) {
            if (node.matrix.size() != 16) fail(what + ": matrix must have 16 numbers");
            for (int k = 0; k < 16; ++k) local.m[k] = node.matrix[size_t(k)];
            walk.has_matrix = 1;
            for (int k = 0; k < 16; ++k) walk.matrix[k] = local.m[k];
        } else {
            if (!node.translation.empty() && node.translation.size() != 3)
                fail(what + ": translation must have 3 numbers");
            if (!node.rotation.empty() && node.rotation.size() != 4)
                fail(what + ": rotation must have 4 numbers");
            if (!node.scale.empty() && node.scale.size() != 3) fail(what + ": scale must have 3 numbers");
            double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
            for (size_t k = 0; k < node.translation.size(); ++k) t[k] = node.translation[k];
            for (size_t k = 0; k < node.rotation.size(); ++k) q[k] = node.rotation[k];
            for (size_t k = 0; k < node.scale.size(); ++k) s[k] = node.scale[k];
            local = trs_local(t, q, s, &walk);
        }
        nodes_.push_back(walk);
        const Mat4 world = mul(it.parent, local);
        /* Transform sanity where the data enters (Debian's Embree asserts on invalid rays, and
         * a 1e30 scale hung the cache point build): every entry finite and within
         * IO_MAX_COORDINATE (documented in README.md), or the load fails naming the node. */
        bool finite = true;
        double largest = 0.0;
        for (double e : world.m) {
            finite = finite && std::isfinite(e);
            largest = std::max(largest, std::fabs(e));
        }
        const bool places = node.mesh >= 0 || node.camera >= 0 || extension(node.extensions, "KHR_lights_punctual") ||
                            member(node.extras, "candela_volume") || raw_member_start(node.extras_json_string, "candela_area_light");
        if (places && (!finite || largest > IO_MAX_COORDINATE))
            fail(strf("%s: transform out of range (an entry is %s; the limit is %g)", what.c_str(),
                      finite ? strf("%g", largest).c_str() : "not finite", IO_MAX_COORDINATE));
        const double *a = world.m;
        const double det = a[0] * (a[5] * a[10] - a[9] * a[6]) - a[4] * (a[1] * a[10] - a[9] * a[2]) +
                           a[8] * (a[1] * a[6] - a[5] * a[2]);

        if (node.mesh >= 0) {
            if (size_t(node.mesh) >= m_.meshes.size())
                fail(strf("%s: mesh %d out of range", what.c_str(), node.mesh));
            IoInstance inst{};
            inst.mesh = uint32_t(node.mesh);
            inst.node = walk_index;
            for (int k = 0; k < 16; ++k) inst.xform[k] = float(world.m[k]);
            /* a zero scale hides an object (animation does this): skip it rather than give
             * Embree a transform it cannot invert; an animated one is kept hidden, for the
             * frames where it has a scale (io_scene_pose) */
            if (!(std::fabs(det) > 1e-30 * std::max(largest * largest * largest, 1e-300))) {
                if (animated) {
                    inst.hidden = 1;
                    instances_.push_back(inst);
                } else {
                    warn(what + ": singular transform (a zero scale): the mesh is not rendered");
                }
            } else {
                instances_.push_back(inst);
            }
        } else if (node.mesh < -1) {
            fail(strf("%s: mesh %d out of range", what.c_str(), node.mesh));
        }
        if (node.camera >= 0) {
            if (size_t(node.camera) >= m_.cameras.size())
                fail(strf("%s: camera %d out of range", what.c_str(), node.camera));
            const tinygltf::Camera &cam = m_.cameras[size_t(node.camera)];
            IoCamera c{};
            copy_name(c.name, cam.name.empty() ? node.name : cam.name);
            if (cam.type == "orthographic") {
                c.type = IO_CAMERA_ORTHOGRAPHIC;
                c.xmag = float(cam.orthographic.xmag);
                c.ymag = float(cam.orthographic.ymag);
                c.znear = float(cam.orthographic.znear);
                c.zfar = float(cam.orthographic.zfar);
            } else {
                c.type = IO_CAMERA_PERSPECTIVE;
                c.yfov = float(cam.perspective.yfov);
                c.aspect = float(cam.perspective.aspectRatio);
                c.znear = float(cam.perspective.znear);
                c.zfar = float(cam.perspective.zfar);
            }
            for (int k = 0; k < 16; ++k) c.xform[k] = float(world.m[k]);
            c.node = walk_index;
            if (!(std::fabs(det) > 0.0)) fail(what + ": singular camera transform (a zero scale)");
            cameras_.push_back(c);
        }
        if (member(node.extras, "candela_volume")) {
            load_volume(node, what, world);
            volumes_.back().node = walk_index;
        } else if (const char raw = raw_member_start(node.extras_json_string, "candela_volume"); raw == '{' || raw == '[') {
            fail(what + (raw == '{' ? ": extras.candela_volume has no \"uri\" (the VDB file, required)"
                                    : ": extras.candela_volume must be an object"));
        }
        if (const tinygltf::Value *lp = extension(node.extensions, "KHR_lights_punctual")) {
            const tinygltf::Value *li = member(*lp, "light");
            if (!li || !li->IsNumber()) fail(what + ": KHR_lights_punctual without a light index");
            const int l = index_value(*li);
            if (l < 0 || size_t(l) >= light_defs_.size())
                fail(strf("%s: light %.17g out of range (%zu lights)", what.c_str(), li->GetNumberAsDouble(),
                          light_defs_.size()));
            place_light(size_t(l), node.name, what, world.m, walk_index, &node);
        } else if (raw_member_start(node.extras_json_string, "candela_light")) {
            warn(what + ": extras.candela_light on a node without a KHR_lights_punctual light; ignored");
        }
        if (raw_member_start(node.extras_json_string, "candela_area_light")) load_area_light(node, what, world, walk_index);
        for (size_t k = node.children.size(); k-- > 0;) stack.push_back({node.children[k], world, walk_index, animated});
    }
}

// A node's local matrix from its TRS (rotation normalised; M = T * R * S), also kept in its walk
// record for io_scene_pose.
static Mat4 trs_local(const double t[3], const double q0[4], const double s[3], IoNode *walk) {
    Mat4 local = identity();
    double q[4] = {q0[0], q0[1], q0[2], q0[3]};
    for (int k = 0; k < 3; ++k) walk->translation[k] = t[k];
    for (int k = 0; k < 4; ++k) walk->rotation[k] = q[k];
    for (int k = 0; k < 3; ++k) walk->scale[k] = s[k];
    double qn = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (qn > 0.0 && std::isfinite(qn))
        for (double &c : q) c /= qn;
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    // R (column-major) scaled per column: M = T * R * S
    const double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w),
                         2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w),
                         2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)};
    for (int c = 0; c < 3; ++c)
        for (int row = 0; row < 3; ++row) local.m[c * 4 + row] = r[c * 3 + row] * s[c];
    local.m[12] = t[0];
    local.m[13] = t[1];
    local.m[14] = t[2];
    return local;
}

// A bulk record in the node walk: what flatten_nodes does for a node with a light and nothing else.
void Loader::place_bulk(int gi, const Mat4 &parent, int32_t parent_walk) {
    const BulkNode &b = bulk_nodes_[size_t(-1 - kept_of_gltf_[size_t(gi)])];
    const std::string name = name_of(b.name_at, b.name_len);
    auto what = [&]() { return strf("node %d ('%s')", gi, name.c_str()); }; // for a message only
    IoNode walk{};
    copy_name(walk.name, name);
    walk.gltf_node = gi;
    walk.parent = parent_walk;
    const int32_t walk_index = int32_t(nodes_.size());
    node_of_gltf_[size_t(gi)] = walk_index;
    const Mat4 local = trs_local(b.t, b.q, b.s, &walk);
    nodes_.push_back(walk);
    const Mat4 world = mul(parent, local);
    bool finite = true;
    double largest = 0.0;
    for (double e : world.m) {
        finite = finite && std::isfinite(e);
        largest = std::max(largest, std::fabs(e));
    }
    if (!finite || largest > IO_MAX_COORDINATE)
        fail(strf("%s: transform out of range (an entry is %s; the limit is %g)", what().c_str(),
                  finite ? strf("%g", largest).c_str() : "not finite", IO_MAX_COORDINATE));
    if (size_t(b.light) >= light_defs_.size())
        fail(strf("%s: light %.17g out of range (%zu lights)", what().c_str(), double(b.light), light_defs_.size()));
    place_light(size_t(b.light), name, what, world.m, walk_index, nullptr);
}

// The IoLight of light record l placed by a node's world matrix (node: its tinygltf node, for
// the light shape in its extras; null for a bulk record, which has no extras).
template <class What>
void Loader::place_light(size_t l, const std::string &node_name, const What &what, const double *world_m,
                         int32_t walk_index, const tinygltf::Node *node) {
    auto w = [&]() -> std::string { // the node's name for a message, made only for one
        if constexpr (std::is_invocable_v<What>) return what();
        else return what;
    };
    const LightDef &src = light_defs_[l];
    IoLight d{};
    copy_name(d.name, src.name_len ? name_of(src.name_at, src.name_len) : node_name);
    if (src.type < 0)
        fail(strf("%s: light %d has unknown type '%s'", w().c_str(), int(l), type_name_[l].c_str()));
    d.type = src.type;
    for (int c = 0; c < 3; ++c) d.color[c] = src.has_color ? float(src.color[c]) : 1.0f;
    d.intensity = float(src.intensity);
    for (int c = 0; c < 3; ++c) {
        const double e = double(src.intensity) * double(d.color[c]);
        if (!std::isfinite(e) || std::fabs(e) > IO_MAX_EMISSION || !std::isfinite(d.intensity))
            fail(strf("%s: light intensity out of range (intensity x colour = %g; the limit is %g)",
                      w().c_str(), e, IO_MAX_EMISSION));
    }
    d.range = float(src.range);
    d.inner_cone_angle = float(src.inner);
    d.outer_cone_angle = float(src.outer);
    d.position[0] = float(world_m[12]);
    d.position[1] = float(world_m[13]);
    d.position[2] = float(world_m[14]);
    double dir[3] = {-world_m[8], -world_m[9], -world_m[10]};
    double len = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    if (len > 0.0 && std::isfinite(len)) {
        for (int c = 0; c < 3; ++c) d.direction[c] = float(dir[c] / len);
    } else {
        d.direction[2] = -1.0f;
    }
    d.node = walk_index;
    if (node) light_shape_extras(*node, w(), d);
    lights_.push_back(d);
}

// extras.candela_light {"radius": r} on a point or spot light, {"angle": deg} on a directional
// light (io.h, IoLight; README "Light shapes"). Read from the extras' JSON text (nlohmann), so a
// value of the wrong type is reported rather than dropped.
void Loader::light_shape_extras(const tinygltf::Node &node, const std::string &what0, IoLight &d) {
    if (!raw_member_start(node.extras_json_string, "candela_light")) return;
    const std::string what = what0 + ": extras.candela_light";
    nlohmann::json extras;
    try {
        extras = nlohmann::json::parse(node.extras_json_string);
    } catch (const std::exception &) {
        fail(what + ": malformed JSON");
    }
    const nlohmann::json &cl = extras["candela_light"];
    if (cl.is_null()) return;
    if (!cl.is_object()) fail(what + " must be an object");
    for (auto it = cl.begin(); it != cl.end(); ++it) {
        const std::string &k = it.key();
        const nlohmann::json &v = it.value();
        if (k == "radius") {
            if (d.type == IO_LIGHT_DIRECTIONAL)
                fail(what + ".radius applies to point and spot lights (a directional light takes \"angle\")");
            if (!v.is_number() || !std::isfinite(v.get<double>()) || v.get<double>() < 0.0 ||
                !std::isfinite(float(v.get<double>())) || v.get<double>() > IO_MAX_COORDINATE)
                fail(what + ".radius must be a finite number >= 0 (got " + v.dump() + ")");
            d.radius = float(v.get<double>());
        } else if (k == "angle") {
            if (d.type != IO_LIGHT_DIRECTIONAL)
                fail(what + ".angle applies to directional lights (a point or spot light takes \"radius\")");
            if (!v.is_number() || !(v.get<double>() >= 0.0 && v.get<double>() < 180.0))
                fail(what + ".angle must be a number of degrees in [0, 180) (got " + v.dump() + ")");
            d.angle = float(v.get<double>() * (3.14159265358979323846 / 180.0));
        } else {
            warn(what + ": unknown key '" + k + "' ignored");
        }
    }
}

// extras.candela_area_light {"shape": "rect"|"disk", "size": [x, y], "color": [r, g, b],
// "power": W} (io.h, IoLight; README "Light shapes"): a light of its own, placed by the node.
void Loader::load_area_light(const tinygltf::Node &node, const std::string &what0, const Mat4 &world,
                             int32_t walk_index) {
    const std::string what = what0 + ": extras.candela_area_light";
    nlohmann::json extras;
    try {
        extras = nlohmann::json::parse(node.extras_json_string);
    } catch (const std::exception &) {
        fail(what + ": malformed JSON");
    }
    const nlohmann::json &al = extras["candela_area_light"];
    if (al.is_null()) return;
    if (!al.is_object()) fail(what + " must be an object");
    IoLight d{};
    copy_name(d.name, node.name);
    d.color[0] = d.color[1] = d.color[2] = 1.0f;
    bool have_shape = false, have_size = false, have_power = false;
    auto finite = [](const nlohmann::json &v) {
        return v.is_number() && std::isfinite(v.get<double>()) && std::isfinite(float(v.get<double>()));
    };
    for (auto it = al.begin(); it != al.end(); ++it) {
        const std::string &k = it.key();
        const nlohmann::json &v = it.value();
        if (k == "shape") {
            if (!v.is_string() || (v.get<std::string>() != "rect" && v.get<std::string>() != "disk"))
                fail(what + ".shape must be \"rect\" or \"disk\" (got " + v.dump() + ")");
            d.type = v.get<std::string>() == "rect" ? IO_LIGHT_RECT : IO_LIGHT_DISK;
            have_shape = true;
        } else if (k == "size") {
            bool ok = v.is_array() && v.size() == 2;
            for (size_t i = 0; ok && i < 2; ++i) ok = finite(v[i]) && v[i].get<double>() > 0.0;
            if (!ok) fail(what + ".size must be an array of 2 finite numbers > 0 (got " + v.dump() + ")");
            for (size_t i = 0; i < 2; ++i) d.size[i] = float(v[i].get<double>());
            have_size = true;
        } else if (k == "color") {
            bool ok = v.is_array() && v.size() == 3;
            for (size_t i = 0; ok && i < 3; ++i) ok = finite(v[i]) && v[i].get<double>() >= 0.0;
            if (!ok) fail(what + ".color must be an array of 3 finite numbers >= 0 (got " + v.dump() + ")");
            for (size_t i = 0; i < 3; ++i) d.color[i] = float(v[i].get<double>());
        } else if (k == "power") {
            if (!finite(v) || v.get<double>() < 0.0)
                fail(what + ".power must be a finite number >= 0 (watts; got " + v.dump() + ")");
            d.intensity = float(v.get<double>());
            have_power = true;
        } else {
            warn(what + ": unknown key '" + k + "' ignored");
        }
    }
    if (!have_shape) fail(what + " has no \"shape\" (\"rect\" or \"disk\", required)");
    if (!have_size) fail(what + " has no \"size\" ([x, y], required)");
    if (!have_power) fail(what + " has no \"power\" (watts, required)");
    for (int c = 0; c < 3; ++c) {
        const double e = double(d.intensity) * double(d.color[c]);
        if (!(e <= IO_MAX_EMISSION))
            fail(strf("%s: power out of range (power x colour = %g; the limit is %g)", what.c_str(), e, IO_MAX_EMISSION));
    }
    const double *m = world.m;
    for (int c = 0; c < 3; ++c) {
        d.position[c] = float(m[12 + c]);
        d.axis_u[c] = float(m[c] * 0.5 * d.size[0]);
        d.axis_v[c] = float(m[4 + c] * 0.5 * d.size[1]);
    }
    double dir[3] = {-m[8], -m[9], -m[10]};
    double len = std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
    if (!(len > 0.0) || !std::isfinite(len)) fail(what + ": singular node transform (a zero scale)");
    for (int c = 0; c < 3; ++c) d.direction[c] = float(dir[c] / len);
    d.node = walk_index;
    lights_.push_back(d);
}

// extras.candela_light_linking (io.h, IoLightLink). Read from the extras' original JSON text:
// tinygltf drops empty arrays and objects from extras, and an empty "include" list (a light
// that illuminates nothing) must not read as no list at all.
void Loader::convert_light_links() {
    // only a scene that links lights pays for the name map (1M light nodes: ~1 s, ~100 MB)
    bool any = false;
    for (size_t w = 0; w < nodes_.size() && !any; ++w)
        if (const tinygltf::Node *n = gltf_node(size_t(nodes_[w].gltf_node)))
            any = raw_member_start(n->extras_json_string, "candela_light_linking") != 0;
    if (!any) return;
    std::map<std::string, std::vector<int32_t>> by_name; // node name -> walk indices
    for (size_t w = 0; w < nodes_.size(); ++w)
        by_name[gltf_node_name(size_t(nodes_[w].gltf_node))].push_back(int32_t(w));
    std::vector<int32_t> instances_of_node(nodes_.size(), -1); // first instance of a node (one per node)
    for (size_t i = 0; i < instances_.size(); ++i)
        if (instances_of_node[size_t(instances_[i].node)] < 0) instances_of_node[size_t(instances_[i].node)] = int32_t(i);
    for (size_t w = 0; w < nodes_.size(); ++w) {
        const int gi = nodes_[w].gltf_node;
        if (!gltf_node(size_t(gi))) continue; // a bulk record has no extras
        const tinygltf::Node &node = *gltf_node(size_t(gi));
        if (!raw_member_start(node.extras_json_string, "candela_light_linking")) continue;
        const std::string what = strf("node %d ('%s'): extras.candela_light_linking", gi, node.name.c_str());
        nlohmann::json extras;
        try {
            extras = nlohmann::json::parse(node.extras_json_string);
        } catch (const std::exception &) {
            fail(what + ": malformed JSON");
        }
        const nlohmann::json &ll = extras["candela_light_linking"];
        if (ll.is_null()) continue;
        if (!ll.is_object()) fail(what + " must be an object");
        IoLightLink link{};
        link.node = int32_t(w);
        // a list of node names -> the instances of their subtrees, sorted, without duplicates
        auto resolve = [&](const nlohmann::json &list, const std::string &key, uint32_t *first, uint32_t *count) {
            if (!list.is_array()) fail(what + "." + key + " must be an array of node names");
            std::vector<char> named(nodes_.size(), 0);
            for (const nlohmann::json &e : list) {
                if (!e.is_string()) fail(what + "." + key + " must be an array of node names (strings)");
                auto it = by_name.find(e.get<std::string>());
                if (it == by_name.end())
                    fail(what + "." + key + ": no node named '" + e.get<std::string>() + "' in the scene");
                for (int32_t n : it->second) named[size_t(n)] = 1;
            }
            *first = uint32_t(link_instances_.size());
            for (size_t i = 0; i < instances_.size(); ++i) {
                bool in = false;
                for (int32_t n = instances_[i].node; n >= 0 && !in; n = nodes_[size_t(n)].parent) in = named[size_t(n)];
                if (in) link_instances_.push_back(uint32_t(i));
            }
            *count = uint32_t(link_instances_.size()) - *first;
        };
        for (auto it = ll.begin(); it != ll.end(); ++it) {
            const std::string &k = it.key();
            const nlohmann::json &v = it.value();
            if (k == "receivers") {
                if (v.is_null()) continue;
                if (!v.is_object()) fail(what + ".receivers must be an object with \"include\" or \"exclude\"");
                const bool inc = v.contains("include"), exc = v.contains("exclude");
                if (inc && exc) fail(what + ".receivers has both \"include\" and \"exclude\" (give one)");
                if (!inc && !exc) fail(what + ".receivers needs \"include\" or \"exclude\"");
                for (auto r = v.begin(); r != v.end(); ++r)
                    if (r.key() != "include" && r.key() != "exclude")
                        warn(what + ".receivers: unknown key '" + r.key() + "' ignored");
                link.receivers = inc ? IO_LINK_INCLUDE : IO_LINK_EXCLUDE;
                resolve(v[inc ? "include" : "exclude"], inc ? "receivers.include" : "receivers.exclude",
                        &link.first_receiver, &link.num_receivers);
            } else if (k == "blockers") {
                if (v.is_null()) continue;
                if (!v.is_object() || !v.contains("exclude"))
                    fail(what + ".blockers must be an object with \"exclude\"");
                for (auto r = v.begin(); r != v.end(); ++r)
                    if (r.key() != "exclude") {
                        if (r.key() == "include") fail(what + ".blockers takes only \"exclude\"");
                        warn(what + ".blockers: unknown key '" + r.key() + "' ignored");
                    }
                resolve(v["exclude"], "blockers.exclude", &link.first_blocker, &link.num_blockers);
            } else {
                warn(what + ": unknown key '" + k + "' ignored");
            }
        }
        // the lights it applies to: the node's punctual light, or its mesh if it emits
        bool has_light = extension(node.extensions, "KHR_lights_punctual") != nullptr ||
                         raw_member_start(node.extras_json_string, "candela_area_light");
        if (!has_light && instances_of_node[w] >= 0) {
            const IoMesh &mesh = meshes_[instances_[size_t(instances_of_node[w])].mesh];
            for (uint32_t k = 0; k < mesh.num_primitives && !has_light; ++k) {
                const int32_t mi = prims_[mesh.first_primitive + k].material;
                if (mi < 0 || size_t(mi) >= materials_.size()) continue;
                const IoMaterial &mat = materials_[size_t(mi)];
                has_light = (mat.emissive[0] > 0.0f || mat.emissive[1] > 0.0f || mat.emissive[2] > 0.0f) &&
                            mat.emissive_strength > 0.0f;
            }
        }
        if (!has_light) warn(what + ": the node has no punctual light and no emissive mesh; ignored");
        if (link.receivers == IO_LINK_ALL && link.num_blockers == 0) continue;
        light_links_.push_back(link);
    }
}

// The file's animations (io.h, IoAnimChannel): every sampler checked against the glTF 2.0
// rules the evaluation relies on, every failure one line naming the animation and channel.
void Loader::convert_animations() {
    bool warned_weights = false;
    std::vector<uint8_t> animated(nodes_.size() * 3, 0); // (node, path) already has a channel
    for (size_t ai = 0; ai < m_.animations.size(); ++ai) {
        const tinygltf::Animation &anim = m_.animations[ai];
        for (size_t ci = 0; ci < anim.channels.size(); ++ci) {
            const tinygltf::AnimationChannel &ch = anim.channels[ci];
            const std::string what = strf("animation %zu ('%s') channel %zu", ai, anim.name.c_str(), ci);
            if (ch.target_path == "weights") {
                if (!warned_weights) warn(what + ": morph target weights are animated; they are not rendered");
                warned_weights = true;
                continue;
            }
            int path = -1;
            if (ch.target_path == "translation") path = IO_ANIM_TRANSLATION;
            else if (ch.target_path == "rotation") path = IO_ANIM_ROTATION;
            else if (ch.target_path == "scale") path = IO_ANIM_SCALE;
            if (path < 0) {
                warn(what + ": target path '" + ch.target_path + "' is not supported; the channel is ignored");
                continue;
            }
            if (ch.target_node < 0 || size_t(ch.target_node) >= gltf_node_count())
                fail(strf("%s: target node %d out of range", what.c_str(), ch.target_node));
            const int32_t walk = node_of_gltf_.empty() ? -1 : node_of_gltf_[size_t(ch.target_node)];
            if (walk < 0) continue; // a node outside the loaded scene
            if (nodes_[size_t(walk)].has_matrix)
                fail(strf("%s: node %d ('%s') is animated but has a matrix (glTF allows only TRS there)",
                          what.c_str(), ch.target_node, nodes_[size_t(walk)].name));
            uint8_t &seen = animated[size_t(walk) * 3 + size_t(path)];
            if (seen)
                fail(strf("%s: node %d ('%s') %s is animated by two channels", what.c_str(), ch.target_node,
                          nodes_[size_t(walk)].name, ch.target_path.c_str()));
            seen = 1;
            convert_channel(anim, ai, ci);
            channels_.back().node = walk;
            channels_.back().path = path;
        }
    }
    for (size_t k = 0; k < channels_.size(); ++k) {
        const IoAnimChannel &c = channels_[k];
        const double first = c.times[0], last = c.times[c.num_keys - 1];
        anim_start_ = k == 0 ? first : std::min(anim_start_, first);
        anim_end_ = k == 0 ? last : std::max(anim_end_, last);
    }
}

// One channel's sampler: times and values read and checked into channels_.back().
void Loader::convert_channel(const tinygltf::Animation &anim, size_t ai, size_t ci) {
    const tinygltf::AnimationChannel &ch = anim.channels[ci];
    const std::string what = strf("animation %zu ('%s') channel %zu (%s of node %d)", ai, anim.name.c_str(), ci,
                                  ch.target_path.c_str(), ch.target_node);
    if (ch.sampler < 0 || size_t(ch.sampler) >= anim.samplers.size())
        fail(strf("%s: sampler %d out of range", what.c_str(), ch.sampler));
    const tinygltf::AnimationSampler &sm = anim.samplers[size_t(ch.sampler)];
    IoAnimChannel c{};
    if (sm.interpolation == "STEP") c.interpolation = IO_INTERP_STEP;
    else if (sm.interpolation == "LINEAR" || sm.interpolation.empty()) c.interpolation = IO_INTERP_LINEAR;
    else if (sm.interpolation == "CUBICSPLINE") c.interpolation = IO_INTERP_CUBICSPLINE;
    else fail(what + ": unknown interpolation '" + sm.interpolation + "' (STEP, LINEAR, CUBICSPLINE)");
    const bool rotation = ch.target_path == "rotation";
    const AccView in = accessor(sm.input, what + " input", TINYGLTF_TYPE_SCALAR);
    if (in.ct != TINYGLTF_COMPONENT_TYPE_FLOAT) fail(what + ": input times must be FLOAT");
    const AccView out = accessor(sm.output, what + " output", rotation ? TINYGLTF_TYPE_VEC4 : TINYGLTF_TYPE_VEC3);
    if (out.ct != TINYGLTF_COMPONENT_TYPE_FLOAT && !(rotation && out.normalized))
        fail(what + ": output values must be FLOAT (or normalized integers for a rotation)");
    const size_t per_key = c.interpolation == IO_INTERP_CUBICSPLINE ? 3 : 1;
    if (out.count != in.count * per_key)
        fail(strf("%s: input has %zu times but output has %zu values (%s needs %zu per time)", what.c_str(),
                  in.count, out.count, sm.interpolation.c_str(), per_key));
    if (c.interpolation == IO_INTERP_CUBICSPLINE && in.count < 2)
        fail(what + ": CUBICSPLINE needs at least 2 keys");
    // allocated before any further check can throw, so release_all frees them
    channels_.push_back(c);
    IoAnimChannel &d = channels_.back();
    d.times = read_floats(in, what, false);
    d.num_keys = uint32_t(in.count);
    for (size_t k = 0; k < in.count; ++k) {
        const float t = d.times[k];
        if (!std::isfinite(t)) fail(strf("%s: key time %zu is not finite", what.c_str(), k));
        if (t < 0.0f) fail(strf("%s: key time %zu is negative (%g s)", what.c_str(), k, double(t)));
        if (k > 0 && !(t > d.times[k - 1]))
            fail(strf("%s: key times are not increasing (time %zu is %g s, time %zu is %g s)", what.c_str(), k - 1,
                      double(d.times[k - 1]), k, double(t)));
    }
    d.values = read_floats(out, what, false);
    const size_t ncomp = size_t(out.ncomp);
    for (size_t k = 0; k < out.count; ++k) {
        double norm2 = 0.0;
        for (size_t j = 0; j < ncomp; ++j) {
            const float v = d.values[k * ncomp + j];
            if (!std::isfinite(v) || std::fabs(v) > IO_MAX_COORDINATE)
                fail(strf("%s: value %zu is %s", what.c_str(), k,
                          std::isfinite(v) ? strf("out of range (%g; the limit is %g)", double(v), IO_MAX_COORDINATE).c_str()
                                           : "not finite"));
            norm2 += double(v) * double(v);
        }
        // a rotation key (not a tangent) must be a quaternion that can be normalised
        const bool key_value = per_key == 1 || k % 3 == 1;
        if (rotation && key_value && !(norm2 > 1e-12))
            fail(strf("%s: rotation value %zu is a zero quaternion", what.c_str(), k / per_key));
    }
}

// One grid of a candela_volume: io_load_vdb_grid's message ("VDB: problem") passed through.
void Loader::load_grid(const std::string &vdb, const std::string &grid, const std::string &what,
                       IoVolumeGrid *out) {
    char err[IO_ERR_LEN] = "";
    if (io_load_vdb_grid(vdb.c_str(), grid.c_str(), out, err) != 0) fail(what + ": " + err);
    volume_used_ += out->size;
    if (volume_budget_ && volume_used_ > volume_budget_)
        fail(strf("%s: the volume grids loaded so far take %.1f MiB, over the scene's volume budget of %.1f MiB "
                  "(--volume-budget-mb)",
                  what.c_str(), double(volume_used_) / 1048576.0, double(volume_budget_) / 1048576.0));
}

// A node's extras.candela_volume (io.h, IoVolume): validate every value, then load the grids.
void Loader::load_volume(const tinygltf::Node &node, const std::string &what, const Mat4 &world) {
    const tinygltf::Value &cv = *member(node.extras, "candela_volume");
    const std::string w = what + ": extras.candela_volume";
    if (!cv.IsObject()) fail(w + " must be an object");
    IoVolume v{};
    copy_name(v.name, node.name);
    for (int k = 0; k < 16; ++k) {
        v.xform[k] = float(world.m[k]);
        if (!std::isfinite(v.xform[k])) fail(what + ": non-finite transform on a node with a volume");
    }
    static const char *known[] = {"uri", "density_grid", "density_scale", "albedo", "anisotropy",
                                  "emission_grid", "emission_scale", "emission_color", "temperature_grid"};
    for (const std::string &k : cv.Keys()) {
        bool ok = false;
        for (const char *kn : known) ok = ok || k == kn;
        if (!ok) warn(w + ": unknown key '" + k + "' ignored");
    }
    const tinygltf::Value *uri = member(cv, "uri");
    if (!uri) fail(w + " has no \"uri\" (the VDB file, required)");
    if (!uri->IsString() || uri->Get<std::string>().empty()) fail(w + ".uri must be a non-empty string");
    const std::string file = referenced(url_decode(uri->Get<std::string>()), w);
    if (file.size() >= sizeof v.path) fail(w + ".uri is too long");
    std::memcpy(v.path, file.c_str(), file.size() + 1);

    auto grid_name = [&](const char *key, const char *def) {
        const tinygltf::Value *g = member(cv, key);
        if (!g) return std::string(def);
        if (!g->IsString() || g->Get<std::string>().empty())
            fail(w + "." + key + " must be a non-empty string (a grid name, or \"none\")");
        return g->Get<std::string>();
    };
    const std::string density = grid_name("density_grid", "density");
    const std::string emission = grid_name("emission_grid", "none");
    const std::string temperature = grid_name("temperature_grid", "none");
    if (density == "none") fail(w + ".density_grid cannot be \"none\" (a volume needs a density grid)");

    v.density_scale = float(finite_number(cv, "density_scale", 4.0, w));
    if (v.density_scale < 0.0f) fail(w + ".density_scale must not be negative");
    v.albedo[0] = v.albedo[1] = v.albedo[2] = 0.8f;
    finite_vec3(cv, "albedo", v.albedo, w);
    for (int c = 0; c < 3; ++c)
        if (!(v.albedo[c] >= 0.0f && v.albedo[c] <= 1.0f)) fail(w + ".albedo components must be in [0, 1]");
    const double g = finite_number(cv, "anisotropy", 0.0, w);
    if (!(g > -1.0 && g < 1.0)) fail(w + strf(".anisotropy %g is outside (-1, 1)", g));
    v.anisotropy = float(g);
    v.emission_scale = float(finite_number(cv, "emission_scale", 1.0, w));
    if (v.emission_scale < 0.0f) fail(w + ".emission_scale must not be negative");
    v.emission_color[0] = v.emission_color[1] = v.emission_color[2] = 1.0f;
    finite_vec3(cv, "emission_color", v.emission_color, w);
    for (int c = 0; c < 3; ++c)
        if (v.emission_color[c] < 0.0f) fail(w + ".emission_color must not be negative");

    // The grids last. From here on the volume is in volumes_, so a failure frees what loaded.
    volumes_.push_back(v);
    IoVolume &dst = volumes_.back();
    load_grid(file, density, w, &dst.density);
    if (emission != "none") load_grid(file, emission, w, &dst.emission);
    if (temperature != "none") load_grid(file, temperature, w, &dst.temperature);
}

void Loader::environment(IoScene *out) {
    out->env_path[0] = 0;
    out->env_strength = 1.0f;
    out->env_rotation_deg = 0.0f;
    const tinygltf::Value *env = nullptr;
    if (scene_ >= 0) env = member(m_.scenes[size_t(scene_)].extras, "candela_environment");
    if (!env) env = member(m_.asset.extras, "candela_environment");
    if (!env) env = member(m_.extras, "candela_environment");
    if (!env) return;
    const tinygltf::Value *uri = member(*env, "uri");
    if (!uri || !uri->IsString() || uri->Get<std::string>().empty())
        fail("extras.candela_environment needs a string \"uri\"");
    const tinygltf::Value *strength = member(*env, "strength");
    if (strength && !strength->IsNumber()) fail("extras.candela_environment.strength must be a number");
    const std::string p = referenced(uri->Get<std::string>(), "extras.candela_environment");
    if (p.size() >= sizeof out->env_path) fail("extras.candela_environment.uri is too long");
    std::memcpy(out->env_path, p.c_str(), p.size() + 1);
    out->env_strength = strength ? float(strength->GetNumberAsDouble()) : 1.0f;
    // degrees about the vertical, as Blender's Z rotation of the world's Mapping node
    out->env_rotation_deg = float(finite_number(*env, "rotation", 0.0, "extras.candela_environment"));
}

template <class T>
T *c_array(const std::vector<T> &v) {
    if (v.empty()) return nullptr;
    T *p = static_cast<T *>(std::malloc(sizeof(T) * v.size()));
    if (!p) throw std::bad_alloc();
    std::memcpy(static_cast<void *>(p), v.data(), sizeof(T) * v.size());
    return p;
}

void Loader::transfer(IoScene *out) {
    // Allocate every array first, then hand over ownership in one step that cannot fail.
    IoScene s{};
    size_t n_lights = 0, n_nodes = 0;
    try {
        s.primitives = c_array(prims_);
        s.meshes = c_array(meshes_);
        s.instances = c_array(instances_);
        s.materials = c_array(materials_);
        s.images = c_array(images_);
        s.lights = c_array(lights_);
        n_lights = lights_.size();
        std::vector<IoLight>().swap(lights_); // no owned pointers: freed as soon as copied
        s.cameras = c_array(cameras_);
        s.volumes = c_array(volumes_);
        s.nodes = c_array(nodes_);
        n_nodes = nodes_.size();
        std::vector<IoNode>().swap(nodes_);
        s.channels = c_array(channels_);
        s.light_links = c_array(light_links_);
        s.link_instances = c_array(link_instances_);
    } catch (...) {
        std::free(s.light_links); std::free(s.link_instances);
        std::free(s.primitives); std::free(s.meshes); std::free(s.instances);
        std::free(s.materials); std::free(s.images); std::free(s.lights); std::free(s.cameras);
        std::free(s.volumes); std::free(s.nodes); std::free(s.channels);
        throw;
    }
    out->primitives = s.primitives; out->num_primitives = uint32_t(prims_.size());
    out->meshes = s.meshes;         out->num_meshes = uint32_t(meshes_.size());
    out->instances = s.instances;   out->num_instances = uint32_t(instances_.size());
    out->materials = s.materials;   out->num_materials = uint32_t(materials_.size());
    out->images = s.images;         out->num_images = uint32_t(images_.size());
    out->lights = s.lights;         out->num_lights = uint32_t(n_lights);
    out->cameras = s.cameras;       out->num_cameras = uint32_t(cameras_.size());
    out->volumes = s.volumes;       out->num_volumes = uint32_t(volumes_.size());
    out->nodes = s.nodes;           out->num_nodes = uint32_t(n_nodes);
    out->channels = s.channels;     out->num_channels = uint32_t(channels_.size());
    out->light_links = s.light_links; out->num_light_links = uint32_t(light_links_.size());
    out->link_instances = s.link_instances; out->num_link_instances = uint32_t(link_instances_.size());
    out->anim_start = anim_start_;
    out->anim_end = anim_end_;
    std::snprintf(out->path, sizeof out->path, "%s", path_.c_str());
    out->num_warnings = warnings_;
    if (print_warnings_)
        for (const std::string &w : pending_warnings_)
            std::fprintf(stderr, "%s: warning: %s\n", path_.c_str(), w.c_str());
    prims_.clear();  // ownership of their arrays moved to *out
    images_.clear();
    volumes_.clear();
    channels_.clear();
}

void Loader::run(IoScene *out) {
    parse();
    if (phase_done_) phase_done_(phase_user_, IO_PHASE_PARSED);
    check_required_extensions();
    warn_unrendered();
    convert_meshes();
    convert_materials();
    convert_light_defs();
    flatten_nodes();
    convert_light_links();
    convert_animations();
    if (prims_.size() > UINT32_MAX || instances_.size() > UINT32_MAX) fail("scene too large");
    IoScene tmp{};
    environment(&tmp);
    // tinygltf's model (the file's buffers among it) and the bulk records are converted: freed
    // before the arrays are copied out, so the copies do not add to them (io/README.md, "Memory")
    m_ = tinygltf::Model();
    std::vector<BulkNode>().swap(bulk_nodes_);
    std::vector<LightDef>().swap(light_defs_);
    std::vector<int32_t>().swap(kept_of_gltf_);
    std::vector<int32_t>().swap(node_of_gltf_);
    std::string().swap(names_);
    transfer(out);
    std::memcpy(out->env_path, tmp.env_path, sizeof out->env_path);
    out->env_strength = tmp.env_strength;
    out->env_rotation_deg = tmp.env_rotation_deg;
    if (phase_done_) phase_done_(phase_user_, IO_PHASE_FLATTENED);
}

}  // namespace

extern "C" int io_load_gltf(const char *path, IoScene *scene, char err[IO_ERR_LEN]) {
    return io_load_gltf_opts(path, nullptr, scene, err);
}

// The files a scene references, for the outputs rule (io.h, io_gltf_references): the JSON alone
// (nlohmann, as tinygltf parses it), nothing loaded. URIs resolve as the loader resolves them:
// buffers, images and VDBs percent-decoded relative to the scene's folder, the environment as
// written. Every node's volume and every scene's environment is listed (a superset of what the
// loaded scene reads).
extern "C" int io_gltf_references(const char *path, IoPathList *list, char err[IO_ERR_LEN]) {
    list->paths = nullptr;
    list->count = 0;
    std::vector<std::string> found;
    try {
        std::vector<unsigned char> bytes;
        std::string problem;
        if (!read_whole_file(path, &bytes, &problem)) {
            set_err(err, path, problem);
            return -1;
        }
        const unsigned char *json = bytes.data();
        size_t json_len = bytes.size();
        if (json_len >= 20 && std::memcmp(json, "glTF", 4) == 0) {
            uint32_t len;
            std::memcpy(&len, json + 12, 4);
            if (uint64_t(len) + 20 > json_len) {
                set_err(err, path, "invalid GLB: bad JSON chunk");
                return -1;
            }
            json += 20;
            json_len = len;
        }
        if (json_depth(json, json_len) > JSON_MAX_DEPTH) {
            set_err(err, path, strf("JSON nests deeper than %d levels", JSON_MAX_DEPTH));
            return -1;
        }
        // Only what is listed below is kept while nlohmann parses: a node without extras and the
        // light records are dropped as they complete (a street of 1M light nodes held ~1 GB of
        // JSON tree here, before the load).
        std::string top, ext, ext_key;
        const nlohmann::json d = nlohmann::json::parse(json, json + json_len, [&](int depth, nlohmann::json::parse_event_t e, nlohmann::json &v) {
            using E = nlohmann::json::parse_event_t;
            if (e == E::key) {
                if (depth == 1) top = v.get<std::string>(), ext.clear(), ext_key.clear();
                else if (depth == 2) ext = v.get<std::string>(), ext_key.clear();
                else if (depth == 3) ext_key = v.get<std::string>();
                return true;
            }
            const bool done = e == E::value || e == E::object_end || e == E::array_end;
            if (done && depth == 2 && top == "nodes") return v.is_object() && v.contains("extras");
            if (done && depth == 4 && top == "extensions" && ext == "KHR_lights_punctual" && ext_key == "lights") return false;
            return true;
        });
        const std::string dir = dir_of(path);
        auto uri_of = [](const nlohmann::json &o) -> std::string {
            if (!o.is_object()) return "";
            auto it = o.find("uri");
            if (it == o.end() || !it->is_string()) return "";
            const std::string u = it->get<std::string>();
            return u.compare(0, 5, "data:") == 0 ? "" : u;
        };
        for (const char *key : {"buffers", "images"}) {
            auto a = d.find(key);
            if (a == d.end() || !a->is_array()) continue;
            for (const nlohmann::json &o : *a)
                if (const std::string u = uri_of(o); !u.empty()) found.push_back(join_path(dir, url_decode(u)));
        }
        if (auto nodes = d.find("nodes"); nodes != d.end() && nodes->is_array())
            for (const nlohmann::json &n : *nodes) {
                if (!n.is_object() || !n.contains("extras") || !n["extras"].is_object()) continue;
                auto v = n["extras"].find("candela_volume");
                if (v != n["extras"].end())
                    if (const std::string u = uri_of(*v); !u.empty()) found.push_back(join_path(dir, url_decode(u)));
            }
        auto env_of = [&](const nlohmann::json &o) {
            if (!o.is_object() || !o.contains("extras") || !o["extras"].is_object()) return;
            auto e = o["extras"].find("candela_environment");
            if (e != o["extras"].end())
                if (const std::string u = uri_of(*e); !u.empty()) found.push_back(join_path(dir, u));
        };
        env_of(d);
        if (auto asset = d.find("asset"); asset != d.end()) env_of(*asset);
        if (auto scenes = d.find("scenes"); scenes != d.end() && scenes->is_array())
            for (const nlohmann::json &sc : *scenes) env_of(sc);
    } catch (const std::bad_alloc &) {
        set_err(err, path, "out of memory");
        return -1;
    } catch (const std::exception &e) {
        set_err(err, path, std::string("malformed glTF: ") + e.what());
        return -1;
    }
    if (found.empty()) return 0;
    list->paths = static_cast<char **>(std::calloc(found.size(), sizeof(char *)));
    if (!list->paths) {
        set_err(err, path, "out of memory");
        return -1;
    }
    for (const std::string &f : found) {
        char *c = strdup(f.c_str());
        if (!c) {
            io_path_list_free(list);
            set_err(err, path, "out of memory");
            return -1;
        }
        list->paths[list->count++] = c;
    }
    return 0;
}

extern "C" void io_path_list_free(IoPathList *list) {
    for (int i = 0; list->paths && i < list->count; ++i) std::free(list->paths[i]);
    std::free(list->paths);
    list->paths = nullptr;
    list->count = 0;
}

extern "C" int io_load_gltf_opts(const char *path, const IoLoadOptions *opts, IoScene *scene, char err[IO_ERR_LEN]) {
    const char *confine_dir = opts ? opts->confine_dir : nullptr;
    if (err) err[0] = 0;
    if (!scene) {
        set_err(err, path ? path : "(null)", "no output scene");
        return 1;
    }
    std::memset(scene, 0, sizeof *scene);
    if (!path || !*path) {
        set_err(err, "(null)", "no path given");
        return 1;
    }
    std::string problem, confine;
    if (confine_dir && !*confine_dir) { // a farm script's unset variable must not mean "no confinement"
        set_err(err, path, "the confinement folder (--confine-to) is an empty name");
        return 1;
    }
    if (confine_dir) {
        char *r = ::realpath(confine_dir, nullptr);
        if (!r) {
            set_err(err, confine_dir, "confinement folder (--confine-to) not found");
            return 1;
        }
        confine = r;
        std::free(r);
        if (!inside_folder(path, confine)) {
            set_err(err, path, "is outside " + confine + " (--confine-to)");
            return 1;
        }
    }
    try {
        Loader loader(path, confine, opts ? opts->texture_budget_bytes : 0, opts ? opts->volume_budget_bytes : 0,
                      !(opts && opts->no_warnings));
        if (opts) {
            loader.phase_done_ = opts->phase_done;
            loader.bulk_min_lights_ = opts->bulk_min_lights;
            loader.phase_user_ = opts->phase_user;
        }
        loader.run(scene);
        return 0;
    } catch (const LoadError &e) {
        problem = e.problem;
    } catch (const std::bad_alloc &) {
        problem = "out of memory";
    } catch (const std::exception &e) {
        problem = std::string("malformed glTF: ") + e.what();
    } catch (...) {
        problem = "malformed glTF: unknown exception";
    }
    io_scene_free(scene);
    set_err(err, path, problem);
    return 1;
}

extern "C" void io_scene_free(IoScene *scene) {
    if (!scene) return;
    for (uint32_t i = 0; scene->primitives && i < scene->num_primitives; ++i) {
        IoPrimitive *p = &scene->primitives[i];
        std::free(p->positions);
        std::free(p->normals);
        std::free(p->uvs);
        std::free(p->tangents);
        std::free(p->indices);
    }
    for (uint32_t i = 0; scene->images && i < scene->num_images; ++i) io_image_free(&scene->images[i]);
    for (uint32_t i = 0; scene->volumes && i < scene->num_volumes; ++i) {
        io_volume_grid_free(&scene->volumes[i].density);
        io_volume_grid_free(&scene->volumes[i].emission);
        io_volume_grid_free(&scene->volumes[i].temperature);
    }
    std::free(scene->primitives);
    std::free(scene->meshes);
    std::free(scene->instances);
    std::free(scene->materials);
    std::free(scene->images);
    std::free(scene->lights);
    std::free(scene->cameras);
    std::free(scene->volumes);
    for (uint32_t i = 0; scene->channels && i < scene->num_channels; ++i) {
        std::free(scene->channels[i].times);
        std::free(scene->channels[i].values);
    }
    std::free(scene->channels);
    std::free(scene->nodes);
    std::free(scene->light_links);
    std::free(scene->link_instances);
    std::memset(scene, 0, sizeof *scene);
}
