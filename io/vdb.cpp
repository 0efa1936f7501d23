// io/vdb.cpp: candela_io_vdb.so (io_module.h, loaded on first use: the program itself never
// links OpenVDB): OpenVDB float grids handed to C as NanoVDB buffers (io.h, IoVolumeGrid).
//
// The file is walked first (VdbWalk: every size it declares is checked against the bytes it
// holds, since OpenVDB allocates what a file claims before reading it), then OpenVDB reads it
// (a corrupt file it still meets throws); the grid is converted with NanoVDB's openToNanoVDB
// into one flat buffer, which C code reads with PNanoVDB.h. No OpenVDB or NanoVDB type
// crosses io.h.
#include "io.h"
#include "io_internal.hpp"
#include "io_module.h"

#include <openvdb/openvdb.h>
#include <nanovdb/util/OpenToNanoVDB.h>

#include <blosc.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <map>
#include <mutex>
#include <string>
#include <sys/stat.h>
#include <unistd.h>
#include <vector>

namespace {

// Largest extent of a grid's active bounding box per axis, in voxels: far beyond any
// production volume, and small enough that index arithmetic stays exact in float.
constexpr int kMaxGridExtent = 1 << 20;

void openvdb_init_once() {
    static std::once_flag flag;
    std::call_once(flag, [] { openvdb::initialize(); });
}

// Fills everything but name and buffer from the OpenVDB grid; false with a problem.
bool describe(const openvdb::FloatGrid &grid, IoVolumeGrid *out, std::string *problem) {
    if (!grid.transform().isLinear()) {
        *problem = "grid '" + grid.getName() + "' has a non-linear (frustum) transform, which is not supported";
        return false;
    }
    openvdb::CoordBBox bbox = grid.evalActiveVoxelBoundingBox();
    if (grid.activeVoxelCount() == 0 || bbox.empty()) {
        *problem = "grid '" + grid.getName() + "' is empty (no active voxels)";
        return false;
    }
    for (int k = 0; k < 3; ++k) {
        long long extent = (long long)bbox.max()[k] - (long long)bbox.min()[k] + 1;
        if (extent > kMaxGridExtent || std::llabs((long long)bbox.min()[k]) > kMaxGridExtent ||
            std::llabs((long long)bbox.max()[k]) > kMaxGridExtent) {
            *problem = "grid '" + grid.getName() + "' has absurd bounds (more than 2^20 voxels along an axis)";
            return false;
        }
        out->index_min[k] = bbox.min()[k];
        out->index_max[k] = bbox.max()[k];
    }
    // OpenVDB maps row vectors: world_j = sum_i index_i m[i][j] + m[3][j]
    openvdb::math::Mat4d m = grid.transform().baseMap()->getAffineMap()->getMat4();
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            double v = m[i][j];
            if (!std::isfinite(v)) {
                *problem = "grid '" + grid.getName() + "' has a non-finite transform";
                return false;
            }
            out->index_to_world[i * 4 + j] = (float)v;
        }
    // voxel sizes: the active box in the world must lie within the coordinate limit (a voxel of
    // 1e30 put a small file's volume where nothing downstream can work with it; README "Limits")
    for (int c = 0; c < 8; ++c) {
        double p[3];
        for (int k = 0; k < 3; ++k) p[k] = (c >> k & 1) ? bbox.max()[k] + 1.5 : bbox.min()[k] - 1.5;
        for (int j = 0; j < 3; ++j) {
            double w = p[0] * m[0][j] + p[1] * m[1][j] + p[2] * m[2][j] + m[3][j];
            if (!(std::fabs(w) <= IO_MAX_COORDINATE)) {
                char what[160];
                std::snprintf(what, sizeof what, "': its voxels reach beyond %g in the world (voxel size %g)", IO_MAX_COORDINATE,
                              grid.voxelSize()[0]);
                *problem = "grid '" + grid.getName() + what;
                return false;
            }
        }
    }
    float lo = INFINITY, hi = -INFINITY;
    uint64_t nonfinite = 0;
    for (auto it = grid.cbeginValueOn(); it; ++it) {
        float v = *it;
        if (!std::isfinite(v)) { nonfinite += it.isVoxelValue() ? 1 : it.getVoxelCount(); continue; }
        lo = v < lo ? v : lo;
        hi = v > hi ? v : hi;
    }
    out->value_min = lo <= hi ? lo : 0.0f;
    out->value_max = lo <= hi ? hi : 0.0f;
    out->active_voxels = grid.activeVoxelCount();
    out->nonfinite_voxels = nonfinite;
    return true;
}

bool to_nanovdb(const openvdb::FloatGrid &grid, IoVolumeGrid *out, std::string *problem) {
    auto handle = nanovdb::openToNanoVDB(grid);
    uint64_t size = handle.size();
    if (!handle.data() || size == 0) {
        *problem = "NanoVDB conversion of grid '" + grid.getName() + "' failed";
        return false;
    }
    void *buffer = std::aligned_alloc(32, (size + 31) / 32 * 32);
    if (!buffer) {
        *problem = "out of memory converting grid '" + grid.getName() + "'";
        return false;
    }
    std::memcpy(buffer, handle.data(), size);
    out->buffer = buffer;
    out->size = size;
    return true;
}

