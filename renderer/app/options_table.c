/* renderer/app/options_table.c: every flag of the command line, one row each (options_table.h),
 * and the parser, help and suggestions that read the rows.
 *
 * A row keeps a flag's semantics as they were when main.c and flags.c parsed them with if-chains:
 * the same ranges, the same messages (tests check them), the same fields. Values come as
 * `--flag value` or `--flag=value`. */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "options_table.h"

/* The largest image: 16384 per side, 64 Mpixels in all (the film takes ~100 bytes per pixel). */
#define MAX_RES_SIDE 16384
#define MAX_RES_PIXELS (64 << 20)

/* --- custom values ------------------------------------------------------------------------ */

/* "A<sep>B" as two base-10 longs, each checked by strtol (sscanf's %d wrapped 4294967304 to 8):
 * 0 when both parse and nothing follows B. */
static int parse_long_pair(const char *v, char sep, long *a, long *b) {
    char *mid = NULL, *end = NULL;
    errno = 0;
    *a = strtol(v, &mid, 10);
    if (errno || mid == v || *mid != sep) return -1;
    *b = strtol(mid + 1, &end, 10);
    return errno || end == mid + 1 || *end != 0 ? -1 : 0;
}

static int set_res(void *base, const char *flag, const char *v, char err[CANDELA_ERR_LEN]) {
    (void)flag;
    CandelaOptions *o = base;
    long w = 0, h = 0;
    if (parse_long_pair(v, 'x', &w, &h) != 0 || w < 1 || w > MAX_RES_SIDE || h < 1 || h > MAX_RES_SIDE ||
        (long long)w * h > MAX_RES_PIXELS) {
        snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for --res (expected WxH, 1..%d each, at most %d megapixels)", v,
                 MAX_RES_SIDE, MAX_RES_PIXELS >> 20);
        return -1;
    }
    o->width = (int)w;
    o->height = (int)h;
    return 0;
}

/* --crop X0,Y0,X1,Y1: four base-10 integers; the box must hold a pixel. Whether it lies inside
 * the image is checked where the resolution is known (candela_options_check with --res, the
 * scene's camera otherwise). "none" is the identity's form of no crop. */
static int set_crop(void *base, const char *flag, const char *v, char err[CANDELA_ERR_LEN]) {
    (void)flag;
    CandelaOptions *o = base;
    if (strcmp(v, "none") == 0) {
        memset(o->crop, 0, sizeof o->crop);
        return 0;
    }
    long c[4];
    const char *p = v;
    for (int k = 0; k < 4; ++k) {
        char *end = NULL;
        errno = 0;
        c[k] = strtol(p, &end, 10);
        if (errno || end == p || !(*p >= '0' && *p <= '9') || (k < 3 ? *end != ',' : *end != 0) || c[k] < 0 || c[k] > MAX_RES_SIDE) {
            snprintf(err, CANDELA_ERR_LEN,
                     "invalid value '%.200s' for --crop (expected X0,Y0,X1,Y1: four integers in 0..%d, the pixels "
                     "[X0, X1) x [Y0, Y1))", v, MAX_RES_SIDE);
            return -1;
        }
        p = end + 1;
    }
    if (c[2] <= c[0] || c[3] <= c[1]) {
        snprintf(err, CANDELA_ERR_LEN, "--crop %.200s is an empty box (X1 must be above X0 and Y1 above Y0)", v);
        return -1;
    }
    for (int k = 0; k < 4; ++k) o->crop[k] = (int)c[k];
    return 0;
}

static int set_confine(void *base, const char *flag, const char *v, char err[CANDELA_ERR_LEN]) {
    (void)flag;
    if (!*v) { /* a farm script's unset variable: never "no confinement" */
        snprintf(err, CANDELA_ERR_LEN, "--confine-to needs a folder, not an empty name");
        return -1;
    }
    ((CandelaOptions *)base)->confine_dir = v;
    return 0;
}

/* NAME ends in ext, in any case (x.PLY is a PLY file). */
static int has_extension_nocase(const char *name, const char *ext) {
    size_t n = strlen(name), e = strlen(ext);
    return n > e && strcasecmp(name + n - e, ext) == 0;
}

static int set_dump(void *base, const char *flag, const char *v, char err[CANDELA_ERR_LEN]) {
    (void)flag;
    if (!has_extension_nocase(v, ".ply")) {
        snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for --dump-cachepoints (expected FILE.ply)", v);
        return -1;
    }
    ((CandelaOptions *)base)->cachepoint_dump_path = v;
    return 0;
}

static const char *const AOV_NAMES[] = {"recorder-debug", "cachepoint", "spp", NULL};

/* One AOV name per --aov (repeatable); the identity's form: a comma list of them, or none,
 * which replaces the set instead of adding to it. */
static int set_aov(void *base, const char *flag, const char *v, char err[CANDELA_ERR_LEN]) {
    (void)flag;
    CandelaOptions *o = base;
    int *on[3] = {&o->aov_recorder_debug, &o->aov_selection, &o->aov_spp};
    int list = strchr(v, ',') != NULL || strcmp(v, "none") == 0;
    int set[3] = {0, 0, 0};
    for (const char *c = v; list || c == v;) {
        size_t len = strcspn(c, ",");
        int k = 0;
        while (AOV_NAMES[k] && !(strlen(AOV_NAMES[k]) == len && strncmp(c, AOV_NAMES[k], len) == 0)) ++k;
        if (!AOV_NAMES[k] && !(list && len == 4 && strncmp(c, "none", 4) == 0)) {
            snprintf(err, CANDELA_ERR_LEN, "unknown AOV '%.200s' (recorder-debug, cachepoint, spp)", v);
            return -1;
        }
        if (AOV_NAMES[k]) set[k] = 1;
        if (!c[len]) break;
        c += len + 1;
    }
    for (int k = 0; k < 3; ++k)
        if (list) *on[k] = set[k];
        else if (set[k]) *on[k] = 1; /* repeatable: one AOV each */
    return 0;
}

static int set_sample_shard(void *base, const char *flag, const char *v, char err[CANDELA_ERR_LEN]) {
    (void)flag;
    CandelaCommandLine *cl = base;
    long si = 0, sn = 0;
    if (parse_long_pair(v, '/', &si, &sn) != 0 || si < 0 || sn < 1 || sn > 65536 || si >= sn) {
        snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for --sample-shard (expected I/N with 0 <= I < N <= 65536)", v);
        return -1;
    }
    cl->o.shard_index = (uint32_t)si;
    cl->o.shard_count = (uint32_t)sn;
    return 0;
}

static int set_at(void *base, const char *flag, const char *v, char err[CANDELA_ERR_LEN]) {
    (void)flag;
    CandelaCommandLine *cl = base;
    char *end;
    const char *c = v;
    for (int k = 0; k < 3; ++k) {
        cl->o.guide_dump_at[k] = strtof(c, &end);
        if (end == c || !isfinite(cl->o.guide_dump_at[k]) || (k < 2 && *end != ',') || (k == 2 && *end)) {
            snprintf(err, CANDELA_ERR_LEN, "--at wants X,Y,Z (three finite numbers), not '%.200s'", v);
            return -1;
        }
        c = end + 1;
    }
    cl->have_at = 1;
    return 0;
}


/* --- custom values as JSON (candela_options_json) ------------------------------------------- */

static void json_string_or_null(FILE *f, const char *s) {
    if (s) candela_json_string(f, s);
    else fputs("null", f);
}
static void get_res(const CandelaOptions *o, FILE *f) {
    if (o->width > 0 && o->height > 0) fprintf(f, "\"%dx%d\"", o->width, o->height);
    else fputs("null", f); /* from the camera's aspect */
}
static void get_crop(const CandelaOptions *o, FILE *f) {
    if (o->crop[2] > 0) fprintf(f, "[%d, %d, %d, %d]", o->crop[0], o->crop[1], o->crop[2], o->crop[3]);
    else fputs("null", f);
}
static void show_crop(const CandelaOptions *o, char *buf, size_t size) {
    if (o->crop[2] > 0) snprintf(buf, size, "%d,%d,%d,%d", o->crop[0], o->crop[1], o->crop[2], o->crop[3]);
    else snprintf(buf, size, "none");
}
static void get_confine(const CandelaOptions *o, FILE *f) { json_string_or_null(f, o->confine_dir); }
static void get_dump(const CandelaOptions *o, FILE *f) { json_string_or_null(f, o->cachepoint_dump_path); }
static void get_aov(const CandelaOptions *o, FILE *f) {
    const int on[3] = {o->aov_recorder_debug, o->aov_selection, o->aov_spp};
    fputc('[', f);
    for (int k = 0, first = 1; k < 3; ++k)
        if (on[k]) {
            fprintf(f, "%s\"%s\"", first ? "" : ", ", AOV_NAMES[k]);
            first = 0;
        }
    fputc(']', f);
}
static void show_res(const CandelaOptions *o, char *buf, size_t size) { snprintf(buf, size, "%dx%d", o->width, o->height); }
static void show_aov(const CandelaOptions *o, char *buf, size_t size) {
    const int on[3] = {o->aov_recorder_debug, o->aov_selection, o->aov_spp};
    size_t n = 0;
    buf[0] = 0;
    for (int k = 0; k < 3; ++k)
        if (on[k] && n < size) n += (size_t)snprintf(buf + n, size - n, "%s%s", n ? "," : "", AOV_NAMES[k]);
    if (n == 0) snprintf(buf, size, "none");
}
static void get_sample_shard(const CandelaOptions *o, FILE *f) {
    if (o->shard_count) fprintf(f, "\"%u/%u\"", o->shard_index, o->shard_count);
    else fputs("null", f);
}
static void get_at(const CandelaOptions *o, FILE *f) {
    if (o->guide_dump_prefix)
        fprintf(f, "[%.9g, %.9g, %.9g]", (double)o->guide_dump_at[0], (double)o->guide_dump_at[1], (double)o->guide_dump_at[2]);
    else fputs("null", f);
}

