/* renderer/main.c: the `candela` command line. */
#include <errno.h>
#include <signal.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "candela.h"
#include "io.h"

static const char *USAGE =
    "usage: candela render SCENE.gltf|SCENE.glb [options]\n"
    "       candela bench SCENE [options]   render, then replay the same rays through bare Embree\n"
    "       candela guide-dump SCENE --at X,Y,Z [options]   render with guiding (mis unless --guiding\n"
    "                            ris), then write the learned directional pdf at the point\n"
    "                            (OUT.guide.exr/.png over (u, v) = ((cos theta + 1)/2, phi/2pi)), the\n"
    "                            final iteration's training directions in its leaf (OUT.hist.*)\n"
    "                            and the spatial tree's leaves (OUT.leaves.ply), OUT = -o without .exr\n"
    "       candela compare SCENE [options] render variants at equal spp (or time) vs a reference\n"
    "                            and write a report folder (tables, images, crops, plots, HTML)\n"
    "       candela merge -o OUT.exr [--png FILE | --no-png] SHARD.film...   the films of the\n"
    "                            --sample-shard renders of one frame into its image (sums of L,\n"
    "                            L^2 and counts added: per-pixel means and variances of all samples)\n"
    "       candela --help | --version\n"
    "\n"
    "options:\n"
    "  -o, --output FILE.exr     output EXR (RGBA + albedo, N, Z, variance layers);\n"
    "                            default out/<scene name>.exr\n"
    "  --png FILE.png            preview PNG path (default: the EXR path with .png)\n"
    "  --no-png                  do not write the PNG preview\n"
    "  --confine-to DIR          refuse a scene, or any file it references, outside DIR\n"
    "  --volume-budget-mb N      volume grids and their majorant and emission grids in total\n"
    "                            (default 8192; 0: none)\n"
    "  --texture-budget-mb N     decoded textures in total, 4 bytes per texel for 8-bit files and\n"
    "                            16 for others (default 8192; 0: none)\n"
    "  --save-partial            on Ctrl-C / SIGTERM, stop after the current batch (abandoning the\n"
    "                            rest of the iteration; with --checkpoint its state is written\n"
    "                            first) and write the image so far as NAME.partial.exr (exit 130);\n"
    "                            a second signal exits at once\n"
    "  --checkpoint FILE         write the film and learned state to FILE at the barriers after\n"
    "                            about 4, 8, 16, 32, ... spp (the largest cumulative spp not above\n"
    "                            each) and when interrupted; atomically (FILE.tmp-PID, rename)\n"
    "  --resume-from FILE        continue the render FILE checkpointed (same scene, resolution and\n"
    "                            options, else refused): the image equals the uninterrupted render's\n"
    "  --sample-shard I/N        render only samples [spp I/N, spp (I+1)/N) of every pixel (I from\n"
    "                            0), with the full render's random numbers, and write their film\n"
    "                            sums to -o NAME.film (no EXR); candela merge combines the N films\n"
    "  --spp N                   samples per pixel (default 16)\n"
    "  --seed S                  random seed (default 0)\n"
    "  --sampler sobol|independent  the numbers of each path: Owen-scrambled Sobol' points\n"
    "                            (default) or independent uniforms (the renders before 0.2)\n"
    "  --noise-threshold T       adaptive sampling: a pixel stops once its error estimate (standard\n"
    "                            errors / sqrt(value), Cycles' measure) and its neighbours' are\n"
    "                            below T (e.g. 0.01); --spp is the most any pixel gets\n"
    "  --min-spp N               adaptive sampling: no pixel stops before N samples (default 16)\n"
    "  --time-limit S            stop at the first iteration barrier past S seconds (load included)\n"
    "                            and write the image; its spp depend on the machine's speed\n"
    "  --clamp-direct V          clamp each direct-light contribution's largest channel to V\n"
    "                            (hue kept; biased; default off)\n"
    "  --clamp-indirect V        the same for indirect light (two or more bounces)\n"
    "  --aov spp                 add the channel spp (samples per pixel) to the EXR\n"
    "  --res WxH                 resolution (default: 640 wide, camera aspect)\n"
    "  --threads N               worker threads (default: all cores)\n"
    "  --max-depth N             maximum surface bounces; 1 = direct light only (default 8)\n"
    "  --max-volume-bounces N    maximum scattering events in media per path (default 256)\n"
    "  --volume-emission-sampling on|off|auto  emissive volumes are lights too (NEE with\n"
    "                            line integration, MIS with tracking); auto: per volume, kept\n"
    "                            where it lowers the estimated time to unit variance in the\n"
    "                            first 4 spp (default auto)\n"
    "  --volume-cachepoint-scatter on|off|auto  cache-point in-scattering sampling along\n"
    "                            camera rays through media, MIS with tracking (cachepoints);\n"
    "                            auto: per medium, kept where it measurably lowers the\n"
    "                            time to unit variance in the first 4 spp (default auto)\n"
"  --guiding off|mis|ris|auto  path guiding (default off): mis = one-sample MIS of the BSDF or\n"
    "                            phase function and the learned guide (alpha 0.5); ris = resampling\n"
    "                            of one candidate of each. Trains during the first 8 spp, then\n"
    "                            guides (iterations 1 x 8, then 2, 4, 8, 16, 16, ...); auto = mis\n"
    "                            where a probe over the first 4 spp predicts a gain, else off\n"
