/* renderer/app/metrics.c: image error metrics (metrics.h). */
#include <math.h>

#include "metrics.h"

ImageErrors metrics_image_errors(const float *x, const float *ref, size_t n) {
    ImageErrors e = {0.0, 0.0, 0.0};
    if (n == 0) return e;
    double se = 0.0, rel = 0.0, ae = 0.0;
    for (size_t i = 0; i < n; ++i) {
        double d = (double)x[i] - (double)ref[i];
        se += d * d;
        rel += d * d / ((double)ref[i] * (double)ref[i] + METRICS_RELMSE_EPSILON);
        ae += fabs(d);
    }
    e.mse = se / (double)n;
    e.rmse = sqrt(e.mse);
    e.relmse = rel / (double)n;
    e.mae = ae / (double)n;
    return e;
}

double metrics_mean(const float *v, size_t n) {
    if (n == 0) return 0.0;
    double s = 0.0;
    for (size_t i = 0; i < n; ++i) s += v[i];
    return s / (double)n;
}

double metrics_ttuv(double mean_variance, double seconds) { return mean_variance * seconds; }

double metrics_ratio(double value, double baseline) { return baseline > 0.0 ? value / baseline : NAN; }

ReferenceNoise metrics_reference_noise(const float *ref, const float *ref_variance, size_t n) {
    ReferenceNoise r = {0.0, 0.0};
    if (n == 0) return r;
    double v = 0.0, rel = 0.0;
    for (size_t i = 0; i < n; ++i) {
        v += ref_variance[i];
        rel += ref_variance[i] / ((double)ref[i] * (double)ref[i] + METRICS_RELMSE_EPSILON);
    }
    r.mse = v / (double)n;
    r.relmse = rel / (double)n;
    return r;
}
