/* Checkpoint and restart with real processes on a real segment
 * (tests/coupling/scenes/tire_ckpt.cfg: a small tire set down on 400
 * grains, 1000 exchanges, a checkpoint every 100).
 *
 * interrupt_resume_bit_exact: SIGTERM to fem_server, then SIGINT to
 *   dem_server, at some exchange: both checkpoint that exchange and stop;
 *   `./run --resume` ends with the final states (dem_world_hash,
 *   fem_state_hash) and result files of the uninterrupted run, bit for bit.
 * sigkill_random_step_20_trials: 20 seeded trials killing either server with
 *   SIGKILL at a random exchange: the survivor exits non-zero within 2 s
 *   naming the dead peer, /dev/shm holds no segment of the run, the killed
 *   run's HDF5 files open with every flushed row, its last checkpoint reads,
 *   and `./run --resume` ends as the uninterrupted run.
 * The servers are started directly (not through ./run) so that the test
 * knows their pids; resuming goes through ./run.
 *
 * I/O errors end a run with one clear error line, never a crash:
 * full_disk_one_error_line (RLIMIT_FSIZE in the child, SIGXFSZ ignored:
 * writes fail with EFBIG as on a full disk), output_folder_unwritable (a
 * path under a regular file: as root, permissions would not stop a write),
 * missing_mesh_file. */
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <hdf5.h>

#include "ckpt.h"
#include "proc.h"
#include "test.h"

extern char **environ;

#if !defined(DEMFEM_SOURCE_DIR) || !defined(DEMFEM_BUILD_DIR)
#error "DEMFEM_SOURCE_DIR and DEMFEM_BUILD_DIR must be defined"
#endif

#define DEM_SERVER DEMFEM_BUILD_DIR "/dem_server/dem_server"
#define FEM_SERVER DEMFEM_BUILD_DIR "/fem_server/fem_server"
#define EXCHANGES 1000 /* run.end_time / (coupling.dt * exchange_every) */
#define CKPT_EVERY 100
#ifndef KILL_TRIALS
#define KILL_TRIALS 20
#endif

static char g_dir[200], g_scene[300];

static int file_text(const char *path, char *buf, size_t cap)
{
    FILE *f = fopen(path, "r");
    size_t n = f ? fread(buf, 1, cap - 1, f) : 0;
    if (f)
        fclose(f);
    buf[n] = '\0';
    return f ? 0 : -1;
}

/* Lines of a file minus the header: the rows of a CSV. */
static long csv_rows(const char *path)
{
    FILE *f = fopen(path, "r");
    if (!f)
        return -1;
    long lines = 0;
    int c;
    while ((c = getc(f)) != EOF)
        lines += c == '\n';
    fclose(f);
    return lines - 1;
}

static int same_file(const char *a, const char *b)
{
    FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
    int same = fa && fb;
    while (same) {
        int x = getc(fa), y = getc(fb);
        if (x != y)
            same = 0;
        if (x == EOF || y == EOF)
            break;
    }
    if (fa)
        fclose(fa);
    if (fb)
        fclose(fb);
    return same;
}

static pid_t spawn(const char *const *argv, const char *log)
{
    tp_proc p;
    return tp_spawn(&p, argv, log, 0) == 0 ? p.pid : -1;
}

/* Exit status as the shell reports it, -1 on timeout (the process is killed). */
static int wait_exit(pid_t pid, double timeout_s)
{
    tp_proc p = {.pid = pid, .status = -1, .ready_fd = -1};
    if (tp_wait(&p, timeout_s) != 0) {
        tp_kill(&p);
        return -1;
    }
    return p.status;
}

typedef struct pair {
    pid_t fem, dem;
    char shm[64], out[260], fem_log[300], dem_log[300];
} pair;

/* Both servers on the test scene, with `--set set` when set is not NULL
 * (recorded in OUT/scene.sets as the launcher records it). */
static int pair_start_set(pair *p, const char *out, const char *set)
{
    static int count;
    if (strlen(out) >= sizeof p->out)
        return -1;
    snprintf(p->shm, sizeof p->shm, "/demfem-restart-%d-%d", (int)getpid(), count++);
    snprintf(p->out, sizeof p->out, "%s", out);
    snprintf(p->fem_log, sizeof p->fem_log, "%s.fem.log", out);
    snprintf(p->dem_log, sizeof p->dem_log, "%s.dem.log", out);
    mkdir(out, 0755);
    const char *fa[] = {FEM_SERVER, "--scene", g_scene, "--shm", p->shm, "--out", out, set ? "--set" : NULL, set, NULL};
    const char *da[] = {DEM_SERVER, "--scene", g_scene, "--shm", p->shm, "--out", out, set ? "--set" : NULL, set, NULL};
    if (set) {
        char path[320];
        snprintf(path, sizeof path, "%s/scene.sets", out);
        FILE *f = fopen(path, "w");
        if (!f || fprintf(f, "%s\n", set) < 0 || fclose(f) != 0)
            return -1;
    }
    p->fem = spawn(fa, p->fem_log);
    p->dem = spawn(da, p->dem_log);
    return p->fem > 0 && p->dem > 0 ? 0 : -1;
}

