/*
 * A plain C FMI 2.0 co-simulation host of several FMUs for the tests: no Python in the process.
 * Builds with gcc/clang on Linux and with mingw-w64 for Windows (run under wine).
 *
 *   fmi2_cosim_host SPEC [OUT]
 *
 * With OUT the rows go to the file OUT and the log lines to OUT.log instead of stdout and
 * stderr (under wine: the standard handles can then be the null device, and no pipe is left
 * open by a wineserver the run started).
 * SPEC is a text file, one item a line (fields separated by one space; the last field of
 * "fmu" and "string" lines is the rest of the line):
 *   step H                 communication step [s] (time counted in steps: t_k = k * H)
 *   stop T                 stop time [s]
 *   fmu NAME MODEL_ID DIR  an FMU unzipped in DIR (binaries/<platform>/MODEL_ID.<so|dll>)
 *   real NAME VR VALUE     a parameter set in initialization mode (also: int, bool 0|1,
 *   string NAME VR TEXT    string)
 *   connect SRC VR DST VR  a Real output of SRC drives a Real input of DST
 *   output NAME VR         a Real printed at every communication point
 * Stepping is Jacobi with a zero-order hold (the fixed-step algorithm of libcosim and Ecos,
 * and our master's "jacobi"): at t_k every connection's source value is read, then every
 * target set, the outputs printed, then every FMU steps from t_k to t_k+1. Output: one line
 * per communication point, "%.17g" comma-separated (time, then the outputs in SPEC order).
 * The logger prints "[instance status category] message" to stderr, and the host the wall
 * time of each fmi2Instantiate ("host: fmi2Instantiate NAME S s"). Exit status: 0 all calls
 * OK, 3 an fmi2Instantiate returned NULL, 4 a call returned fmi2Error or worse, 2 bad usage
 * or a library that cannot be loaded.
 */
#ifndef _WIN32
#define _POSIX_C_SOURCE 200809L
#endif
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#ifdef _WIN32
#include <windows.h>
#define PLATFORM "win64"
#define SUFFIX ".dll"
static void *open_library(const char *path) { return (void *)LoadLibraryA(path); }
static double seconds(void)
{
    LARGE_INTEGER t, f;
    QueryPerformanceCounter(&t);
    QueryPerformanceFrequency(&f);
    return (double)t.QuadPart / (double)f.QuadPart;
}
static void *symbol(void *lib, const char *name)
{
    FARPROC f = GetProcAddress((HMODULE)lib, name);
    void *p;
    memcpy(&p, &f, sizeof p);
    return p;
}
#else
#include <dlfcn.h>
#define PLATFORM "linux64"
#define SUFFIX ".so"
#include <time.h>
static void *open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static double seconds(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}
static void *symbol(void *lib, const char *name) { return dlsym(lib, name); }
#endif

#define MAX_FMUS 8
#define MAX_ITEMS 256

typedef struct {
    char name[64], id[128], dir[2048];
    fmi2Component c;
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2DoStepTYPE *do_step;
    fmi2SetRealTYPE *set_real;
    fmi2SetIntegerTYPE *set_integer;
    fmi2SetBooleanTYPE *set_boolean;
    fmi2SetStringTYPE *set_string;
    fmi2GetRealTYPE *get_real;
    fmi2TerminateTYPE *terminate;
    fmi2FreeInstanceTYPE *free_instance;
} Fmu;

typedef struct {
    char kind; /* r i b s */
    int fmu;
    fmi2ValueReference vr;
    char text[512];
} Param;

typedef struct {
    int src, dst;
    fmi2ValueReference src_vr, dst_vr;
} Link;

typedef struct {
    int fmu;
    fmi2ValueReference vr;
} Out;

static Fmu fmus[MAX_FMUS];
static int n_fmus;
static FILE *out_rows, *out_log;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    va_list ap;
    (void)env;
    fprintf(out_log, "[%s %d %s] ", name, (int)status, category);
    va_start(ap, message);
    vfprintf(out_log, message, ap);
    va_end(ap);
    fputc('\n', out_log);
    fflush(out_log);
}