/* --- choices ------------------------------------------------------------------------------ */

static const char *const ON_OFF_AUTO[] = {"on", "off", "auto", NULL};
static const int ON_OFF_AUTO_VALUES[] = {1, 0, 2};
static const char *const ON_OFF[] = {"on", "off", NULL};
static const int ON_OFF_VALUES[] = {1, 0};
static const int ON_OFF_PROGRESSIVE[] = {1, 2}; /* 0 stays "the default" (CandelaOptions) */
static const char *const POOLING[] = {"off", "points", "lights", NULL};
static const int POOLING_VALUES[] = {0, 1, 2};
static const char *const BUILD[] = {"cut", "linear", NULL};
static const int BUILD_VALUES[] = {0, 1};
static const char *const SAMPLER[] = {"sobol", "independent", NULL};
static const int SAMPLER_VALUES[] = {CANDELA_SAMPLER_SOBOL, CANDELA_SAMPLER_INDEPENDENT};
static const char *const GUIDING[] = {"off", "mis", "ris", "auto", NULL};
static const int GUIDING_VALUES[] = {CANDELA_GUIDING_OFF, CANDELA_GUIDING_MIS, CANDELA_GUIDING_RIS, CANDELA_GUIDING_AUTO};
static const char *const GUIDE_ROULETTE[] = {"corrected", "adjoint", NULL};
static const int GUIDE_ROULETTE_VALUES[] = {CANDELA_GUIDE_ROULETTE_CORRECTED, CANDELA_GUIDE_ROULETTE_ADJOINT};
static const char *const LIGHT_SAMPLER[] = {"auto", "uniform", "power", "tree", "optimal", "cachepoints", NULL};
static const int LIGHT_SAMPLER_VALUES[] = {CANDELA_LIGHT_SAMPLER_AUTO, CANDELA_LIGHT_SAMPLER_UNIFORM,
                                           CANDELA_LIGHT_SAMPLER_POWER, CANDELA_LIGHT_SAMPLER_TREE,
                                           CANDELA_LIGHT_SAMPLER_OPTIMAL, CANDELA_LIGHT_SAMPLER_CACHEPOINTS};
static const char *const LIGHT_MODEL[] = {"gltf", "blender3", NULL};
static const int LIGHT_MODEL_VALUES[] = {CANDELA_LIGHT_MODEL_GLTF, CANDELA_LIGHT_MODEL_BLENDER3};
static const int MATERIAL_MODEL_VALUES[] = {CANDELA_MATERIAL_MODEL_GLTF, CANDELA_MATERIAL_MODEL_BLENDER3};
static const char *const LIGHT_UNITS[] = {"blender", "raw", NULL};
static const int LIGHT_UNITS_VALUES[] = {CANDELA_LIGHT_UNITS_BLENDER, CANDELA_LIGHT_UNITS_RAW};

/* --- the table ---------------------------------------------------------------------------- */

/* Who takes what: a render flag goes to every rendering command and to compare's variants
 * (except the few that are the same for every variant or name files); CLI flags belong to render
 * (and some to guide-dump, bench, merge) but the other rendering commands parse them too, to
 * refuse them with a message of their own, as before the table. */
#define RENDERING (CANDELA_CMD_RENDER | CANDELA_CMD_BENCH | CANDELA_CMD_GUIDE_DUMP | CANDELA_CMD_COMPARE)
#define ALL_RENDER (RENDERING | CANDELA_CMD_VARIANT)
#define NOT_RENDER(cmds) (RENDERING & ~(unsigned)(cmds))

#define RO(f) 1, offsetof(CandelaOptions, f), 0     /* a render option that never changes the image */
#define IMG(f) 1, offsetof(CandelaOptions, f), 1    /* a render option that changes the image */
#define CL(f) 0, offsetof(CandelaCommandLine, f), 0 /* a field of the command line */

#define SWITCH(name, alias, where, cmds, tol, help, long_help) \
    {name, alias, CANDELA_FLAG_SWITCH, NULL, 0, 0, NULL, NULL, NULL, where, CANDELA_FIELD_INT, NULL, cmds, tol, NULL, help, long_help}
#define INT(name, meta, lo, hi, where, ft, cmds, tol, ex, help, long_help) \
    {name, NULL, CANDELA_FLAG_INT, meta, lo, hi, NULL, NULL, NULL, where, ft, NULL, cmds, tol, ex, help, long_help}
#define FLOAT(name, meta, lo, hi, where, ft, cmds, tol, ex, help, long_help) \
    {name, NULL, CANDELA_FLAG_FLOAT, meta, lo, hi, NULL, NULL, NULL, where, ft, NULL, cmds, tol, ex, help, long_help}
#define CHOICE(name, meta, names, values, what, where, cmds, ex, help, long_help) \
    {name, NULL, CANDELA_FLAG_CHOICE, meta, 0, 0, names, values, what, where, CANDELA_FIELD_INT, NULL, cmds, 0, ex, help, long_help}
#define STRING(name, alias, meta, where, cmds, tol, ex, help, long_help) \
    {name, alias, CANDELA_FLAG_STRING, meta, 0, 0, NULL, NULL, NULL, where, CANDELA_FIELD_STR, NULL, cmds, tol, ex, help, long_help}
#define CUSTOM(name, meta, render, image, set, get, show, cmds, tol, ex, help, long_help) \
    {name, NULL, CANDELA_FLAG_CUSTOM, meta, 0, 0, NULL, NULL, NULL, render, 0, image, CANDELA_FIELD_NONE, set, cmds, tol, ex, help, long_help, 0, get, show}
/* rows whose value is a file the run reads (IN), writes (OUT) or both: CandelaFlag.files */
#define IN CANDELA_FILES_READS
#define OUT CANDELA_FILES_WRITES
#define STRING_F(files, name, alias, meta, where, cmds, tol, ex, help, long_help) \
    {name, alias, CANDELA_FLAG_STRING, meta, 0, 0, NULL, NULL, NULL, where, CANDELA_FIELD_STR, NULL, cmds, tol, ex, help, long_help, files}
#define CUSTOM_F(files, name, meta, render, image, set, get, show, cmds, tol, ex, help, long_help) \
    {name, NULL, CANDELA_FLAG_CUSTOM, meta, 0, 0, NULL, NULL, NULL, render, 0, image, CANDELA_FIELD_NONE, set, cmds, tol, ex, help, long_help, files, get, show}

