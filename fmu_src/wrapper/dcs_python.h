/*
 * The Python C-API as the wrapper sees it: function pointers looked up with dlsym().
 *
 * The library has no link-time dependency on libpython and references no Python data symbol
 * (Py_None, PyFloat_Type, ...): it loads in any host. Only macros that read object fields
 * (PyList_GET_ITEM, PyBytes_AS_STRING, Py_TYPE flags) are used directly.
 */
#ifndef DCS_PYTHON_H
#define DCS_PYTHON_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "dcs_wrapper.h"

#define DCS_PYAPI(X) \
    X(int, Py_IsInitialized, (void)) \
    X(const char *, Py_GetVersion, (void)) \
    X(void, PyPreConfig_InitPythonConfig, (PyPreConfig *)) \
    X(PyStatus, Py_PreInitialize, (const PyPreConfig *)) \
    X(void, PyConfig_InitPythonConfig, (PyConfig *)) \
    X(PyStatus, PyConfig_SetBytesString, (PyConfig *, wchar_t **, const char *)) \
    X(PyStatus, Py_InitializeFromConfig, (const PyConfig *)) \
    X(void, PyConfig_Clear, (PyConfig *)) \
    X(int, PyStatus_Exception, (PyStatus)) \
    X(PyThreadState *, PyEval_SaveThread, (void)) \
    X(PyGILState_STATE, PyGILState_Ensure, (void)) \
    X(void, PyGILState_Release, (PyGILState_STATE)) \
    X(void, Py_IncRef, (PyObject *)) \
    X(void, Py_DecRef, (PyObject *)) \
    X(PyObject *, Py_BuildValue, (const char *, ...)) \
    X(PyObject *, PyImport_ImportModule, (const char *)) \
    X(PyObject *, PySys_GetObject, (const char *)) \
    X(PyObject *, PyObject_GetAttr, (PyObject *, PyObject *)) \
    X(int, PyObject_SetAttr, (PyObject *, PyObject *, PyObject *)) \
    X(int, PyObject_HasAttr, (PyObject *, PyObject *)) \
    X(PyObject *, PyObject_Call, (PyObject *, PyObject *, PyObject *)) \
    X(PyObject *, PyObject_VectorcallMethod, (PyObject *, PyObject *const *, size_t, \
                                              PyObject *)) \
    X(PyObject *, PyObject_Str, (PyObject *)) \
    X(int, PyObject_IsTrue, (PyObject *)) \
    X(int, PyObject_GetBuffer, (PyObject *, Py_buffer *, int)) \
    X(void, PyBuffer_Release, (Py_buffer *)) \
    X(PyObject *, PyUnicode_InternFromString, (const char *)) \
    X(PyObject *, PyUnicode_FromString, (const char *)) \
    X(PyObject *, PyUnicode_DecodeFSDefault, (const char *)) \
    X(const char *, PyUnicode_AsUTF8AndSize, (PyObject *, Py_ssize_t *)) \
    X(PyObject *, PyUnicode_Join, (PyObject *, PyObject *)) \
    X(PyObject *, PyLong_FromUnsignedLong, (unsigned long)) \
    X(PyObject *, PyLong_FromLong, (long)) \
    X(long, PyLong_AsLong, (PyObject *)) \
    X(void *, PyLong_AsVoidPtr, (PyObject *)) \
    X(PyObject *, PyFloat_FromDouble, (double)) \
    X(double, PyFloat_AsDouble, (PyObject *)) \
    X(PyObject *, PyBool_FromLong, (long)) \
    X(PyObject *, PyList_New, (Py_ssize_t)) \
    X(int, PyList_Insert, (PyObject *, Py_ssize_t, PyObject *)) \
    X(int, PyList_SetSlice, (PyObject *, Py_ssize_t, Py_ssize_t, PyObject *)) \
    X(PyObject *, PySequence_Fast, (PyObject *, const char *)) \
    X(PyObject *, PyTuple_New, (Py_ssize_t)) \
    X(PyObject *, PyDict_New, (void)) \
    X(int, PyDict_SetItemString, (PyObject *, const char *, PyObject *)) \
    X(PyObject *, PyBytes_FromStringAndSize, (const char *, Py_ssize_t)) \
    X(PyObject *, PyErr_Occurred, (void)) \
    X(void, PyErr_Fetch, (PyObject **, PyObject **, PyObject **)) \
    X(void, PyErr_NormalizeException, (PyObject **, PyObject **, PyObject **)) \
    X(void, PyErr_Clear, (void)) \
    X(void, PyErr_Restore, (PyObject *, PyObject *, PyObject *))

#define DCS_DECLARE(ret, name, args) extern ret(*p_##name) args;
DCS_PYAPI(DCS_DECLARE)
#undef DCS_DECLARE

/* Interned method and attribute names, and singletons (created once, never released). */
typedef struct {
    PyObject *setup_experiment, *enter_initialization_mode, *exit_initialization_mode,
        *do_step, *terminate, *reset, *get_real, *get_integer, *get_boolean, *get_string,
        *set_real, *set_integer, *set_boolean, *set_string, *get_fmu_state, *set_fmu_state,
        *to_bytes, *from_bytes, *fmi2_status, *real_buffers, *compiled_step,
        *compiled_step_failed, *get_log_queue, *status,
        *category, *msg, *format_exception;
    PyObject *none, *true_, *false_, *empty, *traceback;
} DcsNames;

extern DcsNames dcs_py;

/* The slave object and its protocol, for dcs_state.c (dcs_slave.c; GIL held). */
PyObject *dcs_slave_object(DcsInstance *in);
fmi2Status dcs_slave_exception(DcsInstance *in, const char *fn);
fmi2Status dcs_slave_status(DcsInstance *in, PyObject *result, const char *fn);
void dcs_slave_drain(DcsInstance *in);
/* End of a Python call that may change the slave: take its compiled step anew (see
 * dcs_slave.c) and drain its log; returns status, raised if the compiled step is unusable. */
fmi2Status dcs_slave_leave(DcsInstance *in, fmi2Status status, const char *fn);

static inline void dcs_decref(PyObject *o)
{
    if (o != NULL)
        p_Py_DecRef(o);
}

static inline void dcs_incref(PyObject *o)
{
    if (o != NULL)
        p_Py_IncRef(o);
}

#endif
