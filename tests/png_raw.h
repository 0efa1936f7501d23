/* tests/png_raw.h: a PNG of any colour type and depth written by hand (stored deflate blocks,
 * no library), for the forms io_write_png (8-bit RGB) cannot make: grey, grey + alpha, RGBA,
 * palette, 16-bit. Shared by test_io and test_texture. */
#ifndef CANDELA_TEST_PNG_RAW_H
#define CANDELA_TEST_PNG_RAW_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* CRC-32 of PNG chunks, continuing from c (0 to start). */
static uint32_t png_crc(const unsigned char *p, size_t n, uint32_t c) {
    c = ~c;
    for (size_t i = 0; i < n; ++i) {
        c ^= p[i];
        for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
    }
    return ~c;
}

static void png_chunk(FILE *f, const char *type, const unsigned char *data, size_t n) {
    unsigned char head[8] = {(unsigned char)(n >> 24), (unsigned char)(n >> 16), (unsigned char)(n >> 8),
                             (unsigned char)n, (unsigned char)type[0], (unsigned char)type[1],
                             (unsigned char)type[2], (unsigned char)type[3]};
    fwrite(head, 1, 8, f);
    if (n) fwrite(data, 1, n, f);
    uint32_t c = png_crc(data, n, png_crc(head + 4, 4, 0));
    unsigned char tail[4] = {(unsigned char)(c >> 24), (unsigned char)(c >> 16), (unsigned char)(c >> 8),
                             (unsigned char)c};
    fwrite(tail, 1, 4, f);
}

/* color_type: 0 grey, 2 RGB, 3 palette, 4 grey + alpha, 6 RGBA; depth 8 or 16. raw: height rows
 * of width * channels samples, big-endian when 16-bit; palette (256 RGB entries) and trns (256
 * alphas) for colour type 3, else NULL. Exits the test when the file cannot be written. */
static void write_png_raw(const char *path, int width, int height, int color_type, int depth,
                          const unsigned char *raw, const unsigned char *palette, const unsigned char *trns) {
    static const int channels[7] = {1, 0, 3, 1, 2, 0, 4};
    const size_t row = (size_t)width * (size_t)channels[color_type] * (size_t)(depth / 8);
    const size_t n = (row + 1) * (size_t)height; /* each row behind filter byte 0 (none) */
    unsigned char *filtered = malloc(n);
    for (int y = 0; y < height; ++y) {
        filtered[(row + 1) * (size_t)y] = 0;
        memcpy(filtered + (row + 1) * (size_t)y + 1, raw + row * (size_t)y, row);
    }
    const size_t blocks = n / 65535 + 1;
    unsigned char *z = malloc(2 + n + 5 * blocks + 4);
    size_t o = 0;
    z[o++] = 0x78; /* zlib header: deflate, 32 KiB window, no dictionary */
    z[o++] = 0x01;
    uint32_t a = 1, b = 0;
    for (size_t at = 0; at < n;) {
        const size_t len = n - at < 65535 ? n - at : 65535;
        z[o++] = at + len == n ? 1 : 0; /* BFINAL, BTYPE 00 (stored) */
        z[o++] = (unsigned char)len;
        z[o++] = (unsigned char)(len >> 8);
        z[o++] = (unsigned char)~len;
        z[o++] = (unsigned char)(~len >> 8);
        memcpy(z + o, filtered + at, len);
        o += len;
        for (size_t i = at; i < at + len; ++i) {
            a = (a + filtered[i]) % 65521u;
            b = (b + a) % 65521u;
        }
        at += len;
    }
    const uint32_t adler = b << 16 | a;
    z[o++] = (unsigned char)(adler >> 24);
    z[o++] = (unsigned char)(adler >> 16);
    z[o++] = (unsigned char)(adler >> 8);
    z[o++] = (unsigned char)adler;
    FILE *f = fopen(path, "wb");
    if (!f) {
        fprintf(stderr, "cannot write %s\n", path);
        exit(1);
    }
    fwrite("\x89PNG\r\n\x1a\n", 1, 8, f);
    const unsigned char ihdr[13] = {(unsigned char)(width >> 24), (unsigned char)(width >> 16),
                                    (unsigned char)(width >> 8), (unsigned char)width,
                                    (unsigned char)(height >> 24), (unsigned char)(height >> 16),
                                    (unsigned char)(height >> 8), (unsigned char)height, (unsigned char)depth,
                                    (unsigned char)color_type, 0, 0, 0};
    png_chunk(f, "IHDR", ihdr, 13);
    if (palette) png_chunk(f, "PLTE", palette, 3 * 256);
    if (trns) png_chunk(f, "tRNS", trns, 256);
    png_chunk(f, "IDAT", z, o);
    png_chunk(f, "IEND", NULL, 0);
    fclose(f);
    free(z);
    free(filtered);
}

#endif
