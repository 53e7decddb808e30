/* The run record: see runrec.h. */
#include "runrec.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "json.h"

static int slot(cm_run_record *r, const char *key)
{
    for (int i = 0; i < r->n; i++)
        if (strcmp(r->item[i].key, key) == 0)
            return i;
    if (r->n >= CM_RUNREC_MAX_ITEMS)
        return -1;
    snprintf(r->item[r->n].key, sizeof r->item[r->n].key, "%s", key);
    return r->n++;
}

void cm_runrec_num(cm_run_record *r, const char *key, double value)
{
    int i = slot(r, key);
    if (i >= 0) {
        r->item[i].is_text = 0;
        r->item[i].num = value;
    }
}

void cm_runrec_text(cm_run_record *r, const char *key, const char *text)
{
    int i = slot(r, key);
    if (i >= 0) {
        r->item[i].is_text = 1;
        snprintf(r->item[i].text, sizeof r->item[i].text, "%s", text ? text : "");
    }
}

int cm_runrec_write(const cm_run_record *r, const char *path, cm_error *err)
{
    char tmp[1200];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *f = fopen(tmp, "w");
    if (!f)
        return cm_fail(err, CM_ERR_IO, "%s: %s", tmp, strerror(errno));
    fputc('{', f);
    for (int i = 0; i < r->n; i++) {
        fprintf(f, "%s\n  ", i ? "," : "");
        cm_json_string(f, r->item[i].key);
        fputs(": ", f);
        if (r->item[i].is_text)
            cm_json_string(f, r->item[i].text);
        else
            cm_json_number(f, r->item[i].num);
    }
    fputs("\n}\n", f);
    const int bad = ferror(f) != 0;
    if (fclose(f) != 0 || bad) {
        remove(tmp);
        return cm_fail(err, CM_ERR_IO, "%s: writing the run record failed", tmp);
    }
    if (rename(tmp, path) != 0) {
        const int e = errno;
        remove(tmp);
        return cm_fail(err, CM_ERR_IO, "%s: %s", path, strerror(e));
    }
    return CM_OK;
}
