/* Gmsh .msh v4.1 ASCII reader: 4-node tetrahedra (type 4) or 10-node ones
 * (type 11, fem.element = "tet10") form the body; physical groups named
 * "rim" (any dimension: their nodes are fixed), "cavity" and "contact"
 * (3- or 6-node triangles, type 2 or 9, on the boundary) give the named
 * sets. Everything read is checked: a malformed file gives an
 * error naming the file, the line and what was expected. */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fem_element.h"
#include "fem_model.h"
#include "log.h"

typedef struct reader {
    const char *p, *end, *name;
    int line;
    cm_error *err;
} reader;

typedef struct ent_flag {
    int dim, tag;
    unsigned flags; /* 1 rim, 2 cavity, 4 contact */
} ent_flag;

enum { G_RIM = 1, G_CAVITY = 2, G_CONTACT = 4 };

static void skip_space(reader *r)
{
    while (r->p < r->end && (*r->p == ' ' || *r->p == '\t' || *r->p == '\r' || *r->p == '\n')) {
        if (*r->p == '\n')
            r->line++;
        r->p++;
    }
}

/* Next whitespace-delimited token into buf; 0 on success. */
static int token(reader *r, char *buf, size_t len, const char *what)
{
    skip_space(r);
    if (r->p >= r->end)
        return cm_fail(r->err, CM_ERR_PARSE, "%s:%d: unexpected end of file, expected %s", r->name, r->line, what);
    size_t n = 0;
    while (r->p < r->end && !(*r->p == ' ' || *r->p == '\t' || *r->p == '\r' || *r->p == '\n')) {
        if (n + 1 >= len)
            return cm_fail(r->err, CM_ERR_PARSE, "%s:%d: expected %s, found a word longer than %zu characters",
                           r->name, r->line, what, len - 1);
        buf[n++] = *r->p++;
    }
    buf[n] = 0;
    return CM_OK;
}

static int read_long(reader *r, long *v, const char *what)
{
    char b[64], *e;
    int rc = token(r, b, sizeof b, what);
    if (rc)
        return rc;
    errno = 0;
    *v = strtol(b, &e, 10);
    if (*e || e == b || errno)
        return cm_fail(r->err, CM_ERR_PARSE, "%s:%d: expected an integer (%s), found \"%s\"", r->name, r->line, what,
                       b);
    return CM_OK;
}

/* An integer that must lie in [lo, hi] (tags and dimensions kept as int). */
static int read_long_in(reader *r, long *v, long lo, long hi, const char *what)
{
    int rc = read_long(r, v, what);
    if (rc)
        return rc;
    if (*v < lo || *v > hi)
        return cm_fail(r->err, CM_ERR_PARSE, "%s:%d: %s %ld outside [%ld, %ld]", r->name, r->line, what, *v, lo, hi);
    return CM_OK;
}

/* Bytes left to read: every item a count announces takes at least two
 * (a digit and a separator), so a count larger than this cannot be honest
 * and is refused before anything is allocated for it. */
static long bytes_left(const reader *r) { return (long)(r->end - r->p); }

static int read_double(reader *r, double *v, const char *what)
{
    char b[64], *e;
    int rc = token(r, b, sizeof b, what);
    if (rc)
        return rc;
    errno = 0;
    *v = strtod(b, &e);
    if (*e || e == b || errno || !isfinite(*v))
        return cm_fail(r->err, CM_ERR_PARSE, "%s:%d: expected a number (%s), found \"%s\"", r->name, r->line, what, b);
    return CM_OK;
}

static int expect(reader *r, const char *word)
{
    char b[64];
    int rc = token(r, b, sizeof b, word);
    if (rc)
        return rc;
    if (strcmp(b, word) != 0)
        return cm_fail(r->err, CM_ERR_PARSE, "%s:%d: expected %s, found \"%s\"", r->name, r->line, word, b);
    return CM_OK;
}

#define TRY(x)                                                                                                 \
    do {                                                                                                       \
        rc = (x);                                                                                              \
        if (rc)                                                                                                \
            goto done;                                                                                         \
    } while (0)

