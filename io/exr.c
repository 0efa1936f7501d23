/* io/exr.c: multi-channel EXR writer and single-channel reader over the OpenEXR 3.1 C API
 * (OpenEXRCore). Plain C17.
 *
 * Writer: one scanline part, FLOAT channels, ZIP compression, channels in the alphabetical
 * order EXR requires, written through the atomic writer (io_atomic_begin: PATH.tmp-PID, synced,
 * renamed).
 * Reader: any scanline file; the requested channel (HALF, FLOAT or UINT) is returned as float. */
#include "io.h"
#include "io_err.h"

#include <openexr.h>
#include <Imath/half.h> /* imath_half_to_float: HALF channels as float */

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* The OpenEXR error callback has no user pointer usable with the default file streams, so the
 * most recent library message is kept per thread. */
static _Thread_local char exr_last_msg[256];

static void exr_capture_error(exr_const_context_t ctxt, exr_result_t code, const char *msg) {
    (void)ctxt;
    snprintf(exr_last_msg, sizeof exr_last_msg, "%s",
             msg ? msg : exr_get_default_error_message(code));
}

/* Library message for rv: the captured one if any, else the default text. */
static const char *exr_msg(exr_result_t rv) {
    if (exr_last_msg[0]) return exr_last_msg;
    return exr_get_default_error_message(rv);
}

static exr_context_initializer_t exr_init(void) {
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;
    return init;
}

/* ---------------------------------------------------------------------------------------- */
/* Writer */

typedef struct SortedChannel {
    const char *name;
    const float *data;
} SortedChannel;

static int cmp_channel(const void *a, const void *b) {
    return strcmp(((const SortedChannel *)a)->name, ((const SortedChannel *)b)->name);
}

/* OpenEXR 3.1.5 (Debian 12) stores a ZIP chunk whose compressed size equals its raw size as
 * compressed data, while every reader takes a chunk of exactly the raw size to be stored raw
 * (upstream issue #2306, fixed in 3.2 by storing such a chunk raw): a 2x2 image of 0, 0, 0, 25
 * read back as garbage. The library's compressor runs first; in that one case the chunk's
 * bytes become the raw ones, which is what the readers expect. */
static exr_result_t compress_unambiguous(exr_encode_pipeline_t *enc) {
    exr_result_t (*const *library_compress)(exr_encode_pipeline_t *) = enc->encoding_user_data;
    exr_result_t rv = (*library_compress)(enc);
    if (rv == EXR_ERR_SUCCESS && enc->compressed_buffer && enc->packed_buffer &&
        enc->compressed_buffer != enc->packed_buffer && enc->compressed_bytes == enc->packed_bytes)
        memcpy(enc->compressed_buffer, enc->packed_buffer, enc->packed_bytes);
    return rv;
}

/* The library's writes, to the atomic file's descriptor (the bytes and offsets its own file
 * writer would use); the first failure's errno is kept in af->error. */
static int64_t exr_output_write(exr_const_context_t ctxt, void *user, const void *buffer, uint64_t sz, uint64_t offset,
                                exr_stream_error_func_ptr_t error_cb) {
    IoAtomicFile *af = user;
    uint64_t done = 0;
    while (done < sz) {
        ssize_t w = pwrite(af->fd, (const char *)buffer + done, (size_t)(sz - done), (off_t)(offset + done));
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            int e = w < 0 ? errno : EIO;
            if (!af->error) af->error = e;
            error_cb(ctxt, EXR_ERR_WRITE_IO, "write error: %s", strerror(e));
            return -1;
        }
        done += (uint64_t)w;
    }
    return (int64_t)done;
}

