/* renderer/app/compare.c: `candela compare`, equal-SPP (or equal-time) comparisons of render
 * variants against a reference, written as a report folder.
 *
 * A variant is a name and render flags ("tree: --light-sampler tree --no-visibility"), parsed
 * by the command line's own parser (candela_parse_render_flag), all of them before anything is
 * rendered or written: a bad flag is a one-line error naming the variant. `--strategies` is
 * the shorthand NAME -> "--light-sampler NAME" (cache points with -linear, -cut, -novis).
 *
 * Every variant renders with the same spp and seed (equal SPP) or until --time-budget seconds
 * have passed, stopping at an iteration barrier (equal time; the table then gives the spp each
 * reached). At every barrier a snapshot of the film's mean is compared with the reference
 * (convergence.csv and the plots); the seconds the snapshots take are subtracted from the
 * times reported and from the time budget. The report folder (OUT):
 *   table.md, table.csv   per variant: spp, time (load + build + render), preprocess time
 *                         (load + build), peak memory, MSE and relMSE minus the reference's own
 *                         noise (its variance layer's variance of the mean, averaged as the MSE
 *                         is: metrics_reference_noise) beside the raw ones, RMSE, MAE, mean
 *                         variance, TTUV and the ratios against the first variant (metrics.h)
 *   NAME.exr, NAME.png    every variant's image; reference.exr / reference.png likewise, and
 *                         reference.key: what the reference depends on; a later run with the
 *                         same key reuses reference.exr instead of rendering it again
 *   NAME_error.png        false-colour relative error against the reference
 *   crops.png             the same crop of the reference and of every variant, side by side;
 *   NAME_crop.png         the crop of one (reference_crop.png too)
 *   convergence.csv, convergence_spp.svg, convergence_time.svg
 *                         relMSE per iteration against spp and against seconds
 *   index.html            all of it on one page: a row per variant holds its image, its
 *                         error map (with the colour bar and its scale) and its crop
 * With --timing-runs N (equal SPP only) every variant is rendered N times, round-robin so slow
 * spells of a shared machine hit all variants alike, and the median time is used (the repeats
 * must give bit-identical images: renders are deterministic). Every file is written under a
 * temporary name and renamed when complete. */
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "candela.h"
#include "clock.h"
#include "io.h"
#include "metrics.h"
#include "options_table.h"
#include "report.h"

enum { COMPARE_MAX_VARIANTS = IO_MAX_VARIANTS, COMPARE_MAX_TIMING_RUNS = 15, COMPARE_NAME_MAX = 48, COMPARE_MAX_VARIANT_READS = 8 };
#define COMPARE_DEFAULT_STRATEGIES "uniform,power,tree,optimal,cachepoints,cachepoints-novis"
/* equal time: the reference's spp when neither --ref-spp nor --reference is given (16 x spp,
 * the equal-SPP default, has no meaning when spp is only a cap) */
#define COMPARE_TIME_BUDGET_REF_SPP 256
#define COMPARE_TIME_BUDGET_MAX_ITERATION_SPP 16

typedef struct Variant {
    char name[COMPARE_NAME_MAX + 1];
    char *flags;   /* owned: as given, for the table */
    char *words;   /* owned: the flags split into NUL-terminated words, which argv and opts' strings point into */
    char **argv;   /* owned */
    int argc;
    CandelaOptions opts;
    int skipped;
    const char *why;
    /* the files its flags read (--env: CANDELA_FILES_READS rows), pointing into words */
    const char *reads[COMPARE_MAX_VARIANT_READS], *read_flag[COMPARE_MAX_VARIANT_READS];
    int nreads;
    uint64_t image_hash; /* of the first render's pixels: repeats must match it */
    int runs, spp;
    double times[COMPARE_MAX_TIMING_RUNS], cp_times[COMPARE_MAX_TIMING_RUNS], pre_times[COMPARE_MAX_TIMING_RUNS];
    double time, time_min, time_max, preprocess, cp_time, mean_var, ttuv;
    ImageErrors errors;
    double mse_corrected, relmse_corrected; /* minus the reference's noise (Report.noise) */
    size_t peak;
    uint32_t cp_count;
    ReportPoint *points; /* owned: one per iteration */
    int num_points, cap_points;
} Variant;

static void variant_free(Variant *v) {
    free(v->flags);
    free(v->words);
    free(v->argv);
    free(v->points);
    memset(v, 0, sizeof *v);
}

static void variants_free(Variant *v, int count) {
    for (int i = 0; i < count; ++i) variant_free(&v[i]);
    free(v);
}

/* FNV-1a over the pixel bytes: equal images, equal hashes (a repeat is compared with it). */
static uint64_t image_hash(const CandelaImage *img) {
    uint64_t h = 0xcbf29ce484222325ull;
    const unsigned char *b = (const unsigned char *)img->rgb;
    size_t n = (size_t)img->width * (size_t)img->height * 3 * sizeof(float);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 0x100000001b3ull;
    return h;
}

static double median(const double *v, int n) {
    double s[COMPARE_MAX_TIMING_RUNS];
    memcpy(s, v, (size_t)n * sizeof *s);
    for (int i = 1; i < n; ++i) /* insertion sort: n <= 15 */
        for (int j = i; j > 0 && s[j - 1] > s[j]; --j) { double t = s[j]; s[j] = s[j - 1]; s[j - 1] = t; }
    return n % 2 ? s[n / 2] : 0.5 * (s[n / 2 - 1] + s[n / 2]);
}

/* ---------------------------------------------------------------- variants */

/* Splits flags at white space into words; '...' and "..." quote (a path with spaces). */
static int split_words(Variant *v, char err[CANDELA_ERR_LEN]) {
    size_t len = strlen(v->flags);
    v->words = malloc(len + 1);
    v->argv = malloc((len / 2 + 2) * sizeof *v->argv); /* at most one word per two characters */
    if (!v->words || !v->argv) { snprintf(err, CANDELA_ERR_LEN, "out of memory"); return -1; }
    char *w = v->words;
    const char *s = v->flags;
    v->argc = 0;
    for (;;) {
        while (isspace((unsigned char)*s)) ++s;
        if (!*s) break;
        v->argv[v->argc++] = w;
        while (*s && !isspace((unsigned char)*s)) {
            if (*s == '\'' || *s == '"') {
                char q = *s++;
                while (*s && *s != q) *w++ = *s++;
                if (*s != q) {
                    snprintf(err, CANDELA_ERR_LEN, "variant '%s': unterminated %c quote in its flags", v->name, q);
                    return -1;
                }
                ++s;
            } else {
                *w++ = *s++;
            }
        }
        *w++ = 0;
    }
    return 0;
}

