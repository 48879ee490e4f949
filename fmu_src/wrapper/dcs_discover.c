/*
 * Finding a Python for a host process that has none (a C/C++ FMI tool such as fmusim).
 *
 * Candidates, in this order (docs/interop.md):
 *   1. $DRILLCOSIM_PYTHON, an interpreter path;
 *   2. a config file with a line "python = /path/to/python3": first
 *      <FMU unzip folder>/drillcosim.conf (can be shipped inside the .fmu), then
 *      $XDG_CONFIG_HOME/drillcosim/drillcosim.conf (default ~/.config/drillcosim/...);
 *   3. on $PATH, folder by folder in PATH order: "python3", then "python3.B" (B: the minor
 *      version that built the FMU), then "python3.M" for the other supported M, newest first;
 *   4. the interpreter that built the FMU (the only absolute path of the building machine).
 * An explicit choice (1 or 2) that does not fit ends the search: the FMU never runs in
 * another Python than the one named.
 *
 * The first candidate that fits is used: CPython 3.10 to 3.13 (any of them: the wrapper uses
 * the stable ABI only; the building version is preferred only among the names of one PATH
 * folder), a shared libpython, every module the FMU requires importable.
 * Each candidate is checked in a child process started with posix_spawn (no fork of a possibly
 * threaded host), stdin /dev/null, stdout and stderr into a pipe, default signal dispositions,
 * killed after CHECK_TIMEOUT_MS:
 *     <candidate> -E -X utf8 -c CHECK_SCRIPT <min minor> <max minor> <module> ...
 * -E ignores PYTHONHOME, PYTHONPATH and every other PYTHON* variable and -X utf8 is the UTF-8
 * mode, the two settings of the embedded interpreter (dcs_python.c): what the child sees is
 * what the FMU will see. The child reports its version, sys.executable, its shared libpython
 * and the required modules it cannot import.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "dcs_discover.h"

extern char **environ;

#define CHECK_TIMEOUT_MS 120000
#define MAX_PATH_CANDIDATES 16
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
    "    d = sysconfig.get_config_var('LIBDIR') or ''\n"
    "    lib = ''\n"
    "    for k in ('INSTSONAME', 'LDLIBRARY'):\n"
    "        n = sysconfig.get_config_var(k) or ''\n"
    "        if '.so' in n and os.path.isfile(os.path.join(d, n)):\n"
    "            lib = os.path.join(d, n)\n"
    "            break\n"
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

static void text_add(Text *t, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

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

/* ------------------------------------------------------------ one child check */
static long now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long)ts.tv_sec * 1000L + ts.tv_nsec / 1000000L;
}

static int read_child(pid_t pid, int fd, char *out, size_t nout, char *why, size_t nwhy);

/* Run the check script in `exe`; its merged stdout/stderr lands in out (NUL-terminated).
 * Returns the child's wait status, -1 if it could not be started (why set). */
static int run_child(const char *exe, const DcsWant *want, const char *requires, char *out,
                     size_t nout, char *why, size_t nwhy)
{
    char mods[1024], lo[16], hi[16];
    char *argv[8 + MAX_MODULES + 1];
    char *save = NULL, *tok;
    int argc = 0, fds[2], rc, wstatus = -1;
    pid_t pid = -1;
    posix_spawn_file_actions_t actions;
    posix_spawnattr_t attr;
    sigset_t none, reset;

    snprintf(mods, sizeof mods, "%s", requires);
    snprintf(lo, sizeof lo, "%d", want->min_minor);
    snprintf(hi, sizeof hi, "%d", want->max_minor);
    argv[argc++] = (char *)exe;
    argv[argc++] = (char *)"-E";
    argv[argc++] = (char *)"-X";
    argv[argc++] = (char *)"utf8";
    argv[argc++] = (char *)"-c";
    argv[argc++] = (char *)CHECK_SCRIPT;
    argv[argc++] = lo;
    argv[argc++] = hi;
    for (tok = strtok_r(mods, " \t\r\n", &save); tok != NULL && argc < 8 + MAX_MODULES;
         tok = strtok_r(NULL, " \t\r\n", &save))
        argv[argc++] = tok;
    argv[argc] = NULL;
    out[0] = '\0';
    if (pipe2(fds, O_CLOEXEC) != 0) {
        snprintf(why, nwhy, "cannot create a pipe: %s", strerror(errno));
        pid = -1;
    } else {
        posix_spawn_file_actions_init(&actions);
        posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
        posix_spawn_file_actions_adddup2(&actions, fds[1], 1);
        posix_spawn_file_actions_adddup2(&actions, fds[1], 2);
        posix_spawnattr_init(&attr);
        sigemptyset(&none);
        sigemptyset(&reset);
        sigaddset(&reset, SIGPIPE);
        sigaddset(&reset, SIGINT);
        sigaddset(&reset, SIGTERM);
        sigaddset(&reset, SIGHUP);
        sigaddset(&reset, SIGQUIT);
        sigaddset(&reset, SIGCHLD);
        posix_spawnattr_setsigmask(&attr, &none);
        posix_spawnattr_setsigdefault(&attr, &reset);
        posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
        rc = posix_spawn(&pid, exe, &actions, &attr, argv, environ);
        posix_spawn_file_actions_destroy(&actions);
        posix_spawnattr_destroy(&attr);
        close(fds[1]);
        if (rc != 0) {
            close(fds[0]);
            snprintf(why, nwhy, "cannot be started: %s", strerror(rc));
            pid = -1;
        }
    }
    if (pid != -1)
        wstatus = read_child(pid, fds[0], out, nout, why, nwhy);
    return wstatus;
}

