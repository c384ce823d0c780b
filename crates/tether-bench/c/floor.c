/*
 * The FMI floor: a hand-written C master for the paper's oscillator pair that
 * makes exactly the FMI calls of Tether's predictor/corrector macro step
 * (Method 1, Baumgarte, one constraint g = x2 - x1 driving F1 = +lambda,
 * F2 = -lambda) and does the same scalar arithmetic, with nothing else: no
 * error context, no observers, no generality. Its time per macro step is the
 * floor the master's overhead is measured against.
 *
 * Per macro step and instance (k = polynomial degree):
 *   predictor:  fmi2GetFMUstate (reusing the state), fmi2SetReal(F),
 *               [fmi2SetRealInputDerivatives], fmi2DoStep, fmi2GetReal(x, v, a)
 *   perturbed:  fmi2SetFMUstate, fmi2SetReal, [derivatives], fmi2DoStep, fmi2GetReal
 *   corrector:  fmi2SetFMUstate, fmi2SetReal, [derivatives], fmi2DoStep
 *   accepted:   fmi2GetReal(x, v, a, x, v, a): the coupled and the recorded outputs in one call
 */
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef int fmi2Status; /* fmi2OK = 0, fmi2Warning = 1 */

typedef struct {
    void (*logger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef fmi2Component (*InstantiateFn)(fmi2String, int, fmi2String, fmi2String,
                                     const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef void (*FreeInstanceFn)(fmi2Component);
typedef fmi2Status (*SetupExperimentFn)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean,
                                      fmi2Real);
typedef fmi2Status (*PlainFn)(fmi2Component);
typedef fmi2Status (*SetRealFn)(fmi2Component, const fmi2ValueReference *, size_t, const fmi2Real *);
typedef fmi2Status (*GetRealFn)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
typedef fmi2Status (*SetBooleanFn)(fmi2Component, const fmi2ValueReference *, size_t,
                                 const fmi2Boolean *);
typedef fmi2Status (*InputDerivativesFn)(fmi2Component, const fmi2ValueReference *, size_t,
                                       const fmi2Integer *, const fmi2Real *);
typedef fmi2Status (*GetStateFn)(fmi2Component, fmi2FMUstate *);
typedef fmi2Status (*SetStateFn)(fmi2Component, fmi2FMUstate);
typedef fmi2Status (*FreeStateFn)(fmi2Component, fmi2FMUstate *);
typedef fmi2Status (*DoStepFn)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);

/* What to run; filled by the Rust side (same layout as `FloorConfig`). */
typedef struct {
    const char *library;
    const char *guid;
    const char *resources;
    double m[2], c, d, x0, v0;
    int exact;
    int order;
    double beta, gamma, epsilon, h, start, lambda0;
    long steps;
    unsigned vr_m, vr_c, vr_d, vr_x0, vr_v0, vr_exact, vr_f, vr_x, vr_v, vr_a;
} FloorConfig;

/* What happened (same layout as `FloorResult`). */
typedef struct {
    double seconds;
    double lambda, x1;
    /* Per instance: doStep, getFMUstate, setFMUstate, setReal, getReal,
     * setRealInputDerivatives. */
    long calls[2][6];
} FloorResult;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env; (void)name; (void)status; (void)category; (void)message;
}

typedef struct { double value, d1, d2; } Taylor;

static Taylor extrapolation(const double *hist, int degree, double h) {
    Taylor t = {hist[0], 0.0, 0.0};
    if (degree == 1) {
        t.d1 = (hist[0] - hist[1]) / h;
    } else if (degree >= 2) {
        t.d1 = (3.0 * hist[0] - 4.0 * hist[1] + hist[2]) / (2.0 * h);
        t.d2 = (hist[0] - 2.0 * hist[1] + hist[2]) / (h * h);
    }
    return t;
}

static Taylor interpolation(double u_new, const double *hist, int degree, double h) {
    Taylor t = {u_new, 0.0, 0.0};
    if (degree == 1) {
        t.value = hist[0];
        t.d1 = (u_new - hist[0]) / h;
    } else if (degree >= 2) {
        t.value = hist[0];
        t.d1 = (u_new - hist[1]) / (2.0 * h);
        t.d2 = (u_new - 2.0 * hist[0] + hist[1]) / (h * h);
    }
    return t;
}