static int pair_start(pair *p, const char *out) { return pair_start_set(p, out, NULL); }

/* Waits until the run has written `rows` rows of traction.csv (or ended). */
static int wait_rows(const pair *p, long rows, double timeout_s)
{
    char csv[300];
    snprintf(csv, sizeof csv, "%s/traction.csv", p->out);
    double t0 = tp_now();
    while (tp_now() - t0 < timeout_s) {
        if (csv_rows(csv) >= rows)
            return 0;
        if (tp_pid_exited(p->fem) || tp_pid_exited(p->dem))
            return -1;
        tp_nap_ms(1);
    }
    return -1;
}

/* "KEY <hex>" in a log. */
static int log_hash(const char *log, const char *key, uint64_t *h)
{
    static char buf[1 << 18];
    if (file_text(log, buf, sizeof buf))
        return -1;
    const char *p = strstr(buf, key);
    unsigned long long v;
    if (!p || sscanf(p + strlen(key), " %llx", &v) != 1)
        return -1;
    *h = v;
    return 0;
}

/* ./run --resume OUT (with `--set SET` when set is not NULL). */
static int run_resume_set(const char *out, const char *log, const char *set)
{
    setenv("DEMFEM_NO_BUILD", "1", 1);
    setenv("DEMFEM_BUILD_DIR", DEMFEM_BUILD_DIR, 1);
    /* the scene named: the servers were started without the launcher, which
     * records it in DIR/scene.path */
    const char *argv[] = {DEMFEM_SOURCE_DIR "/run", g_scene, "--resume", out, set ? "--set" : NULL, set, NULL};
    pid_t pid = spawn(argv, log);
    return pid > 0 ? wait_exit(pid, 120) : -1;
}

static int run_resume(const char *out, const char *log) { return run_resume_set(out, log, NULL); }

typedef struct reference {
    uint64_t dem_hash, fem_hash;
    char out[260];
} reference;

/* A folder of its own with the scene and its settled bed (the bed is cached
 * beside the scene: every run then starts from the same loaded bed), and
 * the uninterrupted run. */
/* Replaces the first `from` in text (of capacity cap) by `to`. */
static int replace_once(char *text, size_t cap, const char *from, const char *to)
{
    char *at = strstr(text, from);
    ENSURE_MSG(at, "'%s' not in the test scene", from);
    size_t tail = strlen(at + strlen(from));
    ENSURE((size_t)(at - text) + strlen(to) + tail < cap);
    memmove(at + strlen(to), at + strlen(from), tail + 1);
    memcpy(at, to, strlen(to));
    return 0;
}

/* window: the scene with a terrain window that removes grains behind the
 * wheel, appends a stretch in front and freezes the far grains at the start
 * (the wheel travels only millimetres in the test), so that the checkpoints
 * hold a window-changed world and the frozen set keeps being updated; and
 * with the rolling spring (its rotations in the pair and wall springs of the
 * checkpoint). */
enum { SCENE_WINDOW = 1, SCENE_HELD = 2 };

