/*
 * Finding a Python for a host process that has none (a C/C++ FMI tool such as fmusim).
 *
 * Candidates, in this order (docs/interop.md):
 *   1. $DRILLCOSIM_PYTHON, an interpreter path;
 *   2. a config file with a line "python = /path/to/python3": first
 *      <FMU unzip folder>/drillcosim.conf (can be shipped inside the .fmu), then the user's
 *      (POSIX: $XDG_CONFIG_HOME/drillcosim/drillcosim.conf, default ~/.config/drillcosim/...;
 *      Windows: %APPDATA%\drillcosim\drillcosim.conf);
 *   3. the installed ones:
 *      on $PATH, folder by folder in PATH order: "python3" (Windows: "python.exe", then
 *      "python3.exe"), then "python3.B" (B: the minor version that built the FMU), then
 *      "python3.M" for the other supported M, newest first (Windows: with ".exe");
 *      then, on Windows, those CPython's installer registered (PEP 514: HKEY_CURRENT_USER,
 *      then HKEY_LOCAL_MACHINE, Software\Python\PythonCore\3.M), 3.B first, then newest;
 *   4. the interpreter that built the FMU (the only absolute path of the building machine;
 *      not recorded in a binary cross-built for another system).
 * An explicit choice (1 or 2) that does not fit ends the search: the FMU never runs in
 * another Python than the one named.
 *
 * The first candidate that fits is used: CPython 3.10 to 3.13 (any of them: the wrapper uses
 * the stable ABI only; the building version is preferred only among the names of one PATH
 * folder), a shared libpython, every module the FMU requires importable.
 * Each candidate is checked in a child process (dcs_run_process of the platform layer: stdin
 * the null device, stdout and stderr into a pipe, killed after CHECK_TIMEOUT_MS):
 *     <candidate> -E -X utf8 -c CHECK_SCRIPT <min minor> <max minor> <module> ...
 * -E ignores PYTHONHOME, PYTHONPATH and every other PYTHON* variable and -X utf8 is the UTF-8
 * mode, the two settings of the embedded interpreter (dcs_python.c): what the child sees is
 * what the FMU will see. The child reports its version, sys.executable, its shared libpython
 * and the required modules it cannot import.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dcs_discover.h"

#define CHECK_TIMEOUT_MS 120000
#define MAX_PATH_CANDIDATES 16
#define MAX_INSTALLED 16
#define MAX_MODULES 16
#define CONFIG_NAME "drillcosim.conf"

/* Runs in the candidate (Python >= 3.6 syntax); argv: min minor, max minor, modules. */
static const char CHECK_SCRIPT[] =
    "import sys\n"
    "v = sys.version_info\n"
    "print('dcs:version=%d.%d.%d' % (v[0], v[1], v[2]))\n"
    "print('dcs:executable=' + (sys.executable or ''))\n"
    "if v[0] == 3 and int(sys.argv[1]) <= v[1] <= int(sys.argv[2]):\n"
    "    import os, sysconfig\n"
    "    lib = ''\n"
    "    if sys.platform == 'win32':\n"
    "        import _winapi\n"
    "        lib = _winapi.GetModuleFileName(sys.dllhandle)\n"
    "    else:\n"
    "        d = sysconfig.get_config_var('LIBDIR') or ''\n"
    "        for k in ('INSTSONAME', 'LDLIBRARY'):\n"
    "            n = sysconfig.get_config_var(k) or ''\n"
    "            if '.so' in n and os.path.isfile(os.path.join(d, n)):\n"
    "                lib = os.path.join(d, n)\n"
    "                break\n"
    "    print('dcs:libpython=' + lib)\n"
    "    for m in sys.argv[3:]:\n"
    "        try:\n"
    "            __import__(m)\n"
    "        except Exception as e:\n"
    "            t = str(e).strip().splitlines()\n"
    "            print('dcs:missing=%s (%s: %s)' % (m, type(e).__name__, t[0] if t else ''))\n"
    "print('dcs:done')\n";

/* ------------------------------------------------------------------ growing text */
typedef struct {
    char *buf;
    size_t len, cap;
} Text;

static void text_add(Text *t, const char *fmt, ...) DCS_PRINTF(2, 3);

