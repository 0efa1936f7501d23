/* renderer/app/checkpoint.c: checkpoints (--checkpoint, --resume-from), film files of sample shards
 * (--sample-shard) and `candela merge` (see checkpoint.h for what a checkpoint holds).
 *
 * File layout (native byte order; the byte-order mark refuses a file of another byte order):
 *   "CANDCKPT", u32 byte-order mark 0x01020304, u32 format version, u32 kind (1 checkpoint,
 *   2 finished film), u32 width, u32 height, u32 identity length, the identity text,
 *   u64 spp_total, sample_begin, sample_count, u32 shard_index, shard_count,
 *   i32 iteration, i32 spp_done, u64 iteration_paths, u32 record length, the record text
 *   (version 2: CandelaOptions.checkpoint_record, what `--resume-from FILE` alone needs and the
 *   --version line of the build that wrote it; empty in
 *   a finished film),
 *   the sections (film; for a checkpoint also recorder, guiding, the two auto probes and the
 *   light sampler's learned state), each opening with its tag and version,
 *   u64 FNV-1a checksum of every byte before it.
 * The checksum is verified before anything is parsed, so a truncated file (a checkpoint being
 * written when the machine died leaves only NAME.tmp-PID, but a copy may be cut) or a damaged one
 * is refused with one line, never half-loaded. */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "checkpoint.h"
#include "feature.h"
#include "io.h"
#include "options_table.h"

#define CKPT_MAGIC "CANDCKPT"
#define CKPT_BOM 0x01020304u
#define CKPT_FORMAT_VERSION 2u /* 2: the identity generated from the options table, and the record */
#define CKPT_RECORD_LEN 16384
#define CKPT_KIND_CHECKPOINT 1u
#define CKPT_KIND_FILM 2u
#define LSAMPLER_TAG CKPT_TAG('L', 'S', 'M', 'P')
#define LSAMPLER_VERSION 1u

/* ---------------------------------------------------------------- hashing */

static uint64_t fnv1a(uint64_t h, const void *data, size_t n) {
    const unsigned char *p = data;
    for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 0x100000001b3ull;
    return h;
}
#define FNV_OFFSET 0xcbf29ce484222325ull

/* FNV-1a of the first `n` bytes of f (from the start). -1 on a read error. */
static int hash_prefix(FILE *f, uint64_t n, uint64_t *h) {
    unsigned char buf[1 << 16];
    *h = FNV_OFFSET;
    if (fseek(f, 0, SEEK_SET) != 0) return -1;
    while (n > 0) {
        size_t want = n < sizeof buf ? (size_t)n : sizeof buf;
        if (fread(buf, 1, want, f) != want) return -1;
        *h = fnv1a(*h, buf, want);
        n -= want;
    }
    return 0;
}

int checkpoint_scene_hash(const char *scene_path, uint64_t *hash, char err[CANDELA_ERR_LEN]) {
    char ioerr[IO_ERR_LEN];
    FILE *f = io_open_input_file(scene_path, IO_MAX_SCENE_BYTES, "a scene (4 GiB)", NULL, ioerr);
    if (!f) {
        snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
        return -1;
    }
    uint64_t h = FNV_OFFSET;
    unsigned char buf[1 << 16];
    for (size_t n; (n = fread(buf, 1, sizeof buf, f)) > 0;) h = fnv1a(h, buf, n);
    int bad = ferror(f);
    fclose(f);
    if (bad) {
        snprintf(err, CANDELA_ERR_LEN, "%s: cannot read", scene_path);
        return -1;
    }
    *hash = h;
    return 0;
}

int candela_scene_hash(const char *scene_path, uint64_t *hash, char err[CANDELA_ERR_LEN]) {
    return checkpoint_scene_hash(scene_path, hash, err);
}

/* ---------------------------------------------------------------- identity */

