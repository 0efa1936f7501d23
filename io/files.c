/* io/files.c: how the program opens its inputs, tells files apart and keeps two processes from
 * writing one output (io.h, "files"; the rules in io/README.md). Plain C17, POSIX.
 *
 * Inputs are checked with stat, opened with O_NONBLOCK and checked with fstat before a byte is
 * read: open() on a FIFO blocks until a writer appears (forever, for a farm script's typo) and a device such as
 * /dev/zero never ends, so only regular files are read, and never more than the caller's limit
 * (the size is checked from fstat first, and the read stops at the limit if the file grows).
 * Also io_fmt / io_err (io_err.h), the one-line messages of every C file of io/. */
#include "io.h"
#include "io_err.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

void io_fmt(char *buf, size_t len, const char *format, ...) {
    va_list ap;
    va_start(ap, format);
    vsnprintf(buf, len, format, ap);
    va_end(ap);
}

void io_err(char err[IO_ERR_LEN], const char *path, const char *format, ...) {
    if (!err) return;
    int k = snprintf(err, IO_ERR_LEN, "%.400s: ", path ? path : "(null)");
    if (k < 0 || k >= IO_ERR_LEN) k = 0;
    va_list ap;
    va_start(ap, format);
    vsnprintf(err + k, (size_t)(IO_ERR_LEN - k), format, ap);
    va_end(ap);
    for (char *p = err; *p; ++p)
        if (*p == '\n' || *p == '\r') *p = ' ';
}

/* "4 GiB", "1 MiB", "300 bytes": a limit as the messages give it */
static void bytes_text(uint64_t n, char *buf, size_t len) {
    if (n >= ((uint64_t)1 << 30) && n % ((uint64_t)1 << 30) == 0) snprintf(buf, len, "%llu GiB", (unsigned long long)(n >> 30));
    else if (n >= ((uint64_t)1 << 20) && n % ((uint64_t)1 << 20) == 0) snprintf(buf, len, "%llu MiB", (unsigned long long)(n >> 20));
    else snprintf(buf, len, "%llu bytes", (unsigned long long)n);
}

static const char *special_kind(mode_t mode) {
    return S_ISDIR(mode)                         ? "a directory"
           : S_ISFIFO(mode)                      ? "a FIFO"
           : S_ISCHR(mode) || S_ISBLK(mode)      ? "a device"
                                                 : "a socket or other special file";
}

int io_open_input(const char *path, uint64_t max_bytes, const char *what, int *fd_out, uint64_t *size,
                  char err[IO_ERR_LEN]) {
    *fd_out = -1;
    if (size) *size = 0;
    if (!path || !*path) {
        io_err(err, "(null)", "no path given");
        return -1;
    }
    /* stat first: opening a device can act (a tape rewinds, a watchdog arms, /dev/tty without a
     * terminal fails with its own error), so a name that is no regular file now is not opened */
    struct stat st;
    if (stat(path, &st) == 0 && !S_ISREG(st.st_mode)) {
        io_err(err, path, "not a regular file (%s): not read", special_kind(st.st_mode));
        return -1;
    }
    /* ... and fstat of what was opened (O_NONBLOCK: a FIFO swapped in meanwhile does not block
     * the open), which is the file then read */
    int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd < 0) {
        io_err(err, path, "cannot read: %s", strerror(errno));
        return -1;
    }
    if (fstat(fd, &st) != 0) {
        io_err(err, path, "cannot read: %s", strerror(errno));
        close(fd);
        return -1;
    }
    if (!S_ISREG(st.st_mode)) {
        io_err(err, path, "not a regular file (%s): not read", special_kind(st.st_mode));
        close(fd);
        return -1;
    }
    if (max_bytes && (uint64_t)st.st_size > max_bytes) {
        char limit[32];
        bytes_text(max_bytes, limit, sizeof limit);
        io_err(err, path, "%llu bytes, over the %s limit of %.60s", (unsigned long long)st.st_size, limit,
                  what ? what : "this input");
        close(fd);
        return -1;
    }
    /* a regular file never blocks; blocking reads from here (a short read means an error) */
    int fl = fcntl(fd, F_GETFL);
    if (fl >= 0) (void)fcntl(fd, F_SETFL, fl & ~O_NONBLOCK);
    *fd_out = fd;
    if (size) *size = (uint64_t)st.st_size;
    return 0;
}

