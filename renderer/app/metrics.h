/* renderer/app/metrics.h (private): the image error metrics of `candela compare`, in one place
 * (the table, the convergence snapshots and the tests use these functions). */
#ifndef CANDELA_METRICS_H
#define CANDELA_METRICS_H

#include <stddef.h>

/* relMSE's denominator is ref^2 + METRICS_RELMSE_EPSILON: it keeps black reference pixels from
 * dividing by zero (0.01: what candela compare has always used). */
#define METRICS_RELMSE_EPSILON 0.01

typedef struct ImageErrors {
    double rmse;   /* sqrt(mean (x - ref)^2) */
    double relmse; /* mean (x - ref)^2 / (ref^2 + METRICS_RELMSE_EPSILON) */
    double mae;    /* mean |x - ref| */
    double mse;    /* mean (x - ref)^2 */
} ImageErrors;

/* The reference's own noise in those errors. For a reference independent of the image,
 * E[(x - ref)^2] = E[(x - mu)^2] + Var[ref], so the reference's variance of the mean (its EXR's
 * variance layer), averaged as the MSE averages, is what the MSE holds of the reference's noise:
 * mse = mean ref_var, relmse = mean ref_var / (ref^2 + METRICS_RELMSE_EPSILON). candela compare
 * shows MSE and relMSE minus these (rmse and mae are left as they are). */
typedef struct ReferenceNoise {
    double mse, relmse;
} ReferenceNoise;
/* Over n values, accumulated in double in index order. n = 0: zero. */
ReferenceNoise metrics_reference_noise(const float *ref, const float *ref_variance, size_t n);

/* Over n values (pixels x channels), accumulated in double in index order. n = 0: all zero. */
ImageErrors metrics_image_errors(const float *x, const float *ref, size_t n);
/* Mean of n values in double (the mean per-pixel variance of an image's variance AOV). */
double metrics_mean(const float *v, size_t n);
/* Time to unit variance: the variance of the estimate times the seconds it took. For an
 * unbiased estimator at a fixed cost per sample it does not depend on the sample count, so
 * lower is better whatever the spp (the cache points paper's Table 3). */
double metrics_ttuv(double mean_variance, double seconds);
/* value / baseline, the ratios against the first variant; NaN when the baseline is not > 0. */
double metrics_ratio(double value, double baseline);

#endif