int candela_image_identity(const CandelaOptions *o, uint64_t scene_hash, int width, int height, char *buf, size_t size) {
    /* Every row of the options table that changes the image (options_table.c: `image`), with the
     * resolved resolution. Not there: threads and batch size (never change the image),
     * --time-limit (where a render stops, not what it computes: a time-limited render's
     * checkpoint resumes with any limit), output names, quiet, the texture and volume budgets
     * (they refuse a scene, never change one), guide-dump. The scene's referenced files
     * (buffers, textures, VDBs) are not hashed: the glTF names them, a changed one is the
     * user's doing. max-iteration-spp is no flag (the library's, compare's equal time). */
    CandelaOptions r = *o;
    r.width = width;
    r.height = height;
    int n = snprintf(buf, size, "scene=%016" PRIx64 " ", scene_hash);
    if (n < 0 || (size_t)n >= size) return -1;
    int m = candela_options_identity(&r, buf + n, size - (size_t)n);
    if (m < 0) return -1;
    n += m;
    m = snprintf(buf + n, size - (size_t)n, " max-iteration-spp=%d", o->max_iteration_spp);
    return m < 0 || (size_t)m >= size - (size_t)n ? -1 : 0;
}

int checkpoint_identity(const CandelaOptions *o, int width, int height, uint64_t sample_begin, uint64_t sample_count,
                        CheckpointIdentity *id, char err[CANDELA_ERR_LEN]) {
    memset(id, 0, sizeof *id);
    uint64_t h;
    if (checkpoint_scene_hash(o->scene_path, &h, err) != 0) return -1;
    if (candela_image_identity(o, h, width, height, id->text, sizeof id->text) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s: the render's options are too long for a checkpoint (camera or --env name)",
                 o->scene_path);
        return -1;
    }
    if (o->checkpoint_record && strlen(o->checkpoint_record) >= CKPT_RECORD_LEN) {
        snprintf(err, CANDELA_ERR_LEN, "%s: the paths are too long for a checkpoint", o->scene_path);
        return -1;
    }
    id->record = o->checkpoint_record;
    id->spp_total = (uint64_t)o->spp;
    id->sample_begin = sample_begin;
    id->sample_count = sample_count;
    id->shard_index = o->shard_count ? o->shard_index : 0;
    id->shard_count = o->shard_count ? o->shard_count : 1;
    return 0;
}

/* Every option that differs, "--KEY VALUE_THERE (here VALUE_HERE)", ... */
static void identity_difference(const char *there, const char *here, char *out, size_t len) {
    if (candela_identity_differences(there, here, "here", out, len) == 0) snprintf(out, len, "the options differ");
}

/* ---------------------------------------------------------------- header */

typedef struct Header {
    uint32_t kind, width, height;
    CheckpointIdentity id;
    char record[CKPT_RECORD_LEN];
    CheckpointProgress pr;
    uint64_t size; /* of the file, checksum included */
} Header;

static int write_header(FILE *f, uint32_t kind, int width, int height, const CheckpointIdentity *id,
                        const CheckpointProgress *pr) {
    uint32_t head[6] = {CKPT_BOM, CKPT_FORMAT_VERSION, kind, (uint32_t)width, (uint32_t)height,
                        (uint32_t)strlen(id->text)};
    uint64_t samples[3] = {id->spp_total, id->sample_begin, id->sample_count};
    uint32_t shard[2] = {id->shard_index, id->shard_count};
    int32_t it[2] = {pr->iteration, pr->spp_done};
    /* the record only in a checkpoint: a finished film is the same bytes wherever it was written */
    const char *record = kind == CKPT_KIND_CHECKPOINT && id->record ? id->record : "";
    uint32_t record_len = (uint32_t)strlen(record);
    return ckpt_put(f, CKPT_MAGIC, 8) | ckpt_put(f, head, sizeof head) | ckpt_put(f, id->text, head[5]) |
           ckpt_put(f, samples, sizeof samples) | ckpt_put(f, shard, sizeof shard) | ckpt_put(f, it, sizeof it) |
           ckpt_put(f, &pr->iteration_paths, sizeof pr->iteration_paths) | ckpt_put(f, &record_len, sizeof record_len) |
           ckpt_put(f, record, record_len);
}

