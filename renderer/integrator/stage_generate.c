/* renderer/integrator/stage_generate.c: camera rays. Path j of the iteration is pixel j mod npixels (of
 * the iteration's pixels with adaptive sampling), sample sample_base + j / npixels; its numbers
 * are functions of (seed, pixel, sample) (sequence.h). The film's pixel (PathState.pixel) is the
 * crop's with --crop; the numbers and the ray are the full image's pixel's, so a crop pixel
 * draws exactly what the full render's pixel there draws. */
#include "integrator.h"
#include "rng.h"
#include "record.h"

void stage_generate(const Integrator *ig, Slice *s) {
    const PathState *ps = &ig->ps; /* the arrays, not the integrator, are written */
    const Camera *cam = &ig->scene->camera;
    s->num_rays = 0;
    for (uint32_t p = s->begin; p < s->end; ++p) {
        uint64_t j = ig->batch_first + p;
        uint32_t k = (uint32_t)(j % ig->iteration_pixels);
        uint32_t pixel = ig->pixel_list ? ig->pixel_list[k] : k;
        /* the film's pixel -> the full image's (the same without --crop) */
        uint32_t ix = (uint32_t)cam->crop_x + pixel % (uint32_t)cam->crop_width;
        uint32_t iy = (uint32_t)cam->crop_y + pixel / (uint32_t)cam->crop_width;
        uint32_t image_pixel = iy * (uint32_t)cam->width + ix;
        uint64_t sample = ig->sample_base + j / ig->iteration_pixels;
        uint64_t key = rng_path_key(ig->opt->seed, image_pixel, sample);
        ps->rng_key[p] = key;
        ps->pixel[p] = pixel;
        ps->sample_rindex[p] = sequence_reverse_bits((uint32_t)sample); /* below 2^24: --spp is at most 2^20 */
        ps->scramble[p] = ig->sobol ? sequence_pixel_scramble(ig->opt->seed, image_pixel) : 0;
        ps->depth[p] = 0;
        ps->volume_bounces[p] = 0;
        ps->medium[p] = ig->camera_medium;
        ps->crossings[p] = 0;
        ps->probe_medium[p] = 0;
        ps->probe_null[p] = ps->probe_mis[p] = ps->probe_cost[p] = 0.0f;
        ps->probe_em_medium[p] = 0;
        ps->probe_em_on[p] = ps->probe_em_off[p] = ps->probe_em_cost[p] = 0.0f;
        ps->probe_indirect[p] = 0.0f;
        PathDims dims = path_dims(ig, p);
        float fx = (float)ix + dims_camera(&dims, RNG_DIM_PIXEL_X);
        float fy = (float)iy + dims_camera(&dims, RNG_DIM_PIXEL_Y);
        vec3 o, d;
        camera_generate_ray(cam, fx, fy, &o, &d);
        ps->ray[p] = (SceneRay){o, 0.0f, d, INFINITY};
        ps->radiance[p] = v3s(0.0f);
        ps->throughput[p] = v3s(1.0f);
        ps->rr_scale[p] = 1.0f;
        ps->pixel_estimate[p] = ig->guide.pixel_estimate ? ig->guide.pixel_estimate[pixel] : 0.0f;
        ps->reg_roughness[p] = 0.0f;
        ps->prev_delta[p] = 1; /* the camera: emission seen directly takes no MIS weight */
        ps->prev_scatter_pdf[p] = 0.0f;
        ps->prev_link_class[p] = 0; /* the camera sees every emitter (light linking) */
        path_write_aovs(ps, p, v3s(0.0f), v3s(0.0f), INFINITY);
        if (ig->film.sel_aov) ps->aov_sel_point[p] = ps->aov_sel_light[p] = v3s(0.0f);
        record_camera(ig, p, j);
        s->rays[s->num_rays++] = p; /* pixel order: coherent already, so not sorted (no key) */
    }
}
