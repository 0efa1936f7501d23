/* volumes/trackers.c: null-collision estimators over the media of a view.
 *
 * Both trackers walk the merged majorant of the view: each medium's majorant iterator yields
 * piecewise-constant segments; on a sub-interval where several media are present the
 * combined majorant is the sum of theirs (the sum of majorants bounds the sum of
 * extinctions). Free flights are sampled with the combined majorant and restart at every
 * boundary of any medium's segment (carrying the residual optical depth over, see
 * sample_depth), which is exact because exponential distances are memoryless (the cache
 * points paper §4.1, Eq. 7: sigma_maj = sigma_a + sigma_s + sigma_n).
 * Nothing here allocates: a walk's state (iterators, NanoVDB accessors) lives on the stack. */
#include <string.h>

#include "internal.h"

typedef struct Lane {
    const Medium *m;
    MajorantIterator it;
    float a, b, maj;     /* the iterator's current segment */
    float ctl;           /* its control extinction (residual walks; 0 otherwise) */
    int live;            /* 0: no segment left */
    GridMediumCache cache;
} Lane;

typedef struct Walk {
    Lane lane[VOLUME_MAX_OVERLAP];
    int n;               /* lanes (the view's count; NULL media are dead lanes) */
    unsigned active;     /* lanes present on the current sub-interval with a majorant > 0 */
    float t, tmax;
    const float *o, *d;
} Walk;

/* walk_begin_mode's modes: plain majorants, with controls (residual ratio tracking), with
 * controls and emitting media's coarse majorants (media_emission_line_at, VOLUME_LINE_COARSE) */
enum { WALK_PLAIN = 0, WALK_CONTROL = 1, WALK_COARSE = 2 };

static void walk_begin_mode(Walk *w, const MediaView *v, const float o[3], const float d[3], float tmin, float tmax,
                            int control) {
    w->n = v ? (v->count < 0 ? 0 : v->count > VOLUME_MAX_OVERLAP ? VOLUME_MAX_OVERLAP : v->count) : 0;
    w->t = tmin;
    w->tmax = tmax;
    w->o = o;
    w->d = d;
    w->active = 0;
    for (int i = 0; i < w->n; ++i) {
        Lane *l = &w->lane[i];
        l->m = v->media[i];
        l->live = 0;
        l->cache.ready = 0;
        if (!l->m) continue;
        l->ctl = 0.0f;
        if (control == WALK_COARSE) {
            medium_majorant_begin_coarse(l->m, o, d, tmin, tmax, &l->it);
            l->live = medium_majorant_next_control(&l->it, &l->a, &l->b, &l->maj, &l->ctl);
        } else if (control) {
            medium_majorant_begin_control(l->m, o, d, tmin, tmax, &l->it);
            l->live = medium_majorant_next_control(&l->it, &l->a, &l->b, &l->maj, &l->ctl);
        } else {
            medium_majorant_begin(l->m, o, d, tmin, tmax, &l->it);
            l->live = medium_majorant_next(&l->it, &l->a, &l->b, &l->maj);
        }
    }
}

static void walk_begin(Walk *w, const MediaView *v, const float o[3], const float d[3], float tmin, float tmax) {
    walk_begin_mode(w, v, o, d, tmin, tmax, WALK_PLAIN);
}

/* The combined majorant on [w->t, *end] and the lanes present there; 0 once the walk has
 * reached tmax (or for a NaN interval). Every call ends at a boundary of some lane's segment
 * or at tmax, and each lane has finitely many segments, so a walk takes finitely many. */
static inline int walk_interval(Walk *w, float *end, float *maj) {
    if (!(w->t < w->tmax)) return 0;
    float e = w->tmax, s = 0.0f;
    unsigned act = 0;
    for (int i = 0; i < w->n; ++i) {
        Lane *l = &w->lane[i];
        while (l->live && !(l->b > w->t)) l->live = medium_majorant_next(&l->it, &l->a, &l->b, &l->maj);
        if (!l->live) continue;
        if (l->a <= w->t) {
            s += l->maj;
            e = vminf(e, l->b);
            if (l->maj > 0.0f) act |= 1u << i;
        } else {
            e = vminf(e, l->a);
        }
    }
    *end = e;
    *maj = s;
    w->active = act;
    return 1;
}

