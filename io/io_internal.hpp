// io/io_internal.hpp: private C++ glue shared by the C++ files of io/ (io_util.cpp has the helpers).
// Not part of the public API (io.h); never included from C.
#ifndef CANDELA_IO_INTERNAL_HPP
#define CANDELA_IO_INTERNAL_HPP

#include "io.h"

#include <cstddef>
#include <string>

namespace candela_io {

// Largest texture / environment map accepted: per side and in total pixels.
constexpr int kMaxImageSide = 16384;
constexpr long long kMaxImagePixels = 1LL << 28;

// Decode an image with OpenImageIO (candela_io_image.so, loaded on first use: io_module.h) into an IoImage (see io.h): linear float RGBA, or with
// keep_8bit an 8-bit file's code values as RGBA8. Either from the file `path` (mem == nullptr)
// or from the encoded bytes mem[0..mem_size) (path is then only a name whose extension hints
// at the format). srgb: the file's RGB are sRGB-encoded (decoded to linear for integer
// sources held as float; recorded in IoImage.srgb for RGBA8). On failure returns false with a
// one-line description in `problem` (without any file-name prefix; the caller adds it). `out`
// is untouched on failure. max_bytes: refuse (from the header, before decoding) an image whose
// texels as held (io_image_bytes: 4 or 16 bytes each) would exceed it (0: no limit).
// When the module cannot be loaded, problem says so (naming the module file).
bool decode_image(const std::string &path, const void *mem, size_t mem_size, bool srgb, bool keep_8bit,
                  uint64_t max_bytes, IoImage *out, std::string *problem);

// Exact sRGB EOTF (IEC 61966-2-1), encoded [0,1] -> linear.
double srgb_to_linear(double c);

// Replace every run of CR/LF in s by "; " and trim trailing separators and spaces.
std::string one_line(const std::string &s);

// Write "prefix: problem" (one line, truncated) into err.
void set_err(char err[IO_ERR_LEN], const std::string &prefix, const std::string &problem);

}  // namespace candela_io

#endif