static const CandelaFlag FLAGS[] = {
    SWITCH("--help", "-h", CL(help), RENDERING | CANDELA_CMD_MERGE, 0, "print this command's flags, one line each",
           "print the command's flags, one line each, and exit (candela help FLAG explains one)"),
    /* outputs */
    STRING_F(OUT, "--output", "-o", "FILE.exr", CL(out), CANDELA_CMD_RENDER | CANDELA_CMD_GUIDE_DUMP | CANDELA_CMD_MERGE,
           CANDELA_CMD_BENCH | CANDELA_CMD_COMPARE, "x.exr", "output EXR (default out/<scene name>.exr)",
           "output EXR (RGBA + albedo, N, Z, variance layers); default out/<scene name>.exr. Its folder is made when "
           "missing; the extension may be in any case (.exr, .EXR)"),
    STRING_F(OUT, "--png", NULL, "FILE.png", CL(png), CANDELA_CMD_RENDER | CANDELA_CMD_GUIDE_DUMP | CANDELA_CMD_MERGE,
           CANDELA_CMD_BENCH | CANDELA_CMD_COMPARE, "x.png", "preview PNG path (default: the EXR path with .png)",
           "preview PNG path (default: the EXR path with .png); its folder is made when missing"),
    SWITCH("--no-png", NULL, CL(no_png), CANDELA_CMD_RENDER | CANDELA_CMD_GUIDE_DUMP | CANDELA_CMD_MERGE,
           CANDELA_CMD_BENCH | CANDELA_CMD_COMPARE, "do not write the PNG preview", "do not write the PNG preview"),
    SWITCH("--save-partial", NULL, CL(save_partial), CANDELA_CMD_RENDER | CANDELA_CMD_GUIDE_DUMP,
           CANDELA_CMD_BENCH | CANDELA_CMD_COMPARE, "on Ctrl-C / SIGTERM, write the image so far as NAME.partial.exr",
           "on Ctrl-C / SIGTERM, stop after the current batch (abandoning the rest of the iteration; with --checkpoint "
           "its state is written first) and write the image so far as NAME.partial.exr (exit 130); a second signal exits "
           "at once"),
    STRING_F(OUT, "--checkpoint", NULL, "FILE", CL(o.checkpoint_path), CANDELA_CMD_RENDER, NOT_RENDER(CANDELA_CMD_RENDER),
           "x.ckpt", "write the film and learned state to FILE now and then",
           "write the film and learned state to FILE at the barriers after about 4, 8, 16, 32, ... spp (the largest "
           "cumulative spp not above each) and when interrupted; atomically (FILE.tmp-PID, rename). Its folder is made "
           "when missing"),
    STRING_F(IN | OUT, "--resume-from", NULL, "FILE", CL(o.resume_from), CANDELA_CMD_RENDER, NOT_RENDER(CANDELA_CMD_RENDER),
           "x.ckpt", "continue the render FILE checkpointed (its scene, options, outputs)",
           "continue the render FILE checkpointed: the image equals the uninterrupted render's. The scene, every option "
           "that changes the image, the sample shard and the outputs come from the checkpoint (candela render "
           "--resume-from FILE needs no other flag); flags given as well must agree with it (all disagreements are "
           "listed in one error), except those that never change the image (--threads, --batch, -o, --quiet, ...). "
           "Without --checkpoint the render goes on checkpointing into FILE"),
    CUSTOM("--sample-shard", "I/N", 0, 0, set_sample_shard, get_sample_shard, NULL, CANDELA_CMD_RENDER, NOT_RENDER(CANDELA_CMD_RENDER), "1/4",
           "render only samples [spp I/N, spp (I+1)/N) into -o NAME.film",
           "render only samples [spp I/N, spp (I+1)/N) of every pixel (I from 0), with the full render's random numbers, "
           "and write their film sums to -o NAME.film (no EXR); candela merge combines the N films"),
    /* render options (renderer/app/flags.c: candela_parse_render_flag, compare's variants too) */
    CUSTOM("--confine-to", "DIR", 1, 0, set_confine, get_confine, NULL, RENDERING, 0, "/tmp",
           "refuse a scene, or any file it references, outside DIR",
           "refuse a scene, or any file it references, outside DIR (not in a compare variant)"),
    INT("--volume-budget-mb", "N", 0, 1 << 24, RO(volume_budget_mb), CANDELA_FIELD_U32, ALL_RENDER, 0, "512",
        "volume grids in total, MiB (default 8192; 0: none)",
        "volume grids and their majorant and emission grids in total, in MiB (default 8192; 0: none)"),
    INT("--texture-budget-mb", "N", 0, 1 << 24, RO(texture_budget_mb), CANDELA_FIELD_U32, ALL_RENDER, 0, "512",
        "decoded textures in total, MiB (default 8192; 0: none)",
        "decoded textures in total, in MiB, 4 bytes per texel for 8-bit files and 16 for others (default 8192; 0: none)"),
    INT("--spp", "N", 1, 1 << 20, IMG(spp), CANDELA_FIELD_INT, RENDERING, 0, "4", "samples per pixel (default 16)",
        "samples per pixel (default 16); with candela compare --time-budget a cap (default 1048576). The same for "
        "every compare variant"),
    INT("--seed", "S", 0, LONG_MAX, IMG(seed), CANDELA_FIELD_U64, RENDERING, 0, "7", "random seed (default 0)",
        "random seed (default 0); the same for every compare variant"),
    CHOICE("--sampler", "sobol|independent", SAMPLER, SAMPLER_VALUES, "sampler", IMG(sampler), ALL_RENDER, "independent",
           "each path's numbers: Owen-scrambled Sobol' (default) or independent",
           "the numbers of each path: Owen-scrambled Sobol' points (default) or independent uniforms (the renders before "
           "0.2)"),
    FLOAT("--noise-threshold", "T", 1e-6, 100.0, IMG(noise_threshold), CANDELA_FIELD_FLOAT, ALL_RENDER, 0, "0.5",
          "adaptive sampling: samples per pixel from its neighbours' noise, larger T fewer",
          "adaptive sampling, unbiased: after the pilot (--min-spp) each pixel's sample count is fixed from its "
          "neighbours' pilot noise, never its own: n = 4 sigma / (T x image mean), the least-MSE allocation "
          "(e.g. 0.25-2); --spp is the most any pixel gets"),
    INT("--min-spp", "N", 1, 1 << 20, IMG(min_spp), CANDELA_FIELD_INT, ALL_RENDER, 0, "8",
        "adaptive sampling: the pilot every pixel takes (default 16)",
        "adaptive sampling: the pilot, N samples every pixel takes, whose statistics fix the sample counts (the "
        "first iteration barrier at or past N; default 16); needs --noise-threshold"),
    FLOAT("--time-limit", "S", 1e-6, 1e9, RO(time_limit), CANDELA_FIELD_DOUBLE, ALL_RENDER, 0, "60",
          "stop at the first iteration barrier past S seconds",
          "stop at the first iteration barrier past S seconds (load included) and write the image; its spp depend on "
          "the machine's speed"),
    FLOAT("--clamp-direct", "V", 1e-9, 1e30, IMG(clamp_direct), CANDELA_FIELD_FLOAT, ALL_RENDER, 0, "10",
          "clamp direct light contributions to V (biased; default off)",
          "clamp each direct-light contribution's largest channel to V (hue kept; biased; default off)"),
    FLOAT("--clamp-indirect", "V", 1e-9, 1e30, IMG(clamp_indirect), CANDELA_FIELD_FLOAT, ALL_RENDER, 0, "10",
          "clamp indirect light contributions to V (biased; default off)",
          "the same as --clamp-direct for indirect light (two or more bounces): each contribution's largest channel is "
          "clamped to V (hue kept; biased; default off)"),
    CUSTOM("--aov", "spp|recorder-debug|cachepoint", 1, 1, set_aov, get_aov, show_aov, ALL_RENDER, 0, "spp",
           "add an AOV to the EXR (repeatable)",
           "add an AOV to the EXR (repeatable, one each): spp = the channel spp (samples per pixel); recorder-debug = "
           "recorder_debug.RGB, the radiance recorder's primary training samples times their throughput (converges to "
           "RGB); cachepoint = cachepoint.RGB and cachepoint_light.RGB (false colours of each first hit's cache point "
           "and of the entry it weighs most), and NAME.cachepoint.png, NAME.cachepoint_light.png beside the PNG"),
    CUSTOM("--res", "WxH", 1, 1, set_res, get_res, show_res, RENDERING, 0, "32x16", "resolution (default: 640 wide, camera aspect)",
           "resolution, 1..16384 per side and at most 64 megapixels (default: 640 wide, camera aspect); the same for "
           "every compare variant"),
    CUSTOM("--crop", "X0,Y0,X1,Y1", 1, 1, set_crop, get_crop, show_crop, RENDERING, 0, "8,4,24,12",
           "render only pixels [X0,X1) x [Y0,Y1) of the image, at the crop's size",
           "render only the pixels [X0, X1) x [Y0, Y1) of the full image (pbrt's --pixelbounds, Blender's border "
           "render): the camera and every pixel's rays and random numbers are the full image's, and the EXR and PNG "
           "are the crop's size, (X1 - X0) x (Y1 - Y0). Without a light sampler or guide that learns (uniform, power, "
           "tree, optimal; guiding off) each pixel equals the full render's bit for bit; cache points build their "
           "pilot paths from the crop's pixels and learn from its paths, guiding and adaptive sampling decide from the "
           "crop's samples (the same in expectation, not bit for bit). The same for every compare variant"),
    INT("--threads", "N", 1, 1024, RO(threads), CANDELA_FIELD_INT, ALL_RENDER, 0, "2",
        "worker threads (default: all cores)", "worker threads (default: all cores); never changes the image"),
    INT("--max-depth", "N", 0, 1024, IMG(max_depth), CANDELA_FIELD_INT, ALL_RENDER, 0, "4",
        "maximum surface bounces; 1 = direct light only (default 8)",
        "maximum surface bounces; 1 = direct light only (default 8)"),
    INT("--max-volume-bounces", "N", 0, 100000, IMG(max_volume_bounces), CANDELA_FIELD_INT, ALL_RENDER, 0, "16",
        "maximum scattering events in media per path (default 256)",
        "maximum scattering events in media per path (default 256)"),
    CHOICE("--volume-emission-sampling", "on|off|auto", ON_OFF_AUTO, ON_OFF_AUTO_VALUES, NULL,
           IMG(volume_emission_sampling), ALL_RENDER, "on", "emissive volumes are lights too (default auto)",
           "emissive volumes are lights too (NEE with line integration, MIS with tracking); auto: per volume, kept where "
           "it lowers the estimated time to unit variance in the first 4 spp (default auto)"),
    CHOICE("--volume-cachepoint-scatter", "on|off|auto", ON_OFF_AUTO, ON_OFF_AUTO_VALUES, NULL,
           IMG(volume_inscatter_sampling), ALL_RENDER, "off", "cache-point in-scattering sampling in media (default auto)",
           "cache-point in-scattering sampling along camera rays through media, MIS with tracking (cachepoints); auto: "
           "per medium, kept where it measurably lowers the time to unit variance in the first 4 spp (default auto)"),
    CHOICE("--guiding", "off|mis|ris|auto", GUIDING, GUIDING_VALUES, NULL, IMG(guiding), ALL_RENDER, "mis",
           "path guiding (default off)",
           "path guiding (default off): mis = one-sample MIS of the BSDF or phase function and the learned guide (the "
           "BSDF's share 1/2, --guide-bsdf-share); ris = resampling of one candidate of each. Trains during the first 8 spp, then guides (iterations 1 x "
           "8, then 2, 4, 8, 16, 16, ...); auto = mis, kept after a probe over the first 4 spp only where it predicts a gain, else off"),
    INT("--guide-training-spp", "N", 1, 1 << 20, IMG(guide_training_spp), CANDELA_FIELD_INT, ALL_RENDER, 0, "8",
        "guiding learns from the first N spp",
        "guiding learns from the first N spp, then renders with what it learned (default: enough for about 2^21 "
        "training paths, between an eighth and a fifth of --spp, at least 22)"),
    FLOAT("--guide-spatial-threshold", "C", 1.0, 1e9, IMG(guide_spatial_threshold), CANDELA_FIELD_FLOAT, ALL_RENDER, 0,
          "3000", "a guiding leaf splits past C sqrt(spp) samples (default 3000)",
          "a guiding leaf splits past C sqrt(spp of the iteration) training samples (default 3000)"),
    FLOAT("--path-regularization", "G", 0.0, 1.0, IMG(path_regularization), CANDELA_FIELD_FLOAT, ALL_RENDER, 0, "0.01",
          "roughen a vertex after a rough one (biased; default 0: off)",
          "roughen a vertex after a rough one: alpha' = 1 - (1 - alpha) (1 - G alpha'_prev) (the course's 0.01 helps "
          "guiding find caustics; biased; default 0: off)"),
    CHOICE("--guide-spatial-filter", "on|off", ON_OFF, ON_OFF_VALUES, NULL, IMG(guide_spatial_filter), ALL_RENDER, "on",
           "jitter training samples within their leaf (default off)",
           "train each sample into the leaf at a point jittered within a box of its leaf's size (Mueller et al. 2019; "
           "default off)"),
    CHOICE("--guide-directional-filter", "on|off", ON_OFF, ON_OFF_VALUES, NULL, IMG(guide_directional_filter), ALL_RENDER,
           "off", "spread each training sample over its direction's cell (default on)",
           "train each sample into a box of its directional cell's size around its direction, every cell the share it "
           "overlaps (Mueller et al. 2019; default on)"),
    FLOAT("--guide-bsdf-share", "F", 0.0, 1.0, IMG(guide_bsdf_share), CANDELA_FIELD_FLOAT, ALL_RENDER, 0, "0",
          "the BSDF's share of guided MIS (default 0.5; 0: learned per leaf)",
          "the probability that guided MIS samples the BSDF or phase function rather than the guide, everywhere "
          "(default 0.5); 0 learns it per guiding leaf, at or above --guide-min-bsdf-share, from the training samples' "
          "second moments (ch. 1 3.2.1; no gain measured on the benchmark scenes, guiding/README.md)"),
    FLOAT("--guide-min-bsdf-share", "F", 0.0, 1.0, IMG(guide_min_bsdf_share), CANDELA_FIELD_FLOAT, ALL_RENDER, 0, "0.25",
          "the smallest BSDF share a guiding leaf learns (default 0.5)",
          "the smallest BSDF share a guiding leaf learns, of 0.25, 0.375, ..., 1 (default 0.5: below it a caustic the "
          "guide has not learned, which only the BSDF finds, is weighted by more than 2)"),
    FLOAT("--guide-caustic-threshold", "T", 0.0, 1.0, IMG(guide_caustic_threshold), CANDELA_FIELD_FLOAT, ALL_RENDER, 0,
          "0.002", "more BSDF samples where it sees glass, the guide no caustic (default 0: off)",
          "the caustic guard of guided MIS: a guiding leaf whose BSDF sampling reaches delta scatterers (glass, mirrors) "
          "with probability above T while the light training found beyond them is dimmer than the leaf's average "
          "samples the BSDF with probability --guide-caustic-share, so caustics the guide has not learned get 1/0.75 "
          "of their unguided weight instead of twice it (default 0: off, since the caustic defense keeps their weight for "
          "less; 0.002 is what it was measured at; guiding/README.md)"),
    FLOAT("--guide-caustic-share", "F", 0.5, 1.0, IMG(guide_caustic_share), CANDELA_FIELD_FLOAT, ALL_RENDER, 0, "1",
          "the BSDF share where the caustic guard acts (default 0.75)",
          "the probability of sampling the BSDF in the guiding leaves the caustic guard acts on (at least the share the "
          "leaf has otherwise; default 0.75: 1 also removed what guiding gained there, on scenes/default.gltf)"),
    FLOAT("--guide-caustic-defense", "F", 0.0, 16.0, IMG(guide_caustic_defense), CANDELA_FIELD_FLOAT, ALL_RENDER, 0,
          "0", "the guide's density toward glass and mirrors over the BSDF's (default 1; 0: off)",
          "the caustic defense of path guiding: training samples whose rays reached delta scatterers (glass, mirrors) "
          "teach the guide to send about F times the BSDF's own density there, so a caustic the guide has not learned "
          "keeps about its unguided weight in guided MIS (default 1; 0: off; guiding/README.md)"),
    CHOICE("--guide-roulette", "corrected|adjoint", GUIDE_ROULETTE, GUIDE_ROULETTE_VALUES, NULL, IMG(guide_roulette),
           ALL_RENDER, "adjoint", "Russian roulette at guided vertices (default corrected)",
           "Russian roulette at guided vertices: corrected (the default) decides by the throughput, corrected for guided "
           "sampling (ch. 1 4.1.1); adjoint keeps a path by the guide's estimate of what it brings to its pixel (ch. 1 "
           "4.2.1: longer paths where they matter; guiding/README.md)"),
    INT("--recorder-budget", "N", 0, 1 << 20, IMG(recorder_budget), CANDELA_FIELD_INT, ALL_RENDER, 0, "4",
        "recorded vertices per path before skipping (default 4)",
        "recorded vertices per path before path/vertex skipping (default 4; 0: record every vertex)"),
    INT("--recorder-mb", "N", 1, 1 << 20, IMG(recorder_mb), CANDELA_FIELD_U32, ALL_RENDER, 0, "64",
        "radiance recorder storage bound in MiB (default 256)", "radiance recorder storage bound in MiB (default 256)"),
    CHOICE("--light-sampler", "S", LIGHT_SAMPLER, LIGHT_SAMPLER_VALUES, "light sampler", IMG(light_sampler), ALL_RENDER,
           "power", "auto | uniform | power | tree | optimal | cachepoints (default auto)",
           "auto | uniform | power | tree | optimal | cachepoints (default auto: power for one light, optimal up to ~128 "
           "punctual lights (an area light counts 8), else cachepoints; cachepoints with media)"),
    SWITCH("--no-visibility", NULL, IMG(cachepoint_no_visibility), ALL_RENDER, 0,
           "cache points without visibility learning", "cache points without visibility learning"),
    CHOICE("--cachepoint-build", "B", BUILD, BUILD_VALUES, "cache point build", IMG(cachepoint_build_linear), ALL_RENDER,
           "linear", "cut (default) | linear (the paper's)",
           "cut (default: far entries are light-tree clusters) | linear (the paper: every light estimated at every point)"),
    INT("--cachepoint-cut-size", "N", 1, 1 << 20, IMG(cachepoint_cut_size), CANDELA_FIELD_U32, ALL_RENDER, 0, "64",
        "cut build: far entries per cache point (default 128)", "cut build: far entries per cache point (default 128)"),
    INT("--cachepoint-max-near", "N", 1, 256, IMG(cachepoint_max_near), CANDELA_FIELD_U32, ALL_RENDER, 0, "16",
        "near lights per cache point at most (default 256)",
        "near lights per cache point at most, evaluated exactly at every vertex that uses the point; the "
        "strongest by fluence stay near, the rest go to the far entries (default 256, at most 256)"),
    INT("--cachepoint-candidates", "N", 0, 10000000, IMG(cachepoint_candidates), CANDELA_FIELD_U32, ALL_RENDER, 0,
        "25000", "cache point candidates in object boxes",
        "cache point candidates in object boxes (default: 100000 at 1280x720 pixels or more, in proportion below, at "
        "least 25000)"),
    INT("--cachepoint-pilots", "N", 0, 4000000, IMG(cachepoint_pilots), CANDELA_FIELD_U32, ALL_RENDER, 0, "4096",
        "cache point pilot paths (default 65536)", "cache point pilot paths (default 65536)"),
    SWITCH("--cachepoint-retruncate", NULL, IMG(cachepoint_retruncate), ALL_RENDER, 0,
           "linear build: re-apply the 97%/256 rule after the blur",
           "linear build: re-apply the 97%/256 rule after the blur (less memory)"),
    CHOICE("--cachepoint-pooling", "off|points|lights", POOLING, POOLING_VALUES, NULL, IMG(cachepoint_pooling), ALL_RENDER,
           "points", "pool the visibility counters of sparse slots (default off)",
           "visibility counters of slots with too few attempts pooled over the 16 neighbouring points (points), then "
           "over the lights next to the slot's in the light tree (lights; default off)"),
    CHOICE("--cachepoint-progressive", "on|off", ON_OFF, ON_OFF_PROGRESSIVE, NULL, IMG(cachepoint_progressive), ALL_RENDER,
           "on", "insert cache points between iterations (default off)",
           "insert cache points between iterations where neighbouring points' learned visibility jumps (default off)"),
    FLOAT("--cachepoint-progressive-budget", "F", 0.0, 4.0, IMG(cachepoint_progressive_budget), CANDELA_FIELD_FLOAT,
          ALL_RENDER, 0, "0.15", "inserted points as a fraction of the built ones (default 0.15)",
          "inserted points as a fraction of the built ones (default 0.15)"),
    CHOICE("--cachepoint-bsdf", "on|off", ON_OFF, ON_OFF_VALUES, NULL, IMG(cachepoint_bsdf), ALL_RENDER, "off",
           "weigh cache point entries by the glossy BSDF lobe (default on)",
           "at glossy vertices weigh cache point entries by the BSDF lobe too, not only by the normal (default on; "
           "diffuse vertices unchanged)"),
    CUSTOM_F(OUT, "--dump-cachepoints", "FILE.ply", 1, 0, set_dump, get_dump, NULL, CANDELA_CMD_RENDER | CANDELA_CMD_BENCH | CANDELA_CMD_GUIDE_DUMP,
           CANDELA_CMD_COMPARE, "x.ply", "write the cache points after the render as an ASCII PLY",
           "write the cache points after the render as an ASCII PLY (position, radius, near/far counts, learned "
           "visibility, colour); an empty PLY (0 vertices) when --light-sampler auto picks another sampler. Its folder "
           "is made when missing. Not with --frames or compare (nor in a variant)"),
    SWITCH("--optimal-occlusion", NULL, IMG(optimal_occlusion), ALL_RENDER, 0,
           "optimal sampler: one shadow ray per light per vertex", "optimal sampler: one shadow ray per light per vertex"),
    CHOICE("--light-units", "U", LIGHT_UNITS, LIGHT_UNITS_VALUES, "light units", IMG(light_units), ALL_RENDER, "raw",
           "blender (default: cd/683, lux/683) | raw (W/sr, W/m^2)",
           "blender (default: cd/683, lux/683) | raw (W/sr, W/m^2)"),
    CHOICE("--light-model", "M", LIGHT_MODEL, LIGHT_MODEL_VALUES, "light model", IMG(light_model), ALL_RENDER, "blender3",
           "gltf (default) | blender3 (Cycles 3.4's spot blend)",
           "gltf (default: glTF's spot cone ramp) | blender3 (Cycles 3.4's spot blend smoothstep, blend = 1 - "
           "inner/outer cone angle)"),
    CHOICE("--material-model", "M", LIGHT_MODEL, MATERIAL_MODEL_VALUES, "material model", IMG(material_model), ALL_RENDER,
           "blender3", "gltf (default) | blender3 (Blender 3.4's Principled v1)",
           "gltf (default: glTF 2.0 Appendix B BRDF) | blender3 (Blender 3.4's Principled BSDF v1 as its glTF importer "
           "sets it up)"),
    STRING("--camera", NULL, "NAME", IMG(camera_name), ALL_RENDER, 0, "Camera",
           "glTF camera by name (default: the first, or a framing view)",
           "glTF camera by name (default: the first, or a framing view); an unknown name's error lists the scene's "
           "cameras"),
    STRING_F(IN, "--env", NULL, "FILE", IMG(env_path), ALL_RENDER, 0, "sky.exr", "lat-long environment map (EXR/HDR/PNG...)",
           "lat-long environment map (EXR/HDR/PNG...); it overrides the scene's"),
    FLOAT("--env-strength", "S", 0.0, 1e9, IMG(env_strength), CANDELA_FIELD_FLOAT, ALL_RENDER, 0, "2",
          "environment multiplier (default 1)", "environment multiplier (default 1)"),
    FLOAT("--env-rotation", "DEG", -1e6, 1e6, IMG(env_rotation_deg), CANDELA_FIELD_FLOAT, ALL_RENDER, 0, "90",
          "turn the environment about the vertical, in degrees",
          "turn the environment about the vertical, in degrees, with the sign of Blender's Mapping-node Z rotation "
          "(default: the scene's, else 0)"),
    INT("--batch", "N", 1, 1 << 22, RO(batch_size), CANDELA_FIELD_U32, ALL_RENDER, 0, "1024",
        "paths in flight per batch (default 2048 per thread)",
        "paths in flight per batch (default 2048 per thread; never changes the image)"),
    STRING_F(OUT, "--stats-json", NULL, "FILE", CL(stats_json), CANDELA_CMD_RENDER | CANDELA_CMD_BENCH | CANDELA_CMD_GUIDE_DUMP,
           CANDELA_CMD_COMPARE, "x.json", "write render statistics as JSON",
           "write render statistics as JSON (one render's; with --frames use --frame-stats). Its folder is made when "
           "missing"),
    /* animation frames (render) */
    STRING("--frames", NULL, "A-B[:step]|LIST", CL(batch.frames), CANDELA_CMD_RENDER, NOT_RENDER(CANDELA_CMD_RENDER),
           "1-4:2", "render these frames of the glTF animation (-o with a run of '#')",
           "render these frames (e.g. 1-48, 1-48:4, 1,5,10-12) of the glTF animation at time frame / fps, one scene load "
           "for all; -o must then hold a run of '#' for the zero-padded frame number (default out/<scene>.####.exr; the "
           "PNG follows it; the folder is made when missing). Frame f's seed is splitmix64 of --seed and f (README "
           "\"Animation\"). Exit status: the number of failed frames (at most 100), 101 when the request is bad (nothing "
           "rendered), 130 when interrupted"),
    FLOAT("--fps", "F", 1e-3, 1e6, CL(batch.fps), CANDELA_FIELD_DOUBLE, CANDELA_CMD_RENDER, NOT_RENDER(CANDELA_CMD_RENDER),
          "24", "frames per second (default 24)", "frames per second of --frames (default 24)"),
    SWITCH("--resume", NULL, CL(batch.resume), CANDELA_CMD_RENDER, NOT_RENDER(CANDELA_CMD_RENDER),
           "skip frames whose EXR (and PNG) already exist",
           "skip frames whose EXR (and PNG) already exist and read back whole at the batch's resolution, rendered with "
           "this run's image options (the EXR's candela:identity); others render again, with a line saying why"),
    STRING("--shard", NULL, "I/N", CL(batch.shard), CANDELA_CMD_RENDER, NOT_RENDER(CANDELA_CMD_RENDER), "0/2",
           "render every N-th frame of the list starting at position I",
           "render every N-th frame of the list starting at position I (0 <= I < N, round-robin); without it "
           "SLURM_ARRAY_TASK_ID, _COUNT, _MIN and _STEP choose the shard of a Slurm job array"),
    SWITCH("--dry-run", NULL, CL(batch.dry_run), CANDELA_CMD_RENDER, NOT_RENDER(CANDELA_CMD_RENDER),
           "check the command and print what it would render",
           "check the command and print what it would render, loading nothing: 'shard I/N' and 'frame F EXR' per frame "
           "of this task (--frames), 'sample-shard I/N samples B-E of SPP FILM' or 'render EXR' "
           "(scenes/farm/candela_submit.sh asks candela so)"),
    STRING_F(OUT, "--frame-stats", NULL, "FILE.jsonl", CL(batch.stats_jsonl), CANDELA_CMD_RENDER, NOT_RENDER(CANDELA_CMD_RENDER),
           "x.jsonl", "append one JSON line per frame",
           "append one JSON line per frame (frame, time, seed, status, pose and cache point seconds, the --stats-json "
           "fields)"),
    SWITCH("--quiet", "-q", CL(o.quiet), RENDERING, 0, "no progress or statistics on stderr (warnings stay)",
           "no progress or statistics on stderr (warnings stay)"),
    SWITCH("--no-warnings", NULL, CL(o.no_warnings), RENDERING, 0, "no warnings about the scene",
           "no warnings about the scene (what it holds that is not rendered)"),
    /* candela guide-dump */
    CUSTOM("--at", "X,Y,Z", 0, 0, set_at, get_at, NULL, CANDELA_CMD_GUIDE_DUMP, 0, "0,0.5,-1", "the point whose learned guide is written",
           "the point whose learned directional pdf is written (OUT.guide.exr/.png), with the final iteration's training "
           "directions in its leaf (OUT.hist.*) and the spatial tree's leaves (OUT.leaves.ply); OUT = -o without .exr"),
    /* candela compare */
    STRING_F(IN, "--variants", NULL, "SPEC", CL(co.variants), CANDELA_CMD_COMPARE, 0, "a: --spp 1",
           "\"NAME: FLAGS; NAME: FLAGS\" or FILE.toml / FILE.json",
           "\"NAME: FLAGS; NAME: FLAGS\" or FILE.toml / FILE.json: any render flags per variant (not --spp, --seed, "
           "--res, --confine-to, nor a flag that writes a file); the first variant is the ratios' baseline (examples: "
           "scenes/compare/)"),
    STRING("--strategies", NULL, "LIST", CL(co.strategies), CANDELA_CMD_COMPARE, 0, "power,tree",
           "shorthand: NAME = --light-sampler NAME",
           "shorthand: NAME = --light-sampler NAME (default uniform,power,tree,optimal,cachepoints,cachepoints-novis; "
           "also cachepoints-linear, cachepoints-cut, with -novis)"),
    FLOAT("--time-budget", "S", 0.001, 1e7, CL(co.time_budget), CANDELA_FIELD_DOUBLE, CANDELA_CMD_COMPARE, 0, "10",
          "equal time: every variant renders until S seconds",
          "equal time: every variant renders until S seconds (load and build included), stopping at an iteration "
          "barrier; --spp is then a cap (default 1048576) and the table reports the spp reached"),
    INT("--ref-spp", "N", 1, 1 << 20, CL(co.reference_spp), CANDELA_FIELD_INT, CANDELA_CMD_COMPARE, 0, "64",
        "reference spp (default 16 x --spp)",
        "reference spp (default 16 x --spp; 256 with --time-budget), tree sampler"),
    STRING_F(IN, "--reference", NULL, "FILE.exr", CL(co.reference_path), CANDELA_CMD_COMPARE, 0, "ref.exr",
           "reuse a reference instead of rendering one",
           "reuse a reference instead of rendering one; render it with another --seed than the variants' (a "
           "warning says so otherwise: with the same seed a variant draws the reference's own first samples, and its "
           "error against it reads low)"),
    STRING_F(OUT, "--out-dir", NULL, "DIR", CL(co.out_dir), CANDELA_CMD_COMPARE, 0, "report",
           "report folder (default out/compare-<scene name>)", "the report folder (default out/compare-<scene name>)"),
    INT("--optimal-max-lights", "N", 0, 1 << 30, CL(co.optimal_max_lights), CANDELA_FIELD_INT, CANDELA_CMD_COMPARE, 0,
        "100", "skip optimal above N lights (default 5000; 0 = never)",
        "skip optimal above N lights (default 5000; 0 = never)"),
    INT("--timing-runs", "N", 1, 15, CL(co.timing_runs), CANDELA_FIELD_INT, CANDELA_CMD_COMPARE, 0, "3",
        "render each variant N times and report the median time",
        "render each variant N times (1-15, round-robin) and report the median time: robust timings on a busy machine "
        "(default 1; equal spp only)"),
};
#undef IN
#undef OUT

