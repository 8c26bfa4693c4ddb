// What one `lock`ed add costs on this machine, with nothing around it: the floor under a
// `count` fragment (docs/performance.md, "2026-11-26, evening").
//  1. In order over an array that fits in L1 (4096 words), then over 16 MiB (a 2048x2048
//     buffer of counts).
//  2. Over bunny-like covered runs: triangles of 22 rows whose runs are up to 11 pixels
//     wide, at random places of a 2048x2048 buffer, then at places that drift as a mesh's
//     triangles do; each frame on a freshly zeroed buffer.
// Build and run: gcc -O2 -o /tmp/lock_floor ci/c/lock_floor.c && /tmp/lock_floor
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define W 2048

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

static void in_order(size_t n, int reps) {
    uint32_t *a = calloc(n, 4);
    double t = now();
    for (int r = 0; r < reps; r++)
        for (size_t i = 0; i < n; i++) __atomic_fetch_add(&a[i], 1, __ATOMIC_ACQ_REL);
    printf("in order over %zu words: %.2f ns an add\n", n, (now() - t) * 1e9 / ((double)n * reps));
    free(a);
}

static void runs(int drifting, int ntri, int rows) {
    uint32_t *a = aligned_alloc(64, (size_t)W * W * 4);
    int *tx = malloc(ntri * sizeof(int)), *ty = malloc(ntri * sizeof(int));
    srand(1);
    int x = 400, y = 400;
    for (int i = 0; i < ntri; i++) {
        if (drifting) {
            x += rand() % 21 - 10;
            y += rand() % 21 - 10;
            x = x < 100 ? 100 : x > 1800 ? 1800 : x;
            y = y < 100 ? 100 : y > 1800 ? 1800 : y;
        } else {
            x = 400 + rand() % 1100;
            y = 400 + rand() % 1100;
        }
        tx[i] = x;
        ty[i] = y;
    }
    double best = 1e9;
    long n = 0;
    for (int f = 0; f < 6; f++) {
        memset(a, 0, (size_t)W * W * 4);
        double t = now();
        n = 0;
        for (int i = 0; i < ntri; i++)
            for (int r = 0; r < rows; r++) {
                int len = 1 + (r * rows - r * r) / (rows / 2 + 1);
                uint32_t *row = a + (size_t)(ty[i] + r) * W + tx[i];
                for (int k = 0; k < len; k++, n++) __atomic_fetch_add(&row[k], 1, __ATOMIC_ACQ_REL);
            }
        double dt = now() - t;
        best = dt < best ? dt : best;
    }
    printf("%s runs: %ld adds, best of 6 frames %.2f ms, %.2f ns an add\n",
           drifting ? "drifting" : "random", n, best * 1e3, best * 1e9 / n);
    free(a);
    free(tx);
    free(ty);
}

int main(void) {
    in_order(4096, 20000);
    in_order((size_t)W * W, 5);
    runs(0, 3674, 22);
    runs(1, 3674, 22);
    return 0;
}
