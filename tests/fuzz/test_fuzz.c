/* Bad input refused: scene files, Gmsh meshes and the shared-memory header,
 * fuzzed. Every case must end in a non-zero status with a message that
 * names the input (or, for a mutation that happens to leave the input
 * valid, in success) - never in a crash, a hang or an out-of-bounds access
 * (run under the ASan/UBSan build too). A per-case alarm turns a hang into
 * a failure that names the case.
 *
 *   scene_generated  SCENE_CASES scenes from fuzz_gen.c through the real readers
 *   gmsh_generated   GMSH_CASES meshes through the real .msh parser
 *   shm_header       every header field at its boundary values, plus random
 *                    combinations; a forked child attaches as the DEM
 *   shm_hello        the DEM's hello (version, dt, exchange_every) fuzzed
 *   shm_layout       ipc_layout_compute at the count limits
 *   huge_meshes      box and tire meshes too large for int indices refused
 *   corpus           tests/fuzz/corpus/: the cases that exposed bugs, plus
 *                    representatives; expectations in corpus/expect.txt
 *
 * Reproduce one generated case: test_fuzz --dump scene|gmsh INDEX > file */
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <semaphore.h>
#include <signal.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "drive.h"
#include "fem.h"
#include "fem_mesh.h"
#include "fem_model.h"
#include "fuzz_gen.h"
#include "ipc.h"
#include "log.h"
#include "runcfg.h"
#include "scene.h"
#include "segment.h"
#include "test.h"

#ifndef FUZZ_SCENE_CASES
#define FUZZ_SCENE_CASES 10000
#endif
#ifndef FUZZ_GMSH_CASES
#define FUZZ_GMSH_CASES 10000
#endif
#define FUZZ_SHM_RANDOM 60
#define CASE_TIMEOUT_S 20 /* generous: the ASan build on a busy machine */

/* libconfig 1.5 leaks its string buffer on some syntax errors (a few bytes
 * per refused scene, in a process that then exits): not ours to fix. */
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void) { return "leak:libconfig.so\n"; }

/* ---- per-case alarm ------------------------------------------------------------ */

static char g_case[160];

static void on_alarm(int sig)
{
    (void)sig;
    static const char msg[] = "\nHANG: no answer within the per-case timeout in case ";
    ssize_t w = write(2, msg, sizeof msg - 1);
    w = write(2, g_case, strlen(g_case));
    w = write(2, "\n", 1);
    (void)w;
    _exit(124);
}

static void case_begin(const char *kind, unsigned long long index)
{
    snprintf(g_case, sizeof g_case, "%s %llu", kind, index);
    alarm(CASE_TIMEOUT_S);
}

static void case_end(void) { alarm(0); }

static void install_alarm(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_alarm;
    sigaction(SIGALRM, &sa, NULL);
}

/* ---- verdicts -------------------------------------------------------------------- */

typedef struct tally {
    long accepted, refused;
    long by_code[8]; /* -rc */
} tally;

/* A refusal must carry a negative code and a message naming the input. */
static int check_refusal(int rc, const cm_error *err, const char *name, const char *what)
{
    if (rc >= 0) {
        fprintf(stderr, "%s: positive status %d (%s)\n", g_case, rc, what);
        return 1;
    }
    if (!err->msg[0]) {
        fprintf(stderr, "%s: status %d with an empty message (%s)\n", g_case, rc, what);
        return 1;
    }
    if (name && !strstr(err->msg, name)) {
        fprintf(stderr, "%s: message does not name the input %s: \"%s\" (%s)\n", g_case, name, err->msg, what);
        return 1;
    }
    return 0;
}

/* ---- scenes ---------------------------------------------------------------------- */

/* Everything fem_server does with a scene before it builds the model, then
 * the box mesh when it is small. rc 0 accepted. */
static int scene_pipeline(cm_scene *s, cm_error *err)
{
    cm_run_config rcfg;
    drive_def drive = drive_def_default();
    fem_config cfg = fem_config_default();
    int rc;
    if ((rc = cm_run_config_read(s, &rcfg, err)) || (rc = drive_config_read(s, &drive, err)) ||
        (rc = fem_config_read(s, &cfg, err)))
        return rc;
    cm_scene_mark_known(s, "dem");
    static const char *const sections[] = {"run", "coupling", "wheel", "fem", NULL};
    if ((rc = cm_scene_check_unknown(s, sections, err)))
        return rc;
    if (!(rcfg.end_time >= 0 && rcfg.dt > 0 && rcfg.exchange_every >= 1 && cfg.dt > 0 && cfg.E > 0 &&
          isfinite(cfg.E) && cfg.rho > 0 && cfg.nu > -1 && cfg.nu < 0.5))
        return cm_fail(err, CM_ERR_STATE, "FUZZ: accepted an out-of-range value");
    if (cfg.mesh == FEM_MESH_BOX) {
        long cells = (long)cfg.box_cells[0] * cfg.box_cells[1] * cfg.box_cells[2];
        if (cells <= 64 || 6.0 * (double)cells > 1e8) { /* small, or refused at once */
            fem_mesh m;
            if ((rc = fem_mesh_box(cfg.box_size, cfg.box_cells, &m, err)))
                return rc;
            fem_mesh_free(&m);
        }
    }
    return CM_OK;
}

