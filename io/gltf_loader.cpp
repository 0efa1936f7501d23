// io/gltf_loader.cpp: thin extern "C" adapter over tinygltf (C++17): the core walk.
//
// tinygltf parses the JSON / GLB container and loads buffers; images are NOT decoded by it
// (a no-op image loader keeps uri / bufferView, and stashes the bytes of data: URIs, which
// tinygltf does not keep otherwise). Everything the renderer relies on is validated here
// (accessor and buffer bounds, index ranges, finite positions, node graph shape) and
// converted to the plain C arrays of io.h. Images are decoded with OpenImageIO
// (image_module.cpp, in candela_io_image.so: io_module.h) once per (image, colour space).
//
// This file parses the file (tinygltf, after the GLB container and the JSON depth are checked
// here, and the bulk pass for a file with many light nodes: gltf_bulk.cpp), walks the node graph
// (transforms checked where they enter; meshes placed as instances, lights, cameras and volumes
// by their files), hands the arrays over to C and holds the extern "C" API. The other concerns
// have their own files, sharing gltf_internal.hpp (its header lists them).
#include "io.h"
#include "gltf_internal.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <new>
#include <string>
#include <vector>

namespace candela_io::gltf {

// A GLB's magic, or JSON's first character '{' after an optional UTF-8 BOM and white space: an
// OBJ, USD or PNG given as the scene is named as such in one line, not by the JSON parser's
// "[json.exception.parse_error.101] ..." about its first byte.
static bool looks_like_gltf(const std::vector<unsigned char> &bytes) {
    if (bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0) return true;
    size_t i = 0;
    if (bytes.size() >= 3 && bytes[0] == 0xEF && bytes[1] == 0xBB && bytes[2] == 0xBF) i = 3;
    while (i < bytes.size() && (bytes[i] == ' ' || bytes[i] == '\t' || bytes[i] == '\n' || bytes[i] == '\r')) ++i;
    return i < bytes.size() && bytes[i] == '{';
}

// The scene file through the one input door (io_open_input: regular files only, never a
// FIFO's blocking open or /dev/zero's endless bytes; the size checked before reading).
static bool read_whole_file(const std::string &path, std::vector<unsigned char> *out, std::string *problem) {
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
static bool fs_read_whole_file(std::vector<unsigned char> *out, std::string *err, const std::string &path, void *) {
    std::string problem;
    if (read_whole_file(path, out, &problem)) return true;
    if (err) *err = path + ": " + problem;
    return false;
}

// tinygltf FileExists callback: a buffer file is looked up only under the glTF's own folder
// path (tinygltf would otherwise also search the current working directory) and, with a
// confinement folder, only when it resolves inside it.
static bool fs_file_exists(const std::string &abs_filename, void *user) {
    const FsUser &fs = *static_cast<const FsUser *>(user);
    if (!fs.dir.empty()) {
        std::string prefix = fs.dir.back() == '/' ? fs.dir : fs.dir + "/";
        if (abs_filename.compare(0, prefix.size(), prefix) != 0) return false;
    }
    return is_regular_file(abs_filename) && inside_folder(abs_filename, fs.confine);
}

// tinygltf image callback: decode nothing. Keep the bytes of data: URI images (tinygltf
// keeps neither the URI nor the bytes for those); file and bufferView images are read later.
static bool keep_image_bytes(tinygltf::Image *image, const int, std::string *, std::string *, int, int,
                             const unsigned char *bytes, int size, void *) {
    if (image->uri.empty() && image->bufferView < 0 && bytes && size > 0)
        image->image.assign(bytes, bytes + size);
    return true;
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

void Loader::parse_again_slow() {
    m_ = tinygltf::Model();
    reset_bulk();
    bulk_slow_ = true;
    parse();
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
        if (bulk_fast_) return parse_again_slow();
        fail(std::string("malformed glTF: ") + e.what());
    }
    // simdjson's bulk pass validates what it reads, not what it passes on: a file tinygltf
    // refuses is read again without it, so it fails with the message it always got
    if (!ok && bulk_fast_) return parse_again_slow();
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
        if (node.camera >= 0) place_camera(node, what, world, det, walk_index);
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
Mat4 trs_local(const double t[3], const double q0[4], const double s[3], IoNode *walk) {
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
static T *c_array(const std::vector<T> &v) {
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

}  // namespace candela_io::gltf

using candela_io::set_err;
using namespace candela_io::gltf;

extern "C" int io_load_gltf(const char *path, IoScene *scene, char err[IO_ERR_LEN]) {
    return io_load_gltf_opts(path, nullptr, scene, err);
}

// The files a scene references, for the outputs rule (io.h, io_gltf_references): the JSON alone
// (nlohmann, as tinygltf parses it), nothing loaded. URIs resolve as the loader resolves them:
// buffers, images and VDBs percent-decoded relative to the scene's folder, the environment as
// written. Every node's volume and every scene's environment is listed (a superset of what the
// loaded scene reads).
static int path_list_of(const std::vector<std::string> &found, IoPathList *list, const char *path, char err[IO_ERR_LEN]);

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
        // simdjson first (gltf_references.cpp: GB/s, no tree); nlohmann when it gives up
        const size_t offset = size_t(json - bytes.data());
        bytes.resize(bytes.size() + JSON_FAST_PADDING);
        json = bytes.data() + offset;
        if (references_fast(bytes.data() + offset, json_len, bytes.size() - offset, dir_of(path), &found))
            return path_list_of(found, list, path, err);
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
    return path_list_of(found, list, path, err);
}

// found as the C list io_gltf_references returns (0; -1 out of memory, said in err).
static int path_list_of(const std::vector<std::string> &found, IoPathList *list, const char *path, char err[IO_ERR_LEN]) {
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
