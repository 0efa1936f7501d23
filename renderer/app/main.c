/* renderer/app/main.c: the `candela` command line. */
#include <errno.h>
#include <signal.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "candela.h"
#include "candela_version.h"
#include "io.h"
#include "options_table.h"

static const char *USAGE =
    "usage: candela render SCENE.gltf|SCENE.glb [options]\n"
    "       candela bench SCENE [options]   render, then replay the same rays through bare Embree\n"
    "       candela guide-dump SCENE --at X,Y,Z [options]   render with guiding (mis unless --guiding\n"
    "                            ris), then write the learned directional pdf at the point\n"
    "                            (OUT.guide.exr/.png on the octahedral square of directions), the\n"
    "                            final iteration's training directions in its leaf (OUT.hist.*)\n"
    "                            and the spatial tree's leaves (OUT.leaves.ply), OUT = -o without .exr\n"
    "       candela compare SCENE [options] render variants at equal spp (or time) vs a reference\n"
    "                            and write a report folder (tables, images, crops, plots, HTML)\n"
    "       candela merge -o OUT.exr [--png FILE | --no-png] SHARD.film...   the films of the\n"
    "                            --sample-shard renders of one frame into its image (sums of L,\n"
    "                            L^2 and counts added: per-pixel means and variances of all samples)\n"
    "       candela --help | --version\n"
    "       candela help FLAG            what FLAG does (its long help)\n"
    "       candela COMMAND --help       COMMAND's flags, one line each\n";

/* candela --help: the synopsis, then every flag of the table (renderer/app/options_table.c) one
 * line each (scripts grep it: scenes/farm/candela_submit.sh looks for "--resume "). */
static void print_usage(FILE *f) {
    fputs(USAGE, f);
    fputs("\noptions (candela COMMAND --help lists a command's own):\n", f);
    candela_print_flags(f, 0);
}

/* Interruption (SIGINT, SIGTERM): the first asks the render to stop at the next iteration
 * barrier (CandelaOptions.stop); a second removes the output being written, if any, and exits
 * at once. A signal handler can only touch sig_atomic_t state, so this flag is the program's
 * one global. */
static volatile sig_atomic_t interrupts;

