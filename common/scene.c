#include "scene.h"

#include <errno.h>
#include <libconfig.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

struct cm_scene {
    config_t cfg;
    char path[1024];
    char dir[1024];
};

/* A setting counts as read when its hook points at this marker. */
static char g_known_marker;

static void mark_known(config_setting_t *st)
{
    for (; st; st = config_setting_parent(st))
        config_setting_set_hook(st, &g_known_marker);
}

static int line_of(const config_setting_t *st)
{
    return st ? (int)config_setting_source_line(st) : 0;
}

static int open_common(cm_scene *s, const char *name, cm_scene **out)
{
    snprintf(s->path, sizeof s->path, "%s", name);
    snprintf(s->dir, sizeof s->dir, "%s", name);
    char *slash = strrchr(s->dir, '/');
    if (slash)
        *slash = '\0';
    else
        snprintf(s->dir, sizeof s->dir, ".");
    *out = s;
    return CM_OK;
}

int cm_scene_open(const char *path, cm_scene **out, cm_error *err)
{
    *out = NULL;
    FILE *f = fopen(path, "r");
    if (!f)
        return cm_fail(err, CM_ERR_IO, "cannot open scene file %s: %s", path, strerror(errno));
    cm_scene *s = calloc(1, sizeof *s);
    if (!s) {
        fclose(f);
        return cm_fail(err, CM_ERR_NOMEM, "out of memory reading %s", path);
    }
    config_init(&s->cfg);
    int ok = config_read(&s->cfg, f);
    fclose(f);
    if (!ok) {
        cm_fail(err, CM_ERR_PARSE, "%s:%d: %s", path, config_error_line(&s->cfg), config_error_text(&s->cfg));
        config_destroy(&s->cfg);
        free(s);
        return CM_ERR_PARSE;
    }
    return open_common(s, path, out);
}

int cm_scene_open_string(const char *text, const char *name, cm_scene **out, cm_error *err)
{
    *out = NULL;
    cm_scene *s = calloc(1, sizeof *s);
    if (!s)
        return cm_fail(err, CM_ERR_NOMEM, "out of memory reading %s", name);
    config_init(&s->cfg);
    if (!config_read_string(&s->cfg, text)) {
        cm_fail(err, CM_ERR_PARSE, "%s:%d: %s", name, config_error_line(&s->cfg), config_error_text(&s->cfg));
        config_destroy(&s->cfg);
        free(s);
        return CM_ERR_PARSE;
    }
    return open_common(s, name, out);
}

void cm_scene_close(cm_scene **s)
{
    if (!s || !*s)
        return;
    config_destroy(&(*s)->cfg);
    free(*s);
    *s = NULL;
}

const char *cm_scene_path(const cm_scene *s) { return s->path; }
const char *cm_scene_dir(const cm_scene *s) { return s->dir; }

bool cm_scene_has(cm_scene *s, const char *path)
{
    return config_lookup(&s->cfg, path) != NULL;
}

/* Line of the deepest existing ancestor of path, for "missing key" messages. */
static int line_of_path(cm_scene *s, const char *path)
{
    char buf[512];
    snprintf(buf, sizeof buf, "%s", path);
    for (;;) {
        char *dot = strrchr(buf, '.');
        if (!dot)
            return 0;
        *dot = '\0';
        config_setting_t *st = config_lookup(&s->cfg, buf);
        if (st)
            return line_of(st);
    }
}

static int missing(cm_scene *s, const char *path, cm_error *err)
{
    int line = line_of_path(s, path);
    if (line > 0)
        return cm_fail(err, CM_ERR_KEY, "%s:%d: missing required key '%s'", s->path, line, path);
    return cm_fail(err, CM_ERR_KEY, "%s: missing required key '%s'", s->path, path);
}

static int as_double(cm_scene *s, const config_setting_t *st, const char *path, double *out, cm_error *err)
{
    switch (config_setting_type(st)) {
    case CONFIG_TYPE_FLOAT: *out = config_setting_get_float(st); break;
    case CONFIG_TYPE_INT: *out = (double)config_setting_get_int(st); break;
    case CONFIG_TYPE_INT64: *out = (double)config_setting_get_int64(st); break;
    default:
        return cm_fail(err, CM_ERR_KEY, "%s:%d: key '%s' must be a number", s->path, line_of(st), path);
    }
    if (!isfinite(*out))
        return cm_fail(err, CM_ERR_RANGE, "%s:%d: key '%s' is not a finite number", s->path, line_of(st), path);
    return CM_OK;
}

static int check_range(cm_scene *s, const config_setting_t *st, const char *path, double v, double lo, double hi,
                       cm_error *err)
{
    if (v < lo || v > hi)
        return cm_fail(err, CM_ERR_RANGE, "%s:%d: key '%s' = %g is outside the allowed range [%g, %g]", s->path,
                       line_of(st), path, v, lo, hi);
    return CM_OK;
}

