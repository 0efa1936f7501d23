/* renderer/checkpoint.h (private): checkpoints and film files (checkpoint.c), and the
 * save/load pair each module of the renderer gives its own state (film.c, record.c, guide.c,
 * auto_probe.c; the light sampler's in its ops, guiding's and the cache points' in their
 * modules).
 *
 * A checkpoint is the state at a batch boundary: the film sums, every learned structure the
 * next batch reads or accumulates into, and where the render stands (iteration, samples done,
 * paths of the iteration done). A render resumed from it continues bit-identically, because
 * every random number is a function of (seed, pixel, sample) and the rest of the state is in
 * the file. Files are native byte order (a byte-order mark in the header refuses a foreign
 * one), carry a format version, the identity of the render (scene content hash, resolution and
 * every option that changes the image) and end in a checksum of all that precedes it. */
#ifndef CANDELA_CHECKPOINT_H
#define CANDELA_CHECKPOINT_H

#include <stdint.h>
#include <stdio.h>

#include "integrator.h"

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

/* Where a render stands at a batch boundary. */
typedef struct CheckpointProgress {
    int32_t iteration;         /* the iteration to run next (or continue) */
    int32_t spp_done;          /* samples per pixel of the completed iterations */
    uint64_t iteration_paths;  /* paths of `iteration` already rendered (0 at a barrier) */
} CheckpointProgress;

/* The render's identity: its options as canonical text (key=value pairs) with the scene's
 * content hash and resolution. The shard part is kept apart so that `candela merge` can require
 * everything else to match. */
#define CKPT_IDENTITY_LEN CANDELA_IDENTITY_LEN
typedef struct CheckpointIdentity {
    char text[CKPT_IDENTITY_LEN];  /* candela_image_identity (candela.h) */
    const char *record;            /* CandelaOptions.checkpoint_record (not part of the identity) */
    uint64_t spp_total;            /* the render's spp (all shards) */
    uint64_t sample_begin, sample_count; /* this file's samples per pixel: [begin, begin + count) */
    uint32_t shard_index, shard_count;   /* 0/1 without sharding */
} CheckpointIdentity;

/* FNV-1a 64 of the scene file's bytes (the identity's scene hash; provenance's
 * candela:sceneHash). -1 with a message when it cannot be read. */
int checkpoint_scene_hash(const char *scene_path, uint64_t *hash, char err[CANDELA_ERR_LEN]);
/* Fills the identity of the render o of a scene resolved to width x height. -1 when the
 * scene file cannot be read (message in err). */
int checkpoint_identity(const CandelaOptions *o, int width, int height, uint64_t sample_begin, uint64_t sample_count,
                        CheckpointIdentity *id, char err[CANDELA_ERR_LEN]);

/* Before anything is built: the checkpoint at path belongs to this render (same identity), is
 * intact (checksum) and is a checkpoint, not a finished film. -1 with a one-line message. */
int checkpoint_check(const char *path, const CheckpointIdentity *id, char err[CANDELA_ERR_LEN]);
/* Writes the state through io's atomic writer (io_atomic_begin: PATH.tmp-PID, synced, renamed). final: a finished film (a shard's
 * result, what `candela merge` reads), which holds the film only. -1 with a message. */
int checkpoint_write(const char *path, const CheckpointIdentity *id, const CheckpointProgress *pr, Integrator *ig,
                     const LightSampler *sampler, int final, char err[CANDELA_ERR_LEN]);
/* Restores the state into a freshly built render of the same identity. -1 with a message. */
int checkpoint_load(const char *path, const CheckpointIdentity *id, CheckpointProgress *pr, Integrator *ig,
                    const LightSampler *sampler, char err[CANDELA_ERR_LEN]);
/* The checkpoint-skipping schedule (path-guiding-in-production ch. 2 §5.2.2): a checkpoint at
 * the barrier reaching spp_done when some ideal cumulative count 4, 8, 16, ... lies in
 * [spp_done, next_spp_done): the barrier with the largest cumulative spp not above it. None
 * at the last barrier (the image itself is written then). */
int checkpoint_due(int spp_done, int next_spp_done, int spp_total);

/* The modules' sections. film_load checks the size (and the recorder AOV's presence); -3: an
 * adaptive film of the rule before the pilot rule (not resumable). */
int film_save(const Film *f, FILE *out);
int film_load(Film *f, FILE *in);
/* A loaded shard film fit to merge: every pixel's count equal to the shard's samples, sums
 * finite (film.c). -1 with the first bad pixel in what. */
int film_check(const Film *f, uint64_t samples, char *what, size_t len);
/* The same for a checkpoint's film: a pixel still sampling counts [done, most], one adaptive
 * sampling stopped [1, done]. */
int film_check_counts(const Film *f, uint64_t done, uint64_t most, const char *declares, char *what, size_t len);
int record_save(const Integrator *ig, FILE *out);
int record_load(Integrator *ig, FILE *in);
int guide_save(const Integrator *ig, FILE *out);
int guide_load(Integrator *ig, FILE *in);
int auto_probe_save(const AutoProbe *ap, uint32_t npixels, FILE *out);
int auto_probe_load(AutoProbe *ap, uint32_t npixels, FILE *in);

#endif
