/* renderer/app/checkpoint.h (private): checkpoints and film files (checkpoint.c), and the film's
 * save/load pair (film.c). The integrator's features save and load their own state through the
 * feature table (feature.h), the light sampler through its ops, guiding's fields and the cache
 * points in their modules; all of them write with ckpt_io.h.
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

#include "ckpt_io.h"
#include "integrator.h"

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

#endif