"  --guide-training-spp N    guiding learns from the first N spp, then renders with what it\n"
    "                            learned (default: an eighth of --spp, at least 22)\n"
    "  --guide-spatial-threshold C  a guiding leaf splits past C sqrt(spp of the iteration)\n"
    "                            training samples (default 3000)\n"
    "  --path-regularization G   roughen a vertex after a rough one: alpha' = 1 - (1 - alpha)\n"
    "                            (1 - G alpha'_prev) (the course's 0.01 helps guiding find caustics;\n"
    "                            biased; default 0: off)\n"
    "  --guide-spatial-filter on|off  train each sample into the leaf at a point jittered within\n"
    "                            a box of its leaf's size (Mueller et al. 2019; default off)\n"
    "  --aov recorder-debug      add recorder_debug.RGB to the EXR: the radiance recorder's primary\n"
    "                            training samples times their throughput (converges to RGB)\n"
    "  --recorder-budget N       recorded vertices per path before path/vertex skipping (default 4;\n"
    "                            0: record every vertex)\n"
    "  --recorder-mb N           radiance recorder storage bound in MiB (default 256)\n"
    "  --light-sampler S         auto | uniform | power | tree | optimal | cachepoints (default auto:\n"
    "                            power for one light, optimal up to ~128 punctual lights (an area\n"
    "                            light counts 8), else cachepoints; cachepoints with media)\n"
    "  --no-visibility           cache points without visibility learning\n"
    "  --cachepoint-build B      cut (default: far entries are light-tree clusters) | linear (the\n"
    "                            paper: every light estimated at every point)\n"
    "  --cachepoint-cut-size N   cut build: far entries per cache point (default 128)\n"
    "  --cachepoint-candidates N cache point candidates in object boxes (default: 100000 at\n"
    "                            1280x720 pixels or more, in proportion below, at least 25000)\n"
    "  --cachepoint-pilots N     cache point pilot paths (default 65536)\n"
    "  --cachepoint-retruncate   linear build: re-apply the 97%/256 rule after the blur (less memory)\n"
    "  --cachepoint-pooling off|points|lights  visibility counters of slots with too few attempts\n"
    "                            pooled over the 16 neighbouring points (points), then over the\n"
    "                            lights next to the slot's in the light tree (lights; default off)\n"
    "  --cachepoint-progressive on|off  insert cache points between iterations where neighbouring\n"
    "                            points' learned visibility jumps (default off)\n"
    "  --cachepoint-progressive-budget F  inserted points as a fraction of the built ones (default 0.15)\n"
    "  --cachepoint-bsdf on|off  at glossy vertices weigh cache point entries by the BSDF lobe\n"
    "                            too, not only by the normal (default on; diffuse vertices unchanged)\n"
    "  --aov cachepoint          add cachepoint.RGB and cachepoint_light.RGB to the EXR (false colours\n"
    "                            of each first hit's cache point and of the entry it weighs most) and\n"
    "                            write NAME.cachepoint.png, NAME.cachepoint_light.png beside the PNG\n"
    "  --dump-cachepoints FILE.ply  write the cache points after the render as an ASCII PLY\n"
    "                            (position, radius, near/far counts, learned visibility, colour)\n"
    "  --optimal-occlusion       optimal sampler: one shadow ray per light per vertex\n"
    "  --light-units U           blender (default: cd/683, lux/683) | raw (W/sr, W/m^2)\n"
    "  --light-model M           gltf (default: glTF's spot cone ramp) | blender3 (Cycles 3.4's\n"
    "                            spot blend smoothstep, blend = 1 - inner/outer cone angle)\n"
    "  --material-model M        gltf (default: glTF 2.0 Appendix B BRDF) | blender3 (Blender 3.4's\n"
    "                            Principled BSDF v1 as its glTF importer sets it up)\n"
    "  --camera NAME             glTF camera by name (default: the first, or a framing view)\n"
    "  --env FILE                lat-long environment map (EXR/HDR/PNG...)\n"
    "  --env-strength S          environment multiplier (default 1)\n"
    "  --env-rotation DEG        turn the environment about the vertical, in degrees, with the sign\n"
    "                            of Blender's Mapping-node Z rotation (default: the scene's, else 0)\n"
    "  --batch N                 paths in flight per batch (default 2048 per thread; never changes the image)\n"
    "  --stats-json FILE         write render statistics as JSON\n"
    "animation frames (render):\n"
    "  --frames A-B[:step]|LIST  render these frames (e.g. 1-48, 1-48:4, 1,5,10-12) of the glTF\n"
    "                            animation at time frame / fps, one scene load for all; -o must\n"
    "                            then hold a run of '#' for the zero-padded frame number\n"
    "                            (default out/<scene>.####.exr; the PNG follows it). Frame f's\n"
    "                            seed is splitmix64 of --seed and f (README \"Animation\"). Exit\n"
    "                            status: the number of failed frames (at most 100), 101 when the\n"
    "                            request is bad (nothing rendered), 130 when interrupted\n"
    "  --fps F                   frames per second (default 24)\n"
    "  --resume                  skip frames whose EXR (and PNG) already exist and read back whole\n"
    "                            at the batch's resolution (others render again, with a warning)\n"
    "  --shard I/N               render every N-th frame of the list starting at position I\n"
    "                            (0 <= I < N, round-robin); without it SLURM_ARRAY_TASK_ID,\n"
    "                            _COUNT, _MIN and _STEP choose the shard of a Slurm job array\n"
    "  --dry-run                 check the command and print what it would render, loading\n"
    "                            nothing: 'shard I/N' and 'frame F EXR' per frame of this task\n"
    "                            (--frames), 'sample-shard I/N samples B-E of SPP FILM' or\n"
    "                            'render EXR' (scenes/farm/candela_submit.sh asks candela so)\n"
    "  --frame-stats FILE.jsonl  append one JSON line per frame (frame, time, seed, status,\n"
    "                            pose and cache point seconds, the --stats-json fields)\n"
    "  --quiet                   no progress or statistics on stderr (warnings stay)\n"
    "  --no-warnings             no warnings about the scene (what it holds that is not rendered)\n"
    "compare options (the options above apply to every variant and the reference):\n"
    "  --variants SPEC           \"NAME: FLAGS; NAME: FLAGS\" or FILE.toml / FILE.json: any render\n"
    "                            flags per variant (not --spp, --seed, --res); the first variant\n"
    "                            is the ratios' baseline (examples: scenes/compare/)\n"
    "  --strategies LIST         shorthand: NAME = --light-sampler NAME (default uniform,power,tree,\n"
    "                            optimal,cachepoints,cachepoints-novis; also cachepoints-linear,\n"
    "                            cachepoints-cut, with -novis)\n"
    "  --time-budget S           equal time: every variant renders until S seconds (load and build\n"
    "                            included), stopping at an iteration barrier; --spp is then a cap\n"
    "                            (default 1048576) and the table reports the spp reached\n"
    "  --ref-spp N               reference spp (default 16 x --spp; 256 with --time-budget), tree\n"
    "                            sampler\n"
    "  --reference FILE.exr      reuse a reference instead of rendering one\n"
    "  --out-dir DIR             default out/compare-<scene name>\n"
    "  --optimal-max-lights N    skip optimal above N lights (default 5000; 0 = never)\n"
    "  --timing-runs N           render each variant N times (1-15, round-robin) and report the\n"
    "                            median time: robust timings on a busy machine (default 1; equal\n"
    "                            spp only)\n";