static int setup_scene(reference *ref, int variant)
{
    const int window = variant & SCENE_WINDOW;
    snprintf(g_dir, sizeof g_dir, "/tmp/demfem-restart-%d", (int)getpid());
    snprintf(g_scene, sizeof g_scene, "%s/tire_ckpt.cfg", g_dir);
    mkdir(g_dir, 0755);
    static char text[1 << 14];
    ENSURE(file_text(DEMFEM_SOURCE_DIR "/tests/coupling/scenes/tire_ckpt.cfg", text, sizeof text) == 0);
    if (window && (replace_once(text, sizeof text, "surface_material = \"tread\";",
                                "surface_material = \"tread\";\n  window = { behind = 0.07; ahead = 0.16; shift = 0.03; "
                                "sample_margin = 0.03; freeze_distance = 0.035; };") ||
                   replace_once(text, sizeof text, "material = \"soil\";", "material = \"soil\"; side_walls = true;") ||
                   replace_once(text, sizeof text, "friction = 0.6; }", "friction = 0.6; rolling_friction = 0.3; }") ||
                   replace_once(text, sizeof text, "threads = 1;", "threads = 1;\n  rolling_model = \"spring\";")))
        return 1;
    /* held: traction.csv rows written only at the checkpoints and the end */
    if ((variant & SCENE_HELD) && replace_once(text, sizeof text, "series_flush = 0.0;", "series_flush = 1e9;"))
        return 1;
    FILE *f = fopen(g_scene, "w");
    ENSURE(f && fputs(text, f) >= 0 && fclose(f) == 0);
    char out[300], log[320];
    snprintf(out, sizeof out, "%s/bed", g_dir);
    snprintf(log, sizeof log, "%s/bed.log", g_dir);
    mkdir(out, 0755);
    const char *argv[] = {DEM_SERVER, "--scene", g_scene, "--standalone", "--out", out, NULL};
    pid_t pid = spawn(argv, log);
    ENSURE(pid > 0 && wait_exit(pid, 120) == 0);
    /* The run record says the bed was settled, and how long that took (a
     * study counts a run's cost without it: bench/study/run). */
    double loaded = -1, bed_s = -1;
    ENSURE(tp_record_num(out, "dem_run.json", "bed_loaded", &loaded) == 0 && loaded == 0);
    ENSURE(tp_record_num(out, "dem_run.json", "bed_s", &bed_s) == 0 && bed_s > 0 && bed_s < 120);

    pair p;
    snprintf(ref->out, sizeof ref->out, "%s/reference", g_dir);
    ENSURE(pair_start(&p, ref->out) == 0);
    int fem_rc = wait_exit(p.fem, 120), dem_rc = wait_exit(p.dem, 10);
    ENSURE_MSG(fem_rc == 0 && dem_rc == 0, "reference run: fem exit %d, dem exit %d (logs %s, %s)", fem_rc, dem_rc,
               p.fem_log, p.dem_log);
    double loaded_s = -1;
    ENSURE(tp_record_num(ref->out, "dem_run.json", "bed_loaded", &loaded) == 0 && loaded == 1);
    ENSURE(tp_record_num(ref->out, "dem_run.json", "bed_s", &loaded_s) == 0 && loaded_s >= 0);
    ENSURE(log_hash(p.dem_log, "dem_world_hash", &ref->dem_hash) == 0);
    ENSURE(log_hash(p.fem_log, "fem_state_hash", &ref->fem_hash) == 0);
    char csv[300];
    snprintf(csv, sizeof csv, "%s/traction.csv", ref->out);
    ENSURE(csv_rows(csv) == EXCHANGES);
    return 0;
}

static int setup(reference *ref) { return setup_scene(ref, 0); }

static void cleanup(void)
{
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", g_dir);
    if (g_dir[0] && system(cmd) != 0)
        fprintf(stderr, "could not remove %s\n", g_dir);
}

/* Rows of a 1-D dataset, groups under a group: -1 when unreadable. */
static long h5_rows(hid_t f, const char *path)
{
    hid_t d = H5Dopen2(f, path, H5P_DEFAULT);
    if (d < 0)
        return -1;
    hid_t s = H5Dget_space(d);
    hsize_t n = 0;
    long r = s >= 0 && H5Sget_simple_extent_dims(s, &n, NULL) == 1 ? (long)n : -1;
    if (s >= 0)
        H5Sclose(s);
    H5Dclose(d);
    return r;
}

static long h5_links(hid_t f, const char *group)
{
    H5G_info_t gi;
    hid_t g = H5Gopen2(f, group, H5P_DEFAULT);
    long n = g >= 0 && H5Gget_info(g, &gi) >= 0 ? (long)gi.nlinks : -1;
    if (g >= 0)
        H5Gclose(g);
    return n;
}

/* The result files of `out` match the reference's. */
static int same_results(const reference *ref, const char *out)
{
    static const char *const files[] = {"traction.csv", "dem_series.csv", "fem_series.csv"};
    for (int k = 0; k < 3; k++) {
        char a[400], b[400];
        snprintf(a, sizeof a, "%s/%s", ref->out, files[k]);
        snprintf(b, sizeof b, "%s/%s", out, files[k]);
        ENSURE_MSG(same_file(a, b), "%s differs from the uninterrupted run's", b);
    }
    static const char *const h5[] = {"wheel.h5", "fem.h5", "dem_grains.h5"};
    long counts[2][3];
    for (int r = 0; r < 2; r++)
        for (int k = 0; k < 3; k++) {
            char path[400];
            snprintf(path, sizeof path, "%s/%s", r ? out : ref->out, h5[k]);
            hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
            ENSURE_MSG(f >= 0, "%s does not open", path);
            counts[r][k] = k == 0 ? h5_rows(f, "/series") : k == 1 ? h5_links(f, "/steps") : h5_links(f, "/");
            H5Fclose(f);
        }
    for (int k = 0; k < 3; k++)
        ENSURE_MSG(counts[0][k] == counts[1][k] && counts[0][k] > 0, "%s: %ld entries, uninterrupted %ld", h5[k],
                   counts[1][k], counts[0][k]);
    return 0;
}

