/* tests/fuzz/fuzz_image.c: libFuzzer over the image reader of textures and environments
 * (io_load_image, OpenImageIO): the first byte picks the file name's extension and the flags
 * (bit 7 sRGB, bit 6 keep 8-bit files as 8-bit, the glTF textures' form), the rest is the file
 * (OIIO picks its reader from the name, then from the content). */
#include "fuzz_common.h"
#include "io.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static const char *const names[] = {"in.png", "in.jpg", "in.exr", "in.hdr", "in.tga", "in.bmp"};
    if (size < 1) return 0;
    const char *path = fuzz_write_input(names[data[0] % 6], data + 1, size - 1);
    IoImage image;
    char err[IO_ERR_LEN];
    const int flags = (data[0] & 0x80 ? IO_IMAGE_SRGB : 0) | (data[0] & 0x40 ? IO_IMAGE_KEEP_8BIT : 0);
    if (io_load_image(path, flags, &image, err) == 0) io_image_free(&image);
    return 0;
}
