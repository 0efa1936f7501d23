/* io/io_err.h: the one-line messages of io/'s C files (private to io/, never included from outside
 * it; io_internal.hpp is the C++ files' counterpart). Defined in files.c. */
#ifndef CANDELA_IO_ERR_H
#define CANDELA_IO_ERR_H

#include "io.h"

#include <stddef.h>

/* snprintf that may truncate, without the compiler's truncation warning: a message is one line
 * of at most IO_ERR_LEN bytes, and a cut one is still worth giving. */
void io_fmt(char *buf, size_t len, const char *format, ...) __attribute__((format(printf, 3, 4)));

/* "PATH: problem" into err (nothing when err is NULL; "(null)" for a NULL path). The path is cut
 * at 400 bytes so that the problem still fits, and a CR or LF (a library's message, a file name)
 * becomes a space: the message stays one line. */
void io_err(char err[IO_ERR_LEN], const char *path, const char *format, ...) __attribute__((format(printf, 3, 4)));

#endif