static int resume_matches_set(const reference *ref, const char *out, const char *set)
{
    char log[320];
    snprintf(log, sizeof log, "%s.resume.log", out);
    int rc = run_resume_set(out, log, set);
    ENSURE_MSG(rc == 0, "./run --resume %s: exit %d (log %s)", out, rc, log);
    uint64_t dh = 0, fh = 0;
    ENSURE(log_hash(log, "dem_world_hash", &dh) == 0 && log_hash(log, "fem_state_hash", &fh) == 0);
    ENSURE_MSG(dh == ref->dem_hash && fh == ref->fem_hash,
               "resumed: dem %016" PRIx64 " fem %016" PRIx64 ", uninterrupted: dem %016" PRIx64 " fem %016" PRIx64,
               dh, fh, ref->dem_hash, ref->fem_hash);
    return same_results(ref, out);
}

static int resume_matches(const reference *ref, const char *out) { return resume_matches_set(ref, out, NULL); }

static int interrupt_resume_bit_exact(void)
{
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    reference ref;
    if (setup(&ref))
        return 1;
    /* fem_server by SIGTERM, then dem_server by SIGINT (it asks for the checkpoint) */
    const int sigs[2] = {SIGTERM, SIGINT};
    const long at[2] = {230, 640};
    for (int v = 0; v < 2; v++) {
        pair p;
        char out[300];
        snprintf(out, sizeof out, "%s/interrupted%d", g_dir, v);
        ENSURE(pair_start(&p, out) == 0);
        ENSURE(wait_rows(&p, at[v], 60) == 0);
        kill(v == 0 ? p.fem : p.dem, sigs[v]);
        int fem_rc = wait_exit(p.fem, 20), dem_rc = wait_exit(p.dem, 20);
        int want_fem = v == 0 ? 128 + SIGTERM : 0, want_dem = v == 0 ? 0 : 128 + SIGINT;
        ENSURE_MSG(fem_rc == want_fem && dem_rc == want_dem, "interrupted run: fem exit %d (want %d), dem exit %d "
                   "(want %d)", fem_rc, want_fem, dem_rc, want_dem);
        long x;
        char dem_ck[1100], fem_ck[1100], csv[400];
        cm_error err = {0};
        ENSURE_MSG(cm_ckpt_choose(out, &x, dem_ck, fem_ck, sizeof dem_ck, &err) == CM_OK, "%s", err.msg);
        /* the checkpoint is the exchange after the signal, and the run stopped there */
        snprintf(csv, sizeof csv, "%s/traction.csv", out);
        printf("  %s interrupted after %ld rows: checkpoint of exchange %ld, %ld rows\n", v ? "dem" : "fem", at[v],
               x, csv_rows(csv));
        ENSURE(x >= at[v] - 1 && x < EXCHANGES - 1);
        ENSURE(csv_rows(csv) == x + 1);
        if (resume_matches(&ref, out))
            return 1;
    }
    /* Refused with a reason: a changed scene, then checkpoints of one side only. */
    char out[300], log[320], path[400];
    snprintf(out, sizeof out, "%s/interrupted1", g_dir);
    snprintf(log, sizeof log, "%s.refused.log", out);
    static char text[1 << 16];
    FILE *f = fopen(g_scene, "a");
    ENSURE(f && fputs("# edited after the run\n", f) >= 0 && fclose(f) == 0);
    int rc = run_resume(out, log);
    file_text(log, text, sizeof text);
    ENSURE_MSG(rc != 0 && strstr(text, "the scene file or its --set overrides differs from the checkpointed run"),
               "exit %d (log %s)", rc, log);
    for (int k = 0; k < 2; k++) {
        cm_ckpt_path(out, "dem", k, path, sizeof path);
        unlink(path);
    }
    rc = run_resume(out, log);
    file_text(log, text, sizeof text);
    ENSURE_MSG(rc != 0 && strstr(text, "no consistent checkpoint"), "exit %d (log %s)", rc, log);
    cleanup();
    return 0;
}

