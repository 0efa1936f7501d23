// io/image_oiio.cpp: thin extern "C" adapter over OpenImageIO (C++17).
// Decodes any image OIIO reads into linear float RGBA (or keeps an 8-bit file as 8-bit RGBA)
// and writes 8-bit PNGs atomically (temp name + rename). Also hosts the small helpers shared
// with gltf_loader.cpp.
#include "io.h"
#include "io_internal.hpp"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <sys/stat.h>
#include <vector>

namespace candela_io {

std::string one_line(const std::string &s) {
    std::string out;
    out.reserve(s.size());
    bool pending_sep = false;
    for (char c : s) {
        if (c == '\n' || c == '\r') {
            pending_sep = true;
            continue;
        }
        if (pending_sep && !out.empty()) out += "; ";
        pending_sep = false;
        out += (c == '\t') ? ' ' : c;
    }
    while (!out.empty() && (out.back() == ' ' || out.back() == ';')) out.pop_back();
    return out;
}

void set_err(char err[IO_ERR_LEN], const std::string &prefix, const std::string &problem) {
    if (!err) return;
    std::string msg = one_line(prefix + ": " + problem);
    std::snprintf(err, IO_ERR_LEN, "%s", msg.c_str());
}

// Exact sRGB EOTF (IEC 61966-2-1), encoded [0,1] -> linear.
static double srgb_to_linear(double c) {
    if (c <= 0.04045) return c / 12.92;
    return std::pow((c + 0.055) / 1.055, 2.4);
}

static bool is_integer_format(OIIO::TypeDesc t) {
    switch (t.basetype) {
    case OIIO::TypeDesc::UINT8: case OIIO::TypeDesc::INT8:
    case OIIO::TypeDesc::UINT16: case OIIO::TypeDesc::INT16:
    case OIIO::TypeDesc::UINT32: case OIIO::TypeDesc::INT32:
    case OIIO::TypeDesc::UINT64: case OIIO::TypeDesc::INT64:
        return true;
    default:
        return false;
    }
}

// A file-name extension OIIO can use to pick a reader for in-memory bytes.
static const char *sniff_extension(const unsigned char *p, size_t n) {
    if (n >= 8 && p[0] == 0x89 && p[1] == 'P' && p[2] == 'N' && p[3] == 'G') return "png";
    if (n >= 3 && p[0] == 0xFF && p[1] == 0xD8 && p[2] == 0xFF) return "jpg";
    if (n >= 4 && p[0] == 0x76 && p[1] == 0x2F && p[2] == 0x31 && p[3] == 0x01) return "exr";
    if (n >= 2 && p[0] == '#' && p[1] == '?') return "hdr";
    if (n >= 12 && std::memcmp(p, "RIFF", 4) == 0 && std::memcmp(p + 8, "WEBP", 4) == 0)
        return "webp";
    return "bin";
}

// Whether every channel of the file is 8-bit unsigned: such an image can be held as its own
// code values (IO_IMAGE_KEEP_8BIT) and lose nothing.
static bool is_8bit(const OIIO::ImageSpec &spec) {
    if (spec.format != OIIO::TypeDesc::UINT8) return false;
    for (const OIIO::TypeDesc &t : spec.channelformats)
        if (t != OIIO::TypeDesc::UINT8) return false;
    return true;
}

bool decode_image(const std::string &path, const void *mem, size_t mem_size, bool srgb, bool keep_8bit,
                  uint64_t max_bytes, IoImage *out, std::string *problem) {
    OIIO::ImageSpec config;
    // glTF (and PNG) alpha is straight; keep it so (OIIO premultiplies by default).
    config.attribute("oiio:UnassociatedAlpha", 1);

    std::unique_ptr<OIIO::Filesystem::IOMemReader> proxy;
    std::string name = path;
    if (mem) {
        if (mem_size == 0) {
            *problem = "image data is empty";
            return false;
        }
        proxy.reset(new OIIO::Filesystem::IOMemReader(mem, mem_size));
        name = std::string("embedded.") +
               sniff_extension(static_cast<const unsigned char *>(mem), mem_size);
        // OIIO 2.4's PNG reader ignores the ioproxy argument of ImageInput::open() and tries
        // the file name; the "oiio:ioproxy" configuration hint works for every reader.
        void *pp = proxy.get();
        config.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &pp);
    }
    // Only the reader the name implies: with OIIO's default, a file its reader rejects is
    // offered to every other format reader it has (ICO, IFF, PIC, RLA, DPX, ...), the least
    // tested code it ships, for files that are not images of the named kind anyway (fuzz_image
    // found a heap overflow somewhere behind io_load_image; its input was lost, see
    // tests/fuzz/README.md). A mislabelled file now gets "cannot open" instead.
    OIIO::attribute("try_all_readers", 0);
    auto in = OIIO::ImageInput::open(name, &config);
    if (!in) {
        std::string e = OIIO::geterror();
        *problem = "cannot open: " + (e.empty() ? std::string("unknown format") : e);
        return false;
    }
    const OIIO::ImageSpec spec = in->spec();
    const long long w = spec.width, h = spec.height;
    if (w <= 0 || h <= 0 || spec.depth > 1) {
        *problem = "invalid image size " + std::to_string(w) + "x" + std::to_string(h);
        return false;
    }
    if (w > kMaxImageSide || h > kMaxImageSide || w * h > kMaxImagePixels) {
        *problem = "image too large (" + std::to_string(w) + "x" + std::to_string(h) +
                   "; limit " + std::to_string(kMaxImageSide) + " per side, 2^28 pixels)";
        return false;
    }
    const bool as_8bit = keep_8bit && is_8bit(spec);
    const uint64_t texel_bytes = as_8bit ? 4u : 4u * sizeof(float);
    const uint64_t bytes = uint64_t(w) * uint64_t(h) * texel_bytes;
    if (max_bytes && bytes > max_bytes) {
        *problem = "image of " + std::to_string(w) + "x" + std::to_string(h) + " needs " +
                   std::to_string(bytes >> 20) + " MiB (" + (as_8bit ? "8-bit" : "float") +
                   " RGBA); the texture budget has " + std::to_string(max_bytes >> 20) +
                   " MiB left (--texture-budget-mb)";
        return false;
    }
    const int nc_file = spec.nchannels;
    if (nc_file <= 0) {
        *problem = "image has no channels";
        return false;
    }
    const int nc = nc_file < 4 ? nc_file : 4;
    const size_t npix = size_t(w) * size_t(h);

