/* renderer/app/report.c: text, SVG plots and crop images of `candela compare`'s report (report.h).
 *
 * The plots are SVG written here (no plotting dependency): log-log axes with decade ticks
 * (and 2x, 5x ticks when the data span less than two decades), one polyline with markers per
 * series, a legend. Browsers show them inline through <img>. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "io.h"
#include "report.h"

/* ---------------------------------------------------------------- text */

void report_printf(ReportText *t, const char *fmt, ...) {
    if (t->failed) return;
    for (;;) {
        va_list ap;
        va_start(ap, fmt);
        size_t room = t->cap - t->len;
        int n = vsnprintf(t->s ? t->s + t->len : NULL, t->s ? room : 0, fmt, ap);
        va_end(ap);
        if (n < 0) { t->failed = 1; return; }
        if (t->s && (size_t)n < room) { t->len += (size_t)n; return; }
        size_t cap = t->cap ? t->cap : 4096;
        while (cap < t->len + (size_t)n + 1) cap *= 2;
        char *s = realloc(t->s, cap);
        if (!s) { t->failed = 1; return; }
        t->s = s;
        t->cap = cap;
    }
}

void report_html(ReportText *t, const char *s) {
    for (; *s; ++s) {
        switch (*s) {
        case '&': report_printf(t, "&amp;"); break;
        case '<': report_printf(t, "&lt;"); break;
        case '>': report_printf(t, "&gt;"); break;
        case '"': report_printf(t, "&quot;"); break;
        default: report_printf(t, "%c", *s);
        }
    }
}

void report_text_free(ReportText *t) {
    free(t->s);
    memset(t, 0, sizeof *t);
}

int report_write_text(const char *path, const ReportText *t, char err[CANDELA_ERR_LEN]) {
    if (t->failed) { snprintf(err, CANDELA_ERR_LEN, "%.400s: out of memory", path); return -1; }
    char ioerr[IO_ERR_LEN];
    if (io_atomic_write(path, t->s, t->len, ioerr) != 0) { snprintf(err, CANDELA_ERR_LEN, "%s", ioerr); return -1; }
    return 0;
}

/* ---------------------------------------------------------------- plots */

/* Colours of the series: distinguishable on white, in order. */
static const char *const PALETTE[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
                                      "#8c564b", "#e377c2", "#17becf", "#7f7f7f", "#bcbd22"};

typedef struct LogAxis {
    double lo, hi;     /* data range in log10, widened to at least a factor of 2 */
    double pix0, pix1; /* where lo and hi land */
} LogAxis;

static double axis_map(const LogAxis *a, double v) {
    return a->pix0 + (log10(v) - a->lo) / (a->hi - a->lo) * (a->pix1 - a->pix0);
}

static void axis_fit(LogAxis *a, double vmin, double vmax) {
    if (!(vmin > 0.0) || !(vmax >= vmin)) { vmin = 1.0; vmax = 10.0; }
    double lo = log10(vmin), hi = log10(vmax);
    if (hi - lo < log10(2.0)) { double mid = 0.5 * (lo + hi); lo = mid - 0.5 * log10(2.0); hi = mid + 0.5 * log10(2.0); }
    double pad = 0.04 * (hi - lo);
    a->lo = lo - pad;
    a->hi = hi + pad;
}

static void tick_label(char *buf, size_t size, double v, int integers) {
    if (integers) snprintf(buf, size, "%.0f", v);
    else if (v >= 1e-3 && v < 1e4) snprintf(buf, size, "%g", v);
    else snprintf(buf, size, "%.0e", v);
}

/* Ticks at 10^k, or (integers, the spp axis) at powers of two; with fewer than three of them
 * in range also at 2 and 5 times each decade. */
