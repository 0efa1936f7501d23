/* tests/test_compare.c: `candela compare` on the default scene, end to end, through the CLI.
 *
 * The report's numbers are checked against metrics this test computes itself from the EXRs
 * the report wrote (its own loops, not renderer/app/metrics.c): RMSE, relMSE, MAE and the mean
 * variance to the CSV's print precision, TTUV = mean variance x time and the ratios against
 * the first variant; every variant at the requested spp; the convergence snapshots end at
 * the final image; the crops PNG holds the reference's and the variants' pixels at the crop
 * the page names. The noise-corrected MSE and relMSE are the raw ones minus the reference's
 * variance term, computed here from reference.exr's variance layer; the page has a row per
 * variant holding its image, its error map with the colour bar and its crop (parsed from the
 * HTML), and no test marker. Then equal time: every variant runs at least the budget and reports the spp
 * it reached.
 * usage: test_compare CANDELA_BINARY SCENE */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "check.h"
#include "io.h"

enum { MAX_ROWS = 512, MAX_COLS = 40 };

typedef struct Csv {
    int rows, cols;
    char *cell[MAX_ROWS + 1][MAX_COLS]; /* row 0: the header */
} Csv;

/* A CSV with "quoted" fields ("" inside is a quote), one record per line. */
static int csv_read(const char *path, Csv *csv) {
    memset(csv, 0, sizeof *csv);
    FILE *f = fopen(path, "r");
    if (!f) return -1;
    char line[4096];
    while (csv->rows <= MAX_ROWS && fgets(line, sizeof line, f)) {
        int col = 0;
        char field[1024];
        size_t len = 0;
        int quoted = 0;
        for (char *p = line;; ++p) {
            if (quoted) {
                if (*p == '"' && p[1] == '"') { field[len++] = '"'; ++p; }
                else if (*p == '"') quoted = 0;
                else if (*p) field[len++] = *p;
                else break;
                continue;
            }
            if (*p == '"') { quoted = 1; continue; }
            if (*p == ',' || *p == '\n' || *p == 0) {
                field[len] = 0;
                if (col < MAX_COLS) csv->cell[csv->rows][col++] = strdup(field);
                len = 0;
                if (*p != ',') break;
            } else if (len + 1 < sizeof field) {
                field[len++] = *p;
            }
        }
        if (csv->rows == 0) csv->cols = col;
        ++csv->rows;
    }
    fclose(f);
    --csv->rows; /* data rows */
    return 0;
}

static void csv_free(Csv *csv) {
    for (int r = 0; r <= MAX_ROWS; ++r)
        for (int c = 0; c < MAX_COLS; ++c) free(csv->cell[r][c]);
}

static int csv_col(const Csv *csv, const char *name) {
    for (int c = 0; c < csv->cols; ++c)
        if (strcmp(csv->cell[0][c], name) == 0) return c;
    CHECK(0, "no column %s", name);
    return 0;
}

static double num(const Csv *csv, int row, const char *name) {
    const char *s = csv->cell[row][csv_col(csv, name)];
    return s && *s ? strtod(s, NULL) : NAN;
}

static int row_of(const Csv *csv, const char *variant) {
    for (int r = 1; r <= csv->rows; ++r)
        if (strcmp(csv->cell[r][0], variant) == 0) return r;
    return -1;
}

/* R, G, B (or variance.R, ...) of an EXR, interleaved. */
static float *read_rgb(const char *path, const char *prefix, int *w, int *h) {
    float *rgb = NULL;
    const char *names[3] = {"R", "G", "B"};
    for (int k = 0; k < 3; ++k) {
        char name[64];
        snprintf(name, sizeof name, "%s%s", prefix, names[k]);
        float *ch = NULL;
        char err[IO_ERR_LEN];
        if (io_read_exr_channel(path, name, w, h, &ch, err) != 0) {
            CHECK(0, "%s", err);
            free(rgb);
            return NULL;
        }
        size_t n = (size_t)*w * (size_t)*h;
        if (!rgb) rgb = malloc(3 * n * sizeof(float));
        for (size_t i = 0; i < n; ++i) rgb[3 * i + k] = ch[i];
        free(ch);
    }
    return rgb;
}

static int rel_close(double a, double b, double tol) { return fabs(a - b) <= tol * fmax(fabs(a), fabs(b)) + 1e-300; }