const CandelaFlag *candela_flags(size_t *count) {
    *count = sizeof FLAGS / sizeof FLAGS[0];
    return FLAGS;
}

static const struct { const char *name; unsigned bit; } COMMANDS[] = {
    {"render", CANDELA_CMD_RENDER}, {"bench", CANDELA_CMD_BENCH}, {"guide-dump", CANDELA_CMD_GUIDE_DUMP},
    {"compare", CANDELA_CMD_COMPARE}, {"merge", CANDELA_CMD_MERGE}};

unsigned candela_command_bit(const char *name) {
    for (size_t k = 0; k < sizeof COMMANDS / sizeof COMMANDS[0]; ++k)
        if (strcmp(name, COMMANDS[k].name) == 0) return COMMANDS[k].bit;
    return 0;
}

static const char *command_name(unsigned cmd) {
    for (size_t k = 0; k < sizeof COMMANDS / sizeof COMMANDS[0]; ++k)
        if (cmd == COMMANDS[k].bit) return COMMANDS[k].name;
    return NULL;
}

/* The length of arg's name part (before '=' of --flag=value). */
static size_t name_length(const char *arg) {
    const char *eq = strncmp(arg, "--", 2) == 0 ? strchr(arg, '=') : NULL;
    return eq ? (size_t)(eq - arg) : strlen(arg);
}

