/* renderer/util/threads.c: pthread worker pool behind threadpool_parallel_for. */
#include "threads.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <unistd.h>

typedef struct Job {
    ParallelForFn fn;
    void *ctx;
    size_t n, grain;
    atomic_size_t next;
} Job;

struct ThreadPool {
    int num_threads;           /* including the caller */
    pthread_t *workers;        /* num_threads - 1 */
    int *worker_index;
    pthread_mutex_t mutex;
    pthread_cond_t wake, done;
    Job *job;
    atomic_ulong generation;   /* bumped per job so waiting workers notice a new one */
    atomic_int busy;           /* workers still inside the current job */
    atomic_int quit;
};

int threads_available_cores(void) {
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (int)n : 1;
}

static void run_chunks(Job *job, int thread_index) {
    for (;;) {
        size_t begin = atomic_fetch_add(&job->next, job->grain);
        if (begin >= job->n) break;
        size_t end = begin + job->grain < job->n ? begin + job->grain : job->n;
        job->fn(job->ctx, begin, end, thread_index);
    }
}

typedef struct { ThreadPool *pool; int index; } WorkerArg;

/* Parallel loops come in quick succession (one per batch of a few milliseconds, and the
 * cache point build's many short loops), so a worker spins for a while before sleeping, and
 * the caller spins before waiting: a condition variable round trip per loop is then rare. */
#define SPIN_ITERATIONS 2000

static inline void cpu_relax(void) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
}

static void *worker_main(void *arg) {
    ThreadPool *pool = ((WorkerArg *)arg)->pool;
    int index = ((WorkerArg *)arg)->index;
    free(arg);
    unsigned long seen = 0;
    for (;;) {
        for (int spin = 0; spin < SPIN_ITERATIONS && atomic_load(&pool->generation) == seen && !atomic_load(&pool->quit); ++spin)
            cpu_relax();
        if (atomic_load(&pool->generation) == seen && !atomic_load(&pool->quit)) {
            pthread_mutex_lock(&pool->mutex);
            while (!atomic_load(&pool->quit) && atomic_load(&pool->generation) == seen)
                pthread_cond_wait(&pool->wake, &pool->mutex);
            pthread_mutex_unlock(&pool->mutex);
        }
        if (atomic_load(&pool->quit)) break;
        seen = atomic_load(&pool->generation);
        Job *job = pool->job;
        run_chunks(job, index);
        if (atomic_fetch_sub(&pool->busy, 1) == 1) {
            pthread_mutex_lock(&pool->mutex);
            pthread_cond_signal(&pool->done);
            pthread_mutex_unlock(&pool->mutex);
        }
    }
    return NULL;
}

ThreadPool *threadpool_create(int num_threads) {
    if (num_threads <= 0) num_threads = threads_available_cores();
    ThreadPool *pool = calloc(1, sizeof *pool);
    if (!pool) return NULL;
    pool->num_threads = num_threads;
    pthread_mutex_init(&pool->mutex, NULL);
    pthread_cond_init(&pool->wake, NULL);
    pthread_cond_init(&pool->done, NULL);
    pool->workers = calloc((size_t)num_threads, sizeof *pool->workers);
    if (!pool->workers) { free(pool); return NULL; }
    for (int i = 1; i < num_threads; ++i) {
        WorkerArg *arg = malloc(sizeof *arg);
        if (!arg) { pool->num_threads = i; break; }
        arg->pool = pool; arg->index = i;
        if (pthread_create(&pool->workers[i - 1], NULL, worker_main, arg) != 0) {
            free(arg); pool->num_threads = i; break;
        }
    }
    return pool;
}

void threadpool_destroy(ThreadPool *pool) {
    if (!pool) return;
    pthread_mutex_lock(&pool->mutex);
    atomic_store(&pool->quit, 1);
    pthread_cond_broadcast(&pool->wake);
    pthread_mutex_unlock(&pool->mutex);
    for (int i = 1; i < pool->num_threads; ++i) pthread_join(pool->workers[i - 1], NULL);
    pthread_mutex_destroy(&pool->mutex);
    pthread_cond_destroy(&pool->wake);
    pthread_cond_destroy(&pool->done);
    free(pool->workers);
    free(pool);
}

int threadpool_size(const ThreadPool *pool) { return pool->num_threads; }

void threadpool_parallel_for(ThreadPool *pool, size_t n, size_t grain, ParallelForFn fn, void *ctx) {
    if (n == 0) return;
    if (grain == 0) grain = 1;
    Job job = {.fn = fn, .ctx = ctx, .n = n, .grain = grain};
    atomic_init(&job.next, 0);
    if (pool->num_threads == 1 || n <= grain) {
        run_chunks(&job, 0);
        return;
    }
    /* publish the job, then bump the generation (workers read the job after seeing it) */
    pool->job = &job;
    atomic_store(&pool->busy, pool->num_threads - 1);
    pthread_mutex_lock(&pool->mutex);
    atomic_fetch_add(&pool->generation, 1);
    pthread_cond_broadcast(&pool->wake);
    pthread_mutex_unlock(&pool->mutex);
    run_chunks(&job, 0);
    for (int spin = 0; spin < SPIN_ITERATIONS && atomic_load(&pool->busy) > 0; ++spin) cpu_relax();
    if (atomic_load(&pool->busy) > 0) {
        pthread_mutex_lock(&pool->mutex);
        while (atomic_load(&pool->busy) > 0) pthread_cond_wait(&pool->done, &pool->mutex);
        pthread_mutex_unlock(&pool->mutex);
    }
    pool->job = NULL;
}
