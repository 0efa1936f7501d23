/* renderer/app/batch.c: candela render --frames, a batch of animation frames from one session.
 *
 *   frame list (--frames) -> this task's share (--shard I/N, else SLURM_ARRAY_*) -> the scene
 *   loaded once (candela_session_open) -> every frame checked against the animation's time
 *   range -> per frame: skip if --resume and its outputs exist, else pose + render at
 *   t = frame / fps with the frame's seed, write EXR/PNG (temp + rename), append a JSON line.
 * Everything that can be wrong with the request is found before the first frame renders, so a
 * bad request writes nothing. A frame that fails later (a transform the scene cannot take at
 * that time, out of memory, an unwritable file) is reported with its number and the batch goes
 * on; the caller's exit status counts the failures. */
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "candela.h"
#include "clock.h"
#include "io.h"
#include "options_table.h"

#define MAX_FRAME_NUMBER 9999999     /* seven digits; a day of 120 fps is 10.4 million frames */
#define MAX_BATCH_FRAMES (1 << 20)

/* ---------------------------------------------------------------- frame seeds */

uint64_t candela_frame_seed(uint64_t seed, int64_t frame) {
    /* splitmix64 (Steele, Lea & Flood 2014): state advanced frame + 1 times, then mixed */
    uint64_t z = seed + (uint64_t)(frame + 1) * 0x9E3779B97F4A7C15ull;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

/* ---------------------------------------------------------------- the frame list */

typedef struct FrameList {
    int64_t *frames;
    size_t count, capacity;
} FrameList;

static int frames_push(FrameList *l, int64_t f) {
    if (l->count == l->capacity) {
        size_t cap = l->capacity ? 2 * l->capacity : 64;
        int64_t *p = realloc(l->frames, cap * sizeof *p);
        if (!p) return -1;
        l->frames = p;
        l->capacity = cap;
    }
    l->frames[l->count++] = f;
    return 0;
}

static int cmp_i64(const void *a, const void *b) {
    int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* A whole number in [0, MAX_FRAME_NUMBER] at *p; advances *p. */
static int parse_frame_number(const char **p, int64_t *out) {
    const char *s = *p;
    if (*s < '0' || *s > '9') return -1;
    int64_t v = 0;
    while (*s >= '0' && *s <= '9') {
        v = v * 10 + (*s - '0');
        if (v > MAX_FRAME_NUMBER) return -1;
        ++s;
    }
    *p = s;
    *out = v;
    return 0;
}

/* "A-B[:step]" or a comma list of frames and such ranges: sorted, each frame once. */
static int parse_frames(const char *spec, FrameList *l, char err[CANDELA_ERR_LEN]) {
    const char *p = spec;
    memset(l, 0, sizeof *l);
    for (;;) {
        int64_t a, b, step = 1;
        if (parse_frame_number(&p, &a) != 0) goto bad;
        b = a;
        if (*p == '-') {
            ++p;
            if (parse_frame_number(&p, &b) != 0 || b < a) goto bad;
            if (*p == ':') {
                ++p;
                if (parse_frame_number(&p, &step) != 0 || step < 1) goto bad;
            }
        }
        for (int64_t f = a; f <= b; f += step) {
            if (l->count >= MAX_BATCH_FRAMES) {
                snprintf(err, CANDELA_ERR_LEN, "candela: --frames '%.200s' lists more than %d frames", spec,
                         MAX_BATCH_FRAMES);
                return -1;
            }
            if (frames_push(l, f) != 0) {
                snprintf(err, CANDELA_ERR_LEN, "candela: out of memory");
                return -1;
            }
        }
        if (*p == 0) break;
        if (*p != ',') goto bad;
        ++p;
    }
    qsort(l->frames, l->count, sizeof *l->frames, cmp_i64);
    size_t w = 0;
    for (size_t r = 0; r < l->count; ++r)
        if (w == 0 || l->frames[r] != l->frames[w - 1]) l->frames[w++] = l->frames[r];
    l->count = w;
    return 0;
bad:
    snprintf(err, CANDELA_ERR_LEN,
             "candela: invalid --frames '%.200s' (expected A-B[:step] or a comma list of frames and ranges, "
             "whole numbers 0..%d, A <= B, step >= 1)",
             spec, MAX_FRAME_NUMBER);
    return -1;
}

/* ---------------------------------------------------------------- sharding */

/* A whole number in [lo, hi] that is all of s. */
static int parse_exact(const char *s, long lo, long hi, long *out) {
    if (!s || !*s) return -1;
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (errno || end == s || *end != 0 || v < lo || v > hi) return -1;
    *out = v;
    return 0;
}

/* This task's shard: --shard I/N, else a Slurm array task (SLURM_ARRAY_TASK_ID minus
 * SLURM_ARRAY_TASK_MIN, divided by SLURM_ARRAY_TASK_STEP when set, of SLURM_ARRAY_TASK_COUNT),
 * else 0/1. Shard i of n renders the frames at positions i, i + n, i + 2n, ... of the sorted
 * list (round-robin: every task gets a share of early and late frames, so a shot whose cost
 * grows along it still spreads evenly). */
static int resolve_shard(const char *spec, long *index, long *count, char what[96], char err[CANDELA_ERR_LEN]) {
    *index = 0;
    *count = 1;
    what[0] = 0;
    if (spec) {
        const char *slash = strchr(spec, '/');
        char left[32];
        long i, n;
        size_t len = slash ? (size_t)(slash - spec) : 0;
        if (!slash || len == 0 || len >= sizeof left) goto bad_spec;
        memcpy(left, spec, len);
        left[len] = 0;
        if (parse_exact(slash + 1, 1, 1000000, &n) != 0 || parse_exact(left, 0, n - 1, &i) != 0) goto bad_spec;
        *index = i;
        *count = n;
        snprintf(what, 96, "shard %ld/%ld", i, n);
        return 0;
    bad_spec:
        snprintf(err, CANDELA_ERR_LEN, "candela: invalid --shard '%.100s' (expected I/N with 0 <= I < N, N <= 1000000)",
                 spec);
        return -1;
    }
    const char *id_s = getenv("SLURM_ARRAY_TASK_ID");
    if (!id_s) return 0;
    const char *count_s = getenv("SLURM_ARRAY_TASK_COUNT"), *min_s = getenv("SLURM_ARRAY_TASK_MIN");
    const char *step_s = getenv("SLURM_ARRAY_TASK_STEP");
    long id, n, min = 0, step = 1;
    if (parse_exact(id_s, 0, LONG_MAX / 2, &id) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "candela: invalid SLURM_ARRAY_TASK_ID '%.60s' (expected a whole number >= 0)", id_s);
        return -1;
    }
    if (!count_s || parse_exact(count_s, 1, 1000000, &n) != 0) {
        snprintf(err, CANDELA_ERR_LEN,
                 "candela: SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is %s%.60s%s (expected 1..1000000)",
                 count_s ? "'" : "missing", count_s ? count_s : "", count_s ? "'" : "");
        return -1;
    }
    if (min_s && parse_exact(min_s, 0, id, &min) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "candela: invalid SLURM_ARRAY_TASK_MIN '%.60s' (expected 0..SLURM_ARRAY_TASK_ID %ld)",
                 min_s, id);
        return -1;
    }
    if (step_s && parse_exact(step_s, 1, LONG_MAX / 2, &step) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "candela: invalid SLURM_ARRAY_TASK_STEP '%.60s'", step_s);
        return -1;
    }
    long i = (id - min) / step;
    if ((id - min) % step != 0 || i >= n) {
        snprintf(err, CANDELA_ERR_LEN,
                 "candela: Slurm array task %ld (min %ld, step %ld) is not one of SLURM_ARRAY_TASK_COUNT=%ld tasks "
                 "(candela shards a dense array, e.g. --array=0-%ld or 1-%ld)",
                 id, min, step, n, n - 1, n);
        return -1;
    }
    *index = i;
    *count = n;
    snprintf(what, 96, "Slurm array task %ld = shard %ld/%ld", id, i, n);
    return 0;
}