/* name and flags -> a checked variant: every flag through the render's own parser. */
static int variant_init(Variant *v, const char *name, size_t name_len, const char *flags, size_t flags_len,
                        const CandelaOptions *base, char err[CANDELA_ERR_LEN]) {
    memset(v, 0, sizeof *v);
    while (name_len && isspace((unsigned char)*name)) { ++name; --name_len; }
    while (name_len && isspace((unsigned char)name[name_len - 1])) --name_len;
    int good = name_len > 0 && name_len <= COMPARE_NAME_MAX && name[0] != '.' && name[0] != '-';
    for (size_t k = 0; good && k < name_len; ++k)
        good = isalnum((unsigned char)name[k]) || name[k] == '_' || name[k] == '-' || name[k] == '.';
    if (!good) {
        snprintf(err, CANDELA_ERR_LEN,
                 "variant name '%.*s': 1 to %d letters, digits, '_', '-' or '.' (not first), it names the files", (int)(name_len > 100 ? 100 : name_len),
                 name, COMPARE_NAME_MAX);
        return -1;
    }
    memcpy(v->name, name, name_len);
    v->name[name_len] = 0;
    if (strcmp(v->name, "reference") == 0 || strcmp(v->name, "crops") == 0 || strcmp(v->name, "index") == 0 ||
        strcmp(v->name, "reference_crop") == 0) {
        snprintf(err, CANDELA_ERR_LEN, "variant name '%s' is taken by the report's own files", v->name);
        return -1;
    }
    while (flags_len && isspace((unsigned char)*flags)) { ++flags; --flags_len; }
    while (flags_len && isspace((unsigned char)flags[flags_len - 1])) --flags_len;
    v->flags = strndup(flags, flags_len);
    if (!v->flags) { snprintf(err, CANDELA_ERR_LEN, "out of memory"); return -1; }
    if (split_words(v, err) != 0) return -1;
    v->opts = *base;
    for (int i = 0; i < v->argc; ++i) {
        const char *a = v->argv[i];
        const int start = i; /* the flag's word (parsing moves i to its value) */
        /* the flag's own name, also when written --flag=value */
        size_t a_len = strncmp(a, "--", 2) == 0 && strchr(a, '=') ? (size_t)(strchr(a, '=') - a) : strlen(a);
        char name[64];
        snprintf(name, sizeof name, "%.*s", (int)(a_len < sizeof name ? a_len : sizeof name - 1), a);
        a = name;
        /* a variant changes how the scene renders, never which files the run writes (they are
         * the report's, in --out-dir) nor what applies to every render: only the table's
         * variant rows are taken, and another known flag is named with why (its row says) */
        const CandelaFlag *row = candela_flag_find(a, 0);
        if (row && !(row->commands & CANDELA_CMD_VARIANT)) {
            if (row->files & CANDELA_FILES_WRITES)
                snprintf(err, CANDELA_ERR_LEN,
                         "variant '%s': %s writes a file; a variant may only change render flags (the report's files "
                         "are candela compare's, in --out-dir)", v->name, a);
            else if (row->render || (row->commands & CANDELA_CMD_COMPARE))
                snprintf(err, CANDELA_ERR_LEN, "variant '%s': %s is the same for every variant (give it to candela compare)",
                         v->name, a);
            else
                snprintf(err, CANDELA_ERR_LEN, "variant '%s': %s is not a variant's flag (a variant may only change render "
                         "flags)", v->name, a);
            return -1;
        }
        char flag_err[CANDELA_ERR_LEN];
        int r = candela_parse_render_flag(&v->opts, v->argc, v->argv, &i, flag_err);
        if (r < 0) {
            snprintf(err, CANDELA_ERR_LEN, "variant '%s': %.400s", v->name, flag_err);
            return -1;
        }
        if (r == 0) {
            const char *near = a[0] == '-' ? candela_flag_suggest(a, CANDELA_CMD_VARIANT) : NULL;
            if (near)
                snprintf(err, CANDELA_ERR_LEN, "variant '%s': unknown option '%.200s' (did you mean '%s'?)", v->name, a, near);
            else
                snprintf(err, CANDELA_ERR_LEN, "variant '%s': %s '%.200s' (render flags only, see candela --help)", v->name,
                         a[0] == '-' ? "unknown option" : "unexpected argument", v->argv[i]);
            return -1;
        }
        /* a file a variant reads (--env) is read like the scene's files: inside --confine-to when
         * given, an input of the run and a regular file (record_report_files), all checked before
         * the reference renders, not when the variant's turn comes */
        if (row && (row->files & CANDELA_FILES_READS)) {
            const char *eq = strchr(v->argv[start], '=');
            const char *path = strncmp(v->argv[start], "--", 2) == 0 && eq ? eq + 1 : v->argv[i];
            if (v->opts.confine_dir && !io_path_inside(path, v->opts.confine_dir)) {
                snprintf(err, CANDELA_ERR_LEN, "variant '%s': %s %.150s is outside %.150s (--confine-to)", v->name, a, path,
                         v->opts.confine_dir);
                return -1;
            }
            if (v->nreads == COMPARE_MAX_VARIANT_READS) { /* kept whole, never dropped unchecked */
                snprintf(err, CANDELA_ERR_LEN, "variant '%s': more than %d flags that read files", v->name,
                         COMPARE_MAX_VARIANT_READS);
                return -1;
            }
            v->reads[v->nreads] = path;
            v->read_flag[v->nreads++] = row->name;
        }
    }
    char check_err[CANDELA_ERR_LEN];
    if (candela_options_check(&v->opts, check_err) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "variant '%s': %.400s", v->name, check_err);
        return -1;
    }
    return 0;
}

/* A --strategies name -> its flags: a light sampler, or cachepoints with -linear, -cut and/or
 * -novis suffixes. */
static int strategy_flags(const char *tok, char *flags, size_t size) {
    CandelaLightSampler s;
    if (strncmp(tok, "cachepoints", 11) != 0) {
        if (candela_light_sampler_parse(tok, &s) != 0) return -1;
        snprintf(flags, size, "--light-sampler %s", tok);
        return 0;
    }
    snprintf(flags, size, "--light-sampler cachepoints");
    for (const char *t = tok + 11; *t;) {
        const char *add;
        if (strncmp(t, "-linear", 7) == 0) { add = " --cachepoint-build linear"; t += 7; }
        else if (strncmp(t, "-cut", 4) == 0) { add = " --cachepoint-build cut"; t += 4; }
        else if (strncmp(t, "-novis", 6) == 0) { add = " --no-visibility"; t += 6; }
        else return -1;
        strncat(flags, add, size - strlen(flags) - 1);
    }
    return 0;
}

static int ends_with(const char *s, const char *suffix) {
    size_t n = strlen(s), m = strlen(suffix);
    return n >= m && strcmp(s + n - m, suffix) == 0;
}

int candela_variants_is_file(const char *spec) {
    if (!ends_with(spec, ".toml") && !ends_with(spec, ".json")) return 0;
    /* "a: --light-sampler tree --env sky.json" ends in .json too: a spec with a colon is inline
     * unless a file of that name exists (then it is read, and must be a regular file) */
    struct stat st;
    return strchr(spec, ':') == NULL || lstat(spec, &st) == 0;
}

/* The variants of the run, every one checked: from --variants (a file or "NAME: FLAGS; ...")
 * or from --strategies. */
static int build_variants(const CandelaOptions *base, const CandelaCompareOptions *c, Variant **out, int *count,
                          char err[CANDELA_ERR_LEN]) {
    Variant *vs = calloc(COMPARE_MAX_VARIANTS, sizeof *vs);
    if (!vs) { snprintf(err, CANDELA_ERR_LEN, "out of memory"); return -1; }
    int n = 0, rc = 0;
    if (c->variants && c->strategies) {
        snprintf(err, CANDELA_ERR_LEN, "give --variants or --strategies, not both");
        rc = -1;
    } else if (c->variants && candela_variants_is_file(c->variants)) {
        IoVariant *list = NULL;
        int m = 0;
        char ioerr[IO_ERR_LEN];
        if (io_read_variants(c->variants, &list, &m, ioerr) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
            rc = -1;
        }
        for (int i = 0; rc == 0 && i < m; ++i) {
            char verr[CANDELA_ERR_LEN];
            rc = variant_init(&vs[n], list[i].name, strlen(list[i].name), list[i].flags, strlen(list[i].flags), base, verr);
            ++n;
            if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%.200s: %.300s", c->variants, verr);
        }
        io_variants_free(list, m);
    } else if (c->variants) {
        /* NAME: FLAGS; NAME: FLAGS (an empty entry, e.g. after a final ';', is skipped) */
        for (const char *s = c->variants; rc == 0 && *s;) {
            const char *end = strchr(s, ';');
            if (!end) end = s + strlen(s);
            const char *p = s;
            while (p < end && isspace((unsigned char)*p)) ++p;
            if (p < end) {
                const char *colon = memchr(s, ':', (size_t)(end - s));
                if (!colon) {
                    snprintf(err, CANDELA_ERR_LEN, "--variants: '%.*s' is not NAME: FLAGS", (int)(end - s > 100 ? 100 : end - s), s);
                    rc = -1;
                } else if (n == COMPARE_MAX_VARIANTS) {
                    snprintf(err, CANDELA_ERR_LEN, "--variants: more than %d variants", COMPARE_MAX_VARIANTS);
                    rc = -1;
                } else {
                    rc = variant_init(&vs[n], s, (size_t)(colon - s), colon + 1, (size_t)(end - colon - 1), base, err);
                    ++n;
                }
            }
            s = *end ? end + 1 : end;
        }
    } else {
        char list[1024];
        snprintf(list, sizeof list, "%s", c->strategies ? c->strategies : COMPARE_DEFAULT_STRATEGIES);
        for (char *save = NULL, *tok = strtok_r(list, ",", &save); rc == 0 && tok; tok = strtok_r(NULL, ",", &save)) {
            char flags[256];
            if (strategy_flags(tok, flags, sizeof flags) != 0) {
                snprintf(err, CANDELA_ERR_LEN, "unknown strategy '%.200s' in --strategies", tok);
                rc = -1;
            } else if (n == COMPARE_MAX_VARIANTS) {
                snprintf(err, CANDELA_ERR_LEN, "--strategies: give 1 to %d strategies", COMPARE_MAX_VARIANTS);
                rc = -1;
            } else {
                rc = variant_init(&vs[n], tok, strlen(tok), flags, strlen(flags), base, err);
                ++n;
            }
        }
    }
    if (rc == 0 && n == 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s: no variants", c->variants ? "--variants" : "--strategies");
        rc = -1;
    }
    for (int i = 0; rc == 0 && i < n; ++i)
        for (int j = 0; j < i; ++j)
            if (strcmp(vs[i].name, vs[j].name) == 0) {
                snprintf(err, CANDELA_ERR_LEN, "variant '%s' is given twice", vs[i].name);
                rc = -1;
                break;
            } else {
                /* NAME_error.png is both NAME's error image and NAME_error's preview (NAME_crop.png
                 * likewise) */
                const char *a = vs[i].name, *b = vs[j].name;
                size_t la = strlen(a), lb = strlen(b);
                int clash = 0;
                for (int k = 0; k < 2; ++k) {
                    const char *suffix = k ? "_crop" : "_error";
                    size_t ls = strlen(suffix);
                    clash |= (la == lb + ls && strncmp(a, b, lb) == 0 && strcmp(a + lb, suffix) == 0) ||
                             (lb == la + ls && strncmp(b, a, la) == 0 && strcmp(b + la, suffix) == 0);
                }
                if (clash) {
                    snprintf(err, CANDELA_ERR_LEN, "variants '%s' and '%s' would write the same file", b, a);
                    rc = -1;
                    break;
                }
            }
    if (rc != 0) { variants_free(vs, COMPARE_MAX_VARIANTS); return -1; }
    *out = vs;
    *count = n;
    return 0;
}

