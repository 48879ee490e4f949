/*
 * The platform layer on Windows (64-bit; cross-built with mingw-w64): dcs_platform.h.
 *
 * The wrapper keeps every path and text in UTF-8; each call into Windows converts to UTF-16
 * and uses the W function (never the ANSI code page). Only kernel32 and advapi32 (the
 * registry) are used, both part of every Windows.
 */
#ifdef _WIN32
#ifndef WIN32_LEAN_AND_MEAN
#define WIN32_LEAN_AND_MEAN
#endif
#include <windows.h>
#include <psapi.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dcs_platform.h"
#include "dcs_wrapper.h" /* dcs_strdup */

const char dcs_path_list_sep = ';';
/* python.org's installer puts python.exe on PATH; the Microsoft Store's Python adds
 * python3.exe and python3.X.exe aliases. */
const char *const dcs_python_plain_names[] = {"python.exe", "python3.exe", NULL};
const char dcs_executable_suffix[] = ".exe";
const DcsWording dcs_wording = {"py -3.X -m pip install", "C:\\...\\python.exe",
                                "%DRILLCOSIM_PYTHON%"};

#define WIDE_MAX 32768 /* the longest path the wide API takes */

/* ------------------------------------------------------------------ UTF-8 <-> UTF-16 */
static wchar_t *wide(const char *s)
{
    int n = MultiByteToWideChar(CP_UTF8, 0, s, -1, NULL, 0);
    wchar_t *w = n > 0 ? (wchar_t *)malloc((size_t)n * sizeof *w) : NULL;
    if (w != NULL && MultiByteToWideChar(CP_UTF8, 0, s, -1, w, n) != n) {
        free(w);
        w = NULL;
    }
    return w;
}

static char *narrow(const wchar_t *w)
{
    int n = WideCharToMultiByte(CP_UTF8, 0, w, -1, NULL, 0, NULL, NULL);
    char *s = n > 0 ? (char *)malloc((size_t)n) : NULL;
    if (s != NULL && WideCharToMultiByte(CP_UTF8, 0, w, -1, s, n, NULL, NULL) != n) {
        free(s);
        s = NULL;
    }
    return s;
}

/* The system's text for an error code, UTF-8, into why ("... (error 193)"). */
static void system_error(DWORD code, char *why, size_t nwhy)
{
    wchar_t text[512];
    char *utf8 = NULL;
    DWORD n = FormatMessageW(FORMAT_MESSAGE_FROM_SYSTEM | FORMAT_MESSAGE_IGNORE_INSERTS, NULL,
                             code, 0, text, sizeof text / sizeof text[0], NULL);
    while (n > 0 && (text[n - 1] == L'\n' || text[n - 1] == L'\r' || text[n - 1] == L' ' ||
                     text[n - 1] == L'.'))
        text[--n] = L'\0';
    if (n > 0)
        utf8 = narrow(text);
    snprintf(why, nwhy, "%s (error %lu)", utf8 != NULL ? utf8 : "Windows error",
             (unsigned long)code);
    free(utf8);
}