static double srgb8(float x) { /* the preview's encoding, quantised as the PNG is */
    double v = x <= 0.0f ? 0.0 : x >= 1.0f ? 1.0 : x <= 0.0031308f ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055;
    return floor(v * 255.0 + 0.5) / 255.0;
}

static int run(const char *cmd) {
    int rc = system(cmd);
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : 255;
}

static const char *const VARIANTS[3] = {"power", "tree", "guided"};

/* The string attribute name of path's EXR header into value ("" when none). */
static void exr_attribute(const char *path, const char *name, char *value, size_t size) {
    char err[IO_ERR_LEN];
    int w, h;
    value[0] = 0;
    CHECK(io_exr_complete_attribute(path, &w, &h, name, value, size, err) == 0, "%s", err);
}

/* issue 27: a report image's header says how it was made: the compare command line, its own
 * render's options (every option as JSON), the scene and its hash, the variant's name */
static void check_provenance(const char *path, const char *variant, const char *options_part) {
    static char value[16384];
    exr_attribute(path, "candela:compareVariant", value, sizeof value);
    CHECK(strcmp(value, variant) == 0, "%s: candela:compareVariant '%s', not '%s'", path, value, variant);
    exr_attribute(path, "candela:options", value, sizeof value);
    CHECK(value[0] == '{' && strstr(value, options_part), "%s: candela:options lacks %s: %s", path, options_part, value);
    exr_attribute(path, "candela:commandLine", value, sizeof value);
    CHECK(strstr(value, " compare ") != NULL, "%s: candela:commandLine '%s'", path, value);
    exr_attribute(path, "candela:sceneHash", value, sizeof value);
    CHECK(strlen(value) == 16 && strspn(value, "0123456789abcdef") == 16, "%s: candela:sceneHash '%s'", path, value);
    exr_attribute(path, "software", value, sizeof value);
    CHECK(strncmp(value, "candela ", 8) == 0, "%s: software '%s'", path, value);
    exr_attribute(path, "candela:sppDone", value, sizeof value);
    CHECK(atoi(value) > 0, "%s: candela:sppDone '%s'", path, value);
}