FILE *io_open_input_file(const char *path, uint64_t max_bytes, const char *what, uint64_t *size, char err[IO_ERR_LEN]) {
    int fd;
    if (io_open_input(path, max_bytes, what, &fd, size, err) != 0) return NULL;
    FILE *f = fdopen(fd, "rb");
    if (!f) {
        io_err(err, path, "cannot read: %s", strerror(errno));
        close(fd);
    }
    return f;
}

int io_read_input(const char *path, uint64_t max_bytes, const char *what, void **data, size_t *size,
                  char err[IO_ERR_LEN]) {
    *data = NULL;
    *size = 0;
    int fd;
    uint64_t declared;
    if (io_open_input(path, max_bytes, what, &fd, &declared, err) != 0) return -1;
    if (declared > (uint64_t)SIZE_MAX - 2) {
        io_err(err, path, "too large to read");
        close(fd);
        return -1;
    }
    /* the declared size plus one byte: a file that grew since fstat is caught at its limit,
     * never read on without bound; one more zero byte terminates text for the callers */
    size_t cap = (size_t)declared + 1, n = 0;
    unsigned char *buf = malloc(cap + 1);
    if (!buf) {
        io_err(err, path, "out of memory reading it");
        close(fd);
        return -1;
    }
    for (;;) {
        if (n == cap) {
            if (max_bytes && n > max_bytes) break;
            size_t grow = cap < ((size_t)1 << 20) ? cap : ((size_t)1 << 20);
            unsigned char *p = realloc(buf, cap + grow + 1);
            if (!p) {
                free(buf);
                io_err(err, path, "out of memory reading it");
                close(fd);
                return -1;
            }
            buf = p;
            cap += grow;
        }
        ssize_t r = read(fd, buf + n, cap - n);
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) {
            io_err(err, path, "read error: %s", strerror(errno));
            free(buf);
            close(fd);
            return -1;
        }
        if (r == 0) break;
        n += (size_t)r;
    }
    close(fd);
    if (max_bytes && n > max_bytes) {
        char limit[32];
        bytes_text(max_bytes, limit, sizeof limit);
        io_err(err, path, "grew past the %s limit while read", limit);
        free(buf);
        return -1;
    }
    buf[n] = 0;
    *data = buf;
    *size = n;
    return 0;
}

/* ---------------------------------------------------------------- telling files apart */

int io_file_id(const char *path, IoFileId *id) {
    memset(id, 0, sizeof *id);
    char resolved[IO_PATH_MAX], ioerr[IO_ERR_LEN];
    /* a symbolic link names its target (writers write there, io_output_path) */
    if (io_output_path(path, resolved, ioerr) != 0) snprintf(resolved, sizeof resolved, "%s", path);
    struct stat st;
    if (stat(resolved, &st) == 0) {
        id->exists = 1;
        id->dev = (uint64_t)st.st_dev;
        id->ino = (uint64_t)st.st_ino;
    }
    /* the real folder + the name: how two spellings of a file that does not exist yet compare */
    char dir[IO_PATH_MAX];
    const char *slash = strrchr(resolved, '/');
    const char *base = slash ? slash + 1 : resolved;
    if (!slash) snprintf(dir, sizeof dir, ".");
    else if (slash == resolved) snprintf(dir, sizeof dir, "/");
    else snprintf(dir, sizeof dir, "%.*s", (int)(slash - resolved), resolved);
    int rc = 0;
    char *real = realpath(dir, NULL);
    if (real) {
        size_t n = strlen(real);
        if (n + 1 + strlen(base) < sizeof id->path) {
            memcpy(id->path, real, n);
            if (strcmp(real, "/") != 0) id->path[n++] = '/';
            memcpy(id->path + n, base, strlen(base) + 1);
        } else {
            snprintf(id->path, sizeof id->path, "%s", resolved);
            rc = -1;
        }
        free(real);
    } else {
        snprintf(id->path, sizeof id->path, "%s", resolved);
        rc = -1;
    }
    return rc;
}