static int name_is(const char *name, const char *arg, size_t len) {
    return name && strlen(name) == len && strncmp(name, arg, len) == 0;
}

const CandelaFlag *candela_flag_find(const char *arg, int bare) {
    size_t len = name_length(arg);
    for (size_t k = 0; k < sizeof FLAGS / sizeof FLAGS[0]; ++k) {
        const CandelaFlag *f = &FLAGS[k];
        if (name_is(f->name, arg, len) || name_is(f->alias, arg, len)) return f;
        if (bare && arg[0] != '-' && name_is(f->name + 2, arg, len)) return f;
    }
    return NULL;
}

/* --- parsing ------------------------------------------------------------------------------ */

static int store(const CandelaFlag *f, void *base, long n, float x, const char *s) {
    char *p = (char *)base + f->offset;
    switch (f->field) {
    case CANDELA_FIELD_INT: *(int *)p = (int)n; break;
    case CANDELA_FIELD_U32: *(uint32_t *)p = (uint32_t)n; break;
    case CANDELA_FIELD_U64: *(uint64_t *)p = (uint64_t)n; break;
    case CANDELA_FIELD_FLOAT: *(float *)p = x; break;
    case CANDELA_FIELD_DOUBLE: *(double *)p = x; break;
    case CANDELA_FIELD_STR: *(const char **)p = s; break;
    case CANDELA_FIELD_NONE: break;
    }
    return 0;
}