/* ---------------------------------------------------------------- reference and images */

static int load_reference(const char *path, int w, int h, float **out, char err[CANDELA_ERR_LEN]) {
    const char *names[3] = {"R", "G", "B"};
    size_t n = (size_t)w * (size_t)h;
    float *ref = malloc(3 * n * sizeof(float));
    if (!ref) { snprintf(err, CANDELA_ERR_LEN, "%.400s: out of memory", path); return -1; }
    for (int k = 0; k < 3; ++k) {
        int rw, rh;
        float *ch = NULL;
        char ioerr[IO_ERR_LEN];
        if (io_read_exr_channel(path, names[k], &rw, &rh, &ch, ioerr) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
            free(ref);
            return -1;
        }
        if (rw != w || rh != h) {
            snprintf(err, CANDELA_ERR_LEN, "%s: reference is %dx%d, the comparison renders %dx%d", path, rw, rh, w, h);
            free(ch); free(ref);
            return -1;
        }
        for (size_t i = 0; i < n; ++i) ref[3 * i + k] = ch[i];
        free(ch);
    }
    *out = ref;
    return 0;
}

/* Warns when a --reference EXR was rendered with the compared renders' seed (its
 * candela:identity says so): then a variant with the reference's sampler and light sampler
 * draws the reference's first samples, its error against the reference is correlated with the
 * reference's own, and its MSE reads low (on the production crop, half). compare's own
 * reference takes seed + 0x5eed for that reason. A reference from elsewhere records no
 * identity and is taken as it is. */
static void warn_reference_seed(const char *path, unsigned long long seed) {
    char identity[CANDELA_IDENTITY_LEN], ioerr[IO_ERR_LEN];
    int w, h;
    if (io_exr_complete_attribute(path, &w, &h, "candela:identity", identity, sizeof identity, ioerr) != 0) return;
    const char *at = strstr(identity, " seed="); /* (the identity starts with scene=) */
    if (!at) return;
    char *end;
    unsigned long long ref_seed = strtoull(at + 6, &end, 10);
    if (end == at + 6 || ref_seed != seed) return;
    fprintf(stderr,
            "candela compare: warning: %s was rendered with seed %llu, the compared renders' seed: their errors "
            "against it are correlated and read low; render it with another --seed\n",
            path, seed);
}

/* The reference's variance layer (variance.R, .G, .B: the variance of each pixel's mean),
 * interleaved; *out = NULL when the EXR has none (a reference from elsewhere): the errors are then
 * not corrected for the reference's noise. -1 only on a size mismatch or out of memory. */
static int load_reference_variance(const char *path, int w, int h, float **out, char err[CANDELA_ERR_LEN]) {
    const char *names[3] = {"variance.R", "variance.G", "variance.B"};
    size_t n = (size_t)w * (size_t)h;
    *out = NULL;
    float *var = malloc(3 * n * sizeof(float));
    if (!var) { snprintf(err, CANDELA_ERR_LEN, "%.400s: out of memory", path); return -1; }
    for (int k = 0; k < 3; ++k) {
        int rw, rh;
        float *ch = NULL;
        char ioerr[IO_ERR_LEN];
        if (io_read_exr_channel(path, names[k], &rw, &rh, &ch, ioerr) != 0) { free(var); return 0; } /* no layer */
        if (rw != w || rh != h) {
            snprintf(err, CANDELA_ERR_LEN, "%.400s: reference variance is %dx%d, the comparison renders %dx%d", path, rw, rh, w, h);
            free(ch); free(var);
            return -1;
        }
        for (size_t i = 0; i < n; ++i) var[3 * i + k] = ch[i];
        free(ch);
    }
    *out = var;
    return 0;
}

/* What a rendered reference depends on, as one line: OUT/reference.exr is reused when
 * OUT/reference.key starts with this line (issue 27). The build: the version and git revision
 * and the running binary's size and modification time (/proc/self/exe), so a rebuilt binary
 * never reuses an older build's reference; the scene's content hash and every image option
 * (candela_image_identity, the options table's `image` rows); an --env file by its size and
 * modification time. Files the scene references are not in it (delete reference.key after
 * changing only a texture). */
static int reference_key(const CandelaOptions *o, const char *build, char *key, size_t size) {
    struct stat exe, env;
    if (stat("/proc/self/exe", &exe) != 0) memset(&exe, 0, sizeof exe);
    if (!o->env_path || stat(o->env_path, &env) != 0) memset(&env, 0, sizeof env);
    uint64_t scene_hash = 0;
    char err[CANDELA_ERR_LEN];
    char *identity = malloc(CANDELA_IDENTITY_LEN);
    if (!identity || candela_scene_hash(o->scene_path, &scene_hash, err) != 0 ||
        candela_image_identity(o, scene_hash, o->width, o->height, identity, CANDELA_IDENTITY_LEN) != 0) {
        free(identity); /* no key: the reference is rendered (and its errors said) and not cached */
        return -1;
    }
    snprintf(key, size, "build %s; binary %lld bytes %lld.%09ld; env %lld %lld.%09ld; %s\n",
             build ? build : "candela " CANDELA_VERSION, (long long)exe.st_size, (long long)exe.st_mtim.tv_sec,
             exe.st_mtim.tv_nsec, (long long)env.st_size, (long long)env.st_mtim.tv_sec, env.st_mtim.tv_nsec, identity);
    free(identity);
    return 0;
}

/* The cached reference when OUT/reference.key matches key (and its render time), else -1. */
static int cached_reference(const char *dir, const char *key, float **ref, int *w, int *h, double *seconds) {
    char path[IO_PATH_MAX + 64], ioerr[IO_ERR_LEN];
    snprintf(path, sizeof path, "%s/reference.key", dir);
    void *data = NULL;
    size_t len = 0;
    /* a key is a line or two: anything else (a FIFO, a huge file) is no cached reference */
    if (io_read_input(path, 65536, "a reference key", &data, &len, ioerr) != 0) return -1;
    const char *text = data;
    size_t klen = strlen(key);
    int match = len >= klen && memcmp(text, key, klen) == 0 && sscanf(text + klen, "seconds %lf", seconds) == 1;
    free(data);
    if (!match) return -1;
    snprintf(path, sizeof path, "%s/reference.exr", dir);
    float *r = NULL;
    char err[CANDELA_ERR_LEN];
    if (io_read_exr_channel(path, "R", w, h, &r, ioerr) != 0) return -1;
    free(r);
    return load_reference(path, *w, *h, ref, err);
}