static void on_interrupt(int sig) {
    (void)sig;
    if (interrupts++ > 0) {
        io_remove_active_temps();
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

/* 0 when path's folder exists and is writable, else -1 with errno saying why (access also says
 * EROFS on a read-only file system, where root's rights do not help). A missing folder is made
 * first, with its missing parents (mkdir -p: `-o newdir/shot.####.exr` or `--stats-json
 * logs/today/s.json` should not fail after the user named where the file goes). */
static int ensure_parent_dir(const char *path) {
    char dir[PATH_MAX];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (!slash) return access(".", W_OK) == 0 ? 0 : -1;
    *slash = 0;
    if (dir[0] == 0) return 0;
    /* each level, ignoring failures: the stat below says why the folder is not there */
    for (char *p = dir + 1; *p; ++p)
        if (*p == '/') {
            *p = 0;
            mkdir(dir, 0777);
            *p = '/';
        }
    mkdir(dir, 0777);
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
            "  time (wall): load %.3fs, setup %.3fs, render %.3fs (generate %.3f, sort %.3f, trace %.3f, medium %.3f,"
            " shade %.3f, shadow %.3f, learn %.3f, film %.3f, barrier %.3f), other %.3fs, total %.3fs\n"
            "  rays: %llu camera, %llu bounce, %llu shadow; %.2f Mrays/s\n"
            "  peak memory: %.1f MiB\n",
            s->num_triangles, s->num_instances, s->num_lights, s->num_volumes, s->iterations, (unsigned long long)s->paths,
            s->time_load, s->time_build, render, s->time_generate, s->time_sort, s->time_trace, s->time_medium, s->time_shade,
            s->time_shadow, s->time_learn, s->time_film, s->time_barrier, candela_stats_other_seconds(s), s->time_total, (unsigned long long)s->rays_camera,
            (unsigned long long)s->rays_bounce, (unsigned long long)s->rays_shadow,
            render > 0 ? (double)rays / render * 1e-6 : 0.0, (double)s->peak_memory_bytes / (1024.0 * 1024.0));
    /* the phases from file to first image: wall time and the peak memory by each one's end
     * (candela.h, CANDELA_PHASE_*) */
    fprintf(stderr, "  phases (wall, peak memory so far):");
    for (int k = 0; k < CANDELA_PHASES; ++k)
        fprintf(stderr, "%s %s %.3fs %.0f MiB", k ? "," : "", candela_phase_name(k), s->phase_seconds[k],
                (double)s->phase_peak_bytes[k] / (1024.0 * 1024.0));
    fputc('\n', stderr);
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
    if (s->guide_updates && s->guide_share_per_leaf) {
        fprintf(stderr, "  guiding's BSDF share, leaves at each:");
        for (int j = 0; j < CANDELA_GUIDE_SHARES; ++j)
            if (s->guide_share_leaves[j]) fprintf(stderr, " %g: %u", (double)s->guide_share_value[j], s->guide_share_leaves[j]);
        fprintf(stderr, "\n");
    }
    if (s->spp_dropped)
        fprintf(stderr, "  samples per pixel: %d in the image of %d rendered (the first %d, unguided, trained the guide)\n",
                s->spp_done - s->spp_dropped, s->spp_done, s->spp_dropped);
    else if (s->spp_min != s->spp_done)
        fprintf(stderr, "  samples per pixel: %d to %d, mean %.1f%s\n", s->spp_min, s->spp_done, s->spp_mean,
                s->adaptive_active_pixels ? "" : " (adaptive sampling: every pixel reached its target)");
    if (s->time_limited)
        fprintf(stderr, "  --time-limit: stopped at %d spp after %.1fs\n", s->spp_done, s->time_total);
    if (s->num_volumes)
        fprintf(stderr, "  volumes: %.1f MiB, %llu majorant collisions%s\n", (double)s->volume_bytes / (1024.0 * 1024.0),
                (unsigned long long)s->volume_collisions,
                s->volume_capped_walks ? "; WARNING: some walks hit the collision cap (an extreme medium): the image is biased there" : "");
}

/* The --version line, which the EXR headers carry as "software". */
static void software_line(char *buf, size_t size) {
    snprintf(buf, size, "candela %s (git %s)", CANDELA_VERSION, CANDELA_GIT_REVISION);
}

/* NAME ends in ext, in any case. */
static int has_extension(const char *name, const char *ext) {
    size_t n = strlen(name), e = strlen(ext);
    return n > e && strcasecmp(name + n - e, ext) == 0; /* any case: x.EXR is an EXR */
}

/* candela merge -o OUT.exr [--png FILE | --no-png] SHARD.film... */
static int merge_main(int argc, char **argv) {
    CandelaCommandLine cl;
    memset(&cl, 0, sizeof cl);
    int n = 0;
    const char **files = calloc((size_t)argc, sizeof *files);
    if (!files) { fprintf(stderr, "candela: out of memory\n"); return 1; }
    for (int i = 2; i < argc; ++i) {
        const char *a = argv[i];
        char flag_err[CANDELA_ERR_LEN];
        int parsed = candela_parse_flag(&cl, CANDELA_CMD_MERGE, argc, argv, &i, NULL, flag_err);
        if (parsed < 0) { fprintf(stderr, "candela: %s\n", flag_err); free(files); return 2; }
        if (cl.help) {
            printf("usage: candela merge -o OUT.exr [--png FILE | --no-png] SHARD.film...\n");
            candela_print_flags(stdout, CANDELA_CMD_MERGE);
            free(files);
            return 0;
        }
        if (parsed > 0) continue;
        if (a[0] == '-') {
            candela_unknown_flag_message(a, CANDELA_CMD_MERGE, "merge option", flag_err);
            fprintf(stderr, "candela: %s\n", flag_err);
            free(files);
            return 2;
        }
        files[n++] = a;
    }
    const char *out = cl.out, *png = cl.png;
    int no_png = cl.no_png;
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
        const char *dirs_of[2] = {out, png};
        for (int k = 0; k < 2 && rc == 0; ++k)
            if (dirs_of[k] && ensure_parent_dir(dirs_of[k]) != 0) {
                snprintf(err, sizeof err, "%.400s: output directory cannot be made or is not writable (%s)", dirs_of[k],
                         strerror(errno));
                rc = 1;
            }
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
        else {
            char software[256];
            software_line(software, sizeof software);
            CandelaProvenance prov;
            if (candela_provenance_begin(&prov, software, argc, argv) != 0) {
                fprintf(stderr, "candela: out of memory\n");
                rc = 1;
            } else if (candela_merge_provenance(out, png, files, n, &prov, err) != 0) {
                fprintf(stderr, "candela: %s\n", err);
                rc = 1;
            }
            candela_provenance_free(&prov);
        }
        while (nlocks > 0) io_unlock_output(&locks[--nlocks]);
    }
    free(files);
    return rc;
}