/* The coefficients of the active lanes at a collision at t: sums, each lane's sigma_s, and
 * (when em != NULL) the emission source term sum_i sigma_a,i L_e,i with each lane's term in
 * lane_em (when not NULL; set for every lane, 0 where it does not emit here). */
static void walk_eval(Walk *w, float t, float sa[3], float ss[3], float lane_ss[][3], float em[3],
                      float lane_em[][3]) {
    for (int k = 0; k < 3; ++k) sa[k] = ss[k] = 0.0f;
    if (em) em[0] = em[1] = em[2] = 0.0f;
    if (lane_em)
        for (int i = 0; i < w->n; ++i) lane_em[i][0] = lane_em[i][1] = lane_em[i][2] = 0.0f;
    for (unsigned act = w->active; act; act &= act - 1) {
        int i = __builtin_ctz(act);
        Lane *l = &w->lane[i];
        const Medium *m = l->m;
        float *ls = lane_ss ? lane_ss[i] : NULL;
        if (m->kind == MEDIUM_HOMOGENEOUS) {
            for (int k = 0; k < 3; ++k) {
                sa[k] += m->sigma_a[k];
                ss[k] += m->sigma_s[k];
                if (ls) ls[k] = m->sigma_s[k];
            }
            continue;
        }
        if (!l->cache.ready) {
            grid_reader_init(&l->cache.density, &m->density);
            if (m->emissive) grid_reader_init(&l->cache.aux, m->emission.buffer ? &m->emission : &m->temperature);
            l->cache.ready = 1;
        }
        /* the density at the DDA's own index-space position, so that the point is in the
         * cell whose majorant was used (up to rounding, which the majorant's slack covers) */
        float dt = t - l->it.t_base, pi[3];
        for (int k = 0; k < 3; ++k) pi[k] = l->it.o_index[k] + dt * l->it.d_index[k];
        float st = grid_sigma_t(m, &l->cache.density, pi);
        for (int k = 0; k < 3; ++k) {
            float s = m->albedo[k] * st;
            ss[k] += s;
            sa[k] += st - s;
            if (ls) ls[k] = s;
        }
        if (em && m->emissive && st > 0.0f) {
            float p[3] = {w->o[0] + t * w->d[0], w->o[1] + t * w->d[1], w->o[2] + t * w->d[2]}, le[3];
            grid_emission(m, &l->cache.aux, p, le);
            for (int k = 0; k < 3; ++k) {
                float src = (1.0f - m->albedo[k]) * st * le[k];
                em[k] += src;
                if (lane_em) lane_em[i][k] = src;
            }
        }
    }
}

/* Free flights. The optical depth to the next collision of the majorant process is
 * Exp(1): -ln(1 - u), with 1 - u in (0, 1] (a u of 1 from a bad generator gives an infinite
 * depth, which passes everything). Within a sub-interval of constant majorant the flight is
 * depth / maj; at the sub-interval's end the depth left over carries into the next one
 * (minus maj x length). By memorylessness this is the same process as restarting the
 * exponential at every boundary, without a random number and a log per boundary (a ray
 * through a cloud crosses ~10 majorant cells for a few collisions). */
static inline float sample_depth(VolumeRng *rng) { return -logf(1.0f - rng->next(rng->state)); }

/* Advances the walk to the next collision inside [walk.t, end) of majorant maj: 1 with
 * walk->t at the collision, or 0 with walk->t = end and *depth reduced by what was crossed. */
static inline int next_collision(Walk *w, float end, float maj, float *depth) {
    float tn = w->t + *depth / maj;
    if (tn < end) {
        w->t = tn;
        return 1;
    }
    *depth = vmaxf(*depth - maj * (end - w->t), 0.0f);
    w->t = end;
    return 0;
}

/* ---------------------------------------------------------------- spectral tracking */

