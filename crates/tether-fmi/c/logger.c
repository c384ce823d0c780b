/*
 * C shim for the FMI 2.0 callbacks that stable Rust cannot define.
 *
 * fmi2CallbackLogger is C-variadic (printf-style). tether_fmi_logger formats the message
 * with vsnprintf and hands the finished string to a non-variadic Rust function whose
 * address is stored at the start of the component environment the master passed to
 * fmi2Instantiate. The memory callbacks forward to calloc/free.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

typedef void (*tether_fmi_sink)(const void *env, const char *instance, int status,
                                const char *category, const char *message);

/* Whether a message would be shown: not below the active level, not rate-limited.
 * Asked before formatting, so that discarded messages cost no vsnprintf. */
typedef int (*tether_fmi_wanted)(const void *env, int status, const char *category);

/* The first fields of the Rust `LogEnv` (#[repr(C)]). */
typedef struct {
    tether_fmi_sink sink;
    tether_fmi_wanted wanted;
} tether_fmi_env_header;

void tether_fmi_logger(void *env, const char *instance, int status, const char *category,
                       const char *message, ...) {
    const tether_fmi_env_header *header = (const tether_fmi_env_header *)env;
    char stack_buffer[1024];
    va_list args;
    int needed;
    char *heap_buffer;

    if (header == NULL || header->sink == NULL) {
        return;
    }
    if (header->wanted != NULL && !header->wanted(env, status, category)) {
        return;
    }
    if (message == NULL) {
        header->sink(env, instance, status, category, "");
        return;
    }
    va_start(args, message);
    needed = vsnprintf(stack_buffer, sizeof stack_buffer, message, args);
    va_end(args);
    if (needed < 0) {
        /* Formatting failed: pass the raw format string rather than nothing. */
        header->sink(env, instance, status, category, message);
        return;
    }
    if ((size_t)needed < sizeof stack_buffer) {
        header->sink(env, instance, status, category, stack_buffer);
        return;
    }
    heap_buffer = (char *)malloc((size_t)needed + 1);
    if (heap_buffer == NULL) {
        /* Out of memory: the truncated message is better than none. */
        header->sink(env, instance, status, category, stack_buffer);
        return;
    }
    va_start(args, message);
    vsnprintf(heap_buffer, (size_t)needed + 1, message, args);
    va_end(args);
    header->sink(env, instance, status, category, heap_buffer);
    free(heap_buffer);
}

void *tether_fmi_calloc(size_t nobj, size_t size) { return calloc(nobj, size); }

void tether_fmi_free(void *obj) { free(obj); }
