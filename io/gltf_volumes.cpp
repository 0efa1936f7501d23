// io/gltf_volumes.cpp: a node's extras.candela_volume (io.h, IoVolume): every value checked,
// then its VDB grids loaded (io_load_vdb_grid, candela_io_vdb.so) within the volume budget.
#include "gltf_internal.hpp"

#include <cmath>
#include <cstring>
#include <string>

namespace candela_io::gltf {

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

}  // namespace candela_io::gltf
