// io/gltf_meshes.cpp: accessors (every bufferView and accessor bound checked, sparse
// substitution, component types) and mesh primitives (positions, normals, UVs, tangents,
// indices; finite positions, index ranges).
#include "gltf_internal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <new>
#include <string>

namespace candela_io::gltf {

// Largest accessor element count accepted (also bounds accessors that have no bufferView).
static constexpr size_t kMaxCount = size_t(1) << 28;

static float comp_to_float(const unsigned char *p, int ct, bool normalized) {
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

static uint32_t comp_to_uint(const unsigned char *p, int ct) {
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

static bool is_index_type(int ct) {
    return ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
           ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ||
           ct == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
}

static const char *type_name(int t) {
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

}  // namespace candela_io::gltf
