/* Logging for the two servers: one line per message, prefixed with the
 * process tag ("dem", "fem") so that the launcher can interleave both logs.
 * Progress lines go to stdout; warnings and errors to stderr. */
#ifndef CM_LOG_H
#define CM_LOG_H

void cm_log_set_tag(const char *tag);  /* e.g. "dem"; at most 15 chars */
void cm_log_set_quiet(int quiet);      /* 1: only warnings and errors */

void cm_log_info(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void cm_log_warn(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void cm_log_error(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

#endif