/* Interruption (SIGINT, SIGTERM): the first asks the render to stop at the next iteration
 * barrier (CandelaOptions.stop); a second removes the output being written, if any, and exits
 * at once. A signal handler can only touch sig_atomic_t state, so this flag is the program's
 * one global. */
static volatile sig_atomic_t interrupts;

static void on_interrupt(int sig) {
    (void)sig;
    if (interrupts++ > 0) {
        io_remove_active_temp();
        _exit(130);
    }
}

static void install_interrupt_handlers(void) {
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_interrupt;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
}

/* NAME.exr -> NAME.partial.exr (NAME.partial when there is no extension). */
static void partial_name(const char *path, char out[PATH_MAX]) {
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    if (!dot || (slash && dot < slash)) snprintf(out, PATH_MAX, "%s.partial", path);
    else snprintf(out, PATH_MAX, "%.*s.partial%s", (int)(dot - path), path, dot);
}

static void die(const char *msg, const char *arg) {
    fprintf(stderr, "candela: %s%s%s\n", msg, arg ? arg : "", arg ? "" : "");
    exit(2);
}

static long parse_long(const char *flag, const char *s, long lo, long hi) {
    if (!s) die("missing value for ", flag);
    char *end;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (errno || end == s || *end != 0 || v < lo || v > hi) {
        fprintf(stderr, "candela: invalid value '%s' for %s (expected an integer in [%ld, %ld])\n", s, flag, lo, hi);
        exit(2);
    }
    return v;
}

static float parse_float(const char *flag, const char *s, float lo, float hi) {
    if (!s) die("missing value for ", flag);
    char *end;
    errno = 0;
    float v = strtof(s, &end);
    if (errno || end == s || *end != 0 || !(v >= lo && v <= hi)) {
        fprintf(stderr, "candela: invalid value '%s' for %s (expected a number in [%g, %g])\n", s, flag, lo, hi);
        exit(2);
    }
    return v;
}

/* 0 when path's folder exists and is writable (made first with create), else -1 with errno
 * saying why (access also says EROFS on a read-only file system, where root's rights do not
 * help). */
static int ensure_parent_dir(const char *path, int create) {
    char dir[PATH_MAX];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (!slash) return access(".", W_OK) == 0 ? 0 : -1;
    *slash = 0;
    if (dir[0] == 0) return 0;
    if (create) mkdir(dir, 0777);
    struct stat st;
    if (stat(dir, &st) != 0) return -1;
    if (!S_ISDIR(st.st_mode)) {
        errno = ENOTDIR;
        return -1;
    }
    return access(dir, W_OK) == 0 ? 0 : -1;
}

static void print_stats(const CandelaStats *s) {
    uint64_t rays = s->rays_camera + s->rays_bounce + s->rays_shadow;
    double render = candela_stats_render_seconds(s);
    fprintf(stderr,
            "candela: %u triangles, %u instances, %u lights, %u volumes; %d iterations, %llu paths\n"
            "  time: load %.3fs, setup %.3fs, render %.3fs (generate %.3f, sort %.3f, trace %.3f, medium %.3f,"
            " shade %.3f, shadow %.3f, film %.3f), total %.3fs\n"
            "  rays: %llu camera, %llu bounce, %llu shadow; %.2f Mrays/s\n"
            "  peak memory: %.1f MiB\n",
            s->num_triangles, s->num_instances, s->num_lights, s->num_volumes, s->iterations, (unsigned long long)s->paths,
            s->time_load, s->time_build, render, s->time_generate, s->time_sort, s->time_trace, s->time_medium, s->time_shade,
            s->time_shadow, s->time_film, s->time_total, (unsigned long long)s->rays_camera,
            (unsigned long long)s->rays_bounce, (unsigned long long)s->rays_shadow,
            render > 0 ? (double)rays / render * 1e-6 : 0.0, (double)s->peak_memory_bytes / (1024.0 * 1024.0));
    if (s->num_textures)
        fprintf(stderr, "  textures: %u (%u 8-bit, %u float), %.1f MiB decoded\n", s->num_textures,
                s->num_textures_8bit, s->num_textures - s->num_textures_8bit,
                (double)s->texture_bytes / (1024.0 * 1024.0));
    if (s->num_cachepoints)
        fprintf(stderr,
                "  cache points: %u from %u candidates, built in %.3fs, %.1f MiB; per point %.1f near lights, "
                "%.1f far entries (%.1f clusters)\n",
                s->num_cachepoints, s->cachepoint_candidates, s->time_cachepoints,
                (double)s->cachepoint_bytes / (1024.0 * 1024.0), s->cachepoint_mean_near, s->cachepoint_mean_far,
                s->cachepoint_mean_clusters);
    if (s->cachepoints_inserted)
        fprintf(stderr, "  cache points inserted between iterations: %u, in %.3fs\n", s->cachepoints_inserted,
                s->time_cachepoint_insertion);
    if (s->recorder_bound_bytes)
        fprintf(stderr,
                "  radiance recorder: %llu vertices for %llu recorded paths (%.2f per path), %llu samples, peak %u live "
                "vertices, %.1f MiB of %.1f MiB bound%s\n",
                (unsigned long long)s->recorder_vertices, (unsigned long long)s->recorder_paths,
                s->recorder_paths ? (double)s->recorder_vertices / (double)s->recorder_paths : 0.0,
                (unsigned long long)s->recorder_samples, s->recorder_peak_vertices,
                (double)s->recorder_peak_bytes / (1024.0 * 1024.0), (double)s->recorder_bound_bytes / (1024.0 * 1024.0),
                s->recorder_refused ? "; full at times (rays carried their parent on)" : "");
    if (s->guide_updates)
        fprintf(stderr, "  guiding: %d updates, %llu training samples, %u leaves, %.1f MiB, training %.3fs (%.4fs per "
                        "update)%s\n",
                s->guide_updates, (unsigned long long)s->guide_samples, s->guide_leaves,
                (double)s->guide_bytes / (1024.0 * 1024.0), s->guide_train_seconds,
                s->guide_train_seconds / s->guide_updates,
                s->guide_dropped ? "; WARNING: out of memory, some training was lost" : "");
    if (s->spp_min != s->spp_done)
        fprintf(stderr, "  samples per pixel: %d to %d, mean %.1f%s\n", s->spp_min, s->spp_done, s->spp_mean,
                s->adaptive_active_pixels ? "" : " (adaptive sampling: every pixel reached the noise threshold)");
    if (s->time_limited)
        fprintf(stderr, "  --time-limit: stopped at %d spp after %.1fs\n", s->spp_done, s->time_total);
    if (s->num_volumes)
        fprintf(stderr, "  volumes: %.1f MiB, %llu majorant collisions%s\n", (double)s->volume_bytes / (1024.0 * 1024.0),
                (unsigned long long)s->volume_collisions,
                s->volume_capped_walks ? "; WARNING: some walks hit the collision cap (an extreme medium): the image is biased there" : "");
}