/* path made absolute against the working folder (not resolved: it may not exist yet) */
static void absolute_path(const char *path, char out[PATH_MAX]) {
    char cwd[PATH_MAX];
    if (path[0] == '/' || !getcwd(cwd, sizeof cwd)) snprintf(out, PATH_MAX, "%s", path);
    else if ((size_t)snprintf(out, PATH_MAX, "%.*s/%s", (int)(PATH_MAX / 2), cwd, path) >= PATH_MAX) out[PATH_MAX - 1] = 0;
}

/* A checkpoint's identity and record, kept for the whole run: the options --resume-from takes
 * from it point into them. */
static CandelaCheckpointInfo resume_info;
static char resume_identity[CANDELA_IDENTITY_LEN];
static char resume_record[sizeof resume_info.record];
static char record_text[3 * 3 * PATH_MAX + 1024]; /* 3 quoted paths, the keys and the quoted --version line */

/* --resume-from FILE (issue 27): the render's options are the checkpoint's. Every image option
 * given as well must agree with it (all disagreements in one message, exit 2); the scene, -o and
 * the PNG default to what the checkpoint recorded; other options (threads, outputs, --quiet,
 * --time-limit) are this run's. Without --checkpoint the render goes on checkpointing into FILE.
 * Returns 0 (cl updated), 2 on a disagreement or an unusable file; a file that cannot be read is
 * left to the render's own check when the scene is given (its message then), else refused. */
