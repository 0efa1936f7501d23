/* tests/test_metrics.c: candela compare's metrics (renderer/app/metrics.h) on images whose errors
 * are known by hand, and the arithmetic of time to unit variance. */
#include <math.h>

#include "check.h"
#include "metrics.h"

static int close_to(double a, double b) { return fabs(a - b) <= 1e-12 * fmax(1.0, fabs(b)); }

int main(void) {
    /* differences 0, 1, 2, 3 against a reference of ones: MSE 14/4, MAE 6/4,
     * relMSE (0 + 1 + 4 + 9) / (1 + 0.01) / 4 */
    const float x[4] = {1.0f, 2.0f, 3.0f, 4.0f}, ones[4] = {1.0f, 1.0f, 1.0f, 1.0f};
    ImageErrors e = metrics_image_errors(x, ones, 4);
    CHECK(close_to(e.rmse, sqrt(3.5)), "rmse %.17g", e.rmse);
    CHECK(close_to(e.mae, 1.5), "mae %.17g", e.mae);
    CHECK(close_to(e.relmse, 14.0 / 1.01 / 4.0), "relmse %.17g", e.relmse);
    /* the sign of the difference does not matter: the reference above the image */
    ImageErrors swapped = metrics_image_errors(ones, x, 4);
    CHECK(close_to(swapped.rmse, e.rmse) && close_to(swapped.mae, e.mae), "rmse/mae not symmetric");
    /* relMSE divides by the reference: (1 + 4 + 9) spread over references 2, 3, 4 */
    CHECK(close_to(swapped.relmse, (1.0 / 4.01 + 4.0 / 9.01 + 9.0 / 16.01) / 4.0), "relmse %.17g", swapped.relmse);

    /* a black reference: relMSE's epsilon keeps it finite, 0.1^2 / 0.01 = 1 at that pixel */
    const float dark[2] = {0.1f, 0.0f}, black[2] = {0.0f, 0.0f};
    ImageErrors d = metrics_image_errors(dark, black, 2);
    CHECK(fabs(d.relmse - 0.5 * (double)0.1f * (double)0.1f / METRICS_RELMSE_EPSILON) < 1e-12, "relmse %.17g", d.relmse);
    CHECK(close_to(d.rmse, sqrt(0.5 * (double)0.1f * (double)0.1f)), "rmse %.17g", d.rmse);

    /* equal images: all zero; no values: all zero (never a division by zero) */
    ImageErrors same = metrics_image_errors(x, x, 4), none = metrics_image_errors(x, ones, 0);
    CHECK(same.rmse == 0.0 && same.relmse == 0.0 && same.mae == 0.0, "equal images");
    CHECK(none.rmse == 0.0 && none.relmse == 0.0 && none.mae == 0.0, "empty images");

    /* a larger image: 1000 pixels of constant error 0.25 -> RMSE = MAE = 0.25 exactly */
    float big[3000], base[3000];
    for (int i = 0; i < 3000; ++i) { base[i] = (float)(i % 7) * 0.5f; big[i] = base[i] + 0.25f; }
    ImageErrors b = metrics_image_errors(big, base, 3000);
    CHECK(close_to(b.rmse, 0.25) && close_to(b.mae, 0.25), "constant error: rmse %.17g mae %.17g", b.rmse, b.mae);

    /* mean of the variance AOV */
    const float var[4] = {0.5f, 0.25f, 0.125f, 0.125f};
    CHECK(close_to(metrics_mean(var, 4), 0.25), "mean %.17g", metrics_mean(var, 4));
    CHECK(metrics_mean(var, 0) == 0.0, "mean of nothing");

    /* TTUV = variance x time: 0.02 at 10 s is 0.2. An unbiased estimator with per-sample
     * variance s2 and per-sample cost c has variance s2 / N after N samples and N c seconds,
     * so its TTUV is s2 c whatever N: the measure compares methods, not sample counts. */
    CHECK(close_to(metrics_ttuv(0.02, 10.0), 0.2), "ttuv %.17g", metrics_ttuv(0.02, 10.0));
    const double s2 = 3.0, cost = 0.004;
    for (int spp = 1; spp <= 4096; spp *= 4)
        CHECK(close_to(metrics_ttuv(s2 / spp, spp * cost), s2 * cost), "ttuv at %d spp: %.17g", spp,
              metrics_ttuv(s2 / spp, spp * cost));
    /* twice the variance at half the time: equal TTUV (an equal-time tie) */
    CHECK(close_to(metrics_ttuv(0.04, 5.0), metrics_ttuv(0.02, 10.0)), "ttuv trade-off");

    /* ratios against the first variant; a zero baseline has no ratio */
    CHECK(close_to(metrics_ratio(3.0, 1.5), 2.0), "ratio");
    CHECK(isnan(metrics_ratio(1.0, 0.0)), "ratio against 0 is %g", metrics_ratio(1.0, 0.0));
    return test_exit();
}
