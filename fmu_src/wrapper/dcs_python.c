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
#include <wchar.h>

#include "dcs_discover.h"
#include "dcs_lock.h"
#include "dcs_platform.h"

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

static int start_interpreter(const char *executable, char *why, size_t nwhy)
{
    static wchar_t program[DCS_PATH_MAX]; /* Py_SetProgramName keeps the pointer */
    char *saved = NULL;
    const char *current = setlocale(LC_CTYPE, NULL);
    int rc = 0;
    if (dcs_utf8_to_wide(executable, program, sizeof program / sizeof program[0]) != 0) {
        snprintf(why, nwhy, "its path is too long: %.200s...", executable);
        rc = -1;
    } else {
        saved = current != NULL ? dcs_strdup(current) : NULL;
        *p_Py_IgnoreEnvironmentFlag = 1;
        *p_Py_UTF8Mode = 1;
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
        rc = start_interpreter(py->executable, why, nwhy);
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
    char why[1024] = "";
    char *message = NULL;
    void *process_python = NULL;
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
    } else {
        rc = start_in_plain_host(in, &message);
    }
    if (rc == 0 && !g_ready)
        rc = make_names(why, sizeof why);
    if (rc == 0) {
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
    char *text = NULL;
    int rc = -1;
    if (unzip_dir != NULL && out != NULL && size > 0) {
        dcs_lock(&g_lock); /* the discovery's buffers are shared */
        rc = discover(unzip_dir, pretend_load, "would be used", &text) == 0 ? 1 : 0;
        dcs_unlock(&g_lock);
        snprintf(out, size, "%s", text != NULL ? text : "(out of memory)\n");
        free(text);
    }
    return rc;
}