/* Blue (0) -> green -> yellow -> red (>= 1): a readable false-colour ramp for |error|. */
static void false_colour(float t, float rgb[3]) {
    t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
    const float stops[4][3] = {{0.05f, 0.05f, 0.5f}, {0.1f, 0.7f, 0.3f}, {0.95f, 0.9f, 0.1f}, {0.9f, 0.1f, 0.05f}};
    float x = t * 3.0f;
    int i = x >= 3.0f ? 2 : (int)x;
    float f = x - (float)i;
    for (int k = 0; k < 3; ++k) rgb[k] = stops[i][k] * (1.0f - f) + stops[i + 1][k] * f;
}

/* Relative error per pixel: sum over RGB of |x - ref|, over the reference's sum + 0.03 (so
 * black pixels do not blow up); 0 .. 100 % spans the ramp. */
static float relative_error(const float *x, const float *ref) {
    double e = 0.0, r = 0.0;
    for (int k = 0; k < 3; ++k) { e += fabs((double)x[k] - ref[k]); r += ref[k]; }
    return (float)(e / (r + 0.03));
}

/* The false-colour PNG; also adds every pixel's relative error to error_map (the crop's pick). */
static int write_error_png(const char *path, const CandelaImage *img, const float *ref, float *error_map,
                           const CandelaProvenance *prov, char err[CANDELA_ERR_LEN]) {
    size_t n = (size_t)img->width * (size_t)img->height;
    float *rgb = malloc(3 * n * sizeof(float));
    if (!rgb) { snprintf(err, CANDELA_ERR_LEN, "%.400s: out of memory", path); return -1; }
    for (size_t i = 0; i < n; ++i) {
        float e = relative_error(img->rgb + 3 * i, ref + 3 * i);
        error_map[i] += e;
        false_colour(e, rgb + 3 * i);
    }
    char ioerr[IO_ERR_LEN];
    IoExrAttribute attrs[CANDELA_PROVENANCE_MAX];
    int nattrs = prov ? prov->count : 0;
    for (int k = 0; k < nattrs; ++k) attrs[k] = (IoExrAttribute){prov->attrs[k].name, prov->attrs[k].value};
    int rc = io_write_png(path, img->width, img->height, rgb, nattrs ? attrs : NULL, nattrs, ioerr);
    free(rgb);
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
    return rc;
}

/* The provenance of one of the report's images (issue 27): the run's (software, command line,
 * host, date), the scene and its hash (hashed once, into *scene_prov), what this render did
 * with its own options (o, st) and candela:compareVariant = variant. Without the run's
 * provenance (c->provenance NULL) p stays empty. 0 ok, -1 with err. */
static int compare_provenance(const CandelaCompareOptions *c, CandelaProvenance *scene_prov, const CandelaOptions *o,
                              const CandelaStats *st, int width, int height, const char *variant, CandelaProvenance *p,
                              char err[CANDELA_ERR_LEN]) {
    memset(p, 0, sizeof *p);
    if (!c->provenance) return 0;
    if (scene_prov->count == 0) {
        if (candela_provenance_copy(scene_prov, c->provenance) != 0) {
            snprintf(err, CANDELA_ERR_LEN, "out of memory");
            return -1;
        }
        if (candela_provenance_scene(scene_prov, o->scene_path, err) != 0) {
            candela_provenance_free(scene_prov);
            return -1;
        }
    }
    int rc = candela_provenance_copy(p, scene_prov);
    if (rc == 0 && st) rc = candela_provenance_render(p, o, st) | candela_provenance_identity(p, o, width, height);
    if (rc == 0) rc = candela_provenance_set(p, "candela:compareVariant", variant);
    if (rc != 0) {
        candela_provenance_free(p);
        snprintf(err, CANDELA_ERR_LEN, "out of memory");
        return -1;
    }
    return 0;
}

static int write_srgb_png(const char *path, const float *linear, int width, int height, char err[CANDELA_ERR_LEN]) {
    size_t n = 3 * (size_t)width * (size_t)height;
    float *rgb = malloc(n * sizeof(float));
    if (!rgb) { snprintf(err, CANDELA_ERR_LEN, "%.400s: out of memory", path); return -1; }
    for (size_t i = 0; i < n; ++i) rgb[i] = candela_srgb_encode(linear[i]);
    char ioerr[IO_ERR_LEN];
    int rc = io_write_png(path, width, height, rgb, NULL, 0, ioerr);
    free(rgb);
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
    return rc;
}

/* The crop of a variant, read back from its EXR (every image is not kept in memory). */
static int read_crop(const char *path, int width, const int crop[3], float *out, char err[CANDELA_ERR_LEN]) {
    const char *names[3] = {"R", "G", "B"};
    for (int k = 0; k < 3; ++k) {
        int rw, rh;
        float *ch = NULL;
        char ioerr[IO_ERR_LEN];
        if (io_read_exr_channel(path, names[k], &rw, &rh, &ch, ioerr) != 0) { snprintf(err, CANDELA_ERR_LEN, "%s", ioerr); return -1; }
        if (rw != width) { free(ch); snprintf(err, CANDELA_ERR_LEN, "%.400s: changed while the report was written", path); return -1; }
        for (int y = 0; y < crop[2]; ++y)
            for (int x = 0; x < crop[2]; ++x)
                out[3 * ((size_t)y * crop[2] + x) + k] = ch[(size_t)(crop[1] + y) * (size_t)width + (size_t)(crop[0] + x)];
        free(ch);
    }
    return 0;
}

static void crop_of(const float *rgb, int width, const int crop[3], float *out) {
    for (int y = 0; y < crop[2]; ++y)
        memcpy(out + 3 * (size_t)y * crop[2], rgb + 3 * ((size_t)(crop[1] + y) * (size_t)width + (size_t)crop[0]),
               3 * (size_t)crop[2] * sizeof(float));
}

/* ---------------------------------------------------------------- snapshots */

typedef struct Snapshots {
    Variant *v;
    const float *ref;
    float *mean;         /* scratch: the film's mean at a barrier */
    size_t values;       /* 3 x pixels */
    double time_budget;  /* > 0: stop at the first barrier at or past it */
    double hook_seconds; /* spent here so far: not the render's time */
    int failed;          /* 1: out of memory; 2: the image is not the reference's size */
} Snapshots;

static int on_iteration(void *user, const CandelaIterationInfo *info) {
    Snapshots *s = user;
    double t0 = clock_seconds();
    Variant *v = s->v;
    if ((size_t)info->width * (size_t)info->height * 3 != s->values) { s->failed = 2; return 1; } /* not the reference's size */
    if (v->num_points == v->cap_points) {
        int cap = v->cap_points ? 2 * v->cap_points : 32;
        ReportPoint *p = realloc(v->points, (size_t)cap * sizeof *p);
        if (!p) { s->failed = 1; return 1; }
        v->points = p;
        v->cap_points = cap;
    }
    candela_iteration_mean(info, s->mean);
    ImageErrors e = metrics_image_errors(s->mean, s->ref, s->values);
    double seconds = info->seconds - s->hook_seconds;
    v->points[v->num_points++] = (ReportPoint){info->spp_done, seconds, e.rmse, e.relmse, e.mae};
    s->hook_seconds += clock_seconds() - t0;
    return s->time_budget > 0.0 && seconds >= s->time_budget;
}

/* ---------------------------------------------------------------- tables and page */

static void csv_quoted(ReportText *t, const char *s) {
    report_printf(t, "\"");
    for (; *s; ++s) report_printf(t, *s == '"' ? "\"\"" : "%c", *s);
    report_printf(t, "\"");
}

static void md_code(ReportText *t, const char *s) {
    report_printf(t, "`");
    for (; *s; ++s) report_printf(t, *s == '|' ? "\\|" : *s == '`' ? "'" : "%c", *s);
    report_printf(t, "`");
}

typedef struct Report {
    const CandelaOptions *base;
    const CandelaCompareOptions *c;
    Variant *v;
    int count, first; /* first: the index of the baseline (the first variant that rendered) */
    int width, height, runs;
    double ref_time;
    int ref_spp, ref_cached;
    int crop[3];
    ReferenceNoise noise; /* the reference's own noise in the MSE and relMSE (zero when unknown) */
    int noise_known;      /* the reference EXR has a variance layer */
} Report;

