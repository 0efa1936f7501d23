/* io/png.c: 8-bit sRGB PNGs through libpng (io_write_png), encoded in memory, then written
 * atomically (io_atomic_write: temp name, sync, rename) with every write, flush, sync and close checked: an image
 * library's writer once reported success on a full disk and a truncated file was renamed into
 * place (issue 13 item 10). The chunks are the ones OpenImageIO wrote before (IHDR, oFFs 0 0,
 * IDAT, IEND), so a plain render needs no image library beyond libpng; provenance attributes
 * (issue 27) go into text chunks (tEXt, zTXt, iTXt) before IDAT. */
#include "io.h"
#include "io_err.h"

#include <png.h>

#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct PngBuffer {
    unsigned char *data;
    size_t size, cap;
    int out_of_memory;
} PngBuffer;

static void png_buffer_write(png_structp png, png_bytep bytes, png_size_t n) {
    PngBuffer *b = (PngBuffer *)png_get_io_ptr(png);
    if (b->size + n > b->cap) {
        size_t cap = b->cap ? b->cap : 4096;
        while (cap < b->size + n) cap *= 2;
        unsigned char *d = realloc(b->data, cap);
        if (!d) {
            b->out_of_memory = 1;
            png_error(png, "out of memory");
        }
        b->data = d;
        b->cap = cap;
    }
    memcpy(b->data + b->size, bytes, n);
    b->size += n;
}

static void png_buffer_flush(png_structp png) { (void)png; }

/* The message of the last libpng error (one per encode, which runs on one thread). */
static _Thread_local char png_problem[256];
static void png_on_error(png_structp png, png_const_charp msg) {
    io_fmt(png_problem, sizeof png_problem, "%s", msg);
    png_longjmp(png, 1);
}
static void png_on_warning(png_structp png, png_const_charp msg) { (void)png; (void)msg; }

/* The PNG keyword of an attribute name: the registered keywords for OpenEXR's names. */
static const char *png_keyword(const char *name) {
    if (strcmp(name, "software") == 0) return "Software";
    if (strcmp(name, "capDate") == 0) return "Creation Time";
    return name;
}

/* 0 when key is a PNG keyword: 1-79 printable Latin-1 characters, no leading, trailing or
 * consecutive spaces (PNG specification 11.3.4.2) */
static int png_keyword_ok(const char *key) {
    size_t n = strlen(key);
    if (n < 1 || n > 79 || key[0] == ' ' || key[n - 1] == ' ') return -1;
    for (size_t i = 0; i < n; ++i) {
        unsigned char c = (unsigned char)key[i];
        if (!((c >= 32 && c <= 126) || c >= 161)) return -1;
        if (c == ' ' && key[i + 1] == ' ') return -1;
    }
    return 0;
}

/* The text chunk of one value: tEXt for short ASCII, zTXt for long ASCII, iTXt (compressed
 * when long) for anything else (UTF-8; tEXt is Latin-1 only). */
static int png_text_compression(const char *value) {
    int ascii = 1;
    size_t n = 0;
    for (const unsigned char *c = (const unsigned char *)value; *c; ++c, ++n)
        if (*c >= 0x80) ascii = 0;
    if (ascii) return n > 1024 ? PNG_TEXT_COMPRESSION_zTXt : PNG_TEXT_COMPRESSION_NONE;
    return n > 1024 ? PNG_ITXT_COMPRESSION_zTXt : PNG_ITXT_COMPRESSION_NONE;
}

/* PNG bytes of 8-bit RGB rows px (3 bytes a pixel, top row first), with the text chunks
 * (num_text of them) into *out; 0 ok. */