int io_same_file(const IoFileId *a, const IoFileId *b) {
    if (a->exists && b->exists) return a->dev == b->dev && a->ino == b->ino;
    if (a->exists != b->exists) return 0;
    return strcmp(a->path, b->path) == 0;
}

int io_path_inside(const char *path, const char *folder) {
    if (!folder || !*folder) return 0;
    char *dir = realpath(folder, NULL), *file = realpath(path, NULL);
    int inside = 0;
    if (dir && file) {
        size_t n = strlen(dir);
        /* "/" is every absolute path (a prefix of "/" + "/" would match none) */
        inside = strcmp(dir, "/") == 0 || (strncmp(file, dir, n) == 0 && file[n] == '/');
    }
    free(dir);
    free(file);
    return inside;
}

/* ---------------------------------------------------------------- output locks */

int io_lock_path(const char *output, char lock[IO_PATH_MAX + 8], char err[IO_ERR_LEN]) {
    char resolved[IO_PATH_MAX];
    lock[0] = 0;
    if (io_output_path(output, resolved, err) != 0) return -1;
    if (snprintf(lock, IO_PATH_MAX + 8, "%s.lock", resolved) >= IO_PATH_MAX + 8) {
        io_err(err, output, "path too long");
        lock[0] = 0;
        return -1;
    }
    return 0;
}

int io_lock_output(const char *output, IoLock *lock, char err[IO_ERR_LEN]) {
    lock->fd = -1;
    if (io_lock_path(output, lock->path, err) != 0) return -1;
    /* flock, not O_EXCL + a pid: the kernel drops a dead process's lock (a SIGKILL or a
     * power loss leaves a lock file nobody holds, which the next writer simply takes), and
     * NFS carries flock as a POSIX lock between hosts, where another host's pid means nothing.
     * The file is removed when the writer is done; a writer that opened it just before that
     * finds its inode gone from the name and tries again. */
    for (int attempt = 0; attempt < 16; ++attempt) {
        int fd = open(lock->path, O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK, 0666);
        if (fd < 0) {
            io_err(err, output, "cannot create its lock file %.200s: %s", lock->path, strerror(errno));
            lock->path[0] = 0;
            return -1;
        }
        if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
            int e = errno;
            if (e == EWOULDBLOCK || e == EAGAIN) {
                char pid[32] = "";
                ssize_t n = pread(fd, pid, sizeof pid - 1, 0);
                pid[n > 0 ? n : 0] = 0;
                pid[strcspn(pid, "\n")] = 0;
                char who[96];
                snprintf(who, sizeof who, "%s%s%s", pid[0] ? " (pid " : "", pid, pid[0] ? ")" : "");
                io_err(err, output, "another candela%s is writing it (its lock %.200s is held): not started", who,
                          lock->path);
                close(fd);
                lock->path[0] = 0;
                return -1;
            }
            /* a file system without locks (some FUSE mounts): writing goes on unguarded, as
             * before locks existed, rather than refusing every render there */
            close(fd);
            unlink(lock->path);
            lock->path[0] = 0;
            return 0;
        }
        struct stat held, named;
        if (fstat(fd, &held) == 0 && stat(lock->path, &named) == 0 && held.st_dev == named.st_dev &&
            held.st_ino == named.st_ino) {
            char pid[32];
            int n = snprintf(pid, sizeof pid, "%ld\n", (long)getpid());
            if (ftruncate(fd, 0) == 0 && pwrite(fd, pid, (size_t)n, 0) == n) { /* only for the message */ }
            lock->fd = fd;
            return 0;
        }
        close(fd); /* removed by its previous holder after we opened it: take the new one */
    }
    io_err(err, output, "cannot take its lock file %.200s (it keeps changing)", lock->path);
    lock->path[0] = 0;
    return -1;
}

void io_unlock_output(IoLock *lock) {
    if (lock->fd >= 0) {
        unlink(lock->path); /* while still held: nobody takes a lock that is about to go */
        close(lock->fd);
    }
    lock->fd = -1;
    lock->path[0] = 0;
}