/* One value for row f into base (CandelaOptions or CandelaCommandLine). 0 ok, -1 with err. */
static int set_value(const CandelaFlag *f, void *base, const char *v, char err[CANDELA_ERR_LEN]) {
    char *end;
    errno = 0;
    switch (f->kind) {
    case CANDELA_FLAG_SWITCH: return store(f, base, 1, 0.0f, NULL);
    case CANDELA_FLAG_INT: {
        long lo = (long)f->lo, hi = f->hi >= (double)LONG_MAX ? LONG_MAX : (long)f->hi;
        long n = strtol(v, &end, 10);
        if (errno || end == v || *end != 0 || n < lo || n > hi) {
            snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for %s (expected an integer in [%ld, %ld])", v, f->name, lo,
                     hi);
            return -1;
        }
        return store(f, base, n, 0.0f, NULL);
    }
    case CANDELA_FLAG_FLOAT: {
        /* floats as before the table (the messages print the float bounds) */
        float lo = (float)f->lo, hi = (float)f->hi;
        float x = strtof(v, &end);
        if (errno || end == v || *end != 0 || !(x >= lo && x <= hi)) {
            snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for %s (expected a number in [%g, %g])", v, f->name, lo, hi);
            return -1;
        }
        return store(f, base, 0, x, NULL);
    }
    case CANDELA_FLAG_CHOICE: {
        char list[128] = "";
        for (int k = 0; f->names[k]; ++k) {
            if (strcmp(v, f->names[k]) == 0) return store(f, base, f->values[k], 0.0f, NULL);
            snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", k ? ", " : "", f->names[k]);
        }
        if (f->what) snprintf(err, CANDELA_ERR_LEN, "unknown %s '%.200s' (%s)", f->what, v, list);
        else snprintf(err, CANDELA_ERR_LEN, "unknown value '%.200s' for %s (%s)", v, f->name, list);
        return -1;
    }
    case CANDELA_FLAG_STRING: return store(f, base, 0, 0.0f, v);
    case CANDELA_FLAG_CUSTOM: return f->set(base, f->name, v, err);
    }
    return -1;
}

/* Row f's value from argv at *i (the next word, or after '='); advances *i past a separate
 * value. 0 ok, -1 with err. */
static int parse_row(const CandelaFlag *f, void *base, int argc, char *const *argv, int *i, char err[CANDELA_ERR_LEN]) {
    const char *a = argv[*i];
    size_t len = name_length(a);
    const char *v = a[len] == '=' ? a + len + 1 : NULL;
    if (f->kind == CANDELA_FLAG_SWITCH) {
        if (v) {
            snprintf(err, CANDELA_ERR_LEN, "%s takes no value ('%.200s')", f->name, a);
            return -1;
        }
        return set_value(f, base, NULL, err);
    }
    if (!v) {
        if (*i + 1 >= argc) {
            snprintf(err, CANDELA_ERR_LEN, "missing value for %.*s", (int)len, a);
            return -1;
        }
        v = argv[*i + 1];
        if (set_value(f, base, v, err) != 0) return -1;
        ++*i;
        return 0;
    }
    return set_value(f, base, v, err);
}

int candela_parse_flag(CandelaCommandLine *cl, unsigned cmd, int argc, char *const *argv, int *i,
                       const CandelaFlag **row, char err[CANDELA_ERR_LEN]) {
    const CandelaFlag *f = candela_flag_find(argv[*i], 0);
    if (!f || !((f->commands | f->tolerated) & cmd)) return 0;
    if (row) *row = f;
    return parse_row(f, f->render ? (void *)&cl->o : (void *)cl, argc, argv, i, err) == 0 ? 1 : -1;
}

int candela_parse_render_flag(CandelaOptions *o, int argc, char *const *argv, int *i, char err[CANDELA_ERR_LEN]) {
    const CandelaFlag *f = candela_flag_find(argv[*i], 0);
    if (!f || !f->render) return 0; /* not a render flag */
    return parse_row(f, o, argc, argv, i, err) == 0 ? 1 : -1;
}

/* --- suggestions -------------------------------------------------------------------------- */

/* Optimal string alignment distance (Levenshtein plus adjacent transpositions: "--sep" and
 * "--spe" are one typo apart), on names of at most 63 characters. */
static int edit_distance(const char *a, size_t n, const char *b, size_t m) {
    if (n > 63 || m > 63) return 1 << 20;
    int d[64][64];
    for (size_t x = 0; x <= n; ++x) d[x][0] = (int)x;
    for (size_t y = 0; y <= m; ++y) d[0][y] = (int)y;
    for (size_t x = 1; x <= n; ++x)
        for (size_t y = 1; y <= m; ++y) {
            int cost = a[x - 1] != b[y - 1];
            int best = d[x - 1][y] + 1;
            if (d[x][y - 1] + 1 < best) best = d[x][y - 1] + 1;
            if (d[x - 1][y - 1] + cost < best) best = d[x - 1][y - 1] + cost;
            if (x > 1 && y > 1 && a[x - 1] == b[y - 2] && a[x - 2] == b[y - 1] && d[x - 2][y - 2] + 1 < best)
                best = d[x - 2][y - 2] + 1;
            d[x][y] = best;
        }
    return d[n][m];
}

const char *candela_flag_suggest(const char *arg, unsigned cmd) {
    /* compared without the dashes: "spl" against "spp", and "-spp" or "spp" still finds "--spp" */
    size_t len = name_length(arg);
    while (*arg == '-' && len > 0) { ++arg; --len; }
    const char *best = NULL;
    int best_d = 1 << 20;
    for (size_t k = 0; k < sizeof FLAGS / sizeof FLAGS[0]; ++k) {
        const CandelaFlag *f = &FLAGS[k];
        if (cmd && !(f->commands & cmd)) continue;
        const char *name = f->name + 2;
        size_t m = strlen(name);
        int d = edit_distance(arg, len, name, m);
        /* close: a typo or two, or a third of the name (long names tolerate more); never more
         * edits than the typed name has letters ("-o" is not a typo of "--aov") */
        if ((d <= 2 || 3 * (size_t)d <= m) && (size_t)d < len && d < best_d) {
            best = f->name;
            best_d = d;
        }
    }
    return best;
}

