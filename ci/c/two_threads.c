// How much two threads get out of this machine's two vCPUs: a throughput-bound loop
// (eight independent chains of adds and xors, no memory) on one thread, then twice the work
// on two threads at once. Two cores would take the same time for both; two hyperthreads of
// one core (or a busy host) take longer. Four rounds.
// Build and run: gcc -O2 -pthread -o /tmp/two_threads ci/c/two_threads.c && /tmp/two_threads
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <time.h>

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

static void *work(void *arg) {
    (void)arg;
    uint64_t a0 = 1, a1 = 2, a2 = 3, a3 = 4, a4 = 5, a5 = 6, a6 = 7, a7 = 8;
    for (uint64_t i = 0; i < 300000000; i++) {
        a0 += i;
        a1 ^= i;
        a2 += a0;
        a3 ^= a1;
        a4 += i;
        a5 ^= i;
        a6 += a4;
        a7 ^= a5;
        // Keeps the chains in registers and the loop from being folded away.
        __asm__ volatile("" : "+r"(a0), "+r"(a1), "+r"(a2), "+r"(a3), "+r"(a4), "+r"(a5),
                         "+r"(a6), "+r"(a7));
    }
    return (void *)(uintptr_t)(a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7);
}

int main(void) {
    for (int r = 0; r < 4; r++) {
        double t = now();
        work(NULL);
        double one = now() - t;
        pthread_t a, b;
        t = now();
        pthread_create(&a, NULL, work, NULL);
        pthread_create(&b, NULL, work, NULL);
        pthread_join(a, NULL);
        pthread_join(b, NULL);
        double two = now() - t;
        printf("1 thread %.3f s; 2 threads, twice the work, %.3f s: %.2fx the throughput\n", one,
               two, 2 * one / two);
    }
    return 0;
}
