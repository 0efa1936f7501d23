/* tests/test_atomic.c: io's one atomic writer (io/atomic_file.c, io.h "atomic files"), which every
 * output of the program goes through.
 *   - a write appears under its name only complete: while it is written the final name holds the
 *     old file (or nothing), the temporary PATH.tmp-PID beside it; after the commit, the new bytes
 *     and no temporary; stream ("wb", "w+b" read back), whole-buffer and by-descriptor writes;
 *   - a failed write (a file size limit, RLIMIT_FSIZE, which needs no privilege; a full tmpfs
 *     where this test may mount one) is one line naming the file and the reason ("File too
 *     large", "No space left on device"), leaves no temporary and the old file untouched; so
 *     does an abort, a missing folder, and a directory where the file should go;
 *   - the registry: io_remove_active_temps removes exactly the temporaries of the writes in
 *     progress (several at once, more than its slots, none after a commit), and a process killed
 *     by a signal whose handler calls it leaves no file; io_remove_stale_temps removes a dead
 *     process's temporary and keeps a live one's. */
#include "check.h"
#include "io.h"

#include <errno.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

static char dir[256];

static const char *at(const char *name) {
    static char buf[8][512];
    static int k;
    char *p = buf[k++ % 8];
    snprintf(p, 512, "%s/%s", dir, name);
    return p;
}

static int exists(const char *path) {
    struct stat st;
    return lstat(path, &st) == 0;
}

/* the whole file, or NULL (*n its size) */
static char *slurp(const char *path, size_t *n) {
    *n = 0;
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    char *buf = NULL;
    size_t cap = 0;
    for (;;) {
        if (*n + 4096 > cap) {
            cap = cap ? 2 * cap : 8192;
            char *b = realloc(buf, cap);
            if (!b) break;
            buf = b;
        }
        size_t r = fread(buf + *n, 1, cap - *n, f);
        *n += r;
        if (r == 0) break;
    }
    fclose(f);
    return buf;
}

static int holds(const char *path, const char *want) {
    size_t n;
    char *got = slurp(path, &n);
    int same = got && n == strlen(want) && memcmp(got, want, n) == 0;
    free(got);
    return same;
}

static void put(const char *path, const char *text) {
    FILE *f = fopen(path, "wb");
    if (f) {
        fputs(text, f);
        fclose(f);
    }
}

/* files in dir whose name contains ".tmp-" */
static int temporaries(void) {
    char cmd[600];
    snprintf(cmd, sizeof cmd, "ls -A '%s' | grep -c '\\.tmp-'", dir);
    FILE *p = popen(cmd, "r");
    int n = -1;
    if (p) {
        if (fscanf(p, "%d", &n) != 1) n = -1;
        pclose(p);
    }
    return n;
}

/* a one-line message that names path and says reason */
static int one_line(const char *err, const char *path, const char *reason) {
    return strchr(err, '\n') == NULL && strncmp(err, path, strlen(path)) == 0 && strstr(err, reason) != NULL;
}

static void test_complete_only(void) {
    char err[IO_ERR_LEN];
    const char *path = at("out.txt");
    put(path, "old");
    IoAtomicFile af;
    CHECK(io_atomic_begin(&af, path, "wb", err) == 0, "%s", err);
    CHECK(strcmp(af.path, path) == 0, "final name %s", af.path);
    char tmp[600];
    snprintf(tmp, sizeof tmp, "%s.tmp-%ld", path, (long)getpid());
    CHECK(strcmp(af.tmp, tmp) == 0, "temporary %s", af.tmp);
    for (int i = 0; i < 20000; ++i) fprintf(af.f, "line %d\n", i); /* past any stdio buffer */
    fflush(af.f);
    /* half way: the final name still holds the old file, the new bytes are in the temporary */
    CHECK(holds(path, "old"), "the final name changed before the commit");
    CHECK(exists(tmp), "no temporary while writing");
    CHECK(io_atomic_commit(&af, err) == 0, "%s", err);
    size_t n;
    char *got = slurp(path, &n);
    CHECK(got && n > 100000 && strncmp(got, "line 0\n", 7) == 0 && strncmp(got + n - 11, "line 19999\n", 11) == 0,
          "committed file: %zu bytes", n);
    free(got);
    CHECK(!exists(tmp) && temporaries() == 0, "a temporary left after the commit");

    /* the whole buffer at once, over an existing file */
    CHECK(io_atomic_write(path, "new bytes", 9, err) == 0, "%s", err);
    CHECK(holds(path, "new bytes"), "io_atomic_write's file");
    CHECK(io_atomic_write(at("empty"), NULL, 0, err) == 0 && holds(at("empty"), ""), "an empty file: %s", err);

    /* "w+b": what was written is read back (a checkpoint's checksum) before the end is added */
    CHECK(io_atomic_begin(&af, at("rw.bin"), "w+b", err) == 0, "%s", err);
    fputs("abcdef", af.f);
    char back[8] = {0};
    CHECK(fseek(af.f, 0, SEEK_SET) == 0 && fread(back, 1, 6, af.f) == 6 && strcmp(back, "abcdef") == 0, "read back '%s'",
          back);
    CHECK(fseek(af.f, 0, SEEK_END) == 0 && ftell(af.f) == 6, "seek to the end");
    fputs("gh", af.f);
    CHECK(io_atomic_commit(&af, err) == 0 && holds(at("rw.bin"), "abcdefgh"), "w+b: %s", err);

    /* by descriptor (mode NULL: a library writes the temporary, which exists already) */
    CHECK(io_atomic_begin(&af, at("fd.bin"), NULL, err) == 0 && af.f == NULL && exists(af.tmp), "by name: %s", err);
    CHECK(pwrite(af.fd, "xyz", 3, 0) == 3, "pwrite");
    CHECK(!exists(at("fd.bin")), "the final name before the commit");
    CHECK(io_atomic_commit(&af, err) == 0 && holds(at("fd.bin"), "xyz"), "by descriptor: %s", err);

    /* a symbolic link: its target gets the file, the link stays */
    put(at("target"), "t");
    CHECK(symlink("target", at("link")) == 0, "symlink");
    CHECK(io_atomic_write(at("link"), "via link", 8, err) == 0, "%s", err);
    struct stat st;
    CHECK(lstat(at("link"), &st) == 0 && S_ISLNK(st.st_mode) && holds(at("target"), "via link"),
          "a write through a link replaced the link");
    CHECK(temporaries() == 0, "temporaries left");
}