int io_write_exr(const char *path_arg, int width, int height, const IoExrChannel *channels,
                 int num_channels, const IoExrAttribute *attributes, int num_attributes,
                 char err[IO_ERR_LEN]) {
    if (err) err[0] = 0;
    if (!path_arg || !*path_arg) {
        io_err(err, "(null)", "no path given");
        return 1;
    }
    const char *path = path_arg; /* the arguments' messages name it as given */
    if (width <= 0 || height <= 0 || (int64_t)width * height > ((int64_t)1 << 31)) {
        io_err(err, path, "invalid image size %dx%d", width, height);
        return 1;
    }
    if (!channels || num_channels <= 0 || num_channels > 1024) {
        io_err(err, path, "invalid channel list (%d channels)", num_channels);
        return 1;
    }
    if (num_attributes < 0 || (num_attributes > 0 && !attributes)) {
        io_err(err, path, "invalid attribute list (%d attributes)", num_attributes);
        return 1;
    }
    int need_longnames = 0;
    for (int i = 0; i < num_attributes; ++i) {
        if (!attributes[i].name || !attributes[i].name[0] || !attributes[i].value) {
            io_err(err, path, "attribute %d has no name or no value", i);
            return 1;
        }
        if (strlen(attributes[i].name) > 255) {
            io_err(err, path, "attribute name too long (%zu chars)", strlen(attributes[i].name));
            return 1;
        }
        if (strlen(attributes[i].name) > 31) need_longnames = 1;
        if (strlen(attributes[i].value) > (size_t)INT32_MAX / 2) {
            io_err(err, path, "attribute '%s' too long", attributes[i].name);
            return 1;
        }
    }

    SortedChannel *sorted = malloc(sizeof *sorted * (size_t)num_channels);
    if (!sorted) {
        io_err(err, path, "out of memory");
        return 1;
    }
    for (int i = 0; i < num_channels; ++i) {
        if (!channels[i].name || !channels[i].name[0] || !channels[i].data) {
            io_err(err, path, "channel %d has no name or no data", i);
            free(sorted);
            return 1;
        }
        size_t len = strlen(channels[i].name);
        if (len > 255) {
            io_err(err, path, "channel name too long (%zu chars)", len);
            free(sorted);
            return 1;
        }
        if (len > 31) need_longnames = 1;
        sorted[i].name = channels[i].name;
        sorted[i].data = channels[i].data;
    }
    qsort(sorted, (size_t)num_channels, sizeof *sorted, cmp_channel);
    for (int i = 1; i < num_channels; ++i) {
        if (strcmp(sorted[i - 1].name, sorted[i].name) == 0) {
            io_err(err, path, "duplicate channel name '%s'", sorted[i].name);
            free(sorted);
            return 1;
        }
    }

    /* through the one atomic writer (io.h): the library writes the temporary's descriptor
     * (exr_output_write), which keeps a failed write's reason */
    IoAtomicFile af;
    if (io_atomic_begin(&af, path_arg, NULL, err) != 0) {
        free(sorted);
        return 1;
    }
    path = af.path;

    exr_last_msg[0] = 0;
    exr_context_initializer_t init = exr_init();
    init.user_data = &af;
    init.write_fn = exr_output_write;
    exr_context_t ctxt = NULL;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int have_enc = 0;
    exr_result_t (*library_compress)(exr_encode_pipeline_t *) = NULL;
    int part = 0;
    const char *stage = "cannot open";
    exr_result_t rv = exr_start_write(&ctxt, path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv != EXR_ERR_SUCCESS) goto fail;
    stage = "cannot write header";
    if (need_longnames && (rv = exr_set_longname_support(ctxt, 1)) != EXR_ERR_SUCCESS) goto fail;
    if ((rv = exr_add_part(ctxt, "main", EXR_STORAGE_SCANLINE, &part)) != EXR_ERR_SUCCESS)
        goto fail;
    rv = exr_initialize_required_attr_simple(ctxt, part, width, height, EXR_COMPRESSION_ZIP);
    if (rv != EXR_ERR_SUCCESS) goto fail;
    for (int i = 0; i < num_channels; ++i) {
        rv = exr_add_channel(ctxt, part, sorted[i].name, EXR_PIXEL_FLOAT,
                             EXR_PERCEPTUALLY_LINEAR, 1, 1);
        if (rv != EXR_ERR_SUCCESS) goto fail;
    }
    for (int i = 0; i < num_attributes; ++i) {
        const exr_attribute_t *existing = NULL;
        exr_result_t found = exr_get_attribute_by_name(ctxt, part, attributes[i].name, &existing);
        exr_last_msg[0] = 0; /* "not found" is the good answer, not a message to keep */
        if (found == EXR_ERR_SUCCESS && existing) {
            stage = "cannot add attribute (already in the header)";
            rv = EXR_ERR_INVALID_ARGUMENT;
            goto fail;
        }
        stage = "cannot add attribute";
        if ((rv = exr_attr_set_string(ctxt, part, attributes[i].name, attributes[i].value)) != EXR_ERR_SUCCESS)
            goto fail;
    }
    stage = "cannot write header";
    if ((rv = exr_write_header(ctxt)) != EXR_ERR_SUCCESS) goto fail;

    stage = "cannot write pixels";
    int32_t lines_per_chunk = 0;
    if ((rv = exr_get_scanlines_per_chunk(ctxt, part, &lines_per_chunk)) != EXR_ERR_SUCCESS)
        goto fail;
    if (lines_per_chunk <= 0) {
        rv = EXR_ERR_UNKNOWN;
        goto fail;
    }
    for (int y = 0; y < height; y += lines_per_chunk) {
        exr_chunk_info_t cinfo;
        if ((rv = exr_write_scanline_chunk_info(ctxt, part, y, &cinfo)) != EXR_ERR_SUCCESS)
            goto fail;
        if (!have_enc) {
            rv = exr_encoding_initialize(ctxt, part, &cinfo, &enc);
            if (rv != EXR_ERR_SUCCESS) goto fail;
            have_enc = 1;
        } else if ((rv = exr_encoding_update(ctxt, part, &cinfo, &enc)) != EXR_ERR_SUCCESS) {
            goto fail;
        }
        for (int c = 0; c < enc.channel_count; ++c) {
            exr_coding_channel_info_t *ch = &enc.channels[c];
            const SortedChannel *src = NULL;
            for (int i = 0; i < num_channels && !src; ++i)
                if (strcmp(sorted[i].name, ch->channel_name) == 0) src = &sorted[i];
            if (!src) {
                rv = EXR_ERR_UNKNOWN;
                goto fail;
            }
            ch->user_bytes_per_element = 4;
            ch->user_data_type = EXR_PIXEL_FLOAT;
            ch->user_pixel_stride = 4;
            ch->user_line_stride = 4 * width;
            ch->encode_from_ptr = (const uint8_t *)(src->data + (size_t)cinfo.start_y * (size_t)width);
        }
        if (y == 0) {
            if ((rv = exr_encoding_choose_default_routines(ctxt, part, &enc)) != EXR_ERR_SUCCESS) goto fail;
            library_compress = enc.compress_fn;
            enc.encoding_user_data = &library_compress;
            enc.compress_fn = compress_unambiguous;
        }
        if ((rv = exr_encoding_run(ctxt, part, &enc)) != EXR_ERR_SUCCESS) goto fail;
    }
    if (have_enc) {
        exr_encoding_destroy(ctxt, &enc);
        have_enc = 0;
    }
    stage = "cannot finish";
    rv = exr_finish(&ctxt);
    ctxt = NULL;
    if (rv != EXR_ERR_SUCCESS) goto fail;
    free(sorted);
    return io_atomic_commit(&af, err);

fail:
    /* a failed write says why (a full disk), not only where the library was */
    if (af.error) io_err(err, path, "cannot write: %s", strerror(af.error));
    else io_err(err, path, "%s: %s", stage, exr_msg(rv));
    if (have_enc) exr_encoding_destroy(ctxt, &enc);
    if (ctxt) exr_finish(&ctxt);
    io_atomic_abort(&af);
    free(sorted);
    return 1;
}

