#include "scene.h"

#include <ctype.h>
#include <errno.h>
#include <libconfig.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "json.h"

/* The --set overrides of this process (cm_scene_add_override). */
static const char *g_overrides[CM_SCENE_MAX_OVERRIDES];
static int g_n_overrides;

struct cm_scene {
    config_t cfg;
    char path[1024];
    char dir[1024];
    char where[1100]; /* message buffer of where() */
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

/* "file:line" of a setting, or "file (--set)" for one an override created. */
static const char *where(cm_scene *s, const config_setting_t *st)
{
    int line = line_of(st);
    if (line > 0)
        snprintf(s->where, sizeof s->where, "%s:%d", s->path, line);
    else
        snprintf(s->where, sizeof s->where, "%s (--set)", s->path);
    return s->where;
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
    open_common(s, path, out);
    for (int i = 0; i < g_n_overrides; i++) {
        int rc = cm_scene_set(s, g_overrides[i], err);
        if (rc) {
            cm_scene_close(out);
            return rc;
        }
    }
    return CM_OK;
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
        return cm_fail(err, CM_ERR_KEY, "%s: key '%s' must be a number", where(s, st), path);
    }
    if (!isfinite(*out))
        return cm_fail(err, CM_ERR_RANGE, "%s: key '%s' is not a finite number", where(s, st), path);
    return CM_OK;
}

