/* The run record: a small JSON file a server writes when it ends, however
 * it ends (dem_run.json, fem_run.json in the output folder): its exit status,
 * the error that stopped it (the message it logged), and the figures of the
 * run that scripts need (sizes, time-step limits, exchanges). Scripts read
 * this, never the servers' logs (bench/study/run).
 *
 *   { "program": "fem_server", "exit_code": 0, "error": "", "tets": 1234, ... }
 *
 * Items keep the order they were set in; setting a key again replaces its
 * value. No allocation: a fixed number of items. */
#ifndef CM_RUNREC_H
#define CM_RUNREC_H

#include "error.h"

enum { CM_RUNREC_MAX_ITEMS = 24 };

typedef struct cm_run_record {
    int n;
    struct {
        char key[40];
        int is_text;
        double num;      /* written with 17 digits (cm_json_number) */
        char text[1100]; /* a message (cm_error's) or a name */
    } item[CM_RUNREC_MAX_ITEMS];
} cm_run_record;

/* Sets key to a number or a text (truncated to fit); beyond
 * CM_RUNREC_MAX_ITEMS keys a new key is dropped (a programming error:
 * the record's keys are fixed in the code). */
void cm_runrec_num(cm_run_record *r, const char *key, double value);
void cm_runrec_text(cm_run_record *r, const char *key, const char *text);

/* Writes the record to path (a temporary file renamed into place, so that a
 * reader never sees half a record). CM_OK or CM_ERR_IO naming the file. */
int cm_runrec_write(const cm_run_record *r, const char *path, cm_error *err);

#endif
