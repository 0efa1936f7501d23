// io/io_util.cpp: the small helpers every C++ file of io/ shares (one-line messages) and the
// image functions that need no image library (the 8-bit tables, sizes, freeing). Linked into
// the program and into each module (io_module.h), where -fvisibility=hidden keeps the copy
// private to the module.
#include "io.h"
#include "io_internal.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

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

double srgb_to_linear(double c) {
    if (c <= 0.04045) return c / 12.92;
    return std::pow((c + 0.055) / 1.055, 2.4);
}

}  // namespace candela_io

extern "C" const IoTexel8Tables *io_texel8_tables(void) {
    // linear: OpenImageIO's own uint8 -> float conversion (convert_pixel_values, the one
    // read_image applies when a float decode of an 8-bit file is asked for: k * (1/255) in
    // single precision, checked equal for all 256 codes); srgb: the table the float decode of
    // an sRGB 8-bit file uses. (A function-local static: built once, thread-safe.)
    static const IoTexel8Tables tables = [] {
        IoTexel8Tables t{};
        for (int k = 0; k < 256; ++k) t.linear[k] = float(k) * (1.0f / 255.0f);
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

extern "C" void io_image_free(IoImage *image) {
    if (!image) return;
    std::free(image->rgba);
    std::free(image->rgba8);
    std::memset(image, 0, sizeof *image);
}

extern "C" void io_volume_grid_free(IoVolumeGrid *grid) {
    std::free(grid->buffer);
    std::memset(grid, 0, sizeof *grid);
}
