/*
 * The operating system as the wrapper sees it: shared libraries, files and paths, the
 * environment, child processes, the Pythons a system lists as installed. One implementation
 * per platform, each a whole file that compiles to nothing elsewhere (the build lists both):
 *   dcs_platform_posix.c  Linux and other POSIX systems: dlopen/dlsym, posix_spawn, realpath;
 *   dcs_platform_win32.c  Windows (cross-built with mingw-w64): LoadLibraryExW, CreateProcessW,
 *                         the registry keys of CPython's installer (PEP 514).
 * Every path and text crossing this interface is UTF-8 (Windows: converted to UTF-16 at the
 * API; '/' and '\' both separate folders there). The lock type is in dcs_lock.h (a static
 * initialiser needs the type). Nothing here needs Python.h.
 */
#ifndef DCS_PLATFORM_H
#define DCS_PLATFORM_H

#include <stddef.h>
#include <stdio.h>
#include <wchar.h>

#define DCS_PATH_MAX 4096

/* printf-like functions, checked by the compiler against the printf the C runtime has:
 * mingw-w64's C99 one in a Windows build (its default archetype, ms_printf, knows no %zu). */
#ifdef __MINGW_PRINTF_FORMAT
#define DCS_PRINTF(f, a) __attribute__((format(__MINGW_PRINTF_FORMAT, f, a)))
#else
#define DCS_PRINTF(f, a) __attribute__((format(printf, f, a)))
#endif

/* ------------------------------------------------------------------ shared libraries */
/* Load the library at path with every symbol resolved now and visible to libraries loaded
 * after it (POSIX RTLD_GLOBAL: extension modules need libpython's symbols; Windows: the
 * library's own folder is searched for its dependencies, e.g. python3XX.dll's
 * vcruntime140.dll). NULL on failure, with the system's reason in why. */
void *dcs_library_open(const char *path, char *why, size_t nwhy);
void dcs_library_close(void *lib);
/* Address of the function or variable name in lib (a handle of dcs_library_open or
 * dcs_process_python), NULL if it has none. */
void *dcs_library_symbol(void *lib, const char *name);
/* Whether a libpython is loaded in this process already (a Python host, or a host linked
 * against one): 1 with *lib its handle for dcs_library_symbol, else 0. */
int dcs_process_python(void **lib);
/* File system path of the library this code is in (malloc'd; NULL if unknown). */
char *dcs_own_library_path(void);

/* ------------------------------------------------------------------ files and paths */
FILE *dcs_fopen(const char *path, const char *mode);
int dcs_exists(const char *path);
/* A regular file this user may run (Windows: a regular file). */
int dcs_is_executable(const char *path);
/* 1 if path is a regular file, 0 if it does not exist, -1 if it is something else. */
int dcs_is_regular_file(const char *path);
int dcs_is_absolute(const char *path);
int dcs_is_dir_sep(char c);
/* The separator of the entries of PATH (':' or ';'). */
extern const char dcs_path_list_sep;
/* The path with every link resolved (POSIX realpath; Windows: the final path of the open
 * file), into out; 0 on success, -1 if it cannot be resolved (out untouched). */
int dcs_canonical_path(const char *path, char *out, size_t n);
/* The path part of a file URI with its percent escapes decoded ("///a/b", "//host/a/b",
 * "/C:/a" or "///C:/a" on Windows) as a file system path (malloc'd; NULL if out of memory). */
char *dcs_file_uri_path(const char *decoded);
/* "~/x" -> the user's home folder + "/x"; any other path unchanged. Into out. */
void dcs_expand_home(const char *path, char *out, size_t n);

/* ------------------------------------------------------------------ environment */
/* The value of an environment variable (malloc'd UTF-8), NULL if unset. */
char *dcs_getenv(const char *name);
/* The user's drillcosim.conf (POSIX: $XDG_CONFIG_HOME/drillcosim/drillcosim.conf, default
 * ~/.config/...; Windows: %APPDATA%\drillcosim\drillcosim.conf) into out: 0, or -1 if the
 * system names no such folder (no HOME / APPDATA). */
int dcs_user_config_file(char *out, size_t n);

/* ------------------------------------------------------------------ Python executables */
/* The unversioned names of a Python 3 interpreter in a PATH folder, in the order tried
 * (NULL-terminated: "python3"; Windows "python.exe", "python3.exe"), and the suffix of the
 * versioned names ("python3.12" + suffix). */
extern const char *const dcs_python_plain_names[];
extern const char dcs_executable_suffix[];

/* How messages name things here: an install command, a Python's path, the variable. */
typedef struct {
    const char *pip, *python_path, *python_variable;
} DcsWording;
extern const DcsWording dcs_wording;

/* A Python the system lists as installed (Windows: PEP 514). */
typedef struct {
    int minor;                     /* 3.minor */
    char executable[DCS_PATH_MAX]; /* its python.exe */
    char where[256];               /* where it is listed, for the report */
} DcsInstalled;

/* The CPython 3 installations the system lists (Windows: the registry keys CPython's installer
 * writes, HKEY_CURRENT_USER before HKEY_LOCAL_MACHINE, 64-bit ones only: a 32-bit Python
 * cannot run in this 64-bit process), up to max of them, each key's order; their count, or -1
 * on a system that keeps no such list (POSIX). */
int dcs_installed_pythons(DcsInstalled *out, int max);

/* ------------------------------------------------------------------ child processes */
/* Run the program argv[0] (a path) with the arguments argv[1..] (NULL-terminated): stdin the
 * null device, stdout and stderr into one pipe read into out (NUL-terminated; what does not
 * fit is read and dropped so the child never blocks), default signal dispositions (POSIX; no
 * fork of a possibly threaded host), no console window (Windows); killed after timeout_ms.
 * Lines end in "\n" alone: on Windows each line's trailing white space is removed (the "\r"
 * of a child's text mode; a Windows file name cannot end with a space), on POSIX nothing.
 * Returns 0 when it ended by itself, *exit_code its exit status (-1 if a signal ended it);
 * -1 if it could not be started or was killed at the timeout (why says which). */
int dcs_run_process(const char *const argv[], char *out, size_t nout, long timeout_ms,
                    int *exit_code, char *why, size_t nwhy);

/* ------------------------------------------------------------------ text */
/* UTF-8 -> wchar_t (the Python C-API's file names); bytes that are not UTF-8 become U+DC80..
 * U+DCFF as Python decodes file names (POSIX). 0 on success, -1 if it does not fit or is not
 * valid (Windows). */
int dcs_utf8_to_wide(const char *s, wchar_t *out, size_t n);

#endif