/* ---------------------------------------------------------------- output names */

/* The last run of '#' in the file name part of pattern: *at and *len (len 0: none). */
static void find_pattern(const char *pattern, size_t *at, size_t *len) {
    const char *base = strrchr(pattern, '/');
    base = base ? base + 1 : pattern;
    const char *end = NULL, *start = NULL;
    for (const char *c = base; *c; ++c)
        if (*c == '#') {
            if (!end || c != end) start = c;
            end = c + 1;
        }
    *at = start ? (size_t)(start - pattern) : 0;
    *len = start ? (size_t)(end - start) : 0;
}

static void frame_name(const char *pattern, int64_t frame, char out[PATH_MAX]) {
    size_t at, len;
    find_pattern(pattern, &at, &len);
    if (!len) {
        snprintf(out, PATH_MAX, "%s", pattern);
        return;
    }
    snprintf(out, PATH_MAX, "%.*s%0*lld%s", (int)at, pattern, (int)len, (long long)frame, pattern + at + len);
}

/* NAME.exr -> NAME.partial.exr */
static void partial_name(const char *path, char out[PATH_MAX]) {
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    int n;
    if (!dot || (slash && dot < slash)) n = snprintf(out, PATH_MAX, "%s.partial", path);
    else n = snprintf(out, PATH_MAX, "%.*s.partial%s", (int)(dot - path), path, dot);
    if (n >= PATH_MAX) out[0] = 0; /* never a truncated name that might be another file */
}