/* Opens path, verifies its checksum and reads the header. NULL with a one-line message. */
static FILE *open_verified(const char *path, Header *h, char err[CANDELA_ERR_LEN]) {
    memset(h, 0, sizeof *h);
    /* through the input door: a FIFO (which blocked in fopen) or a device is refused unread;
     * the size is the file's own (the whole file is hashed before anything is parsed) */
    char ioerr[IO_ERR_LEN];
    uint64_t file_size = 0;
    FILE *f = io_open_input_file(path, 0, "a checkpoint", &file_size, ioerr);
    if (!f) {
        snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
        return NULL;
    }
    char magic[8];
    uint32_t head[6];
    if (ckpt_get(f, magic, 8) || memcmp(magic, CKPT_MAGIC, 8) != 0 || ckpt_get(f, head, sizeof head)) {
        snprintf(err, CANDELA_ERR_LEN, "%s: not a candela checkpoint or film file", path);
        fclose(f);
        return NULL;
    }
    if (head[0] != CKPT_BOM || head[1] != CKPT_FORMAT_VERSION) {
        snprintf(err, CANDELA_ERR_LEN, "%s: a checkpoint of another format version or byte order (version %u, this is %u)",
                 path, head[0] == CKPT_BOM ? head[1] : 0u, CKPT_FORMAT_VERSION);
        fclose(f);
        return NULL;
    }
    uint64_t sum = 0, stored = 0;
    h->size = file_size;
    if (h->size < 8 + sizeof head + 8 || hash_prefix(f, h->size - 8, &sum) || ckpt_get(f, &stored, sizeof stored) ||
        sum != stored) {
        snprintf(err, CANDELA_ERR_LEN, "%s: damaged or truncated (checksum mismatch)", path);
        fclose(f);
        return NULL;
    }
    uint64_t samples[3];
    uint32_t shard[2], record_len = 0;
    int32_t it[2];
    if (fseek(f, 8 + (long)sizeof head, SEEK_SET) != 0 || head[5] >= CKPT_IDENTITY_LEN ||
        ckpt_get(f, h->id.text, head[5]) || ckpt_get(f, samples, sizeof samples) || ckpt_get(f, shard, sizeof shard) ||
        ckpt_get(f, it, sizeof it) || ckpt_get(f, &h->pr.iteration_paths, sizeof h->pr.iteration_paths) ||
        ckpt_get(f, &record_len, sizeof record_len) || record_len >= CKPT_RECORD_LEN ||
        ckpt_get(f, h->record, record_len)) {
        snprintf(err, CANDELA_ERR_LEN, "%s: damaged header", path);
        fclose(f);
        return NULL;
    }
    h->id.text[head[5]] = 0;
    h->record[record_len] = 0;
    h->kind = head[2];
    h->width = head[3];
    h->height = head[4];
    h->id.spp_total = samples[0];
    h->id.sample_begin = samples[1];
    h->id.sample_count = samples[2];
    h->id.shard_index = shard[0];
    h->id.shard_count = shard[1];
    h->pr.iteration = it[0];
    h->pr.spp_done = it[1];
    return f;
}

static int check_identity(const char *path, const Header *h, const CheckpointIdentity *id, char err[CANDELA_ERR_LEN]) {
    if (strcmp(h->id.text, id->text) != 0) {
        char why[256];
        identity_difference(h->id.text, id->text, why, sizeof why);
        snprintf(err, CANDELA_ERR_LEN, "%s: a checkpoint of another render (%s)", path, why);
        return -1;
    }
    if (h->id.shard_index != id->shard_index || h->id.shard_count != id->shard_count) {
        snprintf(err, CANDELA_ERR_LEN, "%s: a checkpoint of another sample shard (%u/%u there, %u/%u here)", path,
                 h->id.shard_index, h->id.shard_count, id->shard_index, id->shard_count);
        return -1;
    }
    return 0;
}

