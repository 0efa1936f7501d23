/* io/atomic_file.c: how every output file is written (io.h, "atomic files"; io/README.md, "Writing
 * an output"). Plain C17, POSIX.
 *
 * One protocol for every writer (EXR, PNG, statistics, checkpoints and films, the comparison
 * report's files, cache point and guiding dumps, VDB files): the bytes go to PATH.tmp-PID beside
 * the final name, every write, flush, sync and close is checked, the file is synced to disk and
 * only then renamed over PATH. So the final name holds either the old file or the complete new
 * one, never a cut one: not after a full disk (an image library's writer once reported success
 * there and a truncated file was renamed into place, issue 13 item 10), nor a crash or power
 * loss (the sync before the rename), nor an interrupt (the temporary is registered for the
 * signal handler, which removes it), nor a SIGKILL (its leftover is removed by the next write of
 * PATH, io_remove_stale_temps). Before this file the block existed in seven copies (issue 30),
 * with their differences: the comparison report's neither registered nor synced its temporary,
 * the VDB writer's did not sync, and most said no reason for a failed write. */
#include "io.h"
#include "io_err.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---------------------------------------------------------------- where an output goes */

int io_output_path(const char *path, char resolved[IO_PATH_MAX], char err[IO_ERR_LEN]) {
    char cur[IO_PATH_MAX];
    if (snprintf(cur, sizeof cur, "%s", path) >= (int)sizeof cur) {
        io_err(err, path, "path too long");
        return 1;
    }
    for (int hops = 0; hops < 40; ++hops) {
        struct stat st;
        if (lstat(cur, &st) != 0) break; /* a new file: written here */
        if (S_ISLNK(st.st_mode)) {
            char target[IO_PATH_MAX];
            ssize_t n = readlink(cur, target, sizeof target - 1);
            if (n < 0 || n >= (ssize_t)sizeof target - 1) {
                io_err(err, path, "cannot read the symbolic link");
                return 1;
            }
            target[n] = 0;
            if (target[0] == '/') {
                memcpy(cur, target, (size_t)n + 1);
            } else { /* relative to the link's folder */
                char *slash = strrchr(cur, '/');
                size_t dir = slash ? (size_t)(slash - cur) + 1 : 0;
                if (dir + (size_t)n + 1 > sizeof cur) {
                    io_err(err, path, "path too long");
                    return 1;
                }
                memcpy(cur + dir, target, (size_t)n + 1);
            }
            continue;
        }
        if (!S_ISREG(st.st_mode)) {
            io_err(err, path, "not a regular file (a directory, device or FIFO): not replaced");
            return 1;
        }
        break;
    }
    struct stat st;
    if (lstat(cur, &st) == 0 && S_ISLNK(st.st_mode)) {
        io_err(err, path, "too many levels of symbolic links");
        return 1;
    }
    memcpy(resolved, cur, strlen(cur) + 1);
    return 0;
}

/* ---------------------------------------------------------------- the registry of temporaries */

/* The one piece of process-wide mutable state in io/: a signal handler must be able to find the
 * files to remove without locks or allocation. A few slots, so that writes on two threads (or a
 * write begun while another is open) are each registered; a slot is claimed by a compare-and-swap
 * and published (state 2) only once its name is complete, so the handler never reads a name
 * being copied. Lock-free atomics are async-signal-safe (C17 7.14.1.1 p5). */
enum { TEMP_SLOTS = 8, SLOT_FREE = 0, SLOT_FILLING = 1, SLOT_SET = 2 };
_Static_assert(ATOMIC_INT_LOCK_FREE == 2, "the signal handler needs lock-free atomics");
static char temp_name[TEMP_SLOTS][IO_TEMP_PATH_MAX];
static atomic_int temp_state[TEMP_SLOTS];

/* The slot holding tmp, or -1 when every slot is taken (the write still works; an interrupt
 * then leaves the file, which the next write of its name removes). */
static int temp_register(const char *tmp) {
    size_t n = strlen(tmp);
    if (n >= IO_TEMP_PATH_MAX) return -1;
    for (int i = 0; i < TEMP_SLOTS; ++i) {
        int expected = SLOT_FREE;
        if (!atomic_compare_exchange_strong(&temp_state[i], &expected, SLOT_FILLING)) continue;
        memcpy(temp_name[i], tmp, n + 1);
        atomic_store(&temp_state[i], SLOT_SET);
        return i;
    }
    return -1;
}

static void temp_unregister(int slot) {
    if (slot >= 0 && slot < TEMP_SLOTS) atomic_store(&temp_state[slot], SLOT_FREE);
}

void io_remove_active_temps(void) {
    for (int i = 0; i < TEMP_SLOTS; ++i)
        if (atomic_load(&temp_state[i]) == SLOT_SET) unlink(temp_name[i]);
}

void io_remove_stale_temps(const char *path) {
    const char *slash = strrchr(path, '/');
    const char *base = slash ? slash + 1 : path;
    const size_t base_len = strlen(base);
    char dir[IO_PATH_MAX];
    if (!slash) {
        snprintf(dir, sizeof dir, ".");
    } else if ((size_t)(slash - path) + 1 < sizeof dir) {
        memcpy(dir, path, (size_t)(slash - path) + 1); /* with the slash: "/" stays the root */
        dir[slash - path + 1] = 0;
    } else {
        return;
    }
    if (base_len == 0) return;
    DIR *d = opendir(dir);
    if (!d) return; /* the writer reports the folder's problem itself */
    const int dfd = dirfd(d);
    const pid_t self = getpid();
    for (struct dirent *e; (e = readdir(d)) != NULL;) {
        const char *n = e->d_name;
        if (strncmp(n, base, base_len) != 0 || strncmp(n + base_len, ".tmp-", 5) != 0) continue;
        /* exactly the digits "%ld" gives for a pid: no sign, no leading zero */
        const char *digits = n + base_len + 5;
        size_t k = strspn(digits, "0123456789");
        if (k == 0 || k > 10 || digits[k] != 0 || digits[0] == '0') continue;
        long long pid = strtoll(digits, NULL, 10);
        if (pid > INT_MAX || (pid_t)pid == self) continue;
        if (kill((pid_t)pid, 0) == 0 || errno != ESRCH) continue; /* alive (EPERM: someone else's) */
        struct stat st;
        if (fstatat(dfd, n, &st, AT_SYMLINK_NOFOLLOW) == 0 && S_ISREG(st.st_mode)) unlinkat(dfd, n, 0);
    }
    closedir(d);
}