/* 0 pass, 1 fail; *accepted tells which way it went. */
static int scene_text_case(const char *text, const char *name, int must_accept, const char *what, tally *t)
{
    cm_scene *s = NULL;
    cm_error err = {0};
    int rc = cm_scene_open_string(text, name, &s, &err);
    if (rc == CM_OK) {
        rc = scene_pipeline(s, &err);
        cm_scene_close(&s);
    }
    if (strstr(err.msg, "FUZZ:")) {
        fprintf(stderr, "%s: %s\n", g_case, err.msg);
        return 1;
    }
    if (rc == CM_OK) {
        t->accepted++;
        return 0;
    }
    t->refused++;
    t->by_code[-rc < 8 && -rc > 0 ? -rc : 0]++;
    if (must_accept) {
        fprintf(stderr, "%s: an unmutated seed was refused: %s\n", g_case, err.msg);
        return 1;
    }
    return check_refusal(rc, &err, name, what);
}

static int scene_generated(void)
{
    fz_buf b = {0};
    tally t = {0};
    int failed = 0;
    char what[512];
    for (uint64_t i = 0; i < FUZZ_SCENE_CASES && failed < 10; i++) {
        case_begin("scene", (unsigned long long)i);
        int n_mut = fz_scene_case(i, &b, what, sizeof what);
        char name[64];
        snprintf(name, sizeof name, "fuzz-scene-%llu.cfg", (unsigned long long)i);
        failed += scene_text_case(b.p, name, n_mut == 0, what, &t);
        case_end();
    }
    fz_buf_free(&b);
    printf("scene: %d cases, %ld accepted, %ld refused (parse %ld, key %ld, range %ld, other %ld)\n",
           FUZZ_SCENE_CASES, t.accepted, t.refused, t.by_code[2], t.by_code[3], t.by_code[4],
           t.refused - t.by_code[2] - t.by_code[3] - t.by_code[4]);
    ENSURE(failed == 0);
    /* the mutations must bite, and not only at the syntax level */
    ENSURE(t.refused > FUZZ_SCENE_CASES / 2 && t.by_code[3] > 100 && t.by_code[4] > 100);
    return 0;
}

/* ---- Gmsh ------------------------------------------------------------------------ */

/* What an accepted mesh must be: finite coordinates, indices in range,
 * positive volumes, boundary faces of real nodes, and a rim. */
static int check_mesh(const fem_mesh *m)
{
    if (m->n_nodes < 4 || m->n_tets < 1 || !m->x || !m->tets)
        return fprintf(stderr, "%s: accepted an empty mesh\n", g_case), 1;
    for (int i = 0; i < 3 * m->n_nodes; i++)
        if (!isfinite(m->x[i]))
            return fprintf(stderr, "%s: accepted a non-finite coordinate (node %d)\n", g_case, i / 3), 1;
    char *used = calloc((size_t)m->n_nodes, 1);
    for (int e = 0; e < m->n_tets; e++) {
        const int32_t *t = &m->tets[4 * e];
        for (int k = 0; k < 4; k++) {
            if (t[k] < 0 || t[k] >= m->n_nodes) {
                free(used);
                return fprintf(stderr, "%s: tet %d has node %d of %d\n", g_case, e, t[k], m->n_nodes), 1;
            }
            used[t[k]] = 1;
        }
        const double *a = &m->x[3 * t[0]], *b = &m->x[3 * t[1]], *c = &m->x[3 * t[2]], *d = &m->x[3 * t[3]];
        double u[3], v[3], w[3];
        for (int k = 0; k < 3; k++)
            u[k] = b[k] - a[k], v[k] = c[k] - a[k], w[k] = d[k] - a[k];
        double V = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
                   u[2] * (v[0] * w[1] - v[1] * w[0]);
        if (!(V > 0)) {
            free(used);
            return fprintf(stderr, "%s: accepted tet %d with volume %g\n", g_case, e, V / 6), 1;
        }
    }
    int unused = 0;
    for (int i = 0; i < m->n_nodes; i++)
        unused += !used[i];
    free(used);
    if (unused)
        return fprintf(stderr, "%s: accepted %d node(s) that no tetrahedron uses (no mass, no stiffness: "
                       "the solver would divide by zero)\n", g_case, unused), 1;
    for (int f = 0; f < m->n_faces; f++)
        for (int k = 0; k < 3; k++)
            if (m->faces[3 * f + k] < 0 || m->faces[3 * f + k] >= m->n_nodes)
                return fprintf(stderr, "%s: face %d has node %d\n", g_case, f, m->faces[3 * f + k]), 1;
    int rim = 0;
    for (int i = 0; i < m->n_nodes; i++)
        rim += (m->node_tag[i] & FEM_NODE_RIM) != 0;
    if (!rim)
        return fprintf(stderr, "%s: accepted a mesh without rim nodes\n", g_case), 1;
    return 0;
}

/* The text goes in an exact-size buffer without a terminating NUL, so that
 * ASan sees any read past its end. */
static int gmsh_text_case(const char *text, size_t len, const char *name, int must_accept, const char *what,
                          tally *t)
{
    char *exact = malloc(len ? len : 1);
    memcpy(exact, text, len);
    fem_mesh m;
    cm_error err = {0};
    int rc = fem_mesh_parse_gmsh(exact, len, name, &m, &err);
    free(exact);
    if (rc == CM_OK) {
        t->accepted++;
        int bad = check_mesh(&m);
        if (bad)
            fprintf(stderr, "  (mutations: %s)\n", what);
        fem_mesh_free(&m);
        return bad;
    }
    t->refused++;
    t->by_code[-rc < 8 && -rc > 0 ? -rc : 0]++;
    if (must_accept) {
        fprintf(stderr, "%s: an unmutated seed was refused: %s\n", g_case, err.msg);
        return 1;
    }
    return check_refusal(rc, &err, name, what);
}