void media_sample_event(const MediaView *v, const float o[3], const float d[3], float tmin, float tmax,
                        const float beta[3], VolumeRng *rng, VolumeEvent *ev, VolumeStats *stats) {
    float w[3] = {1.0f, 1.0f, 1.0f}, em[3] = {0.0f, 0.0f, 0.0f};
    const float one[3] = {1.0f, 1.0f, 1.0f};
    if (!beta) beta = one;
    memset(ev->emitted_by, 0, sizeof ev->emitted_by);
    ev->type = VOLUME_EVENT_PASSED;
    ev->t = tmax;
    ev->medium = -1;
    ev->null_mis = 1.0f;
    ev->sigma_s_mean = 0.0f;
    float null_mis = 1.0f;
    uint64_t collisions = 0;
    int decompose = v && v->decomposition;
    Walk walk;
    walk_begin(&walk, v, o, d, tmin, tmax);
    float end, maj, depth = sample_depth(rng);
    while (walk_interval(&walk, &end, &maj)) {
        if (!(maj > 0.0f)) {
            walk.t = end;
            continue;
        }
        while (next_collision(&walk, end, maj, &depth)) {
            float tn = walk.t;
            if (collisions == VOLUME_MAX_COLLISIONS) {
                /* the bias of last resort: a walk that would not end is cut (counted) */
                if (stats) ++stats->capped_walks;
                ev->type = VOLUME_EVENT_ABSORBED;
                w[0] = w[1] = w[2] = 0.0f;
                goto done;
            }
            ++collisions;
            float sa[3], ss[3], lane_ss[VOLUME_MAX_OVERLAP][3], src[3], sn[3], lane_src[VOLUME_MAX_OVERLAP][3];
            /* Decomposition tracking (Kutz et al. 2017 §4): where homogeneous media (a control
             * component of constant coefficients) overlap grid media (the residual), the
             * collision belongs to the control with probability maj_c / maj and then needs no
             * grid lookup; each component's collision decides among its own coefficients, with
             * its own majorant (the null coefficient splits into the components' parts, so the
             * weights below stay those of spectral tracking with maj -> maj_component). */
            unsigned all = walk.active;
            float maj_full = maj;
            if (decompose && __builtin_popcount(all) > 1) {
                unsigned control = 0;
                float maj_c = 0.0f;
                for (unsigned act = all; act; act &= act - 1) {
                    int i = __builtin_ctz(act);
                    if (walk.lane[i].m->kind == MEDIUM_HOMOGENEOUS) { control |= 1u << i; maj_c += walk.lane[i].maj; }
                }
                if (control && control != all) {
                    int to_control = rng->next(rng->state) * maj < maj_c;
                    maj = to_control ? maj_c : vmaxf(maj - maj_c, 1e-30f);
                    walk.active = to_control ? control : all & ~control;
                }
            }
            if (stats)
                for (unsigned act = walk.active; act; act &= act - 1)
                    if (walk.lane[__builtin_ctz(act)].m->kind != MEDIUM_HOMOGENEOUS) { ++stats->grid_collisions; break; }
            walk_eval(&walk, tn, sa, ss, lane_ss, src, lane_src);
            float inv_maj = 1.0f / maj;
            /* Emission, a collision estimator at every collision (Eq. 7's sigma_a L_e term
             * over the density maj exp(-maj t) of the collision; the spec's §7.4 Algorithm 1
             * with P_a = P_n = 1): the absorption and null events below then only decide
             * whether the walk goes on, so the estimate stays unbiased though absorption ends
             * the walk. */
            for (int k = 0; k < 3; ++k) {
                em[k] += w[k] * src[k] * inv_maj;
                sn[k] = vmaxf(maj - sa[k] - ss[k], 0.0f);
            }
            /* the same estimate split by the medium it came from (emitted_by, for MIS) */
            if (src[0] != 0.0f || src[1] != 0.0f || src[2] != 0.0f)
                for (int i = 0; i < walk.n; ++i)
                    for (int k = 0; k < 3; ++k) ev->emitted_by[i][k] += w[k] * lane_src[i][k] * inv_maj;
            /* Kutz et al. 2017 §5 (spectral tracking with history-aware probabilities): the
             * event probabilities are the averages over channels of the coefficients weighted
             * by the path throughput beta x w, so chromatic media stay unbiased per channel
             * and the weights stay bounded. */
            float pa = 0.0f, ps = 0.0f, pn = 0.0f;
            for (int k = 0; k < 3; ++k) {
                float c = fabsf(beta[k] * w[k]);
                pa += sa[k] * c;
                ps += ss[k] * c;
                pn += sn[k] * c;
            }
            float sum = pa + ps + pn;
            if (!(sum > 0.0f) || !isfinite(sum)) { /* a zero throughput: the plain averages */
                pa = sa[0] + sa[1] + sa[2];
                ps = ss[0] + ss[1] + ss[2];
                pn = sn[0] + sn[1] + sn[2];
                sum = pa + ps + pn;
                if (!(sum > 0.0f) || !isfinite(sum)) {
                    ev->type = VOLUME_EVENT_ABSORBED;
                    w[0] = w[1] = w[2] = 0.0f;
                    goto done;
                }
            }
            float u = rng->next(rng->state) * sum;
            if (u < pa) { /* absorbed: the emission was already gathered */
                ev->type = VOLUME_EVENT_ABSORBED;
                w[0] = w[1] = w[2] = 0.0f;
                goto done;
            }
            if (u < pa + ps) {
                /* Real scattering. The phase function is one medium's, picked with
                 * probability q_i proportional to lum(sigma_s,i): the in-scattering term
                 * sum_i sigma_s,i (phase_i * L) is estimated by sigma_s,i (phase_i * L) / q_i,
                 * so the weight carries sigma_s,i / (maj P_s q_i), per channel. */
                float lsum = 0.0f, lum[VOLUME_MAX_OVERLAP] = {0};
                int pick = -1;
                for (unsigned act = walk.active; act; act &= act - 1) {
                    int i = __builtin_ctz(act);
                    lum[i] = vlum(lane_ss[i]);
                    lsum += lum[i];
                    if (lum[i] > 0.0f) pick = i;
                }
                if (pick < 0) { /* ps > 0 needs some sigma_s > 0; guards rounding only */
                    ev->type = VOLUME_EVENT_ABSORBED;
                    w[0] = w[1] = w[2] = 0.0f;
                    goto done;
                }
                if (__builtin_popcount(walk.active) > 1) {
                    float x = rng->next(rng->state) * lsum;
                    for (unsigned act = walk.active; act; act &= act - 1) {
                        int i = __builtin_ctz(act);
                        if (lum[i] <= 0.0f) continue;
                        pick = i;
                        if (x < lum[i]) break;
                        x -= lum[i];
                    }
                }
                float f = sum / (ps * maj) * (lsum / lum[pick]);
                for (int k = 0; k < 3; ++k) w[k] *= lane_ss[pick][k] * f;
                ev->type = VOLUME_EVENT_SCATTER;
                ev->t = tn;
                ev->medium = pick;
                ev->null_mis = null_mis;
                ev->sigma_s_mean = (ss[0] + ss[1] + ss[2]) * (1.0f / 3.0f);
                goto done;
            }
            /* null collision: w *= sigma_n / (maj P_n) */
            float f = sum / (pn * maj);
            for (int k = 0; k < 3; ++k) w[k] *= sn[k] * f;
            null_mis *= (sn[0] + sn[1] + sn[2]) * (1.0f / 3.0f) * inv_maj;
            maj = maj_full;
            walk.active = all;
            depth = sample_depth(rng);
        }
    }
done:
    if (stats) stats->collisions += collisions;
    for (int k = 0; k < 3; ++k) {
        ev->weight[k] = w[k];
        ev->emitted[k] = em[k];
    }
}

