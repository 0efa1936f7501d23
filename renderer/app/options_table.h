/* renderer/app/options_table.h: the command line's flags as one table (private to the CLI, its
 * tests and renderer/app/flags.c; issue 27).
 *
 * Every flag of every subcommand is one row of renderer/app/options_table.c: its name and short
 * alias, the kind of value it takes and that value's range or names, the field it sets, which
 * subcommands take it, and its help. The parser, `candela CMD --help`, `candela help FLAG` and
 * the "did you mean" of an unknown flag all read the rows, so a flag cannot be parsed by one and
 * missing from another. */
#ifndef CANDELA_OPTIONS_TABLE_H
#define CANDELA_OPTIONS_TABLE_H

#include <stddef.h>
#include <stdio.h>

#include "candela.h"

/* The subcommands, as bits of CandelaFlag.commands. CANDELA_CMD_VARIANT is a variant of
 * `candela compare --variants` (the render flags that may differ between variants). */
enum {
    CANDELA_CMD_RENDER = 1u << 0,
    CANDELA_CMD_BENCH = 1u << 1,
    CANDELA_CMD_GUIDE_DUMP = 1u << 2,
    CANDELA_CMD_COMPARE = 1u << 3,
    CANDELA_CMD_MERGE = 1u << 4,
    CANDELA_CMD_VARIANT = 1u << 5
};

/* Everything one command line sets: the render options and the other commands' own. The table's
 * CLI rows point into it (offsetof); its render rows point into CandelaOptions, so
 * candela_parse_render_flag can fill a variant's options alone. */
typedef struct CandelaCommandLine {
    CandelaOptions o;
    CandelaCompareOptions co;
    CandelaBatchOptions batch;
    const char *out, *png, *stats_json;
    int no_png, save_partial;
    int have_at;  /* guide-dump's --at was given */
    int spp_given; /* --spp was given (compare's equal time: --spp is then a cap, not 1048576) */
    int help;     /* -h / --help: print the command's flags and stop */
} CandelaCommandLine;

typedef enum {
    CANDELA_FLAG_SWITCH, /* no value: sets an int field to 1 */
    CANDELA_FLAG_INT,    /* an integer in [lo, hi] */
    CANDELA_FLAG_FLOAT,  /* a number in [lo, hi] (parsed as a float, as always) */
    CANDELA_FLAG_CHOICE, /* one of names[] -> values[] */
    CANDELA_FLAG_STRING, /* any word (a path, a list checked later) */
    CANDELA_FLAG_CUSTOM  /* set(): resolutions, I/N, X,Y,Z, ... (metavar says which) */
} CandelaFlagKind;

/* CandelaFlag.files */
enum { CANDELA_FILES_READS = 1u << 0, CANDELA_FILES_WRITES = 1u << 1 };

typedef enum { CANDELA_FIELD_INT, CANDELA_FIELD_U32, CANDELA_FIELD_U64, CANDELA_FIELD_FLOAT, CANDELA_FIELD_DOUBLE,
               CANDELA_FIELD_STR, CANDELA_FIELD_NONE } CandelaFieldType;

typedef struct CandelaFlag {
    const char *name;     /* "--spp" */
    const char *alias;    /* "-o", or NULL */
    CandelaFlagKind kind;
    const char *metavar;  /* what the value looks like in the help ("N", "WxH", "on|off"); NULL: none */
    double lo, hi;        /* INT / FLOAT ranges */
    const char *const *names; /* CHOICE: NULL-terminated */
    const int *values;
    const char *what;     /* CHOICE: "unknown WHAT 'x' (...)"; NULL: "unknown value 'x' for FLAG (...)" */
    int render;           /* 1: a render option (field in CandelaOptions, candela_parse_render_flag takes
                           * it); 0: the field is in CandelaCommandLine */
    size_t offset;
    int image;            /* 1: the option changes the image: it is part of the render's identity
                           * (candela_options_identity: checkpoints, films, --frames --resume,
                           * compare's cached reference) and --resume-from takes it from the
                           * checkpoint; 0: it never does (threads, outputs, budgets, --time-limit:
                           * where a render stops, not what it computes) */
    CandelaFieldType field;
    /* CUSTOM: sets the value into base (CandelaOptions or CandelaCommandLine as `render` says);
     * 0 ok, -1 with err (no program-name prefix) */
    int (*set)(void *base, const char *flag, const char *value, char err[CANDELA_ERR_LEN]);
    unsigned commands;    /* the subcommands it belongs to (listed in their --help, suggested) */
    unsigned tolerated;   /* further subcommands that parse it, only to refuse or ignore it later
                           * with their own message (e.g. --frames in bench: "belongs to candela render") */
    const char *example;  /* a valid value (the tests feed every row its example); NULL for switches */
    const char *help;     /* one line */
    const char *long_help; /* candela help FLAG */
    /* CANDELA_FILES_ bits: the value names a file (or folder) the run reads or writes. The
     * outputs rule's inputs and outputs, and why a compare variant may not hold a flag that
     * writes (its files are the report's) and a flag that reads is confined like the scene. */
    unsigned files;
    /* CUSTOM rows whose value is in CandelaOptions: writes it as a JSON value (the provenance's
     * candela:options); NULL: the row is not there */
    void (*get)(const CandelaOptions *o, FILE *f);
    /* CUSTOM rows with `image`: writes the value as set() takes it back (the identity's form) */
    void (*show)(const CandelaOptions *o, char *buf, size_t size);
} CandelaFlag;