static void check_equal_spp(const char *bin, const char *scene, const char *dir) {
    char cmd[8192], path[4096];
    snprintf(cmd, sizeof cmd,
             "'%s' compare '%s' --spp 4 --res 32x24 --ref-spp 16 --out-dir '%s' --quiet --variants "
             "'power: --light-sampler power; tree: --light-sampler tree --max-depth 3; guided: --light-sampler tree "
             "--guiding ris --guide-training-spp 2' > /dev/null",
             bin, scene, dir);
    int rc = run(cmd);
    CHECK(rc == 0, "compare exited %d", rc);
    if (rc != 0) return;

    int w, h;
    snprintf(path, sizeof path, "%s/reference.exr", dir);
    float *ref = read_rgb(path, "", &w, &h);
    if (!ref) return;
    CHECK(w == 32 && h == 24, "reference %dx%d", w, h);
    size_t n = 3 * (size_t)w * (size_t)h;
    /* the reference's noise: its variance of the mean, averaged as the MSE averages */
    int rvw, rvh;
    float *ref_var = read_rgb(path, "variance.", &rvw, &rvh);
    double ref_noise = 0.0, ref_noise_rel = 0.0;
    for (size_t i = 0; ref_var && i < n; ++i) {
        ref_noise += ref_var[i];
        ref_noise_rel += ref_var[i] / ((double)ref[i] * ref[i] + 0.01);
    }
    ref_noise /= (double)n;
    ref_noise_rel /= (double)n;
    CHECK(ref_var && ref_noise > 0.0, "reference.exr: no variance layer, or a zero one");
    free(ref_var);
    check_provenance(path, "reference", "\"spp\": 16,");

    static Csv csv, conv;
    snprintf(path, sizeof path, "%s/table.csv", dir);
    CHECK(csv_read(path, &csv) == 0, "no %s", path);
    CHECK(csv.rows == 3, "%d rows", csv.rows);
    double first[5] = {0}; /* time, rmse, relmse, mae, ttuv of the first variant */
    for (int v = 0; v < 3 && csv.rows == 3; ++v) {
        int r = row_of(&csv, VARIANTS[v]);
        CHECK(r == v + 1, "%s in row %d (variants keep their order)", VARIANTS[v], r);
        if (r < 0) continue;
        int vw, vh;
        snprintf(path, sizeof path, "%s/%s.exr", dir, VARIANTS[v]);
        check_provenance(path, VARIANTS[v], v == 1 ? "\"max-depth\": 3," : v == 2 ? "\"guiding\": \"ris\"" : "\"light-sampler\": \"power\"");
        float *img = read_rgb(path, "", &vw, &vh);
        float *var = read_rgb(path, "variance.", &vw, &vh);
        if (!img || !var) { free(img); free(var); continue; }
        /* the metrics, computed here */
        double se = 0, rel = 0, ae = 0, vs = 0;
        for (size_t i = 0; i < n; ++i) {
            double d = (double)img[i] - (double)ref[i];
            se += d * d;
            rel += d * d / ((double)ref[i] * ref[i] + 0.01);
            ae += fabs(d);
            vs += var[i];
        }
        double rmse = sqrt(se / n), relmse = rel / n, mae = ae / n, mvar = vs / n;
        /* the main numbers: raw minus the reference's noise (a difference: compared against the
         * size of its terms) */
        double mse = se / n, mse_c = num(&csv, r, "mse_corrected"), rel_c = num(&csv, r, "relmse_corrected");
        CHECK(rel_close(num(&csv, r, "mse"), mse, 1e-8), "%s mse %.9g, computed %.9g", VARIANTS[v], num(&csv, r, "mse"), mse);
        CHECK(fabs(mse_c - (mse - ref_noise)) <= 1e-8 * fmax(mse, ref_noise), "%s mse_corrected %.9g, computed %.9g - %.9g",
              VARIANTS[v], mse_c, mse, ref_noise);
        CHECK(fabs(rel_c - (relmse - ref_noise_rel)) <= 1e-8 * fmax(relmse, ref_noise_rel),
              "%s relmse_corrected %.9g, computed %.9g - %.9g", VARIANTS[v], rel_c, relmse, ref_noise_rel);
        CHECK(rel_close(num(&csv, r, "ref_noise_mse"), ref_noise, 1e-8) && rel_close(num(&csv, r, "ref_noise_relmse"), ref_noise_rel, 1e-8),
              "%s reference noise %.9g %.9g, computed %.9g %.9g", VARIANTS[v], num(&csv, r, "ref_noise_mse"),
              num(&csv, r, "ref_noise_relmse"), ref_noise, ref_noise_rel);
        double t = num(&csv, r, "time_s"), ttuv = num(&csv, r, "ttuv");
        /* printed with 9 significant digits: equal to ~5e-9 relative */
        CHECK(rel_close(num(&csv, r, "rmse"), rmse, 1e-8), "%s rmse %.9g, computed %.9g", VARIANTS[v], num(&csv, r, "rmse"), rmse);
        CHECK(rel_close(num(&csv, r, "relmse"), relmse, 1e-8), "%s relmse %.9g, computed %.9g", VARIANTS[v],
              num(&csv, r, "relmse"), relmse);
        CHECK(rel_close(num(&csv, r, "mae"), mae, 1e-8), "%s mae %.9g, computed %.9g", VARIANTS[v], num(&csv, r, "mae"), mae);
        CHECK(rel_close(num(&csv, r, "mean_variance"), mvar, 1e-8), "%s mean variance %.9g, computed %.9g", VARIANTS[v],
              num(&csv, r, "mean_variance"), mvar);
        CHECK(rel_close(ttuv, mvar * t, 2e-8), "%s ttuv %.9g, mean variance x time %.9g", VARIANTS[v], ttuv, mvar * t);
        CHECK(num(&csv, r, "spp") == 4, "%s spp %g", VARIANTS[v], num(&csv, r, "spp"));
        CHECK(t > 0 && num(&csv, r, "preprocess_s") >= 0 && num(&csv, r, "preprocess_s") <= t && num(&csv, r, "peak_mib") > 0,
              "%s times %g, %g, peak %g", VARIANTS[v], t, num(&csv, r, "preprocess_s"), num(&csv, r, "peak_mib"));
        double mine[5] = {t, rmse, relmse, mae, ttuv};
        const char *ratio_cols[5] = {"time_ratio", "rmse_ratio", "relmse_ratio", "mae_ratio", "ttuv_ratio"};
        if (v == 0) memcpy(first, mine, sizeof first);
        for (int k = 0; k < 5; ++k)
            CHECK(rel_close(num(&csv, r, ratio_cols[k]), mine[k] / first[k], 4e-8), "%s %s %.9g, computed %.9g", VARIANTS[v],
                  ratio_cols[k], num(&csv, r, ratio_cols[k]), mine[k] / first[k]);
        free(img);
        free(var);
    }
    /* the variants differ (else the test could not tell rows apart) */
    if (csv.rows == 3) CHECK(num(&csv, 1, "rmse") != num(&csv, 2, "rmse"), "power and tree have the same RMSE");

    /* convergence: spp rises at every snapshot to 4, and the last one is the final image */
    snprintf(path, sizeof path, "%s/convergence.csv", dir);
    CHECK(csv_read(path, &conv) == 0, "no %s", path);
    for (int v = 0; v < 3; ++v) {
        int last = -1, prev_spp = 0, rising = 1;
        double prev_t = 0;
        for (int r = 1; r <= conv.rows; ++r) {
            if (strcmp(conv.cell[r][0], VARIANTS[v]) != 0) continue;
            int spp = (int)num(&conv, r, "spp");
            double t = num(&conv, r, "seconds");
            rising &= spp > prev_spp && t >= prev_t;
            prev_spp = spp;
            prev_t = t;
            last = r;
        }
        CHECK(rising, "%s: snapshots not in order", VARIANTS[v]);
        int tr = row_of(&csv, VARIANTS[v]);
        if (last > 0 && tr > 0) {
            CHECK(num(&conv, last, "spp") == 4, "%s: last snapshot at %g spp", VARIANTS[v], num(&conv, last, "spp"));
            CHECK(rel_close(num(&conv, last, "rmse"), num(&csv, tr, "rmse"), 1e-8), "%s: last snapshot rmse %.9g, image %.9g",
                  VARIANTS[v], num(&conv, last, "rmse"), num(&csv, tr, "rmse"));
        } else {
            CHECK(0, "%s: no snapshots", VARIANTS[v]);
        }
    }
    csv_free(&conv);

    /* crops.png: panel p, pixel (x, y) is the crop's pixel of the reference (p = 0) or of
     * variant p, enlarged; the crop is the one the page names */
    snprintf(path, sizeof path, "%s/index.html", dir);
    FILE *f = fopen(path, "r");
    int x0 = -1, x1 = -1, y0 = -1, y1 = -1;
    if (f) {
        char line[8192];
        while (fgets(line, sizeof line, f)) {
            char *p = strstr(line, "<p>Pixels ");
            if (p && sscanf(p, "<p>Pixels %d-%d &times; %d-%d", &x0, &x1, &y0, &y1) == 4) break;
        }
        fclose(f);
    }
    int side = x1 - x0 + 1;
    CHECK(x0 >= 0 && side == y1 - y0 + 1 && side == 8 && x1 < w && y1 < h, "crop %d-%d x %d-%d", x0, x1, y0, y1);
    IoImage crops;
    char err[IO_ERR_LEN];
    snprintf(path, sizeof path, "%s/crops.png", dir);
    if (side == 8 && io_load_image(path, 0, &crops, err) == 0) {
        int scale = 20, panel = 160; /* panels at least 160 pixels */
        CHECK(crops.width == 4 * panel + 3 * 4 && crops.height == panel, "crops.png %dx%d", crops.width, crops.height);
        for (int p = 0; p < 4 && crops.width == 4 * panel + 3 * 4; ++p) {
            float *src = ref;
            if (p > 0) {
                int vw, vh;
                snprintf(path, sizeof path, "%s/%s.exr", dir, VARIANTS[p - 1]);
                src = read_rgb(path, "", &vw, &vh);
                if (!src) continue;
            }
            int bad = 0;
            for (int y = 0; y < side; ++y)
                for (int x = 0; x < side; ++x)
                    for (int k = 0; k < 3; ++k) {
                        size_t d = 4 * ((size_t)(y * scale + scale / 2) * crops.width + (size_t)(p * (panel + 4) + x * scale + scale / 2));
                        double want = srgb8(src[3 * ((size_t)(y0 + y) * w + (x0 + x)) + k]);
                        /* the PNG reader decodes sRGB to linear: compare in linear */
                        double got = crops.rgba[d + k];
                        double want_lin = want <= 0.04045 ? want / 12.92 : pow((want + 0.055) / 1.055, 2.4);
                        bad += fabs(got - want_lin) > 1e-3 && fabs(got - want) > 1e-3;
                    }
            CHECK(bad == 0, "crops.png panel %d: %d values differ from the image", p, bad);
            if (p > 0) free(src);
        }
        io_image_free(&crops);
    } else if (side == 8) {
        CHECK(0, "%s", err);
    }

    /* the page: a row per image (the reference and each variant) holding its image, its error
     * map with the colour bar and its scale, and its crop; the corrected MSE is the row's main
     * number in the table; no test marker or script */
    snprintf(path, sizeof path, "%s/index.html", dir);
    static char page[1 << 20];
    size_t page_len = 0;
    if ((f = fopen(path, "r"))) {
        page_len = fread(page, 1, sizeof page - 1, f);
        fclose(f);
    }
    page[page_len] = 0;
    int rows = 0;
    for (const char *p = page; (p = strstr(p, "<tr class=\"image-row\">")); ++p) ++rows;
    CHECK(rows == 4, "index.html: %d image rows, expected 4 (the reference and 3 variants)", rows);
    CHECK(!strstr(page, "IMAGES-OK") && !strstr(page, "<script"), "index.html holds a test marker or a script");
    for (int v = -1; v < 3; ++v) {
        const char *name = v < 0 ? "reference" : VARIANTS[v];
        char start[128], want[160];
        snprintf(start, sizeof start, "<tr class=\"image-row\"><th>%s</th>", name);
        const char *row = strstr(page, start), *end = row ? strstr(row, "</tr>") : NULL;
        CHECK(row && end, "index.html: no image row for %s", name);
        if (!row || !end) continue;
        size_t len = (size_t)(end - row);
        char *text = strndup(row, len);
        const char *parts[3] = {".png", "_error.png", "_crop.png"};
        for (int k = 0; k < 3; ++k) {
            if (v < 0 && k == 1) continue; /* the reference has no error map */
            snprintf(want, sizeof want, "<img src=\"%s%s\"", name, parts[k]);
            if (k == 2) snprintf(want, sizeof want, "<img class=\"crop\" src=\"%s%s\"", name, parts[k]);
            CHECK(strstr(text, want) != NULL, "%s's row lacks %s", name, want);
            struct stat st;
            snprintf(path, sizeof path, "%s/%s%s", dir, name, parts[k]);
            CHECK(stat(path, &st) == 0 && st.st_size > 0, "%s missing", path);
        }
        if (v >= 0)
            CHECK(strstr(text, "class=\"colourbar\"") && strstr(text, "<span>0 %</span>") && strstr(text, "100 %</span>"),
                  "%s's row lacks the colour bar and its scale", name);
        free(text);
        if (v >= 0 && row_of(&csv, name) > 0) {
            snprintf(want, sizeof want, "<td class=\"main\">%.5g</td>", num(&csv, row_of(&csv, name), "mse_corrected"));
            CHECK(strstr(page, want) != NULL, "index.html: no %s for %s", want, name);
        }
    }
    IoImage one;
    snprintf(path, sizeof path, "%s/reference_crop.png", dir);
    if (io_load_image(path, 0, &one, err) == 0) {
        CHECK(one.width == 160 && one.height == 160, "reference_crop.png %dx%d", one.width, one.height);
        io_image_free(&one);
    } else {
        CHECK(0, "%s", err);
    }

    /* every file the page shows */
    const char *files[] = {"reference.png", "crops.png", "convergence_spp.svg", "convergence_time.svg", "table.md", "index.html"};
    for (int i = 0; i < 6; ++i) {
        struct stat st;
        snprintf(path, sizeof path, "%s/%s", dir, files[i]);
        CHECK(stat(path, &st) == 0 && st.st_size > 0, "%s missing", files[i]);
    }
    for (int v = 0; v < 3; ++v) {
        struct stat st;
        snprintf(path, sizeof path, "%s/%s_error.png", dir, VARIANTS[v]);
        CHECK(stat(path, &st) == 0 && st.st_size > 0, "%s missing", path);
        snprintf(path, sizeof path, "%s/%s.png", dir, VARIANTS[v]);
        CHECK(stat(path, &st) == 0 && st.st_size > 0, "%s missing", path);
    }
    csv_free(&csv);
    free(ref);
}