static int nodes_of_type(long type)
{
    switch (type) {
    case 15: return 1;  /* point */
    case 1: return 2;   /* line */
    case 2: return 3;   /* triangle */
    case 3: return 4;   /* quadrangle */
    case 4: return 4;   /* tetrahedron */
    case 5: return 8;   /* hexahedron */
    case 6: return 6;   /* prism */
    case 7: return 5;   /* pyramid */
    case 8: return 3;   /* 2nd order line */
    case 9: return 6;   /* 2nd order triangle */
    case 11: return 10; /* 2nd order tetrahedron */
    default: return -1;
    }
}

int fem_mesh_parse_gmsh(const char *text, size_t len, const char *name, fem_mesh *m, cm_error *err)
{
    reader r = {text, text + len, name, 1, err};
    int rc = CM_OK;
    char b[256];
    memset(m, 0, sizeof *m);
    /* physical groups of interest: (dim, tag) -> flag */
    int phys_dim[64], phys_tag[64];
    unsigned phys_flag[64];
    int n_phys = 0;
    ent_flag *ents = NULL;
    size_t n_ents = 0;
    double *xs = NULL;
    long *tag_to_index = NULL, min_tag = 0, max_tag = -1, n_nodes = 0, nodes_read = 0;
    long *tet_nodes = NULL, *tet_ids = NULL, n_tets = 0, cap_tets = 0;
    long *tet_mids = NULL; /* second-order tets (type 11): 6 mid-edge nodes each, in our order */
    int tet_type = 0;      /* 4 or 11, the first tetrahedra's; a mesh mixing both is refused */
    long *tri = NULL, n_tri = 0, cap_tri = 0; /* 3 node tags + flags + line */
    unsigned char *rim_tag = NULL;
    long *renum = NULL; /* file node index -> mesh node index, -1 if unused */
    bool have_nodes = false, have_elements = false, have_phys = false, have_ents = false;

    TRY(expect(&r, "$MeshFormat"));
    double version;
    long ftype, dsize;
    TRY(read_double(&r, &version, "format version"));
    TRY(read_long(&r, &ftype, "file type"));
    TRY(read_long(&r, &dsize, "data size"));
    if (version < 4.0 || version >= 5.0) {
        rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: MSH format %g not supported (need 4.x; save with "
                     "Mesh.MshFileVersion = 4.1)", name, r.line, version);
        goto done;
    }
    if (ftype != 0) {
        rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: binary MSH not supported, save as ASCII", name, r.line);
        goto done;
    }
    TRY(expect(&r, "$EndMeshFormat"));

    for (;;) {
        skip_space(&r);
        if (r.p >= r.end)
            break;
        TRY(token(&r, b, sizeof b, "a section"));
        int sec_line = r.line;
        bool *seen = !strcmp(b, "$PhysicalNames") ? &have_phys : !strcmp(b, "$Entities") ? &have_ents
                     : !strcmp(b, "$Nodes") ? &have_nodes : !strcmp(b, "$Elements") ? &have_elements : NULL;
        if (seen && *seen) {
            rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: section %s appears twice", name, sec_line, b);
            goto done;
        }
        if (strcmp(b, "$PhysicalNames") == 0) {
            long n;
            TRY(read_long(&r, &n, "number of physical names"));
            for (long i = 0; i < n; i++) {
                long dim, tag;
                TRY(read_long_in(&r, &dim, 0, 3, "physical dimension"));
                TRY(read_long_in(&r, &tag, 1, INT_MAX, "physical tag"));
                skip_space(&r);
                if (r.p >= r.end || *r.p != '"') {
                    rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: expected a quoted physical name", name, r.line);
                    goto done;
                }
                const char *q = ++r.p;
                while (r.p < r.end && *r.p != '"' && *r.p != '\n')
                    r.p++;
                if (r.p >= r.end || *r.p != '"') {
                    rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: unterminated physical name", name, r.line);
                    goto done;
                }
                size_t nl = (size_t)(r.p - q);
                r.p++;
                unsigned fl = nl == 3 && !strncmp(q, "rim", 3) ? G_RIM
                              : nl == 6 && !strncmp(q, "cavity", 6) ? G_CAVITY
                              : nl == 7 && !strncmp(q, "contact", 7) ? G_CONTACT : 0;
                if (fl && n_phys < 64) {
                    phys_dim[n_phys] = (int)dim;
                    phys_tag[n_phys] = (int)tag;
                    phys_flag[n_phys++] = fl;
                }
            }
            TRY(expect(&r, "$EndPhysicalNames"));
            have_phys = true;
        } else if (strcmp(b, "$Entities") == 0) {
            long cnt[4];
            for (int d = 0; d < 4; d++)
                TRY(read_long(&r, &cnt[d], "number of entities"));
            /* each count checked before they are added: no overflow */
            long total = 0;
            for (int d = 0; d < 4; d++) {
                if (cnt[d] < 0 || cnt[d] > bytes_left(&r) / 2) {
                    rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: bad entity counts (%ld of dimension %d, file has %ld "
                                 "bytes left)", name, r.line, cnt[d], d, bytes_left(&r));
                    goto done;
                }
                total += cnt[d];
            }
            ents = calloc(total ? (size_t)total : 1, sizeof *ents);
            if (!ents) {
                rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", name);
                goto done;
            }
            for (int d = 0; d < 4; d++)
                for (long i = 0; i < cnt[d]; i++) {
                    long tag, np, nb, pt;
                    double v;
                    TRY(read_long_in(&r, &tag, 1, INT_MAX, "entity tag"));
                    for (int k = 0; k < (d == 0 ? 3 : 6); k++)
                        TRY(read_double(&r, &v, "entity bounding box"));
                    TRY(read_long(&r, &np, "number of physical tags"));
                    unsigned fl = 0;
                    for (long k = 0; k < np; k++) {
                        TRY(read_long(&r, &pt, "physical tag"));
                        for (int q = 0; q < n_phys; q++)
                            if (phys_dim[q] == d && (pt == phys_tag[q] || pt == -(long)phys_tag[q]))
                                fl |= phys_flag[q];
                    }
                    if (d > 0) {
                        TRY(read_long(&r, &nb, "number of bounding entities"));
                        for (long k = 0; k < nb; k++)
                            TRY(read_long(&r, &pt, "bounding entity"));
                    }
                    ents[n_ents++] = (ent_flag){d, (int)tag, fl};
                }
            TRY(expect(&r, "$EndEntities"));
            have_ents = true;
        } else if (strcmp(b, "$Nodes") == 0) {
            long nb;
            TRY(read_long(&r, &nb, "number of node blocks"));
            TRY(read_long(&r, &n_nodes, "number of nodes"));
            TRY(read_long(&r, &min_tag, "minimum node tag"));
            TRY(read_long(&r, &max_tag, "maximum node tag"));
            /* a node takes at least 8 bytes (tag and three coordinates) */
            if (n_nodes < 1 || n_nodes > 100000000 || n_nodes > bytes_left(&r) / 8 || min_tag < 1 ||
                max_tag < min_tag || max_tag - min_tag > 10 * n_nodes + 1000) {
                rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: bad node counts/tags (%ld nodes, tags %ld..%ld, file has %ld "
                             "bytes left)", name, r.line, n_nodes, min_tag, max_tag, bytes_left(&r));
                goto done;
            }
            xs = malloc((size_t)n_nodes * 3 * sizeof *xs);
            tag_to_index = malloc((size_t)(max_tag - min_tag + 1) * sizeof *tag_to_index);
            rim_tag = calloc((size_t)n_nodes, 1);
            if (!xs || !tag_to_index || !rim_tag) {
                rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", name);
                goto done;
            }
            for (long i = 0; i <= max_tag - min_tag; i++)
                tag_to_index[i] = -1;
            for (long bl = 0; bl < nb; bl++) {
                long dim, etag, par, n;
                TRY(read_long(&r, &dim, "entity dimension"));
                TRY(read_long(&r, &etag, "entity tag"));
                TRY(read_long(&r, &par, "parametric flag"));
                TRY(read_long(&r, &n, "nodes in block"));
                if (par != 0) {
                    rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: parametric nodes not supported", name, r.line);
                    goto done;
                }
                if (n < 0 || nodes_read + n > n_nodes) {
                    rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: node block of %ld nodes exceeds the declared %ld", name,
                                 r.line, n, n_nodes);
                    goto done;
                }
                for (long i = 0; i < n; i++) {
                    long t;
                    TRY(read_long(&r, &t, "node tag"));
                    if (t < min_tag || t > max_tag || tag_to_index[t - min_tag] >= 0) {
                        rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: node tag %ld out of range %ld..%ld or repeated", name,
                                     r.line, t, min_tag, max_tag);
                        goto done;
                    }
                    tag_to_index[t - min_tag] = nodes_read + i;
                }
                for (long i = 0; i < n; i++)
                    for (int a = 0; a < 3; a++)
                        TRY(read_double(&r, &xs[3 * (nodes_read + i) + a], "node coordinate"));
                nodes_read += n;
            }
            if (nodes_read != n_nodes) {
                rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: %ld nodes declared, %ld read", name, r.line, n_nodes,
                             nodes_read);
                goto done;
            }
            TRY(expect(&r, "$EndNodes"));
            have_nodes = true;
        } else if (strcmp(b, "$Elements") == 0) {
            if (!have_nodes) {
                rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: $Elements before $Nodes", name, r.line);
                goto done;
            }
            long nb, ne, mn, mx;
            TRY(read_long(&r, &nb, "number of element blocks"));
            TRY(read_long(&r, &ne, "number of elements"));
            TRY(read_long(&r, &mn, "minimum element tag"));
            TRY(read_long(&r, &mx, "maximum element tag"));
            for (long bl = 0; bl < nb; bl++) {
                long dim, etag, type, n;
                TRY(read_long_in(&r, &dim, 0, 3, "entity dimension"));
                TRY(read_long_in(&r, &etag, 1, INT_MAX, "entity tag"));
                TRY(read_long(&r, &type, "element type"));
                TRY(read_long(&r, &n, "elements in block"));
                int nn = nodes_of_type(type);
                if (nn < 0) {
                    rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: element type %ld not supported", name, r.line, type);
                    goto done;
                }
                unsigned fl = 0;
                for (size_t q = 0; q < n_ents; q++)
                    if (ents[q].dim == (int)dim && ents[q].tag == (int)etag)
                        fl = ents[q].flags;
                for (long i = 0; i < n; i++) {
                    long id, nd[10];
                    TRY(read_long(&r, &id, "element tag"));
                    int eline = r.line;
                    for (int k = 0; k < nn; k++) {
                        long t;
                        TRY(read_long(&r, &t, "element node tag"));
                        if (t < min_tag || t > max_tag || tag_to_index[t - min_tag] < 0) {
                            rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: element %ld refers to unknown node %ld", name,
                                         r.line, id, t);
                            goto done;
                        }
                        nd[k] = tag_to_index[t - min_tag];
                    }
                    if (fl & G_RIM)
                        for (int k = 0; k < nn; k++)
                            rim_tag[nd[k]] = 1;
                    if (type == 4 || type == 11) {
                        if (tet_type != 0 && tet_type != type) {
                            rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: element %ld: first-order (type 4) and "
                                         "second-order (type 11) tetrahedra mixed in one mesh", name, r.line, id);
                            goto done;
                        }
                        tet_type = (int)type;
                        if (n_tets >= INT_MAX / 6) {
                            rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: more than %d tetrahedra", name, r.line,
                                         INT_MAX / 4);
                            goto done;
                        }
                        if (n_tets == cap_tets) {
                            cap_tets = cap_tets ? 2 * cap_tets : 1024;
                            long *t1 = realloc(tet_nodes, (size_t)cap_tets * 4 * sizeof *t1);
                            long *t2 = t1 ? realloc(tet_ids, (size_t)cap_tets * sizeof *t2) : NULL;
                            long *t3 = t2 && type == 11 ? realloc(tet_mids, (size_t)cap_tets * 6 * sizeof *t3)
                                                         : NULL;
                            if (t1)
                                tet_nodes = t1;
                            if (t2)
                                tet_ids = t2;
                            if (t3)
                                tet_mids = t3;
                            if (!t1 || !t2 || (type == 11 && !t3)) {
                                rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", name);
                                goto done;
                            }
                        }
                        memcpy(&tet_nodes[4 * n_tets], nd, 4 * sizeof *nd);
                        if (type == 11) {
                            /* Gmsh's 10-node tet: 4 (0,1), 5 (1,2), 6 (2,0), 7 (3,0), 8 (3,2),
                             * 9 (3,1); ours (fem_element.h) has (1,3) before (2,3) */
                            static const int g2o[6] = {4, 5, 6, 7, 9, 8};
                            for (int k = 0; k < 6; k++)
                                tet_mids[6 * n_tets + k] = nd[g2o[k]];
                        }
                        tet_ids[n_tets++] = id;
                    } else if ((type == 2 || type == 9) && (fl & (G_CAVITY | G_CONTACT))) {
                        if (n_tri == cap_tri) {
                            cap_tri = cap_tri ? 2 * cap_tri : 1024;
                            long *t1 = realloc(tri, (size_t)cap_tri * 6 * sizeof *t1);
                            if (!t1) {
                                rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", name);
                                goto done;
                            }
                            tri = t1;
                        }
                        long *q = &tri[6 * n_tri++];
                        q[0] = nd[0];
                        q[1] = nd[1];
                        q[2] = nd[2];
                        q[3] = fl;
                        q[4] = eline;
                        q[5] = id;
                    }
                }
            }
            TRY(expect(&r, "$EndElements"));
            have_elements = true;
        } else if (b[0] == '$' && strncmp(b, "$End", 4) != 0) {
            /* unknown section: skip to its $End<name> */
            char endw[260];
            snprintf(endw, sizeof endw, "$End%s", b + 1);
            for (;;) {
                rc = token(&r, b, sizeof b, endw);
                if (rc) {
                    rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: section opened here is not closed by %s", name, sec_line,
                                 endw);
                    goto done;
                }
                if (strcmp(b, endw) == 0)
                    break;
            }
        } else {
            rc = cm_fail(err, CM_ERR_PARSE, "%s:%d: expected a section ($Nodes, $Elements, ...), found \"%s\"", name,
                         r.line, b);
            goto done;
        }
    }
    if (!have_nodes || !have_elements || n_tets == 0) {
        rc = cm_fail(err, CM_ERR_PARSE, "%s: no %s", name,
                     !have_nodes      ? "$Nodes section"
                     : !have_elements ? "$Elements section"
                                      : "tetrahedra (type 4 or 11)");
        goto done;
    }
    /* Nodes no tetrahedron uses (Gmsh writes geometry points such as circle
     * centres as nodes) would have no mass and no stiffness: drop them. */
    renum = malloc((size_t)n_nodes * sizeof *renum);
    if (!renum) {
        rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", name);
        goto done;
    }
    for (long i = 0; i < n_nodes; i++)
        renum[i] = -1;
    for (long e = 0; e < 4 * n_tets; e++)
        renum[tet_nodes[e]] = 0;
    long n_used = 0;
    for (long i = 0; i < n_nodes; i++)
        if (renum[i] == 0)
            renum[i] = n_used++;
    long n_corner = n_used; /* corners first, then the mid-edge nodes (fem_mesh.h) */
    if (tet_mids) {
        for (long e = 0; e < 6 * n_tets; e++) {
            if (renum[tet_mids[e]] >= 0 && renum[tet_mids[e]] < n_corner) {
                rc = cm_fail(err, CM_ERR_PARSE, "%s: element %ld: node %ld is a corner and a mid-edge node", name,
                             tet_ids[e / 6], tet_mids[e] + min_tag);
                goto done;
            }
            if (renum[tet_mids[e]] < 0)
                renum[tet_mids[e]] = n_used++;
        }
    }
    TRY(fem_mesh_alloc(m, (int)n_used, (int)n_tets, err));
    m->n_corner = (int)n_corner;
    snprintf(m->source, sizeof m->source, "%s", name);
    int n_rim = 0;
    for (long i = 0; i < n_nodes; i++) {
        if (renum[i] < 0)
            continue;
        memcpy(&m->x[3 * renum[i]], &xs[3 * i], 3 * sizeof *xs);
        if (rim_tag[i]) {
            m->node_tag[renum[i]] |= FEM_NODE_RIM;
            n_rim++;
        }
    }
    for (long e = 0; e < 4 * n_tets; e++)
        m->tets[e] = (int32_t)renum[tet_nodes[e]];
    TRY(fem_mesh_finish(m, false, tet_ids, err));
    if (tet_mids) {
        m->tet_mid = malloc((size_t)6 * (size_t)n_tets * sizeof *m->tet_mid);
        if (!m->tet_mid) {
            rc = cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", name);
            goto done;
        }
        for (long e = 0; e < 6 * n_tets; e++)
            m->tet_mid[e] = (int32_t)renum[tet_mids[e]];
        /* A node order read wrongly (e.g. Gmsh's 8 and 9 taken as ours)
         * puts mid-edge nodes on other edges, half an edge away from their
         * own edge's midpoint on a regular tet: refuse a node farther than
         * 0.4 of its edge's length from the midpoint (a curved edge on a
         * 90-degree arc in one element has its node 0.21 lengths off). */
        for (long e = 0; e < n_tets; e++)
            for (int k = 0; k < 6; k++) {
                const double *p = &m->x[3 * m->tet_mid[6 * e + k]];
                const double *pa = &m->x[3 * m->tets[4 * e + fem_tet10_edges[k][0]]];
                const double *pb = &m->x[3 * m->tets[4 * e + fem_tet10_edges[k][1]]];
                double d2 = 0, l2 = 0;
                for (int q = 0; q < 3; q++) {
                    d2 += (p[q] - 0.5 * (pa[q] + pb[q])) * (p[q] - 0.5 * (pa[q] + pb[q]));
                    l2 += (pb[q] - pa[q]) * (pb[q] - pa[q]);
                }
                if (!(d2 < 0.16 * l2)) {
                    rc = cm_fail(err, CM_ERR_PARSE, "%s: second-order element %ld: mid-edge node %d lies %.3g edge "
                                 "lengths from its edge's midpoint (node order?)", name, tet_ids[e],
                                 k + 4, sqrt(d2 / l2));
                    goto done;
                }
            }
        TRY(fem_mesh_faces_quadratic(m, err));
    }
    for (long k = 0; k < n_tri; k++) {
        const long *q = &tri[6 * k];
        int f = fem_mesh_find_face(m, (int)renum[q[0]], (int)renum[q[1]], (int)renum[q[2]]);
        if (f < 0) {
            rc = cm_fail(err, CM_ERR_PARSE, "%s:%ld: triangle %ld of group %s is not a face of the tetrahedral "
                         "boundary", name, q[4], q[5], (q[3] & G_CAVITY) ? "cavity" : "contact");
            goto done;
        }
        m->face_tag[f] |= (uint8_t)(((q[3] & G_CAVITY) ? FEM_FACE_CAVITY : 0) |
                                    ((q[3] & G_CONTACT) ? FEM_FACE_CONTACT : 0));
    }
    if (n_rim == 0) {
        rc = cm_fail(err, CM_ERR_PARSE, "%s: no nodes in a physical group named \"rim\"", name);
        goto done;
    }
