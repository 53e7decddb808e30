/* common/h5io: the XDMF 3 index beside a results file, written in full
 * (atomically) or appended one step at a time (h5io.h, Durability). */
#include "h5io_impl.h"

/* ---- growing text buffer for the XDMF ---------------------------------------- */

typedef struct strbuf {
    char *s;
    size_t len, cap;
    int oom;
} strbuf;

static void sb_printf(strbuf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void sb_printf(strbuf *b, const char *fmt, ...)
{
    if (b->oom)
        return;
    for (;;) {
        va_list ap;
        va_start(ap, fmt);
        int n = vsnprintf(b->s ? b->s + b->len : NULL, b->s ? b->cap - b->len : 0, fmt, ap);
        va_end(ap);
        if (n < 0) {
            b->oom = 1;
            return;
        }
        if (b->s && b->len + (size_t)n < b->cap) {
            b->len += (size_t)n;
            return;
        }
        size_t cap = b->cap ? b->cap : 4096;
        while (cap <= b->len + (size_t)n)
            cap *= 2;
        char *s = realloc(b->s, cap);
        if (!s) {
            b->oom = 1;
            return;
        }
        b->s = s;
        b->cap = cap;
    }
}

/* Text with XML's five special characters escaped. */
static void sb_xml(strbuf *b, const char *s)
{
    for (; *s; s++) {
        switch (*s) {
        case '&': sb_printf(b, "&amp;"); break;
        case '<': sb_printf(b, "&lt;"); break;
        case '>': sb_printf(b, "&gt;"); break;
        case '"': sb_printf(b, "&quot;"); break;
        case '\'': sb_printf(b, "&apos;"); break;
        default: sb_printf(b, "%c", *s);
        }
    }
}


static void xdmf_item(strbuf *b, const cm_h5 *f, const char *indent, const char *path, int is_int, size_t n,
                      int ncomp)
{
    sb_printf(b, "%s<DataItem Dimensions=\"%zu", indent, n);
    if (ncomp > 1)
        sb_printf(b, " %d", ncomp);
    sb_printf(b, "\" NumberType=\"%s\" Precision=\"%d\" Format=\"HDF\">", is_int ? "Int" : "Float",
              is_int ? 4 : 8);
    sb_xml(b, f->base);
    sb_printf(b, ":%s</DataItem>\n", path);
}

static void xdmf_step(strbuf *b, const cm_h5 *f, const step_rec *r)
{
    char group[32], path[sizeof group + NAME_MAX_LEN + 2];
    snprintf(group, sizeof group, "/steps/%06ld", r->step);
    sb_printf(b, "      <Grid Name=\"step_%06ld\" GridType=\"Uniform\">\n", r->step);
    sb_printf(b, "        <Time Value=\"%.17g\"/>\n", r->time);
    if (f->xdmf == CM_H5_XDMF_POLYVERTEX) {
        sb_printf(b, "        <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"%zu\" "
                     "NodesPerElement=\"1\">\n", r->npoints);
        if (r->npoints == f->vertex_ids_len) {
            xdmf_item(b, f, "          ", "/xdmf/vertex_ids", 1, r->npoints, 1);
        } else { /* the first npoints of the shared ids */
            sb_printf(b, "          <DataItem ItemType=\"HyperSlab\" Dimensions=\"%zu\" Type=\"HyperSlab\">\n",
                      r->npoints);
            sb_printf(b, "            <DataItem Dimensions=\"3 1\" Format=\"XML\">0 1 %zu</DataItem>\n",
                      r->npoints);
            xdmf_item(b, f, "            ", "/xdmf/vertex_ids", 1, f->vertex_ids_len, 1);
            sb_printf(b, "          </DataItem>\n");
        }
    } else {
        sb_printf(b, "        <Topology TopologyType=\"Tetrahedron\" NumberOfElements=\"%zu\">\n", r->ncells);
        xdmf_item(b, f, "          ", f->connectivity, 1, r->ncells, 4);
    }
    sb_printf(b, "        </Topology>\n");
    sb_printf(b, "        <Geometry GeometryType=\"XYZ\">\n");
    if (f->geometry_static) {
        xdmf_item(b, f, "          ", f->geometry, 0, r->npoints, 3);
    } else {
        snprintf(path, sizeof path, "%s/%s", group, f->geometry);
        xdmf_item(b, f, "          ", path, 0, r->npoints, 3);
    }
    sb_printf(b, "        </Geometry>\n");
    for (size_t i = r->first; i < r->first + r->count; i++) {
        const field *fl = &f->fields[i];
        if (fl->center == CM_H5_UNLISTED || (!f->geometry_static && strcmp(fl->name, f->geometry) == 0))
            continue;
        const char *type = fl->ncomp == 1 ? "Scalar" : fl->ncomp == 3 ? "Vector" : fl->ncomp == 6 ? "Tensor6"
                                                                                                  : "Tensor";
        sb_printf(b, "        <Attribute Name=\"%s\" AttributeType=\"%s\" Center=\"%s\">\n", fl->name, type,
                  fl->center == CM_H5_NODE ? "Node" : "Cell");
        snprintf(path, sizeof path, "%s/%s", group, fl->name);
        xdmf_item(b, f, "          ", path, fl->is_int, fl->n, fl->ncomp);
        sb_printf(b, "        </Attribute>\n");
    }
    sb_printf(b, "      </Grid>\n");
}

static const char k_xdmf_tail[] = "    </Grid>\n  </Domain>\n</Xdmf>\n";

/* Writes all of buf at offset off of fd. */
static int write_at(int fd, const char *buf, size_t len, off_t off, const char *path, cm_error *err)
{
    size_t done = 0;
    while (done < len) {
        ssize_t w = pwrite(fd, buf + done, len - done, off + (off_t)done);
        if (w < 0 && errno == EINTR)
            continue;
        if (w < 0)
            return cm_fail(err, CM_ERR_IO, "writing %s: %s", path, strerror(errno));
        done += (size_t)w;
    }
    return CM_OK;
}

/* Writes the whole XDMF to a temporary file, syncs it and renames it over
 * the old one: a reader sees either the old or the new index, never half.
 * The new file is then kept open for h5io_xdmf_append. */
int h5io_write_xdmf(cm_h5 *f, cm_error *err)
{
    if (f->xmf_fd >= 0) {
        close(f->xmf_fd);
        f->xmf_fd = -1;
    }
    strbuf b = {0};
    sb_printf(&b, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n");
    sb_printf(&b, "<Xdmf Version=\"3.0\">\n  <Domain>\n");
    sb_printf(&b, "    <Grid Name=\"%s\" GridType=\"Collection\" CollectionType=\"Temporal\">\n", f->grid_name);
    for (size_t i = 0; i < f->nsteps; i++)
        xdmf_step(&b, f, &f->steps[i]);
    size_t body = b.len;
    sb_printf(&b, "%s", k_xdmf_tail);
    if (b.oom) {
        free(b.s);
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->xmf_path);
    }
    size_t tlen = strlen(f->xmf_path) + 5;
    char *tmp = malloc(tlen);
    if (!tmp) {
        free(b.s);
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->xmf_path);
    }
    snprintf(tmp, tlen, "%s.tmp", f->xmf_path);
    int rc = CM_OK;
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) {
        rc = cm_fail(err, CM_ERR_IO, "cannot create %s: %s", tmp, strerror(errno));
    } else {
        rc = write_at(fd, b.s, b.len, 0, tmp, err);
        if (rc == CM_OK && fsync(fd) != 0)
            rc = cm_fail(err, CM_ERR_IO, "syncing %s: %s", tmp, strerror(errno));
        if (rc == CM_OK && rename(tmp, f->xmf_path) != 0)
            rc = cm_fail(err, CM_ERR_IO, "renaming %s to %s: %s", tmp, f->xmf_path, strerror(errno));
        if (rc != CM_OK) {
            close(fd);
            unlink(tmp);
        } else { /* the descriptor now names the renamed file */
            f->xmf_fd = fd;
            f->xmf_end = (off_t)body;
            f->xmf_ids_len = f->vertex_ids_len;
        }
    }
    free(tmp);
    free(b.s);
    return rc;
}