void set_name(IoVolumeGrid *out, const std::string &name) {
    std::snprintf(out->name, sizeof out->name, "%s", name.c_str());
}

// ---------------------------------------------------------------- the file, checked before OpenVDB reads it
//
// OpenVDB's reader trusts every size and count the file declares: a string's length, a
// metadata value's size, a compressed chunk's byte count is allocated before the bytes are
// read, and a root node's tile and child counts are looped over whether or not the file holds
// them. A truncated or corrupt file can thus make it ask for terabytes (std::bad_alloc in a
// release build, an abort under AddressSanitizer) or allocate a node per read past the end.
// So the file is walked first, along exactly the path OpenVDB 10's io::File::open() and
// readGrid(name) take for a float grid, and every declared size is held against the bytes left
// in the file; OpenVDB is handed only a file that passed. The walk knows file formats 222-224
// with grid offsets (io::File; OpenVDB 10 writes 224) and refuses, with one line, what it does
// not know rather than let OpenVDB read it unchecked.
//
// Besides sizes, it refuses what OpenVDB would read without complaint but then misbehave on:
// a root child given twice (the first one leaks), a tile's "active" byte other than 0 or 1 (a
// bool load), a child and a tile in the same internal-node slot, and compressed values of an
// internal node that do not decompress (OpenVDB throws from inside the root's child loop and
// leaks the half-read child; those chunks are small, so they are decompressed here once).
// Leaf values are not decompressed: a bad leaf chunk throws where the tree already owns it.

// OpenVDB's stream constants (io/Compression.h, version.h), named as there.
constexpr uint32_t kFormatNodeMaskCompression = 222;  // OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION
constexpr uint32_t kCompressZip = 0x1, kCompressActiveMask = 0x2, kCompressBlosc = 0x4;
constexpr int kMaskAndAllVals = 6;  // NO_MASK_AND_ALL_VALS: the largest per-node metadata flag
constexpr int kRootChildDim = 4096;  // a root child (32^3 node of 16^3 nodes of 8^3 leaves) spans 4096 voxels
// Root tile and child origins farther out than this are refused: Candela refuses active voxels
// beyond 2^20 anyway (kMaxGridExtent), and an origin plus a few node sizes then stays far from
// int overflow in the OpenVDB and NanoVDB code that follows.
constexpr int64_t kMaxRootOrigin = int64_t(1) << 30;
// Metadata and map type names are compared with known ones, so they are read; longer ones
// (which no known type has) are only skipped. Grid names are read whole, however long.
constexpr uint32_t kMaxKeptString = 4096;

struct Descriptor {
    std::string unique_name, grid_name, type, parent;  // type without the "_HalfFloat" suffix
    int64_t grid_pos = 0;
};

class VdbWalk {
public:
    VdbWalk(int fd, uint64_t size) : fd_(fd), size_(size) {}

    // The whole path OpenVDB takes to read grid_name; false with a one-line problem.
    bool check(const std::string &grid_name, std::string *problem);

private:
    int fd_;
    uint64_t size_, pos_ = 0;
    std::string problem_;
    // read-ahead window over the file (the walk reads small pieces and skips large ones)
    std::vector<unsigned char> buf_ = std::vector<unsigned char>(1 << 16);
    uint64_t buf_start_ = 0, buf_len_ = 0;
    uint32_t version_ = 0, compression_ = 0;
    std::vector<Descriptor> descriptors_;

    bool fail(const std::string &what) {
        if (problem_.empty()) problem_ = what;
        return false;
    }
    bool fail_at(const std::string &what) { return fail(what + " (at byte " + std::to_string(pos_) + ")"); }
    uint64_t left() const { return size_ - pos_; }
    bool need(uint64_t n, const char *what) {
        if (n <= left()) return true;
        return fail(std::string("truncated or corrupt: ") + what + " needs " + std::to_string(n) + " bytes at byte " +
                    std::to_string(pos_) + ", the file has " + std::to_string(left()) + " left");
    }
    bool skip(uint64_t n, const char *what) {
        if (!need(n, what)) return false;
        pos_ += n;
        return true;
    }
    bool read(void *dst, size_t n, const char *what);
    template <class T> bool value(T *v, const char *what) { return read(v, sizeof *v, what); }
    bool string(std::string *s, bool *too_long, const char *what, uint64_t keep = kMaxKeptString);

    bool header();
    bool metadata(const char *owner, bool *half = nullptr);
    bool delayed_load_metadata(uint32_t num_bytes);
    bool descriptors();
    const Descriptor *find(const std::string &name) const;
    bool grid(const Descriptor &d, bool with_tree);
    bool transform(const std::string &grid);
    bool tree(bool half);
    bool internal_topology(int log2dim, bool half, std::vector<uint16_t> *leaves);
    bool node_values(uint32_t count, uint32_t active, bool half, bool decode);
    bool chunk(uint64_t num_bytes, bool decode);
    bool blosc_header(uint64_t chunk_bytes, uint64_t max_nbytes, bool exact, const char *what, size_t *nbytes);
};