static void axis_ticks(ReportText *t, const LogAxis *a, int vertical, int integers, double x0, double y0,
                       double length) {
    double ticks[64];
    int n = 0;
    if (integers) {
        for (int k = 0; k < 31 && n < 64; ++k) {
            double v = (double)(1u << k);
            if (log10(v) >= a->lo && log10(v) <= a->hi) ticks[n++] = v;
        }
        if (n > 8) { /* thin out: every second or fourth power */
            int step = n > 16 ? 4 : 2, m = 0;
            for (int k = 0; k < n; k += step) ticks[m++] = ticks[k];
            n = m;
        }
    } else {
        for (int e = (int)floor(a->lo); e <= (int)ceil(a->hi) && n < 60; ++e)
            if (e >= a->lo && e <= a->hi) ticks[n++] = pow(10.0, e);
        if (n < 3) {
            n = 0;
            for (int e = (int)floor(a->lo); e <= (int)ceil(a->hi) && n < 60; ++e)
                for (int m = 0; m < 3; ++m) {
                    double v = (m == 0 ? 1.0 : m == 1 ? 2.0 : 5.0) * pow(10.0, e);
                    if (log10(v) >= a->lo && log10(v) <= a->hi) ticks[n++] = v;
                }
        }
    }
    for (int k = 0; k < n; ++k) {
        double p = axis_map(a, ticks[k]);
        char label[32];
        tick_label(label, sizeof label, ticks[k], integers);
        if (vertical) {
            report_printf(t, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#ddd\"/>\n", x0, p, x0 + length, p);
            report_printf(t, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\" dominant-baseline=\"middle\">%s</text>\n",
                          x0 - 6, p, label);
        } else {
            report_printf(t, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#ddd\"/>\n", p, y0, p, y0 - length);
            report_printf(t, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%s</text>\n", p, y0 + 16, label);
        }
    }
}

int report_convergence_svg(const char *path, const ReportSeries *series, int num_series, ReportAxis x,
                           char err[CANDELA_ERR_LEN]) {
    const double W = 560, H = 380, left = 70, right = 150, top = 30, bottom = 50;
    double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY;
    for (int s = 0; s < num_series; ++s)
        for (int i = 0; i < series[s].count; ++i) {
            const ReportPoint *p = &series[s].points[i];
            double xv = x == REPORT_X_SPP ? p->spp : p->seconds;
            if (!(xv > 0.0) || !(p->relmse > 0.0) || !isfinite(p->relmse)) continue; /* not on a log axis */
            xmin = fmin(xmin, xv); xmax = fmax(xmax, xv);
            ymin = fmin(ymin, p->relmse); ymax = fmax(ymax, p->relmse);
        }
    LogAxis ax = {0}, ay = {0};
    axis_fit(&ax, xmin, xmax);
    axis_fit(&ay, ymin, ymax);
    ax.pix0 = left; ax.pix1 = W - right;
    ay.pix0 = H - bottom; ay.pix1 = top;
    ReportText t = {0};
    report_printf(&t, "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" viewBox=\"0 0 %.0f %.0f\" "
                      "font-family=\"sans-serif\" font-size=\"12\">\n", W, H, W, H);
    report_printf(&t, "<rect width=\"100%%\" height=\"100%%\" fill=\"white\"/>\n");
    report_printf(&t, "<text x=\"%.1f\" y=\"18\" text-anchor=\"middle\" font-size=\"14\">relMSE against %s (log-log)</text>\n",
                  0.5 * (left + W - right), x == REPORT_X_SPP ? "samples per pixel" : "seconds");
    axis_ticks(&t, &ay, 1, 0, left, 0, W - right - left);
    axis_ticks(&t, &ax, 0, x == REPORT_X_SPP, 0, H - bottom, H - bottom - top);
    report_printf(&t, "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"none\" stroke=\"black\"/>\n", left, top,
                  W - right - left, H - bottom - top);
    report_printf(&t, "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%s</text>\n", 0.5 * (left + W - right), H - 10,
                  x == REPORT_X_SPP ? "samples per pixel" : "seconds (load and build included)");
    report_printf(&t, "<text transform=\"translate(16 %.1f) rotate(-90)\" text-anchor=\"middle\">relMSE</text>\n",
                  0.5 * (top + H - bottom));
    for (int s = 0; s < num_series; ++s) {
        const char *colour = PALETTE[s % (int)(sizeof PALETTE / sizeof PALETTE[0])];
        report_printf(&t, "<g stroke=\"%s\" fill=\"%s\">\n<polyline fill=\"none\" stroke-width=\"2\" points=\"", colour, colour);
        for (int i = 0; i < series[s].count; ++i) {
            const ReportPoint *p = &series[s].points[i];
            double xv = x == REPORT_X_SPP ? p->spp : p->seconds;
            if (!(xv > 0.0) || !(p->relmse > 0.0) || !isfinite(p->relmse)) continue;
            report_printf(&t, "%.1f,%.1f ", axis_map(&ax, xv), axis_map(&ay, p->relmse));
        }
        report_printf(&t, "\"/>\n");
        for (int i = 0; i < series[s].count; ++i) {
            const ReportPoint *p = &series[s].points[i];
            double xv = x == REPORT_X_SPP ? p->spp : p->seconds;
            if (!(xv > 0.0) || !(p->relmse > 0.0) || !isfinite(p->relmse)) continue;
            report_printf(&t, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"2.5\"/>\n", axis_map(&ax, xv), axis_map(&ay, p->relmse));
        }
        double ly = top + 10 + 18.0 * s;
        report_printf(&t, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke-width=\"2\"/>\n", W - right + 10, ly,
                      W - right + 30, ly);
        report_printf(&t, "<text x=\"%.1f\" y=\"%.1f\" stroke=\"none\" fill=\"black\" dominant-baseline=\"middle\">", W - right + 35,
                      ly);
        report_html(&t, series[s].name);
        report_printf(&t, "</text>\n</g>\n");
    }
    report_printf(&t, "</svg>\n");
    int rc = report_write_text(path, &t, err);
    report_text_free(&t);
    return rc;
}

/* ---------------------------------------------------------------- crops */

void report_pick_crop(const float *error_map, int width, int height, int crop[3]) {
    int shorter = width < height ? width : height;
    int side = shorter / 4 >= 8 ? shorter / 4 : (shorter < 8 ? shorter : 8);
    if (side < 1) side = 1;
    int step = side / 2 > 0 ? side / 2 : 1;
    double best = -1.0;
    crop[0] = (width - side) / 2; crop[1] = (height - side) / 2; crop[2] = side;
    for (int y0 = 0; y0 + side <= height; y0 += step)
        for (int x0 = 0; x0 + side <= width; x0 += step) {
            double e = 0.0;
            for (int y = y0; y < y0 + side; ++y)
                for (int x = x0; x < x0 + side; ++x) e += error_map[(size_t)y * (size_t)width + (size_t)x];
            if (e > best) { best = e; crop[0] = x0; crop[1] = y0; }
        }
}

int report_crops_png(const char *path, const float *const *crops, int num_panels, int side, char err[CANDELA_ERR_LEN]) {
    const int gap = 4;
    int scale = side >= 160 ? 1 : (160 + side - 1) / side; /* panels at least 160 pixels wide */
    int panel = side * scale;
    int W = num_panels * panel + (num_panels - 1) * gap, H = panel;
    float *rgb = malloc((size_t)W * (size_t)H * 3 * sizeof(float));
    if (!rgb) { snprintf(err, CANDELA_ERR_LEN, "%.400s: out of memory", path); return -1; }
    for (size_t i = 0; i < (size_t)W * (size_t)H * 3; ++i) rgb[i] = 0.5f; /* the grey bars */
    for (int p = 0; p < num_panels; ++p) {
        int ox = p * (panel + gap);
        for (int y = 0; y < panel; ++y)
            for (int x = 0; x < panel; ++x) {
                size_t s = 3 * ((size_t)(y / scale) * (size_t)side + (size_t)(x / scale));
                size_t d = 3 * ((size_t)y * (size_t)W + (size_t)(ox + x));
                for (int k = 0; k < 3; ++k) rgb[d + k] = candela_srgb_encode(crops[p][s + k]);
            }
    }
    char ioerr[IO_ERR_LEN];
    int rc = io_write_png(path, W, H, rgb, NULL, 0, ioerr);
    free(rgb);
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
    return rc;
}
