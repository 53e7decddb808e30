/* Scene-file reader: every kind of user mistake gives an error naming the key
 * and the file line; valid files read back exactly. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "scene.h"
#include "test.h"

static const char *k_scene =
    "run = {\n"                  /* 1 */
    "  name = \"demo\";\n"       /* 2 */
    "  end_time = 0.5;\n"        /* 3 */
    "};\n"                       /* 4 */
    "dem = {\n"                  /* 5 */
    "  E = 50000000;\n"          /* 6: integer accepted as float */
    "  gravity = [0.0, 0.0, -9.81];\n" /* 7 */
    "  layers = ( { radius = 0.003; }, { radius = 0.004; } );\n" /* 8 */
    "  verbose = true;\n"        /* 9 */
    "  integrator = \"explicit\";\n" /* 10 */
    "};\n";

static int reads_values(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(k_scene, "demo.cfg", &s, &err) == CM_OK);
    double t, E, g[3], r1;
    char name[32];
    bool verbose;
    ENSURE(cm_scene_string(s, "run.name", name, sizeof name, &err) == CM_OK);
    ENSURE(strcmp(name, "demo") == 0);
    ENSURE(cm_scene_double(s, "run.end_time", 0.0, 10.0, &t, &err) == CM_OK);
    ENSURE(t == 0.5);
    ENSURE(cm_scene_double(s, "dem.E", 1.0, 1e12, &E, &err) == CM_OK);
    ENSURE(E == 5e7);
    ENSURE(cm_scene_doubles(s, "dem.gravity", 3, -100, 100, g, &err) == CM_OK);
    ENSURE(g[2] == -9.81 && g[0] == 0.0);
    ENSURE(cm_scene_length(s, "dem.layers") == 2);
    ENSURE(cm_scene_double(s, "dem.layers.[1].radius", 0, 1, &r1, &err) == CM_OK);
    ENSURE(r1 == 0.004);
    ENSURE(cm_scene_bool_opt(s, "dem.verbose", false, &verbose, &err) == CM_OK && verbose);
    static const char *const kinds[] = {"rigid", "explicit", "newmark", NULL};
    int k = -1;
    ENSURE(cm_scene_choice(s, "dem.integrator", kinds, &k, &err) == CM_OK && k == 1);
    double d;
    ENSURE(cm_scene_double_opt(s, "dem.missing", 0, 1, 0.25, &d, &err) == CM_OK && d == 0.25);
    cm_scene_close(&s);
    ENSURE(s == NULL);
    return 0;
}