/* Equal time: each variant renders at least the budget (it stops at the first barrier past
 * it) and the table reports the spp it reached, as its last snapshot does. */
static void check_equal_time(const char *bin, const char *scene, const char *dir) {
    char cmd[8192], path[4096];
    const double budget = 0.3;
    snprintf(cmd, sizeof cmd,
             "'%s' compare '%s' --time-budget %g --res 32x24 --ref-spp 16 --out-dir '%s' --quiet "
             "--strategies power,tree > /dev/null",
             bin, scene, budget, dir);
    int rc = run(cmd);
    CHECK(rc == 0, "compare --time-budget exited %d", rc);
    if (rc != 0) return;
    static Csv csv, conv; /* static: large, and used one at a time */
    snprintf(path, sizeof path, "%s/table.csv", dir);
    CHECK(csv_read(path, &csv) == 0 && csv.rows == 2, "equal time: table rows");
    snprintf(path, sizeof path, "%s/convergence.csv", dir);
    CHECK(csv_read(path, &conv) == 0, "equal time: convergence.csv");
    for (int r = 1; r <= csv.rows; ++r) {
        double spp = num(&csv, r, "spp"), t = num(&csv, r, "time_s");
        CHECK(spp >= 1 && spp < (1 << 20), "%s: spp %g", csv.cell[r][0], spp);
        CHECK(t >= budget, "%s: stopped at %g s, before the budget", csv.cell[r][0], t);
        int last = -1;
        for (int k = 1; k <= conv.rows; ++k)
            if (strcmp(conv.cell[k][0], csv.cell[r][0]) == 0) last = k;
        CHECK(last > 0 && num(&conv, last, "spp") == spp && num(&conv, last, "seconds") >= budget,
              "%s: last snapshot at %g spp, %g s", csv.cell[r][0], last > 0 ? num(&conv, last, "spp") : -1.0,
              last > 0 ? num(&conv, last, "seconds") : -1.0);
    }
    csv_free(&csv);
    csv_free(&conv);
}

