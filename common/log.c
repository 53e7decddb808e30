#include "log.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static char g_tag[16] = "demfem";
static int g_quiet;

void cm_log_set_tag(const char *tag)
{
    snprintf(g_tag, sizeof g_tag, "%s", tag ? tag : "");
}

void cm_log_set_quiet(int quiet) { g_quiet = quiet; }

static void log_line(FILE *f, const char *level, const char *fmt, va_list ap)
{
    char line[2048];
    vsnprintf(line, sizeof line, fmt, ap);
    /* One fprintf per line so that lines of two processes never interleave mid-line. */
    fprintf(f, "[%s]%s %s\n", g_tag, level, line);
    fflush(f);
}

void cm_log_info(const char *fmt, ...)
{
    if (g_quiet)
        return;
    va_list ap;
    va_start(ap, fmt);
    log_line(stdout, "", fmt, ap);
    va_end(ap);
}

void cm_log_warn(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    log_line(stderr, " warning:", fmt, ap);
    va_end(ap);
}

void cm_log_error(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    log_line(stderr, " error:", fmt, ap);
    va_end(ap);
}
