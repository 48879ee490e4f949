/*
 * The Python runtime a self-contained FMU carries (drillcosim build --standalone):
 * resources/dcs_runtime/<platform>/ with its MANIFEST, checked before anything of it is loaded.
 * See dcs_runtime.c.
 */
#ifndef DCS_RUNTIME_H
#define DCS_RUNTIME_H

#include <stddef.h>

#define DCS_RUNTIME_DIR "dcs_runtime"
#define DCS_RUNTIME_MANIFEST "MANIFEST"

typedef struct DcsRuntime DcsRuntime;

/* The runtime of the FMU whose resources folder is `resources`, for the platform this
 * wrapper was built for: 0 and *out NULL if the FMU carries none; 1 and *out (free with
 * dcs_runtime_free) if it carries one and its MANIFEST is well formed; -1 with ONE line in
 * why if the MANIFEST is missing (but the folder exists), damaged or not of this platform. */
int dcs_runtime_open(const char *resources, DcsRuntime **out, char *why, size_t nwhy);
void dcs_runtime_free(DcsRuntime *rt);

/* Every file of the MANIFEST is there with its size (stat only); with `hashes`, also its
 * SHA-256. 0, or -1 with ONE line naming the first bad file in why. */
int dcs_runtime_verify(const DcsRuntime *rt, int hashes, char *why, size_t nwhy);

/* Fields of the MANIFEST as absolute paths (NULL if the MANIFEST has none). */
const char *dcs_runtime_root(const DcsRuntime *rt);     /* the runtime folder */
const char *dcs_runtime_library(const DcsRuntime *rt);  /* libpython / python3XX.dll */
const char *dcs_runtime_program(const DcsRuntime *rt);  /* Py_SetProgramName */
const char *dcs_runtime_home(const DcsRuntime *rt);     /* Py_SetPythonHome, or NULL */
const char *dcs_runtime_python(const DcsRuntime *rt);   /* "3.11.7" */
size_t dcs_runtime_count(const DcsRuntime *rt, const char *key); /* "preload", "path" */
const char *dcs_runtime_item(const DcsRuntime *rt, const char *key, size_t i);

/* Whether an FMU whose runtime is `other` may use the interpreter `running` started: the same
 * interpreter and standard library (the "base" files), and every package both carry
 * byte-identical. 1 if so; else 0 with why naming what differs. */
int dcs_runtime_compatible(const DcsRuntime *running, const DcsRuntime *other, char *why,
                           size_t nwhy);

#endif