int cm_scene_double(cm_scene *s, const char *path, double lo, double hi, double *out, cm_error *err)
{
    config_setting_t *st = config_lookup(&s->cfg, path);
    if (!st)
        return missing(s, path, err);
    mark_known(st);
    double v;
    int rc = as_double(s, st, path, &v, err);
    if (rc)
        return rc;
    rc = check_range(s, st, path, v, lo, hi, err);
    if (rc)
        return rc;
    *out = v;
    return CM_OK;
}

int cm_scene_double_opt(cm_scene *s, const char *path, double lo, double hi, double def, double *out, cm_error *err)
{
    if (!config_lookup(&s->cfg, path)) {
        *out = def;
        return CM_OK;
    }
    return cm_scene_double(s, path, lo, hi, out, err);
}

int cm_scene_int(cm_scene *s, const char *path, long lo, long hi, long *out, cm_error *err)
{
    config_setting_t *st = config_lookup(&s->cfg, path);
    if (!st)
        return missing(s, path, err);
    mark_known(st);
    long long v;
    switch (config_setting_type(st)) {
    case CONFIG_TYPE_INT: v = config_setting_get_int(st); break;
    case CONFIG_TYPE_INT64: v = config_setting_get_int64(st); break;
    default:
        return cm_fail(err, CM_ERR_KEY, "%s:%d: key '%s' must be an integer", s->path, line_of(st), path);
    }
    if (v < lo || v > hi)
        return cm_fail(err, CM_ERR_RANGE, "%s:%d: key '%s' = %lld is outside the allowed range [%ld, %ld]",
                       s->path, line_of(st), path, v, lo, hi);
    *out = (long)v;
    return CM_OK;
}

int cm_scene_int_opt(cm_scene *s, const char *path, long lo, long hi, long def, long *out, cm_error *err)
{
    if (!config_lookup(&s->cfg, path)) {
        *out = def;
        return CM_OK;
    }
    return cm_scene_int(s, path, lo, hi, out, err);
}

int cm_scene_bool_opt(cm_scene *s, const char *path, bool def, bool *out, cm_error *err)
{
    config_setting_t *st = config_lookup(&s->cfg, path);
    if (!st) {
        *out = def;
        return CM_OK;
    }
    mark_known(st);
    if (config_setting_type(st) != CONFIG_TYPE_BOOL)
        return cm_fail(err, CM_ERR_KEY, "%s:%d: key '%s' must be true or false", s->path, line_of(st), path);
    *out = config_setting_get_bool(st) != 0;
    return CM_OK;
}

int cm_scene_string(cm_scene *s, const char *path, char *buf, size_t len, cm_error *err)
{
    config_setting_t *st = config_lookup(&s->cfg, path);
    if (!st)
        return missing(s, path, err);
    mark_known(st);
    if (config_setting_type(st) != CONFIG_TYPE_STRING)
        return cm_fail(err, CM_ERR_KEY, "%s:%d: key '%s' must be a string in double quotes", s->path, line_of(st),
                       path);
    const char *v = config_setting_get_string(st);
    if (strlen(v) >= len)
        return cm_fail(err, CM_ERR_RANGE, "%s:%d: key '%s' is longer than %zu characters", s->path, line_of(st),
                       path, len - 1);
    memcpy(buf, v, strlen(v) + 1);
    return CM_OK;
}

int cm_scene_string_opt(cm_scene *s, const char *path, const char *def, char *buf, size_t len, cm_error *err)
{
    if (!config_lookup(&s->cfg, path)) {
        if (strlen(def) >= len)
            return cm_fail(err, CM_ERR_RANGE, "default for '%s' too long", path);
        memcpy(buf, def, strlen(def) + 1);
        return CM_OK;
    }
    return cm_scene_string(s, path, buf, len, err);
}

int cm_scene_doubles(cm_scene *s, const char *path, int n, double lo, double hi, double *out, cm_error *err)
{
    config_setting_t *st = config_lookup(&s->cfg, path);
    if (!st)
        return missing(s, path, err);
    mark_known(st);
    int type = config_setting_type(st);
    if ((type != CONFIG_TYPE_ARRAY && type != CONFIG_TYPE_LIST) || config_setting_length(st) != n)
        return cm_fail(err, CM_ERR_KEY, "%s:%d: key '%s' must be an array of %d numbers, e.g. [%s]", s->path,
                       line_of(st), path, n, n == 3 ? "0.0, 0.0, -9.81" : "...");
    for (int i = 0; i < n; i++) {
        config_setting_t *el = config_setting_get_elem(st, (unsigned)i);
        char elpath[600];
        snprintf(elpath, sizeof elpath, "%s[%d]", path, i);
        double v;
        int rc = as_double(s, el, elpath, &v, err);
        if (!rc)
            rc = check_range(s, el, elpath, v, lo, hi, err);
        if (rc)
            return rc;
        out[i] = v;
    }
    return CM_OK;
}

