/* volumes/distance.c: a piecewise-linear density over distance along a ray, mixed with a
 * defensive uniform term (the cache points paper §4.2: "a piecewise-linear 1-D CDF over
 * distance" built from the cache points' scattering weights along a camera ray; the spec's
 * §7.2 proposal for the stations and the mixture). */
#include <math.h>

#include "volumes.h"

int volume_distance_table_init(VolumeDistanceTable *tab, const float *t, const float *s, int n, float delta) {
    if (n < 2 || n > VOLUME_DISTANCE_STATIONS || !(delta >= 0.0f && delta <= 1.0f)) return -1;
    double sum = 0.0;
    for (int i = 0; i < n; ++i) {
        if (!isfinite(t[i]) || !isfinite(s[i]) || s[i] < 0.0f) return -1;
        if (i > 0 && !(t[i] >= t[i - 1])) return -1;
        tab->t[i] = t[i];
        tab->s[i] = s[i];
        if (i > 0) sum += 0.5 * ((double)s[i - 1] + s[i]) * ((double)t[i] - t[i - 1]);
        tab->cdf[i] = sum;
    }
    if (!(t[n - 1] > t[0])) return -1;
    tab->n = n;
    /* nothing to follow: the uniform density alone */
    tab->delta = sum > 0.0 && isfinite(sum) ? delta : 1.0f;
    return 0;
}

/* The segment [t_i, t_i+1] holding t (the last one whose start is <= t). */
static int segment_of(const VolumeDistanceTable *tab, float t) {
    int lo = 0, hi = tab->n - 2;
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (tab->t[mid] <= t) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}

float volume_distance_pdf(const VolumeDistanceTable *tab, float t) {
    float t0 = tab->t[0], t1 = tab->t[tab->n - 1];
    if (!(t >= t0 && t <= t1)) return 0.0f;
    double uniform = 1.0 / ((double)t1 - t0);
    if (tab->delta >= 1.0f) return (float)uniform;
    int i = segment_of(tab, t);
    double h = (double)tab->t[i + 1] - tab->t[i];
    double x = h > 0.0 ? ((double)t - tab->t[i]) / h : 0.0;
    double lin = tab->s[i] + ((double)tab->s[i + 1] - tab->s[i]) * x;
    return (float)((1.0 - tab->delta) * lin / tab->cdf[tab->n - 1] + tab->delta * uniform);
}

float volume_distance_sample(const VolumeDistanceTable *tab, float u0, float u1, float *pdf) {
    float t0 = tab->t[0], t1 = tab->t[tab->n - 1];
    float t;
    if (u0 < tab->delta) {
        t = t0 + u1 * (t1 - t0);
    } else {
        /* the segment by its area, then the point by inverting the segment's quadratic CDF */
        double target = (double)u1 * tab->cdf[tab->n - 1];
        int lo = 0, hi = tab->n - 2; /* first segment whose cdf end exceeds target */
        while (lo < hi) {
            int mid = (lo + hi) / 2;
            if (tab->cdf[mid + 1] > target) hi = mid;
            else lo = mid + 1;
        }
        int i = lo;
        double area = tab->cdf[i + 1] - tab->cdf[i];
        double u = area > 0.0 ? (target - tab->cdf[i]) / area : 0.0;
        u = u < 0.0 ? 0.0 : u > 1.0 ? 1.0 : u;
        double a = tab->s[i], b = tab->s[i + 1];
        /* F(x) = (a x + (b - a) x^2 / 2) / ((a + b) / 2) = u, in the form without cancellation */
        double den = a + sqrt(a * a + (b * b - a * a) * u);
        double x = den > 0.0 ? (a + b) * u / den : 0.0;
        x = x < 0.0 ? 0.0 : x > 1.0 ? 1.0 : x;
        t = (float)(tab->t[i] + x * ((double)tab->t[i + 1] - tab->t[i]));
    }
    t = t < t0 ? t0 : t > t1 ? t1 : t;
    *pdf = volume_distance_pdf(tab, t);
    return t;
}
