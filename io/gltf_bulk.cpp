// io/gltf_bulk.cpp: the bulk pass (io/README.md, "Memory: a scene of a million light nodes"): a
// file with many light nodes has its plain light nodes and light records read into compact
// records while nlohmann parses it, the rest handed to tinygltf; the node walk places a bulk
// record as it would the node.
#include "gltf_internal.hpp"

#include <nlohmann/json.hpp>
#include <simdjson.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <new>
#include <string>
#include <string_view>
#include <vector>

namespace candela_io::gltf {

// How many light nodes make the bulk pass worth its second parse: below this the file goes to
// tinygltf whole, as it always did (its JSON tree and Model cost ~5 KB per light node, 5 GB for
// issue 28's street of 1M lights; 20 MB at this count).
static constexpr size_t BULK_MIN_LIGHTS = 4096;

// glibc's memmem (SIMD, two-way), not std::search: on the 1M-light street's 211 MB the two
// counts took 0.5 s of CPU with std::search (perf: find_if and memcmp, 4.7% of the run).
static size_t count_occurrences(const unsigned char *p, size_t n, const char *what) {
    const size_t w = std::strlen(what);
    size_t count = 0;
    for (const unsigned char *at = p, *end = p + n;
         (at = static_cast<const unsigned char *>(::memmem(at, size_t(end - at), what, w))) != nullptr; at += w)
        ++count;
    return count;
}

// The IO_LIGHT_* of a plain light record of this type (with or without a "spot" object), or -1:
// not plain (a spot without its angles, a point or directional light with them, which tinygltf
// ignores, or an unknown type: left to tinygltf). Both passes decide by it.
static int32_t plain_light_type(std::string_view type, bool spot_seen) {
    if (type == "point" || type == "directional")
        return spot_seen ? -1 : type == "point" ? IO_LIGHT_POINT : IO_LIGHT_DIRECTIONAL;
    return type == "spot" && spot_seen ? IO_LIGHT_SPOT : -1;
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
        store_name(it->get_ref<const std::string &>(), at, n);
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
        d.type = plain_light_type(type, spot_seen);
        if (d.type < 0) return false;
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

// ---- the bulk pass with simdjson (On-Demand: no tree, GB/s; nlohmann read the 1M-light
// street at ~15 MB/s: its lexer, strtod and the per-node trees it built and dropped were most of
// the load's CPU). It reads what bulk_pass reads, as nlohmann would give it, and hands the same
// records and the same JSON (the file's own text for what it keeps: nothing is re-serialised) to
// tinygltf. Anything it is unsure of makes it give up (false, nothing kept) and bulk_pass runs.

namespace od = simdjson::ondemand;

// The text of a value (an object or array whole; a scalar's token), consumed.
static std::string_view raw_of(od::value v) {
    od::json_type t = v.type();
    if (t == od::json_type::object) {
        od::object o = v.get_object();
        return o.raw_json();
    }
    if (t == od::json_type::array) {
        od::array a = v.get_array();
        return a.raw_json();
    }
    return v.raw_json_token();
}

// A field's key as written (escapes and all, without the quotes): read before unescaped_key.
static std::string_view raw_key(od::field &f) {
    const char *k = f.key().raw();
    size_t n = 0;
    for (size_t backslashes = 0; k[n] != '"' || backslashes % 2; ++n) backslashes = k[n] == '\\' ? backslashes + 1 : 0;
    return std::string_view(k, n);
}

// A number as nlohmann gives it as a double: an integer token is read as an integer first, so
// "-0" is +0 (simdjson's double would keep the sign).
static bool fast_number(od::value v, double *out) {
    if (v.type() != od::json_type::number) return false;
    const std::string_view token = v.raw_json_token();
    double d;
    if (v.get_double().get(d)) return false;
    if (d == 0.0 && token.find_first_of(".eE") == std::string_view::npos) d = 0.0;
    *out = d;
    return true;
}

static bool fast_numbers(od::value v, size_t n, double *out) {
    od::array a;
    if (v.get_array().get(a)) return false;
    size_t k = 0;
    for (od::value e : a) {
        if (k == n || !fast_number(e, &out[k])) return false;
        ++k;
    }
    return k == n;
}

// Each key of an object once (a key given twice: not plain; tinygltf reads such a record).
struct SeenKeys {
    uint32_t seen = 0;
    bool first(int bit) { return !(seen >> bit & 1u) && (seen |= 1u << bit, true); }
};

// One element of "nodes" or of the lights, parsed again on its own (raw_of gave its text).
struct ElementParser {
    od::parser parser;
    od::document doc; // what the object returned reads through
    std::string text; // the element and simdjson's padding, reused
    od::object object(std::string_view raw) {
        text.assign(raw);
        text.append(simdjson::SIMDJSON_PADDING, ' ');
        doc = parser.iterate(simdjson::padded_string_view(text.data(), raw.size(), text.size()));
        return doc.get_object();
    }
};

// A bulk record's name, appended to names_ (its place and length in *at, *len).
void Loader::store_name(std::string_view name, uint32_t *at, uint32_t *len) {
    *at = uint32_t(names_.size());
    *len = uint32_t(name.size());
    names_.append(name);
}

bool Loader::fast_plain_node(ElementParserRef ep, std::string_view raw) {
    BulkNode b;
    std::string_view name;
    bool has_name = false, light = false;
    SeenKeys keys;
    od::object o = static_cast<ElementParser *>(ep)->object(raw);
    for (auto f : o) {
        std::string_view k = f.unescaped_key();
        od::value v = f.value();
        if (k == "name") {
            if (!keys.first(0) || v.get_string().get(name)) return false;
            has_name = true;
        } else if (k == "translation") {
            if (!keys.first(1) || !fast_numbers(v, 3, b.t)) return false;
            b.has_t = 1;
        } else if (k == "rotation") {
            if (!keys.first(2) || !fast_numbers(v, 4, b.q)) return false;
            b.has_r = 1;
        } else if (k == "scale") {
            if (!keys.first(3) || !fast_numbers(v, 3, b.s)) return false;
            b.has_s = 1;
        } else if (k == "extensions") {
            if (!keys.first(4)) return false;
            od::object ext;
            if (v.get_object().get(ext)) return false;
            size_t n_ext = 0;
            for (auto e : ext) {
                if (++n_ext > 1 || e.unescaped_key().value() != "KHR_lights_punctual") return false;
                od::object lp;
                if (e.value().get_object().get(lp)) return false;
                size_t n_lp = 0;
                for (auto l : lp) {
                    uint64_t index;
                    if (++n_lp > 1 || l.unescaped_key().value() != "light" || l.value().get_uint64().get(index) ||
                        index >= 2147483648u)
                        return false;
                    b.light = int32_t(index);
                }
                if (n_lp != 1) return false;
            }
            if (n_ext != 1) return false;
            light = true;
        } else {
            return false;
        }
    }
    if (!light || names_.size() > UINT32_MAX / 2) return false;
    if (has_name) store_name(name, &b.name_at, &b.name_len);
    bulk_nodes_.push_back(b);
    return true;
}

bool Loader::fast_plain_light(ElementParserRef ep, std::string_view raw) {
    LightDef d;
    std::string_view name, type;
    bool has_name = false, spot_seen = false;
    SeenKeys keys;
    od::object o = static_cast<ElementParser *>(ep)->object(raw);
    for (auto f : o) {
        std::string_view k = f.unescaped_key();
        od::value v = f.value();
        if (k == "name") {
            if (!keys.first(0) || v.get_string().get(name)) return false;
            has_name = true;
        } else if (k == "type") {
            if (!keys.first(1) || v.get_string().get(type)) return false;
        } else if (k == "color") {
            if (!keys.first(2) || !fast_numbers(v, 3, d.color)) return false;
            d.has_color = true;
        } else if (k == "intensity") {
            if (!keys.first(3) || !fast_number(v, &d.intensity)) return false;
        } else if (k == "range") {
            if (!keys.first(4) || !fast_number(v, &d.range)) return false;
        } else if (k == "spot") {
            if (!keys.first(5)) return false;
            od::object spot;
            if (v.get_object().get(spot)) return false;
            SeenKeys angles;
            for (auto a : spot) {
                std::string_view ak = a.unescaped_key();
                if (ak == "innerConeAngle") {
                    if (!angles.first(0) || !fast_number(a.value(), &d.inner)) return false;
                } else if (ak == "outerConeAngle") {
                    if (!angles.first(1) || !fast_number(a.value(), &d.outer)) return false;
                } else {
                    return false;
                }
            }
            spot_seen = true;
        } else {
            return false;
        }
    }
    d.type = plain_light_type(type, spot_seen);
    if (d.type < 0) return false;
    if (names_.size() > UINT32_MAX / 2) return false;
    if (has_name) store_name(name, &d.name_at, &d.name_len);
    light_defs_.push_back(d);
    return true;
}

// A key met for the first time in its object (false: given twice). nlohmann keeps a repeated
// key's last value, so a pass that read records under its first one would hand tinygltf a file
// whose lights it never sees: such a file is read by tinygltf whole (refuse_bulk).
static bool first_key(std::vector<std::string> *seen, std::string_view key) {
    for (const std::string &k : *seen)
        if (k == key) return false;
    seen->emplace_back(key);
    return true;
}

// The kept JSON is written as the file's own text: a member's key (as written) after a comma
// unless it is the object's first, an array element likewise.
static void put_member(std::string *out, bool *first, std::string_view key_text) {
    if (!*first) *out += ',';
    *first = false;
    *out += '"';
    *out += key_text;
    *out += "\":";
}
static void put_element(std::string *out, bool *first, std::string_view raw) {
    if (!*first) *out += ',';
    *first = false;
    *out += raw;
}

// The next member of an object the pass copies: its key, unescaped, in *key; written to out.
// False when the object gave it before (first_key).
static bool copy_member(od::field &f, std::vector<std::string> *seen, std::string *out, bool *first,
                        std::string_view *key) {
    const std::string_view text = raw_key(f);
    *key = f.unescaped_key();
    if (!first_key(seen, *key)) return false;
    put_member(out, first, text);
    return true;
}

bool Loader::refuse_bulk() {
    bulk_refused_ = true;
    return false;
}

bool Loader::bulk_pass_fast(const unsigned char *json, size_t len, std::string *kept) {
    std::string out;
    out.reserve(len / 64);
    ElementParser element;
    size_t n_nodes_arrays = 0, n_light_arrays = 0;
    int32_t kept_nodes = 0, kept_lights = 0;
    try {
        simdjson::padded_string text(reinterpret_cast<const char *>(json), len);
        {
            // On-Demand is not a validating parser: past the values it reads it may accept what
            // is not JSON (fuzz_gltf: a member `"animations": "x": ]` loaded with the pass and
            // failed without it). simdjson's DOM parser validates the whole text first (its tape
            // freed before the pass); a file it refuses goes to nlohmann's pass, which reports
            // what tinygltf would.
            simdjson::dom::parser validator;
            simdjson::dom::element root;
            if (validator.parse(text).get(root)) return false;
        }
        od::parser parser;
        od::document doc = parser.iterate(text);
        od::object top = doc.get_object();
        out += '{';
        bool first_top = true;
        std::vector<std::string> top_keys;
        for (od::field field : top) {
            std::string_view key;
            if (!copy_member(field, &top_keys, &out, &first_top, &key)) return refuse_bulk();
            od::value v = field.value();
            if (key == "nodes") {
                if (++n_nodes_arrays > 1) return false;
                od::array nodes;
                if (v.get_array().get(nodes)) return false;
                out += '[';
                bool first = true;
                for (od::value e : nodes) {
                    const std::string_view raw = raw_of(e);
                    if (!raw.empty() && raw.front() == '{' && fast_plain_node(&element, raw)) {
                        kept_of_gltf_.push_back(-int32_t(bulk_nodes_.size()));
                        continue;
                    }
                    kept_of_gltf_.push_back(kept_nodes++);
                    put_element(&out, &first, raw);
                }
                out += ']';
            } else if (key == "extensions" && v.type() == od::json_type::object) {
                out += '{';
                bool first_ext = true;
                std::vector<std::string> ext_keys;
                for (od::field ext : v.get_object()) {
                    std::string_view ext_key;
                    if (!copy_member(ext, &ext_keys, &out, &first_ext, &ext_key)) return refuse_bulk();
                    od::value ev = ext.value();
                    if (ext_key != "KHR_lights_punctual" || ev.type() != od::json_type::object) {
                        out += raw_of(ev);
                        continue;
                    }
                    out += '{';
                    bool first_lp = true;
                    std::vector<std::string> lp_keys;
                    for (od::field lp : ev.get_object()) {
                        std::string_view lp_key;
                        if (!copy_member(lp, &lp_keys, &out, &first_lp, &lp_key)) return refuse_bulk();
                        od::value lv = lp.value();
                        if (lp_key != "lights") {
                            out += raw_of(lv);
                            continue;
                        }
                        if (++n_light_arrays > 1) return false;
                        od::array lights;
                        if (lv.get_array().get(lights)) return false;
                        out += '[';
                        bool first = true;
                        for (od::value e : lights) {
                            const std::string_view raw = raw_of(e);
                            if (!raw.empty() && raw.front() == '{' && fast_plain_light(&element, raw)) {
                                light_kept_.push_back(-1);
                                continue;
                            }
                            light_defs_.emplace_back();
                            light_kept_.push_back(kept_lights++);
                            put_element(&out, &first, raw);
                        }
                        out += ']';
                    }
                    out += '}';
                }
                out += '}';
            } else {
                out += raw_of(v);
            }
        }
        out += '}';
        const char *rest;
        if (!doc.current_location().get(rest)) return false; // text after the top-level object: nlohmann judges it
    } catch (const simdjson::simdjson_error &) {
        return false;
    }
    if (kept_of_gltf_.size() > size_t(INT32_MAX) || light_defs_.size() > size_t(INT32_MAX)) return false;
    kept_of_gltf_.shrink_to_fit();
    light_kept_.shrink_to_fit();
    kept->swap(out);
    return true;
}

// The bulk pass when the file has many light nodes (BULK_MIN_LIGHTS); false: tinygltf reads it
// whole. simdjson's pass first, nlohmann's when it gives up.
bool Loader::use_bulk_pass(const unsigned char *json, size_t len, std::string *kept) {
    const size_t lights = count_occurrences(json, len, "\"KHR_lights_punctual\"");
    if (lights < (bulk_min_lights_ ? bulk_min_lights_ : BULK_MIN_LIGHTS)) return false;
    // reserved from counts of the text (upper bounds), so the records never grow by doubling
    const size_t types = std::min(lights, count_occurrences(json, len, "\"type\""));
    bulk_nodes_.reserve(lights);
    light_defs_.reserve(types);
    if (!bulk_slow_ && bulk_pass_fast(json, len, kept)) {
        bulk_ = bulk_fast_ = true;
        return true;
    }
    reset_bulk();
    if (bulk_refused_) return false; // a key given twice where the pass reads: tinygltf alone
    bulk_nodes_.reserve(lights);
    light_defs_.reserve(types);
    bulk_ = bulk_pass(json, len, kept);
    return bulk_;
}

// Back to no bulk records (a pass that gave up, or a load read again).
void Loader::reset_bulk() {
    bulk_ = bulk_fast_ = false;
    bulk_nodes_ = std::vector<BulkNode>();
    kept_of_gltf_ = std::vector<int32_t>();
    light_kept_ = std::vector<int32_t>();
    light_defs_ = std::vector<LightDef>();
    names_ = std::string();
}

// A bulk record in the node walk: what flatten_nodes does for a node with a light and nothing else.
void Loader::place_bulk(int gi, const Mat4 &parent, int32_t parent_walk) {
    const BulkNode &b = bulk_nodes_[size_t(-1 - kept_of_gltf_[size_t(gi)])];
    const std::string name = name_of(b.name_at, b.name_len);
    const BulkWhat what{gi, &name}; // for a message only
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

}  // namespace candela_io::gltf