bool VdbWalk::read(void *dst, size_t n, const char *what) {
    if (!need(n, what)) return false;
    unsigned char *out = static_cast<unsigned char *>(dst);
    while (n > 0) {
        if (pos_ < buf_start_ || pos_ >= buf_start_ + buf_len_) {
            ssize_t got;
            do got = pread(fd_, buf_.data(), buf_.size(), (off_t)pos_);
            while (got < 0 && errno == EINTR);
            if (got <= 0) return fail_at(std::string("cannot read: ") + (got < 0 ? std::strerror(errno) : "file shrank"));
            buf_start_ = pos_;
            buf_len_ = (uint64_t)got;
        }
        size_t k = (size_t)std::min<uint64_t>(n, buf_start_ + buf_len_ - pos_);
        std::memcpy(out, buf_.data() + (pos_ - buf_start_), k);
        out += k;
        pos_ += k;
        n -= k;
    }
    return true;
}

// OpenVDB's readString: a uint32 length, then the bytes (allocated at that length first).
// Kept in s when at most `keep` bytes long, else skipped with *too_long set.
bool VdbWalk::string(std::string *s, bool *too_long, const char *what, uint64_t keep) {
    uint32_t n = 0;
    if (!value(&n, what) || !need(n, what)) return false;
    *too_long = n > keep;
    if (*too_long) {
        s->clear();
        return skip(n, what);
    }
    s->resize(n);
    return n == 0 || read(&(*s)[0], n, what);
}

// Archive::readHeader for formats 222-224 (the ones that store compression per grid).
bool VdbWalk::header() {
    int64_t magic = 0;
    if (!value(&magic, "the header") || magic != 0x56444220) return fail("not a VDB file");
    uint32_t major = 0, minor = 0;
    char offsets = 0;
    if (!value(&version_, "the header") || !value(&major, "the header") || !value(&minor, "the header") ||
        !value(&offsets, "the header"))
        return false;
    if (version_ < kFormatNodeMaskCompression)
        return fail("VDB file format " + std::to_string(version_) + " is older than 222 (re-save it with a current OpenVDB)");
    if (version_ > openvdb::OPENVDB_FILE_VERSION)
        return fail("VDB file format " + std::to_string(version_) + " is newer than this OpenVDB reads (" +
                    std::to_string(openvdb::OPENVDB_FILE_VERSION) + ")");
    if (!offsets) return fail("a VDB stream without grid offsets (written by io::Stream) is not supported");
    // the UUID, read by boost::uuids' operator>>: 36 characters as OpenVDB writes them (that
    // reader would also skip white space and so read a different number of bytes)
    char uuid[36];
    if (!read(uuid, sizeof uuid, "the header")) return false;
    for (int i = 0; i < 36; ++i) {
        bool hyphen = i == 8 || i == 13 || i == 18 || i == 23;
        if (hyphen ? uuid[i] != '-' : !std::isxdigit((unsigned char)uuid[i])) return fail("corrupt VDB header (UUID)");
    }
    return true;
}

// MetaMap::readMeta: a count, then name, type name, Index32 size and the value, which
// TypedMetadata reads at its own size whatever the declared one, string and unknown types at
// the declared size, and DelayedLoadMetadata by its own layout. half (a grid's metadata): set
// to what decides whether its values are read as half floats. That is not the descriptor's
// "_HalfFloat" suffix but GridBase::saveFloatAsHalf(), the bool metadata
// "is_saved_as_half_float" (reading the metadata drops what the descriptor set; a later entry
// replaces an earlier one; absent: full floats).
bool VdbWalk::metadata(const char *owner, bool *half) {
    static const std::string half_name = "is_saved_as_half_float";
    if (half) *half = false;
    static const std::map<std::string, uint32_t> fixed = {
        {"bool", 1},   {"double", 8}, {"float", 4},  {"int32", 4},  {"int64", 8},  {"vec2i", 8},
        {"vec2s", 8},  {"vec2d", 16}, {"vec3i", 12}, {"vec3s", 12}, {"vec3d", 24}, {"vec4i", 16},
        {"vec4s", 16}, {"vec4d", 32}, {"mat4s", 64}, {"mat4d", 128}};
    uint32_t count = 0;
    if (!value(&count, "a metadata count")) return false;
    for (uint32_t i = 0; i < count; ++i) {
        std::string name, type;
        bool long_name = false, long_type = false;
        uint32_t size = 0;
        if (!string(&name, &long_name, "a metadata name") || !string(&type, &long_type, "a metadata type") ||
            !value(&size, "a metadata value"))
            return false;
        if (half && name == half_name && type != "bool")
            return fail_at(std::string(owner) + " metadata '" + half_name + "' is a " + type + ", not a bool");
        auto it = fixed.find(type);
        if (it != fixed.end()) {
            if (size != it->second)
                return fail_at(std::string(owner) + " metadata '" + name + "' (" + type + ") declares " +
                               std::to_string(size) + " bytes, not " + std::to_string(it->second));
            if (type == "bool") {  // read into a C++ bool: only 0 or 1 is a value
                unsigned char b = 0;
                if (!value(&b, "a metadata value")) return false;
                if (b > 1) return fail_at(std::string(owner) + " metadata '" + name + "' is a bool of value " + std::to_string(b));
                if (half && name == half_name) *half = b != 0;
                continue;
            }
            if (!skip(size, "a metadata value")) return false;
        } else if (type == "__delayedload" && openvdb::Metadata::isRegisteredType(type)) {
            if (!delayed_load_metadata(size)) return false;
        } else if (type == "string" || long_type || !openvdb::Metadata::isRegisteredType(type)) {
            if (!skip(size, "a metadata value")) return false;  // read as bytes of the declared size
        } else {
            return fail(std::string(owner) + " metadata '" + name + "' has type '" + type +
                        "', whose layout this reader does not know");
        }
    }
    return true;
}