/* Adds the last step to the XDMF: its grid and the closing tags written
 * over the old closing tags, in one write (no rewrite of the earlier steps:
 * rewriting the whole index after every step made output time grow with
 * the square of the steps). Written in place, the index is not atomic as a
 * full rewrite is; a reader catching the moment of the write sees a
 * truncated file and reads again, and a process killed mid-write is rare
 * (one small write) and repaired when the run is resumed (cm_h5_reopen
 * rewrites it). Falls back to the full rewrite when the shared vertex ids
 * grew (earlier steps list their length) or nothing is open yet. */
int h5io_xdmf_append(cm_h5 *f, cm_error *err)
{
    if (f->xmf_fd < 0 || f->xmf_ids_len != f->vertex_ids_len)
        return h5io_write_xdmf(f, err);
    strbuf b = {0};
    xdmf_step(&b, f, &f->steps[f->nsteps - 1]);
    size_t step_len = b.len;
    sb_printf(&b, "%s", k_xdmf_tail);
    if (b.oom) {
        free(b.s);
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", f->xmf_path);
    }
    int rc = write_at(f->xmf_fd, b.s, b.len, f->xmf_end, f->xmf_path, err);
    if (rc == CM_OK)
        f->xmf_end += (off_t)step_len;
    free(b.s);
    return rc;
}
