/* tests/test_options.c: the command line's options table (renderer/app/options_table.c, issue 27).
 *
 * Every row parses its example value in both forms (--flag value, --flag=value) to the same
 * result, for every command that lists it; the render rows are exactly what
 * candela_parse_render_flag (compare's variants) takes; ranges and choices refuse what they
 * must; every row appears in its commands' --help and has a long help; unknown flags get the
 * nearest flag of their command, only when it is close.
 *
 * The image identity (issue 27): every render option of the table says whether it changes the
 * image (a new flag must decide: the options that do not are listed here), the identity holds
 * exactly the `image` rows, and it reads back: options set from an identity give that identity
 * again (every row's example value, and strings with spaces, quotes and percent signs). */
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "options_table.h"

static const unsigned COMMAND_BITS[] = {CANDELA_CMD_RENDER, CANDELA_CMD_BENCH, CANDELA_CMD_GUIDE_DUMP,
                                        CANDELA_CMD_COMPARE, CANDELA_CMD_MERGE};

static void fresh(CandelaCommandLine *cl) {
    memset(cl, 0, sizeof *cl);
    candela_options_default(&cl->o);
}

/* parses argv (n words) from word 0 for cmd: the return and where *i ended */
static int parse(CandelaCommandLine *cl, unsigned cmd, int n, char **argv, int *i, char err[CANDELA_ERR_LEN]) {
    *i = 0;
    err[0] = 0;
    return candela_parse_flag(cl, cmd, n, argv, i, NULL, err);
}

/* the help text of cmd (0: candela --help's list) */
static char *help_text(unsigned cmd) {
    char *buf = NULL;
    size_t size = 0;
    FILE *f = open_memstream(&buf, &size);
    candela_print_flags(f, cmd);
    fclose(f);
    return buf;
}

/* a line of text that starts with the flag's title */
static int help_lists(const char *text, const CandelaFlag *f) {
    char want[128];
    snprintf(want, sizeof want, "  %s%s%s", f->alias ? f->alias : "", f->alias ? ", " : "", f->name);
    for (const char *p = text; p && *p; p = strchr(p, '\n') ? strchr(p, '\n') + 1 : NULL) {
        size_t n = strlen(want);
        if (strncmp(p, want, n) == 0 && (p[n] == ' ' || p[n] == '\n')) return 1;
    }
    return 0;
}

