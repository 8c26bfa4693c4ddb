// Does a locked add cost more when the values it needs are reloaded from memory after the
// previous one? (docs/performance.md, "2026-11-27, morning", tried and dropped.) The counting
// loop reloads a few values from the stack per fragment (the kernel's buffer handle, its
// bound, the row's base); x86 locked instructions order the loads after them.
//   mode 0: the add alone, rows of 1024 pixels of a 2048x2048 buffer of counters;
//   mode 1: base and buffer pointer reloaded (volatile) before each add, a counter bumped;
//   mode 2: as 1, plus a dependent load of a bound through a pointer and a bounds check.
// Build and run: gcc -O2 -o /tmp/lock_chain ci/c/lock_chain.c && /tmp/lock_chain
// Measured (Zen 4 VM): 2.30-2.41, 2.34-2.61, 2.30-2.49 ns an add: no difference.
#include <stdio.h>
#include <stdlib.h>
#include <stdint.h>
#include <time.h>
#define N (2048*2048)
static double now(){struct timespec t;clock_gettime(CLOCK_MONOTONIC,&t);return t.tv_sec*1e3+t.tv_nsec/1e6;}
struct K { uint32_t id, len; } ;
int main(){
  uint32_t *buf = aligned_alloc(4096, N*4); for(long i=0;i<N;i++) buf[i]=0;
  volatile struct K kk = {1, N}; struct K * volatile kp = (struct K*)&kk;
  volatile uint32_t * volatile bp = buf; volatile long base = 0; volatile long steps=0;
  for (int r=0;r<3;r++){
   for (int mode=0; mode<3; mode++){
    double t=now(); long n=0;
    for (int rep=0; rep<8; rep++) for (long y=0;y<512;y++) for(long x=0;x<1024;x++){
      long idx = y*2048 + x;
      if (mode==0) { __atomic_fetch_add(&buf[idx],1,__ATOMIC_RELAXED); }
      else if (mode==1) { long b = base; uint32_t *p=(uint32_t*)bp; __atomic_fetch_add(&p[b+idx],1,__ATOMIC_RELAXED); steps++; }
      else { struct K* k = kp; uint32_t len = k->len; long b = base; uint32_t *p=(uint32_t*)bp; if ((uint32_t)(b+idx) >= len) abort(); __atomic_fetch_add(&p[b+idx],1,__ATOMIC_RELAXED); steps++; }
      n++;
    }
    printf("mode %d: %.2f ns/add\n", mode, (now()-t)*1e6/n);
   }
  }
}