/* ------------------------------------------------------------------ shared libraries */
void *dcs_library_open(const char *path, char *why, size_t nwhy)
{
    wchar_t *w = wide(path);
    HMODULE lib = NULL;
    if (w == NULL) {
        snprintf(why, nwhy, "the path is not valid UTF-8");
    } else {
        /* the library's own folder first for its dependencies (an absolute path) */
        lib = LoadLibraryExW(w, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
        if (lib == NULL)
            system_error(GetLastError(), why, nwhy);
    }
    free(w);
    return (void *)lib;
}

void dcs_library_close(void *lib)
{
    if (lib != NULL)
        FreeLibrary((HMODULE)lib);
}

void *dcs_library_symbol(void *lib, const char *name)
{
    FARPROC f = lib != NULL ? GetProcAddress((HMODULE)lib, name) : NULL;
    void *p;
    memcpy(&p, &f, sizeof p); /* a function or a variable: Windows gives both this way */
    return p;
}

/* Whether the file name of a module is python3XX.dll (not python3.dll, which only forwards). */
static int is_libpython(const wchar_t *file)
{
    const wchar_t *base = file, *p;
    size_t n;
    for (p = file; *p; p++)
        if (*p == L'\\' || *p == L'/')
            base = p + 1;
    n = wcslen(base);
    return n > 11 && _wcsnicmp(base, L"python3", 7) == 0 && _wcsicmp(base + n - 4, L".dll") == 0;
}

int dcs_process_python(void **lib)
{
    static HMODULE mods[4096];
    DWORD needed = 0, i, count;
    wchar_t *file = (wchar_t *)malloc(WIDE_MAX * sizeof *file);
    *lib = NULL;
    if (file == NULL ||
        !K32EnumProcessModules(GetCurrentProcess(), mods, sizeof mods, &needed))
        needed = 0;
    count = needed / sizeof mods[0];
    if (count > sizeof mods / sizeof mods[0])
        count = sizeof mods / sizeof mods[0];
    for (i = 0; i < count && *lib == NULL; i++) {
        DWORD n = GetModuleFileNameW(mods[i], file, WIDE_MAX);
        if (n > 0 && n < WIDE_MAX && is_libpython(file) &&
            GetProcAddress(mods[i], "Py_IsInitialized") != NULL)
            *lib = (void *)mods[i];
    }
    free(file);
    return *lib != NULL;
}

char *dcs_own_library_path(void)
{
    HMODULE self = NULL;
    wchar_t *file = NULL;
    char *out = NULL;
    if (GetModuleHandleExW(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS |
                               GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                           (LPCWSTR)(void *)&dcs_own_library_path, &self) &&
        (file = (wchar_t *)malloc(WIDE_MAX * sizeof *file)) != NULL) {
        DWORD n = GetModuleFileNameW(self, file, WIDE_MAX);
        if (n > 0 && n < WIDE_MAX)
            out = narrow(file);
    }
    free(file);
    return out;
}

/* ------------------------------------------------------------------ files and paths */
FILE *dcs_fopen(const char *path, const char *mode)
{
    wchar_t *w = wide(path), *m = wide(mode);
    FILE *f = w != NULL && m != NULL ? _wfopen(w, m) : NULL;
    free(w);
    free(m);
    return f;
}

static DWORD attributes(const char *path)
{
    wchar_t *w = wide(path);
    DWORD a = w != NULL ? GetFileAttributesW(w) : INVALID_FILE_ATTRIBUTES;
    free(w);
    return a;
}

int dcs_exists(const char *path)
{
    return attributes(path) != INVALID_FILE_ATTRIBUTES;
}

int dcs_is_regular_file(const char *path)
{
    DWORD a = attributes(path);
    return a == INVALID_FILE_ATTRIBUTES ? 0 : (a & FILE_ATTRIBUTE_DIRECTORY) ? -1 : 1;
}

int dcs_is_executable(const char *path)
{
    return dcs_is_regular_file(path) == 1;
}

int dcs_is_dir_sep(char c)
{
    return c == '/' || c == '\\';
}

int dcs_is_absolute(const char *path)
{
    int drive = ((path[0] >= 'A' && path[0] <= 'Z') || (path[0] >= 'a' && path[0] <= 'z')) &&
                path[1] == ':' && dcs_is_dir_sep(path[2]);
    return drive || (dcs_is_dir_sep(path[0]) && dcs_is_dir_sep(path[1]));
}

int dcs_canonical_path(const char *path, char *out, size_t n)
{
    wchar_t *w = wide(path), *final = NULL;
    char *utf8 = NULL;
    HANDLE h = INVALID_HANDLE_VALUE;
    int rc = -1;
    if (w != NULL)
        h = CreateFileW(w, 0, FILE_SHARE_READ | FILE_SHARE_WRITE | FILE_SHARE_DELETE, NULL,
                        OPEN_EXISTING, FILE_FLAG_BACKUP_SEMANTICS, NULL);
    if (h != INVALID_HANDLE_VALUE && (final = (wchar_t *)malloc(WIDE_MAX * sizeof *final))) {
        DWORD k = GetFinalPathNameByHandleW(h, final, WIDE_MAX,
                                            FILE_NAME_NORMALIZED | VOLUME_NAME_DOS);
        if (k > 0 && k < WIDE_MAX) {
            const wchar_t *p = final;
            if (wcsncmp(p, L"\\\\?\\UNC\\", 8) == 0) {
                p += 6; /* \\?\UNC\server\share -> \\server\share */
                final[6] = L'\\';
            } else if (wcsncmp(p, L"\\\\?\\", 4) == 0) {
                p += 4;
            }
            utf8 = narrow(p);
        }
    }
    if (utf8 != NULL && strlen(utf8) + 1 <= n) {
        memcpy(out, utf8, strlen(utf8) + 1);
        rc = 0;
    }
    if (h != INVALID_HANDLE_VALUE)
        CloseHandle(h);
    free(utf8);
    free(final);
    free(w);
    return rc;
}

/* "///C:/a", "//localhost/C:/a" and "/C:/a" are "C:/a"; "//server/share/a" is the UNC path
 * "//server/share/a" (Windows takes '/' for '\'). */
char *dcs_file_uri_path(const char *decoded)
{
    const char *p = decoded;
    if (p[0] == '/' && p[1] == '/') {
        const char *host = p + 2, *slash = strchr(host, '/');
        size_t len = slash != NULL ? (size_t)(slash - host) : strlen(host);
        if (len == 0 || (len == 9 && _strnicmp(host, "localhost", 9) == 0))
            p = slash != NULL ? slash : host + len;
        /* else: a server, kept as //server/... */
    }
    if (p[0] == '/' && p[1] != '\0' && p[2] == ':')
        p++; /* /C:/a */
    return dcs_strdup(p);
}

void dcs_expand_home(const char *path, char *out, size_t n)
{
    char *home = dcs_getenv("USERPROFILE");
    if (path[0] == '~' && dcs_is_dir_sep(path[1]) && home != NULL)
        snprintf(out, n, "%s%s", home, path + 1);
    else
        snprintf(out, n, "%s", path);
    free(home);
}

/* ------------------------------------------------------------------ environment */
/* The process's environment (GetEnvironmentVariableW: what a Python host's os.environ set,
 * and what a child inherits), not the C runtime's copy. */
char *dcs_getenv(const char *name)
{
    wchar_t *w = wide(name), *value = NULL;
    char *out = NULL;
    DWORD n = w != NULL ? GetEnvironmentVariableW(w, NULL, 0) : 0;
    if (n > 0 && (value = (wchar_t *)malloc((size_t)n * sizeof *value)) != NULL &&
        GetEnvironmentVariableW(w, value, n) < n)
        out = narrow(value);
    free(value);
    free(w);
    return out;
}

int dcs_user_config_file(char *out, size_t n)
{
    char *appdata = dcs_getenv("APPDATA");
    int rc = -1;
    if (appdata != NULL && appdata[0] != '\0') {
        snprintf(out, n, "%s\\drillcosim\\drillcosim.conf", appdata);
        rc = 0;
    }
    free(appdata);
    return rc;
}

/* ------------------------------------------------------------------ Python executables */
/* The minor version of a PEP 514 tag of CPython 3 for x86-64 ("3.12"; not "3.12-32",
 * "3.13t", "3.12-arm64"), -1 for any other tag. */
static int tag_minor(const wchar_t *tag)
{
    int minor = -1;
    const wchar_t *p;
    if (tag[0] == L'3' && tag[1] == L'.' && tag[2] != L'\0') {
        minor = 0;
        for (p = tag + 2; *p && minor >= 0; p++)
            minor = *p >= L'0' && *p <= L'9' && minor < 1000 ? 10 * minor + (*p - L'0') : -1;
    }
    return minor;
}

/* The python.exe of one PythonCore\<tag> key: InstallPath's ExecutablePath, else its default
 * value + python.exe. 0 if found. */
static int install_executable(HKEY tag_key, wchar_t *exe, DWORD n)
{
    DWORD size = n * sizeof *exe, arch_size = sizeof(wchar_t[32]), len;
    wchar_t arch[32];
    int rc = -1;
    if (RegGetValueW(tag_key, NULL, L"SysArchitecture", RRF_RT_REG_SZ, NULL, arch,
                     &arch_size) == ERROR_SUCCESS && wcscmp(arch, L"64bit") != 0) {
        rc = -1; /* a 32-bit Python: it cannot run in this process */
    } else if (RegGetValueW(tag_key, L"InstallPath", L"ExecutablePath", RRF_RT_REG_SZ, NULL,
                            exe, &size) == ERROR_SUCCESS && exe[0] != L'\0') {
        rc = 0;
    } else {
        size = n * sizeof *exe;
        if (RegGetValueW(tag_key, L"InstallPath", NULL, RRF_RT_REG_SZ, NULL, exe, &size) ==
                ERROR_SUCCESS && exe[0] != L'\0' && (len = (DWORD)wcslen(exe)) + 12 < n) {
            if (exe[len - 1] != L'\\')
                exe[len++] = L'\\';
            wcscpy(exe + len, L"python.exe");
            rc = 0;
        }
    }
    return rc;
}

static int compare_newest_first(const void *a, const void *b)
{
    return ((const DcsInstalled *)b)->minor - ((const DcsInstalled *)a)->minor;
}

int dcs_installed_pythons(DcsInstalled *out, int max)
{
    static const struct {
        HKEY root;
        const char *name;
    } hives[] = {{HKEY_CURRENT_USER, "HKEY_CURRENT_USER"},
                 {HKEY_LOCAL_MACHINE, "HKEY_LOCAL_MACHINE"}};
    wchar_t tag[64], exe[MAX_PATH + 16];
    int count = 0, h;
    for (h = 0; h < 2; h++) {
        HKEY core;
        DWORD i, n_tag;
        int first = count;
        if (RegOpenKeyExW(hives[h].root, L"Software\\Python\\PythonCore", 0,
                          KEY_READ | KEY_WOW64_64KEY, &core) != ERROR_SUCCESS)
            continue;
        for (i = 0; count < max; i++) {
            HKEY key;
            char *exe8, *tag8;
            int minor;
            n_tag = sizeof tag / sizeof tag[0];
            if (RegEnumKeyExW(core, i, tag, &n_tag, NULL, NULL, NULL, NULL) != ERROR_SUCCESS)
                break;
            if ((minor = tag_minor(tag)) < 0 ||
                RegOpenKeyExW(core, tag, 0, KEY_READ | KEY_WOW64_64KEY, &key) != ERROR_SUCCESS)
                continue;
            if (install_executable(key, exe, sizeof exe / sizeof exe[0]) == 0 &&
                (exe8 = narrow(exe)) != NULL) {
                tag8 = narrow(tag);
                out[count].minor = minor;
                snprintf(out[count].executable, sizeof out[count].executable, "%s", exe8);
                snprintf(out[count].where, sizeof out[count].where,
                         "%s\\Software\\Python\\PythonCore\\%s", hives[h].name,
                         tag8 != NULL ? tag8 : "?");
                free(tag8);
                free(exe8);
                count++;
            }
            RegCloseKey(key);
        }
        RegCloseKey(core);
        qsort(out + first, (size_t)(count - first), sizeof *out, compare_newest_first);
    }
    return count;
}

/* ------------------------------------------------------------------ child processes */
/* Append one argument to a command line, quoted as the C runtime's parser (and
 * CommandLineToArgvW) reads it back: backslashes doubled before a quote, quotes escaped. */
static void append_quoted(char *line, size_t n, const char *arg)
{
    size_t len = strlen(line), slashes = 0;
    const char *p;
#define PUT(c) do { if (len + 1 < n) line[len++] = (c); } while (0)
    if (len > 0)
        PUT(' ');
    PUT('"');
    for (p = arg; *p; p++) {
        if (*p == '\\') {
            slashes++;
            continue;
        }
        while (slashes > 0) {
            PUT('\\');
            if (*p == '"')
                PUT('\\');
            slashes--;
        }
        if (*p == '"')
            PUT('\\');
        PUT(*p);
    }
    for (; slashes > 0; slashes--) { /* before the closing quote: doubled */
        PUT('\\');
        PUT('\\');
    }
    PUT('"');
#undef PUT
    line[len] = '\0';
}

/* A Windows child writes text mode: "\r\n" line ends (Python's print on a pipe). The callers
 * read lines ending in "\n" only: every line's trailing white space ("\r", " ", "\t") is
 * removed in place, so a path read back from the child (its libpython) ends where the path
 * does (a Windows file name cannot end with a space: Win32 drops it). */
static void drop_line_end_spaces(char *text)
{
    char *in = text, *out = text, *line = text;
    for (;; in++) {
        if (*in == '\n' || *in == '\0') {
            while (out > line && (out[-1] == '\r' || out[-1] == ' ' || out[-1] == '\t'))
                out--;
            if (*in == '\0')
                break;
            *out++ = '\n';
            line = out;
        } else {
            *out++ = *in;
        }
    }
    *out = '\0';
}

/* Read the pipe until the child ended and the pipe is empty or broken, or the deadline. */
static int read_child(HANDLE process, HANDLE pipe, char *out, size_t nout, long timeout_ms)
{
    ULONGLONG deadline = GetTickCount64() + (ULONGLONG)timeout_ms;
    size_t len = 0;
    int timed_out = 0, ended = 0;
    for (;;) {
        char trash[4096];
        DWORD avail = 0, got = 0;
        if (!PeekNamedPipe(pipe, NULL, 0, NULL, &avail, NULL))
            break; /* every writer closed it */
        if (avail > 0) {
            char *dst = len + 1 < nout ? out + len : trash;
            DWORD room = len + 1 < nout ? (DWORD)(nout - 1 - len) : (DWORD)sizeof trash;
            if (!ReadFile(pipe, dst, avail < room ? avail : room, &got, NULL))
                break;
            if (dst != trash)
                len += got;
            continue;
        }
        if (ended)
            break; /* ended, and nothing left to read */
        if (GetTickCount64() >= deadline) {
            timed_out = 1;
            TerminateProcess(process, 1);
            WaitForSingleObject(process, 5000);
            break;
        }
        ended = WaitForSingleObject(process, 10) == WAIT_OBJECT_0;
    }
    out[len] = '\0';
    drop_line_end_spaces(out);
    return timed_out;
}

int dcs_run_process(const char *const argv[], char *out, size_t nout, long timeout_ms,
                    int *exit_code, char *why, size_t nwhy)
{
    SECURITY_ATTRIBUTES sa = {sizeof sa, NULL, TRUE};
    STARTUPINFOEXW si;
    PROCESS_INFORMATION pi;
    HANDLE rd = NULL, wr = NULL, nul = INVALID_HANDLE_VALUE, inherit[2];
    LPPROC_THREAD_ATTRIBUTE_LIST attrs = NULL;
    SIZE_T attrs_size = 0;
    char *line = NULL;
    wchar_t *wline = NULL, *wexe = NULL;
    size_t n = 1;
    int i, rc = -1, started = 0;
    DWORD code = 0, flags = CREATE_NO_WINDOW;
    out[0] = '\0';
    *exit_code = -1;
    for (i = 0; argv[i] != NULL; i++)
        n += 2 * strlen(argv[i]) + 3;
    memset(&si, 0, sizeof si);
    memset(&pi, 0, sizeof pi);
    if ((line = (char *)calloc(n, 1)) != NULL) {
        for (i = 0; argv[i] != NULL; i++)
            append_quoted(line, n, argv[i]);
        wline = wide(line);
    }
    wexe = wide(argv[0]);
    nul = CreateFileW(L"NUL", GENERIC_READ, FILE_SHARE_READ | FILE_SHARE_WRITE, &sa,
                      OPEN_EXISTING, 0, NULL);
    if (wline == NULL || wexe == NULL) {
        snprintf(why, nwhy, "its path is not valid UTF-8 (or out of memory)");
    } else if (nul == INVALID_HANDLE_VALUE || !CreatePipe(&rd, &wr, &sa, 0) ||
               !SetHandleInformation(rd, HANDLE_FLAG_INHERIT, 0)) {
        system_error(GetLastError(), why, nwhy);
    } else {
        si.StartupInfo.cb = sizeof si.StartupInfo;
        si.StartupInfo.dwFlags = STARTF_USESTDHANDLES;
        si.StartupInfo.hStdInput = nul;
        si.StartupInfo.hStdOutput = wr;
        si.StartupInfo.hStdError = wr;
        /* the child inherits these two handles only, none of the host's */
        inherit[0] = nul;
        inherit[1] = wr;
        InitializeProcThreadAttributeList(NULL, 1, 0, &attrs_size);
        attrs = (LPPROC_THREAD_ATTRIBUTE_LIST)malloc(attrs_size);
        if (attrs != NULL && InitializeProcThreadAttributeList(attrs, 1, 0, &attrs_size) &&
            UpdateProcThreadAttribute(attrs, 0, PROC_THREAD_ATTRIBUTE_HANDLE_LIST, inherit,
                                      sizeof inherit, NULL, NULL)) {
            si.StartupInfo.cb = sizeof si;
            si.lpAttributeList = attrs;
            flags |= EXTENDED_STARTUPINFO_PRESENT;
        }
        started = CreateProcessW(wexe, wline, NULL, NULL, TRUE, flags, NULL, NULL,
                                 &si.StartupInfo, &pi);
        if (!started)
            system_error(GetLastError(), why, nwhy);
        CloseHandle(wr); /* the child's copy is the only writer left */
        wr = NULL;
    }
    if (started) {
        if (read_child(pi.hProcess, rd, out, nout, timeout_ms)) {
            snprintf(why, nwhy, "did not answer within %ld s (killed)", timeout_ms / 1000);
        } else {
            WaitForSingleObject(pi.hProcess, INFINITE);
            GetExitCodeProcess(pi.hProcess, &code);
            *exit_code = (int)code;
            rc = 0;
        }
        CloseHandle(pi.hThread);
        CloseHandle(pi.hProcess);
    }
    if (attrs != NULL && (flags & EXTENDED_STARTUPINFO_PRESENT))
        DeleteProcThreadAttributeList(attrs);
    free(attrs);
    if (rd != NULL)
        CloseHandle(rd);
    if (wr != NULL)
        CloseHandle(wr);
    if (nul != INVALID_HANDLE_VALUE)
        CloseHandle(nul);
    free(wexe);
    free(wline);
    free(line);
    return rc;
}

/* ------------------------------------------------------------------ text */
int dcs_utf8_to_wide(const char *s, wchar_t *out, size_t n)
{
    int k = MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, s, -1, out, (int)n);
    return k > 0 ? 0 : -1;
}

#endif /* _WIN32 */