/* NAME ends in ext. */
static int has_extension(const char *name, const char *ext) {
    size_t n = strlen(name), e = strlen(ext);
    return n > e && strcmp(name + n - e, ext) == 0;
}

/* candela merge -o OUT.exr [--png FILE | --no-png] SHARD.film... */
static int merge_main(int argc, char **argv) {
    const char *out = NULL, *png = NULL;
    int no_png = 0, n = 0;
    const char **files = calloc((size_t)argc, sizeof *files);
    if (!files) { fprintf(stderr, "candela: out of memory\n"); return 1; }
    for (int i = 2; i < argc; ++i) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0) { if (!v) die("missing value for ", a); out = v; ++i; }
        else if (strcmp(a, "--png") == 0) { if (!v) die("missing value for ", a); png = v; ++i; }
        else if (strcmp(a, "--no-png") == 0) no_png = 1;
        else if (a[0] == '-') { fprintf(stderr, "candela: unknown merge option '%s' (see candela --help)\n", a); free(files); return 2; }
        else files[n++] = a;
    }
    char png_buf[PATH_MAX], err[CANDELA_ERR_LEN];
    int rc = 0;
    if (!out || !has_extension(out, ".exr")) {
        fprintf(stderr, "candela: merge needs -o OUT.exr\n");
        rc = 2;
    } else if (n == 0) {
        fprintf(stderr, "candela: merge needs the shards' .film files\n");
        rc = 2;
    } else {
        if (!png && !no_png) {
            snprintf(png_buf, sizeof png_buf, "%.*s.png", (int)(strlen(out) - 4), out);
            png = png_buf;
        }
        if (no_png) png = NULL;
        /* the outputs rule: the merged image never replaces a film being merged (or its preview
         * the image) */
        CandelaRunFiles run = {0};
        for (int i = 0; i < n && rc == 0; ++i)
            if (candela_run_input(&run, files[i], "a film being merged", err) != 0) rc = 2;
        if (rc == 0 && (candela_run_output(&run, out, "the merged EXR (-o)", err) != 0 ||
                        candela_run_output(&run, png, "the merged PNG (--png)", err) != 0))
            rc = 2;
        candela_run_files_free(&run);
        IoLock locks[2];
        int nlocks = 0;
        const char *lock_these[2] = {out, png};
        for (int k = 0; k < 2 && rc == 0; ++k) {
            char ioerr[IO_ERR_LEN];
            if (!lock_these[k]) continue;
            if (io_lock_output(lock_these[k], &locks[nlocks], ioerr) != 0) {
                snprintf(err, sizeof err, "%s", ioerr);
                rc = 1;
            } else {
                ++nlocks;
            }
        }
        if (rc != 0) fprintf(stderr, "candela: %s\n", err);
        else if (candela_merge(out, png, files, n, err) != 0) {
            fprintf(stderr, "candela: %s\n", err);
            rc = 1;
        }
        while (nlocks > 0) io_unlock_output(&locks[--nlocks]);
    }
    free(files);
    return rc;
}

static int record_run_files(CandelaRunFiles *run, const CandelaOptions *o, const CandelaCompareOptions *co,
                            const CandelaBatchOptions *batch, int compare, int bench, int dump, const char *out,
                            const char *png, const char *stats_json, int save_partial, char err[CANDELA_ERR_LEN]);
static int run_command(CandelaOptions *op, CandelaCompareOptions *cop, CandelaBatchOptions *bp, int compare, int bench,
                       int dump, const char *out, const char *png, const char *stats_json, int save_partial, int argc,
                       char **argv);