static void text_add(Text *t, const char *fmt, ...)
{
    va_list ap;
    int n;
    va_start(ap, fmt);
    n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (n > 0 && t->len + (size_t)n + 1 > t->cap) {
        size_t cap = 2 * (t->len + (size_t)n + 1);
        char *grown = (char *)realloc(t->buf, cap);
        if (grown != NULL) {
            t->buf = grown;
            t->cap = cap;
        }
    }
    if (n > 0 && t->len + (size_t)n + 1 <= t->cap) {
        va_start(ap, fmt);
        vsnprintf(t->buf + t->len, (size_t)n + 1, fmt, ap);
        va_end(ap);
        t->len += (size_t)n;
    }
}

/* The next token of *cursor delimited by any of seps (NUL-terminated in place), NULL at the
 * end; *cursor moves past it (strtok_r, which Windows' C runtime lacks). */
static char *next_token(char **cursor, const char *seps)
{
    char *start = *cursor + strspn(*cursor, seps), *end = start + strcspn(start, seps);
    *cursor = *end ? end + 1 : end;
    *end = '\0';
    return *start != '\0' ? start : NULL;
}

/* ------------------------------------------------------------ one child check */
/* Run the check script in `exe`; its merged stdout/stderr lands in out (NUL-terminated).
 * Returns 0 with *exit_code when it ran to its end, -1 if it could not be started or did
 * not answer in time (why set). */
static int run_child(const char *exe, const DcsWant *want, const char *requires, char *out,
                     size_t nout, int *exit_code, char *why, size_t nwhy)
{
    char mods[1024], lo[16], hi[16];
    const char *argv[8 + MAX_MODULES + 1];
    char *tok, *cursor = mods;
    int argc = 0;
    snprintf(mods, sizeof mods, "%s", requires);
    snprintf(lo, sizeof lo, "%d", want->min_minor);
    snprintf(hi, sizeof hi, "%d", want->max_minor);
    argv[argc++] = exe;
    argv[argc++] = "-E";
    argv[argc++] = "-X";
    argv[argc++] = "utf8";
    argv[argc++] = "-c";
    argv[argc++] = CHECK_SCRIPT;
    argv[argc++] = lo;
    argv[argc++] = hi;
    for (tok = next_token(&cursor, " \t\r\n"); tok != NULL && argc < 8 + MAX_MODULES;
         tok = next_token(&cursor, " \t\r\n"))
        argv[argc++] = tok;
    argv[argc] = NULL;
    return dcs_run_process(argv, out, nout, CHECK_TIMEOUT_MS, exit_code, why, nwhy);
}

/* Value of "dcs:<key>=" in the child's output (the first line), copied into dst. */
static int field(const char *out, const char *key, char *dst, size_t n)
{
    char pat[64];
    const char *p, *e;
    int found = 0;
    snprintf(pat, sizeof pat, "dcs:%s=", key);
    p = strstr(out, pat);
    if (p != NULL && (p == out || p[-1] == '\n')) {
        p += strlen(pat);
        e = strchr(p, '\n');
        snprintf(dst, n, "%.*s", (int)(e != NULL ? e - p : (long)strlen(p)), p);
        found = 1;
    }
    return found;
}

/* The line of the child's output that is not ours and says what went wrong: the last one after
 * a Python traceback (the exception), else the first (e.g. "pyenv: python3.13: command not
 * found" of a pyenv shim, whose later lines are advice). */
static void foreign_line(const char *out, char *dst, size_t n)
{
    const char *p = out, *line_end;
    int traceback = strstr(out, "Traceback (most recent call last)") != NULL;
    dst[0] = '\0';
    while (*p && (traceback || dst[0] == '\0')) {
        line_end = strchr(p, '\n');
        if (line_end == NULL)
            line_end = p + strlen(p);
        if (line_end > p && strncmp(p, "dcs:", 4) != 0)
            snprintf(dst, n, "%.*s", (int)(line_end - p), p);
        p = *line_end ? line_end + 1 : line_end;
    }
}