/* ---------------------------------------------------------------------------------------- */
/* Reader */


/* An input opened by io_open_input, read by the OpenEXR library through these callbacks. */
typedef struct ExrInput {
    int fd;
    uint64_t size;
} ExrInput;

static int64_t exr_input_read(exr_const_context_t ctxt, void *user, void *buffer, uint64_t sz, uint64_t offset,
                              exr_stream_error_func_ptr_t error_cb) {
    const ExrInput *in = user;
    uint64_t done = 0;
    while (done < sz) {
        ssize_t r = pread(in->fd, (char *)buffer + done, (size_t)(sz - done), (off_t)(offset + done));
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) {
            error_cb(ctxt, EXR_ERR_READ_IO, "read error: %s", strerror(errno));
            return -1;
        }
        if (r == 0) break; /* end of file: the library reports the short read */
        done += (uint64_t)r;
    }
    return (int64_t)done;
}

static int64_t exr_input_size(exr_const_context_t ctxt, void *user) {
    (void)ctxt;
    return (int64_t)((const ExrInput *)user)->size;
}

/* The EXR at path opened through the input door (a FIFO would block in the library's own
 * open()), the library reading from that descriptor through the callbacks above: 1 when the door
 * refused it (err says why, nothing to close); else 0, with the library's answer in *rv and the
 * context in *ctxt (NULL when it failed). *input must stay where it is while ctxt is open. */