static void heading(ReportText *t, const Report *r, int html) {
    const CandelaOptions *b = r->base;
    if (html) report_printf(t, "<p>");
    report_printf(t, "%dx%d, ", r->width, r->height);
    if (r->c->time_budget > 0) report_printf(t, "equal time: %.3g s per variant (at most %d spp)", r->c->time_budget, b->spp);
    else report_printf(t, "equal spp: %d", b->spp);
    report_printf(t, ", seed %llu. Reference: ", (unsigned long long)b->seed);
    if (r->c->reference_path) {
        if (html) report_html(t, r->c->reference_path);
        else report_printf(t, "%s", r->c->reference_path);
    } else {
        report_printf(t, "tree sampler, %d spp (%.2f s%s)", r->ref_spp, r->ref_time, r->ref_cached ? ", cached from an earlier run" : "");
    }
    report_printf(t, html ? ".</p>\n" : ".\n\n");
    if (html) report_printf(t, "<p>");
    if (r->noise_known)
        report_printf(t, "MSE and relMSE are shown minus the reference's own noise (its variance of the mean, averaged as the "
                         "MSE is: %.5g for MSE, %.5g for relMSE), the raw values beside them.",
                      r->noise.mse, r->noise.relmse);
    else
        report_printf(t, "The reference has no variance layer: MSE and relMSE are not corrected for its noise.");
    report_printf(t, html ? "</p>\n" : "\n\n");
    if (r->runs > 1) {
        if (html) report_printf(t, "<p>");
        report_printf(t, "Times: median of %d renders per variant, round-robin (min-max in brackets); TTUV uses the median.",
                      r->runs);
        report_printf(t, html ? "</p>\n" : "\n\n");
    }
}

/* The table's columns, in order (the markdown and HTML tables; the CSV has its own names). */
static const char *const COLUMNS[] = {"variant", "flags", "spp", "time s", "preprocess s", "peak MiB", "MSE &minus; ref. noise",
                                      "MSE (raw)", "relMSE &minus; ref. noise", "relMSE (raw)", "RMSE (raw)", "MAE", "TTUV",
                                      "cache points (build s)", "time / first", "MSE / first", "relMSE / first", "MAE / first",
                                      "TTUV / first"};
enum { NUM_COLUMNS = sizeof COLUMNS / sizeof COLUMNS[0] };

static void tables(const Report *r, ReportText *md, ReportText *csv, ReportText *html) {
    report_printf(md, "# %s\n\n", r->base->scene_path);
    heading(md, r, 0);
    report_printf(md, "|");
    report_printf(html, "<table class=\"metrics\">\n<tr>");
    for (int k = 0; k < NUM_COLUMNS; ++k) {
        char name[64];
        snprintf(name, sizeof name, "%s", COLUMNS[k]);
        char *amp = strstr(name, "&minus;"); /* markdown: a plain minus */
        if (amp) { *amp = '-'; memmove(amp + 1, amp + 7, strlen(amp + 7) + 1); }
        report_printf(md, " %s |", name);
        report_printf(html, "<th>%s</th>", COLUMNS[k]);
    }
    report_printf(md, "\n|");
    for (int k = 0; k < NUM_COLUMNS; ++k) report_printf(md, "---|");
    report_printf(md, "\n");
    report_printf(html, "</tr>\n");
    report_printf(csv, "variant,flags,spp,time_s,preprocess_s,peak_mib,rmse,relmse,mae,mean_variance,ttuv,time_ratio,rmse_ratio,"
                       "relmse_ratio,mae_ratio,ttuv_ratio,cachepoint_build_s,cache_points,time_min_s,time_max_s,timing_runs,"
                       "mse,mse_corrected,relmse_corrected,ref_noise_mse,ref_noise_relmse,mse_corrected_ratio,"
                       "relmse_corrected_ratio\n");
    const Variant *f = r->first >= 0 ? &r->v[r->first] : NULL;
    for (int i = 0; i < r->count; ++i) {
        const Variant *v = &r->v[i];
        report_printf(md, "| %s | ", v->name);
        md_code(md, v->flags);
        report_printf(csv, "%s,", v->name);
        csv_quoted(csv, v->flags);
        report_printf(html, "<tr><td>");
        report_html(html, v->name);
        report_printf(html, "</td><td><code>");
        report_html(html, v->flags);
        report_printf(html, "</code></td>");
        if (v->skipped) {
            report_printf(md, " | %s |", v->why);
            for (int k = 3; k < NUM_COLUMNS; ++k) report_printf(md, " |");
            report_printf(md, "\n");
            report_printf(csv, ",skipped,,,,,,,,,,,,,,,,,,,,,,,,,\n");
            report_printf(html, "<td colspan=\"%d\">%s</td></tr>\n", NUM_COLUMNS - 2, v->why);
            continue;
        }
        double ratios[5] = {metrics_ratio(v->time, f->time), metrics_ratio(v->errors.rmse, f->errors.rmse),
                            metrics_ratio(v->errors.relmse, f->errors.relmse), metrics_ratio(v->errors.mae, f->errors.mae),
                            metrics_ratio(v->ttuv, f->ttuv)};
        double corrected_ratios[2] = {metrics_ratio(v->mse_corrected, f->mse_corrected),
                                      metrics_ratio(v->relmse_corrected, f->relmse_corrected)};
        char tm[64], cp[64] = "-";
        if (v->runs > 1) snprintf(tm, sizeof tm, "%.3f (%.3f-%.3f)", v->time, v->time_min, v->time_max);
        else snprintf(tm, sizeof tm, "%.3f", v->time);
        if (v->cp_count) snprintf(cp, sizeof cp, "%u (%.3f)", v->cp_count, v->cp_time);
        double mib = (double)v->peak / 1048576.0;
        /* the main numbers (corrected) first, the raw ones beside them */
        const char *fmt_md = " | %d | %s | %.3f | %.1f | **%.5g** | %.5g | **%.5g** | %.5g | %.5g | %.5g | %.5g | %s | %.3f | %.3f "
                             "| %.3f | %.3f | %.3f |\n";
        report_printf(md, fmt_md, v->spp, tm, v->preprocess, mib, v->mse_corrected, v->errors.mse, v->relmse_corrected,
                      v->errors.relmse, v->errors.rmse, v->errors.mae, v->ttuv, cp, ratios[0], corrected_ratios[0],
                      corrected_ratios[1], ratios[3], ratios[4]);
        report_printf(html, "<td>%d</td><td>%s</td><td>%.3f</td><td>%.1f</td><td class=\"main\">%.5g</td><td class=\"raw\">%.5g</td>"
                            "<td class=\"main\">%.5g</td><td class=\"raw\">%.5g</td><td class=\"raw\">%.5g</td><td>%.5g</td>"
                            "<td>%.5g</td><td>%s</td><td>%.3f</td><td>%.3f</td><td>%.3f</td><td>%.3f</td><td>%.3f</td></tr>\n",
                      v->spp, tm, v->preprocess, mib, v->mse_corrected, v->errors.mse, v->relmse_corrected, v->errors.relmse,
                      v->errors.rmse, v->errors.mae, v->ttuv, cp, ratios[0], corrected_ratios[0], corrected_ratios[1], ratios[3],
                      ratios[4]);
        /* %.9g: every number to float precision and more, so a check can recompute them */
        report_printf(csv, ",%d,%.9g,%.9g,%.3f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,", v->spp, v->time, v->preprocess,
                      mib, v->errors.rmse, v->errors.relmse, v->errors.mae, v->mean_var, v->ttuv, ratios[0], ratios[1], ratios[2],
                      ratios[3], ratios[4]);
        if (v->cp_count) report_printf(csv, "%.6f,%u", v->cp_time, v->cp_count);
        else report_printf(csv, ",");
        report_printf(csv, ",%.9g,%.9g,%d", v->time_min, v->time_max, v->runs);
        report_printf(csv, ",%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", v->errors.mse, v->mse_corrected, v->relmse_corrected,
                      r->noise.mse, r->noise.relmse, corrected_ratios[0], corrected_ratios[1]);
    }
    report_printf(html, "</table>\n");
    report_printf(md, "\nMSE - ref. noise = mean (x - ref)^2 - mean Var[ref] (the reference's variance of the mean; unbiased "
                      "for the variant's own squared error); relMSE = mean (x - ref)^2 / (ref^2 + %g), corrected alike; "
                      "TTUV = mean per-pixel variance x time (lower is better).\n",
                  METRICS_RELMSE_EPSILON);
}

