// Locked adds over a fresh 16 MB buffer, tile by tile (64x64 tiles, one add per pixel,
// a fifth of the tiles skipped), as the `count` frame does them: the machine's cost per
// add, without prefetch (mode 0), with the first line of the row 8 rows ahead (1) and with
// every line of it (2). Best of 15 runs each.
// Build and run: gcc -O2 -o /tmp/locked_adds ci/c/locked_adds.c && for m in 0 1 2; do /tmp/locked_adds $m; done
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include <xmmintrin.h>
static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}
#define W 2048
int main(int argc, char **argv) {
    int mode = argc > 1 ? atoi(argv[1]) : 0;
    double best = 1e9;
    long adds = 0;
    for (int rep = 0; rep < 15; rep++) {
        _Atomic uint32_t *b = calloc((size_t)W * W, 4);
        adds = 0;
        double s = now();
        for (int ty = 0; ty < W; ty += 64)
            for (int tx = 0; tx < W; tx += 64) {
                if (((tx / 64) + (ty / 64)) % 5 == 0) continue;
                for (int y = ty; y < ty + 64; y++) {
                    if (mode && y + 8 < W) {
                        char *p = (char *)&b[(size_t)(y + 8) * W + tx];
                        for (int l = 0; l < (mode == 2 ? 4 : 1); l++) _mm_prefetch(p + 64 * l, _MM_HINT_T0);
                    }
                    for (int x = tx; x < tx + 64; x++, adds++)
                        atomic_fetch_add_explicit(&b[(size_t)y * W + x], 1, memory_order_acq_rel);
                }
            }
        double t = now() - s;
        if (t < best) best = t;
        free(b);
    }
    printf("mode %d: best %.2f ms, %.2f ns per add\n", mode, best * 1e3, best * 1e9 / adds);
    return 0;
}