static int exr_start_input(const char *path, ExrInput *input, exr_context_t *ctxt, exr_result_t *rv,
                           char err[IO_ERR_LEN]) {
    *input = (ExrInput){-1, 0};
    *ctxt = NULL;
    if (io_open_input(path, 0, "an EXR", &input->fd, &input->size, err) != 0) return 1;
    exr_last_msg[0] = 0;
    exr_context_initializer_t init = exr_init();
    init.user_data = input;
    init.read_fn = exr_input_read;
    init.size_fn = exr_input_size;
    *rv = exr_start_read(ctxt, path, &init);
    return 0;
}

int io_read_exr_channel(const char *path, const char *channel, int *width, int *height,
                        float **data, char err[IO_ERR_LEN]) {
    if (err) err[0] = 0;
    if (data) *data = NULL;
    if (width) *width = 0;
    if (height) *height = 0;
    if (!path || !*path) {
        io_err(err, "(null)", "no path given");
        return 1;
    }
    if (!channel || !data || !width || !height) {
        io_err(err, path, "invalid arguments");
        return 1;
    }

    ExrInput input;
    exr_context_t ctxt;
    exr_result_t rv;
    if (exr_start_input(path, &input, &ctxt, &rv, err) != 0) return 1;
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    int have_dec = 0;
    uint8_t *raw = NULL;
    float *out = NULL;
    const char *stage = "cannot open";
    char problem[IO_ERR_LEN];
    problem[0] = 0;
    if (rv != EXR_ERR_SUCCESS) goto fail;

    stage = "cannot read header";
    int nparts = 0;
    if ((rv = exr_get_count(ctxt, &nparts)) != EXR_ERR_SUCCESS) goto fail;
    if (nparts < 1) {
        snprintf(problem, sizeof problem, "no image parts");
        goto fail;
    }
    exr_storage_t storage;
    if ((rv = exr_get_storage(ctxt, 0, &storage)) != EXR_ERR_SUCCESS) goto fail;
    if (storage != EXR_STORAGE_SCANLINE) {
        snprintf(problem, sizeof problem, "only flat scanline EXR files are supported");
        goto fail;
    }
    exr_attr_box2i_t dw;
    if ((rv = exr_get_data_window(ctxt, 0, &dw)) != EXR_ERR_SUCCESS) goto fail;
    /* each side first: two sides of up to 2^32 made the product overflow and wrap past the
     * check (found by tests/fuzz/fuzz_exr: a 398-byte file asked for 12 GB). The limits are
     * the renderer's largest image (16384 per side, 64 megapixels): a reference is compared
     * with a render of the same size */
    int64_t w = (int64_t)dw.max.x - dw.min.x + 1, h = (int64_t)dw.max.y - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w > IO_EXR_MAX_SIDE || h > IO_EXR_MAX_SIDE || w * h > IO_EXR_MAX_PIXELS) {
        snprintf(problem, sizeof problem, "invalid data window %lldx%lld", (long long)w,
                 (long long)h);
        goto fail;
    }
    const exr_attr_chlist_t *chl = NULL;
    if ((rv = exr_get_channels(ctxt, 0, &chl)) != EXR_ERR_SUCCESS) goto fail;
    const exr_attr_chlist_entry_t *want = NULL;
    for (int i = 0; chl && i < chl->num_channels; ++i)
        if (chl->entries[i].name.str && strcmp(chl->entries[i].name.str, channel) == 0)
            want = &chl->entries[i];
    if (!want) {
        snprintf(problem, sizeof problem, "no channel '%s'", channel);
        goto fail;
    }
    if (want->x_sampling != 1 || want->y_sampling != 1) {
        snprintf(problem, sizeof problem, "channel '%s' is subsampled (unsupported)", channel);
        goto fail;
    }
    const exr_pixel_type_t ptype = want->pixel_type;
    const int bpe = ptype == EXR_PIXEL_HALF ? 2 : 4;
    if (ptype != EXR_PIXEL_HALF && ptype != EXR_PIXEL_FLOAT && ptype != EXR_PIXEL_UINT) {
        snprintf(problem, sizeof problem, "channel '%s' has unknown pixel type", channel);
        goto fail;
    }
    const size_t npix = (size_t)w * (size_t)h;
    out = malloc(npix * sizeof(float));
    raw = ptype == EXR_PIXEL_FLOAT ? (uint8_t *)out : malloc(npix * (size_t)bpe);
    if (!out || !raw) {
        snprintf(problem, sizeof problem, "out of memory");
        goto fail;
    }

    stage = "cannot read pixels";
    int32_t lines_per_chunk = 0;
    if ((rv = exr_get_scanlines_per_chunk(ctxt, 0, &lines_per_chunk)) != EXR_ERR_SUCCESS)
        goto fail;
    if (lines_per_chunk <= 0) {
        snprintf(problem, sizeof problem, "invalid scanlines per chunk");
        goto fail;
    }
    for (int64_t y = dw.min.y; y <= dw.max.y; y += lines_per_chunk) {
        exr_chunk_info_t cinfo;
        if ((rv = exr_read_scanline_chunk_info(ctxt, 0, (int)y, &cinfo)) != EXR_ERR_SUCCESS)
            goto fail;
        if (!have_dec) {
            if ((rv = exr_decoding_initialize(ctxt, 0, &cinfo, &dec)) != EXR_ERR_SUCCESS)
                goto fail;
            have_dec = 1;
        } else if ((rv = exr_decoding_update(ctxt, 0, &cinfo, &dec)) != EXR_ERR_SUCCESS) {
            goto fail;
        }
        int64_t row0 = (int64_t)cinfo.start_y - dw.min.y;
        if (row0 < 0 || row0 + cinfo.height > h || cinfo.width != w) {
            snprintf(problem, sizeof problem, "corrupt chunk at scanline %lld", (long long)y);
            goto fail;
        }
        for (int c = 0; c < dec.channel_count; ++c) {
            exr_coding_channel_info_t *ch = &dec.channels[c];
            if (strcmp(ch->channel_name, channel) == 0) {
                ch->user_bytes_per_element = (int16_t)bpe;
                ch->user_data_type = (uint16_t)ptype;
                ch->user_pixel_stride = bpe;
                ch->user_line_stride = (int32_t)(bpe * w);
                ch->decode_to_ptr = raw + (size_t)row0 * (size_t)w * (size_t)bpe;
            } else {
                ch->decode_to_ptr = NULL;
            }
        }
        if ((rv = exr_decoding_choose_default_routines(ctxt, 0, &dec)) != EXR_ERR_SUCCESS)
            goto fail;
        if ((rv = exr_decoding_run(ctxt, 0, &dec)) != EXR_ERR_SUCCESS) goto fail;
    }
    exr_decoding_destroy(ctxt, &dec);
    have_dec = 0;
    exr_finish(&ctxt);
    close(input.fd);

    if (ptype == EXR_PIXEL_HALF) {
        const uint16_t *src = (const uint16_t *)raw;
        for (size_t i = 0; i < npix; ++i) out[i] = imath_half_to_float(src[i]); /* Imath's C API (Imath/half.h) */
        free(raw);
    } else if (ptype == EXR_PIXEL_UINT) {
        const uint32_t *src = (const uint32_t *)raw;
        for (size_t i = 0; i < npix; ++i) out[i] = (float)src[i];
        free(raw);
    }
    *data = out;
    *width = (int)w;
    *height = (int)h;
    return 0;