static int gmsh_generated(void)
{
    fz_buf b = {0};
    tally t = {0};
    int failed = 0;
    char what[512];
    for (uint64_t i = 0; i < FUZZ_GMSH_CASES && failed < 10; i++) {
        case_begin("gmsh", (unsigned long long)i);
        int n_mut = fz_gmsh_case(i, &b, what, sizeof what);
        char name[64];
        snprintf(name, sizeof name, "fuzz-%llu.msh", (unsigned long long)i);
        failed += gmsh_text_case(b.p, b.n, name, n_mut == 0, what, &t);
        case_end();
    }
    fz_buf_free(&b);
    printf("gmsh: %d cases, %ld accepted, %ld refused (parse %ld, range %ld, numeric %ld, other %ld)\n",
           FUZZ_GMSH_CASES, t.accepted, t.refused, t.by_code[2], t.by_code[4], t.by_code[6],
           t.refused - t.by_code[2] - t.by_code[4] - t.by_code[6]);
    ENSURE(failed == 0);
    ENSURE(t.refused > FUZZ_GMSH_CASES / 2 && t.by_code[6] > 100 && t.accepted > FUZZ_GMSH_CASES / 32);
    return 0;
}

/* ---- shared-memory header ---------------------------------------------------------- */

enum { SHM_NODES = 8, SHM_TRIS = 6 };

typedef struct shm_field {
    const char *name;
    size_t off;
    int bytes; /* 4 or 8 */
} shm_field;

#define FLD(f, n) {n, offsetof(ipc_segment_header, f), (int)sizeof(((ipc_segment_header *)0)->f)}
static const shm_field k_fields[] = {
    FLD(magic, "magic"),
    FLD(version, "version"),
    FLD(header_size, "header_size"),
    FLD(segment_size, "segment_size"),
    FLD(state, "state"),
    FLD(failed_role, "failed_role"),
    FLD(pid[0], "pid0"),
    FLD(pid[1], "pid_fem"),
    FLD(pid[2], "pid_dem"),
    FLD(heartbeat_ns[1], "heartbeat_fem"),
    FLD(n_nodes, "n_nodes"),
    FLD(n_tris, "n_tris"),
    FLD(ring_slots, "ring_slots"),
    FLD(flags, "flags"),
    FLD(nodes_offset, "nodes_offset"),
    FLD(tris_offset, "tris_offset"),
    FLD(ring_offset[0], "ring_offset0"),
    FLD(ring_offset[1], "ring_offset_fem"),
    FLD(ring_offset[2], "ring_offset_dem"),
    FLD(slot_size[0], "slot_size0"),
    FLD(slot_size[1], "slot_size_fem"),
    FLD(slot_size[2], "slot_size_dem"),
    FLD(payload_len[0], "payload_len0"),
    FLD(payload_len[1], "payload_len_fem"),
    FLD(payload_len[2], "payload_len_dem"),
    FLD(surface_ready, "surface_ready"),
    FLD(dem_version, "dem_version"),
    FLD(dem_exchange_every, "dem_exchange_every"),
    FLD(reserved_, "reserved"),
    FLD(dem_dt, "dem_dt"),
    FLD(fem_exchange_dt, "fem_exchange_dt"),
};
#define N_FIELDS (int)(sizeof k_fields / sizeof k_fields[0])

/* Edits: a header field set to a raw value, or a surface entry. */
enum { ED_FIELD, ED_TRI, ED_NODE, ED_REASON, ED_EXPECT_NODES };
typedef struct shm_edit {
    int kind, field; /* field index, or surface entry index */
    uint64_t value;  /* raw bits (doubles by memcpy) */
} shm_edit;

static uint64_t field_get(const ipc_segment_header *h, const shm_field *f)
{
    uint64_t v = 0;
    if (f->bytes == 4) {
        uint32_t w;
        memcpy(&w, (const char *)h + f->off, 4);
        v = w;
    } else {
        memcpy(&v, (const char *)h + f->off, 8);
    }
    return v;
}

static void field_set(ipc_segment_header *h, const shm_field *f, uint64_t v)
{
    if (f->bytes == 4) {
        uint32_t w = (uint32_t)v;
        memcpy((char *)h + f->off, &w, 4);
    } else {
        memcpy((char *)h + f->off, &v, 8);
    }
}

static uint64_t dbits(double d)
{
    uint64_t u;
    memcpy(&u, &d, 8);
    return u;
}

static volatile sig_atomic_t g_child_done;
static void on_child(int sig)
{
    (void)sig;
    g_child_done = 1;
}

/* Runs one segment: create (FEM, this process), apply the edits, fork a DEM
 * child that attaches; this process accepts until the child answers or
 * exits. Fills dem_msg / fem_msg; returns 0 when both sides agree and the
 * child ended normally (status 0 attached, 1 refused with a message). */