/* The error maps' ramp (false_colour) as a CSS gradient, with its scale below it. */
static void colour_bar(ReportText *t) {
    report_printf(t, "<div class=\"colourbar\"><div class=\"ramp\" style=\"background: linear-gradient(to right");
    for (int k = 0; k <= 3; ++k) {
        float rgb[3];
        false_colour((float)k / 3.0f, rgb);
        report_printf(t, ", rgb(%d, %d, %d) %.2f%%", (int)lrintf(rgb[0] * 255.0f), (int)lrintf(rgb[1] * 255.0f),
                      (int)lrintf(rgb[2] * 255.0f), 100.0 * k / 3.0);
    }
    report_printf(t, ")\"></div><div class=\"scale\"><span>0 %%</span><span>25 %%</span><span>50 %%</span><span>75 %%</span>"
                     "<span>&ge; 100 %%</span></div></div>\n");
}

static void image_row(ReportText *t, const char *name, int has_error) {
    report_printf(t, "<tr class=\"image-row\"><th>");
    report_html(t, name);
    report_printf(t, "</th>\n<td><img src=\"");
    report_html(t, name);
    report_printf(t, ".png\" alt=\"");
    report_html(t, name);
    report_printf(t, "\"></td>\n<td>");
    if (has_error) {
        report_printf(t, "<img src=\"");
        report_html(t, name);
        report_printf(t, "_error.png\" alt=\"");
        report_html(t, name);
        report_printf(t, ": relative error\">\n");
        colour_bar(t);
    } else {
        report_printf(t, "(the reference)");
    }
    report_printf(t, "</td>\n<td><img class=\"crop\" src=\"");
    report_html(t, name);
    report_printf(t, "_crop.png\" alt=\"");
    report_html(t, name);
    report_printf(t, ": crop\"></td></tr>\n");
}

static void page(const Report *r, const ReportText *table_html, ReportText *t) {
    report_printf(t, "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>candela compare: ");
    report_html(t, r->base->scene_path);
    report_printf(t, "</title>\n<style>\n"
                     "body { font-family: sans-serif; margin: 1.5em; }\n"
                     "table { border-collapse: collapse; font-size: 0.9em; }\n"
                     "th, td { border: 1px solid #bbb; padding: 0.25em 0.5em; text-align: right; }\n"
                     "td:nth-child(1), td:nth-child(2) { text-align: left; }\n"
                     "td code { white-space: nowrap; }\n"
                     "td.main { font-weight: bold; }\n"
                     "td.raw { color: #666; }\n"
                     "table.images td { text-align: center; vertical-align: top; }\n"
                     "table.images img { image-rendering: pixelated; width: 320px; display: block; }\n"
                     "table.images img.crop { width: 160px; }\n"
                     ".colourbar { width: 320px; margin-top: 0.3em; font-size: 0.8em; }\n"
                     ".colourbar .ramp { height: 0.8em; border: 1px solid #888; }\n"
                     ".colourbar .scale { display: flex; justify-content: space-between; }\n"
                     "</style>\n</head>\n<body>\n<h1>candela compare: ");
    report_html(t, r->base->scene_path);
    report_printf(t, "</h1>\n");
    heading(t, r, 1);
    report_printf(t, "%.*s", (int)table_html->len, table_html->s ? table_html->s : "");
    report_printf(t, "<p>MSE &minus; ref. noise = mean (x &minus; ref)&sup2; &minus; mean Var[ref], the reference's variance of "
                     "the mean from its variance layer (what its own noise adds to the MSE); relMSE = mean (x &minus; ref)&sup2; / "
                     "(ref&sup2; + %g), corrected alike; both can dip below 0 when a variant is as good as the reference. "
                     "TTUV = mean per-pixel variance &times; time (lower is better); ratios are against the first variant. "
                     "Data: <a href=\"table.csv\">table.csv</a>, <a href=\"convergence.csv\">convergence.csv</a>.</p>\n",
                  METRICS_RELMSE_EPSILON);
    report_printf(t, "<h2>Images</h2>\n<p>A row per variant: its image, its relative error against the reference per pixel "
                     "(&Sigma;<sub>RGB</sub> |x &minus; ref| / (&Sigma;<sub>RGB</sub> ref + 0.03), false colour on the bar's "
                     "scale) and its crop: pixels %d-%d &times; %d-%d, where the variants differ most from the reference.</p>\n"
                     "<table class=\"images\">\n<tr><th>variant</th><th>image</th><th>relative error</th><th>crop</th></tr>\n",
                  r->crop[0], r->crop[0] + r->crop[2] - 1, r->crop[1], r->crop[1] + r->crop[2] - 1);
    image_row(t, "reference", 0);
    for (int i = 0; i < r->count; ++i)
        if (!r->v[i].skipped) image_row(t, r->v[i].name, 1);
    report_printf(t, "</table>\n");
    report_printf(t, "<h2>Convergence</h2>\n<p>relMSE (raw) of the image after every iteration (seconds exclude the snapshots' own "
                     "cost).</p>\n<img src=\"convergence_spp.svg\" alt=\"relMSE against spp\">\n"
                     "<img src=\"convergence_time.svg\" alt=\"relMSE against time\">\n");
    report_printf(t, "<h2>Crops</h2>\n<p>Pixels %d-%d &times; %d-%d side by side, left to right: reference", r->crop[0],
                  r->crop[0] + r->crop[2] - 1, r->crop[1], r->crop[1] + r->crop[2] - 1);
    for (int i = 0; i < r->count; ++i)
        if (!r->v[i].skipped) { report_printf(t, ", "); report_html(t, r->v[i].name); }
    report_printf(t, ".</p>\n<img src=\"crops.png\" alt=\"crops\">\n</body>\n</html>\n");
}

/* ---------------------------------------------------------------- the comparison */

/* Every file the report writes, and every variant's --env, into the run's files (the outputs
 * rule, candela.h): checked before anything renders or the folder is made. */
static int record_report_files(const CandelaCompareOptions *c, const Variant *vs, int count, char err[CANDELA_ERR_LEN]) {
    char path[IO_PATH_MAX + 64];
    static const char *const fixed[] = {"crops.png", "convergence.csv", "convergence_spp.svg", "convergence_time.svg",
                                        "table.md", "table.csv", "index.html", "reference.png", "reference_crop.png"};
    static const char *const rendered_reference[] = {"reference.exr", "reference.key"};
    for (size_t k = 0; k < sizeof fixed / sizeof *fixed; ++k) {
        snprintf(path, sizeof path, "%s/%s", c->out_dir, fixed[k]);
        if (candela_run_output(c->run, path, "a report file", err) != 0) return -1;
    }
    for (size_t k = 0; !c->reference_path && k < 2; ++k) {
        snprintf(path, sizeof path, "%s/%s", c->out_dir, rendered_reference[k]);
        if (candela_run_output(c->run, path, "a report file", err) != 0) return -1;
    }
    for (int i = 0; i < count; ++i) {
        static const char *const suffix[] = {".exr", ".png", "_error.png", "_crop.png"};
        for (int k = 0; k < 4; ++k) {
            snprintf(path, sizeof path, "%s/%s%s", c->out_dir, vs[i].name, suffix[k]);
            if (candela_run_output(c->run, path, "a report file", err) != 0) return -1;
        }
    }
    for (int i = 0; i < count; ++i)
        for (int k = 0; k < vs[i].nreads; ++k) {
            char role[96];
            snprintf(role, sizeof role, "the %s of variant '%s'", vs[i].read_flag[k], vs[i].name);
            if (candela_run_input(c->run, vs[i].reads[k], role, err) != 0) return -1;
        }
    return 0;
}

/* Every file a variant reads is there to read (the input door: a regular file, opened without
 * blocking), before the reference renders rather than at the variant's turn after it. */
static int open_variant_inputs(const Variant *vs, int count, char err[CANDELA_ERR_LEN]) {
    for (int i = 0; i < count; ++i)
        for (int k = 0; k < vs[i].nreads; ++k) {
            int fd;
            char ioerr[IO_ERR_LEN];
            if (io_open_input(vs[i].reads[k], 0, NULL, &fd, NULL, ioerr) != 0) {
                snprintf(err, CANDELA_ERR_LEN, "variant '%s': %s %.380s", vs[i].name, vs[i].read_flag[k], ioerr);
                return -1;
            }
            close(fd);
        }
    return 0;
}

static int compare_locked(const CandelaOptions *base, const CandelaCompareOptions *c, Variant *vs, int count,
                          char err[CANDELA_ERR_LEN]);