/* --resume: a frame counts as done only when its EXR reads back whole (io_exr_complete: every
 * chunk there, no decompression, so resuming a long batch of large frames stays cheap) at the
 * batch's resolution, and its PNG, when asked for, decodes at that size too. The name alone proved little: a file copied in by hand, a disk
 * that filled during someone else's write, a 0-byte placeholder. NULL when done, else why not. */
static const char *frame_done(const char *exr, const char *png, int width, int height, const char *identity,
                              int *other_options, char why[CANDELA_ERR_LEN]) {
    char ioerr[IO_ERR_LEN];
    struct stat st;
    *other_options = 0;
    if (stat(exr, &st) != 0) {
        snprintf(why, CANDELA_ERR_LEN, "missing");
        return why;
    }
    int w = 0, h = 0;
    char recorded[CANDELA_IDENTITY_LEN];
    if (io_exr_complete_attribute(exr, &w, &h, "candela:identity", recorded, sizeof recorded, ioerr) != 0) {
        snprintf(why, CANDELA_ERR_LEN, "%s", ioerr);
        return why;
    }
    /* rendered with other options (issue 27): the frame's candela:identity is not this run's */
    if (!recorded[0]) {
        snprintf(why, CANDELA_ERR_LEN, "%.400s records no identity (candela:identity: not written by this candela)", exr);
        *other_options = 1;
        return why;
    }
    if (strcmp(recorded, identity) != 0) {
        char diff[CANDELA_ERR_LEN];
        if (candela_identity_differences(recorded, identity, "this run", diff, sizeof diff) == 0)
            snprintf(diff, sizeof diff, "the options differ");
        snprintf(why, CANDELA_ERR_LEN, "%.200s was rendered with other options: %.250s", exr, diff);
        *other_options = 1;
        return why;
    }
    if (w != width || h != height) {
        snprintf(why, CANDELA_ERR_LEN, "%.400s: %dx%d, not the batch's %dx%d", exr, w, h, width, height);
        return why;
    }
    if (png) {
        if (stat(png, &st) != 0) {
            snprintf(why, CANDELA_ERR_LEN, "%.400s: missing", png);
            return why;
        }
        IoImage im;
        if (io_load_image(png, IO_IMAGE_SRGB | IO_IMAGE_KEEP_8BIT, &im, ioerr) != 0) {
            snprintf(why, CANDELA_ERR_LEN, "%s", ioerr);
            return why;
        }
        int pw = im.width, ph = im.height;
        io_image_free(&im);
        if (pw != width || ph != height) {
            snprintf(why, CANDELA_ERR_LEN, "%.400s: %dx%d, not the batch's %dx%d", png, pw, ph, width, height);
            return why;
        }
    }
    return NULL;
}

/* The outputs rule for a batch: each frame's EXR and PNG (and their .partial names with
 * --save-partial) against the run's inputs and outputs, and the EXR against the PNG. Names of
 * different frames differ in their frame number. */