static uint64_t rng_next(uint64_t *s)
{
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    return *s;
}

/* The killed run's files open and hold what was flushed. */
static int killed_files_readable(const char *out)
{
    char path[400];
    snprintf(path, sizeof path, "%s/traction.csv", out);
    long csv = csv_rows(path);
    snprintf(path, sizeof path, "%s/wheel.h5", out);
    hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE_MSG(f >= 0, "%s of the killed run does not open", path);
    long rows = h5_rows(f, "/series");
    H5Fclose(f);
    /* each row goes to the .h5 (flushed), then to the CSV */
    ENSURE_MSG(rows == csv || rows == csv + 1, "%s: %ld rows, traction.csv %ld", path, rows, csv);
    snprintf(path, sizeof path, "%s/dem_grains.h5", out);
    f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE_MSG(f >= 0, "%s of the killed run does not open", path);
    ENSURE(h5_rows(f, "/frame_000000/radius") == 400);
    H5Fclose(f);
    snprintf(path, sizeof path, "%s/fem.h5", out);
    f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    ENSURE_MSG(f >= 0, "%s of the killed run does not open", path);
    ENSURE(h5_rows(f, "/series") >= 0);
    H5Fclose(f);
    return 0;
}

static int sigkill_random_step_20_trials(void)
{
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    reference ref;
    if (setup(&ref))
        return 1;
    uint64_t seed = 0x9e3779b97f4a7c15ull; /* fixed: the same trials every time */
    const int trials = KILL_TRIALS;
    double worst_exit = 0;
    for (int t = 0; t < trials; t++) {
        int kill_fem = (int)(rng_next(&seed) & 1);
        /* after the first checkpoint (exchange 99), before the end */
        long at = CKPT_EVERY + 10 + (long)(rng_next(&seed) % (EXCHANGES - CKPT_EVERY - 60));
        pair p;
        char out[300];
        snprintf(out, sizeof out, "%s/trial%02d", g_dir, t);
        pid_t victim, survivor;
        int rc;
        double t_exit;
        for (int attempt = 0;; attempt++) {
            ENSURE(pair_start(&p, out) == 0);
            ENSURE_MSG(wait_rows(&p, at, 60) == 0, "trial %d: the run did not reach exchange %ld", t, at);
            victim = kill_fem ? p.fem : p.dem, survivor = kill_fem ? p.dem : p.fem;
            kill(victim, SIGKILL);
            double t_kill = tp_now();
            ENSURE(wait_exit(victim, 10) == 128 + SIGKILL);
            rc = wait_exit(survivor, 10);
            t_exit = tp_now() - t_kill;
            /* The survivor finished the run (exit 0): on a loaded machine the
             * pair ran its last exchanges before the kill landed, so this
             * trial killed nothing mid-run. Known for certain, not guessed:
             * repeat it from an earlier exchange. */
            if (rc != 0 || attempt == 2)
                break;
            printf("  trial %2d: the run ended before the kill at exchange ~%ld landed: again from an earlier one\n",
                   t, at);
            at = CKPT_EVERY + 10 + (at - CKPT_EVERY - 10) / 2;
            char cmd[700];
            snprintf(cmd, sizeof cmd, "rm -rf '%s' '%s'.*", out, out);
            ENSURE(system(cmd) == 0);
        }
        worst_exit = t_exit > worst_exit ? t_exit : worst_exit;
        const char *slog = kill_fem ? p.dem_log : p.fem_log;
        static char text[1 << 18];
        file_text(slog, text, sizeof text);
        char peer[64];
        snprintf(peer, sizeof peer, "peer %s (pid %d)", kill_fem ? "fem" : "dem", (int)victim);
        ENSURE_MSG(rc > 0 && rc < 128 && t_exit < 2.0 && strstr(text, peer),
                   "trial %d: survivor exit %d after %.2f s; its log (%s) should name \"%s\"", t, rc, t_exit, slog,
                   peer);
        char shm[100];
        snprintf(shm, sizeof shm, "/dev/shm%s", p.shm);
        ENSURE_MSG(access(shm, F_OK) != 0, "trial %d: %s left behind", t, shm);
        if (killed_files_readable(out))
            return 1;
        /* the last checkpoint reads, and is at most one interval old */
        long x;
        char dem_ck[1100], fem_ck[1100];
        cm_error err = {0};
        ENSURE_MSG(cm_ckpt_choose(out, &x, dem_ck, fem_ck, sizeof dem_ck, &err) == CM_OK, "trial %d: %s", t, err.msg);
        cm_ckpt ck;
        int n = 0;
        double center[3];
        ENSURE(cm_ckpt_begin_read(&ck, dem_ck, x, &err) == CM_OK);
        cm_ckpt_int(&ck, "/grains/n", &n);
        ENSURE_MSG(cm_ckpt_end_read(&ck) == CM_OK && n == 400, "trial %d: %s", t, err.msg);
        ENSURE(cm_ckpt_begin_read(&ck, fem_ck, x, &err) == CM_OK);
        cm_ckpt_f64(&ck, "/drive/center", center, 3);
        ENSURE_MSG(cm_ckpt_end_read(&ck) == CM_OK, "trial %d: %s", t, err.msg);
        ENSURE(x <= at + 2 * CKPT_EVERY && x >= at - 2 * CKPT_EVERY);
        printf("  trial %2d: SIGKILL %s at exchange ~%ld; survivor exit %d after %.2f s; resuming from %ld\n", t,
               kill_fem ? "fem_server" : "dem_server", at, rc, t_exit, x);
        if (resume_matches(&ref, out))
            return 1;
        char cmd[700];
        snprintf(cmd, sizeof cmd, "rm -rf '%s' '%s'.*", out, out);
        if (system(cmd) != 0)
            fprintf(stderr, "could not remove %s\n", out);
    }
    printf("  %d trials; slowest survivor exit %.2f s after the kill\n", trials, worst_exit);
    cleanup();
    return 0;
}