static double at(Taylor t, double tau) { return t.value + tau * (t.d1 + 0.5 * tau * t.d2); }

#define CALL(expr)                                                                       \
    do {                                                                                 \
        if ((expr) > 1) {                                                                \
            snprintf(err, errlen, "%s failed", #expr);                                   \
            return -1;                                                                   \
        }                                                                                \
    } while (0)

int tether_floor_run(const FloorConfig *cfg, FloorResult *res, char *err, size_t errlen) {
    memset(res, 0, sizeof *res);
    void *lib = dlopen(cfg->library, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        snprintf(err, errlen, "dlopen: %s", dlerror());
        return -1;
    }
#define SYM(type, name)                                                                  \
    type name = (type)dlsym(lib, "fmi2" #name);                                          \
    if (!name) {                                                                         \
        snprintf(err, errlen, "missing fmi2" #name);                                     \
        return -1;                                                                       \
    }
    SYM(InstantiateFn, Instantiate)
    SYM(FreeInstanceFn, FreeInstance)
    SYM(SetupExperimentFn, SetupExperiment)
    SYM(PlainFn, EnterInitializationMode)
    SYM(PlainFn, ExitInitializationMode)
    SYM(PlainFn, Terminate)
    SYM(SetRealFn, SetReal)
    SYM(GetRealFn, GetReal)
    SYM(SetBooleanFn, SetBoolean)
    SYM(InputDerivativesFn, SetRealInputDerivatives)
    SYM(GetStateFn, GetFMUstate)
    SYM(SetStateFn, SetFMUstate)
    SYM(FreeStateFn, FreeFMUstate)
    SYM(DoStepFn, DoStep)

    fmi2CallbackFunctions callbacks = {logger, NULL, NULL, NULL, NULL};
    fmi2Component inst[2];
    fmi2FMUstate state[2] = {NULL, NULL};
    const double sign[2] = {1.0, -1.0};
    const fmi2ValueReference outs[3] = {cfg->vr_x, cfg->vr_v, cfg->vr_a};
    const fmi2ValueReference accepted[6] = {cfg->vr_x, cfg->vr_v, cfg->vr_a,
                                            cfg->vr_x, cfg->vr_v, cfg->vr_a};
    double read[6];
    const fmi2ValueReference d_vrs[2] = {cfg->vr_f, cfg->vr_f};
    const fmi2Integer d_orders[2] = {1, 2};
    double y[2][3];
    double recorded[2][3];
    const double stop = cfg->start + (double)cfg->steps * cfg->h;

    for (int s = 0; s < 2; s++) {
        const char *name = s == 0 ? "mass1" : "mass2";
        inst[s] = Instantiate(name, 1, cfg->guid, cfg->resources, &callbacks, 0, 0);
        if (!inst[s]) {
            snprintf(err, errlen, "fmi2Instantiate failed");
            return -1;
        }
        const fmi2ValueReference vrs[5] = {cfg->vr_m, cfg->vr_c, cfg->vr_d, cfg->vr_x0, cfg->vr_v0};
        const double vals[5] = {cfg->m[s], cfg->c, cfg->d, cfg->x0, cfg->v0};
        CALL(SetReal(inst[s], vrs, 5, vals));
        const fmi2Boolean exact = cfg->exact;
        CALL(SetBoolean(inst[s], &cfg->vr_exact, 1, &exact));
        CALL(SetupExperiment(inst[s], 0, 0.0, cfg->start, 1, stop));
        CALL(EnterInitializationMode(inst[s]));
        CALL(ExitInitializationMode(inst[s]));
        const double f = 0.0 + sign[s] * cfg->lambda0;
        CALL(SetReal(inst[s], &cfg->vr_f, 1, &f));
    }

    const int k = cfg->order;
    const int nd = k < 2 ? k : 2;
    const double h = cfg->h;
    double hist[3] = {cfg->lambda0, cfg->lambda0, cfg->lambda0};
    long (*calls)[6] = res->calls;

/* Set F (and its derivatives for k > 0) from the polynomial p on instance s. */
#define APPLY(s, p)                                                                      \
    do {                                                                                 \
        const double f = 0.0 + sign[s] * (p).value;                                      \
        CALL(SetReal(inst[s], &cfg->vr_f, 1, &f));                                       \
        calls[s][3]++;                                                                   \
        if (k > 0) {                                                                     \
            const double df[2] = {0.0 + sign[s] * (p).d1, 0.0 + sign[s] * (p).d2};       \
            CALL(SetRealInputDerivatives(inst[s], d_vrs, (size_t)nd, d_orders, df));     \
            calls[s][5]++;                                                               \
        }                                                                                \
    } while (0)

    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (long n = 0; n < cfg->steps; n++) {
        const double t = cfg->start + (double)n * h;
        const int degree_pred = k < n ? k : (int)n;
        const int degree_corr = k < n + 1 ? k : (int)n + 1;

        /* Predictor. */
        const Taylor pred = extrapolation(hist, degree_pred, h);
        const double u_pred = at(pred, h);
        for (int s = 0; s < 2; s++) {
            CALL(GetFMUstate(inst[s], &state[s]));
            calls[s][1]++;
            APPLY(s, pred);
            CALL(DoStep(inst[s], t, h, 1));
            calls[s][0]++;
            CALL(GetReal(inst[s], outs, 3, y[s]));
            calls[s][4]++;
        }
        double g[3];
        for (int l = 0; l < 3; l++) g[l] = 0.0 + y[1][l] + -1.0 * y[0][l];

        /* Perturbed predictor: one column of the interface Jacobian. */
        const double delta = cfg->epsilon * fmax(fabs(hist[0]), 1.0);
        const Taylor pert = interpolation(u_pred + delta, hist, degree_corr, h);
        for (int s = 0; s < 2; s++) {
            CALL(SetFMUstate(inst[s], state[s]));
            calls[s][2]++;
            APPLY(s, pert);
            CALL(DoStep(inst[s], t, h, 1));
            calls[s][0]++;
            CALL(GetReal(inst[s], outs, 3, y[s]));
            calls[s][4]++;
        }
        double jac[3];
        for (int l = 0; l < 3; l++) jac[l] = ((0.0 + y[1][l] + -1.0 * y[0][l]) - g[l]) / delta;

        /* Corrected multiplier (eq. 68), scaled like Tether's solver. */
        double a = jac[0], b = g[0];
        if (cfg->beta > 0.0) { a += cfg->beta * jac[1]; b += cfg->beta * g[1]; }
        if (cfg->gamma > 0.0) { a += cfg->gamma * jac[2]; b += cfg->gamma * g[2]; }
        const double scale = fabs(a);
        a *= 1.0 / scale;
        b /= scale;
        const double corrected = u_pred - (1.0 / a) * b;

        /* Corrector. */
        const Taylor corr = interpolation(corrected, hist, degree_corr, h);
        for (int s = 0; s < 2; s++) {
            CALL(SetFMUstate(inst[s], state[s]));
            calls[s][2]++;
            APPLY(s, corr);
            CALL(DoStep(inst[s], t, h, 1));
            calls[s][0]++;
        }
        hist[2] = hist[1];
        hist[1] = hist[0];
        hist[0] = corrected;

        /* Accepted point: coupled and recorded outputs. */
        for (int s = 0; s < 2; s++) {
            CALL(GetReal(inst[s], accepted, 6, read));
            memcpy(y[s], read, sizeof y[s]);
            memcpy(recorded[s], read + 3, sizeof recorded[s]);
            calls[s][4]++;
        }
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    res->seconds = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    res->lambda = hist[0];
    res->x1 = recorded[0][0];
    for (int s = 0; s < 2; s++) {
        FreeFMUstate(inst[s], &state[s]);
        Terminate(inst[s]);
        FreeInstance(inst[s]);
    }
    /* The library stays loaded: Tether may hold the same file open. */
    return 0;
}