static int shm_run(const shm_edit *ed, int n_ed, int *attached, char *dem_msg, size_t dlen, char *fem_msg,
                   size_t flen)
{
    static int counter;
    char name[96];
    snprintf(name, sizeof name, "/demfem-fuzz-%d-%d", (int)getpid(), counter++);
    g_child_done = 0;
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = SHM_NODES;
    def.n_tris = SHM_TRIS;
    def.connect_timeout = 5;
    def.stop_flag = &g_child_done;
    ipc_channel *ch;
    char err[512];
    *attached = 0;
    dem_msg[0] = fem_msg[0] = 0;
    uint32_t expect_nodes = 0;
    for (int e = 0; e < n_ed; e++)
        if (ed[e].kind == ED_EXPECT_NODES)
            expect_nodes = (uint32_t)ed[e].value;
    /* Fork while this process has one thread (ipc_create starts a heartbeat
     * thread; a child forked after it may inherit a held allocator lock).
     * The child waits for the go byte: the segment is edited by then. */
    int pfd[2], go[2];
    if (pipe(pfd) != 0 || pipe(go) != 0)
        return fprintf(stderr, "%s: pipe: %s\n", g_case, strerror(errno)), 1;
    fflush(NULL);
    pid_t child = fork();
    if (child == 0) {
        close(pfd[0]);
        close(go[1]);
        alarm(CASE_TIMEOUT_S / 2);
        signal(SIGALRM, SIG_DFL);
        char c;
        if (read(go[0], &c, 1) != 1)
            _exit(4);
        ipc_attach_def ad = ipc_default_attach_def();
        ad.dt = 1e-5;
        ad.connect_timeout = 0.1;
        ad.expect_nodes = expect_nodes;
        ipc_channel *dem = NULL;
        char derr[512] = "";
        int rc = ipc_attach(name, &ad, &dem, derr, sizeof derr);
        if (rc == IPC_OK)
            snprintf(derr, sizeof derr, "attached");
        ssize_t w = write(pfd[1], derr, strlen(derr));
        (void)w;
        close(pfd[1]);
        ipc_close(&dem, IPC_OK);
        _exit(rc == IPC_OK ? 0 : rc < 0 ? 1 : 2);
    }
    close(pfd[1]);
    close(go[0]);
    if (ipc_create(name, &def, &ch, err, sizeof err) != IPC_OK) {
        fprintf(stderr, "%s: ipc_create: %s\n", g_case, err);
        close(go[1]);
        close(pfd[0]);
        waitpid(child, NULL, 0);
        return 1;
    }
    double *x = ipc_surface_nodes(ch);
    uint32_t *t = ipc_surface_tris(ch);
    for (int i = 0; i < 3 * SHM_NODES; i++)
        x[i] = 0.01 * i;
    for (int k = 0; k < SHM_TRIS; k++) {
        t[3 * k] = (uint32_t)k;
        t[3 * k + 1] = (uint32_t)(k + 1);
        t[3 * k + 2] = (uint32_t)(k + 2);
    }
    ipc_segment_header *h = (ipc_segment_header *)((unsigned char *)x - IPC_PAGE);
    for (int e = 0; e < n_ed; e++) {
        const shm_edit *d = &ed[e];
        switch (d->kind) {
        case ED_FIELD: field_set(h, &k_fields[d->field], d->value); break;
        case ED_TRI: t[d->field % (3 * SHM_TRIS)] = (uint32_t)d->value; break;
        case ED_NODE: memcpy(&x[d->field % (3 * SHM_NODES)], &d->value, 8); break;
        case ED_REASON: memset(h->fail_reason, 'x', sizeof h->fail_reason); break; /* no NUL */
        default: break;
        }
    }
    ssize_t gw = write(go[1], "g", 1);
    (void)gw;
    close(go[1]);
    int arc = ipc_accept(ch);
    snprintf(fem_msg, flen, "%s", arc == IPC_OK ? "accepted" : ipc_error(ch));
    size_t got = 0;
    for (;;) {
        ssize_t n = read(pfd[0], dem_msg + got, dlen - 1 - got);
        if (n <= 0)
            break;
        got += (size_t)n;
        if (got >= dlen - 1)
            break;
    }
    dem_msg[got] = 0;
    close(pfd[0]);
    int st = 0;
    while (waitpid(child, &st, 0) < 0 && errno == EINTR)
        ;
    ipc_close(&ch, arc);
    int fail = 0;
    if (!WIFEXITED(st)) {
        fprintf(stderr, "%s: the DEM child died of signal %d (%s)\n", g_case, WTERMSIG(st), dem_msg);
        fail = 1;
    } else if (WEXITSTATUS(st) == 0) {
        *attached = 1;
        if (arc != IPC_OK) {
            fprintf(stderr, "%s: DEM attached but the FEM side says: %s\n", g_case, fem_msg);
            fail = 1;
        }
    } else if (WEXITSTATUS(st) == 1) {
        if (!dem_msg[0]) {
            fprintf(stderr, "%s: DEM refused with an empty message\n", g_case);
            fail = 1;
        }
        if (arc == IPC_OK) {
            fprintf(stderr, "%s: DEM refused (%s) but the FEM side accepted\n", g_case, dem_msg);
            fail = 1;
        }
    } else {
        fprintf(stderr, "%s: DEM child exit status %d (%s)\n", g_case, WEXITSTATUS(st), dem_msg);
        fail = 1;
    }
    /* nothing left behind */
    int fd = shm_open(name, O_RDONLY, 0);
    if (fd >= 0) {
        close(fd);
        shm_unlink(name);
        fprintf(stderr, "%s: segment %s left in /dev/shm\n", g_case, name);
        fail = 1;
    }
    return fail;
}

/* Fields the attacher does not read (its own hello, padding, unused
 * indices): a few values each are enough. Each case costs ~60 ms (two
 * heartbeat threads to join), so the rest get the full list. */
static int minor_field(const shm_field *f)
{
    static const char *const minor[] = {"pid0", "ring_offset0", "slot_size0", "payload_len0", "reserved",
                                        "dem_version", "dem_exchange_every", "dem_dt", "fem_exchange_dt",
                                        "heartbeat_fem", "failed_role", "surface_ready"};
    for (size_t k = 0; k < sizeof minor / sizeof *minor; k++)
        if (!strcmp(f->name, minor[k]))
            return 1;
    return 0;
}