// Reads (and checks) a blosc header at pos_ without moving: the chunk must hold the whole
// compressed buffer it describes (blosc's decompressor reads as far as the header says), and
// the uncompressed size must be max_nbytes (exact) or at most that.
bool VdbWalk::blosc_header(uint64_t chunk_bytes, uint64_t max_nbytes, bool exact, const char *what, size_t *nbytes) {
    unsigned char h[BLOSC_MIN_HEADER_LENGTH];
    if (chunk_bytes < sizeof h) return fail_at(std::string("corrupt ") + what + " (shorter than a blosc header)");
    uint64_t at = pos_;
    if (!read(h, sizeof h, what)) return false;
    pos_ = at;
    size_t cbytes = 0, blocksize = 0;
    blosc_cbuffer_sizes(h, nbytes, &cbytes, &blocksize);
    if (cbytes != chunk_bytes || (exact ? *nbytes != max_nbytes : *nbytes > max_nbytes))
        return fail_at(std::string("corrupt ") + what + " (blosc header sizes do not match the chunk)");
    return true;
}

// DelayedLoadMetadata::readValue: a leaf count, a per-leaf int8 mask and optionally per-leaf
// int64 compressed sizes, each blosc-compressed (a uint32 byte count, 0 = stored raw; the
// sizes' count is ~0u when absent), then any declared bytes beyond those skipped. Both arrays
// are allocated at the leaf count, which a leaf's 64-byte mask in the file bounds.
bool VdbWalk::delayed_load_metadata(uint32_t num_bytes) {
    if (num_bytes == 0) return true;
    const uint64_t start = pos_;
    uint32_t count = 0, bytes = 0;
    if (!value(&count, "delayed-load metadata") || !value(&bytes, "delayed-load metadata")) return false;
    if ((uint64_t)count * 64 > size_) return fail_at("corrupt delayed-load metadata (leaf count " + std::to_string(count) + ")");
    for (int part = 0; part < 2; ++part) {
        const uint64_t elem = part == 0 ? 1 : 8, raw = (uint64_t)count * elem;
        if (part == 1) {
            if (!value(&bytes, "delayed-load metadata")) return false;
            if (bytes == 0xffffffffu) break;  // no compressed sizes stored
        }
        size_t nbytes = 0;
        if (bytes == 0) {
            if (!skip(raw, "delayed-load metadata")) return false;
        } else if (!need(bytes, "delayed-load metadata") ||
                   // padded to 128 bytes when smaller (points/StreamCompression.cc)
                   !blosc_header(bytes, std::max<uint64_t>(raw, 128), false, "delayed-load metadata", &nbytes) ||
                   !skip(bytes, "delayed-load metadata")) {
            return false;
        }
    }
    const uint64_t used = pos_ - start;
    return used >= num_bytes || skip(num_bytes - used, "delayed-load metadata");
}

// File::readGridDescriptors: a count, then per grid its unique name, type (with "_HalfFloat"
// for half-float grids), instance parent and the three stream offsets; the next descriptor
// starts at the end offset.
bool VdbWalk::descriptors() {
    int32_t count = 0;
    if (!value(&count, "the grid count")) return false;
    for (int32_t i = 0; i < count; ++i) {
        Descriptor d;
        bool long_type = false, unused = false;
        int64_t block_pos = 0, end_pos = 0;
        if (!string(&d.unique_name, &unused, "a grid name", UINT64_MAX) || !string(&d.type, &long_type, "a grid type") ||
            !string(&d.parent, &unused, "a grid instance parent", UINT64_MAX) || !value(&d.grid_pos, "grid offsets") ||
            !value(&block_pos, "grid offsets") || !value(&end_pos, "grid offsets"))
            return false;
        static const std::string half_suffix = "_HalfFloat";
        if (d.type.size() >= half_suffix.size() &&
            d.type.compare(d.type.size() - half_suffix.size(), half_suffix.size(), half_suffix) == 0)
            d.type.resize(d.type.size() - half_suffix.size());
        if (long_type) d.type = "(a " + std::to_string(kMaxKeptString) + "+ byte type name)";
        d.grid_name = d.unique_name.substr(0, d.unique_name.find('\x1e'));  // GridDescriptor::stripSuffix
        if (d.grid_pos < 0 || (uint64_t)d.grid_pos > size_ || end_pos < (int64_t)pos_ || (uint64_t)end_pos > size_)
            return fail_at("truncated or corrupt: grid '" + d.grid_name + "' lies past the end of the file (" +
                           std::to_string(size_) + " bytes)");
        descriptors_.push_back(d);
        pos_ = (uint64_t)end_pos;
    }
    return true;
}

