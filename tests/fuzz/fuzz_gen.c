/* Deterministic generator and mutator of bad scene files and Gmsh meshes
 * (see fuzz_gen.h). Each seed is written token by token; the tokens are
 * remembered by class (count, tag, coordinate, value, ...) so that a
 * mutation can aim at, say, "a count" or "a node reference" and replace it
 * with a boundary value, before the purely textual mutations run. */
#include "fuzz_gen.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- PRNG: splitmix64 -------------------------------------------------------- */

fz_rng fz_rng_seed(uint64_t kind, uint64_t index)
{
    fz_rng r = {0x9e3779b97f4a7c15ull * (kind + 1) ^ (index * 0xbf58476d1ce4e5b9ull)};
    fz_next(&r);
    return r;
}

uint64_t fz_next(fz_rng *r)
{
    uint64_t z = (r->s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

uint32_t fz_below(fz_rng *r, uint32_t n) { return n ? (uint32_t)(fz_next(r) % n) : 0; }

static int chance(fz_rng *r, int percent) { return (int)fz_below(r, 100) < percent; }

/* ---- text buffer ------------------------------------------------------------- */

void fz_buf_free(fz_buf *b)
{
    free(b->p);
    b->p = NULL;
    b->n = b->cap = 0;
}

static void reserve(fz_buf *b, size_t extra)
{
    if (b->n + extra + 1 <= b->cap)
        return;
    size_t cap = b->cap ? b->cap : 4096;
    while (cap < b->n + extra + 1)
        cap *= 2;
    char *p = realloc(b->p, cap);
    if (!p) {
        fprintf(stderr, "fuzz_gen: out of memory\n");
        abort();
    }
    b->p = p;
    b->cap = cap;
}

static void vappend(fz_buf *b, const char *fmt, va_list ap)
{
    va_list aq;
    va_copy(aq, ap);
    int n = vsnprintf(NULL, 0, fmt, aq);
    va_end(aq);
    reserve(b, (size_t)n);
    vsnprintf(b->p + b->n, (size_t)n + 1, fmt, ap);
    b->n += (size_t)n;
}

void fz_printf(fz_buf *b, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vappend(b, fmt, ap);
    va_end(ap);
}

static void clear(fz_buf *b)
{
    reserve(b, 0);
    b->n = 0;
    b->p[0] = 0;
}

/* Replaces [at, at+len) by rep. */
static void splice(fz_buf *b, size_t at, size_t len, const char *rep, size_t rlen)
{
    if (at > b->n)
        at = b->n;
    if (at + len > b->n)
        len = b->n - at;
    reserve(b, rlen);
    memmove(b->p + at + rlen, b->p + at + len, b->n - at - len + 1);
    memcpy(b->p + at, rep, rlen);
    b->n = b->n - len + rlen;
}

/* ---- recorded tokens --------------------------------------------------------- */

enum {
    TK_COUNT = 0, /* gmsh: section and block counts */
    TK_TAG,       /* gmsh: node, element and entity tags being defined */
    TK_REF,       /* gmsh: node references of elements */
    TK_COORD,     /* gmsh: coordinates, bounding boxes */
    TK_KIND,      /* gmsh: element type, dimension, parametric flag, format fields */
    TK_NUM,       /* scene: numeric value */
    TK_STR,       /* scene: string value (with its quotes) */
    TK_VALUE,     /* scene: any value (number, string, bool, array) */
    TK_CLASSES
};

typedef struct tok {
    size_t at, len;
    int cls;
} tok;

typedef struct toks {
    tok t[8192];
    int n;
} toks;

static void emit(fz_buf *b, toks *tk, int cls, const char *fmt, ...) __attribute__((format(printf, 4, 5)));
static void emit(fz_buf *b, toks *tk, int cls, const char *fmt, ...)
{
    size_t at = b->n;
    va_list ap;
    va_start(ap, fmt);
    vappend(b, fmt, ap);
    va_end(ap);
    if (tk && tk->n < (int)(sizeof tk->t / sizeof tk->t[0]))
        tk->t[tk->n++] = (tok){at, b->n - at, cls};
}

static void note(char *what, size_t len, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void note(char *what, size_t len, const char *fmt, ...)
{
    if (!what || !len)
        return;
    size_t used = strlen(what);
    if (used + 2 >= len)
        return;
    if (used)
        what[used++] = ' ', what[used] = 0;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(what + used, len - used, fmt, ap);
    va_end(ap);
}

/* Boundary values for numbers of any kind. */
static const char *const k_num_pool[] = {
    "nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e308", "-1e308", "1e400", "-1e400", "1e-320", "0", "-0", "1",
    "-1", "2", "0.5", "-0.5", "2147483647", "2147483648", "-2147483648", "-2147483649", "4294967295", "4294967296",
    "9223372036854775807", "9223372036854775808", "-9223372036854775808", "-9223372036854775809",
    "18446744073709551616", "99999999999999999999999", "100000000", "99999999", "1000000000", "0x10", "1e3", "1.0e",
    "--1", "+-1", "1.2.3", "abc", "", "\"1\"", "1L", "0x7fffffffffffffffL",
};
#define NUM_POOL (sizeof k_num_pool / sizeof k_num_pool[0])

/* Values of another type for scene keys. */
static const char *const k_value_pool[] = {
    "\"text\"", "\"\"", "true", "false", "[]", "[1.0, 2.0]", "[1.0, 2.0, 3.0, 4.0]", "[\"a\", \"b\", \"c\"]", "()",
    "(1, \"a\")", "{}", "{ x = 1; }", "1", "1.5", "-1", "0", "1e308", "nan", "0x7FFFFFFF", "9223372036854775807L",
    "[nan, inf, 1.0]", "[1e308, -1e308, 0.0]", "[1, 2, 3]", "[0.0, 0.0, 0.0]", "\"tire\"", "\"gmsh\"", "\"box\"",
    "\"explicit\"", "\"newmark\"", "\"rigid\"", "\"cg\"", "\"cholmod\"", "\"fixed\"", "\"sink_travel\"", "\"TIRE\"",
    "\"tire \"", "\"/nonexistent/mesh.msh\"", "\"../../../../etc/passwd\"", "\"\\n\"",
};
#define VALUE_POOL (sizeof k_value_pool / sizeof k_value_pool[0])

/* Replaces one recorded token of class cls (or of any class when cls < 0)
 * by rep; the list must be sorted by descending offset so that earlier
 * offsets stay valid: callers pick tokens first, then splice in that order. */
typedef struct pick {
    tok t;
    const char *rep;
    char own[2400];
} pick;

static int pick_token(fz_rng *r, const toks *tk, int cls, tok *out)
{
    int cand = 0;
    for (int i = 0; i < tk->n; i++)
        cand += cls < 0 || tk->t[i].cls == cls;
    if (!cand)
        return 0;
    int k = (int)fz_below(r, (uint32_t)cand);
    for (int i = 0; i < tk->n; i++)
        if (cls < 0 || tk->t[i].cls == cls) {
            if (k-- == 0) {
                *out = tk->t[i];
                return 1;
            }
        }
    return 0;
}

static void apply_picks(fz_buf *b, pick *p, int n)
{
    /* descending offsets, one replacement per token */
    for (int i = 0; i < n; i++)
        for (int j = i + 1; j < n; j++)
            if (p[j].t.at > p[i].t.at) {
                pick t = p[i];
                p[i] = p[j];
                p[j] = t;
            }
    size_t last = (size_t)-1;
    for (int i = 0; i < n; i++) {
        if (p[i].t.at == last)
            continue;
        last = p[i].t.at;
        const char *rep = p[i].rep ? p[i].rep : p[i].own;
        splice(b, p[i].t.at, p[i].t.len, rep, strlen(rep));
    }
}

/* ---- textual mutations (any kind) ------------------------------------------- */

static size_t line_start(const fz_buf *b, size_t at)
{
    while (at > 0 && b->p[at - 1] != '\n')
        at--;
    return at;
}

static size_t line_end(const fz_buf *b, size_t at) /* just past the '\n' (or n) */
{
    while (at < b->n && b->p[at] != '\n')
        at++;
    return at < b->n ? at + 1 : at;
}

static void textual(fz_rng *r, fz_buf *b, char *what, size_t wl, int gmsh)
{
    if (b->n == 0)
        return;
    size_t at = fz_below(r, (uint32_t)b->n);
    switch (fz_below(r, 10)) {
    case 0: { /* byte flip (never NUL: the scene reader takes C strings) */
        unsigned char c = (unsigned char)(1 + fz_below(r, 255));
        note(what, wl, "byte@%zu=0x%02x", at, c);
        b->p[at] = (char)c;
        break;
    }
    case 1: /* bit flip */
        b->p[at] = (char)(b->p[at] ^ (1 << fz_below(r, 7)));
        if (!b->p[at])
            b->p[at] = '?';
        note(what, wl, "bitflip@%zu", at);
        break;
    case 2: /* truncation */
        note(what, wl, "truncate@%zu", at);
        b->n = at;
        b->p[at] = 0;
        break;
    case 3: { /* delete a line */
        size_t s = line_start(b, at), e = line_end(b, at);
        note(what, wl, "delete-line@%zu", s);
        splice(b, s, e - s, "", 0);
        break;
    }
    case 4: { /* duplicate a line */
        size_t s = line_start(b, at), e = line_end(b, at);
        char *copy = malloc(e - s + 2);
        memcpy(copy, b->p + s, e - s);
        size_t cl = e - s;
        if (cl == 0 || copy[cl - 1] != '\n')
            copy[cl++] = '\n';
        note(what, wl, "dup-line@%zu", s);
        splice(b, e, 0, copy, cl);
        free(copy);
        break;
    }
    case 5: { /* swap a line with the next one */
        size_t s = line_start(b, at), e = line_end(b, at), e2 = line_end(b, e);
        if (e2 > e && e > s) {
            size_t l1 = e - s, l2 = e2 - e;
            char *tmp = malloc(l1 + l2 + 1);
            memcpy(tmp, b->p + e, l2);
            memcpy(tmp + l2, b->p + s, l1);
            if (tmp[l2 - 1] != '\n' || tmp[l1 + l2 - 1] != '\n') {
                free(tmp); /* last line without newline: leave it */
                break;
            }
            memcpy(b->p + s, tmp, l1 + l2);
            free(tmp);
            note(what, wl, "swap-lines@%zu", s);
        }
        break;
    }
    case 6: { /* insert garbage */
        static const char *const junk[] = {"{", "}", "[", "]", "(", ")", ";", "=", "\"", "#", "$", "$End", "\n",
                                           "@include \"/nonexistent.cfg\"\n", "\\", "\t", " ", ",", "/*", "//",
                                           "$Nodes\n", "$EndElements\n", "0 0 0\n", "\xff\xfe", "\x01"};
        const char *j = junk[fz_below(r, sizeof junk / sizeof *junk)];
        if (j[0] == '@' && gmsh)
            j = "@";
        note(what, wl, "insert@%zu", at);
        splice(b, at, 0, j, strlen(j));
        break;
    }
    case 7: { /* a number-shaped word anywhere */
        const char *v = k_num_pool[fz_below(r, NUM_POOL)];
        char w[128];
        snprintf(w, sizeof w, " %s ", v);
        note(what, wl, "insert-num@%zu=%s", at, v);
        splice(b, at, 0, w, strlen(w));
        break;
    }
    case 8: { /* delete a span */
        size_t len = 1 + fz_below(r, 64);
        note(what, wl, "delete@%zu+%zu", at, len);
        splice(b, at, len, "", 0);
        break;
    }
    default: { /* repeat a span many times (long lines, long tokens) */
        size_t len = 1 + fz_below(r, 16);
        if (at + len > b->n)
            len = b->n - at;
        size_t times = 10 + fz_below(r, 300);
        char *rep = malloc(len * times + 1);
        for (size_t k = 0; k < times; k++)
            memcpy(rep + k * len, b->p + at, len);
        note(what, wl, "repeat@%zu+%zux%zu", at, len, times);
        splice(b, at, 0, rep, len * times);
        free(rep);
        break;
    }
    }
}

/* ---- scenes ------------------------------------------------------------------ */

typedef struct scene_gen {
    fz_buf *b;
    toks *tk;
} scene_gen;

/* The token just emitted is also "a value" (for wrong-type mutations). */
static void also_value(toks *tk)
{
    if (tk->n > 0 && tk->n < (int)(sizeof tk->t / sizeof tk->t[0])) {
        tk->t[tk->n] = tk->t[tk->n - 1];
        tk->t[tk->n++].cls = TK_VALUE;
    }
}

static void kv_num(scene_gen *g, const char *ind, const char *key, const char *fmt, double v)
{
    fz_printf(g->b, "%s%s = ", ind, key);
    emit(g->b, g->tk, TK_NUM, fmt, v);
    also_value(g->tk);
    fz_printf(g->b, ";\n");
}

static void kv_int(scene_gen *g, const char *ind, const char *key, long v)
{
    fz_printf(g->b, "%s%s = ", ind, key);
    emit(g->b, g->tk, TK_NUM, "%ld", v);
    also_value(g->tk);
    fz_printf(g->b, ";\n");
}

static void kv_str(scene_gen *g, const char *ind, const char *key, const char *v)
{
    fz_printf(g->b, "%s%s = ", ind, key);
    emit(g->b, g->tk, TK_STR, "\"%s\"", v);
    also_value(g->tk);
    fz_printf(g->b, ";\n");
}

static void kv_bool(scene_gen *g, const char *ind, const char *key, int v)
{
    fz_printf(g->b, "%s%s = ", ind, key);
    emit(g->b, g->tk, TK_VALUE, "%s", v ? "true" : "false");
    fz_printf(g->b, ";\n");
}

static void kv_vec(scene_gen *g, const char *ind, const char *key, const double *v, int n, const char *fmt)
{
    fz_printf(g->b, "%s%s = ", ind, key);
    size_t at = g->b->n;
    fz_printf(g->b, "[");
    for (int i = 0; i < n; i++) {
        if (i)
            fz_printf(g->b, ", ");
        emit(g->b, g->tk, TK_NUM, fmt, v[i]);
    }
    fz_printf(g->b, "]");
    if (g->tk->n < (int)(sizeof g->tk->t / sizeof g->tk->t[0]))
        g->tk->t[g->tk->n++] = (tok){at, g->b->n - at, TK_VALUE};
    fz_printf(g->b, ";\n");
}

/* A valid scene for fem_server: run, coupling, wheel, fem (one of the three
 * mesh types), a dem section it skips, comments and optional keys at random. */
static void scene_seed(fz_rng *r, fz_buf *b, toks *tk)
{
    scene_gen g = {b, tk};
    const char *in = "  ";
    fz_printf(b, "# generated scene\n");
    fz_printf(b, "run = {\n");
    if (chance(r, 70))
        kv_str(&g, in, "name", chance(r, 50) ? "fuzz" : "tire_on_sand");
    kv_num(&g, in, "end_time", "%.17g", 0.01 * (1 + fz_below(r, 200)));
    if (chance(r, 50))
        kv_num(&g, in, "progress_every", "%g", 2.0);
    fz_printf(b, "};\n");
    fz_printf(b, "coupling = {\n");
    kv_num(&g, in, "dt", "%.6g", 1e-6 * (1 + fz_below(r, 50)));
    if (chance(r, 60))
        kv_int(&g, in, "exchange_every", 1 + fz_below(r, 10));
    if (chance(r, 40))
        kv_num(&g, in, "stall_timeout", "%g", 1.0);
    if (chance(r, 40))
        kv_num(&g, in, "connect_timeout", "%g", 120.0);
    fz_printf(b, "};\n");
    fz_printf(b, "wheel = {\n");
    int fixed = chance(r, 25);
    if (fixed || chance(r, 30))
        kv_str(&g, in, "motion", fixed ? "fixed" : "sink_travel");
    double c[3] = {0.3, 0.5, 0.45};
    kv_vec(&g, in, "center", c, 3, "%.3f");
    if (fixed) {
        if (chance(r, 50))
            kv_num(&g, in, "radius", "%g", 0.272);
    } else {
        kv_num(&g, in, "radius", "%g", 0.272);
        if (chance(r, 50))
            kv_num(&g, in, "start_gap", "%g", 0.005);
        if (chance(r, 50))
            kv_num(&g, in, "sink_velocity", "%g", 0.1);
        if (chance(r, 30))
            kv_num(&g, in, "approach_velocity", "%g", 0.5);
        kv_num(&g, in, "target_load", "%g", 1500.0);
        if (chance(r, 40))
            kv_num(&g, in, "max_sink", "%g", 0.2);
        if (chance(r, 60))
            kv_num(&g, in, "slip", "%g", 0.05 * (double)fz_below(r, 5));
        if (chance(r, 60))
            kv_num(&g, in, "omega", "%g", 2.0);
        if (chance(r, 60))
            kv_num(&g, in, "travel_distance", "%g", 0.5);
    }
    fz_printf(b, "};\n");
    if (chance(r, 60))
        fz_printf(b, "dem = { grains = { radius = 0.005; }; bed = { depth = 0.1; }; };\n");
    fz_printf(b, "fem = {\n  mesh = {\n");
    const char *in2 = "    ";
    int type = (int)fz_below(r, 3);
    if (type == 0) {
        kv_str(&g, in2, "type", "tire");
        if (chance(r, 60))
            kv_num(&g, in2, "resolution", "%g", 0.25);
        if (chance(r, 40))
            kv_num(&g, in2, "outer_radius", "%g", 0.272);
        if (chance(r, 40))
            kv_num(&g, in2, "rim_radius", "%g", 0.1651);
        if (chance(r, 40))
            kv_num(&g, in2, "width", "%g", 0.165);
        if (chance(r, 40))
            kv_num(&g, in2, "wall", "%g", 0.016);
        if (chance(r, 40))
            kv_num(&g, in2, "lug_depth", "%g", 0.015);
        if (chance(r, 40))
            kv_num(&g, in2, "shoulder_radius", "%g", 0.025);
        if (chance(r, 40))
            kv_int(&g, in2, "lugs", 16);
        if (chance(r, 40))
            kv_num(&g, in2, "lug_fraction", "%g", 0.5);
        if (chance(r, 40))
            kv_num(&g, in2, "contact_depth", "%g", 0.06);
    } else if (type == 1) {
        kv_str(&g, in2, "type", "gmsh");
        kv_str(&g, in2, "file", chance(r, 50) ? "tire.msh" : "meshes/cube.msh");
    } else {
        kv_str(&g, in2, "type", "box");
        double sz[3] = {1.0, 0.1, 0.1}, cells[3] = {1.0 + fz_below(r, 4), 1, 1};
        kv_vec(&g, in2, "size", sz, 3, "%#.17g");
        kv_vec(&g, in2, "cells", cells, 3, chance(r, 50) ? "%g" : "%.1f");
    }
    fz_printf(b, "  };\n  material = {\n");
    kv_num(&g, in2, "E", "%g", 20e6);
    kv_num(&g, in2, "nu", "%g", 0.45);
    kv_num(&g, in2, "rho", "%g", 1100.0);
    if (chance(r, 40))
        kv_num(&g, in2, "rayleigh_alpha", "%g", 0.0);
    if (chance(r, 40))
        kv_num(&g, in2, "rayleigh_beta", "%g", 1e-5);
    fz_printf(b, "  };\n");
    static const char *const integ[] = {"explicit", "newmark", "rigid"};
    kv_str(&g, in, "integrator", integ[fz_below(r, 3)]);
    kv_num(&g, in, "dt", "%g", 1e-5);
    if (chance(r, 40))
        kv_bool(&g, in, "allow_unstable", (int)fz_below(r, 2));
    if (chance(r, 40))
        kv_str(&g, in, "static_solver", chance(r, 50) ? "cg" : "cholmod");
    if (chance(r, 30))
        kv_num(&g, in, "cg_tol", "%g", 1e-10);
    if (chance(r, 30))
        kv_int(&g, in, "cg_max_iter", 0);
    if (chance(r, 40))
        kv_num(&g, in, "pressure", "%g", 0.14e6);
    if (chance(r, 50)) {
        double gr[3] = {0.0, 0.0, -9.81};
        kv_vec(&g, in, "gravity", gr, 3, "%.2f");
    }
    if (chance(r, 30))
        kv_int(&g, in, "power_iterations", 300);
    if (chance(r, 40)) {
        fz_printf(b, "  output = {\n");
        kv_str(&g, in2, "dir", "out/fem");
        kv_int(&g, in2, "every", 100);
        fz_printf(b, "  };\n");
    }
    fz_printf(b, "};\n");
}

static void scene_mutate(fz_rng *r, fz_buf *b, toks *tk, int n_mut, char *what, size_t wl)
{
    /* token mutations first (they rely on the recorded offsets) */
    pick picks[8];
    int np = 0, n_text = 0;
    for (int m = 0; m < n_mut; m++) {
        unsigned kind = fz_below(r, 10);
        if (kind >= 6 || np == 8) {
            n_text++;
            continue;
        }
        pick *p = &picks[np];
        p->rep = NULL;
        p->own[0] = 0;
        if (kind <= 2) { /* a number -> boundary value */
            if (!pick_token(r, tk, TK_NUM, &p->t))
                continue;
            p->rep = k_num_pool[fz_below(r, NUM_POOL)];
            note(what, wl, "num@%zu=%s", p->t.at, p->rep);
        } else if (kind == 3) { /* a value -> another type */
            if (!pick_token(r, tk, TK_VALUE, &p->t))
                continue;
            p->rep = k_value_pool[fz_below(r, VALUE_POOL)];
            note(what, wl, "value@%zu=%s", p->t.at, p->rep);
        } else if (kind == 4) { /* a string -> long or odd string */
            if (!pick_token(r, tk, TK_STR, &p->t))
                continue;
            size_t len = fz_below(r, 4) == 0 ? 600 + fz_below(r, 1500) : fz_below(r, 8);
            p->own[0] = '"';
            for (size_t i = 0; i < len && i + 3 < sizeof p->own; i++)
                p->own[i + 1] = (char)('a' + fz_below(r, 26));
            size_t l = strlen(p->own);
            p->own[l] = '"';
            p->own[l + 1] = 0;
            note(what, wl, "string@%zu(len %zu)", p->t.at, len);
        } else { /* unknown key, inserted after a recorded value's line */
            if (!pick_token(r, tk, TK_VALUE, &p->t))
                continue;
            static const char *const keys[] = {"dept = 1.0;", "radiuss = 0.2;", "Type = \"box\";",
                                               "extra = { a = 1; };", "E = 1.0;", "mesh = 1;", "list = ();",
                                               "arr = [];", "grp = {};"};
            /* insert at the start of the value's line: same section */
            size_t s = p->t.at;
            while (s > 0 && b->p[s - 1] != '\n')
                s--;
            p->t.len = 0;
            p->t.at = s;
            snprintf(p->own, sizeof p->own, "%s\n", keys[fz_below(r, sizeof keys / sizeof *keys)]);
            note(what, wl, "key@%zu:%s", s, p->own);
        }
        np++;
    }
    apply_picks(b, picks, np);
    if (n_mut > 0 && fz_below(r, 40) == 0) { /* deep nesting in place of the whole text's tail */
        int depth = 50 + (int)fz_below(r, 3000);
        fz_buf d = {0};
        fz_printf(&d, "deep = ");
        for (int i = 0; i < depth; i++)
            fz_printf(&d, "{ a = ");
        fz_printf(&d, "1");
        for (int i = 0; i < depth; i++)
            fz_printf(&d, "; }");
        fz_printf(&d, ";\n");
        splice(b, b->n, 0, d.p, d.n);
        fz_buf_free(&d);
        note(what, wl, "nesting %d", depth);
    }
    for (int m = 0; m < n_text; m++)
        textual(r, b, what, wl, 0);
}

static int mutations_for(fz_rng *r, uint64_t index)
{
    if (index % 32 == 0)
        return 0;
    return 1 + (int)fz_below(r, 4) / 2 + (fz_below(r, 4) == 0); /* 1..3, mostly 1-2 */
}

int fz_scene_case(uint64_t index, fz_buf *out, char *what, size_t wl)
{
    static toks tk;
    fz_rng r = fz_rng_seed(FZ_KIND_SCENE, index);
    if (what && wl)
        what[0] = 0;
    clear(out);
    tk.n = 0;
    scene_seed(&r, out, &tk);
    int n_mut = mutations_for(&r, index);
    scene_mutate(&r, out, &tk, n_mut, what, wl);
    return n_mut;
}

/* ---- Gmsh meshes ------------------------------------------------------------- */

enum { GM_MAXN = 96, GM_MAXT = 320, GM_MAXF = 512 };

typedef struct gmesh {
    int nn;
    double x[3 * GM_MAXN];
    long tag[GM_MAXN];
    int nt;
    int tet[GM_MAXT][4];
    int nf;
    int tri[GM_MAXF][3];
    int grp[GM_MAXF]; /* surface entity: 1 rim, 2 cavity, 3 contact, 4 other */
    double lo[3], hi[3];
} gmesh;

static double tet_volume(const gmesh *m, const int *t)
{
    const double *a = &m->x[3 * t[0]], *b = &m->x[3 * t[1]], *c = &m->x[3 * t[2]], *d = &m->x[3 * t[3]];
    double u[3], v[3], w[3];
    for (int k = 0; k < 3; k++) {
        u[k] = b[k] - a[k];
        v[k] = c[k] - a[k];
        w[k] = d[k] - a[k];
    }
    return (u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
            u[2] * (v[0] * w[1] - v[1] * w[0])) / 6.0;
}

/* Box of nx*ny*nz cells, Kuhn split (6 tets a cell), sheared and scaled by a
 * map with positive determinant; boundary faces outward, grouped by plane:
 * x = 0 rim, z = 0 cavity, z = top contact, the rest "other". */
static void gmesh_box(fz_rng *r, gmesh *m)
{
    int nx = 1 + (int)fz_below(r, 3), ny = 1 + (int)fz_below(r, 2), nz = 1 + (int)fz_below(r, 2);
    double L[3] = {0.1 + 0.1 * fz_below(r, 20), 0.1 + 0.1 * fz_below(r, 10), 0.05 + 0.05 * fz_below(r, 10)};
    double shear = 0.1 * (double)fz_below(r, 5), off[3] = {(double)fz_below(r, 3) - 1.0, 0.5, -2.0};
    memset(m, 0, sizeof *m);
    m->nn = (nx + 1) * (ny + 1) * (nz + 1);
    for (int k = 0; k <= nz; k++)
        for (int j = 0; j <= ny; j++)
            for (int i = 0; i <= nx; i++) {
                int n = (k * (ny + 1) + j) * (nx + 1) + i;
                double X = L[0] * i / nx, Y = L[1] * j / ny, Z = L[2] * k / nz;
                m->x[3 * n] = off[0] + X + shear * Z;
                m->x[3 * n + 1] = off[1] + Y;
                m->x[3 * n + 2] = off[2] + Z;
            }
    static const int perm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++)
            for (int i = 0; i < nx; i++)
                for (int p = 0; p < 6; p++) {
                    int c[3] = {i, j, k}, *t = m->tet[m->nt++];
                    t[0] = (c[2] * (ny + 1) + c[1]) * (nx + 1) + c[0];
                    for (int s = 0; s < 3; s++) {
                        c[perm[p][s]]++;
                        t[s + 1] = (c[2] * (ny + 1) + c[1]) * (nx + 1) + c[0];
                    }
                    if (tet_volume(m, t) < 0) {
                        int q = t[2];
                        t[2] = t[3];
                        t[3] = q;
                    }
                }
    /* boundary: faces of exactly one tet (quadratic search: tiny meshes) */
    static const int fl[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
    for (int e = 0; e < m->nt; e++)
        for (int f = 0; f < 4; f++) {
            int a = m->tet[e][fl[f][0]], b = m->tet[e][fl[f][1]], c = m->tet[e][fl[f][2]], shared = 0;
            for (int e2 = 0; e2 < m->nt && !shared; e2++) {
                if (e2 == e)
                    continue;
                int hit = 0;
                for (int q = 0; q < 4; q++)
                    hit += m->tet[e2][q] == a || m->tet[e2][q] == b || m->tet[e2][q] == c;
                shared = hit == 3;
            }
            if (shared)
                continue;
            int *t = m->tri[m->nf];
            t[0] = a;
            t[1] = b;
            t[2] = c;
            /* plane from the grid indices */
            int ia = a % (nx + 1), ib = b % (nx + 1), ic = c % (nx + 1);
            int ka = a / ((nx + 1) * (ny + 1)), kb = b / ((nx + 1) * (ny + 1)), kc = c / ((nx + 1) * (ny + 1));
            m->grp[m->nf] = (ia == 0 && ib == 0 && ic == 0)      ? 1
                            : (ka == 0 && kb == 0 && kc == 0)    ? 2
                            : (ka == nz && kb == nz && kc == nz) ? 3
                                                                 : 4;
            m->nf++;
        }
}

typedef struct gm_opts gm_opts;
static void gm_assign_tags(gmesh *m, const gm_opts *o);

struct gm_opts {
    long tag0, tag_step;  /* node tags tag0 + i*step (shuffled order optional) */
    int shuffle;
    int node_blocks;      /* 1..3 */
    int phys;             /* 0 all four names; 1 no rim; 2 "rimm"; 3 no section; 4 rim as a volume group;
                             5 no contact; 6 unterminated name; 7 name with spaces */
    int comments;         /* an unknown section ($Comments) */
    int points;           /* element blocks of points (type 15) and lines (type 1) too */
    int dup_section;      /* 0 none, 1 $PhysicalNames, 2 $Entities, 3 $Nodes, 4 $Elements */
    int drop_section;     /* 0 none, 1 $PhysicalNames, 2 $Entities, 3 $Nodes, 4 $Elements, 5 $MeshFormat */
    int parametric;       /* a node block with parametric = 1 */
    int bad_type;         /* a block of element type 99 / 11 / 0 */
    int tet_blocks;       /* tets split over 1..2 blocks */
    int rim_points;       /* rim given as a group of points (dim 0) instead of faces */
};

/* Node tags tag0 + i * step, saturating instead of overflowing. */
static void gm_assign_tags(gmesh *m, const gm_opts *o)
{
    long tag = o->tag0;
    for (int i = 0; i < m->nn; i++) {
        m->tag[i] = tag;
        tag = tag > 9223372036854775807L - o->tag_step ? tag : tag + o->tag_step;
    }
}

static void gm_physnames(fz_buf *b, toks *tk, const gm_opts *o)
{
    if (o->phys == 3)
        return;
    const char *rim = o->phys == 2 ? "rimm" : o->phys == 7 ? "r i m" : "rim";
    int n = 4 - (o->phys == 1) - (o->phys == 5);
    fz_printf(b, "$PhysicalNames\n");
    emit(b, tk, TK_COUNT, "%d", n);
    fz_printf(b, "\n");
    if (o->phys != 1) {
        emit(b, tk, TK_KIND, "%d", o->rim_points ? 0 : o->phys == 4 ? 3 : 2);
        fz_printf(b, " ");
        emit(b, tk, TK_TAG, "%d", 1);
        fz_printf(b, o->phys == 6 ? " \"%s\n" : " \"%s\"\n", rim);
    }
    fz_printf(b, "2 2 \"cavity\"\n");
    if (o->phys != 5)
        fz_printf(b, "2 3 \"contact\"\n");
    fz_printf(b, "3 4 \"tire\"\n$EndPhysicalNames\n");
}

static void gm_entities(fz_buf *b, toks *tk, const gmesh *m, const gm_opts *o)
{
    fz_printf(b, "$Entities\n");
    emit(b, tk, TK_COUNT, "%d", o->rim_points ? 1 : 0);
    fz_printf(b, " ");
    emit(b, tk, TK_COUNT, "%d", 0);
    fz_printf(b, " ");
    emit(b, tk, TK_COUNT, "%d", 4);
    fz_printf(b, " ");
    emit(b, tk, TK_COUNT, "%d", 1);
    fz_printf(b, "\n");
    if (o->rim_points) {
        emit(b, tk, TK_TAG, "%d", 1);
        fz_printf(b, " %g %g %g 1 ", m->lo[0], m->lo[1], m->lo[2]);
        emit(b, tk, TK_TAG, "%d", 1);
        fz_printf(b, "\n");
    }
    for (int s = 1; s <= 4; s++) {
        emit(b, tk, TK_TAG, "%d", s);
        fz_printf(b, " ");
        emit(b, tk, TK_COORD, "%g", m->lo[0]);
        fz_printf(b, " %g %g %g %g ", m->lo[1], m->lo[2], m->hi[0], m->hi[1]);
        emit(b, tk, TK_COORD, "%g", m->hi[2]);
        int has = s < 4 && !(s == 1 && o->rim_points);
        fz_printf(b, " ");
        emit(b, tk, TK_COUNT, "%d", has);
        if (has) {
            fz_printf(b, " ");
            emit(b, tk, TK_TAG, "%d", s == 1 ? 1 : s == 2 ? 2 : 3);
        }
        fz_printf(b, " ");
        emit(b, tk, TK_COUNT, "%d", 0);
        fz_printf(b, "\n");
    }
    fz_printf(b, "1 %g %g %g %g %g %g 1 ", m->lo[0], m->lo[1], m->lo[2], m->hi[0], m->hi[1], m->hi[2]);
    emit(b, tk, TK_TAG, "%d", o->phys == 4 ? 1 : 4);
    fz_printf(b, " 4 1 2 3 4\n$EndEntities\n");
}

static void gm_nodes(fz_buf *b, toks *tk, const gmesh *m, const gm_opts *o, const int *order)
{
    long mn = m->tag[0], mx = m->tag[0];
    for (int i = 0; i < m->nn; i++) {
        mn = m->tag[i] < mn ? m->tag[i] : mn;
        mx = m->tag[i] > mx ? m->tag[i] : mx;
    }
    fz_printf(b, "$Nodes\n");
    emit(b, tk, TK_COUNT, "%d", o->node_blocks);
    fz_printf(b, " ");
    emit(b, tk, TK_COUNT, "%d", m->nn);
    fz_printf(b, " ");
    emit(b, tk, TK_COUNT, "%ld", mn);
    fz_printf(b, " ");
    emit(b, tk, TK_COUNT, "%ld", mx);
    fz_printf(b, "\n");
    int per = (m->nn + o->node_blocks - 1) / o->node_blocks;
    for (int bl = 0, first = 0; bl < o->node_blocks; bl++) {
        int n = m->nn - first < per ? m->nn - first : per;
        emit(b, tk, TK_KIND, "%d", 3);
        fz_printf(b, " ");
        emit(b, tk, TK_TAG, "%d", 1);
        fz_printf(b, " ");
        emit(b, tk, TK_KIND, "%d", o->parametric && bl == 0);
        fz_printf(b, " ");
        emit(b, tk, TK_COUNT, "%d", n);
        fz_printf(b, "\n");
        for (int i = 0; i < n; i++) {
            emit(b, tk, TK_TAG, "%ld", m->tag[order[first + i]]);
            fz_printf(b, "\n");
        }
        for (int i = 0; i < n; i++) {
            const double *x = &m->x[3 * order[first + i]];
            for (int a = 0; a < 3; a++) {
                emit(b, tk, TK_COORD, "%.17g", x[a]);
                fz_printf(b, a < 2 ? " " : "\n");
            }
        }
        first += n;
    }
    fz_printf(b, "$EndNodes\n");
}

static void gm_elements(fz_rng *r, fz_buf *b, toks *tk, const gmesh *m, const gm_opts *o)
{
    int count[5] = {0};
    for (int f = 0; f < m->nf; f++)
        count[m->grp[f]]++;
    int blocks = o->tet_blocks + (o->points ? 2 : 0) + (o->bad_type ? 1 : 0) + (o->rim_points ? 1 : 0);
    int ne = m->nt + (o->points ? 2 : 0) + (o->bad_type ? 1 : 0) + (o->rim_points ? 1 : 0);
    for (int s = 1; s <= 4; s++)
        if (count[s] && !(s == 1 && o->rim_points))
            blocks++, ne += count[s];
    fz_printf(b, "$Elements\n");
    emit(b, tk, TK_COUNT, "%d", blocks);
    fz_printf(b, " ");
    emit(b, tk, TK_COUNT, "%d", ne);
    fz_printf(b, " 1 ");
    emit(b, tk, TK_COUNT, "%d", ne);
    fz_printf(b, "\n");
    long id = 1;
    if (o->rim_points) { /* one point element on the rim plane: only that node is fixed */
        fz_printf(b, "0 1 15 1\n");
        emit(b, tk, TK_TAG, "%ld", id++);
        fz_printf(b, " ");
        emit(b, tk, TK_REF, "%ld", m->tag[0]);
        fz_printf(b, "\n");
    }
    for (int s = 1; s <= 4; s++) {
        if (!count[s] || (s == 1 && o->rim_points))
            continue;
        emit(b, tk, TK_KIND, "%d", 2);
        fz_printf(b, " ");
        emit(b, tk, TK_TAG, "%d", s);
        fz_printf(b, " ");
        emit(b, tk, TK_KIND, "%d", 2);
        fz_printf(b, " ");
        emit(b, tk, TK_COUNT, "%d", count[s]);
        fz_printf(b, "\n");
        for (int f = 0; f < m->nf; f++)
            if (m->grp[f] == s) {
                emit(b, tk, TK_TAG, "%ld", id++);
                for (int q = 0; q < 3; q++) {
                    fz_printf(b, " ");
                    emit(b, tk, TK_REF, "%ld", m->tag[m->tri[f][q]]);
                }
                fz_printf(b, "\n");
            }
    }
    if (o->points) {
        fz_printf(b, "0 7 15 1\n%ld %ld\n", id, m->tag[0]);
        id++;
        fz_printf(b, "1 9 1 1\n%ld %ld %ld\n", id, m->tag[0], m->tag[1]);
        id++;
    }
    if (o->bad_type) {
        static const int types[] = {99, 11, 0, -4, 3};
        int ty = types[fz_below(r, 5)];
        fz_printf(b, "3 1 %d 1\n%ld", ty, id++);
        for (int q = 0; q < 4; q++)
            fz_printf(b, " %ld", m->tag[m->tet[0][q]]);
        fz_printf(b, "\n");
    }
    int per = (m->nt + o->tet_blocks - 1) / o->tet_blocks;
    for (int bl = 0, first = 0; bl < o->tet_blocks; bl++) {
        int n = m->nt - first < per ? m->nt - first : per;
        emit(b, tk, TK_KIND, "%d", 3);
        fz_printf(b, " ");
        emit(b, tk, TK_TAG, "%d", 1);
        fz_printf(b, " ");
        emit(b, tk, TK_KIND, "%d", 4);
        fz_printf(b, " ");
        emit(b, tk, TK_COUNT, "%d", n);
        fz_printf(b, "\n");
        for (int e = first; e < first + n; e++) {
            emit(b, tk, TK_TAG, "%ld", id++);
            for (int q = 0; q < 4; q++) {
                fz_printf(b, " ");
                emit(b, tk, TK_REF, "%ld", m->tag[m->tet[e][q]]);
            }
            fz_printf(b, "\n");
        }
        first += n;
    }
    fz_printf(b, "$EndElements\n");
}

/* Structural mutations of the mesh itself, before it is written. */
static void gm_structural(fz_rng *r, gmesh *m, gm_opts *o, char *what, size_t wl)
{
    int e = (int)fz_below(r, (uint32_t)m->nt);
    switch (fz_below(r, 16)) {
    case 0: { /* duplicate node tag */
        int i = (int)fz_below(r, (uint32_t)m->nn), j = (int)fz_below(r, (uint32_t)m->nn);
        if (i == j)
            j = (i + 1) % m->nn;
        m->tag[j] = m->tag[i];
        note(what, wl, "dup-node-tag %ld", m->tag[i]);
        break;
    }
    case 1: { /* non-finite or huge coordinate */
        static const double v[] = {NAN, INFINITY, -INFINITY, 1e308, -1e308, 1e200, 1e-310};
        int i = (int)fz_below(r, (uint32_t)(3 * m->nn));
        m->x[i] = v[fz_below(r, sizeof v / sizeof *v)];
        note(what, wl, "coord[%d]=%g", i, m->x[i]);
        break;
    }
    case 2: { /* zero volume: a repeated node */
        int a = (int)fz_below(r, 4), b2 = (a + 1 + (int)fz_below(r, 3)) % 4;
        m->tet[e][b2] = m->tet[e][a];
        note(what, wl, "tet %d repeats a node", e);
        break;
    }
    case 3: { /* zero volume: a node moved into the plane of the other three (duplicate position) */
        int a = m->tet[e][fz_below(r, 4)], b2 = m->tet[e][0] == a ? m->tet[e][1] : m->tet[e][0];
        memcpy(&m->x[3 * a], &m->x[3 * b2], 3 * sizeof(double));
        note(what, wl, "node %d moved onto node %d", a, b2);
        break;
    }
    case 4: { /* zero volume: coplanar */
        int *t = m->tet[e];
        for (int k = 0; k < 3; k++)
            m->x[3 * t[3] + k] = (m->x[3 * t[0] + k] + m->x[3 * t[1] + k] + m->x[3 * t[2] + k]) / 3.0;
        note(what, wl, "tet %d flattened", e);
        break;
    }
    case 5: { /* inverted tet */
        int q = m->tet[e][0];
        m->tet[e][0] = m->tet[e][1];
        m->tet[e][1] = q;
        note(what, wl, "tet %d inverted", e);
        break;
    }
    case 6: /* missing physical group or bad name */
        o->phys = 1 + (int)fz_below(r, 7);
        note(what, wl, "physnames mode %d", o->phys);
        break;
    case 7: { /* a named triangle that is not a boundary face */
        int f = (int)fz_below(r, (uint32_t)m->nf);
        if (m->grp[f] == 4)
            m->grp[f] = 2 + (int)fz_below(r, 2);
        static const int fl[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
        int k = (int)fz_below(r, 4);
        for (int q = 0; q < 3; q++)
            m->tri[f][q] = fz_below(r, 2) ? m->tet[e][fl[k][q]] : (int)fz_below(r, (uint32_t)m->nn);
        note(what, wl, "triangle %d moved", f);
        break;
    }
    case 8: /* duplicated tet */
        if (m->nt < GM_MAXT) {
            memcpy(m->tet[m->nt], m->tet[e], sizeof m->tet[e]);
            m->nt++;
            note(what, wl, "tet %d duplicated", e);
        }
        break;
    case 9: /* an orphan node */
        if (m->nn < GM_MAXN) {
            m->x[3 * m->nn] = 7.0;
            m->x[3 * m->nn + 1] = 7.0;
            m->x[3 * m->nn + 2] = 7.0;
            m->tag[m->nn] = m->tag[m->nn - 1] + 1;
            m->nn++;
            note(what, wl, "orphan node");
        }
        break;
    case 10:
        o->dup_section = 1 + (int)fz_below(r, 4);
        note(what, wl, "section %d repeated", o->dup_section);
        break;
    case 11:
        o->drop_section = 1 + (int)fz_below(r, 5);
        note(what, wl, "section %d dropped", o->drop_section);
        break;
    case 12:
        o->parametric = 1;
        note(what, wl, "parametric nodes");
        break;
    case 13:
        o->bad_type = 1;
        note(what, wl, "element of another type");
        break;
    case 14: { /* node tags far apart (sparse tag range) or negative/zero */
        static const long t0[] = {0, -1, -5, 1000000, 2147483647, 9223372036854775000L};
        o->tag0 = t0[fz_below(r, sizeof t0 / sizeof *t0)];
        o->tag_step = fz_below(r, 2) ? 1 : 100000;
        gm_assign_tags(m, o);
        note(what, wl, "tags from %ld step %ld", o->tag0, o->tag_step);
        break;
    }
    default: { /* a tet referring to a node of no element (extra node moved far) */
        int *t = m->tet[e];
        int k = (int)fz_below(r, 4);
        m->x[3 * t[k] + fz_below(r, 3)] += 1e3;
        note(what, wl, "tet %d stretched", e);
        break;
    }
    }
}

static void gm_write(fz_rng *r, fz_buf *b, toks *tk, gmesh *m, gm_opts *o)
{
    for (int a = 0; a < 3; a++) {
        m->lo[a] = INFINITY;
        m->hi[a] = -INFINITY;
    }
    for (int i = 0; i < m->nn; i++)
        for (int a = 0; a < 3; a++) {
            double v = m->x[3 * i + a];
            if (isfinite(v)) {
                m->lo[a] = v < m->lo[a] ? v : m->lo[a];
                m->hi[a] = v > m->hi[a] ? v : m->hi[a];
            }
        }
    int order[GM_MAXN];
    for (int i = 0; i < m->nn; i++)
        order[i] = i;
    if (o->shuffle)
        for (int i = m->nn - 1; i > 0; i--) {
            int j = (int)fz_below(r, (uint32_t)i + 1), q = order[i];
            order[i] = order[j];
            order[j] = q;
        }
    if (o->drop_section != 5)
        fz_printf(b, "$MeshFormat\n%s 0 8\n$EndMeshFormat\n", "4.1");
    for (int sec = 1; sec <= 4; sec++) {
        if (o->comments && sec == 2)
            fz_printf(b, "$Comments\nthis mesh was generated by tests/fuzz\n$EndComments\n");
        for (int rep = 0; rep < (o->dup_section == sec ? 2 : 1); rep++) {
            if (o->drop_section == sec)
                continue;
            switch (sec) {
            case 1: gm_physnames(b, tk, o); break;
            case 2: gm_entities(b, tk, m, o); break;
            case 3: gm_nodes(b, tk, m, o, order); break;
            default: gm_elements(r, b, tk, m, o); break;
            }
        }
    }
}

static void gm_tokens(fz_rng *r, fz_buf *b, const toks *tk, int n, char *what, size_t wl)
{
    static const char *const counts[] = {"0", "-1", "1", "2147483648", "2147483647", "4294967296", "100000000",
                                         "99999999", "9223372036854775807", "-9223372036854775808", "3", "1000"};
    pick picks[8];
    int np = 0;
    for (int k = 0; k < n && np < 8; k++) {
        int cls = (int)fz_below(r, 5); /* TK_COUNT .. TK_KIND */
        pick *p = &picks[np];
        p->rep = NULL;
        if (!pick_token(r, tk, cls, &p->t))
            continue;
        if (cls == TK_COUNT && fz_below(r, 3)) {
            if (fz_below(r, 2)) { /* off by one */
                long v = strtol(b->p + p->t.at, NULL, 10);
                snprintf(p->own, sizeof p->own, "%ld", v + (fz_below(r, 2) ? 1 : -1));
            } else {
                p->rep = counts[fz_below(r, sizeof counts / sizeof *counts)];
            }
        } else {
            p->rep = k_num_pool[fz_below(r, NUM_POOL)];
        }
        note(what, wl, "tok%d@%zu=%s", cls, p->t.at, p->rep ? p->rep : p->own);
        np++;
    }
    apply_picks(b, picks, np);
}

int fz_gmsh_case(uint64_t index, fz_buf *out, char *what, size_t wl)
{
    static toks tk;
    static gmesh m;
    fz_rng r = fz_rng_seed(FZ_KIND_GMSH, index);
    if (what && wl)
        what[0] = 0;
    clear(out);
    tk.n = 0;
    gmesh_box(&r, &m);
    gm_opts o = {0};
    o.tag0 = fz_below(&r, 3) == 0 ? 1 + (long)fz_below(&r, 50) : 1;
    o.tag_step = fz_below(&r, 4) == 0 ? 2 : 1;
    o.shuffle = chance(&r, 30);
    o.node_blocks = 1 + (int)fz_below(&r, 3);
    o.comments = chance(&r, 20);
    o.points = chance(&r, 20);
    o.tet_blocks = 1 + (int)fz_below(&r, 2);
    o.rim_points = chance(&r, 10);
    gm_assign_tags(&m, &o);
    int n_mut = mutations_for(&r, index);
    /* mix: structural, token and textual mutations */
    int n_struct = 0, n_tok = 0, n_text = 0;
    for (int k = 0; k < n_mut; k++) {
        unsigned c = fz_below(&r, 10);
        if (c < 4)
            n_struct++;
        else if (c < 7)
            n_tok++;
        else
            n_text++;
    }
    for (int k = 0; k < n_struct; k++)
        gm_structural(&r, &m, &o, what, wl);
    gm_write(&r, out, &tk, &m, &o);
    if (n_tok)
        gm_tokens(&r, out, &tk, n_tok, what, wl);
    for (int k = 0; k < n_text; k++)
        textual(&r, out, what, wl, 1);
    return n_mut;
}