static int fmu_index(const char *name)
{
    int i;
    for (i = 0; i < n_fmus; i++)
        if (strcmp(fmus[i].name, name) == 0)
            return i;
    fprintf(out_log, "unknown FMU %s\n", name);
    exit(2);
}

/* "file:///..." of DIR/resources (DIR: "/a/b" or "C:\a\b"). */
static void resource_uri(const char *dir, char *uri, size_t n)
{
    char *p;
    snprintf(uri, n, "file://%s%s/resources", dir[0] == '/' ? "" : "/", dir);
    for (p = uri; *p; p++)
        if (*p == '\\')
            *p = '/';
}

static int load(Fmu *f)
{
    char path[2300];
    void *lib;
    snprintf(path, sizeof path, "%s/binaries/%s/%s%s", f->dir, PLATFORM, f->id, SUFFIX);
    lib = open_library(path);
    if (lib == NULL) {
        fprintf(out_log, "cannot load %s\n", path);
        return -1;
    }
#define GET(field, name) f->field = (name##TYPE *)symbol(lib, #name)
    GET(instantiate, fmi2Instantiate);
    GET(setup, fmi2SetupExperiment);
    GET(enter, fmi2EnterInitializationMode);
    GET(exit_init, fmi2ExitInitializationMode);
    GET(do_step, fmi2DoStep);
    GET(set_real, fmi2SetReal);
    GET(set_integer, fmi2SetInteger);
    GET(set_boolean, fmi2SetBoolean);
    GET(set_string, fmi2SetString);
    GET(get_real, fmi2GetReal);
    GET(terminate, fmi2Terminate);
    GET(free_instance, fmi2FreeInstance);
#undef GET
    return f->instantiate != NULL && f->do_step != NULL ? 0 : -1;
}

static fmi2Status set_param(const Param *p)
{
    Fmu *f = &fmus[p->fmu];
    if (p->kind == 'r') {
        double v = atof(p->text);
        return f->set_real(f->c, &p->vr, 1, &v);
    }
    if (p->kind == 'i' || p->kind == 'b') {
        int v = atoi(p->text);
        return p->kind == 'i' ? f->set_integer(f->c, &p->vr, 1, &v)
                              : f->set_boolean(f->c, &p->vr, 1, &v);
    }
    {
        fmi2String v = p->text;
        return f->set_string(f->c, &p->vr, 1, &v);
    }
}