static void test_failures(void) {
    char err[IO_ERR_LEN];
    const char *path = at("fail.txt");
    put(path, "old");
    IoAtomicFile af;

    /* abort: the temporary goes, the old file stays */
    CHECK(io_atomic_begin(&af, path, "wb", err) == 0, "%s", err);
    fputs("half", af.f);
    io_atomic_abort(&af);
    CHECK(holds(path, "old") && temporaries() == 0, "abort");

    /* a missing folder, a directory under the name: one line, nothing made */
    CHECK(io_atomic_write(at("nodir/x.txt"), "x", 1, err) != 0 && one_line(err, at("nodir/x.txt"), "No such file"),
          "missing folder: %s", err);
    CHECK(mkdir(at("adir"), 0755) == 0, "mkdir");
    CHECK(io_atomic_write(at("adir"), "x", 1, err) != 0 && one_line(err, at("adir"), "not a regular file"),
          "a directory: %s", err);
    CHECK(io_atomic_write(NULL, "x", 1, err) != 0 && strstr(err, "no path given"), "no path: %s", err);

    /* a write that does not fit (RLIMIT_FSIZE: every write past 64 KiB fails with EFBIG, the
     * signal it raises ignored): the reason, no temporary, the old file as it was; in a
     * child, so that the limit ends with it */
    pid_t pid = fork();
    if (pid == 0) {
        signal(SIGXFSZ, SIG_IGN);
        struct rlimit rl = {65536, 65536};
        int bad = setrlimit(RLIMIT_FSIZE, &rl) != 0;
        IoAtomicFile a;
        char e[IO_ERR_LEN] = "";
        /* a stream: thousands of writes after the first failure, the reason kept */
        if (!bad && io_atomic_begin(&a, path, "wb", e) == 0) {
            for (int i = 0; i < 20000; ++i) fprintf(a.f, "line %d\n", i);
            bad |= io_atomic_commit(&a, e) == 0 || !one_line(e, path, ": cannot write: File too large");
        } else {
            bad = 1;
        }
        fprintf(stderr, "stream past the limit: %s\n", e);
        /* one buffer larger than the limit */
        static char big[100000];
        bad |= io_atomic_write(path, big, sizeof big, e) == 0 || !one_line(e, path, "File too large");
        /* by descriptor (the EXR writer keeps its first error in af.error) */
        if (io_atomic_begin(&a, path, NULL, e) == 0) {
            if (pwrite(a.fd, big, sizeof big, 0) != (ssize_t)sizeof big && !a.error) a.error = errno;
            bad |= io_atomic_commit(&a, e) == 0 || !one_line(e, path, "File too large");
        } else {
            bad = 1;
        }
        _exit(bad);
    }
    int status = 0;
    CHECK(pid > 0 && waitpid(pid, &status, 0) == pid && WIFEXITED(status) && WEXITSTATUS(status) == 0,
          "writes past a file size limit (status %d)", status);
    CHECK(holds(path, "old") && temporaries() == 0, "a failed write changed the file or left a temporary");

    /* a full disk, where this test may mount a small tmpfs (root): ENOSPC said so */
    char full[300];
    snprintf(full, sizeof full, "%s/full", dir);
    mkdir(full, 0755);
    if (mount("tmpfs", full, "tmpfs", 0, "size=64k") == 0) {
        char p[400], fill[400];
        snprintf(p, sizeof p, "%s/o.bin", full);
        snprintf(fill, sizeof fill, "%s/fill", full);
        put(p, "old");
        static char big[200000];
        FILE *f = fopen(fill, "wb");
        if (f) {
            fwrite(big, 1, 40000, f);
            fclose(f);
        }
        CHECK(io_atomic_write(p, big, sizeof big, err) != 0 && one_line(err, p, "cannot write: No space left on device"),
              "full disk: %s", err);
        CHECK(holds(p, "old"), "full disk: the old file changed");
        CHECK(io_atomic_begin(&af, p, "w", err) == 0, "%s", err);
        for (int i = 0; i < 30000; ++i) fprintf(af.f, "%d\n", i);
        CHECK(io_atomic_commit(&af, err) != 0 && one_line(err, p, "No space left on device"), "full disk (stream): %s",
              err);
        char cmd[500];
        snprintf(cmd, sizeof cmd, "ls -A '%s' | grep -q tmp-", full);
        CHECK(system(cmd) != 0 && holds(p, "old"), "full disk: a temporary left or the file changed");
        umount(full);
    } else {
        fprintf(stderr, "full-disk check skipped: cannot mount a tmpfs here (%s)\n", strerror(errno));
    }
}

