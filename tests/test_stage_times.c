/* tests/test_stage_times.c: the statistics' stage times add up (issue 27).
 *
 * Renders through the CLI with --stats-json (plain, guided: its training is the "learn" phase,
 * and adaptive: its decisions are at the barriers) and reads "time_seconds" back: every stage
 * is a wall time measured on the main thread, so load + build + the stages + other equals the
 * total, the stages alone never exceed the render's time (total - load - build) and cover at
 * least 80 % of it ("other" is bookkeeping: progress, checkpoint writes). Only sums of the
 * recorded numbers are compared, never a time against a constant. The per-thread detail
 * ("stage_thread_seconds") must be there too.
 * usage: test_stage_times CANDELA_BINARY SCENES_DIR */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"

static const char *const KEYS[] = {"load", "build", "generate", "sort", "trace", "medium", "shade", "shadow",
                                   "learn", "film", "barrier", "other", "total"};
enum { NKEYS = sizeof KEYS / sizeof KEYS[0] };

/* The number after "KEY": inside the object that starts at `object`, or -1 when missing. */
static double member(const char *object, const char *key) {
    const char *end = strchr(object, '}');
    char pat[64];
    snprintf(pat, sizeof pat, "\"%s\": ", key);
    const char *p = strstr(object, pat);
    if (!p || (end && p > end)) return -1.0;
    return strtod(p + strlen(pat), NULL);
}

static char *slurp(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    static char buf[1 << 16];
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = 0;
    return buf;
}

static void check_render(const char *bin, const char *scene, const char *flags, const char *dir) {
    char cmd[4096], json[1024];
    snprintf(json, sizeof json, "%s/stats.json", dir);
    remove(json);
    snprintf(cmd, sizeof cmd, "'%s' render '%s' %s --threads 2 --no-png -o '%s/x.exr' --stats-json '%s' --quiet", bin, scene,
             flags, dir, json);
    int rc = system(cmd);
    CHECK(rc == 0, "%s: exited %d", cmd, rc);
    const char *text = slurp(json);
    CHECK(text != NULL, "no %s", json);
    if (!text) return;
    const char *times = strstr(text, "\"time_seconds\": {");
    CHECK(times != NULL, "%s: no time_seconds", flags);
    if (!times) return;
    double v[NKEYS];
    for (int k = 0; k < NKEYS; ++k) {
        v[k] = member(times, KEYS[k]);
        CHECK(v[k] >= 0.0, "%s: time_seconds.%s missing or negative (%g)", flags, KEYS[k], v[k]);
    }
    double stages = 0.0;
    for (int k = 2; k <= 10; ++k) stages += v[k]; /* generate .. barrier */
    double total = v[12], render = total - v[0] - v[1];
    /* printed with 6 decimals: 13 roundings of at most 5e-7 each */
    const double print = 13 * 5e-7;
    CHECK(stages <= render + print, "%s: the stages' %.6f s exceed the render's %.6f s", flags, stages, render);
    CHECK(stages >= 0.8 * render, "%s: the stages' %.6f s cover less than 80 %% of the render's %.6f s", flags, stages,
          render);
    CHECK(v[0] + v[1] + stages + v[11] <= total + print && v[0] + v[1] + stages + v[11] >= total - print,
          "%s: load %.6f + build %.6f + stages %.6f + other %.6f != total %.6f", flags, v[0], v[1], stages, v[11], total);
    const char *per_thread = strstr(text, "\"stage_thread_seconds\": {");
    CHECK(per_thread && member(per_thread, "threads") >= 1 && member(per_thread, "trace") >= 0.0,
          "%s: no per-thread stage times", flags);
    fprintf(stderr, "%s: render %.4f s, stages %.4f s (%.1f %%), other %.4f s\n", flags, render, stages,
            render > 0 ? 100.0 * stages / render : 0.0, v[11]);
}

int main(int argc, char **argv) {
    if (argc < 3) { fprintf(stderr, "usage: test_stage_times CANDELA SCENES_DIR\n"); return 2; }
    char dir[] = "/tmp/candela-test-stage-times-XXXXXX";
    if (!mkdtemp(dir)) { perror("mkdtemp"); return 1; }
    char scene[4096];
    snprintf(scene, sizeof scene, "%s/default.gltf", argv[2]);
    check_render(argv[1], scene, "--res 64x48 --spp 8", dir);
    check_render(argv[1], scene, "--res 64x48 --spp 64 --noise-threshold 0.5 --min-spp 8", dir);
    snprintf(scene, sizeof scene, "%s/guiding_interior.gltf", argv[2]);
    check_render(argv[1], scene, "--res 48x32 --spp 32 --guiding mis", dir);
    char cmd[4200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", dir);
    return test_exit();
}