fail:
    if (problem[0])
        io_err(err, path, "%s", problem);
    else
        io_err(err, path, "%s: %s", stage, exr_msg(rv));
    if (have_dec) exr_decoding_destroy(ctxt, &dec);
    if (ctxt) exr_finish(&ctxt);
    close(input.fd);
    if (raw && raw != (uint8_t *)out) free(raw);
    free(out);
    return 1;
}

int io_exr_complete(const char *path, int *width, int *height, char err[IO_ERR_LEN]) {
    return io_exr_complete_attribute(path, width, height, NULL, NULL, 0, err);
}

int io_exr_complete_attribute(const char *path, int *width, int *height, const char *name, char *value, size_t size,
                              char err[IO_ERR_LEN]) {
    if (err) err[0] = 0;
    if (value && size) value[0] = 0;
    *width = *height = 0;
    ExrInput input;
    exr_context_t ctxt;
    exr_result_t rv;
    if (exr_start_input(path, &input, &ctxt, &rv, err) != 0) return 1;
    const char *stage = "cannot open";
    char problem[IO_ERR_LEN] = "";
    int nparts = 0;
    exr_storage_t storage;
    exr_attr_box2i_t dw;
    int32_t lines = 0;
    if (rv != EXR_ERR_SUCCESS) goto fail;
    stage = "cannot read header";
    if ((rv = exr_get_count(ctxt, &nparts)) != EXR_ERR_SUCCESS || (nparts >= 1 && (rv = exr_get_storage(ctxt, 0, &storage)) != EXR_ERR_SUCCESS) ||
        (nparts >= 1 && (rv = exr_get_data_window(ctxt, 0, &dw)) != EXR_ERR_SUCCESS))
        goto fail;
    if (nparts < 1 || storage != EXR_STORAGE_SCANLINE) {
        snprintf(problem, sizeof problem, "not a flat scanline EXR");
        goto fail;
    }
    int64_t w = (int64_t)dw.max.x - dw.min.x + 1, h = (int64_t)dw.max.y - dw.min.y + 1;
    if (w <= 0 || h <= 0 || w > IO_EXR_MAX_SIDE || h > IO_EXR_MAX_SIDE || w * h > IO_EXR_MAX_PIXELS) {
        snprintf(problem, sizeof problem, "invalid data window %lldx%lld", (long long)w, (long long)h);
        goto fail;
    }
    stage = "incomplete";
    if ((rv = exr_get_scanlines_per_chunk(ctxt, 0, &lines)) != EXR_ERR_SUCCESS) goto fail;
    if (lines <= 0) {
        snprintf(problem, sizeof problem, "invalid scanlines per chunk");
        goto fail;
    }
    /* every chunk's table entry and header read, and its bytes inside the file: what a write cut
     * short (or an empty file) lacks, found without decompressing anything */
    for (int64_t y = dw.min.y; y <= dw.max.y; y += lines) {
        exr_chunk_info_t cinfo;
        if ((rv = exr_read_scanline_chunk_info(ctxt, 0, (int)y, &cinfo)) != EXR_ERR_SUCCESS) goto fail;
        if (cinfo.data_offset + cinfo.packed_size > input.size) {
            snprintf(problem, sizeof problem, "cut short (the chunk at scanline %lld ends past the file's %llu bytes)",
                     (long long)y, (unsigned long long)input.size);
            goto fail;
        }
    }
    if (name && value && size) {
        /* a string attribute the header may lack (an older writer's): "" then */
        int32_t len = 0;
        const char *str = NULL;
        if (exr_attr_get_string(ctxt, 0, name, &len, &str) == EXR_ERR_SUCCESS && str && len >= 0)
            snprintf(value, size, "%.*s", (int)((size_t)len < size ? len : (int32_t)(size - 1)), str);
    }
    exr_finish(&ctxt);
    close(input.fd);
    *width = (int)w;
    *height = (int)h;
    return 0;
fail:
    if (problem[0]) io_err(err, path, "%s", problem);
    else io_err(err, path, "%s: %s", stage, exr_msg(rv));
    if (ctxt) exr_finish(&ctxt);
    close(input.fd);
    return 1;
}
