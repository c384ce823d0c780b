/* Host-state probe for the floor bench (docs/performance.md, "Reading the
 * numbers"). On a shared host another tenant's work can take part of this
 * core's execution resources (on a hyperthreaded host, a busy sibling thread):
 * independent work then runs at a lower rate while a chain of dependent
 * instructions barely changes. The two loops below time both:
 * nanoseconds per iteration of eight interleaved add/xor chains (16 integer
 * operations an iteration, most of them independent of each other, so limited
 * by how many the core issues per cycle) and
 * of one dependent multiply-add (limited by its latency). */
#include <stdint.h>
#include <time.h>

volatile uint64_t tether_probe_sink;

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

double tether_probe_independent(long n) {
    uint64_t a = tether_probe_sink | 1, b = 2, c = 3, d = 4, e = 5, f = 6, g = 7, h = 8;
    double t0 = now();
    for (long i = 0; i < n; i++) {
        a += b ^ (uint64_t)i; b += c ^ (uint64_t)i; c += d ^ (uint64_t)i; d += e ^ (uint64_t)i;
        e += f ^ (uint64_t)i; f += g ^ (uint64_t)i; g += h ^ (uint64_t)i; h += a ^ (uint64_t)i;
    }
    double t1 = now();
    tether_probe_sink = a + b + c + d + e + f + g + h;
    return (t1 - t0) / (double)n * 1e9;
}

double tether_probe_dependent(long n) {
    uint64_t x = tether_probe_sink | 1;
    double t0 = now();
    for (long i = 0; i < n; i++) {
        x = x * 3 + 1;
    }
    double t1 = now();
    tether_probe_sink = x;
    return (t1 - t0) / (double)n * 1e9;
}