void candela_unknown_flag_message(const char *arg, unsigned cmd, const char *what, char err[CANDELA_ERR_LEN]) {
    size_t len = name_length(arg);
    const char *near = candela_flag_suggest(arg, cmd);
    const char *cname = command_name(cmd);
    if (near)
        snprintf(err, CANDELA_ERR_LEN, "unknown %s '%.*s' (did you mean '%s'?)", what, (int)(len > 200 ? 200 : len), arg,
                 near);
    else
        snprintf(err, CANDELA_ERR_LEN, "unknown %s '%.*s' (see candela %s%s--help)", what, (int)(len > 200 ? 200 : len),
                 arg, cname ? cname : "", cname ? " " : "");
}

/* --- help --------------------------------------------------------------------------------- */

static void flag_title(const CandelaFlag *f, char *buf, size_t size) {
    snprintf(buf, size, "%s%s%s%s%s", f->alias ? f->alias : "", f->alias ? ", " : "", f->name, f->metavar ? " " : "",
             f->metavar ? f->metavar : "");
}

void candela_print_flags(FILE *out, unsigned cmd) {
    for (size_t k = 0; k < sizeof FLAGS / sizeof FLAGS[0]; ++k) {
        const CandelaFlag *f = &FLAGS[k];
        if (cmd && !(f->commands & cmd)) continue;
        char title[96];
        flag_title(f, title, sizeof title);
        if (strlen(title) < 28) fprintf(out, "  %-28s %s\n", title, f->help);
        else fprintf(out, "  %s  %s\n", title, f->help);
    }
}

void candela_print_flag_names(FILE *out) {
    for (size_t k = 0; k < sizeof FLAGS / sizeof FLAGS[0]; ++k)
        fprintf(out, "%s%s%s\n", FLAGS[k].name, FLAGS[k].alias ? " " : "", FLAGS[k].alias ? FLAGS[k].alias : "");
}

/* text wrapped at 78 columns, each line indented by `indent` spaces */
static void print_wrapped(FILE *out, const char *text, int indent) {
    const int width = 78;
    int col = 0;
    while (*text) {
        while (*text == ' ') ++text;
        size_t w = strcspn(text, " ");
        if (w == 0) break;
        if (col > 0 && col + 1 + (int)w > width) {
            fputc('\n', out);
            col = 0;
        }
        if (col == 0) col = fprintf(out, "%*s", indent, "");
        else col += fprintf(out, " ");
        col += fprintf(out, "%.*s", (int)w, text);
        text += w;
    }
    if (col) fputc('\n', out);
}

int candela_print_flag_help(FILE *out, const char *name) {
    const CandelaFlag *f = candela_flag_find(name, 1);
    if (!f) {
        char err[CANDELA_ERR_LEN];
        candela_unknown_flag_message(name, 0, "option", err);
        fprintf(stderr, "candela: %s\n", err);
        return 2;
    }
    char title[96];
    flag_title(f, title, sizeof title);
    fprintf(out, "%s\n", title);
    print_wrapped(out, f->long_help, 4);
    char line[512] = "";
    if (f->kind == CANDELA_FLAG_INT)
        snprintf(line, sizeof line, "value: an integer in [%ld, %ld]", (long)f->lo, f->hi >= (double)LONG_MAX ? LONG_MAX : (long)f->hi);
    else if (f->kind == CANDELA_FLAG_FLOAT)
        snprintf(line, sizeof line, "value: a number in [%g, %g]", (float)f->lo, (float)f->hi);
    else if (f->kind == CANDELA_FLAG_CHOICE) {
        snprintf(line, sizeof line, "value: one of");
        for (int k = 0; f->names[k]; ++k) snprintf(line + strlen(line), sizeof line - strlen(line), "%s %s", k ? "," : "", f->names[k]);
    }
    if (line[0]) fprintf(out, "    %s\n", line);
    snprintf(line, sizeof line, "commands:");
    int first = 1;
    for (size_t k = 0; k < sizeof COMMANDS / sizeof COMMANDS[0]; ++k)
        if (f->commands & COMMANDS[k].bit) {
            snprintf(line + strlen(line), sizeof line - strlen(line), "%s candela %s", first ? "" : ",", COMMANDS[k].name);
            first = 0;
        }
    if (f->commands & CANDELA_CMD_VARIANT) snprintf(line + strlen(line), sizeof line - strlen(line), ", compare variants");
    fprintf(out, "    %s\n", line);
    fprintf(out, "    forms: %s%s%s", f->name, f->metavar ? " VALUE, " : "", f->metavar ? f->name : "");
    fprintf(out, "%s\n", f->metavar ? "=VALUE" : "");
    return 0;
}

/* --- the render options as JSON (provenance) ------------------------------------------------ */

/* The CLI rows CL(o.field) point into CandelaCommandLine.o, which comes first. */
_Static_assert(offsetof(CandelaCommandLine, o) == 0, "CandelaCommandLine.o must come first");

/* A row's value when it lives in CandelaOptions, as a JSON value; 0 when it does not. */
static int option_json_value(const CandelaFlag *f, const CandelaOptions *o, FILE *out) {
    if (f->kind == CANDELA_FLAG_CUSTOM) {
        if (!f->get) return 0;
        f->get(o, out);
        return 1;
    }
    if (f->field == CANDELA_FIELD_NONE) return 0;
    if (!f->render && f->offset >= sizeof(CandelaOptions)) return 0; /* a command-line field (-o, --frames) */
    const char *p = (const char *)o + f->offset;
    int n = 0;
    switch (f->field) {
    case CANDELA_FIELD_INT: memcpy(&n, p, sizeof n); break;
    case CANDELA_FIELD_U32: {
        uint32_t u;
        memcpy(&u, p, sizeof u);
        fprintf(out, "%u", u);
        return 1;
    }
    case CANDELA_FIELD_U64: {
        uint64_t u;
        memcpy(&u, p, sizeof u);
        fprintf(out, "%llu", (unsigned long long)u);
        return 1;
    }
    case CANDELA_FIELD_FLOAT: {
        float x;
        memcpy(&x, p, sizeof x);
        if (isfinite(x)) fprintf(out, "%.9g", (double)x);
        else fputs("null", out); /* NaN: not given (--env-rotation: the scene's) */
        return 1;
    }
    case CANDELA_FIELD_DOUBLE: {
        double x;
        memcpy(&x, p, sizeof x);
        if (isfinite(x)) fprintf(out, "%.17g", x);
        else fputs("null", out);
        return 1;
    }
    case CANDELA_FIELD_STR: {
        const char *s;
        memcpy(&s, p, sizeof s);
        json_string_or_null(out, s);
        return 1;
    }
    case CANDELA_FIELD_NONE: return 0;
    }
    if (f->kind == CANDELA_FLAG_SWITCH) {
        fputs(n ? "true" : "false", out);
    } else if (f->kind == CANDELA_FLAG_CHOICE) {
        const char *name = NULL;
        for (int k = 0; f->names[k] && !name; ++k)
            if (f->values[k] == n) name = f->names[k];
        candela_json_string(out, name ? name : "default"); /* e.g. --cachepoint-progressive 0 */
    } else {
        fprintf(out, "%d", n);
    }
    return 1;
}

char *candela_options_json(const CandelaOptions *o) {
    char *buf = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&buf, &len);
    if (!f) return NULL;
    fputc('{', f);
    int first = 1;
    for (size_t k = 0; k < sizeof FLAGS / sizeof FLAGS[0]; ++k) {
        const CandelaFlag *row = &FLAGS[k];
        /* every row of a render option (the CLI's o.fields too: --checkpoint, --quiet) */
        if (!row->render && !(row->kind == CANDELA_FLAG_CUSTOM ? row->get != NULL : row->offset < sizeof(CandelaOptions)))
            continue;
        if (row->field == CANDELA_FIELD_NONE && row->kind != CANDELA_FLAG_CUSTOM) continue;
        fputs(first ? "\"" : ", \"", f);
        fputs(row->name + 2, f);
        fputs("\": ", f);
        if (!option_json_value(row, o, f)) fputs("null", f);
        first = 0;
    }
    fputc('}', f);
    if (fclose(f) != 0) {
        free(buf);
        return NULL;
    }
    return buf;
}

/* --- the image identity (options_table.h) --------------------------------------------------- */

void candela_identity_quote(const char *s, char *buf, size_t size) {
    if (!s) {
        snprintf(buf, size, "-");
        return;
    }
    size_t n = 0;
    if (n + 1 < size) buf[n++] = '"';
    for (const unsigned char *c = (const unsigned char *)s; *c && n + 4 < size; ++c) {
        if (*c <= ' ' || *c == '"' || *c == '%' || *c >= 0x7f) n += (size_t)snprintf(buf + n, size - n, "%%%02X", *c);
        else buf[n++] = (char)*c;
    }
    if (n + 1 < size) buf[n++] = '"';
    buf[n < size ? n : size - 1] = 0;
}

