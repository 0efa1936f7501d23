/* tests/fuzz/fuzz_common.h: the libFuzzer harnesses' shared part. The io/ readers take paths
 * (as the renderer uses them), so each input is written to a file in a private temporary
 * folder under the name the reader expects, read, and freed; any crash, leak, hang or
 * undefined behaviour the sanitizers see is a finding. */
#ifndef CANDELA_FUZZ_COMMON_H
#define CANDELA_FUZZ_COMMON_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Writes data to DIR/name (DIR made once per process); returns the path (static storage). */
static const char *fuzz_write_input(const char *name, const uint8_t *data, size_t size) {
    static char dir[64], path[128];
    if (!dir[0]) {
        snprintf(dir, sizeof dir, "/tmp/candela-fuzz-XXXXXX");
        if (!mkdtemp(dir)) abort();
    }
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = fopen(path, "wb");
    if (!f) abort();
    if (size && fwrite(data, 1, size, f) != size) abort();
    if (fclose(f) != 0) abort();
    return path;
}

#endif