/* A verified checkpoint of this render, open after its header; NULL with a message. */
static FILE *open_checkpoint(const char *path, const CheckpointIdentity *id, Header *hp, char err[CANDELA_ERR_LEN]) {
    Header h;
    FILE *f = open_verified(path, &h, err);
    if (!f) return NULL;
    *hp = h;
    if (h.kind != CKPT_KIND_CHECKPOINT) {
        snprintf(err, CANDELA_ERR_LEN, "%s: a finished shard film, not a checkpoint (merge it with candela merge)", path);
        fclose(f);
        return NULL;
    }
    if (check_identity(path, &h, id, err) != 0) {
        fclose(f);
        return NULL;
    }
    if (h.pr.iteration < 0 || h.pr.spp_done < 0 || (uint64_t)h.pr.spp_done > id->sample_count) {
        snprintf(err, CANDELA_ERR_LEN, "%s: damaged progress record", path);
        fclose(f);
        return NULL;
    }
    return f;
}

int checkpoint_check(const char *path, const CheckpointIdentity *id, char err[CANDELA_ERR_LEN]) {
    Header h;
    FILE *f = open_checkpoint(path, id, &h, err);
    if (!f) return -1;
    fclose(f);
    return 0;
}

int candela_checkpoint_info(const char *path, CandelaCheckpointInfo *info, char err[CANDELA_ERR_LEN]) {
    Header *h = malloc(sizeof *h);
    if (!h) {
        snprintf(err, CANDELA_ERR_LEN, "%s: out of memory", path);
        return -1;
    }
    FILE *f = open_verified(path, h, err);
    if (!f) {
        free(h);
        return -1;
    }
    fclose(f);
    memset(info, 0, sizeof *info);
    info->kind = (int)h->kind;
    info->width = (int)h->width;
    info->height = (int)h->height;
    info->spp_done = h->pr.spp_done;
    info->shard_index = h->id.shard_index;
    info->shard_count = h->id.shard_count;
    snprintf(info->identity, sizeof info->identity, "%s", h->id.text);
    snprintf(info->record, sizeof info->record, "%s", h->record);
    free(h);
    return 0;
}

/* ---------------------------------------------------------------- write */

int checkpoint_write(const char *path, const CheckpointIdentity *id, const CheckpointProgress *pr, Integrator *ig,
                     const LightSampler *sampler, int final, char err[CANDELA_ERR_LEN]) {
    /* through io's atomic writer (PATH.tmp-PID, checked, synced, renamed: io.h); "w+b": the
     * checksum reads back what was written */
    IoAtomicFile af;
    char ioerr[IO_ERR_LEN];
    if (io_atomic_begin(&af, path, "w+b", ioerr) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
        return -1;
    }
    FILE *f = af.f;
    int rc = write_header(f, final ? CKPT_KIND_FILM : CKPT_KIND_CHECKPOINT, ig->film.width, ig->film.height, id, pr);
    if (rc == 0) rc = film_save(&ig->film, f);
    if (rc == 0 && !final) {
        uint32_t learns = sampler->ops->save_learned != NULL;
        rc = features_save(ig, f); /* each part in turn: the file's order */
        rc |= ckpt_put_tag(f, LSAMPLER_TAG, LSAMPLER_VERSION);
        rc |= ckpt_put(f, &learns, sizeof learns);
        if (rc == 0) rc = light_sampler_save_learned(sampler, f);
    }
    uint64_t sum = 0;
    long size = rc == 0 && fflush(f) == 0 ? ftell(f) : -1;
    if (size < 0 || hash_prefix(f, (uint64_t)size, &sum) != 0 || fseek(f, 0, SEEK_END) != 0 ||
        ckpt_put(f, &sum, sizeof sum) != 0)
        rc = -1;
    /* a failed write keeps its reason (af.error: "No space left on device"), which commit
     * gives; a failure without one (the read-back of the checksum) is said here */
    if (rc != 0 && !af.error) {
        io_atomic_abort(&af);
        snprintf(err, CANDELA_ERR_LEN, "%.400s: cannot write the %s: write failed", path, final ? "film" : "checkpoint");
        return -1;
    }
    if (io_atomic_commit(&af, ioerr) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
        return -1;
    }
    return 0;
}

