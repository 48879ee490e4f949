/*
 * One FMU in a plain C host (no Python in the process): fmi2Instantiate and its messages, and
 * optionally the cost of a step. Built with gcc (Linux) and mingw-w64 (Windows, run under wine)
 * for tests/test_windows_discovery.py and benchmarks/bench_wine.py.
 *
 *   fmi2_probe LIBRARY RESOURCE_URI GUID [STEP STEPS REPEAT SET_VR... -- OUT_VR...
 *              [-- r:VR=VALUE...]]
 *
 * Every message of the FMU's logger is printed to stdout as one record "LOG <status>
 * <category>|<message>" followed by a line "END"; then "INSTANCE OK" or "INSTANCE NULL". With
 * STEP..., after setupExperiment and initialization (with the r:VR=VALUE parameters): STEPS
 * warm-up steps, then REPEAT blocks of STEPS steps, each step fmi2SetReal of the SET_VRs (a
 * value that changes every step), fmi2DoStep, fmi2GetReal of the OUT_VRs; printed: "TIMING <the
 * best block's microseconds per step> <the last outputs' sum>". Exit status: 0, 3 fmi2Instantiate
 * returned NULL, 4 a call failed, 2 usage or a library that cannot be loaded.
 */
#define _POSIX_C_SOURCE 199309L
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#ifdef _WIN32
#include <windows.h>
static void *open_library(const char *path)
{
    return (void *)LoadLibraryA(path);
}
static void *symbol(void *lib, const char *name)
{
    FARPROC f = GetProcAddress((HMODULE)lib, name);
    void *p;
    memcpy(&p, &f, sizeof p);
    return p;
}
static double now_s(void)
{
    LARGE_INTEGER c, f;
    QueryPerformanceCounter(&c);
    QueryPerformanceFrequency(&f);
    return (double)c.QuadPart / (double)f.QuadPart;
}
#else
#include <dlfcn.h>
#include <time.h>
static void *open_library(const char *path)
{
    return dlopen(path, RTLD_NOW | RTLD_LOCAL);
}
static void *symbol(void *lib, const char *name)
{
    return dlsym(lib, name);
}
static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}
#endif

#define MAX_VR 64

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    static char text[65536];
    va_list ap;
    (void)env;
    (void)name;
    va_start(ap, message);
    vsnprintf(text, sizeof text, message, ap);
    va_end(ap);
    printf("LOG %d %s|%s\nEND\n", (int)status, category, text);
    fflush(stdout);
}

#define LOAD(type, var, name)                                                                  \
    do {                                                                                       \
        void *f_ = lib != NULL ? symbol(lib, name) : NULL;                                     \
        memcpy(&var, &f_, sizeof var);                                                         \
        ok = ok && var != NULL;                                                                \
    } while (0)

int main(int argc, char **argv)
{
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2InstantiateTYPE *instantiate = NULL;
    fmi2SetupExperimentTYPE *setup = NULL;
    fmi2EnterInitializationModeTYPE *enter = NULL;
    fmi2ExitInitializationModeTYPE *leave = NULL;
    fmi2SetRealTYPE *set = NULL;
    fmi2GetRealTYPE *get = NULL;
    fmi2DoStepTYPE *step = NULL;
    fmi2FreeInstanceTYPE *release = NULL;
    fmi2ValueReference in_vr[MAX_VR], out_vr[MAX_VR], par_vr[MAX_VR];
    fmi2Real in_v[MAX_VR], out_v[MAX_VR], par_v[MAX_VR], h, t = 0.0, best = 1e300, sum = 0.0;
    size_t n_in = 0, n_out = 0, n_par = 0, i;
    long steps, repeat, k, r;
    int a = 7, part = 0, ok = 1, rc = 0;
    void *lib;
    fmi2Component c = NULL;
    if (argc != 4 && argc < 8) {
        fprintf(stderr, "usage: fmi2_probe LIB URI GUID [STEP STEPS REPEAT VR... -- VR... "
                        "[-- r:VR=VALUE...]]\n");
        return 2;
    }
    h = argc > 4 ? atof(argv[4]) : 0.0;
    steps = argc > 5 ? atol(argv[5]) : 0;
    repeat = argc > 6 ? atol(argv[6]) : -1;
    for (; a < argc; a++) {
        if (strcmp(argv[a], "--") == 0)
            part++;
        else if (part == 0 && n_in < MAX_VR)
            in_vr[n_in++] = (fmi2ValueReference)atol(argv[a]);
        else if (part == 1 && n_out < MAX_VR)
            out_vr[n_out++] = (fmi2ValueReference)atol(argv[a]);
        else if (part == 2 && n_par < MAX_VR && strncmp(argv[a], "r:", 2) == 0 &&
                 strchr(argv[a], '=') != NULL) {
            par_vr[n_par] = (fmi2ValueReference)atol(argv[a] + 2);
            par_v[n_par++] = atof(strchr(argv[a], '=') + 1);
        }
    }
    lib = open_library(argv[1]);
    LOAD(fmi2InstantiateTYPE, instantiate, "fmi2Instantiate");
    LOAD(fmi2SetupExperimentTYPE, setup, "fmi2SetupExperiment");
    LOAD(fmi2EnterInitializationModeTYPE, enter, "fmi2EnterInitializationMode");
    LOAD(fmi2ExitInitializationModeTYPE, leave, "fmi2ExitInitializationMode");
    LOAD(fmi2SetRealTYPE, set, "fmi2SetReal");
    LOAD(fmi2GetRealTYPE, get, "fmi2GetReal");
    LOAD(fmi2DoStepTYPE, step, "fmi2DoStep");
    LOAD(fmi2FreeInstanceTYPE, release, "fmi2FreeInstance");
    if (!ok) {
        fprintf(stderr, "cannot load %s\n", argv[1]);
        rc = 2;
    } else if ((c = instantiate("probe", fmi2CoSimulation, argv[3], argv[2], &cb, fmi2False,
                                fmi2True)) == NULL) {
        printf("INSTANCE NULL\n");
        rc = 3;
    } else if (printf("INSTANCE OK\n") < 0 || argc == 4) {
        /* instantiate only */
    } else if (setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning ||
               enter(c) > fmi2Warning || (n_par && set(c, par_vr, n_par, par_v) > fmi2Warning) ||
               leave(c) > fmi2Warning) {
        rc = 4;
    }
    for (r = -1; rc == 0 && argc > 4 && r < repeat; r++) { /* r = -1: warm-up */
        double start = now_s(), per;
        for (k = 0; rc == 0 && k < steps; k++) {
            for (i = 0; i < n_in; i++)
                in_v[i] = 1e-6 * (double)((k + (long)i) % 7);
            if (set(c, in_vr, n_in, in_v) > fmi2Warning || step(c, t, h, fmi2True) > fmi2Warning ||
                get(c, out_vr, n_out, out_v) > fmi2Warning)
                rc = 4;
            t += h;
        }
        per = (now_s() - start) / (double)steps;
        if (r >= 0 && per < best)
            best = per;
    }
    for (i = 0; i < n_out; i++)
        sum += out_v[i];
    if (rc == 0 && argc > 4)
        printf("TIMING %.4f %.17g\n", 1e6 * best, sum);
    if (c != NULL)
        release(c);
    return rc;
}
