/* Checkpoint files: one HDF5 file per server holding its complete state at
 * one exchange, written and read by the same list of fields.
 *
 * A server lists its state once, in one function taking a cm_ckpt: the same
 * function writes the checkpoint (mode write) and reads it back (mode read),
 * so what is saved and what is restored cannot drift apart. Errors are
 * sticky: the first failure is kept in the cm_ckpt and later calls do
 * nothing, so a field list reads as a plain list.
 *
 * Files: <dir>/checkpoint/<role>.h5 is the last checkpoint, <role>.prev.h5
 * the one before. A new one is written to <role>.h5.tmp, synced, and only
 * then renamed over the last one (which becomes .prev): a crash during the
 * write never damages the last good checkpoint. Every file holds the dataset
 * /exchange (the exchange after which it was written); cm_ckpt_choose picks
 * the latest exchange for which both servers have a file. */
#ifndef CM_CKPT_H
#define CM_CKPT_H

#include <stddef.h>
#include <stdint.h>

#include "error.h"
#include "h5io.h"

typedef struct cm_ckpt {
    cm_h5 *f;
    int writing;     /* 1: write mode, 0: read mode */
    int rc;          /* first error, CM_OK while none */
    cm_error *err;
    char path[1100]; /* the file read, or the final path of the file written */
    char tmp[1110];  /* write mode: the temporary file */
} cm_ckpt;

/* <dir>/checkpoint/<role>.h5 (prev: <role>.prev.h5) into buf. */
void cm_ckpt_path(const char *dir, const char *role, int prev, char *buf, size_t len);

/* Write mode: creates <dir>/checkpoint/ and the temporary file. */
int cm_ckpt_begin_write(cm_ckpt *ck, const char *dir, const char *role, long exchange, cm_error *err);
/* Closes, syncs and renames the temporary file over the last checkpoint
 * (kept as .prev). On an earlier error only removes the temporary file. */
int cm_ckpt_commit(cm_ckpt *ck);

/* Read mode: opens path and checks that it holds exchange `exchange`. */
int cm_ckpt_begin_read(cm_ckpt *ck, const char *path, long exchange, cm_error *err);
int cm_ckpt_end_read(cm_ckpt *ck);

/* Fields: name is an absolute dataset path ("/drive/center"). In read mode
 * the stored array must have exactly n elements (n may be 0). */
void cm_ckpt_f64(cm_ckpt *ck, const char *name, double *p, size_t n);
void cm_ckpt_i32(cm_ckpt *ck, const char *name, int *p, size_t n);
void cm_ckpt_u32(cm_ckpt *ck, const char *name, uint32_t *p, size_t n);
void cm_ckpt_u64(cm_ckpt *ck, const char *name, uint64_t *p, size_t n);
/* Scalars. */
void cm_ckpt_long(cm_ckpt *ck, const char *name, long *v);
void cm_ckpt_int(cm_ckpt *ck, const char *name, int *v);
void cm_ckpt_double(cm_ckpt *ck, const char *name, double *v);
/* A value that must be the same on both sides (thread count, scene hash):
 * written as is, compared on reading; a difference fails naming `what`. */
void cm_ckpt_same_u64(cm_ckpt *ck, const char *name, uint64_t v, const char *what);
/* A count read before the arrays it sizes: fails unless 0 <= *v <= max. */
void cm_ckpt_count(cm_ckpt *ck, const char *name, int *v, int max);

/* The latest exchange for which <dir>/checkpoint holds both a dem and a fem
 * file (last or previous); fills the two paths. Fails with a message listing
 * what each side has when there is none. */
int cm_ckpt_choose(const char *dir, long *exchange, char *dem_path, char *fem_path, size_t len, cm_error *err);

/* After resuming from `path`: when it is the previous checkpoint
 * (<role>.prev.h5), removes the last one (<role>.h5, newer, of the abandoned
 * run: left in place, the next checkpoint would push the resumed one out
 * while the other server might still need it). The next checkpoint then
 * keeps the resumed one as the previous. */
int cm_ckpt_adopt(const char *path, cm_error *err);

/* FNV-1a 64 of a file's bytes (the scene, to refuse resuming a changed one). */
int cm_ckpt_file_hash(const char *path, uint64_t *hash, cm_error *err);

#endif