// File::findDescriptor: the first grid (in file order, as the multimap keeps equal keys) with
// that name; "name[N]" names the one whose unique name is name + '\x1e' + N.
const Descriptor *VdbWalk::find(const std::string &name) const {
    std::string unique = name;
    if (!unique.empty() && unique.back() == ']' && unique.find('[') != std::string::npos) {
        unique.pop_back();
        unique.replace(unique.find('['), 1, "\x1e");
    }
    std::vector<const Descriptor *> range;
    for (const Descriptor &d : descriptors_)
        if (d.grid_name == name) range.push_back(&d);
    if (range.empty()) {
        const std::string stripped = unique.substr(0, unique.find('\x1e'));
        for (const Descriptor &d : descriptors_)
            if (d.grid_name == stripped) range.push_back(&d);
    }
    if (range.empty()) return nullptr;
    if (name == unique) return range.front();
    for (const Descriptor *d : range)
        if (d->unique_name == unique || d->unique_name == name) return d;
    return nullptr;
}

// math::Transform::read: the map's type name, then its members (Maps.h).
bool VdbWalk::transform(const std::string &grid) {
    static const std::map<std::string, uint32_t> maps = {
        {"AffineMap", 128},         {"UnitaryMap", 128},        {"ScaleMap", 120},
        {"UniformScaleMap", 120},   {"TranslationMap", 24},     {"ScaleTranslateMap", 144},
        {"UniformScaleTranslateMap", 144}};
    std::string type;
    bool long_type = false;
    if (!string(&type, &long_type, "a transform type")) return false;
    if (type == "NonlinearFrustumMap")
        return fail("grid '" + grid + "' has a non-linear (frustum) transform, which is not supported");
    auto it = maps.find(type);
    if (long_type || it == maps.end()) return fail_at("grid '" + grid + "' has an unknown transform type '" + type + "'");
    return skip(it->second, "a transform");
}

// One compressed chunk of num_bytes values (io::readData): blosc or zip by the grid's
// compression flags (a signed int64 byte count, negative = stored raw), else raw bytes.
// decode: decompress it as OpenVDB will and refuse it if that fails.
bool VdbWalk::chunk(uint64_t num_bytes, bool decode) {
    if (!(compression_ & (kCompressBlosc | kCompressZip))) return skip(num_bytes, "uncompressed values");
    const bool blosc = compression_ & kCompressBlosc;
    const char *what = blosc ? "blosc chunk" : "zip chunk";
    int64_t n = 0;
    if (!value(&n, what)) return false;
    if (n <= 0) {
        const uint64_t stored = 0 - (uint64_t)n;  // (n may be INT64_MIN)
        if (stored != num_bytes)
            return fail_at(std::string("corrupt ") + what + " (" + std::to_string(stored) + " bytes stored, " +
                           std::to_string(num_bytes) + " expected)");
        return skip(num_bytes, what);
    }
    if (!need((uint64_t)n, what)) return false;
    size_t nbytes = 0;
    if (blosc && !blosc_header((uint64_t)n, num_bytes, true, what, &nbytes)) return false;
    if (decode) {
        std::vector<unsigned char> src((size_t)n), dst(num_bytes ? num_bytes : 1);
        if (!read(src.data(), src.size(), what)) return false;
        bool ok;
        if (blosc) {
            ok = blosc_decompress_ctx(src.data(), dst.data(), num_bytes, 1) == (int)num_bytes;
        } else {
            uLongf got = num_bytes;
            ok = uncompress(dst.data(), &got, src.data(), (uLong)n) == Z_OK && got == num_bytes;
        }
        return ok || fail_at(std::string("corrupt ") + what + " (does not decompress)");
    }
    return skip((uint64_t)n, what);
}

// io::readCompressedValues for a node of `count` values of which `active` are active: a
// metadata byte, up to two inactive values and a selection mask, then the chunk (only the
// active values when mask compression is on and the flag says so). Half-float grids store
// those values (not the inactive ones) as 16 bits, and no chunk at all when there are none.
bool VdbWalk::node_values(uint32_t count, uint32_t active, bool half, bool decode) {
    int8_t meta = 0;
    if (!value(&meta, "node values")) return false;
    if (meta < 0 || meta > kMaskAndAllVals) return fail_at("corrupt node values (compression flag " + std::to_string(meta) + ")");
    uint64_t extra = (meta == 2 || meta == 4 || meta == 5) ? 4 : 0;  // inactive value 0 (a float)
    if (meta == 5) extra += 4;                                       // inactive value 1
    if (meta >= 3 && meta <= 5) extra += count / 8;                  // selection mask
    if (!skip(extra, "node values")) return false;
    const uint32_t n = (compression_ & kCompressActiveMask) && meta != kMaskAndAllVals ? active : count;
    if (half && n == 0) return true;  // io::HalfReader reads nothing for no values
    return chunk((uint64_t)n * (half ? 2 : 4), decode);
}

