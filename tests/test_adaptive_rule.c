/* tests/test_adaptive_rule.c: the stopping rule of adaptive sampling on a synthetic film
 * (film_adaptive_update, renderer/integrator.h), with samples of known per-pixel noise.
 *
 * Left half of the film: samples of standard deviation 1 around 1; right half: 4 around 1; a
 * black strip at the bottom (every sample 0). Samples are added in the render's doubling
 * schedule (16, 32, 64, ... 4096) to the pixels still sampling, and film_adaptive_update runs at
 * each barrier. The rule stops pixels at equal marginal value sigma / n, so away from the seam the
 * noisier half takes 4x the samples (n proportional to sigma, the least-MSE allocation; Cycles'
 * equal-error rule would give 16x), the black strip stops at once, and the MSE the allocation
 * leaves, sum sigma^2 / n, is below uniform sampling's at the same total number of samples by
 * close to the optimum, mean(sigma^2) / mean(sigma)^2. A threshold scales the budget, not the
 * ratio. */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "check.h"
#include "integrator.h"

enum { W = 64, H = 24, BLACK_ROWS = 4, MAX_SPP = 4096 };

static uint64_t g_state = 0x9E3779B97F4A7C15ull;
static double uniform01(void) { /* splitmix64 */
    uint64_t z = (g_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return (double)((z ^ (z >> 31)) >> 11) * 0x1.0p-53;
}

static double pixel_sigma(int x, int y) { return y >= H - BLACK_ROWS ? 0.0 : x < W / 2 ? 1.0 : 4.0; }

static void add_samples(Film *f, size_t i, int count, double sigma) {
    for (int s = 0; s < count; ++s) {
        double v = sigma > 0.0 ? 1.0 + sigma * sqrt(12.0) * (uniform01() - 0.5) : 0.0;
        for (int k = 0; k < 3; ++k) {
            f->sum[3 * i + k] += v;
            f->sum2[3 * i + k] += v * v;
        }
        f->count[i]++;
    }
}

/* Runs the schedule; returns the mean sample count of the left and right halves' pixels away from
 * the seam and the image edge, and the black strip's largest. */
static void run(float threshold, double *left, double *right, uint32_t *black_max, double *mse_gain) {
    Film f;
    if (film_alloc(&f, W, H) != 0) { CHECK(0, "out of memory"); return; }
    f.stopped = calloc((size_t)W * H, 1);
    for (int n = 16, done = 0; n <= MAX_SPP && f.stopped; done = n, n *= 2) {
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
                size_t i = (size_t)y * W + (size_t)x;
                if (!f.stopped[i]) add_samples(&f, i, n - done, pixel_sigma(x, y));
            }
        if (n < MAX_SPP) film_adaptive_update(&f, threshold);
    }
    double sl = 0, sr = 0, total = 0, mse = 0, sigma2 = 0;
    int nl = 0, nr = 0;
    *black_max = 0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            size_t i = (size_t)y * W + (size_t)x;
            double s = pixel_sigma(x, y), c = f.count[i];
            total += c;
            mse += s * s / c;
            sigma2 += s * s;
            if (y > H - BLACK_ROWS) { if (f.count[i] > *black_max) *black_max = f.count[i]; continue; }
            if (y >= H - BLACK_ROWS) continue;
            if (y < 2 || y >= H - BLACK_ROWS - 2 || x < 2 || x >= W - 2 || (x >= W / 2 - 3 && x < W / 2 + 3)) continue;
            if (x < W / 2) { sl += c; ++nl; } else { sr += c; ++nr; }
        }
    *left = sl / nl;
    *right = sr / nr;
    /* uniform sampling at the same total: every pixel total / npixels samples */
    *mse_gain = (sigma2 / (total / (W * H))) / mse;
    free(f.stopped);
    f.stopped = NULL;
    film_free(&f);
}

int main(void) {
    /* the image mean is 1 x (rows with light) / H: thresholds chosen to stop within the schedule */
    const float thresholds[] = {0.05f, 0.1f, 0.2f};
    double prev_total = INFINITY;
    for (int t = 0; t < 3; ++t) {
        double l = 0, r = 0, gain = 0;
        uint32_t black = 0;
        run(thresholds[t], &l, &r, &black, &gain);
        printf("threshold %g: left %.1f spp, right %.1f spp (ratio %.2f), black strip at most %u, MSE %.3fx lower than uniform\n",
               thresholds[t], l, r, r / l, black, gain);
        CHECK(l > 16.0 && r < MAX_SPP, "threshold %g: the allocation is not inside the schedule (%g, %g)", thresholds[t], l, r);
        CHECK(r / l > 3.0 && r / l < 5.5, "threshold %g: samples right/left %.2f, want ~4 (sigma ratio)", thresholds[t], r / l);
        CHECK(black == 16, "threshold %g: the black strip took up to %u samples, want 16", thresholds[t], black);
        /* optimum over the lit rows: mean(sigma^2)/mean(sigma)^2 = 8.5 / 6.25 = 1.36 (the black rows add to both) */
        CHECK(gain > 1.2, "threshold %g: MSE only %.3fx below uniform sampling at the same budget", thresholds[t], gain);
        CHECK(l + r < prev_total, "a larger threshold spent more samples");
        prev_total = l + r;
    }
    return test_exit();
}