/* Check one interpreter; 0 if it fits (py filled), else -1 with the reason in why. */
static int check_candidate(const char *exe, const DcsWant *want, const char *requires,
                           DcsPython *py, char *why, size_t nwhy)
{
    static char out[65536];
    char line[512];
    int exit_code = -1, kind = dcs_is_regular_file(exe), fits = -1;
    why[0] = '\0';
    if (kind == 0) {
        snprintf(why, nwhy, "not found");
    } else if (kind < 0 || !dcs_is_executable(exe)) {
        snprintf(why, nwhy, "not an executable file");
    } else if (run_child(exe, want, requires, out, sizeof out, &exit_code, why, nwhy) != 0) {
        /* why set by the platform layer */
    } else if (strstr(out, "dcs:done") == NULL) {
        foreign_line(out, line, sizeof line);
        snprintf(why, nwhy, "does not run as a Python 3 interpreter (exit status %d%s%s)",
                 exit_code, line[0] ? ": " : "", line);
    } else {
        const char *m;
        int major = 0, minor = -1;
        field(out, "version", py->version, sizeof py->version);
        field(out, "executable", py->executable, sizeof py->executable);
        if (sscanf(py->version, "%d.%d", &major, &minor) != 2 || major != 3 ||
            minor < want->min_minor || minor > want->max_minor) {
            snprintf(why, nwhy, "Python %s, but the FMU runs on CPython 3.%d to 3.%d",
                     py->version, want->min_minor, want->max_minor);
        } else if (!field(out, "libpython", py->libpython, sizeof py->libpython) ||
                   py->libpython[0] == '\0') {
            snprintf(why, nwhy, "Python %s without a shared libpython (install it, e.g. "
                     "Debian's libpython3.%d, or use a Python built with --enable-shared)",
                     py->version, minor);
        } else if ((m = strstr(out, "dcs:missing=")) != NULL) {
            Text t = {NULL, 0, 0};
            while (m != NULL) {
                const char *e = strchr(m, '\n');
                m += strlen("dcs:missing=");
                text_add(&t, "%s%.*s", t.len ? ", " : "",
                         (int)(e != NULL ? e - m : (long)strlen(m)), m);
                m = e != NULL ? strstr(e, "dcs:missing=") : NULL;
            }
            snprintf(why, nwhy, "Python %s, lacks %s", py->version, t.buf ? t.buf : "?");
            free(t.buf);
        } else if (py->executable[0] == '\0') {
            snprintf(why, nwhy, "Python %s does not know its executable (sys.executable)",
                     py->version);
        } else {
            fits = 0;
        }
    }
    return fits;
}

/* ------------------------------------------------------------------ the order */
typedef struct {
    const DcsWant *want;
    const char *requires, *used;
    DcsLoad load;
    void *ctx;
    Text report;
    int found, stop, n_tried;
    char tried[MAX_PATH_CANDIDATES + MAX_INSTALLED + 4][2 * DCS_PATH_MAX + 2]; /* seen_before */
} Search;

static char *dcs_path_dup(const char *s)
{
    size_t n = strlen(s) + 1;
    char *d = (char *)malloc(n);
    if (d != NULL)
        memcpy(d, s, n);
    return d;
}

/* Whether exe was tried already (recorded if not). A candidate is its folder and the file
 * it resolves to: /bin/python3 and /usr/bin/python3 on a merged /usr are one, so are a
 * folder's python3 and python3.11 links to one file, while a venv's python (a symlink to its
 * base interpreter; the venv is found beside the link) stays distinct from that base. */
static int seen_before(Search *s, const char *exe)
{
    char dir[DCS_PATH_MAX], real_dir[DCS_PATH_MAX], real_exe[DCS_PATH_MAX];
    char key[sizeof s->tried[0]];
    const char *p, *slash = NULL;
    int i, seen = 0;
    for (p = exe; *p; p++)
        if (dcs_is_dir_sep(*p))
            slash = p;
    snprintf(dir, sizeof dir, "%.*s", slash != NULL ? (int)(slash - exe) : 0, exe);
    if (slash == NULL || slash == exe || dcs_canonical_path(dir, real_dir, sizeof real_dir) != 0)
        snprintf(real_dir, sizeof real_dir, "%s", dir);
    if (dcs_canonical_path(exe, real_exe, sizeof real_exe) != 0)
        snprintf(real_exe, sizeof real_exe, "%s", exe);
    snprintf(key, sizeof key, "%s|%s", real_dir, real_exe);
    for (i = 0; i < s->n_tried && !seen; i++)
        seen = strcmp(s->tried[i], key) == 0;
    if (!seen && s->n_tried < (int)(sizeof s->tried / sizeof s->tried[0]))
        snprintf(s->tried[s->n_tried++], sizeof s->tried[0], "%s", key);
    return seen;
}