/* Collect the child's output until it closes the pipe or CHECK_TIMEOUT_MS passed (then it
 * is killed); reap it. Returns its wait status, -1 on a timeout (why set). */
static int read_child(pid_t pid, int fd, char *out, size_t nout, char *why, size_t nwhy)
{
    int wstatus = -1, timed_out = 0;
    size_t len = 0;
    long deadline = now_ms() + CHECK_TIMEOUT_MS;
    pid_t reaped;
    for (;;) {
        struct pollfd p;
        char trash[4096];
        ssize_t k;
        long left = deadline - now_ms();
        int r;
        if (left <= 0) {
            timed_out = 1;
            kill(pid, SIGKILL);
            break;
        }
        p.fd = fd;
        p.events = POLLIN;
        p.revents = 0;
        r = poll(&p, 1, (int)(left > 1000 ? 1000 : left));
        if (r < 0 && errno != EINTR)
            break;
        if (r <= 0)
            continue;
        if (len + 1 < nout)
            k = read(fd, out + len, nout - 1 - len);
        else
            k = read(fd, trash, sizeof trash); /* drain: the child must not block */
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0)
            break;
        if (len + 1 < nout)
            len += (size_t)k;
    }
    out[len] = '\0';
    close(fd);
    do {
        reaped = waitpid(pid, &wstatus, 0);
    } while (reaped < 0 && errno == EINTR);
    if (reaped < 0)
        wstatus = 0; /* a host that ignores SIGCHLD: reaped already, the output decides */
    if (timed_out) {
        snprintf(why, nwhy, "did not answer within %d s (killed)", CHECK_TIMEOUT_MS / 1000);
        wstatus = -1;
    }
    return wstatus;
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
    struct stat st;
    int wstatus, fits = -1;
    why[0] = '\0';
    if (stat(exe, &st) != 0) {
        snprintf(why, nwhy, "not found");
    } else if (!S_ISREG(st.st_mode) || access(exe, X_OK) != 0) {
        snprintf(why, nwhy, "not an executable file");
    } else if ((wstatus = run_child(exe, want, requires, out, sizeof out, why, nwhy)) == -1) {
        /* why set by run_child */
    } else if (strstr(out, "dcs:done") == NULL) {
        foreign_line(out, line, sizeof line);
        snprintf(why, nwhy, "does not run as a Python 3 interpreter (exit status %d%s%s)",
                 WIFEXITED(wstatus) ? WEXITSTATUS(wstatus) : -1, line[0] ? ": " : "", line);
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
    char tried[MAX_PATH_CANDIDATES + 4][2 * PATH_MAX + 2]; /* see seen_before */
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
    char dir[DCS_PATH_MAX], real_dir[PATH_MAX], real_exe[PATH_MAX];
    char key[sizeof s->tried[0]];
    const char *slash = strrchr(exe, '/');
    int i, seen = 0;
    snprintf(dir, sizeof dir, "%.*s", slash != NULL ? (int)(slash - exe) : 0, exe);
    if (slash == NULL || slash == exe || realpath(dir, real_dir) == NULL)
        snprintf(real_dir, sizeof real_dir, "%s", dir);
    if (realpath(exe, real_exe) == NULL)
        snprintf(real_exe, sizeof real_exe, "%s", exe);
    snprintf(key, sizeof key, "%s|%s", real_dir, real_exe);
    for (i = 0; i < s->n_tried && !seen; i++)
        seen = strcmp(s->tried[i], key) == 0;
    if (!seen && s->n_tried < (int)(sizeof s->tried / sizeof s->tried[0]))
        snprintf(s->tried[s->n_tried++], sizeof s->tried[0], "%s", key);
    return seen;
}