static int resume_options(CandelaCommandLine *cl, const CandelaFlag *const *given, int ngiven) {
    const char *path = cl->o.resume_from;
    char err[CANDELA_ERR_LEN];
    if (candela_checkpoint_info(path, &resume_info, err) != 0) {
        if (cl->o.scene_path) return 0;
        fprintf(stderr, "candela: %s\n", err);
        return 2;
    }
    if (resume_info.kind != 1) {
        fprintf(stderr, "candela: %s: a finished shard film, not a checkpoint (merge it with candela merge)\n", path);
        return 2;
    }
    /* the checkpoint's options alone (defaults + its identity) */
    static char text[CANDELA_IDENTITY_LEN];
    snprintf(text, sizeof text, "%s", resume_info.identity);
    CandelaOptions ck;
    candela_options_default(&ck);
    if (candela_options_from_identity(&ck, text, err) != 0) {
        fprintf(stderr, "candela: %s: damaged identity: %s\n", path, err);
        return 2;
    }
    char list[CANDELA_ERR_LEN] = "";
    size_t n = 0;
    int disagree = 0;
    for (int k = 0; k < ngiven; ++k) {
        const CandelaFlag *f = given[k];
        int repeat = 0;
        for (int j = 0; j < k; ++j) repeat |= given[j] == f;
        if (!f->image || repeat) continue;
        char here[1024], there[1024], dh[512], dt[512];
        candela_flag_identity_value(f, &cl->o, here, sizeof here);
        candela_flag_identity_value(f, &ck, there, sizeof there);
        if (strcmp(here, there) == 0) continue;
        candela_identity_display(here, dh, sizeof dh);
        candela_identity_display(there, dt, sizeof dt);
        if (n < sizeof list) n += (size_t)snprintf(list + n, sizeof list - n, "%s%s %s (checkpoint %s)", disagree ? ", " : "",
                                                   f->name, dh, dt);
        ++disagree;
    }
    if (cl->o.scene_path) {
        uint64_t h;
        char hex[32], want[32];
        if (candela_scene_hash(cl->o.scene_path, &h, err) != 0) {
            fprintf(stderr, "candela: %s\n", err);
            return 1;
        }
        snprintf(hex, sizeof hex, "%016llx", (unsigned long long)h);
        candela_identity_value(resume_info.identity, "scene", want, sizeof want);
        if (strcmp(hex, want) != 0) {
            if (n < sizeof list)
                n += (size_t)snprintf(list + n, sizeof list - n, "%s%s (the scene file's content differs)", disagree ? ", " : "",
                                      cl->o.scene_path);
            ++disagree;
        }
    }
    if (disagree) {
        if (n >= sizeof list) memcpy(list + sizeof list - 4, "...", 4);
        fprintf(stderr, "candela: %s: flags disagree with the checkpoint: %s\n", path, list);
        return 2;
    }
    /* the checkpoint's image options over the command line's (they agree where given) */
    snprintf(resume_identity, sizeof resume_identity, "%s", resume_info.identity);
    if (candela_options_from_identity(&cl->o, resume_identity, err) != 0) {
        fprintf(stderr, "candela: %s: damaged identity: %s\n", path, err);
        return 2;
    }
    char mis[64];
    if (candela_identity_value(resume_info.identity, "max-iteration-spp", mis, sizeof mis) == 0)
        cl->o.max_iteration_spp = atoi(mis);
    /* the record: scene="..." output="..." png="..."|- */
    snprintf(resume_record, sizeof resume_record, "%s", resume_info.record);
    const int outputs_given = cl->out || cl->png || cl->no_png;
    for (char *c = resume_record; *c;) {
        size_t len = strcspn(c, " ");
        char *next = c[len] ? c + len + 1 : c + len;
        c[len] = 0;
        char *eq = strchr(c, '=');
        if (eq) {
            *eq = 0;
            char *v = strcmp(eq + 1, "-") == 0 ? NULL : candela_identity_unquote(eq + 1);
            if (strcmp(c, "scene") == 0 && v && !cl->o.scene_path) cl->o.scene_path = v;
            else if (strcmp(c, "output") == 0 && v && !cl->out) cl->out = v;
            else if (strcmp(c, "png") == 0 && !outputs_given) {
                if (v) cl->png = v;
                else cl->no_png = 1;
            } else if (strcmp(c, "software") == 0 && v) {
                char here[256];
                software_line(here, sizeof here);
                if (strcmp(v, here) != 0)
                    fprintf(stderr, "candela: warning: %s was written by %s; this is %s (the options agree, the "
                            "sampling code may not)\n", path, v, here);
            }
        }
        c = next;
    }
    if (!cl->o.scene_path) {
        fprintf(stderr, "candela: %s: the checkpoint records no scene (give it: candela render SCENE --resume-from %s)\n",
                path, path);
        return 2;
    }
    if (!cl->o.shard_count && resume_info.shard_count > 1) { /* a sample shard's checkpoint: that shard */
        cl->o.shard_index = resume_info.shard_index;
        cl->o.shard_count = resume_info.shard_count;
    }
    if (!cl->o.checkpoint_path) cl->o.checkpoint_path = path; /* go on checkpointing into it */
    return 0;
}

static int record_run_files(CandelaRunFiles *run, const CandelaOptions *o, const CandelaCompareOptions *co,
                            const CandelaBatchOptions *batch, int compare, int bench, int dump, const char *out,
                            const char *png, const char *stats_json, int save_partial, char err[CANDELA_ERR_LEN]);
static int run_command(CandelaOptions *op, CandelaCompareOptions *cop, CandelaBatchOptions *bp, int compare, int bench,
                       int dump, const char *out, const char *png, const char *stats_json, int save_partial,
                       int spp_given, int argc, char **argv);

