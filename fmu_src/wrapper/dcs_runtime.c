/*
 * The Python runtime a self-contained FMU carries (drillcosim build --standalone; see
 * fmu_src/standalone/__init__.py for how it is made).
 *
 * resources/dcs_runtime/<platform>/MANIFEST is a text file, one item a line:
 *     dcs-runtime 1
 *     platform linux64                       the FMI platform it runs on
 *     python 3.11.7                          the version of its interpreter
 *     library lib/libpython3.11.so.1.0       the interpreter's shared library
 *     program bin/python3                    Py_SetProgramName (need not exist)
 *     home .                                 Py_SetPythonHome (none: win64, whose ._pth decides)
 *     preload lib/libffi.so.8                libraries loaded before the interpreter, in order
 *     path lib/python3.11/site-packages      sys.path entries it adds after the start
 *     site lib/python3.11/site-packages      where its packages lie (for dcs_runtime_compatible)
 *     glibc 2.34                             linux64: the newest GLIBC_ version its files need
 *     file <sha256> <size> <path>            every file of the runtime, paths relative, '/'
 *     end <sha256 of every byte before this line>
 * Paths are relative to the runtime folder. A runtime is used only in a host without Python
 * (dcs_python.c); before anything of it is loaded the wrapper checks the MANIFEST itself (its
 * end line), that every file is there with its size, and (once per process and runtime) every
 * file's SHA-256: a damaged file is one message and fmi2Error, never a crash in the loader or
 * an abort in Py_InitializeEx.
 *
 * Packages: a "group" is the first path component below `site` (numpy, numpy.libs, scipy,
 * numba-0.68.1.dist-info, ...); everything outside `site` is the "base" (the interpreter, its
 * standard library, its extension modules and libraries). Two runtimes are compatible when
 * their bases are identical and every group both carry is identical (dcs_runtime_compatible).
 */
#include "dcs_runtime.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dcs_platform.h"
#include "dcs_sha256.h"

#ifdef _WIN32
#define DCS_RUNTIME_PLATFORM "win64"
#else
#define DCS_RUNTIME_PLATFORM "linux64"
#endif

#define MANIFEST_MAX (64L << 20)

typedef struct {
    char *path;      /* relative, as in the MANIFEST */
    char hex[65];
    long long size;
    size_t group;    /* index into groups; 0 = base */
} Entry;

typedef struct {
    char *key, *value; /* value: absolute for the path-like keys */
} Item;

struct DcsRuntime {
    char *root;
    Item *items;
    size_t n_items;
    Entry *files;
    size_t n_files;
    char **groups;        /* groups[0] = "" (the base) */
    char (*group_hex)[65];
    size_t n_groups;
};

static char *dup_n(const char *s, size_t n)
{
    char *d = (char *)malloc(n + 1);
    if (d != NULL) {
        memcpy(d, s, n);
        d[n] = '\0';
    }
    return d;
}

static char *join(const char *root, const char *rel)
{
    size_t a = strlen(root), b = strlen(rel);
    char *d = (char *)malloc(a + b + 2);
    if (d != NULL) {
        memcpy(d, root, a);
        d[a] = '/';
        memcpy(d + a + 1, rel, b + 1);
        if (strcmp(rel, ".") == 0)
            d[a] = '\0';
    }
    return d;
}

/* Size of a regular file, -1 if it is missing or not a regular file (the runtime's files
 * are far below 2 GB: ftell's long suffices on Windows too). */
static long long file_size(const char *path)
{
    long long size = -1;
    FILE *f = dcs_is_regular_file(path) == 1 ? dcs_fopen(path, "rb") : NULL;
    if (f != NULL) {
        if (fseek(f, 0, SEEK_END) == 0)
            size = (long long)ftell(f);
        fclose(f);
    }
    return size;
}

/* The whole file into a malloc'd buffer (NUL-terminated), NULL if it cannot be read. */
static char *read_all(const char *path, size_t *len)
{
    long long size = file_size(path);
    char *buf = NULL;
    FILE *f = size >= 0 && size <= MANIFEST_MAX ? dcs_fopen(path, "rb") : NULL;
    if (f != NULL) {
        buf = (char *)malloc((size_t)size + 1);
        if (buf != NULL && fread(buf, 1, (size_t)size, f) != (size_t)size) {
            free(buf);
            buf = NULL;
        }
        fclose(f);
    }
    if (buf != NULL) {
        buf[size] = '\0';
        *len = (size_t)size;
    }
    return buf;
}

