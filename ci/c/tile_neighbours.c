// Why the passes hand out work with `SplitRange` (emu/src/sync/split.rs): one locked add per
// pixel of a 2048x2048 buffer of 32-bit words (page-aligned), 64x64 tiles, row by row
// inside a tile, on one thread and then on two, with the tiles handed out three ways:
//   counter:  one shared counter (the two threads on neighbouring tiles of a row at once),
//   halves:   each thread its own half of the tiles (far apart),
//   blocks:   one shared counter, but each tile a contiguous 16 KiB block (no rows).
// The two threads never touch one cache line; where they work side by side in a row of
// tiles, each core's prefetchers fetch the lines of the other's next tile, and the locked
// adds then wait for them to come back. docs/performance.md, "2026-11-27, night".
// Build and run: gcc -O2 -pthread -o /tmp/tile_neighbours ci/c/tile_neighbours.c && /tmp/tile_neighbours
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define W 2048
#define H 2048
#define T 64
#define TILES ((W / T) * (H / T))

enum order { COUNTER, HALVES, BLOCKS };

static uint32_t *buf;
static enum order order;
static int next_tile;

static double now_ms(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

static void add_tile(int t) {
    if (order == BLOCKS) {
        for (int i = 0; i < T * T; i++) __atomic_fetch_add(&buf[(size_t)t * T * T + i], 1, __ATOMIC_ACQ_REL);
        return;
    }
    int x0 = (t % (W / T)) * T, y0 = (t / (W / T)) * T;
    for (int y = y0; y < y0 + T; y++)
        for (int x = x0; x < x0 + T; x++) __atomic_fetch_add(&buf[(size_t)y * W + x], 1, __ATOMIC_ACQ_REL);
}

struct part {
    int me, threads;
};

static void *run(void *arg) {
    struct part *p = arg;
    if (order == HALVES) {
        for (int t = TILES * p->me / p->threads; t < TILES * (p->me + 1) / p->threads; t++) add_tile(t);
        return NULL;
    }
    for (;;) {
        int t = __atomic_fetch_add(&next_tile, 1, __ATOMIC_RELAXED);
        if (t >= TILES) return NULL;
        add_tile(t);
    }
}

static double timed(int threads) {
    next_tile = 0;
    struct part parts[2] = {{0, threads}, {1, threads}};
    pthread_t other;
    double t = now_ms();
    if (threads == 2) pthread_create(&other, NULL, run, &parts[1]);
    run(&parts[0]);
    if (threads == 2) pthread_join(other, NULL);
    return now_ms() - t;
}

int main(void) {
    buf = aligned_alloc(4096, (size_t)W * H * 4);
    memset(buf, 0, (size_t)W * H * 4);
    const char *names[] = {"counter", "halves", "blocks"};
    for (int round = 0; round < 3; round++) {
        for (order = COUNTER; order <= BLOCKS; order++) {
            double one = timed(1), two = timed(2);
            printf("%-8s 1 thread %6.2f ms (%.2f ns an add), 2 threads %6.2f ms: x%.2f\n", names[order], one,
                   one * 1e6 / ((double)W * H), two, one / two);
        }
    }
    return 0;
}