    // The file's first nc channels go straight into the RGBA buffer (no copy of the whole
    // image on the side: the peak is the image itself), then each texel is completed in place:
    // grey is copied to G and B, a missing alpha is opaque.
    void *buffer = std::malloc(npix * size_t(texel_bytes));
    if (!buffer) {
        *problem = "out of memory";
        return false;
    }
    const OIIO::TypeDesc want = as_8bit ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::FLOAT;
    const OIIO::stride_t xstride = OIIO::stride_t(texel_bytes), ystride = xstride * OIIO::stride_t(w);
    if (!in->read_image(0, 0, 0, nc, want, buffer, xstride, ystride)) {
        std::free(buffer);
        std::string e = in->geterror();
        *problem = "cannot decode: " + (e.empty() ? std::string("read failed") : e);
        return false;
    }
    in->close();
    auto complete = [&](auto *px, auto opaque) {
        for (size_t i = 0; i < npix; ++i) {
            auto *d = px + i * 4;
            switch (nc) {
            case 1: d[1] = d[2] = d[0]; d[3] = opaque; break;
            case 2: d[3] = d[1]; d[1] = d[2] = d[0]; break;
            case 3: d[3] = opaque; break;
            default: break;
            }
        }
    };

    out->width = int(w);
    out->height = int(h);
    if (as_8bit) {
        uint8_t *rgba8 = static_cast<uint8_t *>(buffer);
        complete(rgba8, uint8_t(255));
        // sRGB stays encoded: the lookup decodes each code value with io_texel8_tables()
        out->rgba8 = rgba8;
        out->srgb = srgb ? 1 : 0;
        return true;
    }
    float *rgba = static_cast<float *>(buffer);
    complete(rgba, 1.0f);
    if (srgb && is_integer_format(spec.format)) {
        // 8/16-bit sources decode to k/(2^n-1) exactly; a table per code value is exact (for
        // 8 bits the very table the 8-bit form is looked up with, so both forms agree).
        int bits = 0;
        if (spec.format.basetype == OIIO::TypeDesc::UINT8) bits = 8;
        if (spec.format.basetype == OIIO::TypeDesc::UINT16) bits = 16;
        if (bits) {
            const int maxv = (1 << bits) - 1;
            std::vector<float> lut16;
            const float *lut = io_texel8_tables()->srgb;
            if (bits == 16) {
                lut16.resize(size_t(maxv) + 1);
                for (int k = 0; k <= maxv; ++k) lut16[size_t(k)] = float(srgb_to_linear(double(k) / maxv));
                lut = lut16.data();
            }
            for (size_t i = 0; i < npix; ++i)
                for (int c = 0; c < 3; ++c) {
                    float v = rgba[i * 4 + size_t(c)];
                    long k = std::lround(double(v) * maxv);
                    if (k < 0) k = 0;
                    if (k > maxv) k = maxv;
                    rgba[i * 4 + size_t(c)] = lut[size_t(k)];
                }
        } else {
            for (size_t i = 0; i < npix; ++i)
                for (int c = 0; c < 3; ++c) {
                    float &v = rgba[i * 4 + size_t(c)];
                    v = float(v <= 0.0f ? 0.0 : srgb_to_linear(double(v)));
                }
        }
    }
    out->rgba = rgba;
    return true;
}

}  // namespace candela_io

