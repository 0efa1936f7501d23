// io/image_module.cpp: candela_io_image.so (io_module.h), the thin adapter over OpenImageIO
// (C++17): decodes any image OIIO reads into linear float RGBA, or keeps an 8-bit file as
// 8-bit RGBA. Loaded on first use; the program itself never links OpenImageIO.
#include "io.h"
#include "io_internal.hpp"
#include "io_module.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <fcntl.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <vector>

namespace candela_io {

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

// A JPEG's bytes without its APP13 segments (Photoshop IRB / IPTC-IIM metadata, which no texture
// needs): OpenImageIO 2.4 (Debian 12) parses IPTC records past their segment's end (a heap
// overflow in decode_iptc_iim that fuzz_image found; fixed upstream in OIIO 3.x, PR #5081). The
// marker segments are walked as libjpeg reads them up to the first scan (bytes between segments
// skipped, as libjpeg does); false when a segment's length runs past the end or is below 2
// (libjpeg would fail there too), so no APP13 can reach OIIO unseen.
static bool jpeg_without_app13(const unsigned char *p, size_t n, std::vector<unsigned char> *out) {
    out->clear();
    out->reserve(n);
    out->insert(out->end(), p, p + 2); // SOI (FF D8)
    size_t i = 2;
    for (;;) {
        while (i < n && p[i] != 0xFF) ++i;       // garbage before a marker
        while (i + 1 < n && p[i + 1] == 0xFF) ++i; // fill bytes
        if (i + 1 >= n) return false;              // no scan
        unsigned char m = p[i + 1];
        if (m == 0xDA || m == 0xD9) break; // start of scan, end of image: the rest as is
        if (m == 0x00 || m == 0x01 || (m >= 0xD0 && m <= 0xD7)) { // no length
            out->insert(out->end(), p + i, p + i + 2);
            i += 2;
            continue;
        }
        if (i + 4 > n) return false;
        size_t len = (size_t)p[i + 2] << 8 | p[i + 3];
        if (len < 2 || i + 2 + len > n) return false;
        if (m != 0xED) out->insert(out->end(), p + i, p + i + 2 + len);
        i += 2 + len;
    }
    out->insert(out->end(), p + i, p + n);
    return true;
}

static bool is_jpeg(const unsigned char *p, size_t n) { return n >= 3 && p[0] == 0xFF && p[1] == 0xD8 && p[2] == 0xFF; }
static bool is_png(const unsigned char *p, size_t n) { return n >= 8 && std::memcmp(p, "\x89PNG\r\n\x1a\n", 8) == 0; }

// A PNG whose chunks do not fit in its bytes is refused before libpng sees it: libpng allocates a
// chunk's declared length (up to 2^31 - 1) before reading it, so a 280-byte file whose tEXt chunk
// declared 2 GB took 2 GB and 4 s (fuzz_image). The chunk headers are walked up to IEND
// (read_at(offset, buffer, 8) reads one); a file that ends at a chunk boundary is left to libpng.
template <class ReadAt> static bool png_chunks_fit(ReadAt read_at, uint64_t size, std::string *problem) {
    uint64_t at = 8;
    unsigned char h[8];
    while (at + 8 <= size) {
        if (!read_at(at, h)) {
            *problem = std::string("cannot read: ") + std::strerror(errno);
            return false;
        }
        uint64_t len = (uint64_t)h[0] << 24 | (uint64_t)h[1] << 16 | (uint64_t)h[2] << 8 | h[3];
        if (len > 0x7FFFFFFFu || at + 12 + len > size) {
            char type[5] = {0, 0, 0, 0, 0};
            for (int k = 0; k < 4; ++k) type[k] = std::isalpha(h[4 + k]) ? char(h[4 + k]) : '?';
            *problem = "cannot open: malformed PNG (its chunk '" + std::string(type) + "' declares " + std::to_string(len) +
                       " bytes, past the end of the file)";
            return false;
        }
        if (std::memcmp(h + 4, "IEND", 4) == 0) return true;
        at += 12 + len;
    }
    return true;
}

static bool decode_oiio(const std::string &path, const void *mem, size_t mem_size, bool srgb, bool keep_8bit,
                  uint64_t max_bytes, IoImage *out, std::string *problem) {
    OIIO::ImageSpec config;
    // glTF (and PNG) alpha is straight; keep it so (OIIO premultiplies by default).
    config.attribute("oiio:UnassociatedAlpha", 1);

    // A file is opened once, through the program's input door (io_open_input: a regular file
    // after symbolic links, never a FIFO's blocking open or a device's endless bytes, at most
    // IO_MAX_IMAGE_BYTES from its size before a byte is read), and OpenImageIO reads that very
    // descriptor through an IOProxy: no second open by name that a file swapped in between (a
    // FIFO) could block. Declared before `in`, so the reader is gone before the file closes.
    struct FileCloser {
        FILE *f = nullptr;
        ~FileCloser() { if (f) std::fclose(f); }
    } file;
    std::unique_ptr<OIIO::Filesystem::IOProxy> file_proxy;
    std::unique_ptr<OIIO::Filesystem::IOMemReader> proxy;
    std::string name = path;
    std::vector<unsigned char> jpeg; // a JPEG's bytes without APP13 (jpeg_without_app13)
    if (!mem) {
        int fd = -1;
        uint64_t file_size = 0;
        char ioerr[IO_ERR_LEN];
        if (io_open_input(path.c_str(), IO_MAX_IMAGE_BYTES, "an image file", &fd, &file_size, ioerr) != 0) {
            const std::string m(ioerr); // without the path, which the caller puts first
            *problem = m.compare(0, path.size() + 2, path + ": ") == 0 ? m.substr(path.size() + 2) : m;
            return false;
        }
        file.f = fdopen(fd, "rb");
        if (!file.f) {
            close(fd);
            *problem = std::string("cannot read: ") + std::strerror(errno);
            return false;
        }
        // a JPEG file is read here (its size, checked above, bounds the read) and decoded from
        // memory without its APP13 segments; a PNG's chunks are checked against its size
        unsigned char head[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        size_t head_n = file_size >= 8 ? 8 : size_t(file_size);
        if (head_n > 0 && pread(fd, head, head_n, 0) != ssize_t(head_n)) head_n = 0;
        if (is_png(head, head_n) &&
            !png_chunks_fit([fd](uint64_t at, unsigned char *h) { return pread(fd, h, 8, off_t(at)) == 8; }, file_size,
                            problem))
            return false;
        if (is_jpeg(head, head_n)) {
            std::vector<unsigned char> bytes(static_cast<size_t>(file_size));
            size_t got = 0;
            while (got < bytes.size()) {
                ssize_t r = pread(fd, bytes.data() + got, bytes.size() - got, off_t(got));
                if (r < 0 && errno == EINTR) continue;
                if (r <= 0) break;
                got += size_t(r);
            }
            bytes.resize(got);
            if (!jpeg_without_app13(bytes.data(), bytes.size(), &jpeg)) {
                *problem = "cannot open: malformed JPEG (its marker segments run past the end of the file)";
                return false;
            }
        } else {
            file_proxy.reset(new OIIO::Filesystem::IOFile(file.f, OIIO::Filesystem::IOProxy::Read));
        }
    } else if (is_png(static_cast<const unsigned char *>(mem), mem_size)) {
        const unsigned char *bytes = static_cast<const unsigned char *>(mem);
        if (!png_chunks_fit([bytes](uint64_t at, unsigned char *h) { std::memcpy(h, bytes + at, 8); return true; }, mem_size,
                            problem))
            return false;
    } else if (is_jpeg(static_cast<const unsigned char *>(mem), mem_size)) {
        if (!jpeg_without_app13(static_cast<const unsigned char *>(mem), mem_size, &jpeg)) {
            *problem = "cannot open: malformed JPEG (its marker segments run past the end of the data)";
            return false;
        }
    }
    if (!jpeg.empty()) {
        mem = jpeg.data();
        mem_size = jpeg.size();
    }
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
    // The reader is made from the format name alone (the extension): given a file name,
    // ImageInput::create (and so ImageInput::open) first opens that name to ask the reader's
    // valid_file, outside the descriptor opened above. A reader without IOProxy support (ICO,
    // SGI, RLA, FITS, Cineon, ...) opens by name: it is given the opened descriptor's own name
    // (/proc/self/fd/N, the same inode whatever the path names by then).
    // (lower case: create() looks the format up in lower case but compares it with the name
    // as given, and would take "PNG" for a file name)
    std::string format = OIIO::Filesystem::extension(name, false);
    for (char &ch : format) ch = char(std::tolower((unsigned char)ch));
    auto in = OIIO::ImageInput::create(format.empty() ? name : format, false, &config);
    if (!in) {
        std::string e = OIIO::geterror();
        *problem = "cannot open: " + (e.empty() ? std::string("unknown format") : e);
        return false;
    }
    // Every JPEG goes through jpeg_without_app13 (above): one whose bytes do not start as a JPEG
    // does (FF D8 FF) but that the JPEG reader would take anyway (chosen by its extension) is
    // refused, or its APP13 would reach OpenImageIO 2.4's decode_iptc_iim unseen (fuzz_image: a
    // JPEG behind one stray byte).
    if (jpeg.empty() && std::strcmp(in->format_name(), "jpeg") == 0) {
        *problem = "cannot open: not a JPEG file (it does not start with the JPEG marker FF D8 FF)";
        return false;
    }
    std::string open_name = name;
    if (file_proxy) {
        if (in->supports("ioproxy")) {
            void *pp = file_proxy.get();
            config.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &pp);
        } else {
            open_name = "/proc/self/fd/" + std::to_string(fileno(file.f));
        }
    }
    OIIO::ImageSpec opened;
    if (!in->open(open_name, opened, config)) {
        std::string e = in->geterror();
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

// decode_oiio with a C signature; no exception leaves the module
static int decode_entry(const char *path, const void *mem, size_t mem_size, int srgb, int keep_8bit,
                        uint64_t max_bytes, IoImage *out, char problem[IO_ERR_LEN]) {
    problem[0] = 0;
    IoImage img{};
    std::string why;
    bool ok = false;
    try {
        ok = decode_oiio(path, mem, mem_size, srgb != 0, keep_8bit != 0, max_bytes, &img, &why);
    } catch (const std::exception &e) {
        io_image_free(&img);
        why = std::string("cannot load: ") + e.what();
    } catch (...) {
        io_image_free(&img);
        why = "cannot load: unknown exception";
    }
    if (!ok) {
        std::snprintf(problem, IO_ERR_LEN, "%s", one_line(why).c_str());
        return 1;
    }
    *out = img;
    return 0;
}

}  // namespace candela_io

extern "C" __attribute__((visibility("default"))) int candela_io_image_module(const IoModuleHost *host, void *table,
                                                                              size_t table_size) {
    if (!host || host->abi != IO_MODULE_ABI || !table || table_size != sizeof(IoImageModule)) return 1;
    IoImageModule *module = static_cast<IoImageModule *>(table);
    io_module_set_host(host);
    module->abi = IO_MODULE_ABI;
    module->decode = candela_io::decode_entry;
    return 0;
}