static int check_range(cm_scene *s, const config_setting_t *st, const char *path, double v, double lo, double hi,
                       cm_error *err)
{
    if (v < lo || v > hi)
        return cm_fail(err, CM_ERR_RANGE, "%s: key '%s' = %g is outside the allowed range [%g, %g]", where(s, st), path, v, lo, hi);
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
        return cm_fail(err, CM_ERR_KEY, "%s: key '%s' must be an integer", where(s, st), path);
    }
    if (v < lo || v > hi)
        return cm_fail(err, CM_ERR_RANGE, "%s: key '%s' = %lld is outside the allowed range [%ld, %ld]",
                       where(s, st), path, v, lo, hi);
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
        return cm_fail(err, CM_ERR_KEY, "%s: key '%s' must be true or false", where(s, st), path);
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
        return cm_fail(err, CM_ERR_KEY, "%s: key '%s' must be a string in double quotes", where(s, st),
                       path);
    const char *v = config_setting_get_string(st);
    if (strlen(v) >= len)
        return cm_fail(err, CM_ERR_RANGE, "%s: key '%s' is longer than %zu characters", where(s, st),
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
        return cm_fail(err, CM_ERR_KEY, "%s: key '%s' must be an array of %d numbers, e.g. [%s]", where(s, st), path, n, n == 3 ? "0.0, 0.0, -9.81" : "...");
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
    return cm_fail(err, CM_ERR_RANGE, "%s: key '%s' = \"%s\" is not one of %s", where(s, st), path, word,
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

void cm_scene_skip_foreign(cm_scene *s, const char *const *own)
{
    static const char *const all[] = {"run", "coupling", "wheel", "fem", "dem", "scm", NULL};
    for (int k = 0; all[k]; k++) {
        int ours = 0;
        for (int i = 0; own[i]; i++)
            ours |= strcmp(all[k], own[i]) == 0;
        if (!ours)
            cm_scene_mark_known(s, all[k]);
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
        return cm_fail(err, CM_ERR_KEY, "%s: unknown key '%s' (misspelt, or not used by this scene)", where(s, st), p);
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
            return cm_fail(err, CM_ERR_KEY, "%s: unknown section '%s'", where(s, st), name);
        if (ours) {
            int rc = find_unread(s, st, err);
            if (rc)
                return rc;
        }
    }
    return CM_OK;
}

/* ---- overrides (--set key=value) ------------------------------------------ */

/* Deep copy of src as a new child `name` of parent (name NULL inside lists
 * and arrays). */
static config_setting_t *copy_setting(config_setting_t *parent, const char *name, const config_setting_t *src)
{
    int type = config_setting_type(src);
    config_setting_t *d = config_setting_add(parent, name, type);
    if (!d)
        return NULL;
    int ok = CONFIG_TRUE;
    switch (type) {
    case CONFIG_TYPE_INT: ok = config_setting_set_int(d, config_setting_get_int(src)); break;
    case CONFIG_TYPE_INT64: ok = config_setting_set_int64(d, config_setting_get_int64(src)); break;
    case CONFIG_TYPE_FLOAT: ok = config_setting_set_float(d, config_setting_get_float(src)); break;
    case CONFIG_TYPE_BOOL: ok = config_setting_set_bool(d, config_setting_get_bool(src)); break;
    case CONFIG_TYPE_STRING: ok = config_setting_set_string(d, config_setting_get_string(src)); break;
    default:
        for (int i = 0; i < config_setting_length(src); i++) {
            const config_setting_t *el = config_setting_get_elem(src, (unsigned)i);
            if (!copy_setting(d, config_setting_name(el), el))
                return NULL;
        }
    }
    return ok == CONFIG_TRUE ? d : NULL;
}

static bool is_number_type(int t)
{
    return t == CONFIG_TYPE_INT || t == CONFIG_TYPE_INT64 || t == CONFIG_TYPE_FLOAT;
}

static double number_of(const config_setting_t *st)
{
    switch (config_setting_type(st)) {
    case CONFIG_TYPE_INT: return config_setting_get_int(st);
    case CONFIG_TYPE_INT64: return (double)config_setting_get_int64(st);
    default: return config_setting_get_float(st);
    }
}

/* The parent group of `key` (all but its last component), created as groups
 * where missing; *last points at the last component within key. */
static config_setting_t *parent_for(cm_scene *s, const char *key, const char **last, const char *assignment,
                                    cm_error *err)
{
    const char *dot = strrchr(key, '.');
    *last = dot ? dot + 1 : key;
    if (!dot)
        return config_root_setting(&s->cfg);
    char path[512];
    snprintf(path, sizeof path, "%.*s", (int)(dot - key), key);
    config_setting_t *p = config_lookup(&s->cfg, path);
    if (p)
        return p;
    const char *ignored;
    config_setting_t *grand = parent_for(s, path, &ignored, assignment, err);
    if (!grand)
        return NULL;
    if (!config_setting_is_group(grand) || ignored[0] == '[') {
        cm_fail(err, CM_ERR_KEY, "%s: --set %s: '%s' is not in the scene and cannot be created there", s->path,
                assignment, path);
        return NULL;
    }
    p = config_setting_add(grand, ignored, CONFIG_TYPE_GROUP);
    if (!p)
        cm_fail(err, CM_ERR_KEY, "%s: --set %s: cannot create group '%s'", s->path, assignment, path);
    return p;
}

/* Copies an override's value with every integer literal inside [...]
 * written as a float (10 -> 10.0), quoted strings untouched. */
static void promote_array_ints(const char *v, char *out, size_t len)
{
    size_t o = 0;
    int depth = 0, quoted = 0;
    for (const char *p = v; *p && o + 3 < len; p++) {
        if (quoted) {
            quoted = !(*p == '"' && p[-1] != '\\');
        } else if (*p == '"') {
            quoted = 1;
        } else if (*p == '[') {
            depth++;
        } else if (*p == ']') {
            depth--;
        } else if (depth > 0 && (isdigit((unsigned char)*p) || ((*p == '-' || *p == '+') && isdigit((unsigned char)p[1]))) &&
                   (p == v || strchr("[, \t", p[-1]))) {
            /* a number token: copy it, and add ".0" unless it has a point or exponent or is hex */
            const char *q = p + 1;
            while (*q && !strchr(",] \t", *q))
                q++;
            int is_float = 0;
            for (const char *r = p; r < q; r++)
                is_float |= *r == '.' || *r == 'e' || *r == 'E' || *r == 'x' || *r == 'X';
            while (p < q && o + 3 < len)
                out[o++] = *p++;
            if (!is_float && o + 3 < len) {
                out[o++] = '.';
                out[o++] = '0';
            }
            p--;
            continue;
        }
        out[o++] = *p;
    }
    out[o] = '\0';
}

int cm_scene_write(const cm_scene *s, FILE *f, cm_error *err)
{
    config_write(&s->cfg, f);
    if (fflush(f) != 0 || ferror(f))
        return cm_fail(err, CM_ERR_IO, "%s: writing the resolved scene failed", s->path);
    return CM_OK;
}

/* One setting as JSON: groups are objects, arrays and lists are arrays,
 * floats always carry a point or an exponent (so that a reader keeps 1.0 a
 * float) and 17 digits (they read back bit for bit). */
static void json_setting(FILE *f, const config_setting_t *v, int depth)
{
    switch (config_setting_type(v)) {
    case CONFIG_TYPE_GROUP:
    case CONFIG_TYPE_ARRAY:
    case CONFIG_TYPE_LIST: {
        const int group = config_setting_type(v) == CONFIG_TYPE_GROUP, n = config_setting_length(v);
        fputc(group ? '{' : '[', f);
        for (int i = 0; i < n; i++) {
            const config_setting_t *e = config_setting_get_elem(v, (unsigned)i);
            fputs(i ? ", " : "", f);
            if (group) {
                fprintf(f, "\n%*s", 2 * (depth + 1), "");
                cm_json_string(f, config_setting_name(e));
                fputs(": ", f);
            }
            json_setting(f, e, depth + 1);
        }
        if (group && n > 0)
            fprintf(f, "\n%*s", 2 * depth, "");
        fputc(group ? '}' : ']', f);
        break;
    }
    case CONFIG_TYPE_INT:
    case CONFIG_TYPE_INT64:
        fprintf(f, "%lld", config_setting_get_int64(v));
        break;
    case CONFIG_TYPE_FLOAT: {
        char num[40];
        const double x = config_setting_get_float(v);
        if (!isfinite(x)) { /* JSON has no infinity nor NaN */
            fputs("null", f);
            break;
        }
        snprintf(num, sizeof num, "%.17g", x);
        fputs(num, f);
        if (!strpbrk(num, ".eE"))
            fputs(".0", f);
        break;
    }
    case CONFIG_TYPE_BOOL:
        fputs(config_setting_get_bool(v) ? "true" : "false", f);
        break;
    case CONFIG_TYPE_STRING:
        cm_json_string(f, config_setting_get_string(v));
        break;
    default:
        fputs("null", f);
    }
}

int cm_scene_write_json(const cm_scene *s, FILE *f, cm_error *err)
{
    json_setting(f, config_root_setting(&s->cfg), 0);
    fputc('\n', f);
    if (fflush(f) != 0 || ferror(f))
        return cm_fail(err, CM_ERR_IO, "%s: writing the resolved scene failed", s->path);
    return CM_OK;
}

int cm_scene_print_config(const char *path, int json, FILE *f, cm_error *err)
{
    cm_scene *s = NULL;
    int rc = cm_scene_open(path, &s, err);
    if (rc == CM_OK)
        rc = json ? cm_scene_write_json(s, f, err) : cm_scene_write(s, f, err);
    cm_scene_close(&s);
    return rc;
}

int cm_scene_set(cm_scene *s, const char *assignment, cm_error *err)
{
    const char *eq = strchr(assignment, '=');
    char key[512], value[1024];
    if (!eq || eq == assignment)
        return cm_fail(err, CM_ERR_PARSE, "--set %s: expected KEY=VALUE, e.g. --set coupling.dt=2e-5", assignment);
    /* Trimmed key and value. */
    const char *k0 = assignment, *k1 = eq, *v0 = eq + 1, *v1 = assignment + strlen(assignment);
    while (k0 < k1 && (*k0 == ' ' || *k0 == '\t'))
        k0++;
    while (k1 > k0 && (k1[-1] == ' ' || k1[-1] == '\t'))
        k1--;
    while (v0 < v1 && (*v0 == ' ' || *v0 == '\t'))
        v0++;
    while (v1 > v0 && (v1[-1] == ' ' || v1[-1] == '\t' || v1[-1] == ';'))
        v1--;
    if (k1 == k0 || (size_t)(k1 - k0) >= sizeof key || v1 == v0 || (size_t)(v1 - v0) >= sizeof value - 8)
        return cm_fail(err, CM_ERR_PARSE, "--set %s: expected KEY=VALUE with a non-empty key and value", assignment);
    snprintf(key, sizeof key, "%.*s", (int)(k1 - k0), k0);
    snprintf(value, sizeof value, "%.*s", (int)(v1 - v0), v0);

    /* The value in libconfig syntax, as one setting `v`; a bare word that
     * does not parse is taken as a string. */
    config_t tmp;
    config_init(&tmp);
    char text[2200];
    snprintf(text, sizeof text, "v = %s;", value);
    const config_setting_t *src = NULL;
    int parsed = config_read_string(&tmp, text);
    if (!parsed && strchr(value, '[') && strchr(value, '.')) {
        /* libconfig's arrays hold one scalar type, so [10, 0.0, 0.0] is
         * refused ("mismatched element type in array"): an integer among
         * floats is meant as a float. */
        char promoted[2100];
        promote_array_ints(value, promoted, sizeof promoted);
        snprintf(text, sizeof text, "v = %s;", promoted);
        config_destroy(&tmp);
        config_init(&tmp);
        parsed = config_read_string(&tmp, text);
    }
    if (parsed && config_setting_length(config_root_setting(&tmp)) == 1)
        src = config_lookup(&tmp, "v");
    bool bare = src == NULL;
    if (bare && strpbrk(value, "\"=;{}()[],#") != NULL) {
        char why[200];
        snprintf(why, sizeof why, "%s", config_error_text(&tmp) ? config_error_text(&tmp) : "unknown reason");
        config_destroy(&tmp);
        return cm_fail(err, CM_ERR_PARSE,
                       "%s: --set %s: the value is not valid libconfig syntax (libconfig: %s); values are numbers "
                       "(2e-5, 3), true/false, \"strings\", arrays of one type [0.0, 0.1] or lists (...)",
                       s->path, assignment, why);
    }

    int rc = CM_OK;
    config_setting_t *st = config_lookup(&s->cfg, key);
    int et = st ? config_setting_type(st) : CONFIG_TYPE_NONE;
    int vt = src ? config_setting_type(src) : CONFIG_TYPE_STRING;
    const char *last = "";
    config_setting_t *parent = st ? config_setting_parent(st) : NULL;
    bool in_array = parent && !config_setting_is_group(parent);
    int ok = CONFIG_TRUE;
    if (st && et == CONFIG_TYPE_STRING && (bare || vt != CONFIG_TYPE_GROUP)) {
        /* A string key takes the text as written (name=run3, name=42). */
        ok = config_setting_set_string(st, src && vt == CONFIG_TYPE_STRING ? config_setting_get_string(src) : value);
    } else if (st && et == CONFIG_TYPE_FLOAT && is_number_type(vt)) {
        ok = config_setting_set_float(st, number_of(src));
    } else if (st && (et == CONFIG_TYPE_INT || et == CONFIG_TYPE_INT64) && (vt == CONFIG_TYPE_INT || vt == CONFIG_TYPE_INT64)) {
        ok = et == CONFIG_TYPE_INT && vt == CONFIG_TYPE_INT ? config_setting_set_int(st, config_setting_get_int(src))
                                                             : config_setting_set_int64(st, config_setting_get_int64(src));
    } else if (st && et == CONFIG_TYPE_BOOL && vt == CONFIG_TYPE_BOOL) {
        ok = config_setting_set_bool(st, config_setting_get_bool(src));
    } else if (st && in_array) {
        if (bare || !is_number_type(vt) || !is_number_type(et))
            rc = cm_fail(err, CM_ERR_KEY, "%s: --set %s: an element of '%.*s' can only be given a number", s->path,
                         assignment, (int)(strrchr(key, '.') ? strrchr(key, '.') - key : 0), key);
        else
            ok = et == CONFIG_TYPE_FLOAT ? config_setting_set_float(st, number_of(src))
                                         : config_setting_set_int64(st, (long long)number_of(src));
    } else {
        /* Missing, or a value of another kind (an array for a group, a float
         * for an int): the value's own type, judged by the reader. */
        char name[256];
        if (st) {
            snprintf(name, sizeof name, "%s", config_setting_name(st));
            config_setting_remove(parent, name);
        } else if ((parent = parent_for(s, key, &last, assignment, err)) != NULL) {
            snprintf(name, sizeof name, "%s", last);
        } else {
            rc = err ? err->code : CM_ERR_KEY;
        }
        if (!rc && (name[0] == '[' || !config_setting_is_group(parent)))
            rc = cm_fail(err, CM_ERR_KEY, "%s: --set %s: '%s' is not in the scene and cannot be created", s->path,
                         assignment, key);
        if (!rc && bare) {
            config_setting_t *d = config_setting_add(parent, name, CONFIG_TYPE_STRING);
            ok = d && config_setting_set_string(d, value);
        } else if (!rc) {
            ok = copy_setting(parent, name, src) != NULL;
        }
    }
    config_destroy(&tmp);
    if (!rc && ok != CONFIG_TRUE)
        rc = cm_fail(err, CM_ERR_KEY, "%s: --set %s: cannot set '%s' to that value", s->path, assignment, key);
    return rc;
}

int cm_scene_add_override(const char *assignment, cm_error *err)
{
    const char *eq = strchr(assignment, '=');
    if (!eq || eq == assignment)
        return cm_fail(err, CM_ERR_PARSE, "--set %s: expected KEY=VALUE, e.g. --set coupling.dt=2e-5", assignment);
    if (g_n_overrides >= CM_SCENE_MAX_OVERRIDES)
        return cm_fail(err, CM_ERR_RANGE, "--set %s: more than %d overrides", assignment, CM_SCENE_MAX_OVERRIDES);
    g_overrides[g_n_overrides++] = assignment;
    return CM_OK;
}

void cm_scene_clear_overrides(void) { g_n_overrides = 0; }

uint64_t cm_scene_overrides_hash(uint64_t h)
{
    /* settings that cannot change a result stay out: a run may be resumed
     * with another DEM thread count or MPI layout (the same bits for any,
     * see dem_pairs.c and dem_mpi.h) */
    static const char *const neutral[] = {"dem.threads", "dem.ranks", "dem.balance"};
    for (int i = 0; i < g_n_overrides; i++) {
        int skip = 0;
        for (size_t k = 0; k < sizeof neutral / sizeof *neutral; k++) {
            size_t n = strlen(neutral[k]);
            const char *o = g_overrides[i];
            while (*o == ' ')
                o++;
            skip |= strncmp(o, neutral[k], n) == 0 && (o[n] == '=' || o[n] == ' ');
        }
        if (skip)
            continue;
        for (const unsigned char *c = (const unsigned char *)g_overrides[i];; c++) {
            h ^= *c; /* the terminating 0 separates the assignments */
            h *= 1099511628211ULL;
            if (!*c)
                break;
        }
    }
    return h;
}
