#include "csv.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

struct cm_csv {
    FILE *fp;
    int ncols;
    char *path;
};

static int name_ok(const char *s)
{
    return s && *s && !strpbrk(s, ",\"\r\n");
}

int cm_csv_create(const char *path, const char *const *columns, int ncols, cm_csv **out, cm_error *err)
{
    *out = NULL;
    if (!path || ncols < 1 || !columns)
        return cm_fail(err, CM_ERR_RANGE, "csv %s: need at least one column", path ? path : "(null)");
    for (int i = 0; i < ncols; i++)
        if (!name_ok(columns[i]))
            return cm_fail(err, CM_ERR_RANGE, "csv %s: column %d name \"%s\" is empty or contains ',', '\"' "
                           "or a line break", path, i, columns[i] ? columns[i] : "(null)");
    cm_csv *c = calloc(1, sizeof *c);
    if (!c || !(c->path = strdup(path))) {
        free(c);
        return cm_fail(err, CM_ERR_NOMEM, "csv %s: out of memory", path);
    }
    c->ncols = ncols;
    c->fp = fopen(path, "w");
    if (!c->fp) {
        int rc = cm_fail(err, CM_ERR_IO, "cannot create csv file %s: %s", path, strerror(errno));
        free(c->path);
        free(c);
        return rc;
    }
    for (int i = 0; i < ncols; i++)
        fprintf(c->fp, "%s%s", i ? "," : "", columns[i]);
    fputc('\n', c->fp);
    if (fflush(c->fp) != 0 || ferror(c->fp)) {
        int rc = cm_fail(err, CM_ERR_IO, "writing csv header to %s: %s", path, strerror(errno));
        fclose(c->fp);
        free(c->path);
        free(c);
        return rc;
    }
    *out = c;
    return CM_OK;
}

int cm_csv_rows(cm_csv *c, const double *values, long nrows, cm_error *err)
{
    if (!c || !c->fp)
        return cm_fail(err, CM_ERR_STATE, "csv: row written to a closed file");
    for (long r = 0; r < nrows; r++, values += c->ncols) {
        for (int i = 0; i < c->ncols; i++)
            fprintf(c->fp, "%s%.17g", i ? "," : "", values[i]);
        fputc('\n', c->fp);
    }
    if (fflush(c->fp) != 0 || ferror(c->fp))
        return cm_fail(err, CM_ERR_IO, "writing %s to csv file %s: %s", nrows == 1 ? "a row" : "rows", c->path,
                       strerror(errno));
    return CM_OK;
}

int cm_csv_row(cm_csv *c, const double *values, cm_error *err)
{
    return cm_csv_rows(c, values, 1, err);
}

int cm_csv_close(cm_csv **cp, cm_error *err)
{
    if (!cp || !*cp)
        return CM_OK;
    cm_csv *c = *cp;
    int rc = CM_OK;
    if (c->fp && fclose(c->fp) != 0)
        rc = cm_fail(err, CM_ERR_IO, "closing csv file %s: %s", c->path, strerror(errno));
    free(c->path);
    free(c);
    *cp = NULL;
    return rc;
}

const char *cm_csv_path(const cm_csv *c)
{
    return c ? c->path : NULL;
}

int cm_csv_reopen(const char *path, int ncols, long rows, cm_csv **out, cm_error *err)
{
    *out = NULL;
    if (!path || ncols < 1 || rows < 0)
        return cm_fail(err, CM_ERR_RANGE, "csv %s: bad arguments to reopen", path ? path : "(null)");
    cm_csv *c = calloc(1, sizeof *c);
    if (!c || !(c->path = strdup(path))) {
        free(c);
        return cm_fail(err, CM_ERR_NOMEM, "csv %s: out of memory", path);
    }
    c->ncols = ncols;
    int rc = CM_OK;
    if (!(c->fp = fopen(path, "r+"))) {
        rc = cm_fail(err, CM_ERR_IO, "cannot reopen csv file %s: %s", path, strerror(errno));
        goto fail;
    }
    /* The end of line 1 + rows (the header and the kept rows). */
    long lines = 0, want = rows + 1;
    int ch;
    while (lines < want && (ch = getc(c->fp)) != EOF)
        lines += ch == '\n';
    if (lines < want) {
        rc = cm_fail(err, CM_ERR_IO, "csv file %s holds %ld complete rows, the checkpoint expects %ld", path,
                     lines > 0 ? lines - 1 : 0, rows);
        goto fail;
    }
    long pos = ftell(c->fp);
    if (pos < 0 || fflush(c->fp) != 0 || ftruncate(fileno(c->fp), pos) != 0 || fseek(c->fp, pos, SEEK_SET) != 0) {
        rc = cm_fail(err, CM_ERR_IO, "cutting csv file %s back to %ld rows: %s", path, rows, strerror(errno));
        goto fail;
    }
    *out = c;
    return CM_OK;
fail:
    if (c->fp)
        fclose(c->fp);
    free(c->path);
    free(c);
    return rc;
}