/* ---------------------------------------------------------------- ratio tracking */

/* Below this max(T), Russian roulette: survive with probability max(T) and divide by it. */
#define RATIO_RR_THRESHOLD 0.1f

/* Russian roulette on a ratio-tracking weight below max(w) = RATIO_RR_THRESHOLD: survive with
 * probability max(w) and divide by it (unbiased); 0 (and w = 0) when the walk ends. */
static inline int ratio_roulette(float w[3], VolumeRng *rng) {
    float mx = vmax3(w);
    if (!(mx < RATIO_RR_THRESHOLD)) return 1;
    if (!(mx > 0.0f) || rng->next(rng->state) >= mx) {
        w[0] = w[1] = w[2] = 0.0f;
        return 0;
    }
    float inv = 1.0f / mx;
    for (int k = 0; k < 3; ++k) w[k] *= inv;
    return 1;
}

/* The ratio-tracking walk of media_ratio_track (the null vertices' product it also returns is
 * that of the free flights' own majorant process, which residual tracking would not give): at
 * every collision of the view's majorant process w *= sigma_n / sigma_maj = 1 - sigma_t /
 * sigma_maj per channel (Novák et al. 2014:
 * w stays an unbiased estimate of the transmittance with the grey, max over RGB, majorant);
 * below max(w) = RATIO_RR_THRESHOLD an unbiased Russian roulette (w = 0 when it ends the walk).
 * next_collision places a collision before anything is gathered and stops at the segment's
 * end, so nothing beyond tmax counts. Returns 0 when stopped by VOLUME_MAX_COLLISIONS. */
