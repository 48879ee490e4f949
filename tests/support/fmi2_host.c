/*
 * A plain C FMI 2.0 co-simulation host for the tests: no Python in the process.
 *
 *   fmi2_host UNZIP_DIR MODEL_ID STOP STEP [SET ...] -- OUT_VR [OUT_VR ...]
 *
 * SET is "r:VR=VALUE" (Real), "i:VR=VALUE" (Integer) or "s:VR=TEXT" (String), applied in
 * initialization mode. Prints "BAD <status>" for a doStep with a negative step first (it must
 * be refused, not crash), then one line per communication point (the start included):
 * time and the outputs, "%.17g" comma-separated. Communication points are k * STEP, each step
 * size the difference of two (as fmpy.simulate_fmu steps). Exit status: 0 all calls OK, 3 fmi2Instantiate
 * returned NULL, 4 a call returned fmi2Error or worse, 2 bad usage or a missing library.
 * The logger prints "[instance status category] message" to stderr. After fmi2Instantiate
 * the host prints "HOST locale=<LC_CTYPE> sigint=<unchanged|changed>" to stderr: what an FMU
 * that starts Python in the process left of the host's locale and SIGINT disposition (compared with
 * the one the host had before fmi2Instantiate: a background job inherits SIG_IGN).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <locale.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s %d %s] ", name, (int)status, category);
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

#define LOAD(type, name) type *name = (type *)dlsym(lib, #name)

int main(int argc, char **argv)
{
    char path[4096], uri[4200];
    void *lib;
    int sep, i, rc = 0;
    if (argc < 6) {
        fprintf(stderr, "usage: %s UNZIP_DIR MODEL_ID STOP STEP [SET ...] -- OUT_VR ...\n",
                argv[0]);
        return 2;
    }
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", argv[1], argv[2]);
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) {
        fprintf(stderr, "%s\n", dlerror());
        return 2;
    }
    {
        LOAD(fmi2InstantiateTYPE, fmi2Instantiate);
        LOAD(fmi2SetupExperimentTYPE, fmi2SetupExperiment);
        LOAD(fmi2EnterInitializationModeTYPE, fmi2EnterInitializationMode);
        LOAD(fmi2ExitInitializationModeTYPE, fmi2ExitInitializationMode);
        LOAD(fmi2DoStepTYPE, fmi2DoStep);
        LOAD(fmi2SetRealTYPE, fmi2SetReal);
        LOAD(fmi2SetIntegerTYPE, fmi2SetInteger);
        LOAD(fmi2SetStringTYPE, fmi2SetString);
        LOAD(fmi2GetRealTYPE, fmi2GetReal);
        LOAD(fmi2TerminateTYPE, fmi2Terminate);
        LOAD(fmi2FreeInstanceTYPE, fmi2FreeInstance);
        fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
        double stop = atof(argv[3]), h = atof(argv[4]);
        fmi2ValueReference out[256];
        double y[256];
        size_t n_out = 0;
        long k, n_steps = (long)(stop / h + 0.5);
        fmi2Component c;
        fmi2Status st = fmi2OK;
        struct sigaction before, after;
        for (sep = 5; sep < argc && strcmp(argv[sep], "--") != 0; sep++) {
        }
        for (i = sep + 1; i < argc && n_out < 256; i++)
            out[n_out++] = (fmi2ValueReference)strtoul(argv[i], NULL, 10);
        sigaction(SIGINT, NULL, &before); /* inherited: SIG_IGN in a background job */
        c = fmi2Instantiate("chost", fmi2CoSimulation, "", uri, &cb, fmi2False, fmi2True);
        if (c == NULL)
            return 3;
        {
            const char *loc = setlocale(LC_CTYPE, NULL);
            sigaction(SIGINT, NULL, &after);
            fprintf(stderr, "HOST locale=%s sigint=%s\n", loc != NULL ? loc : "?",
                    after.sa_handler == before.sa_handler ? "unchanged" : "changed");
        }
        st = fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        if (st < fmi2Error)
            st = fmi2EnterInitializationMode(c);
        for (i = 5; i < sep && st < fmi2Error; i++) {
            char kind = argv[i][0];
            char *eq = strchr(argv[i], '=');
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(argv[i] + 2, NULL, 10);
            if (eq == NULL || argv[i][1] != ':') {
                fprintf(stderr, "bad SET %s\n", argv[i]);
                return 2;
            }
            if (kind == 'r') {
                double v = atof(eq + 1);
                st = fmi2SetReal(c, &vr, 1, &v);
            } else if (kind == 'i') {
                int v = atoi(eq + 1);
                st = fmi2SetInteger(c, &vr, 1, &v);
            } else {
                fmi2String v = eq + 1;
                st = fmi2SetString(c, &vr, 1, &v);
            }
        }
        if (st < fmi2Error)
            st = fmi2ExitInitializationMode(c);
        if (st < fmi2Error)
            printf("BAD %d\n", (int)fmi2DoStep(c, 0.0, -1.0, fmi2True));
        for (k = 0; k <= n_steps && st < fmi2Error; k++) {
            size_t j;
            if (k > 0) /* time counted in steps, step = difference (as fmpy does) */
                st = fmi2DoStep(c, (k - 1) * h, k * h - (k - 1) * h, fmi2True);
            if (st < fmi2Error && n_out > 0)
                st = fmi2GetReal(c, out, n_out, y);
            if (st < fmi2Error) {
                printf("%.17g", k * h);
                for (j = 0; j < n_out; j++)
                    printf(",%.17g", y[j]);
                printf("\n");
            }
        }
        if (st >= fmi2Error) {
            fprintf(stderr, "a call returned status %d\n", (int)st);
            rc = 4;
        } else {
            fmi2Terminate(c);
        }
        fmi2FreeInstance(c);
    }
    return rc;
}
