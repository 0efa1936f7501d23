// io/variants.cpp: the variant list of `candela compare --variants FILE` (C++17, extern "C").
//
// A variant is a name and a string of render flags. TOML (toml++) and JSON (nlohmann/json)
// files hold the same data, an ordered list (the first variant is the baseline of the ratios):
//
//   [[variant]]                        {"variant": [
//   name = "uniform"                     {"name": "uniform", "flags": "--light-sampler uniform"},
//   flags = "--light-sampler uniform"    {"name": "tree", "flags": "--light-sampler tree"}]}
//
// Only the keys `variant`, `name` and `flags` are known; any other key is an error (a typo
// such as `flag =` must not silently render the default). The flags themselves are parsed
// by the renderer (the same parser as the command line), not here.
//
// io_json_quote (io.h) is here too, beside the other use of nlohmann/json: the one JSON string
// escaper of the program.
#include "io.h"
#include "io_internal.hpp"

#include <nlohmann/json.hpp>
#include <toml++/toml.h>

#include <cstdlib>
#include <cstring>
#include <exception>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace {

using Entry = std::pair<std::string, std::string>;  // name, flags

bool ends_with(const std::string &s, const char *suffix) {
    size_t n = std::strlen(suffix);
    return s.size() >= n && s.compare(s.size() - n, n, suffix) == 0;
}

// Reads the whole file through the input door (a FIFO or /dev/zero refused before a byte is
// read); refuses anything past 1 MiB from its size, before reading (a variant list is a few lines).
bool read_text(const std::string &path, std::string *text, std::string *problem) {
    void *data = nullptr;
    size_t n = 0;
    char err[IO_ERR_LEN];
    if (io_read_input(path.c_str(), IO_MAX_VARIANTS_BYTES, "a variant list (1 MiB)", &data, &n, err) != 0) {
        const std::string m(err);
        *problem = m.compare(0, path.size() + 2, path + ": ") == 0 ? m.substr(path.size() + 2) : m;
        return false;
    }
    text->assign(static_cast<const char *>(data), n);
    std::free(data);
    return true;
}

bool from_toml(const std::string &text, const std::string &path, std::vector<Entry> *out, std::string *problem) {
    toml::table doc;
    try {
        doc = toml::parse(text, path);
    } catch (const toml::parse_error &e) {
        std::ostringstream m;
        m << "line " << e.source().begin.line << ": " << e.description();
        *problem = m.str();
        return false;
    }
    for (auto &&[key, value] : doc) {
        (void)value;
        if (key.str() != "variant") { *problem = "unknown key '" + std::string(key.str()) + "' (a list of [[variant]] tables)"; return false; }
    }
    const toml::array *list = doc["variant"].as_array();
    if (!list) { *problem = "no [[variant]] tables"; return false; }
    for (size_t i = 0; i < list->size(); ++i) {
        const toml::table *t = (*list)[i].as_table();
        std::string where = "variant " + std::to_string(i + 1);
        if (!t) { *problem = where + ": not a table"; return false; }
        for (auto &&[key, value] : *t) {
            (void)value;
            if (key.str() != "name" && key.str() != "flags") {
                *problem = where + ": unknown key '" + std::string(key.str()) + "' (name, flags)";
                return false;
            }
        }
        std::optional<std::string> name = (*t)["name"].value<std::string>();
        std::optional<std::string> flags = (*t)["flags"].value<std::string>();
        if (!name) { *problem = where + ": no name string"; return false; }
        if (t->contains("flags") && !flags) { *problem = where + " ('" + *name + "'): flags must be a string"; return false; }
        out->emplace_back(*name, flags ? *flags : std::string());
    }
    return true;
}

bool from_json(const std::string &text, std::vector<Entry> *out, std::string *problem) {
    nlohmann::json doc;
    try {
        doc = nlohmann::json::parse(text);
    } catch (const std::exception &e) {
        *problem = candela_io::one_line(e.what());
        return false;
    }
    if (!doc.is_object()) { *problem = "not a JSON object with a \"variant\" list"; return false; }
    for (auto it = doc.begin(); it != doc.end(); ++it)
        if (it.key() != "variant") { *problem = "unknown key '" + it.key() + "' (an object with a \"variant\" list)"; return false; }
    auto list = doc.find("variant");
    if (list == doc.end() || !list->is_array()) { *problem = "no \"variant\" list"; return false; }
    for (size_t i = 0; i < list->size(); ++i) {
        const nlohmann::json &v = (*list)[i];
        std::string where = "variant " + std::to_string(i + 1);
        if (!v.is_object()) { *problem = where + ": not an object"; return false; }
        for (auto it = v.begin(); it != v.end(); ++it)
            if (it.key() != "name" && it.key() != "flags") {
                *problem = where + ": unknown key '" + it.key() + "' (name, flags)";
                return false;
            }
        auto name = v.find("name"), flags = v.find("flags");
        if (name == v.end() || !name->is_string()) { *problem = where + ": no name string"; return false; }
        if (flags != v.end() && !flags->is_string()) {
            *problem = where + " ('" + name->get<std::string>() + "'): flags must be a string";
            return false;
        }
        out->emplace_back(name->get<std::string>(), flags != v.end() ? flags->get<std::string>() : std::string());
    }
    return true;
}

}  // namespace

extern "C" int io_read_variants(const char *path, IoVariant **variants, int *count, char err[IO_ERR_LEN]) {
    *variants = nullptr;
    *count = 0;
    std::string p(path), text, problem;
    std::vector<Entry> entries;
    try {
        bool ok;
        if (!read_text(p, &text, &problem)) ok = false;
        else if (ends_with(p, ".toml")) ok = from_toml(text, p, &entries, &problem);
        else if (ends_with(p, ".json")) ok = from_json(text, &entries, &problem);
        else { problem = "a variant file must end in .toml or .json"; ok = false; }
        if (ok && entries.empty()) { problem = "no variants"; ok = false; }
        if (ok && entries.size() > IO_MAX_VARIANTS) {
            problem = "more than " + std::to_string(IO_MAX_VARIANTS) + " variants";
            ok = false;
        }
        if (!ok) { candela_io::set_err(err, p, problem); return -1; }
    } catch (const std::exception &e) {
        candela_io::set_err(err, p, e.what());
        return -1;
    }
    IoVariant *v = static_cast<IoVariant *>(std::calloc(entries.size(), sizeof(IoVariant)));
    if (!v) { candela_io::set_err(err, p, "out of memory"); return -1; }
    for (size_t i = 0; i < entries.size(); ++i) {
        v[i].name = strdup(entries[i].first.c_str());
        v[i].flags = strdup(entries[i].second.c_str());
        if (!v[i].name || !v[i].flags) {
            io_variants_free(v, static_cast<int>(i + 1));
            candela_io::set_err(err, p, "out of memory");
            return -1;
        }
    }
    *variants = v;
    *count = static_cast<int>(entries.size());
    return 0;
}

extern "C" void io_variants_free(IoVariant *variants, int count) {
    if (!variants) return;
    for (int i = 0; i < count; ++i) {
        std::free(variants[i].name);
        std::free(variants[i].flags);
    }
    std::free(variants);
}

extern "C" char *io_json_quote(const char *s) {
    try {
        std::string q = nlohmann::json(std::string(s ? s : "")).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
        return strdup(q.c_str());
    } catch (const std::exception &) {
        return nullptr; /* std::bad_alloc */
    }
}