void dcs_runtime_free(DcsRuntime *rt)
{
    size_t i;
    if (rt != NULL) {
        for (i = 0; i < rt->n_items; i++) {
            free(rt->items[i].key);
            free(rt->items[i].value);
        }
        for (i = 0; i < rt->n_files; i++)
            free(rt->files[i].path);
        for (i = 0; i < rt->n_groups; i++)
            free(rt->groups[i]);
        free(rt->items);
        free(rt->files);
        free(rt->groups);
        free(rt->group_hex);
        free(rt->root);
        free(rt);
    }
}

static const char *item(const DcsRuntime *rt, const char *key)
{
    size_t i;
    const char *found = NULL;
    for (i = 0; i < rt->n_items && found == NULL; i++)
        if (strcmp(rt->items[i].key, key) == 0)
            found = rt->items[i].value;
    return found;
}

static int is_path_key(const char *key)
{
    static const char *const keys[] = {"library", "program", "home", "preload", "path", NULL};
    int i, found = 0;
    for (i = 0; keys[i] != NULL && !found; i++)
        found = strcmp(key, keys[i]) == 0;
    return found;
}

/* The group of a relative path: its first component below `site` (0, the base, if not below
 * it); a new group is added for a new component. */
static size_t group_of(DcsRuntime *rt, const char *site, const char *path)
{
    size_t n = site != NULL ? strlen(site) : 0, len, i, group = 0;
    const char *top, *slash;
    if (site != NULL && strncmp(path, site, n) == 0 && path[n] == '/') {
        top = path + n + 1;
        slash = strchr(top, '/');
        len = slash != NULL ? (size_t)(slash - top) : strlen(top);
        for (i = 1; i < rt->n_groups && group == 0; i++)
            if (strlen(rt->groups[i]) == len && strncmp(rt->groups[i], top, len) == 0)
                group = i;
        if (group == 0) {
            rt->groups[rt->n_groups] = dup_n(top, len);
            if (rt->groups[rt->n_groups] != NULL)
                group = rt->n_groups++;
        }
    }
    return group;
}

/* The end line of the MANIFEST text: the digest of every byte before it. 0 if it matches. */
static int check_end(char *text, size_t len, char **end_line)
{
    char *p = text, hex[65];
    DcsSha256 whole;
    *end_line = NULL;
    while (p < text + len) {
        char *nl = strchr(p, '\n');
        if (strncmp(p, "end ", 4) == 0)
            *end_line = p;
        p = nl != NULL ? nl + 1 : text + len;
    }
    if (*end_line != NULL) {
        dcs_sha256_init(&whole);
        dcs_sha256_update(&whole, text, (size_t)(*end_line - text));
        dcs_sha256_hex(&whole, hex);
    }
    return *end_line != NULL && strncmp(*end_line + 4, hex, 64) == 0 ? 0 : -1;
}

/* One "file <sha256> <size> <path>" line (after "file ") into e; 0 if well formed. */
static int parse_file_line(const char *q, Entry *e)
{
    char *size_end = NULL;
    int rc = -1;
    if (strlen(q) >= 67 && q[64] == ' ') {
        memcpy(e->hex, q, 64);
        e->hex[64] = '\0';
        e->size = strtoll(q + 65, &size_end, 10);
        if (*size_end == ' ' && e->size >= 0) {
            e->path = dup_n(size_end + 1, strlen(size_end + 1));
            rc = e->path != NULL ? 0 : -1;
        }
    }
    return rc;
}

/* Every line after the first: items and files. 0, or -1 with why. */
static int parse_lines(DcsRuntime *rt, char *text, const char *file, char *why, size_t nwhy)
{
    char *line, *p;
    int rc = 0;
    for (line = strchr(text, '\n') + 1; *line && rc == 0; line = p + 1) {
        char *sp;
        p = strchr(line, '\n');
        if (p == NULL)
            break;
        *p = '\0';
        sp = strchr(line, ' ');
        if (sp == NULL)
            continue;
        *sp = '\0';
        if (strcmp(line, "file") == 0) {
            rc = parse_file_line(sp + 1, &rt->files[rt->n_files]);
            if (rc == 0)
                rt->n_files++;
            else
                snprintf(why, nwhy, "%s: a bad file line (damaged?)", file);
        } else {
            Item *it = &rt->items[rt->n_items];
            it->key = dup_n(line, strlen(line));
            it->value = is_path_key(line) ? join(rt->root, sp + 1)
                                           : dup_n(sp + 1, strlen(sp + 1));
            rc = it->key != NULL && it->value != NULL ? 0 : -1;
            rt->n_items++;
        }
    }
    return rc;
}

