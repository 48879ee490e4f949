/*
 * Attaching to, or starting, the Python interpreter the slaves run in.
 *
 * - Python host (fmpy, libcosimpy): the C-API symbols are found in the process (RTLD_DEFAULT)
 *   and its running interpreter is used; a Python of another major.minor than the one this
 *   library is compiled for gives one clear message.
 * - Host without Python (a C/C++ tool): a Python is found by dcs_discover.c (candidates checked
 *   in child processes), its shared libpython is dlopen()ed with RTLD_GLOBAL (extension modules
 *   such as numpy need its symbols globally) and started with
 *       program_name = the candidate's sys.executable (a venv's pyvenv.cfg is honoured),
 *       use_environment = 0 (PYTHONHOME, PYTHONPATH, ... of the host are ignored: the child
 *                            check ran with -E, the same rule),
 *       install_signal_handlers = 0, and in the pre-configuration configure_locale = 0,
 *                            coerce_c_locale = 0, utf8_mode = 1 (the host's signal handlers,
 *                            locale and environment are left alone), parse_argv = 0;
 *   then the GIL is released with PyEval_SaveThread(). The interpreter is never finalised.
 * Every FMI call then takes the GIL with PyGILState_Ensure/Release (dcs_slave.c).
 * A failure before any libpython was loaded is retried at the next fmi2Instantiate (the user
 * may have fixed the environment); one after that is final for the process.
 */
#include "dcs_python.h"

#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dcs_discover.h"

#ifndef DCS_BUILD_PYTHON
#define DCS_BUILD_PYTHON ""
#endif

#define DCS_DEFINE(ret, name, args) ret(*p_##name) args;
DCS_PYAPI(DCS_DEFINE)
#undef DCS_DEFINE

DcsNames dcs_py;

static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static int g_ready = 0;           /* API resolved, interpreter running, names interned */
static int g_loaded = 0;          /* a libpython is in the process (ours or the host's) */
static char *g_final_error = NULL; /* a failure once g_loaded: final for the process */

int dcs_python_started(void)
{
    return g_ready;
}