int main(int argc, char **argv) {
    if (argc < 2) { fputs(USAGE, stderr); return 2; }
    if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) { fputs(USAGE, stdout); return 0; }
    if (strcmp(argv[1], "--version") == 0) { printf("candela %s\n", CANDELA_VERSION); return 0; }
    if (strcmp(argv[1], "merge") == 0) return merge_main(argc, argv);
    int bench = 0, compare = 0, dump = 0, have_at = 0;
    char dump_prefix[PATH_MAX];
    if (strcmp(argv[1], "bench") == 0) bench = 1;
    else if (strcmp(argv[1], "guide-dump") == 0) dump = 1;
    else if (strcmp(argv[1], "compare") == 0) compare = 1;
    else if (strcmp(argv[1], "render") != 0) {
        fprintf(stderr, "candela: unknown command '%s' (see candela --help)\n", argv[1]);
        return 2;
    }
    CandelaOptions o;
    candela_options_default(&o);
    const char *out = NULL, *png = NULL, *stats_json = NULL;
    int no_png = 0, save_partial = 0;
    CandelaBatchOptions batch = {0};
    CandelaCompareOptions co = {NULL, 0, NULL, NULL, 5000}; /* strategies NULL: compare.c's default list */
    char flag_err[CANDELA_ERR_LEN];
    for (int i = 2; i < argc; ++i) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        /* render options (shared with compare's variants: renderer/flags.c) first */
        int parsed = candela_parse_render_flag(&o, argc, argv, &i, flag_err);
        if (parsed < 0) { fprintf(stderr, "candela: %s\n", flag_err); return 2; }
        if (parsed > 0) continue;
        if (strcmp(a, "-o") == 0 || strcmp(a, "--output") == 0) { if (!v) die("missing value for ", a); out = v; ++i; }
        else if (strcmp(a, "--png") == 0) { if (!v) die("missing value for ", a); png = v; ++i; }
        else if (strcmp(a, "--no-png") == 0) no_png = 1;
        else if (strcmp(a, "--save-partial") == 0) save_partial = 1;
        else if (strcmp(a, "--checkpoint") == 0) { if (!v) die("missing value for ", a); o.checkpoint_path = v; ++i; }
        else if (strcmp(a, "--resume-from") == 0) { if (!v) die("missing value for ", a); o.resume_from = v; ++i; }
        else if (strcmp(a, "--sample-shard") == 0) {
            if (!v) die("missing value for ", a);
            char *slash = NULL, *end = NULL;
            errno = 0;
            long si = strtol(v, &slash, 10), sn = 0;
            int good = errno == 0 && slash != v && *slash == '/' && si >= 0;
            if (good) {
                sn = strtol(slash + 1, &end, 10);
                good = errno == 0 && end != slash + 1 && *end == 0 && sn >= 1 && sn <= 65536 && si < sn;
            }
            if (!good) {
                fprintf(stderr, "candela: invalid value '%s' for --sample-shard (expected I/N with 0 <= I < N <= 65536)\n", v);
                return 2;
            }
            o.shard_index = (uint32_t)si;
            o.shard_count = (uint32_t)sn;
            ++i;
        }
        else if (strcmp(a, "--frames") == 0) { if (!v) die("missing value for ", a); batch.frames = v; ++i; }
        else if (strcmp(a, "--fps") == 0) { batch.fps = parse_float(a, v, 1e-3f, 1e6f); ++i; }
        else if (strcmp(a, "--shard") == 0) { if (!v) die("missing value for ", a); batch.shard = v; ++i; }
        else if (strcmp(a, "--resume") == 0) batch.resume = 1;
        else if (strcmp(a, "--dry-run") == 0) batch.dry_run = 1;
        else if (strcmp(a, "--frame-stats") == 0) { if (!v) die("missing value for ", a); batch.stats_jsonl = v; ++i; }
        else if (compare && strcmp(a, "--strategies") == 0) { if (!v) die("missing value for ", a); co.strategies = v; ++i; }
        else if (compare && strcmp(a, "--variants") == 0) { if (!v) die("missing value for ", a); co.variants = v; ++i; }
        else if (compare && strcmp(a, "--time-budget") == 0) { co.time_budget = parse_float(a, v, 0.001f, 1e7f); ++i; }
        else if (compare && strcmp(a, "--ref-spp") == 0) { co.reference_spp = (int)parse_long(a, v, 1, 1 << 20); ++i; }
        else if (compare && strcmp(a, "--reference") == 0) { if (!v) die("missing value for ", a); co.reference_path = v; ++i; }
        else if (compare && strcmp(a, "--out-dir") == 0) { if (!v) die("missing value for ", a); co.out_dir = v; ++i; }
        else if (compare && strcmp(a, "--optimal-max-lights") == 0) { co.optimal_max_lights = (int)parse_long(a, v, 0, 1 << 30); ++i; }
        else if (compare && strcmp(a, "--timing-runs") == 0) { co.timing_runs = (int)parse_long(a, v, 1, 15); ++i; }
        else if (dump && strcmp(a, "--at") == 0) {
            if (!v) die("missing value for ", a);
            char *end;
            const char *c = v;
            for (int k = 0; k < 3; ++k) {
                o.guide_dump_at[k] = strtof(c, &end);
                if (end == c || !isfinite(o.guide_dump_at[k]) || (k < 2 && *end != ',') || (k == 2 && *end)) {
                    fprintf(stderr, "candela: --at wants X,Y,Z (three finite numbers), not '%s'\n", v);
                    return 2;
                }
                c = end + 1;
            }
            have_at = 1;
            ++i;
        }
        else if (strcmp(a, "--stats-json") == 0) { if (!v) die("missing value for ", a); stats_json = v; ++i; }
        else if (strcmp(a, "--quiet") == 0 || strcmp(a, "-q") == 0) o.quiet = 1;
        else if (strcmp(a, "--no-warnings") == 0) o.no_warnings = 1;
        else if (a[0] == '-') {
            fprintf(stderr, "candela: unknown option '%s' (see candela --help)\n", a);
            return 2;
        } else if (!o.scene_path) {
            o.scene_path = a;
        } else {
            fprintf(stderr, "candela: unexpected argument '%s' (one scene per run)\n", a);
            return 2;
        }
    }
    if (!o.scene_path) { fprintf(stderr, "candela: no scene given (see candela --help)\n"); return 2; }
    if (access(o.scene_path, R_OK) != 0) {
        fprintf(stderr, "candela: %s: cannot read: %s\n", o.scene_path, strerror(errno));
        return 1;
    }

    char default_out[PATH_MAX], png_buf[PATH_MAX];
    if (!out) {
        const char *base = strrchr(o.scene_path, '/');
        base = base ? base + 1 : o.scene_path;
        snprintf(default_out, sizeof default_out, "out/%s", base);
        char *dot = strrchr(default_out, '.');
        if (dot && dot > default_out + 4) *dot = 0;
        strncat(default_out, batch.frames ? ".####.exr" : ".exr", sizeof default_out - strlen(default_out) - 1);
        out = default_out;
    }
    if (batch.frames && (o.checkpoint_path || o.resume_from || o.shard_count)) {
        /* one checkpoint or shard film names one frame's render; a batch resumes with --resume */
        fprintf(stderr, "candela: --checkpoint, --resume-from and --sample-shard render one frame (not with --frames)\n");
        return 2;
    }
    if ((compare || bench || dump) && (o.checkpoint_path || o.resume_from)) {
        fprintf(stderr, "candela: --checkpoint and --resume-from are for candela render\n");
        return 2;
    }
    if (o.shard_count) {
        /* a shard's result is its film sums, never an image that could pass for the frame */
        if (compare || bench || dump || !has_extension(out, ".film")) {
            fprintf(stderr, "candela: %s: --sample-shard renders write their film sums to -o NAME.film\n", out);
            return 2;
        }
        if (o.spp < (int)o.shard_count) {
            fprintf(stderr, "candela: --sample-shard %u/%u: %d spp cannot be split %u ways\n", o.shard_index,
                    o.shard_count, o.spp, o.shard_count);
            return 2;
        }
        o.film_path = out;
        no_png = 1;
    }
    if (!png && !no_png) {
        snprintf(png_buf, sizeof png_buf, "%s", out);
        char *dot = strrchr(png_buf, '.');
        char *slash = strrchr(png_buf, '/');
        if (dot && (!slash || dot > slash)) *dot = 0;
        strncat(png_buf, ".png", sizeof png_buf - strlen(png_buf) - 1);
        png = png_buf;
    }
    if (no_png) png = NULL;
    /* the EXR is the image: writing it under a .png name, or the preview over it, loses it */
    const char *ext = strrchr(out, '.');
    if (!compare && !bench && !o.shard_count && (!ext || strcmp(ext, ".exr") != 0)) {
        fprintf(stderr, "candela: %s: the output must be an .exr file (the PNG preview goes to --png)\n", out);
        return 2;
    }
    if (o.cachepoint_dump_path && (batch.frames || compare)) {
        fprintf(stderr, "candela: --dump-cachepoints writes one render's points (not with --frames or compare)\n");
        return 2;
    }
    if (batch.frames && (compare || bench || dump)) {
        fprintf(stderr, "candela: --frames belongs to candela render\n");
        return 2;
    }
    if (batch.dry_run && (compare || bench || dump)) {
        fprintf(stderr, "candela: --dry-run checks a candela render command\n");
        return 2;
    }
    if (!batch.frames && (batch.shard || batch.resume || batch.stats_jsonl || batch.fps > 0.0)) {
        fprintf(stderr, "candela: --shard, --resume, --fps and --frame-stats need --frames\n");
        return 2;
    }
    if (batch.frames && stats_json) {
        fprintf(stderr, "candela: --stats-json writes one render's statistics; with --frames use --frame-stats FILE.jsonl\n");
        return 2;
    }
    if (dump) {
        if (!have_at) { fprintf(stderr, "candela: guide-dump needs --at X,Y,Z\n"); return 2; }
        if (o.guiding == CANDELA_GUIDING_OFF) o.guiding = CANDELA_GUIDING_MIS;
        snprintf(dump_prefix, sizeof dump_prefix, "%s", out);
        char *dot = strrchr(dump_prefix, '.');
        if (dot && strcmp(dot, ".exr") == 0) *dot = 0;
        o.guide_dump_prefix = dump_prefix;
    }
    if (candela_options_check(&o, flag_err) != 0) {
        fprintf(stderr, "candela: %s\n", flag_err);
        return 2;
    }
    if (png && strcmp(png, out) == 0) {
        fprintf(stderr, "candela: %s: --png names the EXR output itself\n", png);
        return 2;
    }
    if (!bench) {
        if (ensure_parent_dir(out, out == default_out) != 0) {
            fprintf(stderr, "candela: %s: output directory does not exist or is not writable (%s)\n", out, strerror(errno));
            return 1;
        }
        if (png && ensure_parent_dir(png, 0) != 0) {
            fprintf(stderr, "candela: %s: output directory does not exist or is not writable (%s)\n", png, strerror(errno));
            return 1;
        }
        /* checked now too: a statistics file that cannot be written fails before the render */
        if (stats_json && ensure_parent_dir(stats_json, 0) != 0) {
            fprintf(stderr, "candela: %s: output directory does not exist or is not writable (%s)\n", stats_json, strerror(errno));
            return 1;
        }
        /* an output that is a device, FIFO or directory is refused before rendering, not after */
        char resolved[IO_PATH_MAX], ioerr[IO_ERR_LEN];
        if (o.checkpoint_path && ensure_parent_dir(o.checkpoint_path, 0) != 0) {
            fprintf(stderr, "candela: %s: checkpoint directory does not exist or is not writable (%s)\n", o.checkpoint_path,
                    strerror(errno));
            return 1;
        }
        if (o.cachepoint_dump_path && ensure_parent_dir(o.cachepoint_dump_path, 0) != 0) {
            fprintf(stderr, "candela: %s: output directory does not exist or is not writable (%s)\n",
                    o.cachepoint_dump_path, strerror(errno));
            return 1;
        }
        const char *outputs[6] = {out, png, stats_json, batch.stats_jsonl, o.checkpoint_path, o.cachepoint_dump_path};
        if (batch.stats_jsonl && ensure_parent_dir(batch.stats_jsonl, 0) != 0) {
            fprintf(stderr, "candela: %s: output directory does not exist or is not writable (%s)\n", batch.stats_jsonl,
                    strerror(errno));
            return 1;
        }
        for (int k = 0; k < 6; ++k)
            if (outputs[k] && io_output_path(outputs[k], resolved, ioerr) != 0) {
                fprintf(stderr, "candela: %s\n", ioerr);
                return 1;
            }
    }

    /* one rule for every output (README "Inputs and outputs"): none may replace an input of this
     * run or another output; every name is known now, before anything is loaded or written */
    CandelaRunFiles run = {0};
    char err[CANDELA_ERR_LEN];
    if (record_run_files(&run, &o, &co, &batch, compare, bench, dump, out, png, stats_json, save_partial, err) != 0) {
        fprintf(stderr, "candela: %s\n", err);
        candela_run_files_free(&run);
        return 2;
    }
    co.run = &run;
    batch.run = &run;
    if (batch.dry_run && !batch.frames) {
        /* everything is checked: say what the render would write (a farm script reads this
         * instead of parsing numbers itself) */
        if (o.shard_count)
            printf("sample-shard %u/%u samples %llu-%llu of %d %s\n", o.shard_index, o.shard_count,
                   (unsigned long long)((uint64_t)o.spp * o.shard_index / o.shard_count),
                   (unsigned long long)((uint64_t)o.spp * (o.shard_index + 1) / o.shard_count), o.spp, out);
        else
            printf("render %s\n", out);
        candela_run_files_free(&run);
        return 0;
    }
    /* one writer per output: another candela writing the same file is refused now, not found
     * out by an EXR from one run beside a PNG from the other (a frame batch locks each frame's
     * files as it renders it, candela compare its report folder) */
    IoLock locks[5];
    int nlocks = 0, rc = 0;
    const char *lock_these[5] = {batch.frames ? NULL : out, batch.frames ? NULL : png, stats_json, o.checkpoint_path,
                                 o.cachepoint_dump_path};
    for (int k = 0; k < 5 && rc == 0 && !compare && !bench; ++k) {
        char ioerr[IO_ERR_LEN];
        if (!lock_these[k]) continue;
        if (io_lock_output(lock_these[k], &locks[nlocks], ioerr) != 0) {
            fprintf(stderr, "candela: %s\n", ioerr);
            rc = 1;
        } else {
            ++nlocks;
        }
    }
    if (rc == 0) rc = run_command(&o, &co, &batch, compare, bench, dump, out, png, stats_json, save_partial, argc, argv);
    while (nlocks > 0) io_unlock_output(&locks[--nlocks]);
    candela_run_files_free(&run);
    return rc;
}