static int ratio_walk(const MediaView *v, const float o[3], const float d[3], float tmin, float tmax, VolumeRng *rng,
                      float w[3], float *null_mis, uint64_t *collisions) {
    Walk walk;
    walk_begin(&walk, v, o, d, tmin, tmax);
    float end, maj, depth = sample_depth(rng);
    while (walk_interval(&walk, &end, &maj)) {
        if (!(maj > 0.0f)) {
            walk.t = end;
            continue;
        }
        float inv_maj = 1.0f / maj;
        while (next_collision(&walk, end, maj, &depth)) {
            float tn = walk.t;
            if (*collisions == VOLUME_MAX_COLLISIONS) return 0;
            ++*collisions;
            float sa[3], ss[3];
            walk_eval(&walk, tn, sa, ss, NULL, NULL, NULL);
            float q[3];
            for (int k = 0; k < 3; ++k) {
                q[k] = vmaxf(1.0f - (sa[k] + ss[k]) * inv_maj, 0.0f);
                w[k] *= q[k];
            }
            if (null_mis) *null_mis *= (q[0] + q[1] + q[2]) * (1.0f / 3.0f);
            if (!ratio_roulette(w, rng)) return 1;
            depth = sample_depth(rng);
        }
    }
    return 1;
}

/* ---------------------------------------------------------------- residual ratio tracking */

/* The residual interval: on [w->t, *end] the control extinction sigma_c (per channel: the
 * homogeneous lanes' exact sigma_t plus the grid lanes' controls), the residual majorant
 * sum(maj - ctl) over the grid lanes that collide, and their summed control (grey). A
 * homogeneous lane never collides: its transmittance is exp(-sigma_t d) exactly. */
static inline int walk_interval_residual(Walk *w, float *end, float *maj_r, float sc[3], float *ctl_active) {
    if (!(w->t < w->tmax)) return 0;
    float e = w->tmax, s = 0.0f, ca = 0.0f;
    sc[0] = sc[1] = sc[2] = 0.0f;
    unsigned act = 0;
    for (int i = 0; i < w->n; ++i) {
        Lane *l = &w->lane[i];
        while (l->live && !(l->b > w->t))
            l->live = medium_majorant_next_control(&l->it, &l->a, &l->b, &l->maj, &l->ctl);
        if (!l->live) continue;
        if (l->a <= w->t) {
            e = vminf(e, l->b);
            if (l->m->kind == MEDIUM_HOMOGENEOUS) {
                for (int k = 0; k < 3; ++k) sc[k] += l->m->sigma_a[k] + l->m->sigma_s[k];
            } else if (l->maj > 0.0f) {
                for (int k = 0; k < 3; ++k) sc[k] += l->ctl;
                s += l->maj - l->ctl;
                ca += l->ctl;
                act |= 1u << i;
            }
        } else {
            e = vminf(e, l->a);
        }
    }
    *end = e;
    *maj_r = s;
    *ctl_active = ca;
    w->active = act;
    return 1;
}

static inline void attenuate(float w[3], const float sc[3], float length) {
    if (length > 0.0f)
        for (int k = 0; k < 3; ++k)
            if (sc[k] > 0.0f) w[k] *= expf(-sc[k] * length);
}

/* Residual ratio tracking (Novak, Selle and Jarosz 2014 §5): T = exp(-integral of sigma_c) x
 * the ratio-tracking estimate of the residual sigma_t - sigma_c under the residual majorant
 * maj - sigma_c, with the control sigma_c a per-cell lower bound of sigma_t (the control grid,
 * majorant.c), so q = 1 - (sigma_t - sigma_c) / (maj - sigma_c) lies in [0, 1]. Where the
 * medium is nearly uniform in a cell the residual is small: few collisions, each with q near
 * 1, instead of ratio tracking's q near 0 that made the transmittance through mist close to a
 * binary estimate. With emitter >= 0 the emission of that lane (whose control is 0, so its
 * whole majorant with the emission term drives the collisions) is gathered as in
 * media_emission_line's collision estimator, weighted by the transmittance estimate so far
 * (the running weight is unbiased for T(tmin, t) at any t fixed before the walk). Russian
 * roulette below max(w) = RATIO_RR_THRESHOLD as ratio tracking. */
