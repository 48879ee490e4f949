/*
 * fmi2Instantiate in a process without Python, for the tests of the Python search (Linux, and
 * Windows under wine: built with mingw-w64).
 *
 *   instantiate_probe LIBRARY RESOURCE_URI
 *
 * Loads the FMU's library, calls fmi2Instantiate (co-simulation, logging on) and prints every
 * message of the FMU's logger to stdout as one record "LOG <status> <category>|<message>"
 * followed by a line "END", then "INSTANCE OK" or "INSTANCE NULL". Exit status: 0 an
 * instance, 3 NULL, 2 the library or a function could not be loaded.
 */
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
#else
#include <dlfcn.h>
static void *open_library(const char *path)
{
    return dlopen(path, RTLD_NOW | RTLD_LOCAL);
}
static void *symbol(void *lib, const char *name)
{
    return dlsym(lib, name);
}
#endif

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    char text[65536];
    va_list ap;
    (void)env;
    (void)name;
    va_start(ap, message);
    vsnprintf(text, sizeof text, message, ap);
    va_end(ap);
    printf("LOG %d %s|%s\nEND\n", (int)status, category, text);
    fflush(stdout);
}

int main(int argc, char **argv)
{
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2InstantiateTYPE *instantiate = NULL;
    fmi2FreeInstanceTYPE *free_instance = NULL;
    void *lib = NULL, *f;
    fmi2Component c = NULL;
    int rc = 2;
    if (argc == 3)
        lib = open_library(argv[1]);
    if (lib != NULL) {
        f = symbol(lib, "fmi2Instantiate");
        memcpy(&instantiate, &f, sizeof instantiate);
        f = symbol(lib, "fmi2FreeInstance");
        memcpy(&free_instance, &f, sizeof free_instance);
    }
    if (instantiate != NULL && free_instance != NULL) {
        c = instantiate("probe", fmi2CoSimulation, "", argv[2], &callbacks, fmi2False,
                        fmi2True);
        printf("INSTANCE %s\n", c != NULL ? "OK" : "NULL");
        rc = c != NULL ? 0 : 3;
        if (c != NULL)
            free_instance(c);
    } else {
        fprintf(stderr, "usage: instantiate_probe LIBRARY RESOURCE_URI (library not loaded)\n");
    }
    return rc;
}
