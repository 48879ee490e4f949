/*
 * The platform layer on POSIX systems (Linux): dcs_platform.h.
 */
#ifndef _WIN32
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "dcs_platform.h"
#include "dcs_wrapper.h" /* dcs_strdup */

extern char **environ;

const char dcs_path_list_sep = ':';
const char *const dcs_python_plain_names[] = {"python3", NULL};
const char dcs_executable_suffix[] = "";
const DcsWording dcs_wording = {"python3.X -m pip install", "/path/to/python3",
                                "$DRILLCOSIM_PYTHON"};

/* ------------------------------------------------------------------ shared libraries */
void *dcs_library_open(const char *path, char *why, size_t nwhy)
{
    void *lib = dlopen(path, RTLD_NOW | RTLD_GLOBAL);
    if (lib == NULL) {
        const char *e = dlerror();
        snprintf(why, nwhy, "%s", e != NULL ? e : "unknown error");
    }
    return lib;
}

void dcs_library_close(void *lib)
{
    if (lib != NULL)
        dlclose(lib);
}

/* lib NULL: the whole process (RTLD_DEFAULT, which glibc defines as NULL too). */
void *dcs_library_symbol(void *lib, const char *name)
{
    return dlsym(lib != NULL ? lib : RTLD_DEFAULT, name);
}

int dcs_process_python(void **lib)
{
    *lib = NULL; /* every library of the process, in load order */
    return dlsym(RTLD_DEFAULT, "Py_IsInitialized") != NULL;
}

char *dcs_own_library_path(void)
{
    Dl_info info;
    char *out = NULL;
    if (dladdr((void *)&dcs_own_library_path, &info) != 0 && info.dli_fname != NULL)
        out = dcs_strdup(info.dli_fname);
    return out;
}

/* ------------------------------------------------------------------ files and paths */
FILE *dcs_fopen(const char *path, const char *mode)
{
    return fopen(path, mode);
}

int dcs_exists(const char *path)
{
    return access(path, F_OK) == 0;
}

int dcs_is_regular_file(const char *path)
{
    struct stat st;
    int kind = 0;
    if (stat(path, &st) == 0)
        kind = S_ISREG(st.st_mode) ? 1 : -1;
    return kind;
}

int dcs_is_executable(const char *path)
{
    return dcs_is_regular_file(path) == 1 && access(path, X_OK) == 0;
}

int dcs_is_absolute(const char *path)
{
    return path[0] == '/';
}

int dcs_is_dir_sep(char c)
{
    return c == '/';
}

int dcs_canonical_path(const char *path, char *out, size_t n)
{
    char resolved[PATH_MAX];
    int rc = -1;
    if (realpath(path, resolved) != NULL && strlen(resolved) + 1 <= n) {
        memcpy(out, resolved, strlen(resolved) + 1);
        rc = 0;
    }
    return rc;
}

/* "///a" and "/a" are "/a"; "//host/a" is "/a" (the host is this machine or unreachable). */
char *dcs_file_uri_path(const char *decoded)
{
    const char *p = decoded;
    if (p[0] == '/' && p[1] == '/') {
        const char *slash = strchr(p + 2, '/');
        p = slash != NULL ? slash : p + strlen(p);
    }
    return dcs_strdup(p);
}

void dcs_expand_home(const char *path, char *out, size_t n)
{
    const char *home = getenv("HOME");
    if (path[0] == '~' && path[1] == '/' && home != NULL)
        snprintf(out, n, "%s%s", home, path + 1);
    else
        snprintf(out, n, "%s", path);
}

/* ------------------------------------------------------------------ environment */
char *dcs_getenv(const char *name)
{
    const char *v = getenv(name);
    return v != NULL ? dcs_strdup(v) : NULL;
}

int dcs_user_config_file(char *out, size_t n)
{
    const char *xdg = getenv("XDG_CONFIG_HOME"), *home = getenv("HOME");
    int rc = 0;
    if (xdg != NULL && xdg[0] == '/')
        snprintf(out, n, "%s/drillcosim/drillcosim.conf", xdg);
    else if (home != NULL && home[0] != '\0')
        snprintf(out, n, "%s/.config/drillcosim/drillcosim.conf", home);
    else
        rc = -1;
    return rc;
}