/* A --reference rendered with the compared renders' seed gets a warning naming it (their
 * errors are correlated); one rendered with another seed does not. */
static void check_reference_seed(const char *bin, const char *scene, const char *dir) {
    char cmd[8192], ref[1024], log[1024];
    for (int seed = 0; seed <= 7; seed += 7) {
        snprintf(ref, sizeof ref, "%s/ref%d.exr", dir, seed);
        snprintf(log, sizeof log, "%s/log%d.txt", dir, seed);
        snprintf(cmd, sizeof cmd, "mkdir -p '%s' && '%s' render '%s' --res 32x24 --spp 8 --seed %d -o '%s' --no-png 2> /dev/null",
                 dir, bin, scene, seed, ref);
        CHECK(run(cmd) == 0, "rendering the seed-%d reference failed", seed);
        snprintf(cmd, sizeof cmd,
                 "'%s' compare '%s' --spp 4 --res 32x24 --reference '%s' --strategies tree --out-dir '%s/cmp%d' "
                 "> /dev/null 2> '%s'",
                 bin, scene, ref, dir, seed, log);
        CHECK(run(cmd) == 0, "compare --reference (seed %d) failed", seed);
        FILE *f = fopen(log, "r");
        static char text[65536];
        size_t n = f ? fread(text, 1, sizeof text - 1, f) : 0;
        if (f) fclose(f);
        text[n] = 0;
        int warned = strstr(text, "warning: ") && strstr(text, ref) && strstr(text, "seed 0");
        CHECK(warned == (seed == 0), "reference of seed %d: %s (stderr: %.300s)", seed,
              seed == 0 ? "no warning about the shared seed" : "a warning, though the seeds differ", text);
    }
}

int main(int argc, char **argv) {
    if (argc < 3) { fprintf(stderr, "usage: test_compare CANDELA SCENE\n"); return 2; }
    char dir[] = "/tmp/candela-test-compare-XXXXXX";
    if (!mkdtemp(dir)) { perror("mkdtemp"); return 1; }
    char a[256], b[256];
    snprintf(a, sizeof a, "%s/spp", dir);
    snprintf(b, sizeof b, "%s/time", dir);
    check_equal_spp(argv[1], argv[2], a);
    check_equal_time(argv[1], argv[2], b);
    char c[256];
    snprintf(c, sizeof c, "%s/seed", dir);
    check_reference_seed(argv[1], argv[2], c);
    char cmd[4300];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (!check_failures) run(cmd); /* kept for a look when something failed */
    else fprintf(stderr, "report kept in %s\n", dir);
    return test_exit();
}