void candela_flag_identity_value(const CandelaFlag *f, const CandelaOptions *o, char *buf, size_t size) {
    buf[0] = 0;
    if (!f->image) return;
    if (f->kind == CANDELA_FLAG_CUSTOM) {
        f->show(o, buf, size);
        return;
    }
    const char *p = (const char *)o + f->offset;
    switch (f->field) {
    case CANDELA_FIELD_INT: {
        int n;
        memcpy(&n, p, sizeof n);
        const char *name = NULL;
        for (int k = 0; f->kind == CANDELA_FLAG_CHOICE && f->names[k] && !name; ++k)
            if (f->values[k] == n) name = f->names[k];
        if (name) snprintf(buf, size, "%s", name);
        else snprintf(buf, size, "%d", n);
        return;
    }
    case CANDELA_FIELD_U32: {
        uint32_t u;
        memcpy(&u, p, sizeof u);
        snprintf(buf, size, "%u", u);
        return;
    }
    case CANDELA_FIELD_U64: {
        uint64_t u;
        memcpy(&u, p, sizeof u);
        snprintf(buf, size, "%llu", (unsigned long long)u);
        return;
    }
    case CANDELA_FIELD_FLOAT: {
        float x;
        memcpy(&x, p, sizeof x);
        snprintf(buf, size, "%a", (double)x);
        return;
    }
    case CANDELA_FIELD_DOUBLE: {
        double x;
        memcpy(&x, p, sizeof x);
        snprintf(buf, size, "%a", x);
        return;
    }
    case CANDELA_FIELD_STR: {
        const char *s;
        memcpy(&s, p, sizeof s);
        candela_identity_quote(s, buf, size);
        return;
    }
    case CANDELA_FIELD_NONE: return;
    }
}

int candela_options_identity(const CandelaOptions *o, char *buf, size_t size) {
    size_t n = 0;
    char value[CANDELA_ERR_LEN * 4];
    if (size) buf[0] = 0;
    for (size_t k = 0; k < sizeof FLAGS / sizeof FLAGS[0]; ++k) {
        const CandelaFlag *f = &FLAGS[k];
        if (!f->image) continue;
        /* no crop is no word: every identity from before --crop (checkpoints, shard films, frames,
         * compare's cached references) stays the identity of the same render */
        if (f->set == set_crop && o->crop[2] == 0) continue;
        candela_flag_identity_value(f, o, value, sizeof value);
        int m = snprintf(buf + n, size - n, "%s%s=%s", n ? " " : "", f->name + 2, value);
        if (m < 0 || (size_t)m >= size - n) return -1;
        n += (size_t)m;
    }
    return (int)n;
}

static int hex_digit(char c) {
    return c >= '0' && c <= '9' ? c - '0' : c >= 'A' && c <= 'F' ? c - 'A' + 10 : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
}

char *candela_identity_unquote(char *v) {
    size_t len = strlen(v);
    if (len < 2 || v[0] != '"' || v[len - 1] != '"') return NULL;
    char *w = v;
    for (size_t i = 1; i + 1 < len; ++i) {
        if (v[i] == '%') {
            int a = i + 3 < len ? hex_digit(v[i + 1]) : -1, b = a >= 0 ? hex_digit(v[i + 2]) : -1;
            if (a < 0 || b < 0 || (a == 0 && b == 0)) return NULL;
            *w++ = (char)(a * 16 + b);
            i += 2;
        } else {
            *w++ = v[i];
        }
    }
    *w = 0;
    return v;
}

/* a canonical value set into o (row f); v may be changed (strings decoded in place) */
static int identity_store(const CandelaFlag *f, CandelaOptions *o, char *v, char err[CANDELA_ERR_LEN]) {
    char *end = NULL;
    errno = 0;
    if (f->set == set_res && strcmp(v, "0x0") == 0) { /* not given: the camera's aspect (compare's reference) */
        o->width = o->height = 0;
        return 0;
    }
    if (f->kind == CANDELA_FLAG_CUSTOM) return f->set(o, f->name, v, err);
    switch (f->field) {
    case CANDELA_FIELD_INT: {
        for (int k = 0; f->kind == CANDELA_FLAG_CHOICE && f->names[k]; ++k)
            if (strcmp(v, f->names[k]) == 0) return store(f, o, f->values[k], 0.0f, NULL);
        long n = strtol(v, &end, 10);
        if (errno || end == v || *end || n < INT_MIN || n > INT_MAX) break;
        return store(f, o, n, 0.0f, NULL);
    }
    case CANDELA_FIELD_U32:
    case CANDELA_FIELD_U64: {
        unsigned long long u = strtoull(v, &end, 10);
        if (errno || end == v || *end || v[0] == '-' || (f->field == CANDELA_FIELD_U32 && u > UINT32_MAX)) break;
        char *p = (char *)o + f->offset;
        if (f->field == CANDELA_FIELD_U32) *(uint32_t *)p = (uint32_t)u;
        else *(uint64_t *)p = (uint64_t)u;
        return 0;
    }
    case CANDELA_FIELD_FLOAT:
    case CANDELA_FIELD_DOUBLE: {
        double x = strtod(v, &end);
        if (end == v || *end) break;
        char *p = (char *)o + f->offset;
        if (f->field == CANDELA_FIELD_FLOAT) *(float *)p = (float)x;
        else *(double *)p = x;
        return 0;
    }
    case CANDELA_FIELD_STR: {
        const char *s = NULL;
        if (strcmp(v, "-") != 0 && !(s = candela_identity_unquote(v))) break;
        return store(f, o, 0, 0.0f, s);
    }
    case CANDELA_FIELD_NONE: break;
    }
    snprintf(err, CANDELA_ERR_LEN, "invalid value '%.200s' for %s in the identity", v, f->name);
    return -1;
}

int candela_options_from_identity(CandelaOptions *o, char *text, char err[CANDELA_ERR_LEN]) {
    for (char *c = text; *c;) {
        size_t len = strcspn(c, " ");
        char *next = c[len] ? c + len + 1 : c + len;
        c[len] = 0;
        char *eq = strchr(c, '=');
        if (!eq) {
            snprintf(err, CANDELA_ERR_LEN, "'%.200s' is no NAME=VALUE", c);
            return -1;
        }
        *eq = 0;
        const CandelaFlag *f = NULL;
        for (size_t k = 0; k < sizeof FLAGS / sizeof FLAGS[0] && !f; ++k)
            if (FLAGS[k].image && strcmp(FLAGS[k].name + 2, c) == 0) f = &FLAGS[k];
        if (f && identity_store(f, o, eq + 1, err) != 0) return -1;
        c = next;
    }
    return 0;
}

int candela_identity_value(const char *text, const char *key, char *buf, size_t size) {
    size_t klen = strlen(key);
    for (const char *c = text; *c;) {
        size_t len = strcspn(c, " ");
        if (len > klen && strncmp(c, key, klen) == 0 && c[klen] == '=') {
            snprintf(buf, size, "%.*s", (int)(len - klen - 1), c + klen + 1);
            return 0;
        }
        c += len;
        while (*c == ' ') ++c;
    }
    if (size) buf[0] = 0;
    return -1;
}

void candela_identity_display(const char *v, char *buf, size_t size) {
    char *end = NULL;
    size_t len = strlen(v);
    const char *hex = v[0] == '-' ? v + 1 : v;
    if (strncmp(hex, "0x", 2) == 0) {
        double x = strtod(v, &end);
        if (end && !*end) {
            snprintf(buf, size, "%.9g", x);
            return;
        }
    }
    if (len >= 2 && v[0] == '"' && v[len - 1] == '"') {
        snprintf(buf, size, "%.*s", (int)(len - 2), v + 1); /* %XX left as it is */
        return;
    }
    snprintf(buf, size, "%s", v);
}

int candela_identity_differences(const char *a, const char *b, const char *label, char *out, size_t size) {
    int count = 0;
    size_t n = 0;
    if (size) out[0] = 0;
    /* every key of a and of b (a key only one has counts as a difference too) */
    for (int side = 0; side < 2; ++side) {
        const char *text = side ? b : a, *other = side ? a : b;
        for (const char *c = text; *c;) {
            size_t len = strcspn(c, " ");
            size_t klen = strcspn(c, "=");
            if (klen > len) klen = len;
            char key[128], va[1024], vb[1024], da[512], db[512];
            snprintf(key, sizeof key, "%.*s", (int)(klen < 127 ? klen : 127), c);
            int in_a = candela_identity_value(a, key, va, sizeof va) == 0;
            int in_b = candela_identity_value(b, key, vb, sizeof vb) == 0;
            if ((side == 0 || !in_a) && (!in_a || !in_b || strcmp(va, vb) != 0)) {
                (void)other;
                candela_identity_display(in_a ? va : "(none)", da, sizeof da);
                candela_identity_display(in_b ? vb : "(none)", db, sizeof db);
                char name[160];
                char flag[132];
                snprintf(flag, sizeof flag, "--%s", key);
                int is_flag = candela_flag_find(flag, 0) != NULL;
                snprintf(name, sizeof name, "%s%s", is_flag ? "--" : "", key);
                if (n < size) {
                    int m = strcmp(key, "scene") == 0
                                ? snprintf(out + n, size - n, "%sthe scene file's content differs", count ? ", " : "")
                                : snprintf(out + n, size - n, "%s%s %s (%s %s)", count ? ", " : "", name, da, label, db);
                    if (m > 0) n += (size_t)m;
                    if (n >= size) n = size;
                }
                ++count;
            }
            c += len;
            while (*c == ' ') ++c;
        }
    }
    return count;
}