int main(int argc, char **argv) {
    if (argc < 2) { print_usage(stderr); return 2; }
    if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) { print_usage(stdout); return 0; }
    if (strcmp(argv[1], "help") == 0) {
        if (argc < 3) { print_usage(stdout); return 0; }
        if (strcmp(argv[2], "--list-flags") == 0) { /* hidden: every flag's name, for tests/test_readme.sh */
            candela_print_flag_names(stdout);
            printf("--version\n"); /* candela --version: the one flag outside the table */
            return 0;
        }
        return candela_print_flag_help(stdout, argv[2]);
    }
    if (strcmp(argv[1], "--version") == 0) {
        char software[256];
        software_line(software, sizeof software);
        printf("%s\n", software);
        return 0;
    }
    if (strcmp(argv[1], "merge") == 0) return merge_main(argc, argv);
    int bench = 0, compare = 0, dump = 0;
    char dump_prefix[PATH_MAX];
    if (strcmp(argv[1], "bench") == 0) bench = 1;
    else if (strcmp(argv[1], "guide-dump") == 0) dump = 1;
    else if (strcmp(argv[1], "compare") == 0) compare = 1;
    else if (strcmp(argv[1], "render") != 0) {
        fprintf(stderr, "candela: unknown command '%s' (see candela --help)\n", argv[1]);
        return 2;
    }
    unsigned cmd = bench ? CANDELA_CMD_BENCH : dump ? CANDELA_CMD_GUIDE_DUMP : compare ? CANDELA_CMD_COMPARE : CANDELA_CMD_RENDER;
    CandelaCommandLine cl;
    memset(&cl, 0, sizeof cl);
    candela_options_default(&cl.o);
    cl.co.optimal_max_lights = 5000; /* strategies NULL: compare.c's default list */
    char flag_err[CANDELA_ERR_LEN];
    const CandelaFlag **given = calloc((size_t)argc, sizeof *given); /* the rows given, in order */
    int ngiven = 0;
    if (!given) { fprintf(stderr, "candela: out of memory\n"); return 1; }
    for (int i = 2; i < argc; ++i) {
        const char *a = argv[i];
        /* every flag is a row of renderer/app/options_table.c (render options shared with compare's
         * variants) */
        const CandelaFlag *row = NULL;
        int parsed = candela_parse_flag(&cl, cmd, argc, argv, &i, &row, flag_err);
        if (parsed < 0) { fprintf(stderr, "candela: %s\n", flag_err); free(given); return 2; }
        if (cl.help) {
            printf("usage: candela %s SCENE.gltf|SCENE.glb [options]\n", argv[1]);
            candela_print_flags(stdout, cmd);
            free(given);
            return 0;
        }
        if (parsed > 0) {
            if (strcmp(row->name, "--spp") == 0) cl.spp_given = 1;
            given[ngiven++] = row;
            continue;
        }
        if (a[0] == '-') {
            candela_unknown_flag_message(a, cmd, "option", flag_err);
            fprintf(stderr, "candela: %s\n", flag_err);
            free(given);
            return 2;
        } else if (!cl.o.scene_path) {
            cl.o.scene_path = a;
        } else {
            fprintf(stderr, "candela: unexpected argument '%s' (one scene per run)\n", a);
            free(given);
            return 2;
        }
    }
    if (cl.o.resume_from && cmd == CANDELA_CMD_RENDER && !cl.batch.frames) {
        int rrc = resume_options(&cl, given, ngiven);
        if (rrc != 0) { free(given); return rrc; }
    }
    free(given);
    CandelaOptions o = cl.o;
    CandelaCompareOptions co = cl.co;
    CandelaBatchOptions batch = cl.batch;
    const char *out = cl.out, *png = cl.png, *stats_json = cl.stats_json;
    int no_png = cl.no_png, save_partial = cl.save_partial, have_at = cl.have_at;
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
    if (!compare && !bench && !o.shard_count && (!ext || strcasecmp(ext, ".exr") != 0)) {
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
    if (compare && stats_json) { /* it used to be accepted and ignored */
        fprintf(stderr, "candela: --stats-json writes one render's statistics; candela compare writes its numbers into its "
                        "report (--out-dir)\n");
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
        if (dot && strcasecmp(dot, ".exr") == 0) *dot = 0;
        o.guide_dump_prefix = dump_prefix;
    }
    if (o.checkpoint_path && !compare && !bench && !dump) {
        /* what --resume-from FILE alone needs beside the identity: the scene and the outputs */
        char abs_path[PATH_MAX], q[3 * PATH_MAX + 3];
        size_t n = 0;
        const char *keys[3] = {"scene", "output", "png"}, *vals[3] = {o.scene_path, out, png};
        for (int k = 0; k < 3; ++k) {
            if (vals[k]) absolute_path(vals[k], abs_path);
            candela_identity_quote(vals[k] ? abs_path : NULL, q, sizeof q);
            n += (size_t)snprintf(record_text + n, sizeof record_text - n, "%s%s=%s", k ? " " : "", keys[k], q);
            if (n >= sizeof record_text) n = sizeof record_text - 1; /* too long: checkpoint_write refuses it */
        }
        /* and the build that wrote it (provenance; a resume by another build says so) */
        char software[256];
        software_line(software, sizeof software);
        candela_identity_quote(software, q, sizeof q);
        n += (size_t)snprintf(record_text + n, sizeof record_text - n, " software=%s", q);
        o.checkpoint_record = record_text;
    }
    if (candela_options_check(&o, flag_err) != 0) {
        fprintf(stderr, "candela: %s\n", flag_err);
        return 2;
    }
    if (png && strcmp(png, out) == 0) {
        fprintf(stderr, "candela: %s: --png names the EXR output itself\n", png);
        return 2;
    }
    /* bench writes no image (its -o and --png are ignored), but its statistics and PLY like render */
    if (!bench && ensure_parent_dir(out) != 0) {
        fprintf(stderr, "candela: %s: output directory cannot be made or is not writable (%s)\n", out, strerror(errno));
        return 1;
    }
    if (!bench && png && ensure_parent_dir(png) != 0) {
        fprintf(stderr, "candela: %s: output directory cannot be made or is not writable (%s)\n", png, strerror(errno));
        return 1;
    }
    {
        /* checked now too: a statistics file that cannot be written fails before the render */
        if (stats_json && ensure_parent_dir(stats_json) != 0) {
            fprintf(stderr, "candela: %s: output directory cannot be made or is not writable (%s)\n", stats_json, strerror(errno));
            return 1;
        }
        /* an output that is a device, FIFO or directory is refused before rendering, not after */
        char resolved[IO_PATH_MAX], ioerr[IO_ERR_LEN];
        if (o.checkpoint_path && ensure_parent_dir(o.checkpoint_path) != 0) {
            fprintf(stderr, "candela: %s: checkpoint directory cannot be made or is not writable (%s)\n", o.checkpoint_path,
                    strerror(errno));
            return 1;
        }
        if (o.cachepoint_dump_path && ensure_parent_dir(o.cachepoint_dump_path) != 0) {
            fprintf(stderr, "candela: %s: output directory cannot be made or is not writable (%s)\n",
                    o.cachepoint_dump_path, strerror(errno));
            return 1;
        }
        const char *outputs[6] = {bench ? NULL : out, bench ? NULL : png, stats_json, batch.stats_jsonl, o.checkpoint_path,
                                  o.cachepoint_dump_path};
        if (batch.stats_jsonl && ensure_parent_dir(batch.stats_jsonl) != 0) {
            fprintf(stderr, "candela: %s: output directory cannot be made or is not writable (%s)\n", batch.stats_jsonl,
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
    const char *lock_these[5] = {batch.frames || bench ? NULL : out, batch.frames || bench ? NULL : png, stats_json,
                                 o.checkpoint_path, o.cachepoint_dump_path};
    for (int k = 0; k < 5 && rc == 0 && !compare; ++k) {
        char ioerr[IO_ERR_LEN];
        if (!lock_these[k]) continue;
        if (io_lock_output(lock_these[k], &locks[nlocks], ioerr) != 0) {
            fprintf(stderr, "candela: %s\n", ioerr);
            rc = 1;
        } else {
            ++nlocks;
        }
    }
    if (rc == 0) rc = run_command(&o, &co, &batch, compare, bench, dump, out, png, stats_json, save_partial, cl.spp_given, argc, argv);
    while (nlocks > 0) io_unlock_output(&locks[--nlocks]);
    candela_run_files_free(&run);
    return rc;
}

/* The files of this run (CandelaRunFiles): the inputs named on the command line and the scene's,
 * then every output this command writes. 0 ok, -1 with the first clash in err. */
static int record_run_files(CandelaRunFiles *run, const CandelaOptions *o, const CandelaCompareOptions *co,
                            const CandelaBatchOptions *batch, int compare, int bench, int dump, const char *out,
                            const char *png, const char *stats_json, int save_partial, char err[CANDELA_ERR_LEN]) {
    /* --confine-to names a folder (a file there confined everything to nothing: "SCENE is
     * outside FILE"); an empty name never gets this far (options_table.c) */
    struct stat cst;
    int confine_found = o->confine_dir && stat(o->confine_dir, &cst) == 0;
    if (o->confine_dir && (!confine_found || !S_ISDIR(cst.st_mode))) {
        snprintf(err, CANDELA_ERR_LEN, "%.400s: --confine-to needs a folder (%s)", o->confine_dir,
                 confine_found ? "this is not one" : strerror(errno));
        return -1;
    }
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
    if (candela_run_output(run, stats_json, "the statistics (--stats-json)", err) ||
        candela_run_output(run, batch->stats_jsonl, "the frame log (--frame-stats)", err) ||
        candela_run_output_continuing(run, o->checkpoint_path, "the checkpoint (--checkpoint)", o->resume_from, err) ||
        candela_run_output(run, o->cachepoint_dump_path, "the cache point dump (--dump-cachepoints)", err))
        return -1;
    if (bench) return 0; /* no image: the statistics and the PLY above are all it writes */
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
                       int dump, const char *out, const char *png, const char *stats_json, int save_partial,
                       int spp_given, int argc, char **argv) {
    CandelaOptions o = *op;
    CandelaCompareOptions co = *cop;
    CandelaBatchOptions batch = *bp;
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
        char build[256];
        software_line(build, sizeof build);
        co.build = build; /* the cached reference's key */
        /* equal time: --spp is only a cap, by default the largest (the time budget decides) */
        if (co.time_budget > 0 && !spp_given) o.spp = 1 << 20;
        /* each report image's provenance (README "Output"): the scene is hashed once rendered */
        CandelaProvenance cprov;
        if (candela_provenance_begin(&cprov, build, argc, argv) != 0) {
            fprintf(stderr, "candela: out of memory\n");
            return 1;
        }
        co.provenance = &cprov;
        int crc = candela_compare(&o, &co, err);
        candela_provenance_free(&cprov);
        if (crc != 0) {
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
    /* how the images are made (the EXR headers, --stats-json): README "Output" */
    char software[256];
    software_line(software, sizeof software);
    CandelaProvenance prov;
    if (candela_provenance_begin(&prov, software, argc, argv) != 0) {
        fprintf(stderr, "candela: out of memory\n");
        return 1;
    }
    if (dump) o.guide_dump_provenance = &prov; /* OUT.guide/hist.exr/png (renderer/integrator/guide.c) */
    if (batch.frames) {
        if (candela_provenance_scene(&prov, o.scene_path, err) != 0) {
            fprintf(stderr, "candela: %s\n", err);
            candela_provenance_free(&prov);
            return 101;
        }
        batch.exr_pattern = out;
        batch.png_pattern = png;
        batch.save_partial = save_partial;
        batch.provenance = &prov;
        int interrupted = 0;
        int failed = candela_batch_render(&o, &batch, &interrupted, err);
        candela_provenance_free(&prov);
        if (failed < 0) {
            fprintf(stderr, "%s%s\n", strncmp(err, "candela: ", 9) == 0 ? "" : "candela: ", err);
            return 101;
        }
        if (interrupted) return 130;
        return failed > 100 ? 100 : failed;
    }
    if (candela_render(&o, &image, &stats, bench ? &log : NULL, err) != 0) {
        fprintf(stderr, "candela: %s\n", err);
        candela_provenance_free(&prov);
        return 1;
    }
    /* the scene hashed once the render read it (its errors are the loader's) */
    if (!bench && candela_provenance_scene(&prov, o.scene_path, err) != 0) {
        fprintf(stderr, "candela: %s\n", err);
        candela_image_free(&image);
        candela_provenance_free(&prov);
        return 1;
    }
    if (candela_provenance_render(&prov, &o, &stats) != 0 ||
        candela_provenance_identity(&prov, &o, image.full_width, image.full_height) != 0) {
        fprintf(stderr, "candela: out of memory\n");
        candela_image_free(&image);
        candela_provenance_free(&prov);
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
            printf("renderer         %.3f s  %.3f Mrays/s (the render's stages, wall time)\n", render, rr * 1e-6);
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
                candela_provenance_free(&prov);
                return 130;
            }
            if (!save_partial) {
                fprintf(stderr, "candela: interrupted after %d of %d spp; nothing written (--save-partial keeps the image so far)\n",
                        stats.spp_done, o.spp);
                candela_image_free(&image);
                candela_provenance_free(&prov);
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
        } else if (candela_write_outputs_provenance(&image, out, png, &prov, err) != 0) {
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
    if ((rc == 0 || rc == 130) && stats_json && candela_write_stats_json(stats_json, &o, &stats, &prov, err) != 0) {
        fprintf(stderr, "candela: %s\n", err);
        rc = 1;
    }
    candela_image_free(&image);
    candela_provenance_free(&prov);
    return rc;
}