int cm_scene_doubles_opt(cm_scene *s, const char *path, int n, double lo, double hi, const double *def,
                         double *out, cm_error *err)
{
    if (!config_lookup(&s->cfg, path)) {
        memcpy(out, def, (size_t)n * sizeof *out);
        return CM_OK;
    }
    return cm_scene_doubles(s, path, n, lo, hi, out, err);
}

int cm_scene_choice(cm_scene *s, const char *path, const char *const *choices, int *out, cm_error *err)
{
    char word[128];
    int rc = cm_scene_string(s, path, word, sizeof word, err);
    if (rc)
        return rc;
    char list[512] = "";
    for (int i = 0; choices[i]; i++) {
        if (strcmp(word, choices[i]) == 0) {
            *out = i;
            return CM_OK;
        }
        size_t used = strlen(list);
        snprintf(list + used, sizeof list - used, "%s\"%s\"", i ? ", " : "", choices[i]);
    }
    config_setting_t *st = config_lookup(&s->cfg, path);
    return cm_fail(err, CM_ERR_RANGE, "%s:%d: key '%s' = \"%s\" is not one of %s", s->path, line_of(st), path, word,
                   list);
}

int cm_scene_choice_opt(cm_scene *s, const char *path, const char *const *choices, int def, int *out,
                        cm_error *err)
{
    if (!config_lookup(&s->cfg, path)) {
        *out = def;
        return CM_OK;
    }
    return cm_scene_choice(s, path, choices, out, err);
}

int cm_scene_length(cm_scene *s, const char *path)
{
    config_setting_t *st = config_lookup(&s->cfg, path);
    if (!st)
        return 0;
    mark_known(st);
    return config_setting_length(st);
}

static void mark_subtree(config_setting_t *st)
{
    config_setting_set_hook(st, &g_known_marker);
    int n = config_setting_is_aggregate(st) ? config_setting_length(st) : 0;
    for (int i = 0; i < n; i++)
        mark_subtree(config_setting_get_elem(st, (unsigned)i));
}

void cm_scene_mark_known(cm_scene *s, const char *path)
{
    config_setting_t *st = config_lookup(&s->cfg, path);
    if (st) {
        mark_known(st);
        mark_subtree(st);
    }
}

/* Builds "a.b.[2].c" for st into buf (libconfig's own path syntax). */
static void setting_path(const config_setting_t *st, char *buf, size_t len)
{
    const config_setting_t *chain[64];
    int n = 0;
    for (const config_setting_t *p = st; p && !config_setting_is_root(p) && n < 64; p = config_setting_parent(p))
        chain[n++] = p;
    buf[0] = '\0';
    for (int i = n - 1; i >= 0; i--) {
        size_t used = strlen(buf);
        const char *name = config_setting_name(chain[i]);
        if (name)
            snprintf(buf + used, len - used, "%s%s", used ? "." : "", name);
        else
            snprintf(buf + used, len - used, "%s[%d]", used ? "." : "", config_setting_index(chain[i]));
    }
}

static int find_unread(cm_scene *s, config_setting_t *st, cm_error *err)
{
    /* Groups and lists are containers: report their unread leaves, so the
     * message names the exact key. An unread empty container is reported. */
    int aggregate = config_setting_is_group(st) || config_setting_is_list(st);
    if (config_setting_get_hook(st) != &g_known_marker && (!aggregate || config_setting_length(st) == 0)) {
        char p[600];
        setting_path(st, p, sizeof p);
        return cm_fail(err, CM_ERR_KEY, "%s:%d: unknown key '%s' (misspelt, or not used by this scene)", s->path,
                       line_of(st), p);
    }
    /* Elements of a numeric array are read as a whole. */
    if (config_setting_type(st) == CONFIG_TYPE_ARRAY)
        return CM_OK;
    int n = config_setting_is_aggregate(st) ? config_setting_length(st) : 0;
    for (int i = 0; i < n; i++) {
        int rc = find_unread(s, config_setting_get_elem(st, (unsigned)i), err);
        if (rc)
            return rc;
    }
    return CM_OK;
}

int cm_scene_check_unknown(cm_scene *s, const char *const *sections, cm_error *err)
{
    config_setting_t *root = config_root_setting(&s->cfg);
    int n = config_setting_length(root);
    for (int i = 0; i < n; i++) {
        config_setting_t *st = config_setting_get_elem(root, (unsigned)i);
        const char *name = config_setting_name(st);
        int ours = 0;
        for (int k = 0; sections[k]; k++)
            ours |= strcmp(name, sections[k]) == 0;
        if (!ours && config_setting_get_hook(st) != &g_known_marker)
            return cm_fail(err, CM_ERR_KEY, "%s:%d: unknown section '%s'", s->path, line_of(st), name);
        if (ours) {
            int rc = find_unread(s, st, err);
            if (rc)
                return rc;
        }
    }
    return CM_OK;
}