/* Load a candidate that fits (py; checked, or known to fit) and report a line for it; if
 * it does not load, the line gives why. explicit: stop whatever happens. */
static void offer(Search *s, const char *label, const char *exe, const DcsPython *py,
                  char *why, size_t nwhy, int explicit_choice)
{
    if (py != NULL && s->load(py, s->ctx, why, nwhy, &s->stop) == 0) {
        s->found = 1;
        text_add(&s->report, "  %s %s: Python %s (%s), %s\n", label, exe, py->version,
                 py->executable, s->used);
    } else {
        text_add(&s->report, "  %s %s: %s%s\n", label, exe, why,
                 explicit_choice ? " (an explicit choice: no other candidate is tried)" : "");
    }
    if (explicit_choice)
        s->stop = 1;
}

/* Check one candidate in a child process, then offer it. */
static void try_candidate(Search *s, const char *label, const char *exe, int explicit_choice)
{
    DcsPython py;
    char why[2048];
    memset(&py, 0, sizeof py);
    offer(s, label, exe,
          check_candidate(exe, s->want, s->requires, &py, why, sizeof why) == 0 ? &py : NULL,
          why, sizeof why, explicit_choice);
}

/* "python = /path" of a config file into dst; 1 if found. */
static int config_python(const char *file, char *dst, size_t n)
{
    char line[DCS_PATH_MAX + 64];
    int found = 0;
    FILE *f = dcs_fopen(file, "r");
    while (f != NULL && !found && fgets(line, sizeof line, f) != NULL) {
        char *p = line, *e;
        while (*p == ' ' || *p == '\t')
            p++;
        if (strncmp(p, "python", 6) != 0)
            continue;
        p += 6;
        while (*p == ' ' || *p == '\t')
            p++;
        if (*p != '=')
            continue;
        p++;
        while (*p == ' ' || *p == '\t' || *p == '"' || *p == '\'')
            p++;
        e = p + strlen(p);
        while (e > p && (e[-1] == '\n' || e[-1] == '\r' || e[-1] == ' ' || e[-1] == '\t' ||
                         e[-1] == '"' || e[-1] == '\''))
            *--e = '\0';
        dcs_expand_home(p, dst, n);
        found = dst[0] != '\0';
    }
    if (f != NULL)
        fclose(f);
    return found;
}

static void try_config_files(Search *s, const char *unzip_dir)
{
    char files[2][DCS_PATH_MAX], exe[DCS_PATH_MAX], label[2 * DCS_PATH_MAX + 64];
    int i, n = 1;
    snprintf(files[0], DCS_PATH_MAX, "%s/%s", unzip_dir, CONFIG_NAME);
    if (dcs_user_config_file(files[1], DCS_PATH_MAX) == 0)
        n = 2;
    for (i = 0; i < n && !s->stop; i++) {
        if (!dcs_exists(files[i]))
            continue;
        snprintf(label, sizeof label, "2. config file %s: python =", files[i]);
        if (config_python(files[i], exe, sizeof exe)) {
            seen_before(s, exe);
            try_candidate(s, label, exe, 1);
        } else {
            text_add(&s->report, "  2. config file %s: no line 'python = /path/to/python3' "
                     "(an explicit choice: no other candidate is tried)\n", files[i]);
            s->stop = 1;
        }
    }
    if (!s->stop)
        text_add(&s->report, "  2. config file: none of %s%s%s exists\n", files[0],
                 n > 1 ? ", " : "", n > 1 ? files[1] : "");
}

/* The names tried in one PATH folder, in order (see the top of this file); their count. */
static int path_names(const DcsWant *want, char names[][32], int max)
{
    int n = 0, minor, k;
    for (k = 0; dcs_python_plain_names[k] != NULL && n < max; k++)
        snprintf(names[n++], 32, "%s", dcs_python_plain_names[k]);
    if (want->prefer_minor >= want->min_minor && want->prefer_minor <= want->max_minor &&
        n < max)
        snprintf(names[n++], 32, "python3.%d%s", want->prefer_minor, dcs_executable_suffix);
    for (minor = want->max_minor; minor >= want->min_minor && n < max; minor--)
        if (minor != want->prefer_minor)
            snprintf(names[n++], 32, "python3.%d%s", minor, dcs_executable_suffix);
    return n;
}

