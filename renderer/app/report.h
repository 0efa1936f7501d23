/* renderer/app/report.h (private): the pieces of `candela compare`'s report folder that are not
 * renders: text built in memory and written atomically, convergence plots as SVG, the
 * side-by-side crop PNG and sRGB previews. compare.c decides what goes in them. */
#ifndef CANDELA_REPORT_H
#define CANDELA_REPORT_H

#include <stddef.h>

#include "candela.h"

/* A growing text buffer; after an allocation failure `failed` is set and appends do nothing. */
typedef struct ReportText {
    char *s;
    size_t len, cap;
    int failed;
} ReportText;
void report_printf(ReportText *t, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Appends s with & < > " escaped for HTML (and SVG). */
void report_html(ReportText *t, const char *s);
void report_text_free(ReportText *t);
/* Writes t to path through io's atomic writer (io_atomic_write: PATH.tmp-PID, synced, renamed; never
 * a half-written file). */
int report_write_text(const char *path, const ReportText *t, char err[CANDELA_ERR_LEN]);

/* One convergence snapshot: the image after spp samples, seconds into the render. */
typedef struct ReportPoint {
    int spp;
    double seconds, rmse, relmse, mae;
} ReportPoint;
typedef struct ReportSeries {
    const char *name;
    const ReportPoint *points;
    int count;
} ReportSeries;
typedef enum { REPORT_X_SPP, REPORT_X_SECONDS } ReportAxis;
/* A log-log line plot of relMSE against spp or seconds, one line per series, with a legend. */
int report_convergence_svg(const char *path, const ReportSeries *series, int num_series, ReportAxis x,
                           char err[CANDELA_ERR_LEN]);

/* The square crop (x, y, side), side about a quarter of the shorter image side, whose summed
 * error_map (one value per pixel) is largest: where the variants differ most from the reference. */
void report_pick_crop(const float *error_map, int width, int height, int crop[3]);
/* One PNG of num_panels crops (side x side linear RGB each) left to right, enlarged by an
 * integer factor (nearest neighbour) to at least 160 pixels, separated by grey bars. */
int report_crops_png(const char *path, const float *const *crops, int num_panels, int side, char err[CANDELA_ERR_LEN]);

#endif