/* Runs argv with stdout+stderr to log and, when fsize > 0, file sizes
 * limited to fsize bytes with SIGXFSZ ignored (a write past it fails with
 * EFBIG, as on a full disk). Returns the exit status, 128 + signal. */
static int run_logged(const char *const *argv, const char *log, long fsize)
{
    setenv("DEMFEM_NO_BUILD", "1", 1);
    setenv("DEMFEM_BUILD_DIR", DEMFEM_BUILD_DIR, 1);
    pid_t pid = fork();
    if (pid == 0) {
        int fd = open(log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (fd < 0 || dup2(fd, 1) < 0 || dup2(fd, 2) < 0)
            _exit(120);
        if (fsize > 0) {
            struct rlimit rl = {(rlim_t)fsize, (rlim_t)fsize};
            signal(SIGXFSZ, SIG_IGN);
            if (setrlimit(RLIMIT_FSIZE, &rl) != 0)
                _exit(121);
        }
        execve(argv[0], (char *const *)argv, environ);
        _exit(122);
    }
    return pid > 0 ? wait_exit(pid, 120) : -1;
}

/* Lines of the log containing "error" (a launcher's or a server's), except
 * a peer relaying the failed side's reason; a crash leaves a marker. */
static int error_lines(const char *log, char *first, size_t len)
{
    static char text[1 << 18];
    file_text(log, text, sizeof text);
    if (strstr(text, "Segmentation") || strstr(text, "core dumped") || strstr(text, "Abort") ||
        strstr(text, "Sanitizer") || strstr(text, "HDF5-DIAG"))
        return -1;
    int n = 0;
    for (char *line = strtok(text, "\n"); line; line = strtok(NULL, "\n"))
        if (strstr(line, "error") && !strstr(line, "peer dem failed") && !strstr(line, "peer fem failed")) {
            if (n++ == 0)
                snprintf(first, len, "%s", line);
        }
    return n;
}

static int scene_variant(const char *path, const char *from, const char *to)
{
    static char text[1 << 14];
    ENSURE(file_text(DEMFEM_SOURCE_DIR "/tests/coupling/scenes/tire_ckpt.cfg", text, sizeof text) == 0);
    char *at = from ? strstr(text, from) : NULL;
    ENSURE(!from || at);
    FILE *f = fopen(path, "w");
    ENSURE(f);
    if (at) {
        fwrite(text, 1, (size_t)(at - text), f);
        fputs(to, f);
        fputs(at + strlen(from), f);
    } else {
        fputs(text, f);
    }
    ENSURE(fclose(f) == 0);
    return 0;
}

static int full_disk_one_error_line(void)
{
    snprintf(g_dir, sizeof g_dir, "/tmp/demfem-restart-%d", (int)getpid());
    mkdir(g_dir, 0755);
    snprintf(g_scene, sizeof g_scene, "%s/tire_ckpt.cfg", g_dir);
    if (scene_variant(g_scene, NULL, NULL))
        return 1;
    /* 300 kB: the first results and checkpoints fit, a later write does not */
    char out[300], log[320], first[1024] = "";
    snprintf(out, sizeof out, "%s/full", g_dir);
    snprintf(log, sizeof log, "%s/full.log", g_dir);
    const char *argv[] = {DEMFEM_SOURCE_DIR "/run", g_scene, "--out", out, NULL};
    int rc = run_logged(argv, log, 300 * 1024);
    int n = error_lines(log, first, sizeof first);
    printf("  exit %d; %d error line(s): %s\n", rc, n, first);
    ENSURE_MSG(rc > 0 && rc < 128, "exit %d (log %s)", rc, log);
    ENSURE_MSG(n >= 1 && n <= 2 && strstr(first, "File too large") && strstr(first, out),
               "want one error line naming the file and 'File too large' (log %s)", log);
    /* 2: the failing server's line and the launcher's "failed (exit N)" summary */
    if (n == 2) {
        static char text[1 << 18];
        file_text(log, text, sizeof text);
        ENSURE(strstr(text, "[run]"));
    }
    cleanup();
    return 0;
}

static int output_folder_unwritable(void)
{
    snprintf(g_dir, sizeof g_dir, "/tmp/demfem-restart-%d", (int)getpid());
    mkdir(g_dir, 0755);
    snprintf(g_scene, sizeof g_scene, "%s/tire_ckpt.cfg", g_dir);
    if (scene_variant(g_scene, NULL, NULL))
        return 1;
    char file[300], out[320], log[320], first[1024];
    snprintf(file, sizeof file, "%s/a_file", g_dir);
    FILE *f = fopen(file, "w");
    ENSURE(f && fclose(f) == 0);
    snprintf(out, sizeof out, "%s/results", file); /* under a regular file: nothing can be created */
    snprintf(log, sizeof log, "%s/unwritable.log", g_dir);
    const char *runs[3][9] = {
        {DEMFEM_SOURCE_DIR "/run", g_scene, "--out", out, NULL},
        {DEM_SERVER, "--scene", g_scene, "--standalone", "--out", out, NULL},
        {FEM_SERVER, "--scene", g_scene, "--shm", "/demfem-restart-unwritable", "--out", out, NULL}};
    for (int k = 0; k < 3; k++) {
        int rc = run_logged(runs[k], log, 0);
        int n = error_lines(log, first, sizeof first);
        printf("  %s: exit %d: %s\n", runs[k][0], rc, first);
        ENSURE_MSG(rc == 1 && n == 1 && strstr(first, "cannot create output folder") && strstr(first, out),
                   "%s: exit %d, %d error lines (log %s)", runs[k][0], rc, n, log);
    }
    ENSURE(access("/dev/shm/demfem-restart-unwritable", F_OK) != 0);
    cleanup();
    return 0;
}

static int missing_mesh_file(void)
{
    snprintf(g_dir, sizeof g_dir, "/tmp/demfem-restart-%d", (int)getpid());
    mkdir(g_dir, 0755);
    snprintf(g_scene, sizeof g_scene, "%s/tire_ckpt.cfg", g_dir);
    if (scene_variant(g_scene, "mesh = { type = \"tire\"; resolution = 0.25; };",
                      "mesh = { type = \"gmsh\"; file = \"no_such_tire.msh\"; };"))
        return 1;
    char out[300], log[320], first[1024];
    snprintf(out, sizeof out, "%s/out", g_dir);
    snprintf(log, sizeof log, "%s/nomesh.log", g_dir);
    const char *argv[] = {DEMFEM_SOURCE_DIR "/run", g_scene, "--out", out, NULL};
    int rc = run_logged(argv, log, 0);
    int n = error_lines(log, first, sizeof first);
    printf("  exit %d: %s\n", rc, first);
    ENSURE_MSG(rc == 1 && n >= 1 && strstr(first, "no_such_tire.msh") && strstr(first, "No such file"),
               "exit %d (log %s)", rc, log);
    /* besides the launcher's summary, nothing else complains */
    ENSURE_MSG(n == 1 || n == 2, "%d error lines (log %s)", n, log);
    cleanup();
    return 0;
}

/* The terrain window's state (grains removed and appended, end walls moved,
 * tags, frozen grains, the window's own counters) survives a checkpoint, and
 * a run resumed with another DEM thread count ends bit for bit the same.
 * The interrupted run had an override of its own (restating the scene's
 * exchange_every): `./run --resume DIR --set dem.threads=2` must keep it,
 * or the servers refuse the checkpoint as another scene. */
static int window_resume_bit_exact(void)
{
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    reference ref;
    if (setup_scene(&ref, SCENE_WINDOW))
        return 1;
    static char text[1 << 16];
    char log[320];
    snprintf(log, sizeof log, "%s.dem.log", ref.out);
    file_text(log, text, sizeof text);
    ENSURE_MSG(strstr(text, "window: wheel at") && strstr(text, "appended") && strstr(text, "frozen"),
               "the window did not act in the reference run (log %s)", log);
    pair p;
    char out[300];
    snprintf(out, sizeof out, "%s/interrupted", g_dir);
    ENSURE(file_text(g_scene, text, sizeof text) == 0 && strstr(text, "exchange_every = 2;"));
    ENSURE(pair_start_set(&p, out, "coupling.exchange_every=2") == 0);
    ENSURE(wait_rows(&p, 500, 60) == 0);
    kill(p.fem, SIGTERM);
    int fem_rc = wait_exit(p.fem, 20), dem_rc = wait_exit(p.dem, 20);
    ENSURE_MSG(fem_rc == 128 + SIGTERM && dem_rc == 0, "interrupted run: fem exit %d, dem exit %d", fem_rc, dem_rc);
    /* resumed with two DEM threads where the run had one: the same bits
     * (sphere contacts and the tire's node forces are summed in a fixed
     * order whatever the thread count) */
    if (resume_matches_set(&ref, out, "dem.threads=2"))
        return 1;
    cleanup();
    return 0;
}

/* fem_server holding its traction rows (fem.output.series_flush, here
 * longer than the run): they reach traction.csv and wheel.h5 only at the
 * checkpoints (every 100 exchanges) and the end. Killed after the third
 * checkpoint, the run leaves whole checkpoints' rows, and resumed it ends
 * as the uninterrupted run did (which wrote its rows at the end): the rows a
 * checkpoint counts were written before it. */
static int held_rows_kill_resume_bit_exact(void)
{
    H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
    reference ref;
    if (setup_scene(&ref, SCENE_HELD))
        return 1;
    char out[300], csv[400], path[400];
    snprintf(out, sizeof out, "%s/killed", g_dir);
    /* A kill that lands while a block is being written leaves part of it:
     * known from the count, that attempt is repeated (rows written one by
     * one would miss a whole checkpoint's count every time). */
    long rows = -1, h5 = -1;
    for (int attempt = 0; attempt < 3; attempt++) {
        char cmd[700];
        snprintf(cmd, sizeof cmd, "rm -rf '%s' '%s'.*", out, out);
        ENSURE(system(cmd) == 0);
        pair p;
        ENSURE(pair_start(&p, out) == 0);
        ENSURE_MSG(wait_rows(&p, 3 * CKPT_EVERY, 60) == 0, "no rows before the run's end (logs %s, %s)", p.fem_log,
                   p.dem_log);
        kill(p.fem, SIGKILL);
        int fem_rc = wait_exit(p.fem, 20), dem_rc = wait_exit(p.dem, 20);
        ENSURE_MSG(fem_rc == 128 + SIGKILL && dem_rc > 0, "fem exit %d, dem exit %d: the run was not cut short",
                   fem_rc, dem_rc);
        snprintf(csv, sizeof csv, "%s/traction.csv", out);
        snprintf(path, sizeof path, "%s/wheel.h5", out);
        rows = csv_rows(csv);
        hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
        ENSURE_MSG(f >= 0, "%s of the killed run does not open", path);
        h5 = h5_rows(f, "/series");
        H5Fclose(f);
        printf("  killed with %ld rows in traction.csv, %ld in wheel.h5\n", rows, h5);
        if (rows % CKPT_EVERY == 0 && h5 % CKPT_EVERY == 0)
            break;
    }
    ENSURE_MSG(rows >= 3 * CKPT_EVERY && rows < EXCHANGES && rows % CKPT_EVERY == 0 && h5 >= rows &&
                   h5 % CKPT_EVERY == 0,
               "%ld rows in traction.csv, %ld in wheel.h5: want whole checkpoints' rows", rows, h5);
    if (resume_matches(&ref, out))
        return 1;
    cleanup();
    return 0;
}

static const test_case tests[] = {
    {"window_resume_bit_exact", window_resume_bit_exact},
    {"full_disk_one_error_line", full_disk_one_error_line},
    {"output_folder_unwritable", output_folder_unwritable},
    {"missing_mesh_file", missing_mesh_file},
    {"interrupt_resume_bit_exact", interrupt_resume_bit_exact},
    {"sigkill_random_step_20_trials", sigkill_random_step_20_trials},
    {"held_rows_kill_resume_bit_exact", held_rows_kill_resume_bit_exact},
};

int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