/* ---------------------------------------------------------------- load */

int checkpoint_load(const char *path, const CheckpointIdentity *id, CheckpointProgress *pr, Integrator *ig,
                    const LightSampler *sampler, char err[CANDELA_ERR_LEN]) {
    Header h;
    FILE *f = open_checkpoint(path, id, &h, err);
    if (!f) return -1;
    const char *what = "film";
    int rc = h.width == (uint32_t)ig->film.width && h.height == (uint32_t)ig->film.height ? film_load(&ig->film, f) : -1;
    /* its sums as a film to merge must be (a forged checkpoint's NaN or wrapped count went into
     * the image): counts of spp_done, more only within the interrupted iteration */
    char why[160];
    const uint64_t done = (uint64_t)h.pr.spp_done, most = h.pr.iteration_paths ? id->sample_count : done;
    if (rc == 0 && film_check_counts(&ig->film, done, most, "checkpoint", why, sizeof why) != 0) {
        fclose(f);
        snprintf(err, CANDELA_ERR_LEN, "%.300s: not a checkpoint candela wrote: %s", path, why);
        return -1;
    }
    if (rc == 0) rc = features_load(ig, f, &what);
    uint32_t learns = 0;
    if (rc == 0) {
        what = "light sampler";
        rc = ckpt_get_tag(f, LSAMPLER_TAG, LSAMPLER_VERSION) | ckpt_get(f, &learns, sizeof learns);
        if (rc == 0 && learns != (sampler->ops->save_learned != NULL)) rc = -1;
        if (rc == 0) rc = light_sampler_load_learned(sampler, f);
    }
    long at = ftell(f);
    fclose(f);
    if (rc == 0 && (at < 0 || (uint64_t)at + 8 != h.size)) { what = "end"; rc = -1; }
    if (rc != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s: the checkpoint's %s state does not fit this render%s", path, what,
                 rc == -2 ? " (another cache point build)"
                 : rc == -3 ? " (adaptive sampling by the rule before the pilot rule: render it again with this build)"
                            : "");
        return -1;
    }
    *pr = h.pr;
    return 0;
}

/* ---------------------------------------------------------------- schedule */

int checkpoint_due(int spp_done, int next_spp_done, int spp_total) {
    if (spp_done >= spp_total) return 0;
    for (long ideal = 4; ideal <= (long)spp_total; ideal *= 2)
        if ((long)spp_done <= ideal && ideal < (long)next_spp_done) return 1;
    return 0;
}

/* ---------------------------------------------------------------- candela merge */

static void film_add(Film *dst, const Film *src) {
    size_t n = (size_t)dst->width * (size_t)dst->height;
    for (size_t i = 0; i < 3 * n; ++i) {
        dst->sum[i] += src->sum[i];
        dst->sum2[i] += src->sum2[i];
        dst->albedo[i] += src->albedo[i];
        dst->normal[i] += src->normal[i];
        if (dst->recorder) dst->recorder[i] += src->recorder[i];
    }
    for (size_t i = 0; dst->sel_aov && i < 6 * n; ++i) dst->sel_aov[i] += src->sel_aov[i];
    for (size_t i = 0; i < n; ++i) {
        dst->depth[i] += src->depth[i];
        dst->hits[i] += src->hits[i];
        dst->count[i] += src->count[i];
    }
    dst->dropped += src->dropped;
}