int main(void) {
    size_t count;
    const CandelaFlag *flags = candela_flags(&count);
    CHECK(count >= 70, "only %zu rows", count);
    char err[CANDELA_ERR_LEN];

    /* the rows themselves: names, help, unique names and aliases */
    for (size_t k = 0; k < count; ++k) {
        const CandelaFlag *f = &flags[k];
        CHECK(strncmp(f->name, "--", 2) == 0 && strlen(f->name) > 3, "row %zu: name '%s'", k, f->name);
        CHECK(!f->alias || (f->alias[0] == '-' && f->alias[1] && f->alias[1] != '-' && !f->alias[2]), "%s: alias", f->name);
        CHECK(f->help && *f->help && !strchr(f->help, '\n') && strlen(f->help) <= 80, "%s: one-line help", f->name);
        CHECK(f->long_help && strlen(f->long_help) >= strlen(f->help) / 2, "%s: long help", f->name);
        CHECK(f->commands != 0, "%s: no command", f->name);
        CHECK((f->kind == CANDELA_FLAG_SWITCH) == (f->example == NULL), "%s: example", f->name);
        CHECK((f->kind == CANDELA_FLAG_SWITCH) == (f->metavar == NULL), "%s: metavar", f->name);
        CHECK(!f->render || !(f->commands & CANDELA_CMD_MERGE), "%s: a render flag in merge", f->name);
        for (size_t j = 0; j < k; ++j) {
            CHECK(strcmp(flags[j].name, f->name) != 0, "%s: two rows", f->name);
            CHECK(!f->alias || !flags[j].alias || strcmp(flags[j].alias, f->alias) != 0, "%s: alias twice", f->name);
        }
        CHECK(candela_flag_find(f->name, 0) == f && candela_flag_find(f->name + 2, 1) == f, "%s: find", f->name);
    }

    /* every row, for every command that takes it, in both forms */
    for (size_t k = 0; k < count; ++k) {
        const CandelaFlag *f = &flags[k];
        for (size_t c = 0; c < sizeof COMMAND_BITS / sizeof COMMAND_BITS[0]; ++c) {
            unsigned cmd = COMMAND_BITS[c];
            CandelaCommandLine a, b;
            int i;
            char joined[256];
            if (!((f->commands | f->tolerated) & cmd)) {
                fresh(&a);
                char *argv[] = {(char *)f->name, (char *)(f->example ? f->example : "x")};
                CHECK(parse(&a, cmd, 2, argv, &i, err) == 0, "%s: taken by command %#x", f->name, cmd);
                continue;
            }
            if (f->kind == CANDELA_FLAG_SWITCH) {
                fresh(&a);
                fresh(&b);
                char *argv[] = {(char *)f->name};
                CHECK(parse(&a, cmd, 1, argv, &i, err) == 1 && i == 0, "%s (cmd %#x): %s", f->name, cmd, err);
                CHECK(memcmp(&a, &b, sizeof a) != 0, "%s: changed nothing", f->name);
                snprintf(joined, sizeof joined, "%s=1", f->name);
                char *eq[] = {joined};
                CHECK(parse(&b, cmd, 1, eq, &i, err) == -1 && strstr(err, f->name), "%s=1: '%s'", f->name, err);
                if (f->alias) {
                    fresh(&b);
                    char *al[] = {(char *)f->alias};
                    CHECK(parse(&b, cmd, 1, al, &i, err) == 1 && memcmp(&a, &b, sizeof a) == 0, "%s", f->alias);
                }
                continue;
            }
            fresh(&a);
            fresh(&b);
            char *sep[] = {(char *)f->name, (char *)f->example, "--next"};
            CHECK(parse(&a, cmd, 3, sep, &i, err) == 1 && i == 1, "%s %s (cmd %#x): %s", f->name, f->example, cmd, err);
            snprintf(joined, sizeof joined, "%s=%s", f->name, f->example);
            char *eq[] = {joined, "--next"};
            CHECK(parse(&b, cmd, 2, eq, &i, err) == 1 && i == 0, "%s (cmd %#x): %s", joined, cmd, err);
            if (f->kind == CANDELA_FLAG_STRING) {
                const char *sa = *(const char **)((char *)(f->render ? (void *)&a.o : (void *)&a) + f->offset);
                const char *sb = *(const char **)((char *)(f->render ? (void *)&b.o : (void *)&b) + f->offset);
                CHECK(sa && sb && strcmp(sa, f->example) == 0 && strcmp(sb, f->example) == 0, "%s: the string", f->name);
            } else if (strcmp(f->name, "--confine-to") != 0 && strcmp(f->name, "--dump-cachepoints") != 0) {
                CandelaCommandLine d;
                fresh(&d);
                CHECK(memcmp(&a, &b, sizeof a) == 0, "%s: the two forms differ", f->name);
                CHECK(memcmp(&a, &d, sizeof a) != 0 || strcmp(f->example, "0") == 0, "%s %s changed nothing", f->name,
                      f->example);
            }
            if (f->alias) {
                fresh(&b);
                char *al[] = {(char *)f->alias, (char *)f->example};
                CHECK(parse(&b, cmd, 2, al, &i, err) == 1 && i == 1, "%s", f->alias);
            }
            /* a missing value */
            fresh(&a);
            char *last[] = {(char *)f->name};
            CHECK(parse(&a, cmd, 1, last, &i, err) == -1 && strstr(err, "missing value for") && strstr(err, f->name),
                  "%s without a value: '%s'", f->name, err);
        }
        /* render rows are exactly what compare's variants parse (candela_parse_render_flag) */
        CandelaOptions o;
        candela_options_default(&o);
        char *argv[] = {(char *)f->name, (char *)(f->example ? f->example : "x")};
        int i = 0;
        int r = candela_parse_render_flag(&o, 2, argv, &i, err);
        CHECK(f->render ? r == 1 : r == 0, "%s: candela_parse_render_flag returned %d", f->name, r);
        CHECK(!(f->commands & CANDELA_CMD_VARIANT) || f->render, "%s: a variant flag that is not a render flag", f->name);
        /* the files column (issue 29): a flag whose value names a file says whether the run reads
         * or writes it (compare refuses every writer in a variant and confines every reader), and
         * no variant flag writes one (its file would escape the report's folder) */
        int names_file = f->metavar && (strncmp(f->metavar, "FILE", 4) == 0 || strcmp(f->name, "--out-dir") == 0);
        CHECK(!names_file || f->files, "%s: its value names a file, its files column says nothing", f->name);
        CHECK(!(f->files & ~(unsigned)(CANDELA_FILES_READS | CANDELA_FILES_WRITES)), "%s: files %#x", f->name, f->files);
        CHECK(!(f->commands & CANDELA_CMD_VARIANT) || !(f->files & CANDELA_FILES_WRITES), "%s: a variant flag that writes a file",
              f->name);
    }

    /* ranges and choices: what is outside refused with the flag named */
    for (size_t k = 0; k < count; ++k) {
        const CandelaFlag *f = &flags[k];
        unsigned cmd = f->commands & ~(unsigned)CANDELA_CMD_VARIANT;
        cmd &= -cmd; /* the first command that lists it */
        CandelaCommandLine a;
        int i;
        char v[64];
        if (f->kind == CANDELA_FLAG_INT) {
            long bounds[2] = {(long)f->lo - 1, f->hi >= (double)LONG_MAX ? 0 : (long)f->hi + 1};
            for (int s = 0; s < 2; ++s) {
                if (s == 1 && f->hi >= (double)LONG_MAX) continue;
                snprintf(v, sizeof v, "%ld", bounds[s]);
                char *argv[] = {(char *)f->name, v};
                fresh(&a);
                CHECK(parse(&a, cmd, 2, argv, &i, err) == -1 && strstr(err, "expected an integer") && strstr(err, f->name),
                      "%s %s: '%s'", f->name, v, err);
            }
            snprintf(v, sizeof v, "%.0f", f->lo);
            char *lo[] = {(char *)f->name, v};
            fresh(&a);
            CHECK(parse(&a, cmd, 2, lo, &i, err) == 1, "%s at its lower bound: '%s'", f->name, err);
        }
        if (f->kind == CANDELA_FLAG_FLOAT) {
            char *argv[] = {(char *)f->name, "nan"};
            fresh(&a);
            CHECK(parse(&a, cmd, 2, argv, &i, err) == -1 && strstr(err, "expected a number"), "%s nan: '%s'", f->name, err);
            snprintf(v, sizeof v, "%g", f->hi * 10 + 1);
            char *big[] = {(char *)f->name, v};
            fresh(&a);
            CHECK(parse(&a, cmd, 2, big, &i, err) == -1, "%s %s accepted", f->name, v);
        }
        if (f->kind == CANDELA_FLAG_CHOICE) {
            for (int c = 0; f->names[c]; ++c) {
                char *argv[] = {(char *)f->name, (char *)f->names[c]};
                fresh(&a);
                CHECK(parse(&a, cmd, 2, argv, &i, err) == 1, "%s %s: '%s'", f->name, f->names[c], err);
            }
            char *argv[] = {(char *)f->name, "bogus"};
            fresh(&a);
            CHECK(parse(&a, cmd, 2, argv, &i, err) == -1 && strstr(err, "'bogus'") && strstr(err, f->names[0]),
                  "%s bogus: '%s'", f->name, err);
        }
    }

    /* --help: each command lists exactly its rows, one line each; candela --help lists all */
    for (size_t c = 0; c <= sizeof COMMAND_BITS / sizeof COMMAND_BITS[0]; ++c) {
        unsigned cmd = c < sizeof COMMAND_BITS / sizeof COMMAND_BITS[0] ? COMMAND_BITS[c] : 0;
        char *text = help_text(cmd);
        size_t lines = 0, want = 0;
        for (const char *p = text; *p; ++p) lines += *p == '\n';
        for (size_t k = 0; k < count; ++k) {
            int listed = cmd == 0 || (flags[k].commands & cmd);
            want += listed;
            CHECK(help_lists(text, &flags[k]) == listed, "%s in the help of command %#x: %d", flags[k].name, cmd, !listed);
        }
        CHECK(lines == want, "command %#x: %zu help lines for %zu flags", cmd, lines, want);
        free(text);
    }
    /* candela help FLAG: every row, with and without dashes; an unknown name is exit 2 */
    FILE *null = fopen("/dev/null", "w");
    for (size_t k = 0; k < count; ++k)
        CHECK(candela_print_flag_help(null, flags[k].name) == 0 && candela_print_flag_help(null, flags[k].name + 2) == 0,
              "help %s", flags[k].name);
    CHECK(candela_print_flag_help(null, "--no-such-flag") == 2, "help of an unknown flag");
    fclose(null);

    /* did you mean: the nearest of the command's flags, only when close */
    const struct { const char *typed; unsigned cmd; const char *want; } near[] = {
        {"--spl", CANDELA_CMD_RENDER, "--spp"},
        {"--sede", CANDELA_CMD_RENDER, "--seed"},
        {"--lightsampler", CANDELA_CMD_RENDER, "--light-sampler"},
        {"--light-smapler", CANDELA_CMD_COMPARE, "--light-sampler"},
        {"--sp=4", CANDELA_CMD_BENCH, "--spp"},
        {"--outptu", CANDELA_CMD_RENDER, "--output"},
        {"--pgn", CANDELA_CMD_MERGE, "--png"},
        {"--timing-run", CANDELA_CMD_COMPARE, "--timing-runs"},
        {"--timing-run", CANDELA_CMD_RENDER, NULL},     /* compare's own, not render's */
        {"--at", CANDELA_CMD_RENDER, NULL},             /* "aov" is 2 edits from "at", more than it has letters */
        {"--spp", CANDELA_CMD_MERGE, NULL},
        {"--xyzzy", CANDELA_CMD_RENDER, NULL},
        {"-o", CANDELA_CMD_VARIANT, NULL},
        {"--enviroment", CANDELA_CMD_RENDER, NULL},
        {"--dumpcachepoints", CANDELA_CMD_RENDER, "--dump-cachepoints"},
    };
    for (size_t k = 0; k < sizeof near / sizeof near[0]; ++k) {
        const char *got = candela_flag_suggest(near[k].typed, near[k].cmd);
        CHECK(near[k].want ? got && strcmp(got, near[k].want) == 0 : got == NULL, "%s -> %s (want %s)", near[k].typed,
              got ? got : "none", near[k].want ? near[k].want : "none");
    }
    candela_unknown_flag_message("--spl", CANDELA_CMD_RENDER, "option", err);
    CHECK(strcmp(err, "unknown option '--spl' (did you mean '--spp'?)") == 0, "'%s'", err);
    candela_unknown_flag_message("--spl=3", CANDELA_CMD_RENDER, "option", err);
    CHECK(strcmp(err, "unknown option '--spl' (did you mean '--spp'?)") == 0, "'%s'", err);
    candela_unknown_flag_message("--xyzzy", CANDELA_CMD_COMPARE, "option", err);
    CHECK(strcmp(err, "unknown option '--xyzzy' (see candela compare --help)") == 0, "'%s'", err);

    /* --- the image identity */
    static const char *const not_image[] = {"--confine-to", "--volume-budget-mb", "--texture-budget-mb", "--time-limit",
                                            "--threads", "--dump-cachepoints", "--batch", NULL};
    static char ident[CANDELA_IDENTITY_LEN], again[CANDELA_IDENTITY_LEN], copy[CANDELA_IDENTITY_LEN];
    int image_rows = 0;
    for (size_t k = 0; k < count; ++k) {
        const CandelaFlag *f = &flags[k];
        int listed = 0;
        for (int j = 0; not_image[j]; ++j) listed |= strcmp(f->name, not_image[j]) == 0;
        /* a render option either changes the image or is listed as one that does not */
        if (f->render) CHECK(f->image != listed, "%s: image %d, listed as not changing it %d", f->name, f->image, listed);
        else CHECK(!f->image, "%s: a command-line field in the identity", f->name);
        CHECK(!f->image || f->kind != CANDELA_FLAG_CUSTOM || f->show, "%s: no identity form", f->name);
        image_rows += f->image;
    }
    CHECK(image_rows >= 35, "only %d image rows", image_rows);
    /* the defaults: one NAME=VALUE per image row, in table order, but for --crop, which has no
     * word when unset (identities from before it stay valid) */
    CandelaCommandLine cl;
    fresh(&cl);
    int len = candela_options_identity(&cl.o, ident, sizeof ident);
    CHECK(len > 0 && (size_t)len == strlen(ident), "identity length %d", len);
    int words = 1;
    for (const char *c = ident; *c; ++c) words += *c == ' ';
    CHECK(words == image_rows - 1 && !strstr(ident, "crop="), "%d words for %d image rows: %s", words, image_rows, ident);
    CHECK(strstr(ident, "spp=16 seed=0 ") == ident, "%s", ident);
    CHECK(strstr(ident, " res=0x0 ") && strstr(ident, " env-strength=0x1p+0 ") && strstr(ident, " camera=- "), "%s", ident);
    CHECK(!strstr(ident, "threads=") && !strstr(ident, "time-limit=") && !strstr(ident, "batch="), "%s", ident);
    /* every image row's example, one at a time: it changes the identity, and reads back */
    for (size_t k = 0; k < count; ++k) {
        const CandelaFlag *f = &flags[k];
        if (!f->image || !f->example) continue;
        fresh(&cl);
        char word[96];
        snprintf(word, sizeof word, "%s=%s", f->name, f->example);
        char *argv[] = {word};
        int i;
        CHECK(parse(&cl, CANDELA_CMD_RENDER, 1, argv, &i, err) == 1, "%s: %s", word, err);
        candela_options_identity(&cl.o, ident, sizeof ident);
        CandelaCommandLine back;
        fresh(&back);
        snprintf(copy, sizeof copy, "%s", ident);
        CHECK(candela_options_from_identity(&back.o, copy, err) == 0, "%s: %s", word, err);
        candela_options_identity(&back.o, again, sizeof again);
        CHECK(strcmp(ident, again) == 0, "%s: read back as\n%s\nnot\n%s", word, again, ident);
        char value[256];
        candela_flag_identity_value(f, &cl.o, value, sizeof value);
        fresh(&back);
        candela_flag_identity_value(f, &back.o, word, sizeof word);
        CHECK(strcmp(value, word) != 0 || strcmp(f->name, "--spp") == 0, "%s: its example is the default (%s)", f->name, value);
    }
    /* strings in quotes with escapes, floats exact, several AOVs, a choice no name has */
    fresh(&cl);
    cl.o.camera_name = "my \"cam\" 100%";
    cl.o.env_path = "/sky dir/sky.exr";
    cl.o.env_strength = 0.1f;
    cl.o.aov_spp = cl.o.aov_selection = 1;
    cl.o.cachepoint_progressive = 0;
    cl.o.width = 33;
    cl.o.height = 17;
    candela_options_identity(&cl.o, ident, sizeof ident);
    CHECK(strstr(ident, " camera=\"my%20%22cam%22%20100%25\" ") && strstr(ident, " aov=cachepoint,spp ") &&
              strstr(ident, " res=33x17 ") && strstr(ident, " cachepoint-progressive=0 "), "%s", ident);
    CandelaCommandLine back;
    fresh(&back);
    back.o.aov_recorder_debug = 1; /* replaced by the identity's list */
    snprintf(copy, sizeof copy, "%s", ident);
    CHECK(candela_options_from_identity(&back.o, copy, err) == 0, "%s", err);
    CHECK(back.o.camera_name && strcmp(back.o.camera_name, cl.o.camera_name) == 0, "camera '%s'", back.o.camera_name);
    CHECK(back.o.env_path && strcmp(back.o.env_path, "/sky dir/sky.exr") == 0, "env '%s'", back.o.env_path);
    CHECK(back.o.env_strength == 0.1f && back.o.width == 33 && back.o.height == 17, "%g %dx%d", (double)back.o.env_strength,
          back.o.width, back.o.height);
    CHECK(back.o.aov_spp && back.o.aov_selection && !back.o.aov_recorder_debug, "aovs %d %d %d", back.o.aov_spp,
          back.o.aov_selection, back.o.aov_recorder_debug);
    /* bad identities: one message, nothing half-done matters */
    snprintf(copy, sizeof copy, "spp=x");
    CHECK(candela_options_from_identity(&back.o, copy, err) != 0 && strstr(err, "--spp"), "'%s'", err);
    snprintf(copy, sizeof copy, "camera=\"a%%00b\"");
    CHECK(candela_options_from_identity(&back.o, copy, err) != 0, "a NUL escape was taken");
    snprintf(copy, sizeof copy, "noequals");
    CHECK(candela_options_from_identity(&back.o, copy, err) != 0, "a word without = was taken");
    /* differences: every key, both ways, with display values */
    char diff[CANDELA_ERR_LEN];
    int nd = candela_identity_differences("scene=1 res=8x8 spp=4 env-strength=0x1p+0 seed=1",
                                          "scene=2 res=16x16 spp=4 env-strength=0x1p+1 seed=1", "now", diff, sizeof diff);
    CHECK(nd == 3 && strcmp(diff, "the scene file's content differs, --res 8x8 (now 16x16), --env-strength 1 (now 2)") == 0,
          "%d '%s'", nd, diff);
    return test_exit();
}