/* The files of this run (CandelaRunFiles): the inputs named on the command line and the scene's,
 * then every output this command writes. 0 ok, -1 with the first clash in err. */
static int record_run_files(CandelaRunFiles *run, const CandelaOptions *o, const CandelaCompareOptions *co,
                            const CandelaBatchOptions *batch, int compare, int bench, int dump, const char *out,
                            const char *png, const char *stats_json, int save_partial, char err[CANDELA_ERR_LEN]) {
    /* --env is read like the scene's files: inside --confine-to when given (scene_load checks it
     * again for every render, a variant's too) */
    if (o->env_path && o->confine_dir && !io_path_inside(o->env_path, o->confine_dir)) {
        snprintf(err, CANDELA_ERR_LEN, "%.300s: --env is outside %.150s (--confine-to)", o->env_path, o->confine_dir);
        return -1;
    }
    if (candela_run_scene(run, o->scene_path, err) || candela_run_input(run, o->env_path, "the environment (--env)", err) ||
        candela_run_input(run, o->resume_from, "the checkpoint resumed (--resume-from)", err))
        return -1;
    if (compare) {
        int variants_file = co->variants && candela_variants_is_file(co->variants);
        if ((variants_file && candela_run_input(run, co->variants, "the variant list (--variants)", err)) ||
            candela_run_input(run, co->reference_path, "the reference (--reference)", err))
            return -1;
        return 0; /* the report's files: candela_compare, once it knows the variants */
    }
    if (bench) return 0; /* writes nothing */
    if (candela_run_output(run, stats_json, "the statistics (--stats-json)", err) ||
        candela_run_output(run, batch->stats_jsonl, "the frame log (--frame-stats)", err) ||
        candela_run_output_continuing(run, o->checkpoint_path, "the checkpoint (--checkpoint)", o->resume_from, err) ||
        candela_run_output(run, o->cachepoint_dump_path, "the cache point dump (--dump-cachepoints)", err))
        return -1;
    if (batch->frames) return 0; /* each frame's names: candela_batch_render */
    if (candela_run_output(run, out, o->shard_count ? "the shard's film (-o)" : "the EXR (-o)", err) ||
        candela_run_output(run, png, "the PNG preview (--png)", err))
        return -1;
    char a[PATH_MAX], b[PATH_MAX];
    if (o->aov_selection && png) {
        candela_cachepoint_png_paths(png, a, b, sizeof a);
        if (candela_run_output(run, a, "the cache point AOV's PNG", err) || candela_run_output(run, b, "the cache point AOV's PNG", err))
            return -1;
    }
    if (save_partial && !o->shard_count) {
        partial_name(out, a);
        if (candela_run_output(run, a, "the partial EXR (--save-partial)", err)) return -1;
        if (png) {
            partial_name(png, b);
            if (candela_run_output(run, b, "the partial PNG (--save-partial)", err)) return -1;
        }
    }
    if (dump) {
        static const char *const suffix[] = {".guide.exr", ".guide.png", ".hist.exr", ".hist.png", ".leaves.ply"};
        for (int k = 0; k < 5; ++k) {
            snprintf(a, sizeof a, "%s%s", o->guide_dump_prefix, suffix[k]);
            if (candela_run_output(run, a, "a guide-dump file", err)) return -1;
        }
    }
    return 0;
}

