// What a scope of two spawned threads costs (create and join two pthreads that do almost
// nothing), as each `std::thread::scope` of the executors does per pass.
// Build and run: gcc -O2 -o /tmp/spawn_scope ci/c/spawn_scope.c -lpthread && /tmp/spawn_scope
#include <pthread.h>
#include <stdio.h>
#include <time.h>
static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}
static void *work(void *a) {
    volatile int x = 0;
    for (int i = 0; i < 1000; i++) x += i;
    return a;
}
int main(void) {
    pthread_t t[2];
    int n = 2000;
    double s = now();
    for (int i = 0; i < n; i++) {
        for (int k = 0; k < 2; k++) pthread_create(&t[k], 0, work, 0);
        for (int k = 0; k < 2; k++) pthread_join(t[k], 0);
    }
    printf("scope of 2 spawns: %.1f us\n", (now() - s) / n * 1e6);
    return 0;
}
