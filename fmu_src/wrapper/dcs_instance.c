/*
 * Instance memory, resource files and the log queue of the drillcosim FMI wrapper.
 *
 * Messages are queued while a call runs (possibly holding the GIL) and handed to the host's
 * logger by dcs_flush() at the end of the call, without the GIL: a logger that calls back into
 * Python (fmpy's) or blocks cannot deadlock with the slave. Messages with status fmi2OK are
 * delivered only with debug logging on and their category enabled (fmi2SetDebugLogging; no
 * categories = all); every other status is always delivered.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dcs_platform.h"
#include "dcs_wrapper.h"

static DcsRegistry g_instances = DCS_REGISTRY_INIT;

char *dcs_strdup(const char *s)
{
    const char *src = s != NULL ? s : "";
    size_t n = strlen(src) + 1;
    char *d = (char *)malloc(n);
    if (d != NULL)
        memcpy(d, src, n);
    return d;
}

char *dcs_format(const char *fmt, ...)
{
    va_list ap;
    char *out = NULL;
    int n;
    va_start(ap, fmt);
    n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (n >= 0)
        out = (char *)malloc((size_t)n + 1);
    if (out != NULL) {
        va_start(ap, fmt);
        vsnprintf(out, (size_t)n + 1, fmt, ap);
        va_end(ap);
    }
    return out;
}

DcsInstance *dcs_instance_new(fmi2String name, const fmi2CallbackFunctions *functions,
                              int visible, int logging_on)
{
    DcsInstance *in = (DcsInstance *)calloc(1, sizeof *in);
    if (in != NULL) {
        in->state = DCS_INSTANTIATED;
        in->name = dcs_strdup(name);
        in->logger = functions->logger;
        in->env = functions->componentEnvironment;
        in->visible = visible;
        in->logging_on = logging_on;
        if (in->name == NULL || dcs_registry_add(&g_instances, in) != 0) {
            free(in->name);
            free(in);
            in = NULL;
        }
    }
    return in;
}

DcsInstance *dcs_instance_of(fmi2Component c)
{
    return dcs_registry_contains(&g_instances, c) ? (DcsInstance *)c : NULL;
}

static void clear_categories(DcsInstance *in)
{
    size_t i;
    for (i = 0; i < in->n_categories; i++)
        free(in->categories[i]);
    free(in->categories);
    in->categories = NULL;
    in->n_categories = 0;
}

void dcs_instance_free(DcsInstance *in)
{
    size_t i;
    dcs_registry_remove(&g_instances, in);
    clear_categories(in);
    for (i = 0; i < in->n_messages; i++) {
        free(in->messages[i].category);
        free(in->messages[i].text);
    }
    free(in->messages);
    free(in->name);
    free(in->resources);
    free(in);
}

int dcs_set_categories(DcsInstance *in, int logging_on, size_t n, const fmi2String categories[])
{
    size_t i;
    int rc = 0;
    clear_categories(in);
    in->logging_on = logging_on;
    if (n > 0 && categories != NULL) {
        in->categories = (char **)calloc(n, sizeof *in->categories);
        for (i = 0; in->categories != NULL && i < n; i++) {
            in->categories[i] = dcs_strdup(categories[i]);
            if (in->categories[i] == NULL)
                break;
            in->n_categories++;
        }
        rc = in->n_categories == n ? 0 : -1;
    }
    return rc;
}

static int category_enabled(const DcsInstance *in, const char *category)
{
    size_t i;
    int enabled = in->n_categories == 0;
    for (i = 0; i < in->n_categories && !enabled; i++)
        enabled = strcmp(in->categories[i], category) == 0 ||
                  strcmp(in->categories[i], "logAll") == 0;
    return enabled;
}

const char *dcs_status_category(fmi2Status status)
{
    static const char *const names[] = {"logAll", "logStatusWarning", "logStatusDiscard",
                                        "logStatusError", "logStatusFatal"};
    return status >= fmi2OK && status <= fmi2Fatal ? names[status] : "logStatusFatal";
}

void dcs_log_text(DcsInstance *in, fmi2Status status, const char *category, const char *text)
{
    DcsMessage *m;
    int wanted = in->logger != NULL &&
                 (status != fmi2OK || (in->logging_on && category_enabled(in, category)));
    if (wanted && in->n_messages == in->cap_messages) {
        size_t cap = in->cap_messages ? 2 * in->cap_messages : 8;
        DcsMessage *grown = (DcsMessage *)realloc(in->messages, cap * sizeof *grown);
        if (grown != NULL) {
            in->messages = grown;
            in->cap_messages = cap;
        }
    }
    if (wanted && in->n_messages < in->cap_messages) {
        m = &in->messages[in->n_messages];
        m->status = status;
        m->category = dcs_strdup(category);
        m->text = dcs_strdup(text);
        if (m->category != NULL && m->text != NULL) {
            in->n_messages++;
        } else {
            free(m->category);
            free(m->text);
        }
    }
}

void dcs_log(DcsInstance *in, fmi2Status status, const char *category, const char *fmt, ...)
{
    va_list ap;
    char small[1024];
    char *text = small;
    int n;
    va_start(ap, fmt);
    n = vsnprintf(small, sizeof small, fmt, ap);
    va_end(ap);
    if (n >= (int)sizeof small) { /* a long message (e.g. the Python discovery report) */
        text = (char *)malloc((size_t)n + 1);
        if (text != NULL) {
            va_start(ap, fmt);
            vsnprintf(text, (size_t)n + 1, fmt, ap);
            va_end(ap);
        } else {
            text = small;
        }
    }
    dcs_log_text(in, status, category, text);
    if (text != small)
        free(text);
}