int candela_compare(const CandelaOptions *base, const CandelaCompareOptions *c, char err[CANDELA_ERR_LEN]) {
    Variant *vs = NULL;
    int count = 0;
    /* every variant is checked before anything renders or is written */
    if (build_variants(base, c, &vs, &count, err) != 0) return -1;
    if (c->time_budget > 0 && c->timing_runs > 1) {
        snprintf(err, CANDELA_ERR_LEN, "--timing-runs repeats equal-spp renders; it does not go with --time-budget");
        variants_free(vs, COMPARE_MAX_VARIANTS);
        return -1;
    }
    if ((c->run && record_report_files(c, vs, count, err) != 0) || open_variant_inputs(vs, count, err) != 0) {
        variants_free(vs, COMPARE_MAX_VARIANTS);
        return -1;
    }
    if (mkdir(c->out_dir, 0777) != 0 && errno != EEXIST) {
        snprintf(err, CANDELA_ERR_LEN, "%s: cannot create the output folder: %s", c->out_dir, strerror(errno));
        variants_free(vs, COMPARE_MAX_VARIANTS);
        return -1;
    }
    char path[IO_PATH_MAX + 64];
    /* one comparison per report folder at a time (its files would mix): the lock is the page's */
    IoLock lock;
    char ioerr[IO_ERR_LEN];
    snprintf(path, sizeof path, "%s/index.html", c->out_dir);
    if (io_lock_output(path, &lock, ioerr) != 0) {
        snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
        variants_free(vs, COMPARE_MAX_VARIANTS);
        return -1;
    }
    int rc = compare_locked(base, c, vs, count, err);
    io_unlock_output(&lock);
    return rc;
}