/* Check and load one candidate; report a line for it. explicit: stop whatever happens. */
static void try_candidate(Search *s, const char *label, const char *exe, int explicit_choice)
{
    DcsPython py;
    char why[2048];
    memset(&py, 0, sizeof py);
    if (check_candidate(exe, s->want, s->requires, &py, why, sizeof why) == 0) {
        if (s->load(&py, s->ctx, why, sizeof why, &s->stop) == 0) {
            s->found = 1;
            text_add(&s->report, "  %s %s: Python %s (%s), %s\n", label, exe, py.version,
                     py.executable, s->used);
        }
    }
    if (!s->found)
        text_add(&s->report, "  %s %s: %s%s\n", label, exe, why,
                 explicit_choice ? " (an explicit choice: no other candidate is tried)" : "");
    if (explicit_choice)
        s->stop = 1;
}

/* "python = /path" of a config file into dst; 1 if found. */
static int config_python(const char *file, char *dst, size_t n)
{
    char line[DCS_PATH_MAX + 64];
    int found = 0;
    FILE *f = fopen(file, "r");
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
        if (p[0] == '~' && p[1] == '/' && getenv("HOME") != NULL)
            snprintf(dst, n, "%s%s", getenv("HOME"), p + 1);
        else
            snprintf(dst, n, "%s", p);
        found = dst[0] != '\0';
    }
    if (f != NULL)
        fclose(f);
    return found;
}

static void try_config_files(Search *s, const char *unzip_dir)
{
    char files[2][DCS_PATH_MAX], exe[DCS_PATH_MAX], label[2 * DCS_PATH_MAX + 64];
    const char *xdg = getenv("XDG_CONFIG_HOME"), *home = getenv("HOME");
    int i, n = 0;
    snprintf(files[n++], DCS_PATH_MAX, "%s/%s", unzip_dir, CONFIG_NAME);
    if (xdg != NULL && xdg[0] == '/')
        snprintf(files[n++], DCS_PATH_MAX, "%s/drillcosim/%s", xdg, CONFIG_NAME);
    else if (home != NULL && home[0] != '\0')
        snprintf(files[n++], DCS_PATH_MAX, "%s/.config/drillcosim/%s", home, CONFIG_NAME);
    for (i = 0; i < n && !s->stop; i++) {
        if (access(files[i], F_OK) != 0)
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
    int n = 0, minor;
    snprintf(names[n++], 32, "python3");
    if (want->prefer_minor >= want->min_minor && want->prefer_minor <= want->max_minor)
        snprintf(names[n++], 32, "python3.%d", want->prefer_minor);
    for (minor = want->max_minor; minor >= want->min_minor && n < max; minor--)
        if (minor != want->prefer_minor)
            snprintf(names[n++], 32, "python3.%d", minor);
    return n;
}

static void try_path(Search *s)
{
    const char *path = getenv("PATH");
    char names[16][32], exe[DCS_PATH_MAX];
    char *copy, *save = NULL, *dir;
    int n_found = 0, k, n_names = path_names(s->want, names, 16);
    copy = dcs_path_dup(path != NULL ? path : "");
    for (dir = copy != NULL ? strtok_r(copy, ":", &save) : NULL;
         dir != NULL && !s->stop && n_found < MAX_PATH_CANDIDATES;
         dir = strtok_r(NULL, ":", &save)) {
        if (dir[0] != '/') /* a relative PATH entry would depend on the host's cwd */
            continue;
        for (k = 0; k < n_names && !s->stop && n_found < MAX_PATH_CANDIDATES; k++) {
            snprintf(exe, sizeof exe, "%s/%s", dir, names[k]);
            if (access(exe, X_OK) != 0 || seen_before(s, exe))
                continue;
            n_found++;
            try_candidate(s, "3. on PATH:", exe, 0);
            s->stop = s->stop || s->found;
        }
    }
    free(copy);
    if (n_found == 0)
        text_add(&s->report, "  3. on PATH: no python3 or python3.%d to python3.%d in %s\n",
                 s->want->min_minor, s->want->max_minor,
                 path != NULL && path[0] ? path : "(PATH is empty)");
}

int dcs_discover_python(const char *unzip_dir, const DcsWant *want, const char *requires,
                        const char *build_python, DcsLoad load, void *ctx, const char *used,
                        char **report)
{
    Search *s = (Search *)calloc(1, sizeof *s);
    const char *env = getenv("DRILLCOSIM_PYTHON");
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
        if (!s->stop) {
            if (build_python == NULL || build_python[0] == '\0')
                text_add(&s->report, "  4. the building interpreter: not recorded\n");
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
    return rc;
}
