/* renderer/util/threads.h (private): a fixed pool of worker threads and a parallel-for.
 *
 * Work items are handed out in chunks from an atomic counter, so which thread runs which
 * chunk varies between runs. Stages therefore must make each item's result independent of
 * the thread that computes it (they do: per-path state, counter-based RNG, no shared sums). */
#ifndef CANDELA_THREADS_H
#define CANDELA_THREADS_H

#include <stddef.h>

typedef struct ThreadPool ThreadPool;

/* fn(ctx, begin, end, thread_index) processes items [begin, end). */
typedef void (*ParallelForFn)(void *ctx, size_t begin, size_t end, int thread_index);

ThreadPool *threadpool_create(int num_threads); /* num_threads <= 0: all cores */
void threadpool_destroy(ThreadPool *pool);
int threadpool_size(const ThreadPool *pool);
/* Runs fn over [0, n) in chunks of `grain` items on all pool threads (the caller's thread
 * is thread 0) and returns when every item is done. */
void threadpool_parallel_for(ThreadPool *pool, size_t n, size_t grain, ParallelForFn fn, void *ctx);
int threads_available_cores(void);

#endif
