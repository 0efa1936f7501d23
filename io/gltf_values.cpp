// io/gltf_values.cpp: the glTF loader's shared helpers (gltf_internal.hpp): messages, file
// paths and the confinement rule, and the checked readers of JSON values, where the loader's
// limits on values are enforced (a value of the wrong kind or out of range is one line naming
// the node or material and the key).
#include "gltf_internal.hpp"

#include <sys/stat.h>

#include <cctype>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace candela_io::gltf {

std::string strf(const char *fmt, ...) {
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    return buf;
}

[[noreturn]] void fail(const std::string &problem) { throw LoadError{problem}; }

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

}  // namespace candela_io::gltf