/* Boundary values of one field, given its valid value v, without repeats. */
static int boundary_values(const shm_field *f, uint64_t v, const ipc_segment_header *h, uint64_t *out)
{
    uint64_t all[40];
    int n = 0;
    uint64_t *keep = out;
    out = all;
    out[n++] = 0;
    out[n++] = 1;
    out[n++] = 2;
    out[n++] = v - 1;
    out[n++] = v + 1;
    out[n++] = v + 64;
    out[n++] = v + IPC_PAGE;
    out[n++] = v ^ 0x80000000u;
    out[n++] = 0x7fffffffu;
    out[n++] = 0xffffffffu;
    out[n++] = 0xfffffffeu;
    if (f->bytes == 8) {
        out[n++] = 0x100000000ull;
        out[n++] = 0x8000000000000000ull;
        out[n++] = UINT64_MAX;
        out[n++] = UINT64_MAX - IPC_PAGE + 1;
        out[n++] = dbits(NAN);
        out[n++] = dbits(INFINITY);
        out[n++] = dbits(-1.0);
        /* overlapping regions: another offset's value */
        out[n++] = h->nodes_offset;
        out[n++] = h->tris_offset;
        out[n++] = h->ring_offset[IPC_ROLE_FEM];
        out[n++] = h->ring_offset[IPC_ROLE_DEM];
        out[n++] = h->segment_size;
    } else {
        out[n++] = (uint32_t)-1 / 2 + 1;
        out[n++] = 16;
        out[n++] = 17;
        out[n++] = IPC_MAX_NODES;
        out[n++] = IPC_MAX_NODES + 1;
        out[n++] = IPC_MAX_TRIS + 1;
        out[n++] = (uint32_t)getpid();
    }
    if (minor_field(f)) {
        out[3] = UINT64_MAX;
        n = 4;
    }
    int m = 0;
    for (int i = 0; i < n; i++) {
        uint64_t w = f->bytes == 4 ? (uint32_t)all[i] : all[i];
        int dup = w == (f->bytes == 4 ? (uint32_t)v : v);
        for (int j = 0; j < m && !dup; j++)
            dup = keep[j] == w;
        if (!dup)
            keep[m++] = w;
    }
    return m;
}

static int shm_header(void)
{
    /* The valid header, to know each field's value. */
    ipc_layout lay;
    ENSURE(ipc_layout_compute(SHM_NODES, SHM_TRIS, 2, &lay) == 0);
    ipc_segment_header ref;
    memset(&ref, 0, sizeof ref);
    ref.nodes_offset = lay.nodes_offset;
    ref.tris_offset = lay.tris_offset;
    for (int r = 0; r < 3; r++) {
        ref.ring_offset[r] = lay.ring_offset[r];
        ref.slot_size[r] = lay.slot_size[r];
        ref.payload_len[r] = lay.payload_len[r];
    }
    ref.segment_size = lay.segment_size;
    ref.magic = IPC_MAGIC;
    ref.version = IPC_VERSION;
    ref.header_size = sizeof ref;
    ref.n_nodes = SHM_NODES;
    ref.n_tris = SHM_TRIS;
    ref.ring_slots = 2;
    ref.state = IPC_STATE_STARTING;

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_child;
    sigaction(SIGCHLD, &sa, NULL);
    long cases = 0, attached_n = 0, failed = 0;
    char dm[512], fm[512];
    /* 1. every field, every boundary value */
    for (int fi = 0; fi < N_FIELDS && failed < 5; fi++) {
        uint64_t vals[40];
        int nv = boundary_values(&k_fields[fi], field_get(&ref, &k_fields[fi]), &ref, vals);
        for (int k = 0; k < nv && failed < 5; k++) {
            case_begin(k_fields[fi].name, (unsigned long long)k);
            shm_edit e = {ED_FIELD, fi, vals[k]};
            int att = 0;
            failed += shm_run(&e, 1, &att, dm, sizeof dm, fm, sizeof fm);
            attached_n += att;
            cases++;
            case_end();
        }
    }
    /* 2. the surface: indices out of range or repeated, non-finite nodes */
    static const struct {
        int kind, at;
        uint64_t v;
    } surf[] = {
        {ED_TRI, 0, SHM_NODES}, {ED_TRI, 4, SHM_NODES + 1}, {ED_TRI, 8, UINT32_MAX}, {ED_TRI, 1, 0x80000000u},
        {ED_TRI, 1, 0}, {ED_TRI, 2, 1}, {ED_TRI, 17, SHM_NODES - 1}, {ED_TRI, 5, 3}, {ED_TRI, 3, SHM_NODES - 1},
        {ED_NODE, 0, 0}, {ED_NODE, 23, 0}, {ED_REASON, 0, 0}, {ED_EXPECT_NODES, 0, SHM_NODES + 1},
        {ED_EXPECT_NODES, 0, SHM_NODES}, {ED_EXPECT_NODES, 0, 1},
    };
    static const double node_vals[] = {NAN, -NAN, INFINITY, -INFINITY, 1e308, 4.9e-324};
    for (size_t k = 0; k < sizeof surf / sizeof *surf && failed < 5; k++) {
        int nv = surf[k].kind == ED_NODE ? (int)(sizeof node_vals / sizeof *node_vals) : 1;
        for (int j = 0; j < nv; j++) {
            case_begin("surface", (unsigned long long)(k * 10 + (size_t)j));
            shm_edit e = {surf[k].kind, surf[k].at, surf[k].kind == ED_NODE ? dbits(node_vals[j]) : surf[k].v};
            int att = 0;
            failed += shm_run(&e, 1, &att, dm, sizeof dm, fm, sizeof fm);
            attached_n += att;
            cases++;
            case_end();
        }
    }
    /* 3. random combinations of two to four edits */
    for (int i = 0; i < FUZZ_SHM_RANDOM && failed < 5; i++) {
        fz_rng r = fz_rng_seed(7, (uint64_t)i);
        shm_edit e[4];
        int n = 2 + (int)fz_below(&r, 3);
        for (int k = 0; k < n; k++) {
            int fi = (int)fz_below(&r, N_FIELDS);
            uint64_t vals[40];
            int nv = boundary_values(&k_fields[fi], field_get(&ref, &k_fields[fi]), &ref, vals);
            e[k] = (shm_edit){ED_FIELD, fi, vals[fz_below(&r, (uint32_t)nv)]};
            if (fz_below(&r, 4) == 0)
                e[k] = (shm_edit){ED_TRI, (int)fz_below(&r, 3 * SHM_TRIS), fz_next(&r) % (2 * SHM_NODES)};
        }
        case_begin("shm-random", (unsigned long long)i);
        int att = 0;
        failed += shm_run(e, n, &att, dm, sizeof dm, fm, sizeof fm);
        attached_n += att;
        cases++;
        case_end();
    }
    /* the unedited segment attaches */
    case_begin("shm-valid", 0);
    int att = 0;
    shm_edit none = {ED_EXPECT_NODES, 0, 0};
    failed += shm_run(&none, 1, &att, dm, sizeof dm, fm, sizeof fm);
    case_end();
    signal(SIGCHLD, SIG_DFL);
    printf("shm header: %ld cases, %ld attached, %ld refused\n", cases, attached_n, cases - attached_n);
    ENSURE(failed == 0);
    ENSURE_MSG(att, "valid segment refused: %s / %s", dm, fm);
    ENSURE(cases - attached_n > cases / 2);
    return 0;
}