/* The groups of the files and their digests (over their file lines, in MANIFEST order). */
static int group_digests(DcsRuntime *rt)
{
    size_t i;
    const char *site = item(rt, "site"); /* relative: not a path key */
    DcsSha256 *sha = (DcsSha256 *)calloc(rt->n_files + 1, sizeof *sha);
    rt->group_hex = (char (*)[65])calloc(rt->n_files + 1, sizeof *rt->group_hex);
    if (sha != NULL && rt->group_hex != NULL) {
        for (i = 0; i <= rt->n_files; i++)
            dcs_sha256_init(&sha[i]);
        for (i = 0; i < rt->n_files; i++) {
            Entry *e = &rt->files[i];
            char sz[32];
            e->group = group_of(rt, site, e->path);
            snprintf(sz, sizeof sz, " %lld ", e->size);
            dcs_sha256_update(&sha[e->group], e->hex, 64);
            dcs_sha256_update(&sha[e->group], sz, strlen(sz));
            dcs_sha256_update(&sha[e->group], e->path, strlen(e->path) + 1);
        }
        for (i = 0; i < rt->n_groups; i++)
            dcs_sha256_hex(&sha[i], rt->group_hex[i]);
    }
    free(sha);
    return rt->group_hex != NULL ? 0 : -1;
}

/* Parse the MANIFEST text (checked against its end line). 0, or -1 with why. */
static int parse(DcsRuntime *rt, char *text, size_t len, const char *file, char *why,
                 size_t nwhy)
{
    char *end_line = NULL, *p;
    size_t n_lines = 0;
    int rc = 0;
    for (p = text; p < text + len; p++)
        n_lines += *p == '\n';
    if (strncmp(text, "dcs-runtime 1\n", 14) != 0 || check_end(text, len, &end_line) != 0) {
        snprintf(why, nwhy, "%s is damaged (its end line does not match its content)", file);
        rc = -1;
    } else {
        *end_line = '\0';
        rt->items = (Item *)calloc(n_lines + 1, sizeof *rt->items);
        rt->files = (Entry *)calloc(n_lines + 1, sizeof *rt->files);
        rt->groups = (char **)calloc(n_lines + 2, sizeof *rt->groups);
        if (rt->items == NULL || rt->files == NULL || rt->groups == NULL ||
            (rt->groups[rt->n_groups++] = dup_n("", 0)) == NULL)
            rc = -1;
    }
    if (rc == 0)
        rc = parse_lines(rt, text, file, why, nwhy);
    if (rc == 0)
        rc = group_digests(rt);
    if (rc == 0 && (item(rt, "platform") == NULL ||
                    strcmp(item(rt, "platform"), DCS_RUNTIME_PLATFORM) != 0 ||
                    item(rt, "library") == NULL || item(rt, "python") == NULL)) {
        snprintf(why, nwhy, "%s is for %s, not %s (or lacks its library or python line)", file,
                 item(rt, "platform") ? item(rt, "platform") : "no platform",
                 DCS_RUNTIME_PLATFORM);
        rc = -1;
    }
    return rc;
}

int dcs_runtime_open(const char *resources, DcsRuntime **out, char *why, size_t nwhy)
{
    char folder[4096], file[4200];
    char *text = NULL;
    size_t len = 0;
    DcsRuntime *rt = NULL;
    int rc = 0;
    *out = NULL;
    why[0] = '\0';
    snprintf(folder, sizeof folder, "%s/%s/%s", resources, DCS_RUNTIME_DIR,
             DCS_RUNTIME_PLATFORM);
    snprintf(file, sizeof file, "%s/%s", folder, DCS_RUNTIME_MANIFEST);
    if (dcs_is_regular_file(folder) == -1) { /* a folder; else: no runtime, rc 0 */
        text = read_all(file, &len);
        rt = (DcsRuntime *)calloc(1, sizeof *rt);
        if (text == NULL) {
            snprintf(why, nwhy, "the FMU's own Python runtime is damaged: %s is missing or "
                     "unreadable (unzip the FMU again)", file);
            rc = -1;
        } else if (rt == NULL || (rt->root = dup_n(folder, strlen(folder))) == NULL ||
                   parse(rt, text, len, file, why, nwhy) != 0) {
            if (why[0] == '\0')
                snprintf(why, nwhy, "out of memory reading %s", file);
            rc = -1;
        } else {
            *out = rt;
            rt = NULL;
            rc = 1;
        }
    }
    dcs_runtime_free(rt);
    free(text);
    return rc;
}

