/* The C floor with synthetic work added at four points of every macro step:
 * an experiment on what the host's busy state makes expensive
 * (docs/performance.md, "Extra data and extra code, tried on the C floor";
 * tools/bench/extra_ab.py runs it). Modes come in pairs that differ in
 * one thing only:
 *
 *   1  96 loads a step, each from a different 64-byte line (6 KiB of data)
 *   2  the same 96 loads, all from one line
 *   3  1280 loads a step as straight-line code (four ~2.5 KiB blocks)
 *   4  the same 1280 loads in a loop of eight loads an iteration
 *
 * Mode 0 adds nothing but the call. The loads are volatile and independent
 * of each other, so their cost is whatever fetching the data or the code
 * costs. The floor compiled here is a second copy, `tether_floor_extra_run`;
 * in the measured floor (`tether_floor_run`) the hooks are empty. */

#define LINES 96
#define WORDS (LINES * 8)

static volatile double extra_data[WORDS] __attribute__((aligned(64)));
/* Per thread, so that runs on different threads cannot race on them. */
static _Thread_local int extra_mode;
static _Thread_local int extra_index[LINES];

/* Choose the mode of the next tether_floor_extra_run on this thread. */
void tether_extra_set(int mode) {
    extra_mode = mode;
    for (int i = 0; i < LINES; i++) extra_index[i] = mode == 1 ? i * 8 : i % 8;
}

/* Loads of the eight words of line `n`. */
#define L1(n, k) (void)extra_data[8 * (n) + (k) % 8];
#define L8(n) L1(n, 0) L1(n, 1) L1(n, 2) L1(n, 3) L1(n, 4) L1(n, 5) L1(n, 6) L1(n, 7)
#define L64(n) L8(n) L8(n) L8(n) L8(n) L8(n) L8(n) L8(n) L8(n)
#define L320(n) L64(n) L64(n) L64(n) L64(n) L64(n)

/* Four different blocks (each reads its own line, so that the compiler cannot
 * fold them into one), 8 bytes of code a load: ~10 KiB in all. */
__attribute__((noinline)) static void straight0(void) { L320(0) }
__attribute__((noinline)) static void straight1(void) { L320(1) }
__attribute__((noinline)) static void straight2(void) { L320(2) }
__attribute__((noinline)) static void straight3(void) { L320(3) }

__attribute__((noinline)) static void looped(int point) {
    for (int i = 0; i < 40; i++) {
        L8(point)
    }
}

__attribute__((noinline)) static void extra(int point) {
    switch (extra_mode) {
    case 1:
    case 2:
        for (int i = point * (LINES / 4); i < (point + 1) * (LINES / 4); i++)
            (void)extra_data[extra_index[i]];
        break;
    case 3:
        switch (point) {
        case 0: straight0(); break;
        case 1: straight1(); break;
        case 2: straight2(); break;
        default: straight3(); break;
        }
        break;
    case 4:
        looped(point);
        break;
    default:
        break;
    }
}

#define FLOOR_EXTRA(point) extra(point)
#define tether_floor_run tether_floor_extra_run
#include "floor.c"