// InternalNode::readTopology: child mask, value mask, all values, then the children in index
// order; below the 16^3 nodes, leaves (LeafNode::readTopology: the value mask only), whose
// active counts the buffers pass needs.
bool VdbWalk::internal_topology(int log2dim, bool half, std::vector<uint16_t> *leaves) {
    const uint32_t count = 1u << (3 * log2dim), words = count / 64;
    std::vector<uint64_t> child(words), active(words);
    if (!read(child.data(), words * 8, "a node mask") || !read(active.data(), words * 8, "a node mask")) return false;
    uint32_t num_active = 0;
    for (uint32_t w = 0; w < words; ++w) {
        if (child[w] & active[w]) return fail_at("corrupt tree (a child and a tile in one node slot)");
        num_active += (uint32_t)__builtin_popcountll(active[w]);
    }
    if (!node_values(count, num_active, half, true)) return false;
    for (uint32_t w = 0; w < words; ++w)
        for (uint64_t bits = child[w]; bits; bits &= bits - 1) {
            if (log2dim > 4) {
                if (!internal_topology(log2dim - 1, half, leaves)) return false;
                continue;
            }
            uint64_t mask[8];
            if (!read(mask, sizeof mask, "a leaf mask")) return false;
            uint16_t on = 0;
            for (uint64_t m : mask) on = (uint16_t)(on + __builtin_popcountll(m));
            leaves->push_back(on);
        }
    return true;
}

// Tree::readTopology + readBuffers for a float tree (5-4-3): the root's background, tiles and
// children with their topology, then every leaf's buffer, children taken in the order of the
// root's std::map<Coord> (not file order).
bool VdbWalk::tree(bool half) {
    int32_t buffers = 0;
    if (!value(&buffers, "the tree")) return false;
    if (buffers != 1) return fail_at("corrupt tree (" + std::to_string(buffers) + " buffers per node)");
    float background;
    uint32_t num_tiles = 0, num_children = 0;
    if (!value(&background, "the tree") || !value(&num_tiles, "the tree") || !value(&num_children, "the tree"))
        return false;
    std::map<std::array<int32_t, 3>, size_t> table;  // origin -> child index, or SIZE_MAX for a tile
    auto origin = [&](const char *what, std::array<int32_t, 3> *o) {
        if (!read(o->data(), 12, what)) return false;
        for (int32_t c : *o)
            if (c % kRootChildDim != 0 || std::llabs((long long)c) > kMaxRootOrigin)
                return fail_at(std::string("corrupt tree (") + what + " origin " + std::to_string(c) + ")");
        return true;
    };
    for (uint32_t i = 0; i < num_tiles; ++i) {
        std::array<int32_t, 3> o;
        unsigned char tile[5];  // value, active
        if (!need(17, "a root tile") || !origin("a root tile", &o) || !read(tile, sizeof tile, "a root tile")) return false;
        if (tile[4] > 1) return fail_at("corrupt tree (a root tile's active flag is " + std::to_string(tile[4]) + ")");
        if (!table.emplace(o, SIZE_MAX).second) return fail_at("corrupt tree (two root tiles at one origin)");
    }
    std::vector<std::vector<uint16_t>> leaves;
    for (uint32_t i = 0; i < num_children; ++i) {
        std::array<int32_t, 3> o;
        if (!origin("a root child", &o)) return false;
        if (!table.emplace(o, leaves.size()).second) return fail_at("corrupt tree (two root nodes at one origin)");
        leaves.emplace_back();
        if (!internal_topology(5, half, &leaves.back())) return false;
    }
    for (const auto &entry : table) {
        if (entry.second == SIZE_MAX) continue;
        for (uint16_t on : leaves[entry.second])
            // LeafNode::readBuffers: the value mask again (skipped), then the values
            if (!skip(64, "a leaf mask") || !node_values(512, on, half, false)) return false;
    }
    return true;
}

// Archive::readGrid: compression flags, metadata, transform, and (unless the grid is an
// instance of another grid's tree) topology and buffers.
bool VdbWalk::grid(const Descriptor &d, bool with_tree) {
    pos_ = (uint64_t)d.grid_pos;
    if (!value(&compression_, "the grid's compression flags")) return false;
    const std::string owner = "grid '" + d.grid_name + "'";
    bool half = false;
    if (!metadata(owner.c_str(), &half) || !transform(d.grid_name)) return false;
    return !with_tree || tree(half);
}

// "Tree_vec3s_5_4_3" -> "vec3s", as GridBase::valueType() names it
std::string value_type(const std::string &tree_type) {
    if (tree_type.compare(0, 5, "Tree_") != 0) return tree_type;
    return tree_type.substr(5, tree_type.find('_', 5) - 5);
}

