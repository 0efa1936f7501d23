// io/gltf_references.cpp: the files a scene references, read from its JSON by simdjson's
// On-Demand parser (io_gltf_references in gltf_loader.cpp; the outputs rule of the renderer).
//
// Why a second JSON library: the listing runs before the load, over the whole JSON, for every
// render. nlohmann's parse (tinygltf's parser) reads about 15 MB/s even with a callback that
// drops the nodes as they complete; issue 28's street of a million light nodes (211 MB) took
// 14 s to list before the load began. simdjson finds the JSON's structure with SIMD at GB/s
// and On-Demand builds no tree: the values the listing does not ask for are skipped. It is
// only a fast path: on any error it gives up and the nlohmann listing decides (a file simdjson
// refuses is almost surely malformed, and the loader then reports it in nlohmann's words).
//
// What is listed is what the nlohmann listing lists: "buffers" and "images" URIs and every
// node's extras.candela_volume URI (percent-decoded, relative to the scene's folder), and the
// extras.candela_environment URI of the file, its "asset" and its scenes (as written); data:
// URIs are not files. A key given twice has all of its values listed (nlohmann keeps the
// last): a superset, which is what the rule needs.
#include "gltf_internal.hpp"

#include <simdjson.h>

#include <string>
#include <string_view>
#include <vector>

namespace candela_io::gltf {

namespace od = simdjson::ondemand;
static_assert(JSON_FAST_PADDING >= simdjson::SIMDJSON_PADDING, "the listing pads the JSON as simdjson needs");

// The string under key "uri" of an object value, "" when there is none or it is data:.
static std::string uri_of(od::value v) {
    od::object o;
    if (v.get_object().get(o)) return "";
    std::string uri;
    for (auto field : o) {
        std::string_view key;
        if (field.unescaped_key().get(key) || key != "uri") continue;
        std::string_view s;
        if (field.value().get_string().get(s)) continue;
        uri.assign(s);
    }
    return uri.compare(0, 5, "data:") == 0 ? "" : uri;
}

// The URI of extras.<key> of an object value ("" when none).
static std::string extras_uri(od::value v, std::string_view want) {
    od::object o;
    if (v.get_object().get(o)) return "";
    std::string uri;
    for (auto field : o) {
        std::string_view key;
        if (field.unescaped_key().get(key) || key != "extras") continue;
        od::object extras;
        if (field.value().get_object().get(extras)) continue;
        for (auto e : extras) {
            std::string_view k;
            if (e.unescaped_key().get(k) || k != want) continue;
            od::value ev;
            if (e.value().get(ev)) continue;
            if (std::string u = uri_of(ev); !u.empty()) uri = u;
        }
    }
    return uri;
}

bool references_fast(unsigned char *json, size_t len, size_t capacity, const std::string &dir,
                     std::vector<std::string> *found) {
    if (capacity < len + simdjson::SIMDJSON_PADDING) return false;
    // in the nlohmann listing's order: buffers, images, volumes, then the environments of the
    // file, its asset and its scenes
    enum { BUFFERS, IMAGES, VOLUMES, ENV_FILE, ENV_ASSET, ENV_SCENES, KINDS };
    std::vector<std::string> out[KINDS];
    try {
        od::parser parser;
        od::document doc = parser.iterate(simdjson::padded_string_view(json, len, capacity));
        od::object top = doc.get_object();
        for (auto field : top) {
            std::string_view key = field.unescaped_key();
            od::value v = field.value();
            if (key == "buffers" || key == "images") {
                od::array a;
                if (v.get_array().get(a)) continue;
                for (od::value e : a)
                    if (std::string u = uri_of(e); !u.empty())
                        out[key == "buffers" ? BUFFERS : IMAGES].push_back(join_path(dir, url_decode(u)));
            } else if (key == "nodes") {
                od::array a;
                if (v.get_array().get(a)) continue;
                for (od::value e : a)
                    if (std::string u = extras_uri(e, "candela_volume"); !u.empty())
                        out[VOLUMES].push_back(join_path(dir, url_decode(u)));
            } else if (key == "extras") {
                od::object extras;
                if (v.get_object().get(extras)) continue;
                for (auto e : extras) {
                    std::string_view k = e.unescaped_key();
                    if (k != "candela_environment") continue;
                    if (std::string u = uri_of(e.value()); !u.empty()) out[ENV_FILE].push_back(join_path(dir, u));
                }
            } else if (key == "asset") {
                if (std::string u = extras_uri(v, "candela_environment"); !u.empty())
                    out[ENV_ASSET].push_back(join_path(dir, u));
            } else if (key == "scenes") {
                od::array a;
                if (v.get_array().get(a)) continue;
                for (od::value e : a)
                    if (std::string u = extras_uri(e, "candela_environment"); !u.empty())
                        out[ENV_SCENES].push_back(join_path(dir, u));
            }
        }
    } catch (const simdjson::simdjson_error &) {
        return false;
    }
    for (const std::vector<std::string> &kind : out) found->insert(found->end(), kind.begin(), kind.end());
    return true;
}

}  // namespace candela_io::gltf