/* The table (count rows). */
const CandelaFlag *candela_flags(size_t *count);
/* "render" -> CANDELA_CMD_RENDER ...; 0 when name is no subcommand. */
unsigned candela_command_bit(const char *name);
/* The row named `arg` ("--spp", "-o", "--spp=4": the part before '='; "spp" too when bare is
 * set), or NULL. */
const CandelaFlag *candela_flag_find(const char *arg, int bare);

/* argv[*i] (and its value: the next word, or after '=' in --flag=value) as a flag of command
 * `cmd` (a CANDELA_CMD_ bit). Returns 1 when parsed (*i on its last word, *row the row), 0 when
 * argv[*i] is no flag of cmd (nothing changed), -1 on a missing or bad value (err, one line, no
 * prefix). */
int candela_parse_flag(CandelaCommandLine *cl, unsigned cmd, int argc, char *const *argv, int *i,
                       const CandelaFlag **row, char err[CANDELA_ERR_LEN]);
/* The error line of an unknown option `arg` of cmd: "unknown option '--spl' (did you mean
 * '--spp'?)", or "... (see candela CMD --help)" when no flag is close. `what` replaces
 * "option" (e.g. "merge option"). */
void candela_unknown_flag_message(const char *arg, unsigned cmd, const char *what, char err[CANDELA_ERR_LEN]);
/* The nearest flag of cmd's (any when cmd is 0) to `arg` by edit distance, when close (distance
 * <= 2 or <= a third of the name's length); NULL otherwise. */
const char *candela_flag_suggest(const char *arg, unsigned cmd);
/* The flags of cmd, one line each (cmd 0: every flag). */
void candela_print_flags(FILE *f, unsigned cmd);
/* Every row's name and alias (if any), one row a line ("--output -o"): `candela help
 * --list-flags`, which tests/test_readme.sh compares with README.md's flag list. */
void candela_print_flag_names(FILE *f);
/* candela help FLAG: the flag's long help. 0, or 2 with the error line on stderr. */
int candela_print_flag_help(FILE *f, const char *name);

/* --- the image identity (issue 27) ----------------------------------------------------------
 * Every `image` row of the table as NAME=VALUE (NAME without the dashes), in table order,
 * separated by single spaces: integers in decimal, floats in C99 hex (%a: exact), choices by
 * name (a value no name has, e.g. --cachepoint-progressive's default 0, as its number),
 * switches 0/1, strings in double quotes with bytes <= ' ', '"', '%' and >= 0x7f as %XX, an unset
 * string as -; --res is o->width x o->height (the caller puts the resolved size there); --crop is
 * X0,Y0,X1,Y1, and no word at all without a crop (identities from before the flag stay valid). */

/* s in the identity's string form ("..." with %XX escapes; NULL as -) into buf. */
void candela_identity_quote(const char *s, char *buf, size_t size);
/* Decodes a quoted value in place: the string (v itself, without the quotes), or NULL when v is
 * not in that form. */
char *candela_identity_unquote(char *v);
/* Row f's canonical value (f->image rows; "" for others). */
void candela_flag_identity_value(const CandelaFlag *f, const CandelaOptions *o, char *buf, size_t size);
/* The identity of o's image options; the length written, or -1 when it does not fit size. */
int candela_options_identity(const CandelaOptions *o, char *buf, size_t size);
/* Sets the options an identity names into o (its other fields stay): `text` is modified (the
 * strings are decoded in place and o points into it, so it must outlive o). Keys that are no
 * image row ("scene", "max-iteration-spp") are skipped. 0 ok, -1 with err. */
int candela_options_from_identity(CandelaOptions *o, char *text, char err[CANDELA_ERR_LEN]);
/* The value of `key` in an identity text (canonical form) into buf; 0 when found, -1 when not. */
int candela_identity_value(const char *text, const char *key, char *buf, size_t size);
/* A canonical value as a person reads it (hex floats as %g, strings without quotes). */
void candela_identity_display(const char *value, char *buf, size_t size);
/* Every key whose value differs between identities a and b, as "--KEY A (LABEL B)" joined by
 * ", " into out (keys that are no flag, e.g. "scene", as "KEY"); the number of differences. */
int candela_identity_differences(const char *a, const char *b, const char *label, char *out, size_t size);

#endif
