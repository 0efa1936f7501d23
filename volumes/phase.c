/* volumes/phase.c: the Henyey-Greenstein phase function and the blackbody colour of a
 * temperature grid's emission. */
#include <pthread.h>

#include "internal.h"

/* ---------------------------------------------------------------- Henyey-Greenstein */

/* Below this |g| the medium is isotropic exactly: the inversion's 1/(2g) loses all precision
 * as g -> 0, while HG differs from isotropic by O(g) there. */
#define HG_ISOTROPIC_G 1e-3f
#define HG_MAX_G 0.9999f /* |g| >= 1 is rejected at init; this only keeps the maths finite */

/* HG as a function of the cosine between wi and the forward direction -wo. */
static inline float hg_of_cos(float g, float cos_theta) {
    float denom = 1.0f + g * g - 2.0f * g * cos_theta; /* >= (1 - |g|)^2 > 0 */
    return (1.0f - g * g) / (4.0f * VOL_PI * denom * sqrtf(denom));
}

static inline float hg_clamp_g(float g) {
    if (!(fabsf(g) >= HG_ISOTROPIC_G)) return 0.0f; /* also NaN */
    return g > HG_MAX_G ? HG_MAX_G : g < -HG_MAX_G ? -HG_MAX_G : g;
}

float hg_phase(float g, const float wo[3], const float wi[3]) {
    g = hg_clamp_g(g);
    if (g == 0.0f) return 1.0f / (4.0f * VOL_PI);
    float cos_theta = -(wo[0] * wi[0] + wo[1] * wi[1] + wo[2] * wi[2]); /* forward = -wo */
    cos_theta = cos_theta > 1.0f ? 1.0f : cos_theta < -1.0f ? -1.0f : cos_theta;
    return hg_of_cos(g, cos_theta);
}

float hg_sample(float g, const float wo[3], float u1, float u2, float wi[3]) {
    g = hg_clamp_g(g);
    float cos_theta;
    if (g == 0.0f) {
        cos_theta = 1.0f - 2.0f * u1;
    } else {
        /* Inverting the CDF of cos_theta (Henyey & Greenstein 1941; e.g. Pharr et al., PBRT
         * 3rd ed. §15.2.3): cos = (1 + g^2 - ((1 - g^2) / (1 - g + 2 g u))^2) / (2 g). The
         * inner denominator is >= 1 - |g| > 0, and |2g| >= 2e-3 here. */
        float s = (1.0f - g * g) / (1.0f - g + 2.0f * g * u1);
        cos_theta = (1.0f + g * g - s * s) / (2.0f * g);
    }
    cos_theta = cos_theta > 1.0f ? 1.0f : cos_theta < -1.0f ? -1.0f : cos_theta;
    float sin_theta = sqrtf(vmaxf(0.0f, 1.0f - cos_theta * cos_theta));
    float phi = 2.0f * VOL_PI * u2;
    float sp = sinf(phi), cp = cosf(phi);
    /* frame around the forward direction n = -wo (Duff et al. 2017) */
    float n[3] = {-wo[0], -wo[1], -wo[2]};
    float sign = copysignf(1.0f, n[2]);
    float a = -1.0f / (sign + n[2]);
    float b = n[0] * n[1] * a;
    float t[3] = {1.0f + sign * n[0] * n[0] * a, sign * b, -sign * n[0]};
    float bt[3] = {b, sign + n[1] * n[1] * a, -n[1]};
    for (int k = 0; k < 3; ++k) wi[k] = sin_theta * (cp * t[k] + sp * bt[k]) + cos_theta * n[k];
    /* the pdf of the returned direction exactly as hg_phase evaluates it (MIS needs the
     * same number both ways) */
    return g == 0.0f ? 1.0f / (4.0f * VOL_PI) : hg_phase(g, wo, wi);
}

/* ---------------------------------------------------------------- blackbody */