static int film_alloc_like(Film *f, const Header *h, int recorder) {
    if (film_alloc(f, (int)h->width, (int)h->height) != 0) return -1;
    if (recorder) {
        f->recorder = calloc(3 * (size_t)h->width * h->height, sizeof(double));
        if (!f->recorder) { film_free(f); return -1; }
    }
    char aov[64];
    candela_identity_value(h->id.text, "aov", aov, sizeof aov);
    if (strstr(aov, "cachepoint")) {
        f->sel_aov = calloc(6 * (size_t)h->width * h->height, sizeof(double));
        if (!f->sel_aov) { film_free(f); return -1; }
    }
    return 0;
}

int candela_merge(const char *out_exr, const char *png, const char *const *files, int num_files,
                  char err[CANDELA_ERR_LEN]) {
    return candela_merge_provenance(out_exr, png, files, num_files, NULL, err);
}

int candela_merge_provenance(const char *out_exr, const char *png, const char *const *files, int num_files,
                  const CandelaProvenance *provenance, char err[CANDELA_ERR_LEN]) {
    if (num_files < 1) {
        snprintf(err, CANDELA_ERR_LEN, "merge: no shard files given");
        return -1;
    }
    Header *h = calloc((size_t)num_files, sizeof *h);
    int *order = calloc((size_t)num_files, sizeof *order); /* by shard index */
    if (!h || !order) {
        free(h);
        free(order);
        snprintf(err, CANDELA_ERR_LEN, "merge: out of memory");
        return -1;
    }
    int rc = 0;
    for (int i = 0; i < num_files && rc == 0; ++i) {
        FILE *f = open_verified(files[i], &h[i], err);
        if (!f) { rc = -1; break; }
        fclose(f);
        const char *problem = NULL;
        if (h[i].kind != CKPT_KIND_FILM) problem = "a checkpoint, not a finished shard film (resume its render first)";
        else if (h[i].width == 0 || h[i].height == 0 || (uint64_t)h[i].width * h[i].height > (64u << 20)) problem = "damaged header";
        else if (i > 0 && strcmp(h[i].id.text, h[0].id.text) != 0) problem = "another render than the first file";
        else if (h[i].id.shard_count != (uint32_t)num_files)
            problem = "a shard of a different split (its shard count is not the number of files given)";
        else if (h[i].id.shard_index >= (uint32_t)num_files) problem = "damaged header";
        /* counts are 32-bit per pixel: a total past the largest --spp could wrap them */
        else if (h[i].id.spp_total < 1 || h[i].id.spp_total > ((uint64_t)1 << 20) || h[i].id.sample_count > h[i].id.spp_total)
            problem = "damaged header (sample counts out of range)";
        if (problem) {
            char why[256] = "";
            if (i > 0 && strcmp(h[i].id.text, h[0].id.text) != 0) {
                identity_difference(h[0].id.text, h[i].id.text, why, sizeof why);
                snprintf(err, CANDELA_ERR_LEN, "%s: a shard of another render than %s (%s)", files[i], files[0], why);
            } else {
                snprintf(err, CANDELA_ERR_LEN, "%s: %s", files[i], problem);
            }
            rc = -1;
        }
        /* the samples a shard declares are the ones candela gives shard I/N (render.c's split,
         * never empty: a render refuses --spp below N); a forged film claiming another range
         * (twice its share, or none with sums left in) would still tile [0, spp) with others */
        if (rc == 0) {
            const uint64_t spp = h[i].id.spp_total, k = h[i].id.shard_index, nn = (uint64_t)num_files;
            const uint64_t b = spp * k / nn, e = spp * (k + 1) / nn;
            if (b == e || h[i].id.sample_begin != b || h[i].id.sample_count != e - b) {
                snprintf(err, CANDELA_ERR_LEN,
                         "%.300s: damaged header (its samples [%" PRIu64 ", %" PRIu64 ") are not shard %u/%u's of %" PRIu64
                         " spp, [%" PRIu64 ", %" PRIu64 "))",
                         files[i], h[i].id.sample_begin, h[i].id.sample_begin + h[i].id.sample_count, h[i].id.shard_index,
                         num_files, spp, b, e);
                rc = -1;
            }
        }
    }
    /* every shard exactly once, and their sample ranges tile [0, spp) */
    for (int i = 0; i < num_files; ++i) order[i] = -1;
    for (int i = 0; i < num_files && rc == 0; ++i) {
        if (order[h[i].id.shard_index] >= 0) {
            snprintf(err, CANDELA_ERR_LEN, "%s: shard %u/%u given twice (also %s)", files[i], h[i].id.shard_index,
                     h[i].id.shard_count, files[order[h[i].id.shard_index]]);
            rc = -1;
        } else {
            order[h[i].id.shard_index] = i;
        }
    }
    uint64_t next = 0;
    for (int k = 0; k < num_files && rc == 0; ++k) {
        const Header *s = &h[order[k]];
        if (s->id.sample_begin != next || s->id.spp_total != h[0].id.spp_total) {
            snprintf(err, CANDELA_ERR_LEN, "%s: its samples [%" PRIu64 ", %" PRIu64 ") do not continue the shards before it",
                     files[order[k]], s->id.sample_begin, s->id.sample_begin + s->id.sample_count);
            rc = -1;
        }
        next = s->id.sample_begin + s->id.sample_count;
    }
    if (rc == 0 && next != h[0].id.spp_total) {
        snprintf(err, CANDELA_ERR_LEN, "%s: the shards cover %" PRIu64 " of %" PRIu64 " samples per pixel", files[0], next,
                 h[0].id.spp_total);
        rc = -1;
    }
    /* sums added in shard order: the merge of the same films is bit-identical wherever it runs */
    Film sum = {0}, part = {0};
    char aov[64];
    candela_identity_value(h[0].id.text, "aov", aov, sizeof aov);
    int recorder = rc == 0 && strstr(aov, "recorder-debug") != NULL;
    if (rc == 0 && (film_alloc_like(&sum, &h[0], recorder) != 0 || film_alloc_like(&part, &h[0], recorder) != 0)) {
        snprintf(err, CANDELA_ERR_LEN, "merge: out of memory for a %ux%u film", h[0].width, h[0].height);
        rc = -1;
    }
    for (int k = 0; k < num_files && rc == 0; ++k) {
        const char *path = files[order[k]];
        Header hh;
        FILE *f = open_verified(path, &hh, err);
        if (!f) { rc = -1; break; }
        char why[160];
        if (film_load(&part, f) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%s: damaged film section", path);
            rc = -1;
        } else if (film_check(&part, hh.id.sample_count, why, sizeof why) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%.300s: not a film candela wrote: %s", path, why);
            rc = -1;
        }
        fclose(f);
        if (rc == 0) film_add(&sum, &part);
    }
    CandelaImage image = {0};
    if (rc == 0 && film_resolve(&sum, &image) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "merge: out of memory resolving the film");
        rc = -1;
    }
    /* the shards' dropped samples (path guiding's bootstrap, one per shard), said beside the rest */
    CandelaProvenance merged = {0};
    if (rc == 0 && sum.dropped) {
        char dropped[32];
        snprintf(dropped, sizeof dropped, "%u", sum.dropped);
        if ((provenance && candela_provenance_copy(&merged, provenance) != 0) ||
            candela_provenance_set(&merged, "candela:sppDropped", dropped) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "merge: out of memory");
            rc = -1;
        }
        provenance = &merged;
    }
    if (rc == 0) rc = candela_write_outputs_provenance(&image, out_exr, png, provenance, err);
    candela_provenance_free(&merged);
    candela_image_free(&image);
    film_free(&sum);
    film_free(&part);
    free(h);
    free(order);
    return rc;
}