static int missing_key_names_key_and_line(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(k_scene, "demo.cfg", &s, &err) == CM_OK);
    double v;
    ENSURE(cm_scene_double(s, "dem.density", 0, 1e5, &v, &err) == CM_ERR_KEY);
    /* The enclosing group starts on line 5. */
    ENSURE_MSG(strstr(err.msg, "demo.cfg:5") && strstr(err.msg, "dem.density"), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

static int out_of_range_names_key_and_line(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(k_scene, "demo.cfg", &s, &err) == CM_OK);
    double v;
    ENSURE(cm_scene_double(s, "run.end_time", 1.0, 10.0, &v, &err) == CM_ERR_RANGE);
    ENSURE_MSG(strstr(err.msg, "demo.cfg:3") && strstr(err.msg, "run.end_time"), "%s", err.msg);
    double g[3];
    ENSURE(cm_scene_doubles(s, "dem.gravity", 3, -5, 5, g, &err) == CM_ERR_RANGE);
    ENSURE_MSG(strstr(err.msg, "demo.cfg:7") && strstr(err.msg, "dem.gravity[2]"), "%s", err.msg);
    static const char *const kinds[] = {"rigid", "newmark", NULL};
    int k;
    ENSURE(cm_scene_choice(s, "dem.integrator", kinds, &k, &err) == CM_ERR_RANGE);
    ENSURE_MSG(strstr(err.msg, "demo.cfg:10") && strstr(err.msg, "\"newmark\""), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

static int wrong_type_is_refused(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(k_scene, "demo.cfg", &s, &err) == CM_OK);
    double v;
    ENSURE(cm_scene_double(s, "run.name", 0, 1, &v, &err) == CM_ERR_KEY);
    ENSURE_MSG(strstr(err.msg, "demo.cfg:2") && strstr(err.msg, "number"), "%s", err.msg);
    long n;
    ENSURE(cm_scene_int(s, "run.end_time", 0, 10, &n, &err) == CM_ERR_KEY);
    double g2[2];
    ENSURE(cm_scene_doubles(s, "dem.gravity", 2, -100, 100, g2, &err) == CM_ERR_KEY);
    cm_scene_close(&s);
    return 0;
}

static int unknown_key_is_refused(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(k_scene, "demo.cfg", &s, &err) == CM_OK);
    double v, g[3];
    char name[32];
    bool b;
    int k;
    static const char *const kinds[] = {"rigid", "explicit", NULL};
    ENSURE(cm_scene_string(s, "run.name", name, sizeof name, &err) == 0);
    ENSURE(cm_scene_double(s, "run.end_time", 0, 1, &v, &err) == 0);
    ENSURE(cm_scene_double(s, "dem.E", 0, 1e9, &v, &err) == 0);
    ENSURE(cm_scene_doubles(s, "dem.gravity", 3, -10, 10, g, &err) == 0);
    ENSURE(cm_scene_bool_opt(s, "dem.verbose", false, &b, &err) == 0);
    ENSURE(cm_scene_choice(s, "dem.integrator", kinds, &k, &err) == 0);
    ENSURE(cm_scene_double(s, "dem.layers.[0].radius", 0, 1, &v, &err) == 0);
    /* layers.[1].radius was never read: that is the unknown key reported. */
    static const char *const sections[] = {"run", "dem", NULL};
    ENSURE(cm_scene_check_unknown(s, sections, &err) == CM_ERR_KEY);
    ENSURE_MSG(strstr(err.msg, "demo.cfg:8") && strstr(err.msg, "dem.layers.[1].radius"), "%s", err.msg);
    ENSURE(cm_scene_double(s, "dem.layers.[1].radius", 0, 1, &v, &err) == 0);
    ENSURE_MSG(cm_scene_check_unknown(s, sections, &err) == CM_OK, "%s", err.msg);
    cm_scene_close(&s);
    /* A top-level section that no server reads is an error too. */
    ENSURE(cm_scene_open_string("run = { a = 1; };\nwheeel = { r = 0.3; };\n", "typo.cfg", &s, &err) == 0);
    long a;
    ENSURE(cm_scene_int(s, "run.a", 0, 5, &a, &err) == 0);
    static const char *const only_run[] = {"run", NULL};
    ENSURE(cm_scene_check_unknown(s, only_run, &err) == CM_ERR_KEY);
    ENSURE_MSG(strstr(err.msg, "typo.cfg:2") && strstr(err.msg, "unknown section 'wheeel'"), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

static int syntax_error_names_line(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string("a = 1;\nb = ;\n", "bad.cfg", &s, &err) == CM_ERR_PARSE);
    ENSURE(s == NULL);
    ENSURE_MSG(strstr(err.msg, "bad.cfg:2"), "%s", err.msg);
    ENSURE(cm_scene_open("/nonexistent/scene.cfg", &s, &err) == CM_ERR_IO);
    ENSURE_MSG(strstr(err.msg, "/nonexistent/scene.cfg"), "%s", err.msg);
    return 0;
}

static int non_finite_refused(void)
{
    /* libconfig has no NaN literal; an overflowing literal becomes inf. */
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string("x = 1e999;\n", "inf.cfg", &s, &err) == CM_OK);
    double v;
    ENSURE(cm_scene_double(s, "x", -1e300, 1e300, &v, &err) != CM_OK);
    ENSURE_MSG(strstr(err.msg, "inf.cfg:1"), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

/* --set overrides: values of each type, the existing type kept, new keys
 * created (and then refused if no reader wants them), bad syntax refused. */
static int set_overrides_values(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(k_scene, "demo.cfg", &s, &err) == CM_OK);
    /* A float key given an integer stays a float; a string key takes a bare word. */
    ENSURE_MSG(cm_scene_set(s, "run.end_time=2", &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(cm_scene_set(s, "run.name = run3", &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(cm_scene_set(s, "dem.integrator=\"newmark\"", &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(cm_scene_set(s, "dem.E=2.5e7", &err) == CM_OK, "%s", err.msg); /* int key, float value */
    ENSURE_MSG(cm_scene_set(s, "dem.gravity=[0.0, 0.0, -1.62]", &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(cm_scene_set(s, "dem.layers.[1].radius=0.005", &err) == CM_OK, "%s", err.msg);
    ENSURE_MSG(cm_scene_set(s, "dem.verbose=false", &err) == CM_OK, "%s", err.msg);
    /* A key the file does not have, in a group it does not have either. */
    ENSURE_MSG(cm_scene_set(s, "run.target.tolerance=0.05", &err) == CM_OK, "%s", err.msg);
    double t, E, g[3], r1, tol;
    char name[32], integ[32];
    bool verbose = true;
    ENSURE(cm_scene_double(s, "run.end_time", 0, 10, &t, &err) == CM_OK && t == 2.0);
    ENSURE(cm_scene_string(s, "run.name", name, sizeof name, &err) == CM_OK && strcmp(name, "run3") == 0);
    ENSURE(cm_scene_string(s, "dem.integrator", integ, sizeof integ, &err) == CM_OK);
    ENSURE(strcmp(integ, "newmark") == 0);
    ENSURE(cm_scene_double(s, "dem.E", 0, 1e9, &E, &err) == CM_OK && E == 2.5e7);
    ENSURE(cm_scene_doubles(s, "dem.gravity", 3, -10, 10, g, &err) == CM_OK && g[2] == -1.62 && g[0] == 0.0);
    ENSURE(cm_scene_double(s, "dem.layers.[1].radius", 0, 1, &r1, &err) == CM_OK && r1 == 0.005);
    ENSURE(cm_scene_bool_opt(s, "dem.verbose", true, &verbose, &err) == CM_OK && !verbose);
    ENSURE(cm_scene_double(s, "run.target.tolerance", 0, 1, &tol, &err) == CM_OK && tol == 0.05);
    /* A key the override created has no line: messages say where it came from. */
    ENSURE(cm_scene_set(s, "run.target.tolerance=5", &err) == CM_OK);
    ENSURE(cm_scene_double(s, "run.target.tolerance", 0, 1, &tol, &err) == CM_ERR_RANGE);
    ENSURE_MSG(strstr(err.msg, "demo.cfg (--set)") && strstr(err.msg, "run.target.tolerance"), "%s", err.msg);
    /* An integer key refuses a fractional value, through its reader. */
    long n;
    ENSURE(cm_scene_set(s, "dem.count=3", &err) == CM_OK);
    ENSURE(cm_scene_int(s, "dem.count", 0, 10, &n, &err) == CM_OK && n == 3);
    ENSURE(cm_scene_set(s, "dem.count=2.5", &err) == CM_OK);
    ENSURE(cm_scene_int(s, "dem.count", 0, 10, &n, &err) == CM_ERR_KEY);
    ENSURE_MSG(strstr(err.msg, "dem.count") && strstr(err.msg, "integer"), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

static int set_errors_and_unknown_keys(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(k_scene, "demo.cfg", &s, &err) == CM_OK);
    ENSURE(cm_scene_set(s, "coupling.dt", &err) == CM_ERR_PARSE); /* no '=' */
    ENSURE_MSG(strstr(err.msg, "KEY=VALUE") && strstr(err.msg, "coupling.dt"), "%s", err.msg);
    ENSURE(cm_scene_set(s, "=3", &err) == CM_ERR_PARSE);
    ENSURE(cm_scene_set(s, "run.end_time=", &err) == CM_ERR_PARSE);
    ENSURE(cm_scene_set(s, "run.end_time=[1.0, ", &err) == CM_ERR_PARSE);
    ENSURE_MSG(strstr(err.msg, "run.end_time") && strstr(err.msg, "libconfig"), "%s", err.msg);
    /* One value only: no second setting smuggled in. */
    ENSURE(cm_scene_set(s, "run.end_time=1.0; evil = 2", &err) == CM_ERR_PARSE);
    /* A list element that does not exist cannot be created. */
    ENSURE(cm_scene_set(s, "dem.layers.[5].radius=0.1", &err) == CM_ERR_KEY);
    ENSURE_MSG(strstr(err.msg, "dem.layers.[5]"), "%s", err.msg);
    /* An unknown key is accepted by --set and refused by the strict check. */
    ENSURE(cm_scene_set(s, "dem.dept=0.3", &err) == CM_OK);
    double v, g[3];
    char name[32];
    bool b;
    int k;
    static const char *const kinds[] = {"rigid", "explicit", NULL};
    ENSURE(cm_scene_string(s, "run.name", name, sizeof name, &err) == 0);
    ENSURE(cm_scene_double(s, "run.end_time", 0, 1, &v, &err) == 0);
    ENSURE(cm_scene_double(s, "dem.E", 0, 1e9, &v, &err) == 0);
    ENSURE(cm_scene_doubles(s, "dem.gravity", 3, -10, 10, g, &err) == 0);
    ENSURE(cm_scene_bool_opt(s, "dem.verbose", false, &b, &err) == 0);
    ENSURE(cm_scene_choice(s, "dem.integrator", kinds, &k, &err) == 0);
    ENSURE(cm_scene_double(s, "dem.layers.[0].radius", 0, 1, &v, &err) == 0);
    ENSURE(cm_scene_double(s, "dem.layers.[1].radius", 0, 1, &v, &err) == 0);
    static const char *const sections[] = {"run", "dem", NULL};
    ENSURE(cm_scene_check_unknown(s, sections, &err) == CM_ERR_KEY);
    ENSURE_MSG(strstr(err.msg, "unknown key 'dem.dept'"), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

/* The process-wide list that the servers fill from --set: applied by
 * cm_scene_open to a file, in order (the last one wins). */
static int set_applied_by_open(void)
{
    char path[] = "/tmp/test_scene_set_XXXXXX";
    int fd = mkstemp(path);
    ENSURE(fd >= 0);
    FILE *f = fdopen(fd, "w");
    ENSURE(f != NULL);
    fputs(k_scene, f);
    fclose(f);
    cm_error err = {0};
    ENSURE(cm_scene_add_override("run.end_time=0.25", &err) == CM_OK);
    ENSURE(cm_scene_add_override("run.end_time=0.75", &err) == CM_OK);
    ENSURE(cm_scene_add_override("nonsense", &err) == CM_ERR_PARSE);
    cm_scene *s;
    int rc = cm_scene_open(path, &s, &err);
    ENSURE_MSG(rc == CM_OK, "%s", err.msg);
    double t;
    ENSURE(cm_scene_double(s, "run.end_time", 0, 10, &t, &err) == CM_OK && t == 0.75);
    cm_scene_close(&s);
    /* A value no setting can take: the open fails naming the file and the --set. */
    ENSURE(cm_scene_add_override("dem.gravity.[0]=\"up\"", &err) == CM_OK);
    ENSURE(cm_scene_open(path, &s, &err) == CM_ERR_KEY && s == NULL);
    ENSURE_MSG(strstr(err.msg, path) && strstr(err.msg, "--set dem.gravity.[0]"), "%s", err.msg);
    cm_scene_clear_overrides();
    ENSURE(cm_scene_open(path, &s, &err) == CM_OK);
    ENSURE(cm_scene_double(s, "run.end_time", 0, 10, &t, &err) == CM_OK && t == 0.5);
    cm_scene_close(&s);
    remove(path);
    return 0;
}

/* An integer among floats in an array ([10, 0.0, 0.0]) is not libconfig
 * (one scalar type per array): taken as the float it means; a value that
 * does not parse is refused with libconfig's reason. */
static int set_int_in_float_array(void)
{
    cm_scene *s;
    cm_error err = {0};
    ENSURE(cm_scene_open_string(k_scene, "demo.cfg", &s, &err) == CM_OK);
    ENSURE_MSG(cm_scene_set(s, "dem.gravity=[10, 0.0, -9.81]", &err) == CM_OK, "%s", err.msg);
    double g[3];
    ENSURE(cm_scene_doubles(s, "dem.gravity", 3, -20, 20, g, &err) == CM_OK);
    ENSURE(g[0] == 10.0 && g[1] == 0.0 && g[2] == -9.81);
    ENSURE_MSG(cm_scene_set(s, "dem.v=[-1, 2.5, +3, 1e2]", &err) == CM_OK, "%s", err.msg);
    double v[4];
    ENSURE(cm_scene_doubles(s, "dem.v", 4, -1e3, 1e3, v, &err) == CM_OK);
    ENSURE(v[0] == -1.0 && v[1] == 2.5 && v[2] == 3.0 && v[3] == 100.0);
    /* A string among numbers stays wrong, and the message says why. */
    ENSURE(cm_scene_set(s, "dem.gravity=[1, 2.0, \"a\"]", &err) == CM_ERR_PARSE);
    ENSURE_MSG(strstr(err.msg, "dem.gravity") && strstr(err.msg, "mismatched element type"), "%s", err.msg);
    cm_scene_close(&s);
    return 0;
}

/* --print-config: the scene written back is the scene with the overrides
 * applied, and it reads back to the same values (scripts read this, never
 * the file and the --set list). */
static int print_config_resolves_overrides(void)
{
    char path[] = "/tmp/test_scene_pc_XXXXXX", out[] = "/tmp/test_scene_pc_out_XXXXXX";
    int fd = mkstemp(path), fo = mkstemp(out);
    ENSURE(fd >= 0 && fo >= 0);
    FILE *f = fdopen(fd, "w");
    ENSURE(f != NULL);
    fputs(k_scene, f);
    fclose(f);
    cm_error err = {0};
    ENSURE(cm_scene_add_override("run.end_time=0.25", &err) == CM_OK);
    ENSURE(cm_scene_add_override("dem.gravity=[1, 0.0, -9.81]", &err) == CM_OK);
    ENSURE(cm_scene_add_override("coupling.dt=2e-5", &err) == CM_OK);
    FILE *o = fdopen(fo, "w");
    ENSURE(o != NULL);
    ENSURE_MSG(cm_scene_print_config(path, 0, o, &err) == CM_OK, "%s", err.msg);
    fclose(o);
    cm_scene_clear_overrides();
    cm_scene *s;
    ENSURE_MSG(cm_scene_open(out, &s, &err) == CM_OK, "%s", err.msg);
    double t, dt, g[3], e;
    char name[32];
    ENSURE(cm_scene_double(s, "run.end_time", 0, 10, &t, &err) == CM_OK && t == 0.25);
    ENSURE(cm_scene_double(s, "coupling.dt", 0, 1, &dt, &err) == CM_OK && dt == 2e-5);
    ENSURE(cm_scene_doubles(s, "dem.gravity", 3, -20, 20, g, &err) == CM_OK && g[0] == 1.0 && g[2] == -9.81);
    ENSURE(cm_scene_double(s, "dem.E", 0, 1e9, &e, &err) == CM_OK && e == 5e7);
    ENSURE(cm_scene_string(s, "run.name", name, sizeof name, &err) == CM_OK && strcmp(name, "demo") == 0);
    ENSURE(cm_scene_length(s, "dem.layers") == 2);
    cm_scene_close(&s);
    /* A missing file: an error naming it, nothing printed. */
    ENSURE(cm_scene_print_config("/nonexistent/scene.cfg", 1, stdout, &err) != CM_OK);
    ENSURE_MSG(strstr(err.msg, "/nonexistent/scene.cfg"), "%s", err.msg);
    remove(path);
    remove(out);
    return 0;
}

/* --print-config=json: the resolved scene as JSON (what bench/post/runio.py
 * reads): groups as objects, lists and arrays as arrays, floats with a point
 * and 17 digits (read back bit for bit), strings quoted and escaped, the
 * overrides applied. */
static int print_config_json(void)
{
    char path[] = "/tmp/test_scene_js_XXXXXX";
    int fd = mkstemp(path);
    ENSURE(fd >= 0);
    FILE *f = fdopen(fd, "w");
    ENSURE(f != NULL);
    fputs(k_scene, f);
    fputs("fem = { note = \"a \\\"quoted\\\" word\"; };\n", f);
    fclose(f);
    cm_error err = {0};
    ENSURE(cm_scene_add_override("run.end_time=0.25", &err) == CM_OK);
    ENSURE(cm_scene_add_override("dem.gravity=[1, 0.0, -9.81]", &err) == CM_OK);
    char *text = NULL;
    size_t len = 0;
    FILE *o = open_memstream(&text, &len);
    ENSURE(o != NULL);
    ENSURE_MSG(cm_scene_print_config(path, 1, o, &err) == CM_OK, "%s", err.msg);
    fclose(o);
    cm_scene_clear_overrides();
    remove(path);
    static const char *const want[] = {
        "\"run\": {", "\"name\": \"demo\"", "\"end_time\": 0.25", "\"E\": 50000000,",
        "\"gravity\": [1.0, 0.0, -9.8100000000000005]", "\"layers\": [{", "\"radius\": 0.0030000000000000001",
        "\"verbose\": true", "\"note\": \"a \\\"quoted\\\" word\""};
    for (size_t k = 0; k < sizeof want / sizeof want[0]; k++)
        ENSURE_MSG(strstr(text, want[k]), "missing %s in:\n%s", want[k], text);
    ENSURE(text[0] == '{' && text[len - 2] == '}' && text[len - 1] == '\n');
    double g2 = 0;
    const char *g = strstr(text, "-9.81");
    ENSURE(g && sscanf(g, "%lf", &g2) == 1 && g2 == -9.81);
    free(text);
    return 0;
}

static const test_case tests[] = {
    {"reads_values", reads_values},
    {"print_config_json", print_config_json},
    {"missing_key_names_key_and_line", missing_key_names_key_and_line},
    {"out_of_range_names_key_and_line", out_of_range_names_key_and_line},
    {"wrong_type_is_refused", wrong_type_is_refused},
    {"unknown_key_is_refused", unknown_key_is_refused},
    {"syntax_error_names_line", syntax_error_names_line},
    {"non_finite_refused", non_finite_refused},
    {"set_overrides_values", set_overrides_values},
    {"set_errors_and_unknown_keys", set_errors_and_unknown_keys},
    {"set_applied_by_open", set_applied_by_open},
    {"set_int_in_float_array", set_int_in_float_array},
    {"print_config_resolves_overrides", print_config_resolves_overrides},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