bool VdbWalk::check(const std::string &grid_name, std::string *problem) {
    bool ok = header() && metadata("file") && descriptors();
    if (ok) {
        const Descriptor *d = find(grid_name);
        // (a missing grid is reported by the caller, with the names the file has)
        if (d && d->type != openvdb::FloatGrid::gridType()) {
            ok = fail("grid '" + grid_name + "' is a " + value_type(d->type) + " grid, not a float grid");
        } else if (d && d->parent.empty()) {
            ok = grid(*d, true);
        } else if (d) {
            // File::readGridByName: the instance's metadata and transform, then its parent's
            // grid (that one's tree unless it is an instance itself), whose tree it shares
            const Descriptor *p = find(d->parent.find('\x1e') == std::string::npos
                                           ? d->parent
                                           : d->parent.substr(0, d->parent.find('\x1e')) + "[" +
                                                 d->parent.substr(d->parent.find('\x1e') + 1) + "]");
            ok = grid(*d, false);
            if (ok && p && p->type != openvdb::FloatGrid::gridType())
                ok = fail("grid '" + grid_name + "' shares the tree of a " + value_type(p->type) + " grid");
            else if (ok && p)
                ok = grid(*p, p->parent.empty());
        }
    }
    if (!ok) *problem = problem_.empty() ? std::string("corrupt VDB file") : problem_;
    return ok;
}

// Walks the open file fd (size bytes); false with a one-line problem.
bool check_vdb_file(int fd, uint64_t size, const std::string &grid_name, std::string *problem) {
    return VdbWalk(fd, size).check(grid_name, problem);
}

}  // namespace

static int vdb_load_vdb_grid(const char *path, const char *grid_name, IoVolumeGrid *out, char err[IO_ERR_LEN]) {
    std::memset(out, 0, sizeof *out);
    struct stat st;
    if (stat(path, &st) != 0) {
        candela_io::set_err(err, path, "cannot open: no such file");
        return 1;
    }
    if (!S_ISREG(st.st_mode)) {
        candela_io::set_err(err, path, "not a regular file");
        return 1;
    }
    // The file is opened once, through the program's input door (regular files only, never
    // blocking), walked, and read by OpenVDB from that very descriptor's own name
    // (/proc/self/fd/N: the same inode, whatever the path names by then), so a file swapped in
    // after the walk (a FIFO, another VDB) is never read unchecked.
    int fd = -1;
    uint64_t size = 0;
    if (io_open_input(path, 0, "a VDB file", &fd, &size, err) != 0) return 1;
    struct FdCloser {
        int fd;
        ~FdCloser() { close(fd); }
    } fd_closer{fd};
    const std::string by_fd = "/proc/self/fd/" + std::to_string(fd);
    // OpenVDB's messages name the file it opened; the user named another
    auto named = [&](std::string m) {
        for (size_t k; (k = m.find(by_fd)) != std::string::npos;) m.replace(k, by_fd.size(), path);
        return m;
    };
    try {
        openvdb_init_once();  // (the walk asks OpenVDB's metadata registry)
        std::string problem;
        if (!check_vdb_file(fd, size, grid_name, &problem)) {
            candela_io::set_err(err, path, problem);
            return 1;
        }
        openvdb::io::File file(by_fd);
        file.open(false);  // no delayed loading: the whole grid is read (and checked) now
        if (!file.hasGrid(grid_name)) {
            std::string names;
            for (auto it = file.beginName(); it != file.endName(); ++it) names += (names.empty() ? "" : ", ") + *it;
            file.close();
            candela_io::set_err(err, path, std::string("no grid named '") + grid_name + "' (grids: " +
                                               (names.empty() ? "none" : names) + ")");
            return 1;
        }
        openvdb::GridBase::Ptr base = file.readGrid(grid_name);
        file.close();
        openvdb::FloatGrid::Ptr grid = openvdb::gridPtrCast<openvdb::FloatGrid>(base);
        if (!grid) {
            candela_io::set_err(err, path, std::string("grid '") + grid_name + "' is a " + base->valueType() +
                                               " grid, not a float grid");
            return 1;
        }
        if (!describe(*grid, out, &problem) || !to_nanovdb(*grid, out, &problem)) {
            candela_io::set_err(err, path, problem);
            std::memset(out, 0, sizeof *out);
            return 1;
        }
        set_name(out, grid_name);
        return 0;
    } catch (const std::exception &e) {
        candela_io::set_err(err, path, "not a readable VDB file: " + named(e.what()));
    } catch (...) {
        candela_io::set_err(err, path, "not a readable VDB file");
    }
    io_volume_grid_free(out);
    return 1;
}

namespace {

openvdb::FloatGrid::Ptr dense_grid(const float *values, int nx, int ny, int nz, const float index_to_world[16],
                                   const char *name) {
    openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(0.0f);
    grid->setName(name);
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    openvdb::math::Mat4d m;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) m[i][j] = index_to_world[i * 4 + j];
    grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
    auto acc = grid->getAccessor();
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y)
            for (int x = 0; x < nx; ++x) {
                float v = values[(size_t)x + (size_t)nx * ((size_t)y + (size_t)ny * (size_t)z)];
                if (v != 0.0f) acc.setValue(openvdb::Coord(x, y, z), v);
            }
    return grid;
}

