/* renderer/app/provenance.c: how an image was made, as the EXR header's string attributes (and the
 * statistics JSON's "provenance" object): the program and its command line, the host and date,
 * the scene and its content hash, every render option and what the render did. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "candela.h"
#include "checkpoint.h"

int candela_provenance_set(CandelaProvenance *p, const char *name, const char *value) {
    char *copy = strdup(value ? value : "");
    if (!copy) return -1;
    for (int k = 0; k < p->count; ++k)
        if (strcmp(p->attrs[k].name, name) == 0) {
            free((char *)p->attrs[k].value);
            p->attrs[k].value = copy;
            return 0;
        }
    if (p->count >= CANDELA_PROVENANCE_MAX) {
        free(copy);
        return -1;
    }
    p->attrs[p->count++] = (CandelaAttribute){name, copy};
    return 0;
}

void candela_provenance_free(CandelaProvenance *p) {
    for (int k = 0; k < p->count; ++k) free((char *)p->attrs[k].value);
    p->count = 0;
}

int candela_provenance_copy(CandelaProvenance *dst, const CandelaProvenance *src) {
    memset(dst, 0, sizeof *dst);
    for (int k = 0; k < src->count; ++k)
        if (candela_provenance_set(dst, src->attrs[k].name, src->attrs[k].value) != 0) {
            candela_provenance_free(dst);
            return -1;
        }
    return 0;
}

/* a word as a POSIX shell reads it back: as is when it holds only safe characters, else in
 * single quotes (a quote inside as '\'') */
static void shell_word(FILE *f, const char *w) {
    int safe = *w != 0;
    for (const char *c = w; *c && safe; ++c)
        safe = strchr("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_@%+=:,./-", *c) != NULL;
    if (safe) {
        fputs(w, f);
        return;
    }
    fputc('\'', f);
    for (const char *c = w; *c; ++c) {
        if (*c == '\'') fputs("'\\''", f);
        else fputc(*c, f);
    }
    fputc('\'', f);
}

int candela_provenance_begin(CandelaProvenance *p, const char *software, int argc, char *const *argv) {
    memset(p, 0, sizeof *p);
    char *line = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&line, &len);
    if (!f) return -1;
    for (int k = 0; k < argc; ++k) {
        if (k) fputc(' ', f);
        shell_word(f, argv[k]);
    }
    if (fclose(f) != 0) {
        free(line);
        return -1;
    }
    char host[256] = "";
    if (gethostname(host, sizeof host - 1) != 0) snprintf(host, sizeof host, "unknown");
    host[sizeof host - 1] = 0;
    /* OpenEXR's standard capDate: local time "YYYY:MM:DD hh:mm:ss" (OpenImageIO's DateTime) */
    char date[32] = "";
    time_t now = time(NULL);
    struct tm tm;
    if (localtime_r(&now, &tm)) strftime(date, sizeof date, "%Y:%m:%d %H:%M:%S", &tm);
    int rc = candela_provenance_set(p, "software", software) | candela_provenance_set(p, "candela:commandLine", line) |
             candela_provenance_set(p, "candela:host", host);
    if (date[0]) rc |= candela_provenance_set(p, "capDate", date);
    free(line);
    if (rc != 0) candela_provenance_free(p);
    return rc ? -1 : 0;
}

int candela_provenance_scene(CandelaProvenance *p, const char *scene_path, char err[CANDELA_ERR_LEN]) {
    uint64_t h;
    if (checkpoint_scene_hash(scene_path, &h, err) != 0) return -1;
    char hex[17];
    snprintf(hex, sizeof hex, "%016llx", (unsigned long long)h);
    if (candela_provenance_set(p, "candela:scene", scene_path) | candela_provenance_set(p, "candela:sceneHash", hex)) {
        snprintf(err, CANDELA_ERR_LEN, "%s: out of memory", scene_path);
        return -1;
    }
    return 0;
}

int candela_provenance_render(CandelaProvenance *p, const CandelaOptions *o, const CandelaStats *s) {
    char *options = candela_options_json(o);
    if (!options) return -1;
    char spp[32], seed[32], secs[32], mem[32];
    snprintf(spp, sizeof spp, "%d", s->spp_done);
    snprintf(seed, sizeof seed, "%llu", (unsigned long long)o->seed);
    snprintf(secs, sizeof secs, "%.3f", s->time_total);
    snprintf(mem, sizeof mem, "%zu", s->peak_memory_bytes);
    int rc = candela_provenance_set(p, "candela:options", options) |
             candela_provenance_set(p, "candela:lightSamplerUsed", candela_light_sampler_name(s->light_sampler_used)) |
             candela_provenance_set(p, "candela:sppDone", spp) | candela_provenance_set(p, "candela:seed", seed) |
             candela_provenance_set(p, "candela:sampler", candela_sampler_name(o->sampler)) |
             candela_provenance_set(p, "candela:renderSeconds", secs) |
             candela_provenance_set(p, "candela:peakMemoryBytes", mem);
    if (rc == 0 && s->spp_dropped) { /* what the image holds is fewer: path guiding's bootstrap was dropped */
        char dropped[32];
        snprintf(dropped, sizeof dropped, "%d", s->spp_dropped);
        rc = candela_provenance_set(p, "candela:sppDropped", dropped);
    }
    free(options);
    return rc ? -1 : 0;
}

int candela_provenance_identity(CandelaProvenance *p, const CandelaOptions *o, int width, int height) {
    const char *hex = NULL;
    for (int k = 0; k < p->count; ++k)
        if (strcmp(p->attrs[k].name, "candela:sceneHash") == 0) hex = p->attrs[k].value;
    if (!hex) return 0; /* no scene recorded: no identity either */
    char *text = malloc(CANDELA_IDENTITY_LEN);
    if (!text) return -1;
    int rc = 0;
    if (candela_image_identity(o, strtoull(hex, NULL, 16), width, height, text, CANDELA_IDENTITY_LEN) == 0)
        rc = candela_provenance_set(p, "candela:identity", text);
    free(text);
    return rc;
}