static int residual_walk(const MediaView *v, int emitter, const float o[3], const float d[3], float tmin, float tmax,
                         int mode, VolumeRng *rng, float w[3], float L[3], uint64_t *collisions) {
    Walk walk;
    walk_begin_mode(&walk, v, o, d, tmin, tmax, mode);
    float end, maj, ctl, sc[3], depth = sample_depth(rng);
    while (walk_interval_residual(&walk, &end, &maj, sc, &ctl)) {
        float t_last = walk.t;
        if (!(maj > 0.0f)) {
            attenuate(w, sc, end - t_last);
            walk.t = end;
            continue;
        }
        float inv_maj = 1.0f / maj;
        while (next_collision(&walk, end, maj, &depth)) {
            float tn = walk.t;
            if (*collisions == VOLUME_MAX_COLLISIONS) return 0;
            ++*collisions;
            attenuate(w, sc, tn - t_last);
            t_last = tn;
            float sa[3], ss[3], src[3], lane_src[VOLUME_MAX_OVERLAP][3];
            if (emitter >= 0) {
                walk_eval(&walk, tn, sa, ss, NULL, src, lane_src);
                for (int k = 0; k < 3; ++k) L[k] += w[k] * lane_src[emitter][k] * inv_maj;
            } else {
                walk_eval(&walk, tn, sa, ss, NULL, NULL, NULL);
            }
            for (int k = 0; k < 3; ++k) w[k] *= vmaxf(1.0f - (sa[k] + ss[k] - ctl) * inv_maj, 0.0f);
            if (!ratio_roulette(w, rng)) return 1;
            depth = sample_depth(rng);
        }
        attenuate(w, sc, end - t_last);
    }
    return 1;
}

void media_transmittance(const MediaView *v, const float o[3], const float d[3], float tmin, float tmax,
                         VolumeRng *rng, float T[3], VolumeStats *stats) {
    /* residual ratio tracking (Novák et al. 2014 §5): the walk's weight is the estimate */
    T[0] = T[1] = T[2] = 1.0f;
    uint64_t collisions = 0;
    if (!residual_walk(v, -1, o, d, tmin, tmax, WALK_CONTROL, rng, T, NULL, &collisions)) {
        if (stats) ++stats->capped_walks;
        T[0] = T[1] = T[2] = 0.0f;
    }
    if (stats) stats->collisions += collisions;
}

void media_ratio_track(const MediaView *v, const float o[3], const float d[3], float tmin, float tmax,
                       VolumeRng *rng, float T[3], float *null_mis, VolumeStats *stats) {
    T[0] = T[1] = T[2] = 1.0f;
    *null_mis = 1.0f;
    uint64_t collisions = 0;
    if (!ratio_walk(v, o, d, tmin, tmax, rng, T, null_mis, &collisions)) {
        if (stats) ++stats->capped_walks;
        T[0] = T[1] = T[2] = 0.0f;
    }
    if (stats) stats->collisions += collisions;
}

/* ---------------------------------------------------------------- emission-optimised tracking */

void media_emission_line_at(const MediaView *v, int emitter, const float o[3], const float d[3], float tmin,
                            float tmax, VolumeLineDensity density, VolumeRng *rng, float L[3], VolumeStats *stats) {
    /* The cache points paper §4.3, Algorithm 1 (spec §7.4): the majorant process of the
     * view's merged majorants (which carry the emission term) with P_a = P_n = 1: every
     * collision gathers (a collision estimator of the emission integral weighted by the
     * ratio-tracking transmittance so far), and no absorption or scattering event is chosen. */
    L[0] = L[1] = L[2] = 0.0f;
    int n = v ? (v->count < 0 ? 0 : v->count > VOLUME_MAX_OVERLAP ? VOLUME_MAX_OVERLAP : v->count) : 0;
    if (emitter < 0 || emitter >= n || !v->media[emitter] || !v->media[emitter]->emissive) return;
    float w[3] = {1.0f, 1.0f, 1.0f};
    uint64_t collisions = 0;
    if (!residual_walk(v, emitter, o, d, tmin, tmax, density == VOLUME_LINE_COARSE ? WALK_COARSE : WALK_CONTROL, rng,
                       w, L, &collisions) && stats) ++stats->capped_walks;
    if (stats) stats->collisions += collisions;
}

void media_emission_line(const MediaView *v, int emitter, const float o[3], const float d[3], float tmin, float tmax,
                         VolumeRng *rng, float L[3], VolumeStats *stats) {
    media_emission_line_at(v, emitter, o, d, tmin, tmax, VOLUME_LINE_STANDARD, rng, L, stats);
}
