/*
 * Attaching to, or starting, the Python interpreter the slaves run in.
 *
 * - Python host (fmpy, libcosimpy): the C-API symbols are found in the process's libpython
 *   (dcs_process_python: POSIX RTLD_DEFAULT; Windows the loaded python3XX.dll) and its running
 *   interpreter is used; it must be CPython 3.DCS_PY_MINOR_MIN to
 *   3.DCS_PY_MINOR_MAX (one clear message otherwise).
 * - Host without Python (a C/C++ tool): a Python is found by dcs_discover.c (candidates checked
 *   in child processes started as `python -E -X utf8`), its shared libpython is loaded
 *   (dcs_library_open: POSIX RTLD_GLOBAL, extension modules such as numpy need its symbols
 *   globally; Windows with its own folder searched for its dependencies) and started
 *   through the stable ABI only (no PyConfig: its layout differs per version):
 *       Py_IgnoreEnvironmentFlag = 1  PYTHONHOME, PYTHONPATH, ... of the host are ignored
 *                                     (the child check ran with -E, the same rule);
 *       Py_UTF8Mode = 1               file names and text in UTF-8 whatever the host's locale
 *                                     (the child ran with -X utf8);
 *       Py_SetProgramName(the candidate's sys.executable)  its prefix, and a venv's
 *                                     pyvenv.cfg, are found from there;
 *       Py_InitializeEx(0)            no signal handlers installed;
 *   then the GIL is released with PyEval_SaveThread(). The interpreter is never finalised.
 *   What the stable ABI cannot express: Python's start-up sets LC_CTYPE from the environment
 *   (PyPreConfig.configure_locale); the wrapper saves the host's LC_CTYPE before and restores
 *   it right after, so the host's locale is left as it was. And Py_InitializeEx ends the
 *   process on a failure instead of returning it: the child check has started the same
 *   interpreter the same way just before, so a failure there is reported first.
 * Every FMI call then takes the GIL with PyGILState_Ensure/Release (dcs_slave.c).
 * A failure before any libpython was loaded is retried at the next fmi2Instantiate (the user
 * may have fixed the environment); one after that is final for the process.
 *
 * drillcosim_doctor (exported) runs the same discovery without starting anything and returns
 * its report: `drillcosim doctor` calls it through ctypes.
 */
#include "dcs_python.h"

#include <locale.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <wchar.h>

#include "dcs_discover.h"
#include "dcs_lock.h"
#include "dcs_platform.h"
#include "dcs_runtime.h"
#include "dcs_sha256.h"

#ifndef DCS_BUILD_PYTHON
#define DCS_BUILD_PYTHON ""
#endif
#ifndef DCS_BUILD_MINOR
#define DCS_BUILD_MINOR 0
#endif

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"
#define DCS_DEFINE(name) __typeof__(name) *p_##name;
DCS_PYAPI(DCS_DEFINE)
#undef DCS_DEFINE
__typeof__(Py_UTF8Mode) *p_Py_UTF8Mode;
#pragma GCC diagnostic pop
int *p_Py_IgnoreEnvironmentFlag;
int *p_Py_NoSiteFlag;
int (*p_PyObject_GetBuffer)(PyObject *, DcsBuffer *, int);
void (*p_PyBuffer_Release)(DcsBuffer *);

DcsNames dcs_py;

static DcsLock g_lock = DCS_LOCK_INIT;
static int g_ready = 0;           /* API resolved, interpreter running, names interned */
static int g_loaded = 0;          /* a libpython is in the process (ours or the host's) */
static char *g_final_error = NULL; /* a failure once g_loaded: final for the process */


int dcs_python_started(void)
{
    return g_ready;
}

/* One symbol into *slot (a data pointer; function pointers are copied bytewise, as POSIX
 * allows for dlsym results and Windows gives both kinds through GetProcAddress). 0 if found,
 * else -1 with why set (the first missing one). */
static int resolve_one(void *handle, const char *name, void *slot, size_t size, char *why,
                       size_t nwhy, int rc)
{
    void *sym = dcs_library_symbol(handle, name);
    memcpy(slot, &sym, size);
    if (sym == NULL && rc == 0)
        snprintf(why, nwhy, "Python C-API symbol %s not found", name);
    return sym == NULL ? -1 : rc;
}

