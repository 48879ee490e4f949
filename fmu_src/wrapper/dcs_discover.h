/*
 * Finding a Python for a host process that has none (a C/C++ FMI tool).
 */
#ifndef DCS_DISCOVER_H
#define DCS_DISCOVER_H

#include <stddef.h>

#include "dcs_platform.h" /* DCS_PATH_MAX, and what the search asks of the system */

/* Which Pythons fit: 3.min_minor to 3.max_minor; prefer_minor (the building one, 0 if
 * unknown) is tried first among the versioned names of a PATH folder. */
typedef struct {
    int min_minor, max_minor, prefer_minor;
} DcsWant;

/* A candidate interpreter as its child process described itself. */
typedef struct {
    char executable[DCS_PATH_MAX]; /* sys.executable (a venv's python, not the shim) */
    char libpython[DCS_PATH_MAX];  /* its shared libpython */
    char version[32];              /* "3.11.7" */
} DcsPython;

/* Load and start a candidate that passed the child check (or that is known to fit without
 * one). Returns 0 when it runs; else -1 with the reason in why and *stop = 1 if no other
 * candidate may be tried any more (a libpython is loaded in the process by now). */
typedef int (*DcsLoad)(const DcsPython *py, void *ctx, char *why, size_t nwhy, int *stop);

/* Try the candidates in the documented order (see dcs_discover.c) until one passes the child
 * check and loads. want: the versions; requires: import names separated by blanks; build_python:
 * the interpreter that built the FMU ("" if unknown); unzip_dir: the FMU's unzip folder.
 * used: the word for the candidate that loaded ("used"). Returns 0 on success. *report
 * (malloc'd, the caller frees) lists each candidate tried and what it lacked (or that it is
 * used), one per line. */
int dcs_discover_python(const char *unzip_dir, const DcsWant *want, const char *requires,
                        const char *build_python, DcsLoad load, void *ctx, const char *used,
                        char **report);

#endif