done:
    if (rc)
        fem_mesh_free(m);
    free(ents);
    free(xs);
    free(tag_to_index);
    free(tet_nodes);
    free(tet_ids);
    free(tet_mids);
    free(tri);
    free(rim_tag);
    free(renum);
    return rc;
}

int fem_mesh_read_gmsh(const char *path, fem_mesh *m, cm_error *err)
{
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return cm_fail(err, CM_ERR_IO, "cannot open the Gmsh mesh %s (fem.mesh.file): %s", path, strerror(errno));
    if (fseek(fp, 0, SEEK_END) != 0) {
        fclose(fp);
        return cm_fail(err, CM_ERR_IO, "%s: cannot seek", path);
    }
    long len = ftell(fp);
    rewind(fp);
    char *buf = malloc((size_t)(len > 0 ? len : 1));
    if (!buf) {
        fclose(fp);
        return cm_fail(err, CM_ERR_NOMEM, "%s: out of memory", path);
    }
    size_t got = fread(buf, 1, (size_t)len, fp);
    fclose(fp);
    if (len < 0 || got != (size_t)len) {
        free(buf);
        return cm_fail(err, CM_ERR_IO, "%s: read error", path);
    }
    int rc = fem_mesh_parse_gmsh(buf, got, path, m, err);
    free(buf);
    return rc;
}

