#include "error.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

int cm_fail(cm_error *err, int code, const char *fmt, ...)
{
    if (err) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err->msg, sizeof err->msg, fmt, ap);
        va_end(ap);
        err->code = code;
    }
    return code;
}

int cm_fail_prefix(cm_error *err, const char *fmt, ...)
{
    if (!err)
        return CM_ERR_STATE;
    char old[sizeof err->msg];
    memcpy(old, err->msg, sizeof old);
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(err->msg, sizeof err->msg, fmt, ap);
    va_end(ap);
    if (n >= 0 && (size_t)n < sizeof err->msg)
        snprintf(err->msg + n, sizeof err->msg - (size_t)n, "%s", old);
    return err->code;
}

const char *cm_error_name(int code)
{
    switch (code) {
    case CM_OK: return "ok";
    case CM_ERR_IO: return "i/o error";
    case CM_ERR_PARSE: return "parse error";
    case CM_ERR_KEY: return "scene key error";
    case CM_ERR_RANGE: return "value out of range";
    case CM_ERR_NOMEM: return "out of memory";
    case CM_ERR_NUMERIC: return "numerical error";
    case CM_ERR_STATE: return "invalid state";
    case CM_ERR_PEER: return "peer failed";
    case CM_WARN_STALE: return "stale cached file (warning)";
    default: return "unknown error";
    }
}
