/*
 * pyconfig.h for compiling the wrapper for 64-bit Windows on another system (mingw-w64).
 *
 * The wrapper needs only the declarations of the limited API of 3.10 (dcs_python.h), whose
 * types are the same on every platform except what pyconfig.h says about the target: the
 * sizes of C types (Windows is LLP64: long is 32 bits), Py_ssize_t, and that the core is a DLL
 * (PyAPI_FUNC = __declspec(dllimport); the wrapper never links it: every function is looked up
 * with GetProcAddress). The Python headers of the building interpreter are used with this file
 * in place of their pyconfig.h (fmu_src/platforms.py). Every value below is the one of
 * CPython's own PC/pyconfig.h(.in) for MS_WIN64 with a GNU compiler (__MINGW32__/__GNUC__
 * branches), 3.10 to 3.13; the rest of that file describes how CPython itself is built
 * (HAVE_* of its modules), which the limited API's declarations do not read.
 * tests/test_windows.py runs the result in the official CPython for Windows under wine.
 */
#ifndef Py_CONFIG_H
#define Py_CONFIG_H

#if !defined(_WIN64) || !defined(__GNUC__)
#error "this pyconfig.h is for 64-bit Windows targets of a GNU compiler (mingw-w64)"
#endif

#include <io.h>
#include <limits.h>
#include <stdint.h>
#include <stdio.h>

#define MS_WIN32
#define MS_WIN64
#define MS_WINDOWS
#define NT_THREADS
#define WITH_THREAD
#define PLATFORM "win32"
#define COMPILER "[gcc]"

/* The core is a DLL: PyAPI_FUNC/PyAPI_DATA declare dllimport (never linked here). */
#define Py_ENABLE_SHARED 1
#define MS_COREDLL
#define HAVE_DECLSPEC_DLL

/* LLP64 */
#define LONG_BIT 32
#define WORD_BIT 32
#define SIZEOF_SHORT 2
#define SIZEOF_INT 4
#define SIZEOF_LONG 4
#define ALIGNOF_LONG 4
#define SIZEOF_LONG_LONG 8
#define SIZEOF_DOUBLE 8
#define SIZEOF_FLOAT 4
#define SIZEOF_VOID_P 8
#define SIZEOF_SIZE_T 8
#define ALIGNOF_SIZE_T 8
#define ALIGNOF_MAX_ALIGN_T 8
#define SIZEOF_TIME_T 8
#define SIZEOF_OFF_T 4
#define SIZEOF_FPOS_T 8
#define SIZEOF_HKEY 8
#define SIZEOF_WCHAR_T 2
#define SIZEOF__BOOL 1
#define SIZEOF_PID_T SIZEOF_INT
#define HAVE_LARGEFILE_SUPPORT

typedef long long Py_ssize_t; /* __int64 */
#define HAVE_PY_SSIZE_T 1
#if PY_MINOR_VERSION >= 11 /* 3.10's pyport.h defines it itself (patchlevel.h comes first) */
#define PY_SSIZE_T_MAX LLONG_MAX
#endif

#define PY_LONG_LONG long long
#define PY_LLONG_MIN LLONG_MIN
#define PY_LLONG_MAX LLONG_MAX
#define PY_ULLONG_MAX ULLONG_MAX
#define PY_UINT32_T uint32_t
#define PY_UINT64_T uint64_t
#define PY_INT32_T int32_t
#define PY_INT64_T int64_t

#define DOUBLE_IS_LITTLE_ENDIAN_IEEE754 1
#define Py_WINVER 0x0A00

/* headers the Python headers may include */
#define HAVE_ERRNO_H 1
#define HAVE_FCNTL_H 1
#define HAVE_PROCESS_H 1
#define HAVE_SIGNAL_H 1
#define HAVE_STDDEF_H 1
#define HAVE_SYS_STAT_H 1
#define HAVE_SYS_TYPES_H 1
#define HAVE_WCHAR_H 1
#define STDC_HEADERS 1

#endif /* !Py_CONFIG_H */