/* Runs the command once its files are known (main's last part). */
static int run_command(CandelaOptions *op, CandelaCompareOptions *cop, CandelaBatchOptions *bp, int compare, int bench,
                       int dump, const char *out, const char *png, const char *stats_json, int save_partial, int argc,
                       char **argv) {
    CandelaOptions o = *op;
    CandelaCompareOptions co = *cop;
    CandelaBatchOptions batch = *bp;
    (void)dump;
    char err[CANDELA_ERR_LEN];
    if (compare) {
        char dir[PATH_MAX];
        if (!co.out_dir) {
            const char *base = strrchr(o.scene_path, '/');
            base = base ? base + 1 : o.scene_path;
            mkdir("out", 0777);
            snprintf(dir, sizeof dir, "out/compare-%s", base);
            char *dot = strrchr(dir, '.');
            if (dot && dot > dir + 12) *dot = 0;
            co.out_dir = dir;
        }
        /* equal time: --spp is only a cap, by default the largest (the time budget decides) */
        int spp_given = 0;
        for (int i = 2; i < argc; ++i) spp_given |= strcmp(argv[i], "--spp") == 0;
        if (co.time_budget > 0 && !spp_given) o.spp = 1 << 20;
        if (candela_compare(&o, &co, err) != 0) {
            fprintf(stderr, "candela: %s\n", err);
            return 1;
        }
        return 0;
    }
    CandelaImage image;
    CandelaStats stats;
    CandelaRayLog log = {0};
    install_interrupt_handlers();
    o.stop = &interrupts;
    if (batch.frames) {
        batch.exr_pattern = out;
        batch.png_pattern = png;
        batch.save_partial = save_partial;
        int interrupted = 0;
        int failed = candela_batch_render(&o, &batch, &interrupted, err);
        if (failed < 0) {
            fprintf(stderr, "%s%s\n", strncmp(err, "candela: ", 9) == 0 ? "" : "candela: ", err);
            return 101;
        }
        if (interrupted) return 130;
        return failed > 100 ? 100 : failed;
    }
    if (candela_render(&o, &image, &stats, bench ? &log : NULL, err) != 0) {
        fprintf(stderr, "candela: %s\n", err);
        return 1;
    }
    int rc = 0;
    if (bench) {
        double replay = 0.0;
        if (log.failed) {
            fprintf(stderr, "candela: %s: out of memory recording the rays for the replay (try a smaller --res or --spp)\n",
                    o.scene_path);
            rc = 1;
        } else if (candela_replay_rays(&o, &log, o.threads, &replay, err) != 0) {
            fprintf(stderr, "candela: %s\n", err);
            rc = 1;
        } else {
            double render = candela_stats_render_seconds(&stats);
            double rr = (double)log.count / render, br = (double)log.count / replay;
            printf("scene            %s\n", o.scene_path);
            printf("rays             %zu (%llu camera, %llu bounce, %llu shadow)\n", log.count,
                   (unsigned long long)stats.rays_camera, (unsigned long long)stats.rays_bounce,
                   (unsigned long long)stats.rays_shadow);
            printf("renderer         %.3f s  %.3f Mrays/s (generate+sort+trace+shade+shadow+film)\n", render, rr * 1e-6);
            printf("bare embree      %.3f s  %.3f Mrays/s (same rays, rtcIntersect1/rtcOccluded1)\n", replay, br * 1e-6);
            printf("ratio            %.3f\n", rr / br);
            printf("stage seconds    sort %.3f trace %.3f shade %.3f shadow %.3f generate %.3f film %.3f\n",
                   stats.time_sort, stats.time_trace, stats.time_shade, stats.time_shadow, stats.time_generate,
                   stats.time_film);
        }
        candela_ray_log_free(&log);
    } else {
        char out_partial[PATH_MAX], png_partial[PATH_MAX];
        if (stats.interrupted && o.checkpoint_path && !stats.checkpoint_failed)
            fprintf(stderr, "candela: checkpoint written to %s (continue with --resume-from %s)\n", o.checkpoint_path,
                    o.checkpoint_path);
        if (!stats.interrupted && o.shard_count) {
            if (!o.quiet) fprintf(stderr, "candela: wrote %s (shard %u/%u)\n", out, o.shard_index, o.shard_count);
        } else if (stats.interrupted) {
            /* never a file that looks complete: the image so far only under a .partial name */
            if (o.shard_count) {
                /* a shard's spp are its share of --spp; its film is only ever the complete one
                 * (a partial film would merge as if whole), so --save-partial cannot apply */
                long long b = (long long)o.spp * o.shard_index / o.shard_count;
                long long e = (long long)o.spp * (o.shard_index + 1) / o.shard_count;
                fprintf(stderr,
                        "candela: interrupted after %d of the %lld spp of sample shard %u/%u; nothing written (a shard's film is "
                        "written only when complete, --save-partial does not apply to it%s)\n",
                        stats.spp_done, e - b, o.shard_index, o.shard_count,
                        o.checkpoint_path ? "; --resume-from its checkpoint continues it" : "; --checkpoint would let it resume");
                candela_image_free(&image);
                return 130;
            }
            if (!save_partial) {
                fprintf(stderr, "candela: interrupted after %d of %d spp; nothing written (--save-partial keeps the image so far)\n",
                        stats.spp_done, o.spp);
                candela_image_free(&image);
                return 130;
            }
            partial_name(out, out_partial);
            out = out_partial;
            if (png) {
                partial_name(png, png_partial);
                png = png_partial;
            }
        }
        if (!stats.interrupted && o.shard_count) {
            /* the film file was written by the render */
        } else if (candela_write_outputs(&image, out, png, err) != 0) {
            fprintf(stderr, "candela: %s\n", err);
            rc = 1;
        } else if (stats.interrupted) {
            fprintf(stderr, "candela: interrupted after %d of %d spp; wrote %s%s%s\n", stats.spp_done, o.spp, out,
                    png ? " and " : "", png ? png : "");
            rc = 130;
        } else if (!o.quiet) {
            fprintf(stderr, "candela: wrote %s%s%s\n", out, png ? " and " : "", png ? png : "");
        }
    }
    if (rc == 0 && !o.quiet) print_stats(&stats);
    if ((rc == 0 || rc == 130) && stats_json && candela_write_stats_json(stats_json, &o, &stats, err) != 0) {
        fprintf(stderr, "candela: %s\n", err);
        rc = 1;
    }
    candela_image_free(&image);
    return rc;
}
