/* Checkpoint files; see ckpt.h. */
#include "ckpt.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

void cm_ckpt_path(const char *dir, const char *role, int prev, char *buf, size_t len)
{
    snprintf(buf, len, "%s/checkpoint/%s%s.h5", dir, role, prev ? ".prev" : "");
}

int cm_ckpt_begin_write(cm_ckpt *ck, const char *dir, const char *role, long exchange, cm_error *err)
{
    memset(ck, 0, sizeof *ck);
    ck->writing = 1;
    ck->err = err;
    char sub[1100];
    snprintf(sub, sizeof sub, "%s/checkpoint", dir);
    if (mkdir(sub, 0755) != 0 && errno != EEXIST)
        return ck->rc = cm_fail(err, CM_ERR_IO, "cannot create checkpoint folder %s: %s", sub, strerror(errno));
    cm_ckpt_path(dir, role, 0, ck->path, sizeof ck->path);
    snprintf(ck->tmp, sizeof ck->tmp, "%s.tmp", ck->path);
    if ((ck->rc = cm_h5_create(ck->tmp, NULL, &ck->f, err)) != CM_OK)
        return ck->rc;
    cm_ckpt_long(ck, "/exchange", &exchange);
    return ck->rc;
}

int cm_ckpt_commit(cm_ckpt *ck)
{
    if (ck->f) {
        cm_error e = {0};
        if (cm_h5_close(&ck->f, &e) != CM_OK && ck->rc == CM_OK)
            ck->rc = cm_fail(ck->err, e.code, "%s", e.msg);
    }
    if (ck->rc == CM_OK && cm_fsync_file(ck->tmp) != 0)
        ck->rc = cm_fail(ck->err, CM_ERR_IO, "syncing checkpoint %s: %s", ck->tmp, strerror(errno));
    if (ck->rc != CM_OK) {
        unlink(ck->tmp);
        return ck->rc;
    }
    /* last -> prev, then tmp -> last: at every moment one complete file
     * (last or prev) holds the newest committed state. */
    char prev[1120];
    snprintf(prev, sizeof prev, "%.*s.prev.h5", (int)(strlen(ck->path) - 3), ck->path);
    if (access(ck->path, F_OK) == 0 && rename(ck->path, prev) != 0)
        ck->rc = cm_fail(ck->err, CM_ERR_IO, "renaming %s to %s: %s", ck->path, prev, strerror(errno));
    else if (rename(ck->tmp, ck->path) != 0)
        ck->rc = cm_fail(ck->err, CM_ERR_IO, "renaming %s to %s: %s", ck->tmp, ck->path, strerror(errno));
    if (ck->rc == CM_OK)
        cm_fsync_folder_of(ck->path); /* the renames themselves */
    return ck->rc;
}

int cm_ckpt_begin_read(cm_ckpt *ck, const char *path, long exchange, cm_error *err)
{
    memset(ck, 0, sizeof *ck);
    ck->err = err;
    snprintf(ck->path, sizeof ck->path, "%s", path);
    if ((ck->rc = cm_h5_open(path, 0, &ck->f, err)) != CM_OK)
        return ck->rc;
    long stored = -1;
    cm_ckpt_long(ck, "/exchange", &stored);
    if (ck->rc == CM_OK && stored != exchange)
        ck->rc = cm_fail(err, CM_ERR_STATE, "%s holds exchange %ld, not %ld", path, stored, exchange);
    return ck->rc;
}

int cm_ckpt_end_read(cm_ckpt *ck)
{
    if (ck->f)
        cm_h5_close(&ck->f, NULL);
    return ck->rc;
}

static void field(cm_ckpt *ck, const char *name, cm_h5_type type, void *p, size_t n)
{
    if (ck->rc != CM_OK)
        return;
    ck->rc = ck->writing ? cm_h5_write_array(ck->f, name, type, p, n, 1, ck->err)
                         : cm_h5_read_array(ck->f, name, type, p, n, 1, ck->err);
}

void cm_ckpt_f64(cm_ckpt *ck, const char *name, double *p, size_t n) { field(ck, name, CM_H5_F64, p, n); }
void cm_ckpt_i32(cm_ckpt *ck, const char *name, int *p, size_t n) { field(ck, name, CM_H5_I32, p, n); }
void cm_ckpt_u32(cm_ckpt *ck, const char *name, uint32_t *p, size_t n) { field(ck, name, CM_H5_U32, p, n); }
void cm_ckpt_u64(cm_ckpt *ck, const char *name, uint64_t *p, size_t n) { field(ck, name, CM_H5_U64, p, n); }
void cm_ckpt_double(cm_ckpt *ck, const char *name, double *v) { field(ck, name, CM_H5_F64, v, 1); }
void cm_ckpt_int(cm_ckpt *ck, const char *name, int *v) { field(ck, name, CM_H5_I32, v, 1); }

