// io/gltf_animation.cpp: animation channels (io.h, IoAnimChannel; posed by animation.c): every
// channel's indices checked in the JSON itself (tinygltf drops a channel whose index is not an
// integer), every sampler against the glTF 2.0 rules the evaluation relies on (interpolation,
// key counts, increasing finite times, finite values in range, no zero quaternion), one channel
// per (node, path); each failure one line naming the animation and channel.
#include "gltf_internal.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <exception>
#include <string>
#include <vector>

namespace candela_io::gltf {

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

}  // namespace candela_io::gltf
