/* tests/fuzz/fuzz_variants.c: libFuzzer over `candela compare --variants FILE` (io_read_variants:
 * TOML through toml++, JSON through nlohmann/json, then the key checks): the first byte picks
 * the extension (even: .toml, odd: .json), the rest is the file. */
#include "fuzz_common.h"
#include "io.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size < 1) return 0;
    const char *path = fuzz_write_input(data[0] & 1 ? "in.json" : "in.toml", data + 1, size - 1);
    IoVariant *variants = NULL;
    int count = 0;
    char err[IO_ERR_LEN];
    if (io_read_variants(path, &variants, &count, err) == 0) io_variants_free(variants, count);
    return 0;
}