/* The colour of a blackbody at temperature T: Planck's law
 *     B(lambda, T) = 2 h c^2 / lambda^5 / (exp(h c / (lambda k T)) - 1)
 * integrated against the CIE 1931 2-degree colour matching functions (Wyman, Sloan & Shirley
 * 2013, "Simple Analytic Approximations to the CIE XYZ Color Matching Functions", JCGT 2(2),
 * the multi-lobe piecewise-Gaussian fit) over 360..830 nm in 1 nm steps, converted XYZ ->
 * linear Rec.709 (sRGB primaries, D65 white), negative components (below ~1900 K the
 * Planckian locus leaves the Rec.709 gamut) clipped to 0, then scaled to Rec.709 luminance 1:
 * emission_scale alone sets the brightness, the temperature only the hue. The integration
 * is too slow for a collision, so a table of BB_N temperatures evenly spaced in log T from
 * 500 K to 100000 K is built once and interpolated linearly (a blend of luminance-1 colours
 * has luminance 1); above 100000 K the colour is the table's last (the Rayleigh-Jeans limit
 * is nearly reached there). */
#define BB_N 1024
#define BB_T_MIN 500.0
#define BB_T_MAX 100000.0

static float bb_table[BB_N][3];
static pthread_once_t bb_once = PTHREAD_ONCE_INIT;

static double wyman_lobe(double x, double mu, double s1, double s2) {
    double t = (x - mu) / (x < mu ? s1 : s2);
    return exp(-0.5 * t * t);
}

static void planck_rgb(double kelvin, float rgb[3]) {
    const double c2 = 1.4387769e7; /* h c / k in nm K */
    double X = 0.0, Y = 0.0, Z = 0.0;
    for (int nm = 360; nm <= 830; ++nm) {
        double l = (double)nm;
        double b = 1.0 / (pow(l * 1e-3, 5.0) * expm1(c2 / (l * kelvin))); /* up to a constant */
        X += b * (1.056 * wyman_lobe(l, 599.8, 37.9, 31.0) + 0.362 * wyman_lobe(l, 442.0, 16.0, 26.7) -
                  0.065 * wyman_lobe(l, 501.1, 20.4, 26.2));
        Y += b * (0.821 * wyman_lobe(l, 568.8, 46.9, 40.5) + 0.286 * wyman_lobe(l, 530.9, 16.3, 31.1));
        Z += b * (1.217 * wyman_lobe(l, 437.0, 11.8, 36.0) + 0.681 * wyman_lobe(l, 459.0, 26.0, 13.8));
    }
    double c[3] = {3.2404542 * X - 1.5371385 * Y - 0.4985314 * Z, -0.9692660 * X + 1.8760108 * Y + 0.0415560 * Z,
                   0.0556434 * X - 0.2040259 * Y + 1.0572252 * Z};
    for (int k = 0; k < 3; ++k) c[k] = c[k] > 0.0 ? c[k] : 0.0;
    double lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    for (int k = 0; k < 3; ++k) rgb[k] = (float)(c[k] / lum);
}

static void bb_build(void) {
    for (int i = 0; i < BB_N; ++i)
        planck_rgb(BB_T_MIN * pow(BB_T_MAX / BB_T_MIN, (double)i / (BB_N - 1)), bb_table[i]);
}

void blackbody_lookup(float kelvin, float rgb[3]) {
    pthread_once(&bb_once, bb_build);
    static const float inv_step = (float)((BB_N - 1) / 5.298317366548036); /* ln(BB_T_MAX / BB_T_MIN) */
    float x = logf(kelvin * (float)(1.0 / BB_T_MIN)) * inv_step;
    x = x < 0.0f ? 0.0f : x > (float)(BB_N - 1) ? (float)(BB_N - 1) : x;
    int i = (int)x;
    if (i >= BB_N - 1) i = BB_N - 2;
    float f = x - (float)i;
    for (int k = 0; k < 3; ++k) rgb[k] = bb_table[i][k] + f * (bb_table[i + 1][k] - bb_table[i][k]);
}

void blackbody_rgb(float kelvin, float rgb[3]) {
    if (!(kelvin >= BLACKBODY_MIN_KELVIN)) { /* also NaN */
        rgb[0] = rgb[1] = rgb[2] = 0.0f;
        return;
    }
    blackbody_lookup(kelvin, rgb);
}