static void try_path(Search *s)
{
    char *path = dcs_getenv("PATH");
    char names[16][32], exe[DCS_PATH_MAX], seps[2] = {dcs_path_list_sep, '\0'};
    char *copy, *cursor, *dir;
    int n_found = 0, k, n_names = path_names(s->want, names, 16);
    copy = cursor = dcs_path_dup(path != NULL ? path : "");
    for (dir = copy != NULL ? next_token(&cursor, seps) : NULL;
         dir != NULL && !s->stop && n_found < MAX_PATH_CANDIDATES;
         dir = next_token(&cursor, seps)) {
        size_t len = strlen(dir);
        if (!dcs_is_absolute(dir)) /* a relative PATH entry would depend on the host's cwd */
            continue;
        while (len > 1 && dcs_is_dir_sep(dir[len - 1]))
            dir[--len] = '\0';
        for (k = 0; k < n_names && !s->stop && n_found < MAX_PATH_CANDIDATES; k++) {
            snprintf(exe, sizeof exe, "%s/%s", dir, names[k]);
            if (!dcs_is_executable(exe) || seen_before(s, exe))
                continue;
            n_found++;
            try_candidate(s, "3. on PATH:", exe, 0);
            s->stop = s->stop || s->found;
        }
    }
    free(copy);
    if (n_found == 0)
        text_add(&s->report, "  3. on PATH: no %s or python3.%d%s to python3.%d%s in %s\n",
                 dcs_python_plain_names[0], s->want->min_minor, dcs_executable_suffix,
                 s->want->max_minor, dcs_executable_suffix,
                 path != NULL && path[0] ? path : "(PATH is empty)");
    free(path);
}

/* 3. (Windows) the Pythons the installer registered: the building minor first, then as
 * listed (newest first). Nothing on a system that keeps no list. */
static void try_installed(Search *s)
{
    static DcsInstalled found[MAX_INSTALLED];
    char label[512];
    int n = dcs_installed_pythons(found, MAX_INSTALLED), pass, i, fitting = 0;
    for (pass = 0; pass < 2 && !s->stop; pass++) {
        for (i = 0; i < n && !s->stop; i++) {
            int preferred = found[i].minor == s->want->prefer_minor;
            if ((pass == 0) != preferred || found[i].minor < s->want->min_minor ||
                found[i].minor > s->want->max_minor)
                continue;
            fitting++;
            if (seen_before(s, found[i].executable))
                continue;
            snprintf(label, sizeof label, "3. registered (%s):", found[i].where);
            try_candidate(s, label, found[i].executable, 0);
            s->stop = s->stop || s->found;
        }
    }
    if (n >= 0 && fitting == 0)
        text_add(&s->report, "  3. registered: no CPython 3.%d to 3.%d (64-bit) under "
                 "Software\\Python\\PythonCore of HKEY_CURRENT_USER or HKEY_LOCAL_MACHINE%s\n",
                 s->want->min_minor, s->want->max_minor,
                 n > 0 ? " (only other versions)" : "");
}

int dcs_discover_python(const char *unzip_dir, const DcsWant *want, const char *requires,
                        const char *build_python, DcsLoad load, void *ctx, const char *used,
                        char **report)
{
    Search *s = (Search *)calloc(1, sizeof *s);
    char *env = dcs_getenv("DRILLCOSIM_PYTHON");
    int rc = -1;
    if (s != NULL) {
        s->want = want;
        s->requires = requires;
        s->used = used;
        s->load = load;
        s->ctx = ctx;
        if (env != NULL && env[0] != '\0') {
            seen_before(s, env);
            try_candidate(s, "1. $DRILLCOSIM_PYTHON =", env, 1);
        } else {
            text_add(&s->report, "  1. $DRILLCOSIM_PYTHON: not set\n");
        }
        if (!s->stop)
            try_config_files(s, unzip_dir);
        if (!s->stop)
            try_path(s);
        if (!s->stop)
            try_installed(s);
        if (!s->stop) {
            if (build_python == NULL || build_python[0] == '\0')
                text_add(&s->report, "  4. the building interpreter: not recorded (a binary "
                         "cross-built on another system)\n");
            else if (seen_before(s, build_python))
                text_add(&s->report, "  4. the building interpreter %s: tried above\n",
                         build_python);
            else
                try_candidate(s, "4. the building interpreter", build_python, 0);
        }
        rc = s->found ? 0 : -1;
        *report = s->report.buf;
        free(s);
    }
    free(env);
    return rc;
}