/* candela_compare once the variants are checked and the report folder is locked; frees vs. */
static int compare_locked(const CandelaOptions *base, const CandelaCompareOptions *c, Variant *vs, int count,
                          char err[CANDELA_ERR_LEN]) {
    char path[IO_PATH_MAX + 64];
    CandelaOptions o = *base;
    o.quiet = 1;
    float *ref = NULL, *mean = NULL, *error_map = NULL, **crops = NULL;
    Report r = {base, c, vs, count, -1, 0, 0, 1, 0.0, 0, 0, {0, 0, 0}};
    ReportText md = {0}, csv = {0}, table_html = {0}, html = {0}, conv = {0};
    CandelaProvenance scene_prov = {0}; /* the run's provenance and the scene's hash */
    int rc = -1;

    /* 1. the reference: reuse an EXR, or render with the tree sampler */
    if (c->reference_path) {
        /* the resolution must match: render one sample to learn it cheaply */
        CandelaOptions probe = o;
        probe.spp = 1;
        CandelaImage img;
        if (candela_render(&probe, &img, NULL, NULL, err) != 0) goto done;
        r.width = img.width; r.height = img.height;
        candela_image_free(&img);
        if (load_reference(c->reference_path, r.width, r.height, &ref, err) != 0) goto done;
        if (!base->quiet) warn_reference_seed(c->reference_path, (unsigned long long)base->seed);
        snprintf(path, sizeof path, "%s/reference.png", c->out_dir);
        if (write_srgb_png(path, ref, r.width, r.height, err) != 0) goto done;
    } else {
        CandelaOptions ro = o;
        r.ref_spp = c->reference_spp > 0 ? c->reference_spp
                    : c->time_budget > 0 ? COMPARE_TIME_BUDGET_REF_SPP : 16 * base->spp;
        ro.spp = r.ref_spp;
        ro.seed = base->seed + 0x5eed;  /* independent of the compared renders */
        ro.light_sampler = CANDELA_LIGHT_SAMPLER_TREE; /* the best general-purpose sampler here */
        char key[CANDELA_IDENTITY_LEN + 1024];
        int keyed = reference_key(&ro, c->build, key, sizeof key) == 0;
        if (keyed && cached_reference(c->out_dir, key, &ref, &r.width, &r.height, &r.ref_time) == 0) {
            r.ref_cached = 1;
            if (!base->quiet) fprintf(stderr, "candela compare: reference, %d spp, from %s/reference.exr\n", ro.spp, c->out_dir);
        } else {
            CandelaImage img;
            CandelaStats st;
            if (!base->quiet) fprintf(stderr, "candela compare: reference, %d spp\n", ro.spp);
            if (candela_render(&ro, &img, &st, NULL, err) != 0) goto done;
            r.ref_time = st.time_total;
            r.width = img.width; r.height = img.height;
            char png[IO_PATH_MAX + 64];
            /* the old key goes first: it must never vouch for a new reference.exr */
            snprintf(path, sizeof path, "%s/reference.key", c->out_dir);
            if (remove(path) != 0 && errno != ENOENT) {
                snprintf(err, CANDELA_ERR_LEN, "%.400s: cannot remove: %s", path, strerror(errno));
                candela_image_free(&img);
                goto done;
            }
            snprintf(path, sizeof path, "%s/reference.exr", c->out_dir);
            snprintf(png, sizeof png, "%s/reference.png", c->out_dir);
            CandelaProvenance rp;
            int wrc = compare_provenance(c, &scene_prov, &ro, &st, img.full_width, img.full_height, "reference", &rp, err);
            if (wrc == 0) wrc = candela_write_outputs_provenance(&img, path, png, rp.count ? &rp : NULL, err);
            candela_provenance_free(&rp);
            size_t n = (size_t)r.width * (size_t)r.height;
            ref = wrc == 0 ? malloc(3 * n * sizeof(float)) : NULL;
            if (ref) memcpy(ref, img.rgb, 3 * n * sizeof(float));
            candela_image_free(&img);
            if (wrc != 0) goto done;
            if (!ref) { snprintf(err, CANDELA_ERR_LEN, "out of memory"); goto done; }
            if (keyed) {
                ReportText k = {0};
                report_printf(&k, "%sseconds %.9g\n", key, r.ref_time);
                snprintf(path, sizeof path, "%s/reference.key", c->out_dir);
                wrc = report_write_text(path, &k, err);
                report_text_free(&k);
                if (wrc != 0) goto done;
            }
        }
    }
    size_t n = (size_t)r.width * (size_t)r.height;
    /* the reference's noise: its variance layer, averaged as the MSE averages */
    {
        float *ref_var = NULL;
        if (c->reference_path) snprintf(path, sizeof path, "%s", c->reference_path);
        else snprintf(path, sizeof path, "%s/reference.exr", c->out_dir);
        if (load_reference_variance(path, r.width, r.height, &ref_var, err) != 0) goto done;
        if (ref_var) {
            r.noise = metrics_reference_noise(ref, ref_var, 3 * n);
            r.noise_known = 1;
            free(ref_var);
        }
    }
    mean = malloc(3 * n * sizeof(float));
    error_map = calloc(n, sizeof(float));
    if (!mean || !error_map) { snprintf(err, CANDELA_ERR_LEN, "out of memory"); goto done; }

    /* 2. every variant at the same spp and seed (or the same time), with snapshots */
    for (int i = 0; i < count; ++i) {
        Variant *v = &vs[i];
        CandelaOptions vo = v->opts;
        vo.quiet = 1;
        if (vo.light_sampler == CANDELA_LIGHT_SAMPLER_OPTIMAL && c->optimal_max_lights > 0) {
            CandelaOptions probe = vo;
            probe.spp = 1;
            probe.width = probe.height = 1;
            probe.light_sampler = CANDELA_LIGHT_SAMPLER_POWER;
            CandelaImage img;
            CandelaStats st;
            if (candela_render(&probe, &img, &st, NULL, err) == 0) {
                candela_image_free(&img);
                if (st.num_lights > (uint32_t)c->optimal_max_lights) {
                    v->skipped = 1;
                    v->why = "skipped: O(lights) per vertex is too slow here (--optimal-max-lights)";
                    continue;
                }
            }
        }
        if (!base->quiet) {
            if (c->time_budget > 0) fprintf(stderr, "candela compare: %s, %.3g s\n", v->name, c->time_budget);
            else fprintf(stderr, "candela compare: %s, %d spp\n", v->name, vo.spp);
        }
        /* equal time: iterations of at most 16 spp (the guided cap; unguided renders default to
         * 64), so a render overshoots the budget by less */
        if (c->time_budget > 0 && vo.max_iteration_spp <= 0) vo.max_iteration_spp = COMPARE_TIME_BUDGET_MAX_ITERATION_SPP;
        Snapshots snap = {v, ref, mean, 3 * n, c->time_budget, 0.0, 0};
        vo.on_iteration = on_iteration;
        vo.on_iteration_user = &snap;
        CandelaImage img;
        CandelaStats st;
        if (candela_render(&vo, &img, &st, NULL, err) != 0) goto done;
        if (snap.failed == 2 || img.width != r.width || img.height != r.height) {
            snprintf(err, CANDELA_ERR_LEN, "variant '%s' renders %dx%d, the reference is %dx%d (give --res)", v->name, img.width,
                     img.height, r.width, r.height);
            candela_image_free(&img);
            goto done;
        }
        if (snap.failed) {
            candela_image_free(&img);
            snprintf(err, CANDELA_ERR_LEN, "out of memory recording the convergence of variant '%s'", v->name);
            goto done;
        }
        if (r.first < 0) r.first = i;
        v->opts.quiet = 1;
        v->image_hash = image_hash(&img);
        v->runs = 1;
        v->spp = st.spp_done;
        v->time = v->times[0] = st.time_total - snap.hook_seconds;
        v->time_min = v->time_max = v->time;
        v->cp_time = v->cp_times[0] = st.time_cachepoints;
        v->cp_count = st.num_cachepoints;
        v->preprocess = v->pre_times[0] = st.time_load + st.time_build;
        v->peak = st.peak_memory_bytes;
        v->errors = metrics_image_errors(img.rgb, ref, 3 * n);
        v->mse_corrected = v->errors.mse - r.noise.mse;
        v->relmse_corrected = v->errors.relmse - r.noise.relmse;
        v->mean_var = metrics_mean(img.variance, 3 * n);
        v->ttuv = metrics_ttuv(v->mean_var, v->time);
        char png[IO_PATH_MAX + 64];
        snprintf(path, sizeof path, "%s/%s.exr", c->out_dir, v->name);
        snprintf(png, sizeof png, "%s/%s.png", c->out_dir, v->name);
        CandelaProvenance vp;
        int wrc = compare_provenance(c, &scene_prov, &vo, &st, img.full_width, img.full_height, v->name, &vp, err);
        if (wrc == 0) wrc = candela_write_outputs_provenance(&img, path, png, vp.count ? &vp : NULL, err);
        snprintf(path, sizeof path, "%s/%s_error.png", c->out_dir, v->name);
        if (wrc == 0) wrc = write_error_png(path, &img, ref, error_map, vp.count ? &vp : NULL, err);
        candela_provenance_free(&vp);
        candela_image_free(&img);
        if (wrc != 0) goto done;
    }
    if (r.first < 0) { snprintf(err, CANDELA_ERR_LEN, "every variant was skipped"); goto done; }

    /* 3. timing repeats, round-robin; the median time (and build time) is reported */
    r.runs = c->timing_runs < 1 ? 1 : c->timing_runs > COMPARE_MAX_TIMING_RUNS ? COMPARE_MAX_TIMING_RUNS : c->timing_runs;
    for (int run = 1; run < r.runs; ++run) {
        for (int i = 0; i < count; ++i) {
            Variant *v = &vs[i];
            if (v->skipped) continue;
            if (!base->quiet) fprintf(stderr, "candela compare: %s, timing run %d of %d\n", v->name, run + 1, r.runs);
            CandelaImage img;
            CandelaStats st;
            if (candela_render(&v->opts, &img, &st, NULL, err) != 0) goto done;
            uint64_t hash = image_hash(&img);
            candela_image_free(&img);
            if (hash != v->image_hash) {
                snprintf(err, CANDELA_ERR_LEN, "%s: variant %s gave a different image on a repeated render (not deterministic)",
                         base->scene_path, v->name);
                goto done;
            }
            v->times[v->runs] = st.time_total;
            v->cp_times[v->runs] = st.time_cachepoints;
            v->pre_times[v->runs] = st.time_load + st.time_build;
            ++v->runs;
            if (st.peak_memory_bytes < v->peak) v->peak = st.peak_memory_bytes; /* least disturbed run */
        }
    }
    for (int i = 0; i < count; ++i) {
        Variant *v = &vs[i];
        if (v->skipped || v->runs < 2) continue;
        v->time = median(v->times, v->runs);
        v->cp_time = median(v->cp_times, v->runs);
        v->preprocess = median(v->pre_times, v->runs);
        v->time_min = v->time_max = v->times[0];
        for (int k = 1; k < v->runs; ++k) {
            if (v->times[k] < v->time_min) v->time_min = v->times[k];
            if (v->times[k] > v->time_max) v->time_max = v->times[k];
        }
        v->ttuv = metrics_ttuv(v->mean_var, v->time);
    }

    /* 4. the crops: where the variants' summed relative error is largest */
    report_pick_crop(error_map, r.width, r.height, r.crop);
    size_t crop_values = 3 * (size_t)r.crop[2] * (size_t)r.crop[2];
    crops = calloc((size_t)count + 1, sizeof *crops);
    if (!crops) { snprintf(err, CANDELA_ERR_LEN, "out of memory"); goto done; }
    int panels = 0;
    if (!(crops[panels] = malloc(crop_values * sizeof(float)))) { snprintf(err, CANDELA_ERR_LEN, "out of memory"); goto done; }
    crop_of(ref, r.width, r.crop, crops[panels++]);
    for (int i = 0; i < count; ++i) {
        if (vs[i].skipped) continue;
        if (!(crops[panels] = malloc(crop_values * sizeof(float)))) { snprintf(err, CANDELA_ERR_LEN, "out of memory"); goto done; }
        snprintf(path, sizeof path, "%s/%s.exr", c->out_dir, vs[i].name);
        if (read_crop(path, r.width, r.crop, crops[panels++], err) != 0) goto done;
    }
    snprintf(path, sizeof path, "%s/crops.png", c->out_dir);
    if (report_crops_png(path, (const float *const *)crops, panels, r.crop[2], err) != 0) goto done;
    /* and one PNG per crop, for the page's rows */
    for (int i = -1, p = 0; i < count; ++i) {
        if (i >= 0 && vs[i].skipped) continue;
        snprintf(path, sizeof path, "%s/%s_crop.png", c->out_dir, i < 0 ? "reference" : vs[i].name);
        if (report_crops_png(path, (const float *const *)&crops[p++], 1, r.crop[2], err) != 0) goto done;
    }

    /* 5. convergence: the data and the two plots */
    ReportSeries series[COMPARE_MAX_VARIANTS];
    int num_series = 0;
    report_printf(&conv, "variant,iteration,spp,seconds,rmse,relmse,mae\n");
    for (int i = 0; i < count; ++i) {
        const Variant *v = &vs[i];
        if (v->skipped) continue;
        series[num_series++] = (ReportSeries){v->name, v->points, v->num_points};
        for (int k = 0; k < v->num_points; ++k)
            report_printf(&conv, "%s,%d,%d,%.6f,%.9g,%.9g,%.9g\n", v->name, k, v->points[k].spp, v->points[k].seconds,
                          v->points[k].rmse, v->points[k].relmse, v->points[k].mae);
    }
    snprintf(path, sizeof path, "%s/convergence.csv", c->out_dir);
    if (report_write_text(path, &conv, err) != 0) goto done;
    snprintf(path, sizeof path, "%s/convergence_spp.svg", c->out_dir);
    if (report_convergence_svg(path, series, num_series, REPORT_X_SPP, err) != 0) goto done;
    snprintf(path, sizeof path, "%s/convergence_time.svg", c->out_dir);
    if (report_convergence_svg(path, series, num_series, REPORT_X_SECONDS, err) != 0) goto done;

    /* 6. the tables and the page (last: a page that exists shows files that exist) */
    tables(&r, &md, &csv, &table_html);
    page(&r, &table_html, &html);
    snprintf(path, sizeof path, "%s/table.md", c->out_dir);
    if (report_write_text(path, &md, err) != 0) goto done;
    snprintf(path, sizeof path, "%s/table.csv", c->out_dir);
    if (report_write_text(path, &csv, err) != 0) goto done;
    snprintf(path, sizeof path, "%s/index.html", c->out_dir);
    if (report_write_text(path, &html, err) != 0) goto done;
    fwrite(md.s, 1, md.len, stdout);
    rc = 0;
done:
    if (crops)
        for (int i = 0; i <= count; ++i) free(crops[i]);
    free(crops);
    free(ref);
    free(mean);
    free(error_map);
    report_text_free(&md);
    report_text_free(&csv);
    report_text_free(&table_html);
    report_text_free(&html);
    report_text_free(&conv);
    candela_provenance_free(&scene_prov);
    variants_free(vs, COMPARE_MAX_VARIANTS);
    return rc;
}