static int resolve_api(void *handle, char *why, size_t nwhy)
{
    int rc = 0;
#define DCS_RESOLVE(ret, name, args) \
    p_##name = (ret(*) args)dlsym(handle, #name); \
    if (p_##name == NULL && rc == 0) { \
        snprintf(why, nwhy, "Python C-API symbol %s not found", #name); \
        rc = -1; \
    }
    DCS_PYAPI(DCS_RESOLVE)
#undef DCS_RESOLVE
    return rc;
}

/* "3.11" of this build, and whether version (e.g. "3.11.7 (main, ...)") is one of it. */
static const char *wanted_version(void)
{
    static char want[16];
    snprintf(want, sizeof want, "%d.%d", PY_MAJOR_VERSION, PY_MINOR_VERSION);
    return want;
}

static int version_fits(const char *version)
{
    size_t n = strlen(wanted_version());
    return strncmp(version, wanted_version(), n) == 0 && version[n] == '.';
}

static int start_interpreter(const char *executable, char *why, size_t nwhy)
{
    PyPreConfig pre;
    PyConfig config;
    PyStatus st;
    int rc = 0;
    p_PyPreConfig_InitPythonConfig(&pre);
    pre.use_environment = 0;
    pre.configure_locale = 0; /* no setlocale(), no LC_CTYPE coercion in the host's environ */
    pre.coerce_c_locale = 0;
    pre.utf8_mode = 1;        /* file names and text: UTF-8 whatever the host's locale */
    pre.parse_argv = 0;
    st = p_Py_PreInitialize(&pre);
    p_PyConfig_InitPythonConfig(&config);
    config.use_environment = 0;
    config.install_signal_handlers = 0;
    config.parse_argv = 0;
    if (!p_PyStatus_Exception(st))
        st = p_PyConfig_SetBytesString(&config, &config.program_name, executable);
    if (!p_PyStatus_Exception(st))
        st = p_Py_InitializeFromConfig(&config);
    p_PyConfig_Clear(&config);
    if (p_PyStatus_Exception(st)) {
        snprintf(why, nwhy, "starting it in this process failed: %s",
                 st.err_msg != NULL ? st.err_msg : "unknown error");
        rc = -1;
    } else {
        p_PyEval_SaveThread(); /* the GIL is taken per call with PyGILState_Ensure */
    }
    return rc;
}

/* DcsLoad for dcs_discover_python: load the candidate's libpython and start it. */
static int load_candidate(const DcsPython *py, void *ctx, char *why, size_t nwhy, int *stop)
{
    void *lib;
    int rc = -1;
    (void)ctx;
    lib = dlopen(py->libpython, RTLD_NOW | RTLD_GLOBAL);
    if (lib == NULL) {
        const char *e = dlerror();
        snprintf(why, nwhy, "Python %s, but its libpython %s cannot be loaded: %s", py->version,
                 py->libpython, e != NULL ? e : "unknown error");
    } else if (resolve_api(lib, why, nwhy) != 0) {
        dlclose(lib);
    } else if (!version_fits(p_Py_GetVersion())) {
        snprintf(why, nwhy, "its libpython %s is Python %.20s, not %s", py->libpython,
                 p_Py_GetVersion(), wanted_version());
        dlclose(lib);
    } else {
        *stop = 1; /* from here on this libpython stays in the process */
        g_loaded = 1;
        rc = start_interpreter(py->executable, why, nwhy);
    }
    return rc;
}

static int make_names(char *why, size_t nwhy)
{
    PyGILState_STATE g = p_PyGILState_Ensure();
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
    if (dcs_py.none == NULL || dcs_py.true_ == NULL || dcs_py.false_ == NULL ||
        dcs_py.traceback == NULL)
        ok = 0;
    if (!ok) {
        snprintf(why, nwhy, "cannot create the wrapper's Python constants");
        p_PyErr_Clear();
    }
    p_PyGILState_Release(g);
    return ok ? 0 : -1;
}

/* Requirements of the FMU (resources/python_requires.txt: import names), "" if none. */
static void requirements(const DcsInstance *in, char *out, size_t n)
{
    char *line = dcs_read_resource_line(in->resources, "python_requires.txt");
    snprintf(out, n, "%s", line != NULL ? line : "");
    free(line);
}

/* Find and start a Python for a host without one. On failure *message (malloc'd) is the ONE
 * message listing every candidate tried, what it lacked and how to fix it. */
static int start_in_plain_host(DcsInstance *in, char **message)
{
    char requires[512], unzip[4096], *slash, *report = NULL;
    const char *want = wanted_version();
    const char *xdg = getenv("XDG_CONFIG_HOME");
    int rc, n;
    requirements(in, requires, sizeof requires);
    snprintf(unzip, sizeof unzip, "%s", in->resources);
    slash = strrchr(unzip, '/');
    if (slash != NULL && slash != unzip)
        *slash = '\0'; /* <unzip>/resources -> <unzip> */
    rc = dcs_discover_python(unzip, want, requires, DCS_BUILD_PYTHON, load_candidate, NULL,
                             &report);
    if (rc != 0) {
        const char *fmt =
            "%s: fmi2Instantiate: no usable Python found. This FMU runs its model in Python "
            "%s%s%s; the host process has no Python of its own, so the FMU looks for one, in "
            "this order:\n%s"
            "How to fix: install %s into a Python %s on PATH (python%s -m pip install %s), or "
            "name a Python %s that has them: $DRILLCOSIM_PYTHON=/path/to/python3, or a line "
            "'python = /path/to/python3' in %s/drillcosim/drillcosim.conf. PYTHONHOME and "
            "PYTHONPATH are ignored. See docs/interop.md of drillcosim.";
        const char *rep = report != NULL ? report : "  (out of memory)\n";
        const char *req = requires[0] ? requires : "nothing";
        const char *cfg = xdg != NULL && xdg[0] == '/' ? xdg : "~/.config";
        n = snprintf(NULL, 0, fmt, in->name, want, requires[0] ? " with " : "", requires, rep,
                     req, want, want, req, want, cfg);
        *message = n > 0 ? (char *)malloc((size_t)n + 1) : NULL;
        if (*message != NULL)
            snprintf(*message, (size_t)n + 1, fmt, in->name, want, requires[0] ? " with " : "",
                     requires, rep, req, want, want, req, want, cfg);
    } else {
        dcs_log(in, fmi2OK, "logAll", "%s: fmi2Instantiate: the host has no Python; "
                "candidates:\n%s", in->name, report != NULL ? report : "");
    }
    free(report);
    return rc;
}

int dcs_python_ready(DcsInstance *in)
{
    int rc = 0;
    char why[1024] = "";
    char *message = NULL;
    pthread_mutex_lock(&g_lock);
    if (g_ready) {
        rc = 0;
    } else if (g_final_error != NULL) {
        rc = -1;
    } else if (dlsym(RTLD_DEFAULT, "Py_IsInitialized") != NULL) {
        g_loaded = 1; /* the process's own libpython: nothing else can be tried */
        rc = resolve_api(RTLD_DEFAULT, why, sizeof why);
        if (rc == 0 && !version_fits(p_Py_GetVersion())) {
            snprintf(why, sizeof why, "this process runs Python %.20s, but the FMU's wrapper "
                     "is compiled for Python %s: load the FMU from a Python %s process (or "
                     "rebuild it with this Python: python -m drillcosim.fmu_src.build)",
                     p_Py_GetVersion(), wanted_version(), wanted_version());
            rc = -1;
        } else if (rc == 0 && !p_Py_IsInitialized()) {
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
    pthread_mutex_unlock(&g_lock);
    return rc;
}
