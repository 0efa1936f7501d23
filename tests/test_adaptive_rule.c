/* tests/test_adaptive_rule.c: adaptive sampling's pilot rule on synthetic films
 * (film_adaptive_update, renderer/integrator/film.c), with samples of known distributions.
 *
 * - independence: a pixel's target is a function of the other pixels' pilots only. Changing one
 *   pixel's pilot sums (a firefly added, its samples zeroed) leaves its own target bit for bit and
 *   changes its neighbours'; samples added after the pilot change no target, and a pixel stops
 *   exactly at the first barrier where its count reaches its target;
 * - allocation: left half of the film noise sigma 1, right half 4, a black strip: away from the
 *   seam the right half takes about 4x the samples (n proportional to sigma, the least-MSE
 *   allocation; 3x-4x after rounding up to the schedule's barriers), the black strip stops at the pilot, the MSE the allocation leaves is below
 *   uniform sampling's at the same number of samples, a larger threshold spends fewer samples;
 * - unbiasedness: pixels of heavy-tailed samples (a rare bright value, else 0; its rate varies
 *   over the film so the allocation varies): over independent replicates the image mean of the
 *   adaptive estimates equals the true mean within 4 standard errors (from the replicates'
 *   spread). The same test run with a rule that stops a pixel by its own samples (the rule of
 *   ea27fd5, kept here only as the control) must fail it: the test can see a bias. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "integrator.h"

typedef struct Rng { uint64_t s; } Rng;
static double uniform01(Rng *r) { /* splitmix64 */
    uint64_t z = (r->s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return (double)((z ^ (z >> 31)) >> 11) * 0x1.0p-53;
}

/* The render's unguided schedule after a pilot of 16: barriers at 16, 32, 64, 128, 192, 256, ... */
static int next_barrier(int done) { return done < 64 ? 2 * done : done + 64; }

static int film_new(Film *f, int w, int h) {
    if (film_alloc(f, w, h) != 0) return -1;
    f->stopped = calloc((size_t)w * (size_t)h, 1);
    f->target = calloc((size_t)w * (size_t)h, sizeof(uint32_t));
    if (!f->stopped || !f->target) { film_free(f); return -1; }
    return 0;
}

static void add_sample(Film *f, size_t i, double v) {
    for (int k = 0; k < 3; ++k) {
        f->sum[3 * i + k] += v;
        f->sum2[3 * i + k] += v * v;
    }
    f->count[i]++;
}

/* ---------------------------------------------------------------- independence */

enum { IW = 40, IH = 30, PILOT = 16 };

static void pilot_film(Film *f, uint64_t seed) {
    Rng r = {seed};
    for (size_t i = 0; i < (size_t)IW * IH; ++i)
        for (int s = 0; s < PILOT; ++s) add_sample(f, i, uniform01(&r) < 0.1 ? 20.0 * uniform01(&r) : uniform01(&r));
}

static void test_independence(void) {
    Film a, b;
    if (film_new(&a, IW, IH) != 0 || film_new(&b, IW, IH) != 0) { CHECK(0, "out of memory"); return; }
    pilot_film(&a, 1);
    CHECK(!film_adaptive_pilot_done(&a), "targets set before the pilot barrier");
    film_adaptive_update(&a, 0.5f);
    CHECK(film_adaptive_pilot_done(&a), "no targets after the pilot barrier");
    const size_t n = (size_t)IW * IH;
    uint32_t lo = UINT32_MAX, hi = 0;
    for (size_t i = 0; i < n; ++i) {
        lo = a.target[i] < lo ? a.target[i] : lo;
        hi = a.target[i] > hi ? a.target[i] : hi;
    }
    CHECK(lo >= PILOT && hi > lo, "targets %u..%u: want at least the pilot and some spread", lo, hi);
    /* one pixel's pilot changed (interior, edge, corner): its own target stays, a neighbour's moves */
    const int px[3][2] = {{20, 15}, {0, 7}, {IW - 1, IH - 1}};
    for (int t = 0; t < 3; ++t) {
        for (int change = 0; change < 2; ++change) {
            film_free(&b);
            if (film_new(&b, IW, IH) != 0) { CHECK(0, "out of memory"); return; }
            pilot_film(&b, 1);
            const size_t p = (size_t)px[t][1] * IW + (size_t)px[t][0];
            if (change == 0) { /* a firefly */
                for (int k = 0; k < 3; ++k) { b.sum[3 * p + k] += 1e4; b.sum2[3 * p + k] += 1e8; }
            } else { /* every sample 0 (a pixel that met nothing) */
                for (int k = 0; k < 3; ++k) b.sum[3 * p + k] = b.sum2[3 * p + k] = 0.0;
            }
            film_adaptive_update(&b, 0.5f);
            CHECK(b.target[p] == a.target[p], "pixel (%d, %d): its own pilot changed its target %u -> %u", px[t][0],
                  px[t][1], a.target[p], b.target[p]);
            int moved = 0;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int x = px[t][0] + dx, y = px[t][1] + dy;
                    if ((dx || dy) && x >= 0 && x < IW && y >= 0 && y < IH)
                        moved += b.target[(size_t)y * IW + (size_t)x] != a.target[(size_t)y * IW + (size_t)x];
                }
            CHECK(moved > 0, "pixel (%d, %d): changing its pilot moved no neighbour's target (the test proves nothing)",
                  px[t][0], px[t][1]);
        }
    }
    /* after the pilot: samples change no target; a pixel stops at the first barrier reaching it */
    uint32_t *fixed = malloc(n * sizeof(uint32_t));
    if (!fixed) { CHECK(0, "out of memory"); film_free(&a); film_free(&b); return; }
    memcpy(fixed, a.target, n * sizeof(uint32_t));
    Rng r = {99};
    int wrong_stop = 0;
    for (int done = PILOT; done < 256;) {
        const int next = next_barrier(done);
        for (size_t i = 0; i < n; ++i)
            if (!a.stopped[i])
                for (int s = done; s < next; ++s) add_sample(&a, i, 1e3 * uniform01(&r)); /* wild samples */
        done = next;
        film_adaptive_update(&a, 0.5f);
        for (size_t i = 0; i < n; ++i) {
            const int want_stopped = a.count[i] >= fixed[i];
            wrong_stop += a.stopped[i] != want_stopped;
            /* the count it stopped at is the first barrier at or past its target */
            if (a.stopped[i] && a.count[i] > PILOT) {
                int before = a.count[i] <= 64 ? (int)a.count[i] / 2 : (int)a.count[i] - 64;
                wrong_stop += before >= (int)fixed[i];
            }
        }
    }
    CHECK(memcmp(fixed, a.target, n * sizeof(uint32_t)) == 0, "samples after the pilot changed targets");
    CHECK(wrong_stop == 0, "%d pixel-barriers stopped otherwise than at the first barrier reaching the target", wrong_stop);
    free(fixed);
    film_free(&a);
    film_free(&b);
}