bool dense_size_ok(int nx, int ny, int nz) {
    return nx > 0 && ny > 0 && nz > 0 && nx <= kMaxGridExtent && ny <= kMaxGridExtent && nz <= kMaxGridExtent;
}

}  // namespace

static int vdb_write_vdb_dense(const char *path, const char *const *names, const float *const *values, int num_grids,
                                  int nx, int ny, int nz, const float index_to_world[16], char err[IO_ERR_LEN]) {
    if (!dense_size_ok(nx, ny, nz) || num_grids < 1) {
        candela_io::set_err(err, path, "invalid dense grid size");
        return 1;
    }
    // through the program's atomic writer (io.h; module_host.c): OpenVDB writes the temporary by
    // name, the program syncs and renames it
    IoAtomicFile af;
    if (io_atomic_begin(&af, path, nullptr, err) != 0) return 1;
    try {
        openvdb_init_once();
        openvdb::GridPtrVec grids;
        for (int g = 0; g < num_grids; ++g) grids.push_back(dense_grid(values[g], nx, ny, nz, index_to_world, names[g]));
        openvdb::io::File file(af.tmp);
        file.write(grids);
        file.close();
        return io_atomic_commit(&af, err);
    } catch (const std::exception &e) {
        io_atomic_abort(&af);
        candela_io::set_err(err, af.path, std::string("cannot write: ") + e.what());
    }
    return 1;
}

static int vdb_volume_grid_from_dense(const float *values, int nx, int ny, int nz, const float index_to_world[16],
                                         const char *name, IoVolumeGrid *out, char err[IO_ERR_LEN]) {
    std::memset(out, 0, sizeof *out);
    if (!dense_size_ok(nx, ny, nz)) {
        candela_io::set_err(err, name, "invalid dense grid size");
        return 1;
    }
    try {
        openvdb_init_once();
        openvdb::FloatGrid::Ptr grid = dense_grid(values, nx, ny, nz, index_to_world, name);
        std::string problem;
        if (!describe(*grid, out, &problem) || !to_nanovdb(*grid, out, &problem)) {
            candela_io::set_err(err, name, problem);
            std::memset(out, 0, sizeof *out);
            return 1;
        }
        set_name(out, name);
        return 0;
    } catch (const std::exception &e) {
        candela_io::set_err(err, name, std::string("cannot build the grid: ") + e.what());
    }
    io_volume_grid_free(out);
    return 1;
}

static int vdb_volume_grid_from_voxels(const int32_t *ijk, const float *values, size_t count, const int32_t *boxes,
                                          const float *box_values, size_t num_boxes, const float index_to_world[16],
                                          const char *name, IoVolumeGrid *out, char err[IO_ERR_LEN]) {
    std::memset(out, 0, sizeof *out);
    try {
        openvdb_init_once();
        openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(0.0f);
        grid->setName(name);
        grid->setGridClass(openvdb::GRID_FOG_VOLUME);
        openvdb::math::Mat4d m;
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j) m[i][j] = index_to_world[i * 4 + j];
        grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
        // boxes first (tiles wherever a box covers a whole node), then single voxels over them
        for (size_t b = 0; b < num_boxes; ++b) {
            const int32_t *x = boxes + 6 * b;
            grid->fill(openvdb::CoordBBox(openvdb::Coord(x[0], x[1], x[2]), openvdb::Coord(x[3], x[4], x[5])), box_values[b],
                       true);
        }
        auto acc = grid->getAccessor();
        for (size_t i = 0; i < count; ++i)
            acc.setValue(openvdb::Coord(ijk[3 * i], ijk[3 * i + 1], ijk[3 * i + 2]), values[i]);
        std::string problem;
        if (!describe(*grid, out, &problem) || !to_nanovdb(*grid, out, &problem)) {
            candela_io::set_err(err, name, problem);
            std::memset(out, 0, sizeof *out);
            return 1;
        }
        set_name(out, name);
        return 0;
    } catch (const std::exception &e) {
        candela_io::set_err(err, name, std::string("cannot build the grid: ") + e.what());
    }
    io_volume_grid_free(out);
    return 1;
}

extern "C" __attribute__((visibility("default"))) int candela_io_vdb_module(const IoModuleHost *host, void *table,
                                                                            size_t table_size) {
    if (!host || host->abi != IO_MODULE_ABI || !table || table_size != sizeof(IoVdbModule)) return 1;
    IoVdbModule *module = static_cast<IoVdbModule *>(table);
    io_module_set_host(host);
    module->abi = IO_MODULE_ABI;
    module->load_grid = vdb_load_vdb_grid;
    module->from_dense = vdb_volume_grid_from_dense;
    module->from_voxels = vdb_volume_grid_from_voxels;
    module->write_dense = vdb_write_vdb_dense;
    return 0;
}
