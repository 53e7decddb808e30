/* fem_server --fem-only (issue 16 item 0b): the FEM driven by its scene
 * alone (fem.supports, fem.loads) against closed forms, and the strict
 * checking of the new keys. The bar of tests/fem/scenes/bar_end_load.cfg. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "test.h"

#if !defined(DEMFEM_SOURCE_DIR) || !defined(DEMFEM_BUILD_DIR)
#error "DEMFEM_SOURCE_DIR and DEMFEM_BUILD_DIR must be defined"
#endif

#define BAR DEMFEM_SOURCE_DIR "/tests/fem/scenes/bar_end_load.cfg"

/* The bar's closed forms. */
static const double k_sigma = 1e5, k_E = 1e7, k_L = 0.2, k_A = 0.02 * 0.02;

/* Runs fem_server --fem-only on the bar with extra arguments; returns its
 * exit status, the log and the folder in out. */
static int fem_only_scene(const char *scene, const char *tag, const char *extra, char *out, size_t len, char *log,
                          size_t loglen)
{
    snprintf(out, len, "/tmp/demfem-femonly-%d-%s", (int)getpid(), tag);
    snprintf(log, loglen, "%s.log", out);
    char cmd[2048];
    snprintf(cmd, sizeof cmd, "mkdir -p '%s' && '%s/fem_server/fem_server' --scene '%s' --fem-only --out '%s' %s > '%s' 2>&1",
             out, DEMFEM_BUILD_DIR, scene, out, extra, log);
    int st = system(cmd);
    return st == -1 || !WIFEXITED(st) ? -1 : WEXITSTATUS(st);
}

static int fem_only(const char *tag, const char *extra, char *out, size_t len, char *log, size_t loglen)
{
    return fem_only_scene(BAR, tag, extra, out, len, log, loglen);
}

static const char *slurp(const char *path)
{
    static char buf[1 << 16];
    FILE *f = fopen(path, "r");
    size_t n = f ? fread(buf, 1, sizeof buf - 1, f) : 0;
    if (f)
        fclose(f);
    buf[n] = '\0';
    return buf;
}

/* Column `name` of DIR/fem_series.csv: every row into v (at most cap); the row count. */
static int series_column(const char *dir, const char *name, double *v, int cap)
{
    char path[400], line[4096];
    snprintf(path, sizeof path, "%s/fem_series.csv", dir);
    FILE *f = fopen(path, "r");
    if (!f || !fgets(line, sizeof line, f)) {
        if (f)
            fclose(f);
        return -1;
    }
    int col = -1, c = 0;
    for (char *t = strtok(line, ",\n"); t; t = strtok(NULL, ",\n"), c++)
        if (strcmp(t, name) == 0)
            col = c;
    int n = 0;
    while (col >= 0 && n < cap && fgets(line, sizeof line, f)) {
        c = 0;
        for (char *t = strtok(line, ",\n"); t; t = strtok(NULL, ",\n"), c++)
            if (c == col)
                v[n++] = strtod(t, NULL);
    }
    fclose(f);
    return col >= 0 ? n : -1;
}

static void cleanup(const char *out, const char *log)
{
    char cmd[700];
    snprintf(cmd, sizeof cmd, "rm -rf '%s' '%s'", out, log);
    if (system(cmd) != 0)
        fprintf(stderr, "could not remove %s\n", out);
}

/* Static: uniaxial stress is linear, so linear tetrahedra reproduce it
 * exactly (patch test): tip displacement and elastic energy to round-off. */
static int bar_static_closed_form(void)
{
    char out[256], log[300];
    int st = fem_only("static", "", out, sizeof out, log, sizeof log);
    if (st != 0)
        fprintf(stderr, "%s\n", slurp(log));
    ENSURE(st == 0);
    double umax[4], el[4];
    ENSURE(series_column(out, "umax", umax, 4) == 1 && series_column(out, "elastic", el, 4) == 1);
    double u_exact = k_sigma * k_L / k_E, e_exact = k_sigma * k_sigma / (2 * k_E) * k_A * k_L;
    printf("  tip %.12g m (closed form %.12g), elastic energy %.12g J (%.12g)\n", umax[0], u_exact, el[0], e_exact);
    ENSURE_REL(umax[0], u_exact, 1e-9);
    ENSURE_REL(el[0], e_exact, 1e-9);
    ENSURE(strstr(slurp(log), "fem-only static"));
    cleanup(out, log);
    return 0;
}

/* A prescribed end displacement (a support with a value) instead of the
 * load: the same state, so the same elastic energy, exactly. */
