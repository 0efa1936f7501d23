// io/gltf_lights_cameras.cpp: KHR_lights_punctual (the light records, tinygltf's or the bulk
// pass's, and a light placed by its node), light shapes (extras.candela_light), area lights
// (extras.candela_area_light), light linking (extras.candela_light_linking) and cameras.
#include "gltf_internal.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <map>
#include <string>
#include <type_traits>
#include <vector>

namespace candela_io::gltf {

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

// the two kinds of name place_light is given: a tinygltf node's (gltf_loader.cpp), a bulk record's (gltf_bulk.cpp)
template void Loader::place_light<std::string>(size_t, const std::string &, const std::string &, const double *,
                                               int32_t, const tinygltf::Node *);
template void Loader::place_light<BulkWhat>(size_t, const std::string &, const BulkWhat &, const double *, int32_t,
                                            const tinygltf::Node *);

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

// A node's camera (node.camera >= 0), placed by its world matrix (det: its determinant; a
// camera with a zero scale is refused).
void Loader::place_camera(const tinygltf::Node &node, const std::string &what, const Mat4 &world, double det,
                          int32_t walk_index) {
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

}  // namespace candela_io::gltf
