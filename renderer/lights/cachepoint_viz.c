/* renderer/lights/cachepoint_viz.c: cache point visualisation (README "Cache point AOV" and "Cache
 * point dump"). The colours are a pure function of an index, so the AOV of a pixel names the
 * point its first-hit vertex used (Li et al. 2024, §3.3: the single nearest point) and the
 * PLY's colour of that point is the same one. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "cachepoint_viz.h"
#include "io.h"

static uint32_t mix32(uint32_t x) { /* murmur3's finaliser */
    x ^= x >> 16; x *= 0x85ebca6bu;
    x ^= x >> 13; x *= 0xc2b2ae35u;
    x ^= x >> 16;
    return x;
}

vec3 cachepoint_false_colour(uint32_t id, uint32_t salt) {
    uint32_t h = mix32(id * 0x27d4eb2du + salt);
    float c[3];
    for (int k = 0; k < 3; ++k) c[k] = (float)(40u + ((h >> (8 * k)) & 0xffu) * 215u / 255u) / 255.0f;
    return v3(c[0], c[1], c[2]);
}

static void write_points(FILE *f, const CachePoints *cp) {
    uint32_t n = cp ? cachepoints_count(cp) : 0;
    fprintf(f,
            "ply\nformat ascii 1.0\n"
            "comment candela cache points (Li et al. 2024): position, radius r_p, near and far entry counts,\n"
            "comment far clusters (cut build), visibility slots, attempts and summed visibility (H_total,\n"
            "comment H_success, Eq. 5), slots under Eq. 6's attempt threshold, slots with W' != 1, mean and\n"
            "comment min W' (Eq. 6 then the 3.2.2 blur), and the false colour of --aov cachepoint\n"
            "element vertex %u\n"
            "property float x\nproperty float y\nproperty float z\nproperty float radius\n"
            "property uint near\nproperty uint far\nproperty uint far_clusters\nproperty uint slots\n"
            "property double attempts\nproperty double visible\nproperty uint sparse_slots\nproperty uint learned_slots\n"
            "property float mean_visibility\nproperty float min_visibility\n"
            "property uchar red\nproperty uchar green\nproperty uchar blue\n"
            "end_header\n",
            n);
    for (uint32_t i = 0; i < n; ++i) {
        CachePointSummary s;
        cachepoints_summary(cp, i, &s);
        vec3 c = cachepoint_false_colour(i, CACHEPOINT_COLOUR_POINT);
        fprintf(f, "%.9g %.9g %.9g %.9g %u %u %u %u %llu %.9g %u %u %.9g %.9g %d %d %d\n", s.pos[0], s.pos[1], s.pos[2],
                s.radius, s.near_count, s.far_count, s.far_clusters, s.slots, (unsigned long long)s.attempts,
                s.successes, s.sparse_slots, s.learned_slots, s.mean_w, s.min_w, (int)lrintf(c.x * 255.0f),
                (int)lrintf(c.y * 255.0f), (int)lrintf(c.z * 255.0f));
    }
}

int cachepoint_write_ply(const CachePoints *cp, const char *path, char err[CANDELA_ERR_LEN]) {
    /* through io's atomic writer: PATH.tmp-PID, checked, synced, renamed (io.h) */
    IoAtomicFile af;
    char ioerr[IO_ERR_LEN];
    int rc = io_atomic_begin(&af, path, "w", ioerr);
    if (rc == 0) {
        write_points(af.f, cp);
        rc = io_atomic_commit(&af, ioerr);
    }
    if (rc != 0) snprintf(err, CANDELA_ERR_LEN, "%s", ioerr);
    return rc ? -1 : 0;
}
