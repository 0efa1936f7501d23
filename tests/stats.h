/* tests/stats.h: the statistics the sampling tests share (chi-square p-values). */
#ifndef CANDELA_TEST_STATS_H
#define CANDELA_TEST_STATS_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

/* splitmix64 step -> uniform double in [0, 1): the tests' own small generator (fixed seeds,
 * so every run draws the same numbers). */
static inline double splitmix_uniform(uint64_t *state) {
    uint64_t z = (*state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    z ^= z >> 31;
    return (double)(z >> 11) * (1.0 / 9007199254740992.0);
}

#ifndef MIN_EXPECTED
#define MIN_EXPECTED 5.0
#endif

/* Regularised upper incomplete gamma Q(a, x) (Numerical Recipes gser / gcf). */
static inline double gamma_q(double a, double x) {
    if (x <= 0.0) return 1.0;
    double lg = -x + a * log(x) - lgamma(a);
    if (x < a + 1.0) {
        double ap = a, sum = 1.0 / a, del = sum;
        for (int n = 0; n < 100000; ++n) {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if (fabs(del) < fabs(sum) * 1e-15) break;
        }
        return 1.0 - sum * exp(lg);
    }
    double b = x + 1.0 - a, c = 1.0 / 1e-300, d = 1.0 / b, h = d;
    for (int i = 1; i < 100000; ++i) {
        double an = -i * (i - a);
        b += 2.0;
        d = an * d + b;
        if (fabs(d) < 1e-300) d = 1e-300;
        c = b + an / c;
        if (fabs(c) < 1e-300) c = 1e-300;
        d = 1.0 / d;
        double del = d * c;
        h *= del;
        if (fabs(del - 1.0) < 1e-15) break;
    }
    return exp(lg) * h;
}

typedef struct { double obs, expv; } Bin;

static inline int cmp_bin(const void *a, const void *b) {
    double x = ((const Bin *)a)->expv, y = ((const Bin *)b)->expv;
    return (x > y) - (x < y);
}

/* Pearson chi-square with pooling of low-expected bins (sorted ascending, pooled until the pool
 * reaches MIN_EXPECTED; a leftover pool joins the last emitted cell). Bins whose quadrature
 * gave exactly zero are pooled too rather than failing outright: Gauss nodes are interior, so a
 * bin clipped by a pdf boundary in one corner can integrate to 0 while still being reachable;
 * a real excess there still shows up in the pooled cell. Returns the p-value. */
static inline double chi2_pvalue(const double *obs, const double *expv, int n, int *dof_out, double *stat_out) {
    Bin *b = malloc(sizeof(Bin) * (size_t)n);
    int m = 0;
    for (int i = 0; i < n; ++i) {
        b[m].obs = obs[i];
        b[m].expv = expv[i] > 0.0 ? expv[i] : 0.0;
        ++m;
    }
    qsort(b, (size_t)m, sizeof(Bin), cmp_bin);
    double stat = 0.0, po = 0.0, pe = 0.0, last_o = 0.0, last_e = 0.0;
    int cells = 0;
    for (int i = 0; i < m; ++i) {
        po += b[i].obs;
        pe += b[i].expv;
        if (pe >= MIN_EXPECTED) {
            if (cells > 0) stat += (last_o - last_e) * (last_o - last_e) / last_e;
            last_o = po;
            last_e = pe;
            ++cells;
            po = pe = 0.0;
        }
    }
    if (pe > 0.0) {
        if (cells > 0) {
            last_o += po;
            last_e += pe;
        } else {
            last_o = po;
            last_e = pe;
            cells = 1;
        }
    }
    if (cells > 0 && last_e > 0.0) stat += (last_o - last_e) * (last_o - last_e) / last_e;
    else if (cells > 0 && last_o > 0.0) stat = INFINITY;
    free(b);
    int dof = cells - 1;
    *dof_out = dof;
    *stat_out = stat;
    if (dof <= 0) return 1.0;
    return gamma_q(0.5 * dof, 0.5 * stat);
}

#endif