/* ------------------------------------------------------------------ Python executables */
int dcs_installed_pythons(DcsInstalled *out, int max)
{
    (void)out;
    (void)max;
    return -1; /* no system-wide list of Pythons: PATH is where they are */
}

/* ------------------------------------------------------------------ child processes */
static long now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long)ts.tv_sec * 1000L + ts.tv_nsec / 1000000L;
}

/* Collect the child's output until it closes the pipe or the deadline passed (then it is
 * killed); reap it. Returns 0 or -1 as dcs_run_process. */
static int read_child(pid_t pid, int fd, char *out, size_t nout, long timeout_ms,
                      int *exit_code, char *why, size_t nwhy)
{
    int wstatus = 0, timed_out = 0;
    size_t len = 0;
    long deadline = now_ms() + timeout_ms;
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
    *exit_code = WIFEXITED(wstatus) ? WEXITSTATUS(wstatus) : -1;
    if (timed_out)
        snprintf(why, nwhy, "did not answer within %ld s (killed)", timeout_ms / 1000);
    return timed_out ? -1 : 0;
}

static int spawn(const char *const argv[], int fds[2], pid_t *pid, char *why, size_t nwhy);

int dcs_run_process(const char *const argv[], char *out, size_t nout, long timeout_ms,
                    int *exit_code, char *why, size_t nwhy)
{
    int fds[2], rc = -1;
    pid_t pid = -1;
    out[0] = '\0';
    *exit_code = -1;
    if (pipe2(fds, O_CLOEXEC) != 0) {
        snprintf(why, nwhy, "cannot create a pipe: %s", strerror(errno));
    } else {
        rc = spawn(argv, fds, &pid, why, nwhy);
        if (rc == 0)
            rc = read_child(pid, fds[0], out, nout, timeout_ms, exit_code, why, nwhy);
    }
    return rc;
}

/* Start argv with stdin /dev/null and stdout, stderr the pipe's write end fds[1] (closed here;
 * so is fds[0] on a failure). 0 on success, -1 with why set. */
static int spawn(const char *const argv[], int fds[2], pid_t *pid, char *why, size_t nwhy)
{
    int rc;
    posix_spawn_file_actions_t actions;
    posix_spawnattr_t attr;
    sigset_t none, reset;
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
    rc = posix_spawn(pid, argv[0], &actions, &attr, (char *const *)argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    posix_spawnattr_destroy(&attr);
    close(fds[1]);
    if (rc != 0) {
        close(fds[0]);
        snprintf(why, nwhy, "cannot be started: %s", strerror(rc));
    }
    return rc != 0 ? -1 : 0;
}

/* ------------------------------------------------------------------ text */
/* UTF-8 -> UTF-32; invalid bytes as U+DC80..U+DCFF (surrogateescape, as Python decodes file
 * names). Runs before Python exists: Py_DecodeLocale would need PyMem_RawFree, not in the
 * limited API of 3.10. */
int dcs_utf8_to_wide(const char *s, wchar_t *out, size_t n)
{
    const unsigned char *p = (const unsigned char *)s;
    size_t k = 0;
    while (*p && k + 1 < n) {
        unsigned c = p[0], cp = 0, len = 0, i;
        if (c < 0x80) {
            cp = c;
            len = 1;
        } else if ((c & 0xE0) == 0xC0 && c >= 0xC2) {
            cp = c & 0x1F;
            len = 2;
        } else if ((c & 0xF0) == 0xE0) {
            cp = c & 0x0F;
            len = 3;
        } else if ((c & 0xF8) == 0xF0 && c <= 0xF4) {
            cp = c & 0x07;
            len = 4;
        }
        for (i = 1; i < len && len > 1; i++) {
            if ((p[i] & 0xC0) != 0x80) {
                len = 0;
                break;
            }
            cp = (cp << 6) | (p[i] & 0x3F);
        }
        if (len > 2 && (cp < (len == 3 ? 0x800u : 0x10000u) || cp > 0x10FFFF ||
                        (cp >= 0xD800 && cp <= 0xDFFF)))
            len = 0; /* overlong, out of range or a surrogate */
        if (len == 0) {
            out[k++] = (wchar_t)(0xDC00 + p[0]);
            p++;
        } else {
            out[k++] = (wchar_t)cp;
            p += len;
        }
    }
    out[k] = L'\0';
    return *p == '\0' ? 0 : -1;
}

#endif /* !_WIN32 */