/* ---------------------------------------------------------------- one atomic write */

/* The stream a writer gets is stdio over the temporary's descriptor through these functions
 * (fopencookie), so that the first failing read or write is kept with its errno
 * (af->error): a full disk is then said as "No space left on device" however many stdio calls
 * came after the one that failed (ferror keeps no reason, and errno is anyone's by then). */
static ssize_t cookie_read(void *c, char *buf, size_t n) {
    IoAtomicFile *af = c;
    ssize_t r;
    do r = read(af->fd, buf, n);
    while (r < 0 && errno == EINTR);
    if (r < 0 && !af->error) af->error = errno;
    return r;
}

/* glibc takes a short count for an error: all of buf is written, or the reason is kept */
static ssize_t cookie_write(void *c, const char *buf, size_t n) {
    IoAtomicFile *af = c;
    size_t done = 0;
    while (done < n) {
        ssize_t w = write(af->fd, buf + done, n - done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            if (!af->error) af->error = w < 0 ? errno : EIO;
            break;
        }
        done += (size_t)w;
    }
    return (ssize_t)done;
}

static int cookie_seek(void *c, off64_t *offset, int whence) {
    IoAtomicFile *af = c;
    off_t at = lseek(af->fd, (off_t)*offset, whence);
    if (at < 0) return -1;
    *offset = (off64_t)at;
    return 0;
}

/* the descriptor is closed by io_atomic_commit / io_atomic_abort, after the sync */
static int cookie_close(void *c) {
    (void)c;
    return 0;
}

int io_atomic_begin(IoAtomicFile *af, const char *path, const char *mode, char err[IO_ERR_LEN]) {
    if (err) err[0] = 0;
    af->f = NULL;
    af->fd = -1;
    af->error = 0;
    af->slot = -1;
    af->path[0] = af->tmp[0] = 0;
    if (!path || !*path) {
        io_err(err, "(null)", "no path given");
        return 1;
    }
    /* a symbolic link gets the file written to its target (the temporary beside it) */
    if (io_output_path(path, af->path, err) != 0) return 1;
    snprintf(af->tmp, sizeof af->tmp, "%s.tmp-%ld", af->path, (long)getpid());
    io_remove_stale_temps(af->path);
    /* registered before it exists: an interrupt between the two still removes it */
    af->slot = temp_register(af->tmp);
    /* O_NOFOLLOW: a link planted under the temporary's name is not written through */
    const int rw = mode && strchr(mode, '+') != NULL;
    af->fd = open(af->tmp, O_CREAT | O_TRUNC | O_CLOEXEC | O_NOFOLLOW | (rw ? O_RDWR : O_WRONLY), 0666);
    if (af->fd >= 0 && mode) {
        cookie_io_functions_t fns = {rw ? cookie_read : NULL, cookie_write, cookie_seek, cookie_close};
        af->f = fopencookie(af, rw ? "w+" : "w", fns);
    }
    if (af->fd < 0 || (mode && !af->f)) {
        io_err(err, af->path, "cannot open for writing: %s", strerror(errno));
        io_atomic_abort(af);
        return 1;
    }
    return 0;
}

void io_atomic_abort(IoAtomicFile *af) {
    if (af->f) fclose(af->f);
    if (af->fd >= 0) close(af->fd);
    if (af->tmp[0]) unlink(af->tmp);
    temp_unregister(af->slot);
    af->f = NULL;
    af->fd = af->slot = -1;
    af->tmp[0] = 0;
}

int io_atomic_commit(IoAtomicFile *af, char err[IO_ERR_LEN]) {
    int e = af->error;
    /* what the stream still buffers is written by fclose (a full disk fails there at the latest) */
    if (af->f && fclose(af->f) != 0 && !e) e = af->error ? af->error : EIO;
    af->f = NULL;
    /* on disk before the rename makes it the file: a crash then never leaves an empty or cut
     * file under the final name (a library that wrote by name wrote this same inode) */
    if (!e && fsync(af->fd) != 0) e = errno;
    if (close(af->fd) != 0 && !e) e = errno;
    af->fd = -1;
    if (e) {
        io_err(err, af->path, "cannot write: %s", strerror(e));
    } else if (rename(af->tmp, af->path) != 0) {
        e = errno;
        io_err(err, af->path, "cannot rename %s into place: %s", af->tmp, strerror(e));
    }
    if (e) unlink(af->tmp);
    temp_unregister(af->slot);
    af->slot = -1;
    af->tmp[0] = 0;
    return e ? 1 : 0;
}

int io_atomic_write(const char *path, const void *data, size_t size, char err[IO_ERR_LEN]) {
    IoAtomicFile af;
    if (io_atomic_begin(&af, path, "wb", err) != 0) return 1;
    if (size) fwrite(data, 1, size, af.f); /* a failure is kept with its reason (af.error) */
    return io_atomic_commit(&af, err);
}
