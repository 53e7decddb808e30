/* Error reporting shared by every part: a status code plus a message that
 * names the file, key, step or peer involved.
 *
 * Convention (as SuiteSparse's): 0 is success, negative is an error,
 * positive a warning (the call did its job another way; the message says
 * how). A function that can fail returns int and fills a cm_error supplied by
 * the caller; it never prints and never exits. Only main() decides what to do.
 *
 * One code space per boundary: a library with codes of its own (ipc/: IPC_*)
 * keeps them; its caller maps them here (CM_ERR_PEER, with a message naming
 * the peer) instead of carrying them in the same status variable. */
#ifndef CM_ERROR_H
#define CM_ERROR_H

#include <stddef.h>

enum {
    CM_OK = 0,
    CM_ERR_IO = -1,      /* a file could not be opened, read or written */
    CM_ERR_PARSE = -2,   /* malformed input (scene syntax, mesh format) */
    CM_ERR_KEY = -3,     /* missing, unknown or wrongly typed scene key */
    CM_ERR_RANGE = -4,   /* a value outside its allowed range */
    CM_ERR_NOMEM = -5,   /* allocation failed */
    CM_ERR_NUMERIC = -6, /* NaN, singular matrix, instability */
    CM_ERR_STATE = -7,   /* called in the wrong state */
    CM_ERR_PEER = -8,    /* the exchange with the other server failed: it died, stopped answering, refused the
                            handshake, reported a failure or sent a bad frame (the message names it; exit code 3) */
    CM_WARN_STALE = 1    /* warning: a cached file does not match what is asked (other parameters or code) and
                            was not used; the caller regenerates it */
};

typedef struct cm_error {
    int code;       /* last error code, CM_OK when none */
    char msg[1024]; /* human-readable message, empty when none */
} cm_error;

/* Formats msg into err (err may be NULL) and returns code, so that a failing
 * path reads:  return cm_fail(err, CM_ERR_IO, "%s: %s", path, strerror(errno)); */
int cm_fail(cm_error *err, int code, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

/* Prepends context to an existing message: "reading bed.h5: <old message>". */
int cm_fail_prefix(cm_error *err, const char *fmt, ...)
    __attribute__((format(printf, 2, 3)));

const char *cm_error_name(int code);

#endif