static int encode_png(const unsigned char *px, int width, int height, png_textp text, int num_text, PngBuffer *out,
                      char problem[256]) {
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, png_on_error, png_on_warning);
    if (!png) {
        io_fmt(problem, 256, "cannot create the PNG encoder");
        return 1;
    }
    png_infop info = png_create_info_struct(png);
    png_bytep *volatile rows = NULL;
    if (!info || setjmp(png_jmpbuf(png))) {
        io_fmt(problem, 256, "%s", info ? png_problem : "cannot create the PNG encoder");
        free((void *)rows);
        png_destroy_write_struct(&png, info ? &info : NULL);
        return 1;
    }
    rows = malloc(sizeof(png_bytep) * (size_t)height);
    if (!rows) png_error(png, "out of memory");
    for (int y = 0; y < height; ++y) rows[y] = (png_bytep)(px + (size_t)y * (size_t)width * 3);
    png_set_write_fn(png, out, png_buffer_write, png_buffer_flush);
    png_set_IHDR(png, info, (png_uint_32)width, (png_uint_32)height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_set_oFFs(png, info, 0, 0, PNG_OFFSET_PIXEL);
    if (num_text > 0) png_set_text(png, info, text, num_text);
    png_set_compression_level(png, 6);
    png_write_info(png, info);
    png_write_image(png, rows);
    png_write_end(png, info);
    free((void *)rows);
    png_destroy_write_struct(&png, &info);
    return 0;
}

int io_write_png(const char *path_arg, int width, int height, const float *rgb, const IoExrAttribute *attributes,
                 int num_attributes, char err[IO_ERR_LEN]) {
    if (err) err[0] = 0;
    if (!path_arg || !*path_arg) {
        io_err(err, "(null)", "no path given");
        return 1;
    }
    const char *path = path_arg;
    if (width <= 0 || height <= 0 || !rgb || (long long)width * height > (1LL << 31) / 3) {
        io_err(err, path, "invalid image size or no pixels");
        return 1;
    }
    if (num_attributes < 0 || (num_attributes > 0 && !attributes)) {
        io_err(err, path, "invalid attribute list");
        return 1;
    }
    png_textp text = NULL;
    if (num_attributes > 0) {
        text = calloc((size_t)num_attributes, sizeof *text);
        if (!text) {
            io_err(err, path, "cannot write: out of memory");
            return 1;
        }
    }
    for (int k = 0; k < num_attributes; ++k) {
        char msg[IO_ERR_LEN];
        const char *name = attributes[k].name ? attributes[k].name : "";
        const char *key = png_keyword(name);
        int bad = 0;
        if (png_keyword_ok(key) != 0) {
            io_fmt(msg, sizeof msg, "attribute \"%.100s\": not a PNG keyword (1-79 Latin-1 characters)", name);
            bad = 1;
        } else if (!attributes[k].value) {
            io_fmt(msg, sizeof msg, "attribute \"%.100s\" has no value", name);
            bad = 1;
        }
        for (int j = 0; j < k && !bad; ++j)
            if (strcmp(text[j].key, key) == 0) {
                io_fmt(msg, sizeof msg, "attribute \"%.100s\" given twice", key);
                bad = 1;
            }
        if (bad) {
            io_err(err, path, "%s", msg);
            free(text);
            return 1;
        }
        text[k].compression = png_text_compression(attributes[k].value);
        text[k].key = (png_charp)key;
        text[k].text = (png_charp)attributes[k].value;
        text[k].text_length = strlen(attributes[k].value);
    }
    const size_t n = (size_t)width * (size_t)height * 3;
    unsigned char *px = malloc(n);
    if (!px) {
        io_err(err, path, "cannot write: out of memory");
        free(text);
        return 1;
    }
    for (size_t i = 0; i < n; ++i) {
        float v = rgb[i];
        if (!(v > 0.0f)) v = 0.0f; /* also maps NaN to 0 */
        if (v > 1.0f) v = 1.0f;
        px[i] = (unsigned char)(v * 255.0f + 0.5f);
    }
    PngBuffer bytes = {0};
    char problem[256];
    int rc = encode_png(px, width, height, text, num_attributes, &bytes, problem);
    free(px);
    free(text);
    if (rc != 0 || bytes.size == 0) {
        io_err(err, path, "cannot encode: %s", rc ? problem : "no data");
        free(bytes.data);
        return 1;
    }

    /* the one atomic writer (io.h): PATH.tmp-PID, every write, flush and sync checked, renamed */
    rc = io_atomic_write(path_arg, bytes.data, bytes.size, err);
    free(bytes.data);
    return rc;
}