using candela_io::set_err;

extern "C" const IoTexel8Tables *io_texel8_tables(void) {
    // linear: OpenImageIO's own uint8 -> float conversion, the one read_image applies when a
    // float decode of an 8-bit file is asked for; srgb: the table the float decode of an sRGB
    // 8-bit file uses. (A function-local static: built once, thread-safe.)
    static const IoTexel8Tables tables = [] {
        IoTexel8Tables t{};
        unsigned char codes[256];
        for (int k = 0; k < 256; ++k) codes[k] = (unsigned char)k;
        if (!OIIO::convert_pixel_values(OIIO::TypeDesc::UINT8, codes, OIIO::TypeDesc::FLOAT, t.linear, 256))
            for (int k = 0; k < 256; ++k) t.linear[k] = float(k) * (1.0f / 255.0f); // OIIO's formula
        for (int k = 0; k < 256; ++k) t.srgb[k] = float(candela_io::srgb_to_linear(double(k) / 255.0));
        return t;
    }();
    return &tables;
}

extern "C" uint64_t io_image_bytes(const IoImage *image) {
    if (!image || image->width <= 0 || image->height <= 0) return 0;
    const uint64_t texels = uint64_t(image->width) * uint64_t(image->height);
    if (image->rgba8) return texels * 4u;
    return image->rgba ? texels * 4u * sizeof(float) : 0;
}

extern "C" int io_load_image(const char *path, int flags, IoImage *image, char err[IO_ERR_LEN]) {
    if (err) err[0] = 0;
    if (!image) {
        set_err(err, path ? path : "(null)", "no output image");
        return 1;
    }
    std::memset(image, 0, sizeof *image);
    if (!path || !*path) {
        set_err(err, "(null)", "no path given");
        return 1;
    }
    // a FIFO or a device (/dev/zero) would block or never end: only regular files are read
    struct stat st;
    if (::stat(path, &st) != 0) {
        set_err(err, path, "cannot open: no such file");
        return 1;
    }
    if (!S_ISREG(st.st_mode)) {
        set_err(err, path, "not a regular file");
        return 1;
    }
    try {
        std::string problem;
        if (!candela_io::decode_image(path, nullptr, 0, (flags & IO_IMAGE_SRGB) != 0,
                                      (flags & IO_IMAGE_KEEP_8BIT) != 0, 0, image, &problem)) {
            set_err(err, path, problem);
            return 1;
        }
        return 0;
    } catch (const std::exception &e) {
        io_image_free(image);
        set_err(err, path, std::string("cannot load: ") + e.what());
        return 1;
    } catch (...) {
        io_image_free(image);
        set_err(err, path, "cannot load: unknown exception");
        return 1;
    }
}