int main(int argc, char **argv)
{
    static Param params[MAX_ITEMS];
    static Link links[MAX_ITEMS];
    static Out outs[MAX_ITEMS];
    int n_params = 0, n_links = 0, n_outs = 0, i, rc = 0;
    double h = 0, stop = 0;
    char line[4096];
    long k, n_steps;
    fmi2Status st = fmi2OK;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    FILE *spec;
    out_rows = stdout;
    out_log = stderr;
    if (argc == 3) {
        char log_name[4200];
        snprintf(log_name, sizeof log_name, "%s.log", argv[2]);
        out_rows = fopen(argv[2], "w");
        out_log = fopen(log_name, "w");
    }
    if (argc < 2 || argc > 3 || out_rows == NULL || out_log == NULL ||
        (spec = fopen(argv[1], "r")) == NULL) {
        fprintf(stderr, "usage: %s SPEC [OUT]\n", argv[0]);
        return 2;
    }
    while (fgets(line, sizeof line, spec) != NULL) {
        char a[64], b[128], c[64], d[64], e[64];
        int skip = 0;
        line[strcspn(line, "\r\n")] = '\0';
        if (sscanf(line, "step %lf", &h) == 1 || sscanf(line, "stop %lf", &stop) == 1)
            continue;
        if (sscanf(line, "fmu %63s %127s %n", a, b, &skip) == 2 && n_fmus < MAX_FMUS) {
            Fmu *f = &fmus[n_fmus++];
            snprintf(f->name, sizeof f->name, "%s", a);
            snprintf(f->id, sizeof f->id, "%s", b);
            snprintf(f->dir, sizeof f->dir, "%s", line + skip);
        } else if (sscanf(line, "connect %63s %63s %63s %63s", a, c, d, e) == 4) {
            Link *l = &links[n_links++];
            l->src = fmu_index(a);
            l->src_vr = (fmi2ValueReference)strtoul(c, NULL, 10);
            l->dst = fmu_index(d);
            l->dst_vr = (fmi2ValueReference)strtoul(e, NULL, 10);
        } else if (sscanf(line, "output %63s %63s", a, c) == 2) {
            outs[n_outs].fmu = fmu_index(a);
            outs[n_outs++].vr = (fmi2ValueReference)strtoul(c, NULL, 10);
        } else if (sscanf(line, "%63s %63s %63s %n", d, a, c, &skip) == 3 &&
                   strchr("ribs", d[0]) != NULL && n_params < MAX_ITEMS) {
            Param *p = &params[n_params++];
            p->kind = d[0];
            p->fmu = fmu_index(a);
            p->vr = (fmi2ValueReference)strtoul(c, NULL, 10);
            snprintf(p->text, sizeof p->text, "%s", line + skip);
        } else if (line[0] != '\0' && line[0] != '#') {
            fprintf(out_log, "bad SPEC line: %s\n", line);
            return 2;
        }
    }
    fclose(spec);
    if (h <= 0 || n_fmus == 0) {
        fprintf(out_log, "SPEC needs step > 0 and an fmu\n");
        return 2;
    }
    for (i = 0; i < n_fmus; i++) {
        char uri[2400];
        double t0;
        if (load(&fmus[i]) != 0)
            return 2;
        resource_uri(fmus[i].dir, uri, sizeof uri);
        t0 = seconds();
        fmus[i].c = fmus[i].instantiate(fmus[i].name, fmi2CoSimulation, "", uri, &cb,
                                        fmi2False, fmi2True);
        fprintf(out_log, "host: fmi2Instantiate %s %.6f s\n", fmus[i].name, seconds() - t0);
        fflush(out_log);
        if (fmus[i].c == NULL)
            return 3;
    }
    for (i = 0; i < n_fmus && st < fmi2Error; i++) {
        st = fmus[i].setup(fmus[i].c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        if (st < fmi2Error)
            st = fmus[i].enter(fmus[i].c);
    }
    for (i = 0; i < n_params && st < fmi2Error; i++)
        st = set_param(&params[i]);
    for (i = 0; i < n_fmus && st < fmi2Error; i++)
        st = fmus[i].exit_init(fmus[i].c);
    n_steps = (long)(stop / h + 0.5);
    for (k = 0; k <= n_steps && st < fmi2Error; k++) {
        static double values[MAX_ITEMS];
        for (i = 0; i < n_links && st < fmi2Error; i++) {
            Fmu *s = &fmus[links[i].src];
            st = s->get_real(s->c, &links[i].src_vr, 1, &values[i]);
        }
        for (i = 0; i < n_links && st < fmi2Error; i++) {
            Fmu *t = &fmus[links[i].dst];
            st = t->set_real(t->c, &links[i].dst_vr, 1, &values[i]);
        }
        if (st < fmi2Error)
            fprintf(out_rows, "%.17g", k * h);
        for (i = 0; i < n_outs && st < fmi2Error; i++) {
            Fmu *f = &fmus[outs[i].fmu];
            double v = 0;
            st = f->get_real(f->c, &outs[i].vr, 1, &v);
            fprintf(out_rows, ",%.17g", v);
        }
        if (st < fmi2Error)
            fprintf(out_rows, "\n");
        for (i = 0; i < n_fmus && k < n_steps && st < fmi2Error; i++)
            st = fmus[i].do_step(fmus[i].c, (k) * h, (k + 1) * h - k * h, fmi2True);
    }
    if (st >= fmi2Error) {
        fprintf(out_log, "a call returned status %d\n", (int)st);
        rc = 4;
    }
    for (i = 0; i < n_fmus; i++) {
        if (rc == 0)
            fmus[i].terminate(fmus[i].c);
        fmus[i].free_instance(fmus[i].c);
    }
    fclose(out_rows);
    fclose(out_log);
    return rc;
}
