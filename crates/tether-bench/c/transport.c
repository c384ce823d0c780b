/* Round trips between two processes, for the choice of the transport of
 * isolated FMU instances (docs/performance.md, "Isolation"): a request of
 * `size` bytes from the parent, the same bytes back from a forked child, `n`
 * times; returns microseconds per round trip, or a negative number on error.
 *   kind 0: two pipes (one each way; what Tether uses)
 *   kind 1: a Unix stream socket pair
 *   kind 2: shared memory, futex wait/wake on a sequence word (no spinning)
 *   kind 3: shared memory, both sides spinning (keeps two cores busy: a
 *           reference, not a candidate)
 *   kind 4: a TCP connection on 127.0.0.1 with TCP_NODELAY (what remote
 *           hosts use)
 *   kind 5: two pipes, both processes on the parent's current core (no
 *           wake-up of another core: see tether_one_core)
 * The child does only read/write/futex system calls and _exit (safe after
 * fork in a threaded process). */
#define _GNU_SOURCE
#include <linux/futex.h>
#include <sched.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static int full(int fd, char *buf, size_t n, int reading) {
    size_t done = 0;
    while (done < n) {
        ssize_t r = reading ? read(fd, buf + done, n - done) : write(fd, buf + done, n - done);
        if (r <= 0) return -1;
        done += (size_t)r;
    }
    return 0;
}

struct shared {
    _Atomic uint32_t seq; /* odd: a request is waiting; even: the reply is there */
    char data[4096];
};

static void futex_wait(_Atomic uint32_t *word, uint32_t value) {
    syscall(SYS_futex, (uint32_t *)word, FUTEX_WAIT, value, NULL, NULL, 0);
}

static void futex_wake(_Atomic uint32_t *word) {
    syscall(SYS_futex, (uint32_t *)word, FUTEX_WAKE, 1, NULL, NULL, 0);
}

/* Waits until *word != value: spinning, or sleeping on the futex. */
static void await_change(_Atomic uint32_t *word, uint32_t value, int spin) {
    while (atomic_load_explicit(word, memory_order_acquire) == value) {
        if (!spin) futex_wait(word, value);
    }
}

static double by_fds(int kind, long n, size_t size) {
    int up[2], down[2];
    if (kind == 0) {
        if (pipe(up) || pipe(down)) return -1;
    } else if (kind == 1) {
        int pair[2];
        if (socketpair(AF_UNIX, SOCK_STREAM, 0, pair)) return -1;
        up[0] = pair[1]; up[1] = pair[0]; down[0] = pair[0]; down[1] = pair[1];
    } else {
        struct sockaddr_in at;
        socklen_t len = sizeof at;
        memset(&at, 0, sizeof at);
        at.sin_family = AF_INET;
        at.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        int listener = socket(AF_INET, SOCK_STREAM, 0);
        if (listener < 0 || bind(listener, (struct sockaddr *)&at, sizeof at) || listen(listener, 1) ||
            getsockname(listener, (struct sockaddr *)&at, &len))
            return -1;
        int client = socket(AF_INET, SOCK_STREAM, 0);
        if (client < 0 || connect(client, (struct sockaddr *)&at, sizeof at)) return -1;
        int server = accept(listener, NULL, NULL);
        close(listener);
        int one = 1;
        if (server < 0 || setsockopt(client, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one) ||
            setsockopt(server, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one))
            return -1;
        up[0] = server; up[1] = client; down[0] = client; down[1] = server;
    }
    char buf[4096];
    memset(buf, 1, sizeof buf);
    pid_t child = fork();
    if (child < 0) return -1;
    if (child == 0) {
        for (long i = 0; i < n; i++) {
            if (full(up[0], buf, size, 1) || full(down[1], buf, size, 0)) _exit(1);
        }
        _exit(0);
    }
    double t0 = now();
    for (long i = 0; i < n; i++) {
        if (full(up[1], buf, size, 0) || full(down[0], buf, size, 1)) {
            kill(child, SIGKILL);
            break;
        }
    }
    double t1 = now();
    int status = 0;
    waitpid(child, &status, 0);
    if (kind == 0) { close(up[0]); close(up[1]); close(down[0]); close(down[1]); }
    else { close(up[0]); close(up[1]); }  /* a socket pair or a connection */
    return WIFEXITED(status) && WEXITSTATUS(status) == 0 ? (t1 - t0) / (double)n * 1e6 : -1;
}

static double by_memory(long n, size_t size, int spin) {
    struct shared *s = mmap(NULL, sizeof *s, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    if (s == MAP_FAILED) return -1;
    atomic_store(&s->seq, 0);
    char buf[4096];
    memset(buf, 1, sizeof buf);
    pid_t child = fork();
    if (child < 0) return -1;
    if (child == 0) {
        for (long i = 0; i < n; i++) {
            uint32_t even = (uint32_t)(2 * i);
            await_change(&s->seq, even, spin);
            memcpy(buf, s->data, size);
            memcpy(s->data, buf, size);
            atomic_store_explicit(&s->seq, even + 2, memory_order_release);
            if (!spin) futex_wake(&s->seq);
        }
        _exit(0);
    }
    double t0 = now();
    for (long i = 0; i < n; i++) {
        uint32_t even = (uint32_t)(2 * i);
        memcpy(s->data, buf, size);
        atomic_store_explicit(&s->seq, even + 1, memory_order_release);
        if (!spin) futex_wake(&s->seq);
        await_change(&s->seq, even + 1, spin);
        memcpy(buf, s->data, size);
    }
    double t1 = now();
    int status = 0;
    waitpid(child, &status, 0);
    munmap(s, sizeof *s);
    return WIFEXITED(status) && WEXITSTATUS(status) == 0 ? (t1 - t0) / (double)n * 1e6 : -1;
}

/* on = 1: pins the calling thread (and so the processes it starts from now
 * on) to the core it runs on, keeping its former set of cores; on = 0: gives
 * that set back. Returns 0, or -1 when the system refuses. */
int tether_one_core(int on) {
    static cpu_set_t former;
    static int pinned = 0;
    if (!on) {
        if (!pinned) return 0;
        pinned = 0;
        return sched_setaffinity(0, sizeof former, &former);
    }
    int cpu = sched_getcpu();
    if (pinned || cpu < 0 || sched_getaffinity(0, sizeof former, &former)) return -1;
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(cpu, &one);
    if (sched_setaffinity(0, sizeof one, &one)) return -1;
    pinned = 1;
    return 0;
}

double tether_transport_roundtrip(int kind, long n, long size) {
    if (size < 1 || size > 4096) return -1;
    if (kind == 5) {
        if (tether_one_core(1)) return -1;
        double us = by_fds(0, n, (size_t)size);
        tether_one_core(0);
        return us;
    }
    if (kind <= 1 || kind == 4) return by_fds(kind, n, (size_t)size);
    return by_memory(n, (size_t)size, kind == 3);
}