static int check_frame_names(const CandelaBatchOptions *b, const FrameList *mine, char err[CANDELA_ERR_LEN]) {
    for (size_t k = 0; k < mine->count; ++k) {
        char names[4][PATH_MAX], role[4][64];
        int n = 0;
        frame_name(b->exr_pattern, mine->frames[k], names[n]);
        snprintf(role[n++], sizeof role[0], "frame %lld's EXR", (long long)mine->frames[k]);
        if (b->png_pattern) {
            frame_name(b->png_pattern, mine->frames[k], names[n]);
            snprintf(role[n++], sizeof role[0], "frame %lld's PNG", (long long)mine->frames[k]);
        }
        for (int j = 0, m = n; b->save_partial && j < m; ++j) {
            partial_name(names[j], names[n]);
            snprintf(role[n], sizeof role[0], "%.50s (.partial)", role[j]);
            if (names[n][0]) ++n;
        }
        IoFileId id[4];
        for (int j = 0; j < n; ++j) {
            char e[CANDELA_ERR_LEN];
            if (candela_run_check_output(b->run, names[j], role[j], e) != 0) {
                snprintf(err, CANDELA_ERR_LEN, "candela: %.490s", e);
                return -1;
            }
            (void)io_file_id(names[j], &id[j]);
            for (int i = 0; i < j; ++i)
                if (io_same_file(&id[i], &id[j])) {
                    snprintf(err, CANDELA_ERR_LEN, "candela: %.300s: %.64s and %.64s are the same file", names[j], role[i], role[j]);
                    return -1;
                }
        }
    }
    return 0;
}

/* ---------------------------------------------------------------- the frame log */

/* One line appended with one write() to a file opened O_APPEND: lines of concurrent tasks
 * (a Slurm array sharing the log on a local file system) do not interleave. */
static int append_line(const char *path, const char *line, char err[CANDELA_ERR_LEN]) {
    int fd = open(path, O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0) {
        snprintf(err, CANDELA_ERR_LEN, "%.400s: cannot open for appending: %s", path, strerror(errno));
        return -1;
    }
    size_t n = strlen(line);
    ssize_t w = write(fd, line, n);
    int rc = (w == (ssize_t)n && close(fd) == 0) ? 0 : -1;
    if (w != (ssize_t)n) close(fd);
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%.400s: cannot append the frame's statistics", path);
    return rc;
}

/* The provenance attribute name of the batch ("" without it). */
static const char *batch_attribute(const CandelaBatchOptions *b, const char *name) {
    for (int k = 0; b->provenance && k < b->provenance->count; ++k)
        if (strcmp(b->provenance->attrs[k].name, name) == 0) return b->provenance->attrs[k].value;
    return "";
}

/* One --frame-stats line; identity: the frame's image identity (its EXR's candela:identity,
 * what --resume compares; "" when too long to record). */
static int log_frame(const CandelaBatchOptions *b, const CandelaOptions *fo, int64_t frame, double seconds,
                     const char *status, const char *exr, const char *problem, const CandelaStats *stats,
                     const CandelaFrameInfo *info, const char *identity, char err[CANDELA_ERR_LEN]) {
    if (!b->stats_jsonl) return 0;
    char *stats_json = NULL;
    if (stats && candela_stats_json_line(fo, stats, &stats_json) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "candela: out of memory");
        return -1;
    }
    /* JSON string literals through io_json_quote (nlohmann/json's escaping) */
    char *qexr = io_json_quote(exr), *qproblem = io_json_quote(problem ? problem : "");
    /* how the frame was made (issue 27): the program (the --version line) and the image identity */
    char *qsoftware = io_json_quote(batch_attribute(b, "software")), *qidentity = io_json_quote(identity ? identity : "");
    size_t size = (qexr ? strlen(qexr) : 0) + (qproblem ? strlen(qproblem) : 0) + (stats_json ? strlen(stats_json) : 0) +
                  (qsoftware ? strlen(qsoftware) : 0) + (qidentity ? strlen(qidentity) : 0) + 512;
    char *line = qexr && qproblem && qsoftware && qidentity ? malloc(size) : NULL;
    if (!line) {
        free(stats_json);
        free(qexr);
        free(qproblem);
        free(qsoftware);
        free(qidentity);
        snprintf(err, CANDELA_ERR_LEN, "candela: out of memory");
        return -1;
    }
    snprintf(line, size,
             "{\"frame\": %lld, \"time\": %.9g, \"seed\": %llu, \"status\": \"%s\", \"output\": %s, \"error\": %s, "
             "\"software\": %s, \"identity\": %s, "
             "\"pose_seconds\": %.6f, \"instances_moved\": %u, \"cachepoint_build_seconds\": %.6f, \"stats\": %s}\n",
             (long long)frame, seconds, (unsigned long long)fo->seed, status, qexr, qproblem, qsoftware, qidentity,
             info ? info->time_pose : 0.0, info ? info->instances_moved : 0u, stats ? stats->time_cachepoints : 0.0,
             stats_json ? stats_json : "null");
    int rc = append_line(b->stats_jsonl, line, err);
    free(line);
    free(stats_json);
    free(qexr);
    free(qproblem);
    free(qsoftware);
    free(qidentity);
    return rc;
}