/* ---------------------------------------------------------------- allocation */

enum { W = 96, H = 48, BLACK_ROWS = 8, MAX_SPP = 4096 };

static double pixel_sigma(int x, int y) { return y >= H - BLACK_ROWS ? 0.0 : x < W / 2 ? 1.0 : 4.0; }

static void run_allocation(float threshold, double *left, double *right, uint32_t *black_max, double *mse_gain) {
    Film f;
    if (film_new(&f, W, H) != 0) { CHECK(0, "out of memory"); return; }
    Rng r = {7};
    for (int done = 0, n = 16; done < MAX_SPP; done = n, n = next_barrier(n)) {
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
                const size_t i = (size_t)y * W + (size_t)x;
                const double s = pixel_sigma(x, y);
                if (!f.stopped[i])
                    for (int k = done; k < n; ++k) add_sample(&f, i, s > 0.0 ? 1.0 + s * sqrt(12.0) * (uniform01(&r) - 0.5) : 0.0);
            }
        if (n < MAX_SPP) film_adaptive_update(&f, threshold);
    }
    /* the pooling window is 1/24 of the shorter side: keep 4 pixels away from the seam and edges */
    const int margin = H / 24 + 2;
    double sl = 0, sr = 0, total = 0, mse = 0, sigma2 = 0;
    int nl = 0, nr = 0;
    *black_max = 0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const size_t i = (size_t)y * W + (size_t)x;
            const double s = pixel_sigma(x, y), c = f.count[i];
            total += c;
            mse += s * s / c;
            sigma2 += s * s;
            if (y >= H - BLACK_ROWS + margin && f.count[i] > *black_max) *black_max = f.count[i];
            if (y < margin || y >= H - BLACK_ROWS - margin || x < margin || x >= W - margin ||
                (x >= W / 2 - margin && x < W / 2 + margin))
                continue;
            if (x < W / 2) { sl += c; ++nl; } else { sr += c; ++nr; }
        }
    *left = sl / nl;
    *right = sr / nr;
    *mse_gain = (sigma2 / (total / (W * H))) / mse; /* uniform at the same total: total / npixels each */
    film_free(&f);
}

static void test_allocation(void) {
    /* the image mean is 1 x (lit rows) / H; thresholds chosen to stop inside the schedule */
    const float thresholds[] = {0.1f, 0.2f, 0.4f};
    double prev_total = INFINITY;
    for (int t = 0; t < 3; ++t) {
        double l = 0, r = 0, gain = 0;
        uint32_t black = 0;
        run_allocation(thresholds[t], &l, &r, &black, &gain);
        printf("threshold %g: left %.1f spp, right %.1f spp (ratio %.2f), black strip at most %u, MSE %.3fx lower than "
               "uniform\n", thresholds[t], l, r, r / l, black, gain);
        CHECK(l > 16.0 && r < MAX_SPP, "threshold %g: the allocation is not inside the schedule (%g, %g)", thresholds[t], l, r);
        CHECK(r / l > 2.5 && r / l < 5.5, "threshold %g: samples right/left %.2f, want ~4 (the sigma ratio, to the schedule's steps)", thresholds[t], r / l);
        CHECK(black == 16, "threshold %g: the black strip took up to %u samples, want the pilot's 16", thresholds[t], black);
        /* optimum over the lit rows: mean(sigma^2) / mean(sigma)^2 = 8.5 / 6.25 = 1.36 (black rows add to both) */
        CHECK(gain > 1.2, "threshold %g: MSE only %.3fx below uniform sampling at the same budget", thresholds[t], gain);
        CHECK(l + r < prev_total, "a larger threshold spent more samples");
        prev_total = l + r;
    }
}