/* A DEM that writes whatever hello it likes; the FEM side must refuse the
 * bad ones with a reason and never hang. */
static int hello_case(uint32_t version, double dt, uint32_t every, double fem_dt, int *accepted, char *msg,
                      size_t len)
{
    static int counter;
    char name[96];
    snprintf(name, sizeof name, "/demfem-fuzzh-%d-%d", (int)getpid(), counter++);
    g_child_done = 0;
    ipc_create_def def = ipc_default_create_def();
    def.n_nodes = SHM_NODES;
    def.n_tris = 1;
    def.exchange_dt = fem_dt;
    def.connect_timeout = 5;
    def.stop_flag = &g_child_done;
    ipc_channel *ch;
    char err[512];
    if (ipc_create(name, &def, &ch, err, sizeof err) != IPC_OK)
        return fprintf(stderr, "%s: %s\n", g_case, err), 1;
    uint32_t *t = ipc_surface_tris(ch);
    t[0] = 0, t[1] = 1, t[2] = 2;
    fflush(NULL);
    pid_t child = fork();
    if (child == 0) {
        alarm(CASE_TIMEOUT_S / 2);
        signal(SIGALRM, SIG_DFL);
        int fd = shm_open(name, O_RDWR, 0);
        struct stat st;
        if (fd < 0 || fstat(fd, &st) != 0)
            _exit(3);
        ipc_segment_header *h = mmap(NULL, (size_t)st.st_size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
        close(fd);
        if (h == MAP_FAILED)
            _exit(3);
        struct timespec ts;
        clock_gettime(CLOCK_MONOTONIC, &ts);
        atomic_store(&h->heartbeat_ns[IPC_ROLE_DEM], (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec);
        atomic_store(&h->pid[IPC_ROLE_DEM], (int32_t)getpid());
        h->dem_version = version;
        h->dem_dt = dt;
        h->dem_exchange_every = every;
        sem_post(&h->sem_hello);
        clock_gettime(CLOCK_REALTIME, &ts);
        ts.tv_sec += 5;
        while (sem_timedwait(&h->sem_ack, &ts) != 0 && errno == EINTR)
            ;
        _exit(atomic_load(&h->state) == IPC_STATE_RUNNING ? 0 : 1);
    }
    int rc = ipc_accept(ch);
    snprintf(msg, len, "%s", rc == IPC_OK ? "" : ipc_error(ch));
    int st = 0;
    while (waitpid(child, &st, 0) < 0 && errno == EINTR)
        ;
    ipc_close(&ch, rc);
    *accepted = rc == IPC_OK;
    if (!WIFEXITED(st) || WEXITSTATUS(st) > 1)
        return fprintf(stderr, "%s: hostile DEM child status %d\n", g_case, st), 1;
    if ((WEXITSTATUS(st) == 0) != (rc == IPC_OK))
        return fprintf(stderr, "%s: the two sides disagree (FEM %s)\n", g_case, msg), 1;
    if (rc != IPC_OK && !msg[0])
        return fprintf(stderr, "%s: refused without a message\n", g_case), 1;
    return 0;
}

static int shm_hello(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_child;
    sigaction(SIGCHLD, &sa, NULL);
    static const uint32_t versions[] = {IPC_VERSION, 0, IPC_VERSION + 1, UINT32_MAX};
    static const double dts[] = {1e-5, 0.0, -1e-5, NAN, INFINITY, -INFINITY, 4.9e-324, 1e308};
    static const uint32_t everies[] = {1, 0, 10, UINT32_MAX};
    static const double fem_dts[] = {0.0, 1e-5};
    int failed = 0, cases = 0, acc_n = 0;
    char msg[512];
    for (size_t a = 0; a < 4; a++)
        for (size_t b = 0; b < sizeof dts / sizeof *dts; b++)
            for (size_t c = 0; c < 4; c++)
                for (size_t d = 0; d < 2; d++) {
                    if (failed >= 5 || (a && (b || c))) /* a bad version: one case per fem_dt is enough */
                        continue;
                    case_begin("hello", (unsigned long long)(((a * 8 + b) * 4 + c) * 2 + d));
                    int acc = 0;
                    failed += hello_case(versions[a], dts[b], everies[c], fem_dts[d], &acc, msg, sizeof msg);
                    /* expected: only a finite positive interval that matches (when the FEM has one) */
                    double interval = dts[b] * everies[c];
                    int want = a == 0 && dts[b] > 0 && isfinite(dts[b]) && everies[c] >= 1 &&
                               (fem_dts[d] == 0 || fabs(interval - fem_dts[d]) <= 1e-9 * fem_dts[d]);
                    if (acc != want) {
                        fprintf(stderr, "%s: hello (v%u, dt %g, every %u, fem dt %g) %s: %s\n", g_case, versions[a],
                                dts[b], everies[c], fem_dts[d], acc ? "accepted" : "refused", msg);
                        failed++;
                    }
                    acc_n += acc;
                    cases++;
                    case_end();
                }
    signal(SIGCHLD, SIG_DFL);
    printf("shm hello: %d cases, %d accepted\n", cases, acc_n);
    ENSURE(failed == 0);
    return 0;
}

static int shm_layout(void)
{
    static const uint32_t nodes[] = {0, 1, 2, 3, 1000, IPC_MAX_NODES - 1, IPC_MAX_NODES, IPC_MAX_NODES + 1,
                                     0x7fffffffu, 0x80000000u, UINT32_MAX};
    static const uint32_t tris[] = {0, 1, IPC_MAX_TRIS, IPC_MAX_TRIS + 1, UINT32_MAX};
    static const uint32_t slots[] = {0, 1, 2, 16, 17, UINT32_MAX};
    int n = 0;
    for (size_t a = 0; a < sizeof nodes / sizeof *nodes; a++)
        for (size_t b = 0; b < sizeof tris / sizeof *tris; b++)
            for (size_t c = 0; c < sizeof slots / sizeof *slots; c++) {
                ipc_layout l;
                int rc = ipc_layout_compute(nodes[a], tris[b], slots[c], &l);
                int valid = nodes[a] >= 1 && nodes[a] <= IPC_MAX_NODES && tris[b] >= 1 && tris[b] <= IPC_MAX_TRIS &&
                            slots[c] >= 1 && slots[c] <= 16;
                ENSURE_MSG((rc == 0) == valid, "%u nodes %u tris %u slots: rc %d", nodes[a], tris[b], slots[c], rc);
                n++;
                if (rc)
                    continue;
                /* regions in order, aligned, disjoint, inside the segment */
                ENSURE(l.nodes_offset >= sizeof(ipc_segment_header));
                ENSURE(l.tris_offset >= l.nodes_offset + 24ull * nodes[a]);
                ENSURE(l.ring_offset[1] >= l.tris_offset + 12ull * tris[b]);
                ENSURE(l.ring_offset[2] >= l.ring_offset[1] + l.slot_size[1] * slots[c]);
                ENSURE(l.segment_size >= l.ring_offset[2] + l.slot_size[2] * slots[c]);
                ENSURE(l.slot_size[1] >= sizeof(ipc_frame_head) + 8 * l.payload_len[1]);
                ENSURE(l.slot_size[2] >= sizeof(ipc_frame_head) + 8 * l.payload_len[2]);
                ENSURE(l.ring_offset[1] % IPC_PAGE == 0 && l.ring_offset[2] % IPC_PAGE == 0 &&
                       l.tris_offset % 64 == 0 && l.segment_size % IPC_PAGE == 0);
            }
    printf("shm layout: %d count combinations\n", n);
    return 0;
}

/* ---- meshes too large for int indices ------------------------------------------------ */

static int huge_meshes(void)
{
    case_begin("huge_meshes", 0);
    fem_mesh m;
    cm_error err = {0};
    double size[3] = {1, 1, 1};
    int cells[3] = {1000, 1000, 1000};
    ENSURE(fem_mesh_box(size, cells, &m, &err) != CM_OK);
    ENSURE_MSG(strstr(err.msg, "box mesh"), "%s", err.msg);
    int cells2[3] = {INT_MAX, 2, 2};
    ENSURE(fem_mesh_box(size, cells2, &m, &err) != CM_OK);
    fem_tire_def d = fem_tire_def_default();
    d.lugs = 1000;
    d.resolution = 16;
    ENSURE(fem_mesh_tire(&d, &m, &err) != CM_OK);
    ENSURE_MSG(strstr(err.msg, "tire mesh"), "%s", err.msg);
    case_end();
    return 0;
}

/* ---- the committed corpus -------------------------------------------------------------- */

/* A .shm corpus file: one edit a line, "field VALUE" (VALUE an integer, or
 * nan/inf/-inf for doubles), "tri INDEX VALUE", "node INDEX VALUE",
 * "reason", "expect_nodes N"; '#' starts a comment. */
static int shm_corpus_file(const char *path, int *attached, char *msg, size_t len)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return fprintf(stderr, "%s: %s\n", path, strerror(errno)), 1;
    shm_edit ed[16];
    int n = 0;
    char line[256];
    while (fgets(line, sizeof line, f) && n < 16) {
        char key[64], v1[64] = "", v2[64] = "";
        if (line[0] == '#' || sscanf(line, "%63s %63s %63s", key, v1, v2) < 1)
            continue;
        shm_edit e = {0};
        if (!strcmp(key, "tri") || !strcmp(key, "node")) {
            e.kind = key[0] == 't' ? ED_TRI : ED_NODE;
            e.field = atoi(v1);
            if (e.kind == ED_NODE)
                e.value = dbits(strtod(v2, NULL));
            else
                e.value = strtoull(v2, NULL, 0);
        } else if (!strcmp(key, "reason")) {
            e.kind = ED_REASON;
        } else if (!strcmp(key, "expect_nodes")) {
            e.kind = ED_EXPECT_NODES;
            e.value = strtoull(v1, NULL, 0);
        } else {
            int fi = -1;
            for (int k = 0; k < N_FIELDS; k++)
                if (!strcmp(key, k_fields[k].name))
                    fi = k;
            if (fi < 0) {
                fclose(f);
                return fprintf(stderr, "%s: unknown field %s\n", path, key), 1;
            }
            e.kind = ED_FIELD;
            e.field = fi;
            char *end;
            e.value = strtoull(v1, &end, 0);
            if (*end || v1[0] == '-')
                e.value = k_fields[fi].bytes == 8 ? dbits(strtod(v1, NULL)) : (uint64_t)strtoll(v1, NULL, 0);
        }
        ed[n++] = e;
    }
    fclose(f);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_child;
    sigaction(SIGCHLD, &sa, NULL);
    char fm[512];
    int rc = shm_run(ed, n, attached, msg, len, fm, sizeof fm);
    signal(SIGCHLD, SIG_DFL);
    return rc;
}

static int ends_with(const char *s, const char *suffix)
{
    size_t a = strlen(s), b = strlen(suffix);
    return a >= b && strcmp(s + a - b, suffix) == 0;
}

static int corpus(void)
{
    const char *dir = DEMFEM_FUZZ_CORPUS;
    char path[1024];
    snprintf(path, sizeof path, "%s/expect.txt", dir);
    FILE *f = fopen(path, "r");
    ENSURE_MSG(f, "%s: %s", path, strerror(errno));
    char line[1024];
    int n = 0, failed = 0;
    char listed[512][128];
    int n_listed = 0;
    while (fgets(line, sizeof line, f)) {
        char file[128], verdict[16];
        int used = 0;
        if (line[0] == '#' || sscanf(line, "%127s %15s %n", file, verdict, &used) < 2)
            continue;
        char *want = line + used;
        want[strcspn(want, "\n")] = 0;
        if (n_listed < 512)
            snprintf(listed[n_listed++], sizeof listed[0], "%s", file);
        snprintf(path, sizeof path, "%s/%s", dir, file);
        case_begin(file, 0);
        int accepted = 0, bad = 0;
        char msg[1024] = "";
        tally t = {0};
        if (ends_with(file, ".cfg")) {
            cm_scene *s = NULL;
            cm_error err = {0};
            int rc = cm_scene_open(path, &s, &err);
            if (!rc) {
                rc = scene_pipeline(s, &err);
                cm_scene_close(&s);
            }
            accepted = rc == CM_OK;
            snprintf(msg, sizeof msg, "%s", err.msg);
            if (!accepted)
                bad = check_refusal(rc, &err, file, "corpus");
        } else if (ends_with(file, ".msh")) {
            fem_mesh m;
            cm_error err = {0};
            int rc = fem_mesh_read_gmsh(path, &m, &err);
            accepted = rc == CM_OK;
            snprintf(msg, sizeof msg, "%s", err.msg);
            if (accepted) {
                bad = check_mesh(&m);
                fem_mesh_free(&m);
            } else {
                bad = check_refusal(rc, &err, file, "corpus");
            }
        } else if (ends_with(file, ".shm")) {
            bad = shm_corpus_file(path, &accepted, msg, sizeof msg);
        } else {
            fprintf(stderr, "%s: unknown corpus file type\n", file);
            bad = 1;
        }
        (void)t;
        int want_ok = strcmp(verdict, "ok") == 0;
        if (!bad && want_ok != accepted) {
            fprintf(stderr, "%s: %s, expected %s (%s)\n", file, accepted ? "accepted" : "refused", verdict, msg);
            bad = 1;
        }
        if (!bad && !want_ok && want[0] && !strstr(msg, want)) {
            fprintf(stderr, "%s: message \"%s\" lacks \"%s\"\n", file, msg, want);
            bad = 1;
        }
        case_end();
        failed += bad;
        n++;
    }
    fclose(f);
    /* every file in the folder is listed */
    DIR *d = opendir(dir);
    ENSURE(d);
    struct dirent *de;
    while ((de = readdir(d))) {
        if (de->d_name[0] == '.' || !strcmp(de->d_name, "expect.txt"))
            continue;
        int found = 0;
        for (int k = 0; k < n_listed; k++)
            found |= !strcmp(listed[k], de->d_name);
        if (!found) {
            fprintf(stderr, "corpus file %s is not listed in expect.txt\n", de->d_name);
            failed++;
        }
    }
    closedir(d);
    printf("corpus: %d files\n", n);
    ENSURE(failed == 0 && n > 0);
    return 0;
}

static const test_case tests[] = {
    {"scene_generated", scene_generated}, {"gmsh_generated", gmsh_generated}, {"shm_header", shm_header},
    {"shm_hello", shm_hello},             {"shm_layout", shm_layout},         {"huge_meshes", huge_meshes},
    {"corpus", corpus},
};

int main(int argc, char **argv)
{
    if (argc == 4 && !strcmp(argv[1], "--dump")) {
        fz_buf b = {0};
        char what[512];
        unsigned long long i = strtoull(argv[3], NULL, 10);
        if (!strcmp(argv[2], "scene"))
            fz_scene_case(i, &b, what, sizeof what);
        else
            fz_gmsh_case(i, &b, what, sizeof what);
        fwrite(b.p, 1, b.n, stdout);
        fprintf(stderr, "mutations: %s\n", what);
        fz_buf_free(&b);
        return 0;
    }
    install_alarm();
    cm_log_set_quiet(1);
    signal(SIGPIPE, SIG_IGN);
    return test_main(argc, argv, tests, TEST_COUNT(tests));
}