static int resolve_api(void *handle, char *why, size_t nwhy)
{
    int rc = 0;
#define DCS_RESOLVE(name) \
    rc = resolve_one(handle, #name, (void *)&p_##name, sizeof p_##name, why, nwhy, rc);
    DCS_PYAPI(DCS_RESOLVE)
    DCS_RESOLVE(Py_UTF8Mode)
    DCS_RESOLVE(Py_IgnoreEnvironmentFlag)
    DCS_RESOLVE(Py_NoSiteFlag)
    DCS_RESOLVE(PyObject_GetBuffer)
    DCS_RESOLVE(PyBuffer_Release)
#undef DCS_RESOLVE
    return rc;
}

/* The minor version of a Py_GetVersion() text ("3.12.1 (main, ...)"), -1 if not Python 3. */
static int minor_of(const char *version)
{
    int major = 0, minor = -1;
    if (sscanf(version, "%d.%d", &major, &minor) != 2 || major != 3)
        minor = -1;
    return minor;
}

static int version_fits(const char *version)
{
    int minor = minor_of(version);
    return minor >= DCS_PY_MINOR_MIN && minor <= DCS_PY_MINOR_MAX;
}

/* Py_GetVersion() of the libpython behind handle ("?" without one): asked before anything
 * else is resolved, so a version out of range is named as such. */
static const char *version_of(void *handle)
{
    const char *(*get)(void) = NULL;
    void *sym = dcs_library_symbol(handle, "Py_GetVersion");
    memcpy(&get, &sym, sizeof get);
    return get != NULL ? get() : "?";
}

/* Start the interpreter whose program name is executable. own_runtime: a self-contained FMU's
 * runtime, started without the site module (sys.path is the runtime's: its home, or on win64
 * its ._pth, and the MANIFEST's path lines); home: its Py_SetPythonHome (NULL: none). */
static int start_interpreter(const char *executable, int own_runtime, const char *home,
                             char *why, size_t nwhy)
{
    static wchar_t program[DCS_PATH_MAX]; /* Py_SetProgramName keeps the pointer */
    static wchar_t home_w[DCS_PATH_MAX];  /* so does Py_SetPythonHome */
    char *saved = NULL;
    const char *current = setlocale(LC_CTYPE, NULL);
    int rc = 0;
    if (dcs_utf8_to_wide(executable, program, sizeof program / sizeof program[0]) != 0 ||
        (home != NULL && dcs_utf8_to_wide(home, home_w, sizeof home_w / sizeof home_w[0]) != 0)) {
        snprintf(why, nwhy, "its path is too long: %.200s...", executable);
        rc = -1;
    } else {
        saved = current != NULL ? dcs_strdup(current) : NULL;
        *p_Py_IgnoreEnvironmentFlag = 1;
        *p_Py_UTF8Mode = 1;
        if (own_runtime)
            *p_Py_NoSiteFlag = 1;
        if (home != NULL)
            p_Py_SetPythonHome(home_w);
        p_Py_SetProgramName(program);
        p_Py_InitializeEx(0);
        if (saved != NULL) /* Python set LC_CTYPE from the environment: the host's again */
            setlocale(LC_CTYPE, saved);
        free(saved);
        if (!p_Py_IsInitialized()) {
            snprintf(why, nwhy, "starting it in this process failed");
            rc = -1;
        } else {
            p_PyEval_SaveThread(); /* the GIL is taken per call with PyGILState_Ensure */
        }
    }
    return rc;
}

/* DcsLoad for dcs_discover_python: load the candidate's libpython and start it. */
static int load_candidate(const DcsPython *py, void *ctx, char *why, size_t nwhy, int *stop)
{
    void *lib;
    char error[512];
    int rc = -1;
    (void)ctx;
    lib = dcs_library_open(py->libpython, error, sizeof error);
    if (lib == NULL) {
        snprintf(why, nwhy, "Python %s, but its libpython %s cannot be loaded: %s", py->version,
                 py->libpython, error);
    } else if (!version_fits(version_of(lib))) {
        snprintf(why, nwhy, "its libpython %s is Python %.20s, not 3.%d to 3.%d",
                 py->libpython, version_of(lib), DCS_PY_MINOR_MIN, DCS_PY_MINOR_MAX);
        dcs_library_close(lib);
    } else if (resolve_api(lib, why, nwhy) != 0) {
        dcs_library_close(lib);
    } else {
        *stop = 1; /* from here on this libpython stays in the process */
        g_loaded = 1;
        rc = start_interpreter(py->executable, 0, NULL, why, nwhy);
    }
    return rc;
}

/* DcsLoad of the doctor: nothing is loaded; the first candidate that passes is the one. */
static int pretend_load(const DcsPython *py, void *ctx, char *why, size_t nwhy, int *stop)
{
    (void)py;
    (void)ctx;
    (void)why;
    (void)nwhy;
    *stop = 1;
    return 0;
}

int dcs_isinstance(PyObject *o, PyObject *type)
{
    int r = p_PyObject_IsInstance(o, type);
    if (r < 0)
        p_PyErr_Clear();
    return r > 0;
}

static PyObject *builtin(PyObject *builtins, const char *name)
{
    return builtins != NULL ? p_PyObject_GetAttrString(builtins, name) : NULL;
}

static int make_names(char *why, size_t nwhy)
{
    PyGILState_STATE g = p_PyGILState_Ensure();
    PyObject *builtins = p_PyImport_ImportModule("builtins");
    int ok = 1;
#define N(field, text) if ((dcs_py.field = p_PyUnicode_InternFromString(text)) == NULL) ok = 0;
    N(setup_experiment, "setup_experiment")
    N(enter_initialization_mode, "enter_initialization_mode")
    N(exit_initialization_mode, "exit_initialization_mode")
    N(do_step, "do_step")
    N(terminate, "terminate")
    N(reset, "reset")
    N(get_real, "get_real")
    N(get_integer, "get_integer")
    N(get_boolean, "get_boolean")
    N(get_string, "get_string")
    N(set_real, "set_real")
    N(set_integer, "set_integer")
    N(set_boolean, "set_boolean")
    N(set_string, "set_string")
    N(get_fmu_state, "_get_fmu_state")
    N(set_fmu_state, "_set_fmu_state")
    N(to_bytes, "_fmu_state_to_bytes")
    N(from_bytes, "_fmu_state_from_bytes")
    N(fmi2_status, "_fmi2_status")
    N(real_buffers, "_fmi2_real_buffers")
    N(compiled_step, "_fmi2_compiled_step")
    N(compiled_step_failed, "_fmi2_compiled_step_failed")
    N(get_log_queue, "_get_log_queue")
    N(status, "status")
    N(category, "category")
    N(msg, "msg")
    N(format_exception, "format_exception")
    N(empty, "")
#undef N
    dcs_py.none = p_Py_BuildValue("");
    dcs_py.true_ = p_PyBool_FromLong(1);
    dcs_py.false_ = p_PyBool_FromLong(0);
    dcs_py.traceback = p_PyImport_ImportModule("traceback");
    dcs_py.int_type = builtin(builtins, "int");
    dcs_py.str_type = builtin(builtins, "str");
    dcs_py.bytes_type = builtin(builtins, "bytes");
    dcs_py.list_type = builtin(builtins, "list");
    if (dcs_py.none == NULL || dcs_py.true_ == NULL || dcs_py.false_ == NULL ||
        dcs_py.traceback == NULL || dcs_py.int_type == NULL || dcs_py.str_type == NULL ||
        dcs_py.bytes_type == NULL || dcs_py.list_type == NULL)
        ok = 0;
    dcs_decref(builtins);
    if (!ok) {
        snprintf(why, nwhy, "cannot create the wrapper's Python constants");
        p_PyErr_Clear();
    }
    p_PyGILState_Release(g);
    return ok ? 0 : -1;
}

/* Requirements of the FMU (resources/python_requires.txt: import names), "" if none. */
static void requirements(const char *resources, char *out, size_t n)
{
    char *line = dcs_read_resource_line(resources, "python_requires.txt");
    snprintf(out, n, "%s", line != NULL ? line : "");
    free(line);
}

/* The discovery for the FMU unzipped at unzip_dir: 0 if a candidate was used (by load), else
 * -1; *text (malloc'd, NULL if out of memory) is the report, followed on failure by how to
 * fix it. */
static int discover(const char *unzip_dir, DcsLoad load, const char *used, char **text)
{
    char requires[512], resources[DCS_PATH_MAX], cfg[DCS_PATH_MAX], *report = NULL;
    char *fix = NULL;
    const char *req;
    DcsWant want = {DCS_PY_MINOR_MIN, DCS_PY_MINOR_MAX, DCS_BUILD_MINOR};
    int rc;
    snprintf(resources, sizeof resources, "%s/resources", unzip_dir);
    requirements(resources, requires, sizeof requires);
    req = requires[0] ? requires : "nothing";
    if (dcs_user_config_file(cfg, sizeof cfg) != 0)
        snprintf(cfg, sizeof cfg, "the user's drillcosim/drillcosim.conf");
    rc = dcs_discover_python(unzip_dir, &want, requires, DCS_BUILD_PYTHON, load, NULL, used,
                             &report);
    if (rc != 0)
        fix = dcs_format("How to fix: install %s into a CPython 3.%d to 3.%d on PATH "
                         "(%s %s), or name such a Python: %s=%s, or a line 'python = %s' in "
                         "%s. PYTHONHOME and PYTHONPATH are ignored. `drillcosim doctor FMU` "
                         "prints this report; see docs/interop.md of drillcosim.", req,
                         DCS_PY_MINOR_MIN, DCS_PY_MINOR_MAX, dcs_wording.pip, req,
                         dcs_wording.python_variable, dcs_wording.python_path,
                         dcs_wording.python_path, cfg);
    *text = dcs_format("%sthis FMU runs its model in CPython 3.%d to 3.%d%s%s; in a host "
                       "process without a Python of its own it looks for one, in this "
                       "order:\n%s%s", rc != 0 ? "no usable Python found: " : "",
                       DCS_PY_MINOR_MIN, DCS_PY_MINOR_MAX, requires[0] ? " with " : "",
                       requires, report != NULL ? report : "  (out of memory)\n",
                       fix != NULL ? fix : "");
    free(fix);
    free(report);
    return rc;
}

/* The runtimes on sys.path, kept in the interpreter (sys._drillcosim_runtimes: their folders,
 * the one that started it first): every FMU's wrapper is a library of its own, loaded with its
 * own copy of this file's variables, and the interpreter is what they share. */
#define RUNTIMES_ATTR "_drillcosim_runtimes"

/* The folders on the list (a malloc'd array of malloc'd strings, *n of them); NULL with *n 0
 * if the interpreter was not started from a runtime (a Python host, a discovered Python).
 * GIL held. */
static char **runtime_list(size_t *n)
{
    PyObject *list = p_PySys_GetObject(RUNTIMES_ATTR); /* borrowed */
    Py_ssize_t i, size = list != NULL ? p_PyList_Size(list) : -1;
    char **out = size > 0 ? (char **)calloc((size_t)size, sizeof *out) : NULL;
    *n = 0;
    for (i = 0; out != NULL && i < size; i++) {
        Py_ssize_t len = 0;
        const char *s = p_PyUnicode_AsUTF8AndSize(p_PyList_GetItem(list, i), &len);
        if (s != NULL)
            out[(*n)++] = dcs_strdup(s);
    }
    p_PyErr_Clear();
    return out;
}

static void free_list(char **list, size_t n)
{
    size_t i;
    for (i = 0; i < n; i++)
        free(list[i]);
    free(list);
}

/* Append the runtime's "path" entries that sys.path lacks and its folder to the list of
 * runtimes (GIL held). */
static int add_runtime(const DcsRuntime *rt, char *why, size_t nwhy)
{
    PyObject *path = p_PySys_GetObject("path"); /* borrowed */
    PyObject *list = p_PySys_GetObject(RUNTIMES_ATTR), *root;
    size_t k, n = dcs_runtime_count(rt, "path");
    int rc = path != NULL ? 0 : -1;
    for (k = 0; k < n && rc == 0; k++) {
        const char *entry = dcs_runtime_item(rt, "path", k);
        Py_ssize_t i, size = p_PyList_Size(path);
        int present = 0;
        PyObject *item;
        for (i = 0; i < size && !present; i++) {
            Py_ssize_t len = 0;
            const char *s = p_PyUnicode_AsUTF8AndSize(p_PyList_GetItem(path, i), &len);
            present = s != NULL && strcmp(s, entry) == 0;
        }
        p_PyErr_Clear();
        if (present)
            continue;
        item = p_PyUnicode_DecodeFSDefault(entry);
        rc = item != NULL && p_PyList_Insert(path, size, item) == 0 ? 0 : -1;
        dcs_decref(item);
    }
    if (rc == 0 && list == NULL) {
        PyObject *fresh = p_PyList_New(0);
        rc = fresh != NULL && p_PySys_SetObject(RUNTIMES_ATTR, fresh) == 0 ? 0 : -1;
        dcs_decref(fresh);
        list = p_PySys_GetObject(RUNTIMES_ATTR);
    }
    root = rc == 0 && list != NULL ? p_PyUnicode_FromString(dcs_runtime_root(rt)) : NULL;
    if (root == NULL || p_PyList_Insert(list, p_PyList_Size(list), root) != 0)
        rc = -1;
    dcs_decref(root);
    if (rc != 0) {
        snprintf(why, nwhy, "cannot put the FMU's own runtime on sys.path");
        p_PyErr_Clear();
    }
    return rc;
}

/* The resources folder of a runtime folder (<resources>/dcs_runtime/<platform>). */
static void resources_of(const char *root, char *out, size_t n)
{
    char *slash;
    int k;
    snprintf(out, n, "%s", root);
    for (k = 0; k < 2 && (slash = strrchr(out, '/')) != NULL; k++)
        *slash = '\0';
}

/* Load the runtime's libraries (preloads first), then its libpython, and resolve the C-API.
 * 0, or -1 with why (g_loaded once its libpython stays in the process). */
static int load_runtime(const DcsRuntime *rt, const char *head, char *why, size_t nwhy)
{
    size_t k, n = dcs_runtime_count(rt, "preload");
    void *lib = NULL;
    int rc = 0;
    char error[512];
    for (k = 0; k <= n && rc == 0; k++) { /* the preloads, then the library itself */
        const char *file = k < n ? dcs_runtime_item(rt, "preload", k) : dcs_runtime_library(rt);
        lib = dcs_library_open(file, error, sizeof error);
        if (lib == NULL) {
            snprintf(why, nwhy, "%scannot load %s: %s", head, file, error);
            rc = -1;
        }
    }
    if (rc == 0 && !version_fits(version_of(lib))) {
        snprintf(why, nwhy, "%sis Python %.20s, not 3.%d to 3.%d", head, version_of(lib),
                 DCS_PY_MINOR_MIN, DCS_PY_MINOR_MAX);
        rc = -1;
    }
    if (rc == 0)
        rc = resolve_api(lib, why, nwhy);
    if (rc == 0)
        g_loaded = 1; /* from here on this libpython stays in the process */
    else if (lib != NULL)
        dcs_library_close(lib);
    return rc;
}

/* Start a self-contained FMU's own runtime in a host without Python: every file checked
 * (size and SHA-256) before anything of it is loaded, its libraries loaded, the interpreter
 * started with its home, sys.path completed. */
static int start_runtime(DcsInstance *in, DcsRuntime *rt, char *why, size_t nwhy)
{
    clock_t t0 = clock(), t1 = t0;
    char head[160];
    int rc;
    PyGILState_STATE g;
    snprintf(head, sizeof head, "the FMU's own Python runtime (Python %s) ",
             dcs_runtime_python(rt));
    rc = dcs_runtime_verify(rt, 1, why, nwhy);
    if (rc == 0) {
        t1 = clock();
        rc = load_runtime(rt, head, why, nwhy);
    }
    if (rc == 0)
        rc = start_interpreter(dcs_runtime_program(rt), 1, dcs_runtime_home(rt), why, nwhy);
    if (rc == 0) {
        g = p_PyGILState_Ensure();
        rc = add_runtime(rt, why, nwhy);
        p_PyGILState_Release(g);
    }
    if (rc == 0)
        dcs_log(in, fmi2OK, "logAll", "%s: fmi2Instantiate: the host has no Python; %sin %s "
                "started (CPU time: %.3f s to check its files' sizes and SHA-256%s, %.3f s to "
                "start the interpreter)", in->name, head, dcs_runtime_root(rt),
                (double)(t1 - t0) / CLOCKS_PER_SEC,
                dcs_sha256_accelerated() ? " with the CPU's SHA extensions" : "",
                (double)(clock() - t1) / CLOCKS_PER_SEC);
    return rc;
}

/* An FMU instantiated once an interpreter runs in the process (started by this wrapper or
 * another FMU's, or the host's own). If the FMU carries a runtime and the interpreter was
 * started from one, the FMU's must be compatible with it (dcs_runtime_compatible): then its
 * path entries are added. Its files are checked in full the first time, their sizes at every
 * later instantiation. In a Python host, or one whose Python was found by the discovery, the
 * FMU's runtime is not used. */
static int join_runtime(DcsInstance *in, char *why, size_t nwhy)
{
    DcsRuntime *rt = NULL, *running = NULL;
    char reason[512], resources[DCS_PATH_MAX];
    char **roots = NULL;
    size_t n_roots = 0, i;
    int rc = dcs_runtime_open(in->resources, &rt, why, nwhy), known = 0;
    PyGILState_STATE g;
    if (rc == 0) /* no runtime: nothing to join */
        rt = NULL;
    g = p_PyGILState_Ensure();
    roots = rc != 0 ? runtime_list(&n_roots) : NULL;
    for (i = 0; i < n_roots && rc > 0; i++)
        known = known || strcmp(roots[i], dcs_runtime_root(rt)) == 0;
    if (rc == 0) {
        /* a regular FMU */
    } else if (n_roots == 0) { /* the host's Python or a discovered one: runtime not used */
        dcs_log(in, fmi2OK, "logAll", "%s: fmi2Instantiate: this process runs a Python "
                "already: the FMU's own runtime is not used", in->name);
        rc = 0;
    } else if (rc < 0) {
        /* why set */
    } else if (known) {
        rc = dcs_runtime_verify(rt, 0, why, nwhy);
    } else if ((rc = dcs_runtime_verify(rt, 1, why, nwhy)) != 0) {
        /* why set */
    } else if (resources_of(roots[0], resources, sizeof resources),
               dcs_runtime_open(resources, &running, reason, sizeof reason) <= 0) {
        snprintf(why, nwhy, "this process runs the Python runtime of another self-contained "
                 "FMU (%.1000s), whose MANIFEST cannot be read any more (%s)", roots[0],
                 reason);
        rc = -1;
    } else if (!dcs_runtime_compatible(running, rt, reason, sizeof reason)) {
        snprintf(why, nwhy, "this process runs the Python runtime of another self-contained "
                 "FMU (%.1000s) and this FMU's own runtime (%.1000s) cannot join it: %s. One "
                 "process runs one Python: load this FMU in a process of its own, or build "
                 "the FMUs with one drillcosim (drillcosim build --standalone gives every FMU "
                 "the same packages)", roots[0], dcs_runtime_root(rt), reason);
        rc = -1;
    } else if ((rc = add_runtime(rt, why, nwhy)) == 0) {
        dcs_log(in, fmi2OK, "logAll", "%s: fmi2Instantiate: the FMU's own runtime %s joins "
                "the one running (%s): same interpreter, same packages", in->name,
                dcs_runtime_root(rt), roots[0]);
    }
    p_PyGILState_Release(g);
    free_list(roots, n_roots);
    dcs_runtime_free(running);
    dcs_runtime_free(rt);
    return rc < 0 ? -1 : 0;
}

/* Find and start a Python for a host without one. On failure *message (malloc'd) is the ONE
 * message listing every candidate tried, what it lacked and how to fix it. */
static int start_in_plain_host(DcsInstance *in, char **message)
{
    char unzip[DCS_PATH_MAX], *slash = NULL, *p, *text = NULL;
    int rc;
    snprintf(unzip, sizeof unzip, "%s", in->resources);
    for (p = unzip; *p; p++)
        if (dcs_is_dir_sep(*p))
            slash = p;
    if (slash != NULL && slash != unzip)
        *slash = '\0'; /* <unzip>/resources -> <unzip> */
    rc = discover(unzip, load_candidate, "used", &text);
    if (rc != 0) {
        size_t n = strlen(in->name) + (text != NULL ? strlen(text) : 0) + 64;
        *message = (char *)malloc(n);
        if (*message != NULL)
            snprintf(*message, n, "%s: fmi2Instantiate: %s", in->name,
                     text != NULL ? text : "no usable Python found (out of memory)");
    } else {
        dcs_log(in, fmi2OK, "logAll", "%s: fmi2Instantiate: the host has no Python; %s",
                in->name, text != NULL ? text : "");
    }
    free(text);
    return rc;
}

int dcs_python_ready(DcsInstance *in)
{
    int rc = 0;
    char why[4096] = "";
    char *message = NULL;
    void *process_python = NULL;
    DcsRuntime *rt = NULL;
    int started_own = 0;
    dcs_lock(&g_lock);
    if (g_ready) {
        rc = 0;
    } else if (g_final_error != NULL) {
        rc = -1;
    } else if (dcs_process_python(&process_python)) {
        g_loaded = 1; /* the process's own libpython: nothing else can be tried */
        if (!version_fits(version_of(process_python))) {
            snprintf(why, sizeof why, "this process runs Python %.20s, but the FMU's wrapper "
                     "runs on CPython 3.%d to 3.%d: load the FMU from a process of one of "
                     "these versions", version_of(process_python), DCS_PY_MINOR_MIN,
                     DCS_PY_MINOR_MAX);
            rc = -1;
        } else {
            rc = resolve_api(process_python, why, sizeof why);
        }
        if (rc == 0 && !p_Py_IsInitialized()) {
            /* a host that links libpython without starting it: start it as a plain host */
            rc = start_in_plain_host(in, &message);
        }
    } else if ((rc = dcs_runtime_open(in->resources, &rt, why, sizeof why)) != 0) {
        rc = rc > 0 ? start_runtime(in, rt, why, sizeof why) : -1;
        started_own = rc == 0;
        dcs_runtime_free(rt);
    } else {
        rc = start_in_plain_host(in, &message);
    }
    if (rc == 0 && !g_ready)
        rc = make_names(why, sizeof why);
    if (rc == 0 && !started_own && join_runtime(in, why, sizeof why) != 0) {
        /* this FMU only: the interpreter runs on for the others */
        g_ready = 1;
        rc = -1;
        message = dcs_format("%s: fmi2Instantiate: %s", in->name, why);
    } else if (rc == 0) {
        g_ready = 1;
    } else if (g_final_error == NULL) {
        if (message == NULL) {
            size_t n = strlen(in->name) + strlen(why) + 32;
            message = (char *)malloc(n);
            if (message != NULL)
                snprintf(message, n, "%s: fmi2Instantiate: %s", in->name, why);
        }
        if (g_loaded) { /* final: keep the message for every later instantiation */
            g_final_error = message;
            message = NULL;
        }
    }
    if (rc != 0)
        dcs_log_text(in, fmi2Error, "logStatusError",
                     g_final_error != NULL ? g_final_error
                     : message != NULL ? message : "fmi2Instantiate: Python cannot be started");
    free(message);
    dcs_unlock(&g_lock);
    return rc;
}

/* The doctor: the discovery of a host without Python for the FMU unzipped at unzip_dir,
 * without loading or starting anything; its report (and how to fix a failure) into
 * out[size] (truncated to fit). Returns 1 if a Python would be found, 0 if not, -1 for bad
 * arguments. Safe in any process (a Python host included): it only runs child processes. */
FMI2_Export int drillcosim_doctor(const char *unzip_dir, char *out, size_t size)
{
    char *text = NULL, resources[DCS_PATH_MAX], why[4096] = "";
    DcsRuntime *rt = NULL;
    int rc = -1, own;
    if (unzip_dir != NULL && out != NULL && size > 0) {
        dcs_lock(&g_lock); /* the discovery's buffers are shared */
        snprintf(resources, sizeof resources, "%s/resources", unzip_dir);
        own = dcs_runtime_open(resources, &rt, why, sizeof why);
        if (own > 0 && dcs_runtime_verify(rt, 1, why, sizeof why) != 0)
            own = -1;
        if (own > 0) /* fmi2Instantiate starts it before any other candidate */
            text = dcs_format("this FMU carries its own Python runtime, used in a host process "
                              "without a Python of its own:\n  0. its own runtime %s: Python "
                              "%s, every file checked (size and SHA-256), would be used\n",
                              dcs_runtime_root(rt), dcs_runtime_python(rt));
        else if (own < 0) /* fmi2Instantiate fails: no other candidate is tried */
            text = dcs_format("this FMU carries its own Python runtime, and it cannot be "
                              "used:\n  0. its own runtime: %s\n", why);
        else
            rc = discover(unzip_dir, pretend_load, "would be used", &text) == 0 ? 1 : 0;
        if (own != 0)
            rc = own > 0 ? 1 : 0;
        dcs_runtime_free(rt);
        dcs_unlock(&g_lock);
        snprintf(out, size, "%s", text != NULL ? text : "(out of memory)\n");
        free(text);
    }
    return rc;
}
