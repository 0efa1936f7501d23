/* renderer/util/ckpt_io.h (private): how a module writes its section of a checkpoint (checkpoint.h
 * says what a checkpoint is). Small on purpose: the modules that save state (film, recorder,
 * guiding, the auto probes) include this, not checkpoint.h, so that none of them depends on the
 * checkpoint file's code, which depends on them. */
#ifndef CANDELA_CKPT_IO_H
#define CANDELA_CKPT_IO_H

#include <stdint.h>
#include <stdio.h>

/* A module's section starts with its tag and version (checked on load). */
static inline int ckpt_put(FILE *out, const void *p, size_t n) { return fwrite(p, 1, n, out) == n ? 0 : -1; }
static inline int ckpt_get(FILE *in, void *p, size_t n) { return fread(p, 1, n, in) == n ? 0 : -1; }
static inline int ckpt_put_tag(FILE *out, uint32_t tag, uint32_t version) {
    uint32_t h[2] = {tag, version};
    return ckpt_put(out, h, sizeof h);
}
static inline int ckpt_get_tag(FILE *in, uint32_t tag, uint32_t version) {
    uint32_t h[2];
    return ckpt_get(in, h, sizeof h) == 0 && h[0] == tag && h[1] == version ? 0 : -1;
}
#define CKPT_TAG(a, b, c, d) ((uint32_t)(a) | (uint32_t)(b) << 8 | (uint32_t)(c) << 16 | (uint32_t)(d) << 24)

#endif