void cm_ckpt_long(cm_ckpt *ck, const char *name, long *v)
{
    int64_t x = *v;
    field(ck, name, CM_H5_I64, &x, 1);
    *v = (long)x;
}

void cm_ckpt_same_u64(cm_ckpt *ck, const char *name, uint64_t v, const char *what)
{
    uint64_t x = v;
    field(ck, name, CM_H5_U64, &x, 1);
    if (ck->rc == CM_OK && x != v)
        ck->rc = cm_fail(ck->err, CM_ERR_STATE, "%s: %s differs from the checkpointed run (%llu now, %llu then)",
                         ck->path, what, (unsigned long long)v, (unsigned long long)x);
}

void cm_ckpt_count(cm_ckpt *ck, const char *name, int *v, int max)
{
    cm_ckpt_int(ck, name, v);
    if (ck->rc == CM_OK && (*v < 0 || *v > max))
        ck->rc = cm_fail(ck->err, CM_ERR_RANGE, "%s: %s = %d is outside 0..%d", ck->path, name, *v, max);
}

/* The exchange stored in a checkpoint file, or -1 when it is absent or unreadable. */
static long file_exchange(const char *path)
{
    if (access(path, R_OK) != 0)
        return -1;
    cm_h5 *f = NULL;
    cm_error e = {0};
    int64_t x = -1;
    if (cm_h5_open(path, 0, &f, &e) != CM_OK || cm_h5_read_array(f, "/exchange", CM_H5_I64, &x, 1, 1, &e) != CM_OK)
        x = -1;
    cm_h5_close(&f, NULL);
    return (long)x;
}

int cm_ckpt_choose(const char *dir, long *exchange, char *dem_path, char *fem_path, size_t len, cm_error *err)
{
    char p[2][2][1100];
    long x[2][2];
    static const char *const roles[2] = {"dem", "fem"};
    for (int r = 0; r < 2; r++)
        for (int k = 0; k < 2; k++) {
            cm_ckpt_path(dir, roles[r], k, p[r][k], sizeof p[r][k]);
            x[r][k] = file_exchange(p[r][k]);
        }
    long best = -1;
    int bd = 0, bf = 0;
    for (int d = 0; d < 2; d++)
        for (int f = 0; f < 2; f++)
            if (x[0][d] >= 0 && x[0][d] == x[1][f] && x[0][d] > best)
                best = x[0][d], bd = d, bf = f;
    if (best < 0)
        return cm_fail(err, CM_ERR_STATE,
                       "no consistent checkpoint in %s/checkpoint: dem_server has exchanges %ld and %ld, fem_server "
                       "%ld and %ld (-1: none); both must name the same exchange",
                       dir, x[0][0], x[0][1], x[1][0], x[1][1]);
    *exchange = best;
    snprintf(dem_path, len, "%s", p[0][bd]);
    snprintf(fem_path, len, "%s", p[1][bf]);
    return CM_OK;
}

int cm_ckpt_adopt(const char *path, cm_error *err)
{
    size_t len = strlen(path);
    static const char suffix[] = ".prev.h5";
    if (len < sizeof suffix || strcmp(path + len - (sizeof suffix - 1), suffix) != 0)
        return CM_OK;
    char last[1100];
    snprintf(last, sizeof last, "%.*s.h5", (int)(len - (sizeof suffix - 1)), path);
    /* Removing the newer file (not renaming the previous one over it) keeps
     * the resumed exchange under one name throughout: the other server may
     * be choosing at this very moment. */
    if (unlink(last) != 0 && errno != ENOENT)
        return cm_fail(err, CM_ERR_IO, "removing %s (newer than the checkpoint resumed): %s", last, strerror(errno));
    return CM_OK;
}

int cm_ckpt_file_hash(const char *path, uint64_t *hash, cm_error *err)
{
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return cm_fail(err, CM_ERR_IO, "cannot read %s: %s", path, strerror(errno));
    uint64_t h = 1469598103934665603ULL;
    int c;
    while ((c = getc(fp)) != EOF) {
        h ^= (unsigned char)c;
        h *= 1099511628211ULL;
    }
    fclose(fp);
    *hash = h;
    return CM_OK;
}