static void on_term(int sig) {
    (void)sig;
    io_remove_active_temps();
    _exit(3);
}

static void test_registry(void) {
    char err[IO_ERR_LEN];
    enum { N = 10 }; /* more than the registry's slots: the writes still work */
    IoAtomicFile af[N];
    char name[N][32];
    for (int i = 0; i < N; ++i) {
        snprintf(name[i], sizeof name[i], "reg%d", i);
        CHECK(io_atomic_begin(&af[i], at(name[i]), "wb", err) == 0, "%s", err);
        fputs("x", af[i].f);
        fflush(af[i].f);
    }
    CHECK(temporaries() == N, "%d temporaries, %d writes", temporaries(), N);
    io_remove_active_temps();
    int left = temporaries();
    CHECK(left >= 0 && left < N && left <= N - 8, "io_remove_active_temps left %d of %d", left, N);
    for (int i = 0; i < N; ++i) io_atomic_abort(&af[i]);
    CHECK(temporaries() == 0, "aborts left temporaries");

    /* after a commit its slot is free: a file that takes the temporary's name later is not
     * removed by the handler */
    CHECK(io_atomic_begin(&af[0], at("done"), "wb", err) == 0, "%s", err);
    char tmp[IO_TEMP_PATH_MAX];
    snprintf(tmp, sizeof tmp, "%s", af[0].tmp);
    CHECK(io_atomic_commit(&af[0], err) == 0, "%s", err);
    put(tmp, "someone else's");
    io_remove_active_temps();
    CHECK(exists(tmp), "io_remove_active_temps removed a file after its write ended");
    unlink(tmp);

    /* a process killed while writing, its handler calling io_remove_active_temps (as main.c's
     * does on a second interrupt): no file left, neither the temporary nor the final name */
    pid_t pid = fork();
    if (pid == 0) {
        signal(SIGTERM, on_term);
        IoAtomicFile a;
        char e[IO_ERR_LEN];
        if (io_atomic_begin(&a, at("killed"), "wb", e) != 0) _exit(1);
        fputs("half a file", a.f);
        fflush(a.f);
        raise(SIGTERM);
        _exit(2);
    }
    int status = 0;
    CHECK(pid > 0 && waitpid(pid, &status, 0) == pid && WIFEXITED(status) && WEXITSTATUS(status) == 3,
          "the killed writer's status %d", status);
    CHECK(!exists(at("killed")) && temporaries() == 0, "a killed write left a file");

    /* what a SIGKILL leaves: a dead process's temporary is removed by the next write of the name,
     * a live process's (the parent's, here) stays */
    pid = fork();
    if (pid == 0) _exit(0);
    waitpid(pid, NULL, 0);
    char dead[600], live[600];
    snprintf(dead, sizeof dead, "%s.tmp-%ld", at("stale"), (long)pid);
    snprintf(live, sizeof live, "%s.tmp-%ld", at("stale"), (long)getppid());
    put(dead, "cut");
    put(live, "busy");
    if (kill(pid, 0) == 0) {
        fprintf(stderr, "stale temporary check skipped: pid %ld was reused\n", (long)pid);
    } else {
        CHECK(io_atomic_write(at("stale"), "s", 1, err) == 0, "%s", err);
        CHECK(!exists(dead) && exists(live), "stale temporaries: dead %d, live %d", exists(dead), exists(live));
    }
    unlink(dead);
    unlink(live);
}

int main(void) {
    snprintf(dir, sizeof dir, "/tmp/candela_test_atomic_%ld", (long)getpid());
    if (mkdir(dir, 0755) != 0) {
        fprintf(stderr, "cannot make %s: %s\n", dir, strerror(errno));
        return 1;
    }
    test_complete_only();
    test_failures();
    test_registry();
    char cmd[400];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", dir);
    return test_exit();
}