static int bar_prescribed_displacement(void)
{
    char out[256], log[300];
    int st = fem_only_scene(DEMFEM_SOURCE_DIR "/tests/fem/scenes/bar_end_displacement.cfg", "disp", "", out,
                            sizeof out, log, sizeof log);
    if (st != 0)
        fprintf(stderr, "%s\n", slurp(log));
    ENSURE(st == 0);
    double umax[4], el[4];
    ENSURE(series_column(out, "umax", umax, 4) == 1 && series_column(out, "elastic", el, 4) == 1);
    double e_exact = k_sigma * k_sigma / (2 * k_E) * k_A * k_L;
    printf("  elastic energy %.12g J (closed form %.12g)\n", el[0], e_exact);
    ENSURE(umax[0] == 0.002);
    ENSURE_REL(el[0], e_exact, 1e-9);
    cleanup(out, log);
    return 0;
}

/* Dynamic: the same load applied at once to the bar at rest; the tip
 * overshoots to twice the static displacement after 2 L / c (undamped). */
static int bar_dynamic_step_load(void)
{
    char out[256], log[300];
    int st = fem_only("dynamic", "--set fem.analysis=dynamic", out, sizeof out, log, sizeof log);
    if (st != 0)
        fprintf(stderr, "%s\n", slurp(log));
    ENSURE(st == 0);
    static double umax[1000], t[1000];
    int n = series_column(out, "umax", umax, 1000);
    ENSURE(n > 50 && series_column(out, "time", t, 1000) == n);
    int k = 0;
    for (int i = 1; i < n; i++)
        k = umax[i] > umax[k] ? i : k;
    double u_static = k_sigma * k_L / k_E, t_peak = 2 * k_L / sqrt(k_E / 1000.0);
    printf("  peak %.6g m at t = %.4g s (closed form %.6g m at %.4g s)\n", umax[k], t[k], 2 * u_static, t_peak);
    ENSURE(umax[0] == 0.0);
    ENSURE_REL(umax[k], 2 * u_static, 0.03);
    ENSURE_REL(t[k], t_peak, 0.1);
    cleanup(out, log);
    return 0;
}

/* Without any load (b0 = 0) the static solve factorizes nothing: u0 = 0
 * (issue 18: 29 s of factorizing for a 165 000-tet mesh with no load). */
static int no_load_skips_factorization(void)
{
    char out[256], log[300];
    int st = fem_only("noload", "--set 'fem.loads.[0].value=[0, 0, 0]'", out, sizeof out, log, sizeof log);
    const char *text = slurp(log);
    if (st != 0)
        fprintf(stderr, "%s\n", text);
    ENSURE(st == 0);
    ENSURE(strstr(text, "static solve: no load (b0 = 0)") && !strstr(text, "cholmod"));
    double umax[4];
    ENSURE(series_column(out, "umax", umax, 4) == 1 && umax[0] == 0.0);
    cleanup(out, log);
    return 0;
}

/* The new keys are checked as strictly as the others: the key and the file. */
static int supports_and_loads_checked(void)
{
    static const struct {
        const char *set, *want;
    } bad[] = {
        {"--set 'fem.supports.[0].fix=\"xq\"'", "fem.supports.[0].fix"},
        {"--set 'fem.supports.[1].set=\"ymiddle\"'", "fem.supports.[1].set"},
        {"--set 'fem.loads.[0].type=\"torque\"'", "fem.loads.[0].type"},
        {"--set 'fem.loads.[0].value=5.0'", "fem.loads.[0].value"},
        {"--set fem.loads.[0].sets=xmax", "fem.loads.[0].sets"},
        {"--set 'fem.supports.[2].fix=\"\"'", "fem.supports.[2].fix"},
        {"--set 'fem.analysis=\"dynamic\"' --set run.end_time=0.0", "run.end_time"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
        char out[256], log[300];
        int st = fem_only("bad", bad[i].set, out, sizeof out, log, sizeof log);
        const char *text = slurp(log);
        if (st == 0 || !strstr(text, bad[i].want) || !strstr(text, "bar_end_load.cfg"))
            fprintf(stderr, "%s:\n%s\n", bad[i].set, text);
        ENSURE(st == 1);
        ENSURE(strstr(text, bad[i].want) && strstr(text, "bar_end_load.cfg"));
        cleanup(out, log);
    }
    return 0;
}

static const test_case tests[] = {
    {"bar_static_closed_form", bar_static_closed_form},
    {"bar_prescribed_displacement", bar_prescribed_displacement},
    {"bar_dynamic_step_load", bar_dynamic_step_load},
    {"no_load_skips_factorization", no_load_skips_factorization},
    {"supports_and_loads_checked", supports_and_loads_checked},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
