/* renderer/app/runfiles.c: the files of one run and the rule that keeps an output from replacing
 * an input or another output (candela.h, CandelaRunFiles; README "Inputs and outputs").
 *
 * Paths are compared by what they name (io_file_id: device and inode of an existing file, the
 * real folder and name of one that is not there yet), so "out/../s.gltf", a symbolic link to
 * the scene and a hard link all count as the scene. The commands fill the list before any
 * work (main.c, compare.c, batch.c); the first clash is the run's one error line. An output
 * brings its lock file (OUTPUT.lock, io_lock_output) along as a second output. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "candela.h"
#include "io.h"

struct CandelaRunFile {
    char *path;  /* as given (the message names it so) */
    char *role;  /* "the scene", "the PNG preview (--png)", ... */
    int output;
    IoFileId id;
};

static int add(CandelaRunFiles *r, const char *path, const char *role, int output, char err[CANDELA_ERR_LEN]) {
    if (r->count == r->capacity) {
        int cap = r->capacity ? 2 * r->capacity : 16;
        CandelaRunFile *f = realloc(r->files, (size_t)cap * sizeof *f);
        if (!f) {
            snprintf(err, CANDELA_ERR_LEN, "out of memory");
            return -1;
        }
        r->files = f;
        r->capacity = cap;
    }
    CandelaRunFile *f = &r->files[r->count];
    memset(f, 0, sizeof *f);
    f->path = strdup(path);
    f->role = strdup(role);
    if (!f->path || !f->role) {
        free(f->path);
        free(f->role);
        snprintf(err, CANDELA_ERR_LEN, "out of memory");
        return -1;
    }
    f->output = output;
    (void)io_file_id(path, &f->id); /* a folder that does not exist: compared as written */
    ++r->count;
    return 0;
}

/* The first recorded file that `path` (an output, or an input when !output) may not be. */
static int clash(const CandelaRunFiles *r, const char *path, const char *role, int output, int skip_last,
                 const IoFileId *continued, char err[CANDELA_ERR_LEN]) {
    IoFileId id;
    (void)io_file_id(path, &id);
    int n = r->count - (skip_last ? 1 : 0);
    for (int i = 0; i < n; ++i) {
        const CandelaRunFile *f = &r->files[i];
        if (!output && !f->output) continue; /* two inputs may be one file (a texture used twice) */
        if (!io_same_file(&id, &f->id)) continue;
        if (continued && !f->output && io_same_file(continued, &f->id)) continue;
        if (output && f->output)
            snprintf(err, CANDELA_ERR_LEN, "%.250s: %.80s and %.80s are the same file (every output of a run needs its own)",
                     path, f->role, role);
        else if (output)
            snprintf(err, CANDELA_ERR_LEN, "%.250s: %.80s would replace %.80s, an input of this run", path, role, f->role);
        else
            snprintf(err, CANDELA_ERR_LEN, "%.250s: %.80s would replace %.80s, an input of this run", f->path, f->role,
                     role);
        return -1;
    }
    return 0;
}

int candela_run_input(CandelaRunFiles *r, const char *path, const char *role, char err[CANDELA_ERR_LEN]) {
    if (!path) return 0;
    if (add(r, path, role, 0, err) != 0) return -1;
    return clash(r, path, role, 0, 1, NULL, err);
}

int candela_run_output(CandelaRunFiles *r, const char *path, const char *role, char err[CANDELA_ERR_LEN]) {
    return candela_run_output_continuing(r, path, role, NULL, err);
}

/* The lock file beside an output (io_lock_path: OUTPUT.lock by its resolved path), and its role.
 * A run truncates its locks and removes them when done, so a lock is an output like the file it
 * guards: a scene or film named OUTPUT.lock would otherwise be emptied and deleted. */
static void lock_of(const char *path, const char *role, char lock[IO_PATH_MAX + 8], char lock_role[128]) {
    char ioerr[IO_ERR_LEN];
    /* an output path the writer will refuse (a FIFO, a folder) fails there with its own line */
    if (io_lock_path(path, lock, ioerr) != 0) snprintf(lock, IO_PATH_MAX + 8, "%.4000s.lock", path);
    snprintf(lock_role, 128, "the lock file of %.100s", role);
}

int candela_run_output_continuing(CandelaRunFiles *r, const char *path, const char *role, const char *continued,
                                  char err[CANDELA_ERR_LEN]) {
    if (!path) return 0;
    IoFileId cid;
    if (continued) (void)io_file_id(continued, &cid);
    char lock[IO_PATH_MAX + 8], lock_role[128];
    lock_of(path, role, lock, lock_role);
    if (clash(r, path, role, 1, 0, continued ? &cid : NULL, err) != 0 || clash(r, lock, lock_role, 1, 0, NULL, err) != 0)
        return -1;
    return add(r, path, role, 1, err) != 0 || add(r, lock, lock_role, 1, err) != 0 ? -1 : 0;
}

int candela_run_check_output(const CandelaRunFiles *r, const char *path, const char *role, char err[CANDELA_ERR_LEN]) {
    if (!path) return 0;
    char lock[IO_PATH_MAX + 8], lock_role[128];
    lock_of(path, role, lock, lock_role);
    return clash(r, path, role, 1, 0, NULL, err) != 0 || clash(r, lock, lock_role, 1, 0, NULL, err) != 0 ? -1 : 0;
}

int candela_run_scene(CandelaRunFiles *r, const char *scene_path, char err[CANDELA_ERR_LEN]) {
    if (candela_run_input(r, scene_path, "the scene", err) != 0) return -1;
    IoPathList refs;
    char ioerr[IO_ERR_LEN];
    /* a scene that cannot be listed cannot be loaded either (the same reader and JSON parser):
     * the loader reports it in a moment, before anything is written */
    if (io_gltf_references(scene_path, &refs, ioerr) != 0) return 0;
    int rc = 0;
    for (int i = 0; i < refs.count && rc == 0; ++i) rc = candela_run_input(r, refs.paths[i], "a file the scene references", err);
    io_path_list_free(&refs);
    return rc;
}

void candela_run_files_free(CandelaRunFiles *r) {
    for (int i = 0; i < r->count; ++i) {
        free(r->files[i].path);
        free(r->files[i].role);
    }
    free(r->files);
    memset(r, 0, sizeof *r);
}