/* Writes the mesh as .msh v4.1 ASCII: one volume entity (physical "tire"),
 * surface entities for rim, cavity and contact faces (physicals of those
 * names) and the remaining boundary. Coordinates as %.17g: reading the file
 * back gives the same doubles. */
int fem_mesh_write_gmsh(const fem_mesh *m, const char *path, cm_error *err)
{
    FILE *fp = fopen(path, "w");
    if (!fp)
        return cm_fail(err, CM_ERR_IO, "%s: %s", path, strerror(errno));
    /* surface entity of each face: 1 rim, 2 cavity, 3 contact, 4 other */
    int count[5] = {0, 0, 0, 0, 0};
    for (int f = 0; f < m->n_faces; f++) {
        uint8_t t = m->face_tag[f];
        count[(t & FEM_FACE_RIM) ? 1 : (t & FEM_FACE_CAVITY) ? 2 : (t & FEM_FACE_CONTACT) ? 3 : 4]++;
    }
    int n_blocks = 1;
    for (int s = 1; s <= 4; s++)
        n_blocks += count[s] > 0;
    fprintf(fp, "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n");
    fprintf(fp, "$PhysicalNames\n4\n2 1 \"rim\"\n2 2 \"cavity\"\n2 3 \"contact\"\n3 4 \"tire\"\n$EndPhysicalNames\n");
    fprintf(fp, "$Entities\n0 0 4 1\n");
    for (int s = 1; s <= 4; s++)
        fprintf(fp, "%d 0 0 0 0 0 0 %d %s 0\n", s, s < 4 ? 1 : 0, s == 1 ? "1" : s == 2 ? "2" : s == 3 ? "3" : "");
    fprintf(fp, "1 0 0 0 0 0 0 1 4 0\n$EndEntities\n");
    fprintf(fp, "$Nodes\n1 %d 1 %d\n3 1 0 %d\n", m->n_nodes, m->n_nodes, m->n_nodes);
    for (int n = 0; n < m->n_nodes; n++)
        fprintf(fp, "%d\n", n + 1);
    for (int n = 0; n < m->n_nodes; n++)
        fprintf(fp, "%.17g %.17g %.17g\n", m->x[3 * n], m->x[3 * n + 1], m->x[3 * n + 2]);
    fprintf(fp, "$EndNodes\n$Elements\n%d %d 1 %d\n", n_blocks, m->n_faces + m->n_tets, m->n_faces + m->n_tets);
    long id = 1;
    for (int s = 1; s <= 4; s++) {
        if (!count[s])
            continue;
        fprintf(fp, "2 %d %d %d\n", s, m->face_mid ? 9 : 2, count[s]);
        for (int f = 0; f < m->n_faces; f++) {
            uint8_t t = m->face_tag[f];
            int sf = (t & FEM_FACE_RIM) ? 1 : (t & FEM_FACE_CAVITY) ? 2 : (t & FEM_FACE_CONTACT) ? 3 : 4;
            if (sf != s)
                continue;
            int32_t nd[6];
            int nn = fem_mesh_face_nodes(m, f, nd); /* 6-node triangle: corners, then (0,1), (1,2), (2,0) */
            fprintf(fp, "%ld", id++);
            for (int q = 0; q < nn; q++)
                fprintf(fp, " %d", nd[q] + 1);
            fprintf(fp, "\n");
        }
    }
    fprintf(fp, "3 1 %d %d\n", m->tet_mid ? 11 : 4, m->n_tets);
    for (int e = 0; e < m->n_tets; e++) {
        int32_t nd[10];
        int nn = fem_mesh_tet_nodes(m, e, nd);
        static const int o2g[10] = {0, 1, 2, 3, 4, 5, 6, 7, 9, 8}; /* Gmsh's 8 is (2,3), its 9 (1,3) */
        fprintf(fp, "%ld", id++);
        for (int q = 0; q < nn; q++)
            fprintf(fp, " %d", nd[o2g[q]] + 1);
        fprintf(fp, "\n");
    }
    fprintf(fp, "$EndElements\n");
    if (ferror(fp) | (fclose(fp) != 0))
        return cm_fail(err, CM_ERR_IO, "%s: write error", path);
    return CM_OK;
}
