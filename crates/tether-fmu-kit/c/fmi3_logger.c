/* A model's own messages in an FMI 3.0 build: the kit hands a model the
 * environment's logger with the fmi2CallbackLogger signature (C-variadic, a
 * printf format), which stable Rust cannot define. This function has that
 * signature, formats the message and passes it to the importer's
 * fmi3LogMessageCallback, whose instance environment it finds in its first
 * argument. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

typedef void (*tether_kit_fmi3_log)(void *instance_environment, int status,
                                    const char *category, const char *message);

/* The component environment of an FMI 3.0 instance (ffi::fmi3::Fmi3LogEnv). */
typedef struct {
    tether_kit_fmi3_log log;
    void *instance_environment;
} tether_kit_fmi3_env;

void tether_kit_fmi3_logger(void *component_environment, const char *instance_name,
                            int status, const char *category, const char *format, ...) {
    tether_kit_fmi3_env *env = component_environment;
    char small[512];
    va_list args;
    int n;
    (void)instance_name;
    if (env == NULL || env->log == NULL || format == NULL) {
        return;
    }
    va_start(args, format);
    n = vsnprintf(small, sizeof small, format, args);
    va_end(args);
    if (n < 0) {
        return;
    }
    if ((size_t)n < sizeof small) {
        env->log(env->instance_environment, status, category, small);
        return;
    }
    {
        char *big = malloc((size_t)n + 1);
        if (big == NULL) {
            return;
        }
        va_start(args, format);
        vsnprintf(big, (size_t)n + 1, format, args);
        va_end(args);
        env->log(env->instance_environment, status, category, big);
        free(big);
    }
}