/* ---------------------------------------------------------------- unbiasedness */

enum { UW = 48, UH = 32, REPLICATES = 40, U_MAX_SPP = 256 };
static const double BRIGHT = 50.0;

/* the rate of the rare bright value: from 0.2 % to 4 % across the film (so targets vary) */
static double rate(int x, int y) { return 0.002 + 0.038 * (double)(x + UW * (y % 4)) / (4.0 * UW); }

/* The control: ea27fd5's rule, a pixel stops once its own standard error relative to the image
 * mean, times sqrt(16 / n), is below the threshold (n proportional to its own sigma). */
static void own_sample_rule(Film *f, float threshold) {
    const size_t n = (size_t)f->width * (size_t)f->height;
    double mean = 0.0;
    for (size_t i = 0; i < n; ++i) mean += f->sum[3 * i] / f->count[i] / (double)n;
    for (size_t i = 0; i < n; ++i) {
        const double c = f->count[i], m = f->sum[3 * i] / c;
        const double var = fmax((f->sum2[3 * i] - c * m * m) / (c - 1.0), 0.0);
        if (!f->stopped[i] && sqrt(var / c) / mean * sqrt(16.0 / c) < threshold) f->stopped[i] = 1;
    }
}

/* One replicate: the image mean of the pixels' estimates less the true image mean; mean spp. */
static double replicate(uint64_t seed, int control, float threshold, double *spp) {
    Film f;
    if (film_new(&f, UW, UH) != 0) { CHECK(0, "out of memory"); return 0.0; }
    Rng r = {seed};
    for (int done = 0, n = 16; done < U_MAX_SPP; done = n, n = next_barrier(n)) {
        for (int y = 0; y < UH; ++y)
            for (int x = 0; x < UW; ++x) {
                const size_t i = (size_t)y * UW + (size_t)x;
                if (!f.stopped[i])
                    for (int k = done; k < n; ++k) add_sample(&f, i, uniform01(&r) < rate(x, y) ? BRIGHT : 0.0);
            }
        if (n < U_MAX_SPP) {
            if (control) own_sample_rule(&f, threshold);
            else film_adaptive_update(&f, threshold);
        }
    }
    double err = 0.0, total = 0.0;
    for (int y = 0; y < UH; ++y)
        for (int x = 0; x < UW; ++x) {
            const size_t i = (size_t)y * UW + (size_t)x;
            err += f.sum[3 * i] / f.count[i] - BRIGHT * rate(x, y);
            total += f.count[i];
        }
    *spp = total / (UW * UH);
    film_free(&f);
    return err / (UW * UH);
}

/* The image mean's error over the replicates: mean, its standard error; the mean spp. */
static void bias(int control, float threshold, double *mean_err, double *se, double *spp) {
    double s = 0.0, s2 = 0.0, sp = 0.0;
    for (int k = 0; k < REPLICATES; ++k) {
        double one = 0.0;
        const double e = replicate(1000u + (uint64_t)k * 7919u, control, threshold, &one);
        s += e;
        s2 += e * e;
        sp += one / REPLICATES;
    }
    *mean_err = s / REPLICATES;
    *se = sqrt(fmax(s2 / REPLICATES - *mean_err * *mean_err, 0.0) / (REPLICATES - 1));
    *spp = sp;
}

static void test_unbiased(void) {
    double truth = 0.0;
    for (int y = 0; y < UH; ++y)
        for (int x = 0; x < UW; ++x) truth += BRIGHT * rate(x, y) / (UW * UH);
    double e, se, spp;
    bias(0, 1.0f, &e, &se, &spp);
    printf("pilot rule: image mean %+.3f%% of %.4f (standard error %.3f%%), %.1f spp\n", 100.0 * e / truth, truth,
           100.0 * se / truth, spp);
    CHECK(spp > 20.0 && spp < 0.8 * U_MAX_SPP, "the pilot rule did not adapt (%.1f spp of 16..%d)", spp, U_MAX_SPP);
    CHECK(fabs(e) <= 4.0 * se, "pilot rule: the image mean is off by %g (%.2f standard errors)", e, e / se);
    double ce, cse, cspp;
    bias(1, 0.5f, &ce, &cse, &cspp);
    printf("own-sample rule (control): image mean %+.3f%% (standard error %.3f%%), %.1f spp\n", 100.0 * ce / truth,
           100.0 * cse / truth, cspp);
    CHECK(ce < -6.0 * cse, "the control rule's bias went unseen (%.2f standard errors): the test has no power", ce / cse);
}

int main(void) {
    test_independence();
    test_allocation();
    test_unbiased();
    return test_exit();
}