/* SHA-256 and length of a file; 0, or -1 if it cannot be read. */
static int hash_file(const char *path, char hex[65], long long *size)
{
    static unsigned char buf[1 << 20];
    DcsSha256 s;
    size_t k;
    int rc = -1;
    FILE *f = dcs_fopen(path, "rb");
    if (f != NULL) {
        dcs_sha256_init(&s);
        *size = 0;
        while ((k = fread(buf, 1, sizeof buf, f)) > 0) {
            dcs_sha256_update(&s, buf, k);
            *size += (long long)k;
        }
        rc = ferror(f) ? -1 : 0;
        fclose(f);
        dcs_sha256_hex(&s, hex);
    }
    return rc;
}

int dcs_runtime_verify(const DcsRuntime *rt, int hashes, char *why, size_t nwhy)
{
    size_t i;
    int rc = 0;
    for (i = 0; i < rt->n_files && rc == 0; i++) {
        const Entry *e = &rt->files[i];
        char path[4200], hex[65];
        long long size;
        snprintf(path, sizeof path, "%s/%s", rt->root, e->path);
        size = file_size(path);
        if (size < 0) {
            snprintf(why, nwhy, "the FMU's own Python runtime is incomplete: %s is missing "
                     "(unzip the FMU again; %zu files are listed in %s/%s)", path, rt->n_files,
                     rt->root, DCS_RUNTIME_MANIFEST);
            rc = -1;
        } else if (size != e->size ||
                   (hashes && (hash_file(path, hex, &size) != 0 || strcmp(hex, e->hex) != 0))) {
            snprintf(why, nwhy, "the FMU's own Python runtime is damaged: %s differs from the "
                     "file it was built with (%s; unzip the FMU again)", path,
                     size != e->size ? "another size" : "another SHA-256");
            rc = -1;
        }
    }
    return rc;
}

const char *dcs_runtime_root(const DcsRuntime *rt) { return rt->root; }
const char *dcs_runtime_library(const DcsRuntime *rt) { return item(rt, "library"); }
const char *dcs_runtime_program(const DcsRuntime *rt) { return item(rt, "program"); }
const char *dcs_runtime_home(const DcsRuntime *rt) { return item(rt, "home"); }
const char *dcs_runtime_python(const DcsRuntime *rt) { return item(rt, "python"); }

size_t dcs_runtime_count(const DcsRuntime *rt, const char *key)
{
    size_t i, n = 0;
    for (i = 0; i < rt->n_items; i++)
        n += strcmp(rt->items[i].key, key) == 0;
    return n;
}

const char *dcs_runtime_item(const DcsRuntime *rt, const char *key, size_t k)
{
    size_t i;
    const char *found = NULL;
    for (i = 0; i < rt->n_items && found == NULL; i++)
        if (strcmp(rt->items[i].key, key) == 0 && k-- == 0)
            found = rt->items[i].value;
    return found;
}

int dcs_runtime_compatible(const DcsRuntime *running, const DcsRuntime *other, char *why,
                           size_t nwhy)
{
    size_t i, j;
    char differ[1024] = "";
    int ok = 1;
    if (strcmp(running->group_hex[0], other->group_hex[0]) != 0) {
        snprintf(why, nwhy, "its interpreter or standard library (Python %s) is not the one "
                 "running (Python %s)", dcs_runtime_python(other), dcs_runtime_python(running));
        ok = 0;
    }
    for (i = 1; i < other->n_groups && ok; i++)
        for (j = 1; j < running->n_groups; j++)
            if (strcmp(other->groups[i], running->groups[j]) == 0 &&
                strcmp(other->group_hex[i], running->group_hex[j]) != 0 &&
                strlen(differ) + strlen(other->groups[i]) + 3 < sizeof differ)
                snprintf(differ + strlen(differ), sizeof differ - strlen(differ), "%s%s",
                         differ[0] ? ", " : "", other->groups[i]);
    if (ok && differ[0]) {
        snprintf(why, nwhy, "its packages %s differ from those running", differ);
        ok = 0;
    }
    return ok;
}
