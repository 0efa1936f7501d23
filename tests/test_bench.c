/* tests/test_bench.c: `candela bench`'s ray log (issue 13 item 12). A log that cannot grow is
 * marked failed, so the benchmark reports an error instead of a wrong ray count; the bound is
 * checked before the log's size doubles, so no size wraps. */
#include <stdlib.h>

#include "check.h"
#include "integrator.h"

int main(void) {
    SceneRay rays[4];
    for (int i = 0; i < 4; ++i) rays[i] = (SceneRay){v3(0.0f, 0.0f, 0.0f), 0.0f, v3(0.0f, 0.0f, 1.0f), (float)i};
    const uint32_t items[4] = {0, 1, 2, 3};

    /* the ordinary path: rays are recorded in order, shadow rays with their tfar */
    CandelaRayLog log = {0};
    ray_log_append(&log, rays, items, 4, 0);
    ray_log_append(&log, rays, items, 2, 1);
    CHECK(!log.failed && log.count == 6, "count %zu, failed %d", log.count, log.failed);
    if (log.count == 6) {
        CHECK(log.is_shadow[3] == 0 && log.is_shadow[5] == 1, "shadow flags");
        CHECK(log.org_dir_tfar[7 * 5 + 6] == 1.0f && log.org_dir_tfar[7 * 1 + 6] > 1e30f, "tfar of shadow / camera rays");
    }
    candela_ray_log_free(&log);

    /* at the bound: failed, with nothing allocated or touched (the rays are not read). Before
     * the bound existed, this count made the doubling wrap to 0 and loop forever. */
    CandelaRayLog full = {0};
    full.count = CANDELA_RAY_LOG_MAX - 1;
    ray_log_append(&full, rays, items, 2, 0);
    CHECK(full.failed == 1 && full.count == CANDELA_RAY_LOG_MAX - 1 && full.org_dir_tfar == NULL,
          "a log past its bound: failed %d, count %zu", full.failed, full.count);
    full.count = (size_t)-8;
    full.failed = 0;
    ray_log_append(&full, rays, items, 4, 1);
    CHECK(full.failed == 1 && full.org_dir_tfar == NULL, "a count near SIZE_MAX: failed %d", full.failed);
    /* a failed log stays failed */
    full.count = 0;
    ray_log_append(&full, rays, items, 1, 0);
    CHECK(full.failed == 1 && full.count == 0, "a failed log recorded again");
    return test_exit();
}