/* Hand the queued messages to the logger ('%' doubled: FMI loggers treat it as a format). */
void dcs_flush(DcsInstance *in)
{
    size_t i, k, n;
    for (i = 0; i < in->n_messages; i++) {
        DcsMessage *m = &in->messages[i];
        char *escaped;
        for (k = 0, n = 0; m->text[k]; k++)
            n += m->text[k] == '%' ? 2 : 1;
        escaped = (char *)malloc(n + 1);
        if (escaped != NULL) {
            char *o = escaped;
            for (k = 0; m->text[k]; k++) {
                *o++ = m->text[k];
                if (m->text[k] == '%')
                    *o++ = '%';
            }
            *o = '\0';
            in->logger(in->env, in->name, m->status, m->category, escaped);
            free(escaped);
        }
        free(m->category);
        free(m->text);
    }
    in->n_messages = 0;
}

/* First line of <resources>/<file>, stripped; malloc'd, or NULL if missing or empty. */
char *dcs_read_resource_line(const char *resources, const char *file)
{
    char path[4096], line[1024];
    char *out = NULL;
    FILE *f;
    snprintf(path, sizeof path, "%s/%s", resources, file);
    f = dcs_fopen(path, "r");
    if (f != NULL) {
        if (fgets(line, sizeof line, f) != NULL) {
            size_t n = strlen(line);
            while (n > 0 && (line[n - 1] == '\n' || line[n - 1] == '\r' || line[n - 1] == ' '))
                line[--n] = '\0';
            out = n > 0 ? dcs_strdup(line) : NULL;
        }
        fclose(f);
    }
    return out;
}

/* modelIdentifier = file name of this library without its extension. */
char *dcs_own_model_identifier(void)
{
    char *path = dcs_own_library_path(), *out = NULL;
    if (path != NULL) {
        const char *base = path, *p, *dot;
        for (p = path; *p; p++)
            if (dcs_is_dir_sep(*p))
                base = p + 1;
        dot = strrchr(base, '.');
        out = dcs_strdup(base);
        if (out != NULL && dot != NULL)
            out[dot - base] = '\0';
        free(path);
    }
    return out;
}

/* "file:///a%20b/resources/" -> "/a b/resources" ("file:///C:/x" -> "C:/x" on Windows), the
 * percent escapes decoded here and the authority read by the platform layer (malloc'd). */
char *dcs_uri_to_path(const char *uri)
{
    const char *p = uri;
    char *decoded, *o, *out = NULL;
    if (strncmp(p, "file:", 5) == 0)
        p += 5;
    decoded = (char *)malloc(strlen(p) + 1);
    if (decoded != NULL) {
        for (o = decoded; *p; p++) {
            char hex[3] = {0, 0, 0};
            char *end = NULL;
            long v = 0;
            if (p[0] == '%' && p[1] && p[2]) {
                hex[0] = p[1];
                hex[1] = p[2];
                v = strtol(hex, &end, 16);
            }
            if (end != NULL && *end == '\0') {
                *o++ = (char)v;
                p += 2;
            } else {
                *o++ = *p;
            }
        }
        *o = '\0';
        out = dcs_file_uri_path(decoded);
        free(decoded);
    }
    if (out != NULL) {
        o = out + strlen(out);
        while (o > out + 1 && dcs_is_dir_sep(o[-1]))
            *--o = '\0';
    }
    return out;
}
