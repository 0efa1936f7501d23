// io/image.cpp: image reading as the program sees it (io_load_image, decode_image); the
// decoding itself is OpenImageIO's, in candela_io_image.so, loaded on first use (io_module.h).
#include "io.h"
#include "io_internal.hpp"
#include "io_module.h"

#include <sys/stat.h>

#include <cstring>
#include <string>

namespace {
const char *const kNeeded = "OpenImageIO, needed to read images";
}

namespace candela_io {

bool decode_image(const std::string &path, const void *mem, size_t mem_size, bool srgb, bool keep_8bit,
                  uint64_t max_bytes, IoImage *out, std::string *problem) {
    char err[IO_ERR_LEN];
    const IoImageModule *m = io_image_module("", kNeeded, err);
    if (!m) {
        *problem = err + 2;  // without the empty prefix's ": "
        return false;
    }
    if (m->decode(path.c_str(), mem, mem_size, srgb, keep_8bit, max_bytes, out, err) != 0) {
        *problem = err;
        return false;
    }
    return true;
}

}  // namespace candela_io

using candela_io::set_err;

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
    const IoImageModule *m = io_image_module(path, kNeeded, err);
    if (!m) return 1;
    char problem[IO_ERR_LEN];
    if (m->decode(path, nullptr, 0, (flags & IO_IMAGE_SRGB) != 0, (flags & IO_IMAGE_KEEP_8BIT) != 0, 0, image,
                  problem) != 0) {
        set_err(err, path, problem);
        return 1;
    }
    return 0;
}