/* ---------------------------------------------------------------- the batch */

int candela_batch_render(const CandelaOptions *o, const CandelaBatchOptions *b, int *interrupted,
                         char err[CANDELA_ERR_LEN]) {
    *interrupted = 0;
    double fps = b->fps > 0.0 ? b->fps : 24.0;
    if (!(fps > 0.0) || !isfinite(fps) || fps > 1e6) {
        snprintf(err, CANDELA_ERR_LEN, "candela: invalid --fps %g (expected a number in (0, 1e6])", b->fps);
        return -1;
    }
    FrameList all;
    if (parse_frames(b->frames, &all, err) != 0) {
        free(all.frames);
        return -1;
    }
    long shard, shards;
    char shard_what[96];
    if (resolve_shard(b->shard, &shard, &shards, shard_what, err) != 0) {
        free(all.frames);
        return -1;
    }
    size_t at, len;
    find_pattern(b->exr_pattern, &at, &len);
    if (!len && all.count > 1) {
        snprintf(err, CANDELA_ERR_LEN,
                 "%.400s: the output needs a frame pattern for %zu frames (a run of '#', e.g. shot.####.exr)",
                 b->exr_pattern, all.count);
        free(all.frames);
        return -1;
    }
    if (b->png_pattern) {
        find_pattern(b->png_pattern, &at, &len);
        if (!len && all.count > 1) {
            snprintf(err, CANDELA_ERR_LEN, "%.400s: the PNG name needs a frame pattern for %zu frames (a run of '#')",
                     b->png_pattern, all.count);
            free(all.frames);
            return -1;
        }
    }
    /* this task's frames */
    FrameList mine = {0};
    for (size_t k = (size_t)shard; k < all.count; k += (size_t)shards)
        if (frames_push(&mine, all.frames[k]) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "candela: out of memory");
            free(all.frames);
            free(mine.frames);
            return -1;
        }

    /* every frame's outputs against the run's files (the outputs rule, candela.h) and against
     * each other, before the scene loads */
    if (b->run && check_frame_names(b, &mine, err) != 0) {
        free(all.frames);
        free(mine.frames);
        return -1;
    }
    if (b->dry_run) {
        printf("shard %ld/%ld\n", shard, shards);
        for (size_t k = 0; k < mine.count; ++k) {
            char exr[PATH_MAX];
            frame_name(b->exr_pattern, mine.frames[k], exr);
            printf("frame %lld %s\n", (long long)mine.frames[k], exr);
        }
        free(all.frames);
        free(mine.frames);
        return 0;
    }
    CandelaSession *session = NULL;
    CandelaSessionInfo info;
    if (candela_session_open(o, &session, &info, err) != 0) {
        free(all.frames);
        free(mine.frames);
        return -1;
    }
    /* the whole request against the animation, before any frame renders: a range typo must not
     * render (or overwrite) half a shot. A still scene (no channels) renders any frame. */
    if (info.num_channels > 0) {
        const double slack = 1e-5 * fmax(1.0, fmax(fabs(info.anim_start), fabs(info.anim_end)));
        int64_t first = all.frames[0], last = all.frames[all.count - 1];
        if ((double)first / fps < info.anim_start - slack || (double)last / fps > info.anim_end + slack) {
            double lo = ceil((info.anim_start - slack) * fps) + 0.0 /* not -0 */, hi = floor((info.anim_end + slack) * fps);
            snprintf(err, CANDELA_ERR_LEN,
                     "%s: --frames %lld-%lld at %g fps is %g to %g s, outside the animation (%g to %g s: frames %.0f-%.0f)",
                     o->scene_path, (long long)first, (long long)last, fps, (double)first / fps, (double)last / fps,
                     info.anim_start, info.anim_end, lo, hi);
            candela_session_close(session);
            free(all.frames);
            free(mine.frames);
            return -1;
        }
    }
    if (!o->quiet)
        fprintf(stderr, "candela: %zu of %zu frames%s%s (%g fps), scene loaded in %.3fs, %u animation channels\n",
                mine.count, all.count, shard_what[0] ? " for " : "", shard_what, fps, info.time_load, info.num_channels);

    /* --resume: each frame's identity (issue 27) against its EXR's candela:identity; --frame-stats
     * records it */
    uint64_t scene_hash = 0;
    char identity[CANDELA_IDENTITY_LEN];
    identity[0] = 0;
    if ((b->resume || b->stats_jsonl) && candela_scene_hash(o->scene_path, &scene_hash, err) != 0) {
        candela_session_close(session);
        free(all.frames);
        free(mine.frames);
        return -1;
    }
    int failed = 0;
    size_t rendered = 0, skipped = 0;
    double render_seconds = 0.0;
    for (size_t k = 0; k < mine.count; ++k) {
        const int64_t frame = mine.frames[k];
        const double seconds = (double)frame / fps;
        char exr[PATH_MAX], png[PATH_MAX];
        frame_name(b->exr_pattern, frame, exr);
        if (b->png_pattern) frame_name(b->png_pattern, frame, png);
        /* a final name exists only once candela's own write completed (temp + rename), but the
         * file under it may be anyone's: it must read back whole */
        char why[CANDELA_ERR_LEN];
        const char *not_done = why;
        int other_options = 0;
        if (b->resume || b->stats_jsonl) {
            CandelaOptions io = *o;
            io.seed = candela_frame_seed(o->seed, frame);
            if (candela_image_identity(&io, scene_hash, info.width, info.height, identity, sizeof identity) != 0)
                identity[0] = 0; /* too long to record: never equal to a frame's */
        }
        if (b->resume) {
            not_done = frame_done(exr, b->png_pattern ? png : NULL, info.image_width, info.image_height, identity,
                                  &other_options, why);
        }
        if (b->resume && other_options) /* said even with --quiet: the frame is replaced */
            fprintf(stderr, "candela: frame %lld: %s; rendering it again\n", (long long)frame, not_done);
        else if (b->resume && not_done && strcmp(not_done, "missing") != 0) /* a warning: said even with --quiet */
            fprintf(stderr, "candela: warning: frame %lld: %s; rendered again (--resume)\n", (long long)frame, not_done);
        if (b->resume && !not_done) {
            ++skipped;
            CandelaOptions so = *o;
            so.seed = candela_frame_seed(o->seed, frame);
            char lerr[CANDELA_ERR_LEN];
            if (log_frame(b, &so, frame, seconds, "skipped", exr, NULL, NULL, NULL, identity, lerr) != 0)
                fprintf(stderr, "candela: frame %lld: %s\n", (long long)frame, lerr);
            if (!o->quiet) fprintf(stderr, "candela: [%zu/%zu] frame %lld: %s exists, skipped (--resume)\n", k + 1,
                                   mine.count, (long long)frame, exr);
            continue;
        }
        CandelaOptions fo = *o;
        fo.seed = candela_frame_seed(o->seed, frame);
        fo.quiet = 1; /* one batch progress line per frame instead of each render's bar */
        /* one writer per frame: a task rendering it already (overlapping shards, a resumed batch
         * beside the original) makes this one a failed frame, said so, not a second writer */
        IoLock lock;
        char lock_err[IO_ERR_LEN];
        if (io_lock_output(exr, &lock, lock_err) != 0) {
            ++failed;
            fprintf(stderr, "candela: frame %lld failed: %s\n", (long long)frame, lock_err);
            char lerr[CANDELA_ERR_LEN];
            if (log_frame(b, &fo, frame, seconds, "failed", exr, lock_err, NULL, NULL, identity, lerr) != 0)
                fprintf(stderr, "candela: frame %lld: %s\n", (long long)frame, lerr);
            continue;
        }
        CandelaImage image;
        CandelaStats stats;
        CandelaFrameInfo finfo;
        char ferr[CANDELA_ERR_LEN];
        double t0 = clock_seconds();
        const int have_image = candela_session_render(session, &fo, seconds, &image, &stats, &finfo, ferr) == 0;
        int rc = have_image ? 0 : -1;
        const char *status = "ok";
        const char *out_exr = exr, *out_png = b->png_pattern ? png : NULL;
        char exr_partial[PATH_MAX], png_partial[PATH_MAX];
        if (rc == 0 && stats.interrupted) {
            *interrupted = 1;
            status = "interrupted";
            if (b->save_partial) {
                partial_name(exr, exr_partial);
                out_exr = exr_partial;
                if (out_png) {
                    partial_name(png, png_partial);
                    out_png = png_partial;
                }
            } else {
                out_exr = NULL;
            }
        }
        if (rc == 0 && out_exr) {
            /* the batch's provenance with this frame's render (its seed, spp, time) */
            CandelaProvenance fp = {0};
            char frame_text[32];
            snprintf(frame_text, sizeof frame_text, "%lld", (long long)frame);
            int prc = b->provenance ? candela_provenance_copy(&fp, b->provenance) : 0;
            if (prc == 0 && b->provenance)
                prc = candela_provenance_render(&fp, &fo, &stats) | candela_provenance_set(&fp, "candela:frame", frame_text) |
                      candela_provenance_identity(&fp, &fo, image.full_width, image.full_height);
            if (prc != 0) {
                snprintf(ferr, CANDELA_ERR_LEN, "%.400s: out of memory", out_exr);
                rc = -1;
            } else if (candela_write_outputs_provenance(&image, out_exr, out_png, b->provenance ? &fp : NULL, ferr) != 0) {
                rc = -1;
            }
            candela_provenance_free(&fp);
        }
        if (rc != 0) {
            status = "failed";
            ++failed;
            fprintf(stderr, "candela: frame %lld failed: %s\n", (long long)frame, ferr);
        }
        double dt = clock_seconds() - t0;
        if (rc == 0 && !*interrupted) {
            ++rendered;
            render_seconds += dt;
        }
        char lerr[CANDELA_ERR_LEN];
        if (log_frame(b, &fo, frame, seconds, status, out_exr ? out_exr : "", rc != 0 ? ferr : NULL,
                      have_image ? &stats : NULL, &finfo, identity, lerr) != 0)
            fprintf(stderr, "candela: frame %lld: %s\n", (long long)frame, lerr);
        if (have_image) candela_image_free(&image);
        io_unlock_output(&lock);
        if (*interrupted) {
            fprintf(stderr, "candela: interrupted in frame %lld after %d of %d spp; %s\n", (long long)frame,
                    stats.spp_done, o->spp, b->save_partial ? "its image so far is under a .partial name" : "it was not written");
            break;
        }
        if (!o->quiet && rc == 0) {
            size_t left = mine.count - k - 1;
            double eta = rendered ? render_seconds / (double)rendered * (double)left : 0.0;
            fprintf(stderr,
                    "candela: [%zu/%zu] frame %lld (t = %.4g s) in %.3fs (pose %.4fs, %u instances moved; cache points "
                    "%.4fs); ETA %.1fs\n",
                    k + 1, mine.count, (long long)frame, seconds, dt, finfo.time_pose, finfo.instances_moved,
                    stats.time_cachepoints, eta);
        }
        if (o->stop && *o->stop) {
            *interrupted = 1;
            break;
        }
    }
    if (!o->quiet && !*interrupted)
        fprintf(stderr, "candela: batch done: %zu rendered, %zu skipped, %d failed\n", rendered, skipped, failed);
    candela_session_close(session);
    free(all.frames);
    free(mine.frames);
    return failed;
}