extern "C" void io_image_free(IoImage *image) {
    if (!image) return;
    std::free(image->rgba);
    std::free(image->rgba8);
    std::memset(image, 0, sizeof *image);
}

extern "C" int io_write_png(const char *path_arg, int width, int height, const float *rgb,
                            char err[IO_ERR_LEN]) {
    if (err) err[0] = 0;
    if (!path_arg || !*path_arg) {
        set_err(err, "(null)", "no path given");
        return 1;
    }
    char path[IO_PATH_MAX];
    if (io_output_path(path_arg, path, err) != 0) return 1;
    if (width <= 0 || height <= 0 || !rgb || (long long)width * height > (1LL << 31) / 3) {
        set_err(err, path, "invalid image size or no pixels");
        return 1;
    }
    std::string tmp = std::string(path) + ".tmp-" + std::to_string((long)getpid());
    io_temp_begin(tmp.c_str());
    struct TempEnd {
        ~TempEnd() { io_temp_end(); }
    } temp_end;
    try {
        const size_t n = size_t(width) * size_t(height) * 3;
        std::vector<unsigned char> px(n);
        for (size_t i = 0; i < n; ++i) {
            float v = rgb[i];
            if (!(v > 0.0f)) v = 0.0f;  // also maps NaN to 0
            if (v > 1.0f) v = 1.0f;
            px[i] = (unsigned char)(v * 255.0f + 0.5f);
        }
        // Encoded in memory, then written with every write, flush, sync and close checked:
        // OpenImageIO's PNG writer reported success on a full disk and a truncated file was
        // renamed into place (issue 13 item 10).
        auto out = OIIO::ImageOutput::create("png");
        if (!out) {
            set_err(err, path, "cannot open: " + OIIO::geterror());
            return 1;
        }
        std::vector<unsigned char> bytes;
        OIIO::Filesystem::IOVecOutput vec(bytes);
        void *proxy = &vec;
        OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::UINT8);
        spec.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxy);
        bool ok = out->open("memory.png", spec) && out->write_image(OIIO::TypeDesc::UINT8, px.data());
        std::string e = ok ? std::string() : out->geterror();
        if (!out->close() && ok) {
            ok = false;
            e = out->geterror();
        }
        out.reset();
        if (!ok || bytes.empty()) {
            set_err(err, path, "cannot encode: " + (e.empty() ? std::string("no data") : e));
            return 1;
        }
        FILE *f = std::fopen(tmp.c_str(), "wb");
        if (!f) {
            set_err(err, path, std::string("cannot open for writing: ") + std::strerror(errno));
            return 1;
        }
        bool written = std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size() && std::fflush(f) == 0 &&
                       ::fsync(fileno(f)) == 0;
        int saved = errno;
        if (std::fclose(f) != 0 && written) {
            written = false;
            saved = errno;
        }
        if (!written) {
            std::remove(tmp.c_str());
            set_err(err, path, std::string("cannot write: ") + std::strerror(saved));
            return 1;
        }
        if (std::rename(tmp.c_str(), path) != 0) {
            std::string e2 = std::strerror(errno);
            std::remove(tmp.c_str());
            set_err(err, path, "cannot rename " + tmp + ": " + e2);
            return 1;
        }
        return 0;
    } catch (const std::exception &ex) {
        std::remove(tmp.c_str());
        set_err(err, path, std::string("cannot write: ") + ex.what());
        return 1;
    } catch (...) {
        std::remove(tmp.c_str());
        set_err(err, path, "cannot write: unknown exception");
        return 1;
    }
}
