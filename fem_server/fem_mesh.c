/* Tetrahedral mesh: structured builders (box, tube, tire), orientation and
 * degeneracy checks, boundary surface extraction. */
#include "fem_mesh.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fem_element.h"

int fem_mesh_alloc(fem_mesh *m, int n_nodes, int n_tets, cm_error *err)
{
    memset(m, 0, sizeof *m);
    m->n_nodes = n_nodes;
    m->n_tets = n_tets;
    m->n_corner = n_nodes;
    m->x = calloc((size_t)3 * (size_t)(n_nodes > 0 ? n_nodes : 1), sizeof *m->x);
    m->tets = calloc((size_t)4 * (size_t)(n_tets > 0 ? n_tets : 1), sizeof *m->tets);
    m->node_tag = calloc((size_t)(n_nodes > 0 ? n_nodes : 1), 1);
    if (!m->x || !m->tets || !m->node_tag) {
        fem_mesh_free(m);
        return cm_fail(err, CM_ERR_NOMEM, "mesh: cannot allocate %d nodes, %d tets", n_nodes, n_tets);
    }
    return CM_OK;
}

void fem_mesh_free(fem_mesh *m)
{
    free(m->x);
    free(m->tets);
    free(m->faces);
    free(m->face_tet);
    free(m->face_tag);
    free(m->face_sorted);
    free(m->node_tag);
    free(m->node_ijk);
    free(m->tet_mid);
    free(m->face_mid);
    memset(m, 0, sizeof *m);
}

/* ---- Boundary extraction ------------------------------------------------ */

typedef struct face_rec {
    int32_t key[3]; /* sorted node triple */
    int32_t tet;
    int32_t local;  /* 0..3 */
} face_rec;

static int face_rec_cmp(const void *pa, const void *pb)
{
    const face_rec *a = pa, *b = pb;
    for (int k = 0; k < 3; k++)
        if (a->key[k] != b->key[k])
            return a->key[k] < b->key[k] ? -1 : 1;
    if (a->tet != b->tet)
        return a->tet < b->tet ? -1 : 1;
    return (a->local > b->local) - (a->local < b->local);
}

static void sort3(int32_t k[3])
{
    int32_t t;
    if (k[0] > k[1]) { t = k[0]; k[0] = k[1]; k[1] = t; }
    if (k[1] > k[2]) { t = k[1]; k[1] = k[2]; k[2] = t; }
    if (k[0] > k[1]) { t = k[0]; k[0] = k[1]; k[1] = t; }
}

/* Outward faces of a positively oriented tet (a,b,c,d). */
static const int k_tet_faces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};

static int extract_boundary(fem_mesh *m, cm_error *err)
{
    size_t nf = (size_t)4 * (size_t)m->n_tets;
    face_rec *rec = malloc(nf * sizeof *rec);
    if (!rec)
        return cm_fail(err, CM_ERR_NOMEM, "%s: cannot allocate face list", m->source);
    for (int e = 0; e < m->n_tets; e++)
        for (int f = 0; f < 4; f++) {
            face_rec *r = &rec[4 * (size_t)e + (size_t)f];
            for (int k = 0; k < 3; k++)
                r->key[k] = m->tets[4 * e + k_tet_faces[f][k]];
            sort3(r->key);
            r->tet = e;
            r->local = f;
        }
    qsort(rec, nf, sizeof *rec, face_rec_cmp);
    int n_bnd = 0;
    for (size_t i = 0; i < nf;) {
        size_t j = i + 1;
        while (j < nf && memcmp(rec[j].key, rec[i].key, sizeof rec[i].key) == 0)
            j++;
        if (j - i > 2) {
            int rc = cm_fail(err, CM_ERR_PARSE, "%s: face (%d,%d,%d) shared by more than two elements (%d, %d, ...): "
                             "non-manifold or duplicated element", m->source, rec[i].key[0], rec[i].key[1],
                             rec[i].key[2], rec[i].tet, rec[i + 2].tet);
            free(rec);
            return rc;
        }
        if (j - i == 1)
            n_bnd++;
        i = j;
    }
    m->n_faces = n_bnd;
    m->faces = malloc((size_t)3 * (size_t)(n_bnd ? n_bnd : 1) * sizeof *m->faces);
    m->face_tet = malloc((size_t)(n_bnd ? n_bnd : 1) * sizeof *m->face_tet);
    m->face_tag = calloc((size_t)(n_bnd ? n_bnd : 1), 1);
    m->face_sorted = malloc((size_t)(n_bnd ? n_bnd : 1) * sizeof *m->face_sorted);
    if (!m->faces || !m->face_tet || !m->face_tag || !m->face_sorted) {
        free(rec);
        return cm_fail(err, CM_ERR_NOMEM, "%s: cannot allocate boundary", m->source);
    }
    int b = 0;
    for (size_t i = 0; i < nf;) {
        size_t j = i + 1;
        while (j < nf && memcmp(rec[j].key, rec[i].key, sizeof rec[i].key) == 0)
            j++;
        if (j - i == 1) {
            int e = rec[i].tet, f = rec[i].local;
            for (int k = 0; k < 3; k++)
                m->faces[3 * b + k] = m->tets[4 * e + k_tet_faces[f][k]];
            m->face_tet[b] = e;
            m->face_sorted[b] = b; /* rec is sorted by key, so is this order */
            b++;
        }
        i = j;
    }
    free(rec);
    return CM_OK;
}

int fem_mesh_find_face(const fem_mesh *m, int a, int b, int c)
{
    int32_t key[3] = {a, b, c};
    sort3(key);
    int lo = 0, hi = m->n_faces - 1;
    while (lo <= hi) {
        int mid = (lo + hi) / 2;
        int32_t k2[3];
        memcpy(k2, &m->faces[3 * m->face_sorted[mid]], sizeof k2);
        sort3(k2);
        int c3 = 0;
        for (int k = 0; k < 3 && c3 == 0; k++)
            c3 = key[k] < k2[k] ? -1 : key[k] > k2[k] ? 1 : 0;
        if (c3 == 0)
            return m->face_sorted[mid];
        if (c3 < 0)
            hi = mid - 1;
        else
            lo = mid + 1;
    }
    return -1;
}

int fem_mesh_finish(fem_mesh *m, bool fix_orientation, const long *elem_ids, cm_error *err)
{
    for (int e = 0; e < m->n_tets; e++) {
        int32_t *t = &m->tets[4 * e];
        for (int k = 0; k < 4; k++)
            if (t[k] < 0 || t[k] >= m->n_nodes)
                return cm_fail(err, CM_ERR_RANGE, "%s: element %ld: node index %d out of range [0,%d)", m->source,
                               elem_ids ? elem_ids[e] : (long)e, t[k], m->n_nodes);
        const double *p[4] = {&m->x[3 * t[0]], &m->x[3 * t[1]], &m->x[3 * t[2]], &m->x[3 * t[3]]};
        double V = fem_tet_volume(p[0], p[1], p[2], p[3]);
        double lmax2 = 0.0;
        for (int a = 0; a < 4; a++)
            for (int c = a + 1; c < 4; c++) {
                double d2 = 0.0;
                for (int k = 0; k < 3; k++)
                    d2 += (p[a][k] - p[c][k]) * (p[a][k] - p[c][k]);
                lmax2 = d2 > lmax2 ? d2 : lmax2;
            }
        /* Degenerate: volume tiny compared with the cube of the longest edge
         * (a regular tet has V = 0.118 l^3). */
        if (!(fabs(V) > 1e-9 * lmax2 * sqrt(lmax2)))
            return cm_fail(err, CM_ERR_NUMERIC, "%s: element %ld has zero volume (%.3g m^3, longest edge %.3g m)",
                           m->source, elem_ids ? elem_ids[e] : (long)e, V, sqrt(lmax2));
        if (V < 0.0) {
            if (!fix_orientation)
                return cm_fail(err, CM_ERR_NUMERIC, "%s: element %ld is inverted (volume %.3g m^3)", m->source,
                               elem_ids ? elem_ids[e] : (long)e, V);
            int32_t s = t[2];
            t[2] = t[3];
            t[3] = s;
        }
    }
    return extract_boundary(m, err);
}

typedef struct dedge {
    int32_t lo, hi, dir;
} dedge;

static int dedge_cmp(const void *pa, const void *pb)
{
    const dedge *a = pa, *b = pb;
    if (a->lo != b->lo)
        return a->lo < b->lo ? -1 : 1;
    if (a->hi != b->hi)
        return a->hi < b->hi ? -1 : 1;
    return (a->dir > b->dir) - (a->dir < b->dir);
}

int fem_mesh_check_closed(const fem_mesh *m, cm_error *err)
{
    size_t ne = (size_t)3 * (size_t)m->n_faces;
    dedge *e = malloc((ne ? ne : 1) * sizeof *e);
    if (!e)
        return cm_fail(err, CM_ERR_NOMEM, "%s: cannot allocate edges", m->source);
    for (int f = 0; f < m->n_faces; f++)
        for (int k = 0; k < 3; k++) {
            int32_t a = m->faces[3 * f + k], b = m->faces[3 * f + (k + 1) % 3];
            e[3 * (size_t)f + (size_t)k] = (dedge){a < b ? a : b, a < b ? b : a, a < b ? 1 : -1};
        }
    qsort(e, ne, sizeof *e, dedge_cmp);
    int rc = CM_OK;
    for (size_t i = 0; i < ne; i += 2) {
        if (i + 1 >= ne || e[i].lo != e[i + 1].lo || e[i].hi != e[i + 1].hi || e[i].dir == e[i + 1].dir ||
            (i + 2 < ne && e[i + 2].lo == e[i].lo && e[i + 2].hi == e[i].hi)) {
            rc = cm_fail(err, CM_ERR_NUMERIC, "%s: boundary not closed/oriented at edge (%d,%d)", m->source, e[i].lo,
                         e[i].hi);
            break;
        }
    }
    free(e);
    return rc;
}

void fem_mesh_measure(const fem_mesh *m, double *h_min, double *volume)
{
    double h = INFINITY, vol = 0.0;
    for (int e = 0; e < m->n_tets; e++) {
        const int32_t *t = &m->tets[4 * e];
        double g[4][3];
        double V = fem_tet_gradients(&m->x[3 * t[0]], &m->x[3 * t[1]], &m->x[3 * t[2]], &m->x[3 * t[3]], g);
        vol += V;
        /* altitude over the face opposite node i is 1/|grad N_i| */
        for (int i = 0; i < 4; i++) {
            double a = 1.0 / sqrt(g[i][0] * g[i][0] + g[i][1] * g[i][1] + g[i][2] * g[i][2]);
            h = a < h ? a : h;
        }
    }
    if (h_min)
        *h_min = h;
    if (volume)
        *volume = vol;
}

/* ---- Structured grids --------------------------------------------------- */

static int grid_node(const fem_grid *g, int i, int j, int k)
{
    int nip = g->periodic_i ? g->ni : g->ni + 1;
    if (g->periodic_i)
        i %= g->ni;
    return (k * (g->nj + 1) + j) * nip + i;
}

static bool grid_cell(const fem_grid *g, int i, int j, int k)
{
    return g->cell == NULL || g->cell(g->ctx, i, j, k);
}

/* Largest mesh a grid may make: element and node indices are int, and
 * 4 * n_tets must stay below INT_MAX (tets[4 * e + k]). */
#define GRID_MAX_TETS 100000000.0

int fem_mesh_from_grid(const fem_grid *g, fem_mesh *m, cm_error *err)
{
    /* In double: ni * nj * nk overflows int long before memory runs out. */
    double n_tets_max = 6.0 * (double)g->ni * (double)g->nj * (double)g->nk;
    if (g->ni < 1 || g->nj < 1 || g->nk < 1 || n_tets_max > GRID_MAX_TETS)
        return cm_fail(err, CM_ERR_RANGE, "%s: %d x %d x %d cells make up to %.3g tetrahedra, more than the %.3g "
                       "allowed", m->source[0] ? m->source : "grid mesh", g->ni, g->nj, g->nk, n_tets_max,
                       GRID_MAX_TETS);
    int nip = g->periodic_i ? g->ni : g->ni + 1;
    size_t n_grid = (size_t)nip * (size_t)(g->nj + 1) * (size_t)(g->nk + 1);
    int32_t *id = malloc(n_grid * sizeof *id);
    if (!id)
        return cm_fail(err, CM_ERR_NOMEM, "grid: cannot allocate");
    for (size_t q = 0; q < n_grid; q++)
        id[q] = -1;
    int n_cells = 0;
    for (int k = 0; k < g->nk; k++)
        for (int j = 0; j < g->nj; j++)
            for (int i = 0; i < g->ni; i++)
                if (grid_cell(g, i, j, k)) {
                    n_cells++;
                    for (int c = 0; c < 8; c++)
                        id[grid_node(g, i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1))] = 0;
                }
    int n_nodes = 0;
    for (size_t q = 0; q < n_grid; q++)
        if (id[q] == 0)
            id[q] = n_nodes++;
    char src[256];
    snprintf(src, sizeof src, "%s", m->source[0] ? m->source : "grid mesh");
    int rc = fem_mesh_alloc(m, n_nodes, 6 * n_cells, err);
    if (rc) {
        free(id);
        return rc;
    }
    snprintf(m->source, sizeof m->source, "%s", src);
    m->node_ijk = malloc((size_t)3 * (size_t)(n_nodes ? n_nodes : 1) * sizeof *m->node_ijk);
    if (!m->node_ijk) {
        free(id);
        return cm_fail(err, CM_ERR_NOMEM, "grid: cannot allocate");
    }
    for (int k = 0; k <= g->nk; k++)
        for (int j = 0; j <= g->nj; j++)
            for (int i = 0; i < nip; i++) {
                int n = id[grid_node(g, i, j, k)];
                if (n < 0)
                    continue;
                g->map(g->ctx, (double)i, (double)j, (double)k, &m->x[3 * n]);
                m->node_ijk[3 * n] = i;
                m->node_ijk[3 * n + 1] = j;
                m->node_ijk[3 * n + 2] = k;
            }
    /* Kuhn split: one tet per permutation of the axes, walking from corner
     * 000 to 111 along the cell edges in that order. */
    static const int perm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    int e = 0;
    for (int k = 0; k < g->nk; k++)
        for (int j = 0; j < g->nj; j++)
            for (int i = 0; i < g->ni; i++) {
                if (!grid_cell(g, i, j, k))
                    continue;
                for (int p = 0; p < 6; p++) {
                    int c[3] = {0, 0, 0};
                    int32_t *t = &m->tets[4 * e];
                    t[0] = id[grid_node(g, i, j, k)];
                    for (int s = 0; s < 3; s++) {
                        c[perm[p][s]] = 1;
                        t[s + 1] = id[grid_node(g, i + c[0], j + c[1], k + c[2])];
                    }
                    e++;
                }
            }
    free(id);
    return fem_mesh_finish(m, true, NULL, err);
}

/* ---- Box ------------------------------------------------------------------ */

typedef struct box_ctx {
    double size[3];
    int n[3];
} box_ctx;

static void box_map(const void *ctx, double i, double j, double k, double x[3])
{
    const box_ctx *b = ctx;
    x[0] = b->size[0] * i / b->n[0];
    x[1] = b->size[1] * j / b->n[1];
    x[2] = b->size[2] * k / b->n[2];
}

/* Tags a face whose three nodes all have grid index `axis` == value. */
static bool face_on_plane(const fem_mesh *m, int f, int axis, int value)
{
    for (int c = 0; c < 3; c++)
        if (m->node_ijk[3 * m->faces[3 * f + c] + axis] != value)
            return false;
    return true;
}

int fem_mesh_box(const double size[3], const int cells[3], fem_mesh *m, cm_error *err)
{
    return fem_mesh_box_order(size, cells, 1, m, err);
}

static int check_order(int order, const char *what, cm_error *err)
{
    return order == 1 || order == 2 ? CM_OK
                                    : cm_fail(err, CM_ERR_RANGE, "%s: element order %d (1 or 2 expected)", what, order);
}

int fem_mesh_box_order(const double size[3], const int cells[3], int order, fem_mesh *m, cm_error *err)
{
    int rc = check_order(order, "box mesh", err);
    if (rc)
        return rc;
    for (int a = 0; a < 3; a++)
        if (!(size[a] > 0.0) || cells[a] < 1)
            return cm_fail(err, CM_ERR_RANGE, "box mesh: size and cells must be positive (axis %d)", a);
    box_ctx b = {{size[0], size[1], size[2]}, {cells[0], cells[1], cells[2]}};
    fem_grid g = {cells[0], cells[1], cells[2], false, box_map, NULL, &b};
    memset(m, 0, sizeof *m);
    snprintf(m->source, sizeof m->source, "box mesh");
    rc = fem_mesh_from_grid(&g, m, err);
    if (rc)
        return rc;
    for (int n = 0; n < m->n_nodes; n++)
        if (m->node_ijk[3 * n] == 0)
            m->node_tag[n] |= FEM_NODE_RIM;
    for (int f = 0; f < m->n_faces; f++) {
        if (face_on_plane(m, f, 0, 0))
            m->face_tag[f] |= FEM_FACE_RIM;
        if (face_on_plane(m, f, 2, 0))
            m->face_tag[f] |= FEM_FACE_CAVITY;
        if (face_on_plane(m, f, 2, cells[2]))
            m->face_tag[f] |= FEM_FACE_CONTACT;
    }
    return order == 2 ? fem_mesh_make_quadratic(m, &g, err) : CM_OK;
}

/* ---- Tube ----------------------------------------------------------------- */

typedef struct tube_ctx {
    double ri, ro, L;
    int nt, nr, nz;
} tube_ctx;

static void tube_map(const void *ctx, double i, double j, double k, double x[3])
{
    const tube_ctx *t = ctx;
    double th = 2.0 * M_PI * i / t->nt, r = t->ri + (t->ro - t->ri) * j / t->nr;
    x[0] = r * cos(th);
    x[1] = r * sin(th);
    x[2] = t->L * k / t->nz;
}

int fem_mesh_tube(double ri, double ro, double L, int n_theta, int n_r, int n_z, fem_mesh *m, cm_error *err)
{
    return fem_mesh_tube_order(ri, ro, L, n_theta, n_r, n_z, 1, m, err);
}

int fem_mesh_tube_order(double ri, double ro, double L, int n_theta, int n_r, int n_z, int order, fem_mesh *m,
                        cm_error *err)
{
    int rc = check_order(order, "tube mesh", err);
    if (rc)
        return rc;
    if (!(ri > 0.0 && ro > ri && L > 0.0) || n_theta < 3 || n_r < 1 || n_z < 1)
        return cm_fail(err, CM_ERR_RANGE, "tube mesh: need 0 < ri < ro, L > 0, n_theta >= 3");
    tube_ctx t = {ri, ro, L, n_theta, n_r, n_z};
    fem_grid g = {n_theta, n_r, n_z, true, tube_map, NULL, &t};
    memset(m, 0, sizeof *m);
    snprintf(m->source, sizeof m->source, "tube mesh");
    rc = fem_mesh_from_grid(&g, m, err);
    if (rc)
        return rc;
    for (int n = 0; n < m->n_nodes; n++)
        if (m->node_ijk[3 * n + 2] == 0 || m->node_ijk[3 * n + 2] == n_z)
            m->node_tag[n] |= FEM_NODE_RIM;
    for (int f = 0; f < m->n_faces; f++) {
        if (face_on_plane(m, f, 1, 0))
            m->face_tag[f] |= FEM_FACE_CAVITY;
        if (face_on_plane(m, f, 1, n_r))
            m->face_tag[f] |= FEM_FACE_CONTACT;
        if (face_on_plane(m, f, 2, 0) || face_on_plane(m, f, 2, n_z))
            m->face_tag[f] |= FEM_FACE_RIM;
    }
    return order == 2 ? fem_mesh_make_quadratic(m, &g, err) : CM_OK;
}

/* ---- Tire ----------------------------------------------------------------- */

fem_tire_def fem_tire_def_default(void)
{
    fem_tire_def d;
    d.outer_radius = 0.272; /* table 2 gives 0.544: that is the diameter */
    d.rim_radius = 0.1651;  /* 13 in / 2 */
    d.width = 0.165;
    d.wall = 0.016;
    d.lug_depth = 0.015;
    d.shoulder_radius = 0.025;
    d.lugs = 16;
    d.lug_fraction = 0.5;
    d.contact_depth = 0.06;
    d.resolution = 1.0;
    d.layers = 0;
    return d;
}

typedef struct tire_ctx {
    fem_tire_def d;
    double b;      /* mid-line half width of the sidewalls */
    double rt;     /* mid-line radius of the crown */
    int n_side, n_arc, n_flat, n_s;
    int n_theta, cpp, lug_cells; /* cells around, cells per pitch, cells per lug */
    int n_wall, n_lug;           /* layers through wall and lug */
    int n_groove;                /* crown cells each side of the centre line left without lugs */
} tire_ctx;

/* Mid-line point (y, r) and outward unit normal (away from the cavity) at
 * section grid line j. */
static void tire_section(const tire_ctx *t, double j, double p[2], double n[2])
{
    double rho = t->d.shoulder_radius, b = t->b, rt = t->rt, rr = t->d.rim_radius;
    int a0 = t->n_side, a1 = a0 + t->n_arc, f1 = a1 + t->n_flat, b1 = f1 + t->n_arc;
    if (j <= a0) { /* left sidewall, from the rim up */
        double s = j / t->n_side;
        p[0] = -b;
        p[1] = rr + s * (rt - rho - rr);
        n[0] = -1.0;
        n[1] = 0.0;
    } else if (j <= a1) { /* left shoulder: angle pi -> pi/2 */
        double phi = M_PI - 0.5 * M_PI * (double)(j - a0) / t->n_arc;
        n[0] = cos(phi);
        n[1] = sin(phi);
        p[0] = -b + rho + rho * n[0];
        p[1] = rt - rho + rho * n[1];
    } else if (j <= f1) { /* crown */
        double s = (double)(j - a1) / t->n_flat;
        p[0] = -b + rho + s * 2.0 * (b - rho);
        p[1] = rt;
        n[0] = 0.0;
        n[1] = 1.0;
    } else if (j <= b1) { /* right shoulder: pi/2 -> 0 */
        double phi = 0.5 * M_PI - 0.5 * M_PI * (double)(j - f1) / t->n_arc;
        n[0] = cos(phi);
        n[1] = sin(phi);
        p[0] = b - rho + rho * n[0];
        p[1] = rt - rho + rho * n[1];
    } else { /* right sidewall, down to the rim */
        double s = (double)(j - b1) / t->n_side;
        p[0] = b;
        p[1] = rt - rho + s * (rr - (rt - rho));
        n[0] = 1.0;
        n[1] = 0.0;
    }
}

static void tire_map(const void *ctx, double i, double j, double k, double x[3])
{
    const tire_ctx *t = ctx;
    double p[2], n[2];
    tire_section(t, j, p, n);
    double off = k <= t->n_wall ? -0.5 * t->d.wall + t->d.wall * k / t->n_wall
                                : 0.5 * t->d.wall + t->d.lug_depth * (k - t->n_wall) / t->n_lug;
    double y = p[0] + off * n[0], r = p[1] + off * n[1];
    double th = 2.0 * M_PI * i / t->n_theta;
    x[0] = r * cos(th);
    x[1] = y;
    x[2] = r * sin(th);
}

static bool tire_cell(const void *ctx, int i, int j, int k)
{
    const tire_ctx *t = ctx;
    if (k < t->n_wall)
        return true;
    if (j < t->n_side || j >= t->n_s - t->n_side)
        return false; /* lugs only on shoulders and crown */
    if (j >= t->n_s / 2 - t->n_groove && j < t->n_s / 2 + t->n_groove)
        return false; /* centre groove: left and right lugs would touch along an edge */
    int phase = j < t->n_s / 2 ? i % t->cpp : (i + t->cpp / 2) % t->cpp;
    return phase < t->lug_cells;
}

static int iround_min1(double v)
{
    long r = lround(v);
    return r < 1 ? 1 : (int)r;
}

int fem_mesh_tire(const fem_tire_def *d, fem_mesh *m, cm_error *err)
{
    return fem_mesh_tire_order(d, 1, m, err);
}

int fem_mesh_tire_order(const fem_tire_def *d, int order, fem_mesh *m, cm_error *err)
{
    int rc = check_order(order, "tire mesh", err);
    if (rc)
        return rc;
    tire_ctx t;
    memset(&t, 0, sizeof t);
    t.d = *d;
    t.rt = d->outer_radius - d->lug_depth - 0.5 * d->wall;
    /* lug tops span the tread width: b + wall/2 + lug_depth = width/2 */
    t.b = 0.5 * d->width - 0.5 * d->wall - d->lug_depth;
    if (!(d->resolution > 0.0 && d->resolution <= 16.0))
        return cm_fail(err, CM_ERR_RANGE, "tire mesh: resolution %g outside (0, 16]", d->resolution);
    if (!(d->wall > 0.0 && d->lug_depth >= 0.0 && d->shoulder_radius > 0.5 * d->wall &&
          t.b > d->shoulder_radius && t.rt - d->shoulder_radius > d->rim_radius && d->rim_radius > 0.0))
        return cm_fail(err, CM_ERR_RANGE,
                       "tire mesh: inconsistent geometry (need shoulder_radius > wall/2, crown half-width %.4g m > "
                       "shoulder_radius, shoulder start %.4g m > rim radius %.4g m)",
                       t.b, t.rt - d->shoulder_radius, d->rim_radius);
    if (d->lugs < 1 || !(d->lug_fraction > 0.0 && d->lug_fraction < 1.0))
        return cm_fail(err, CM_ERR_RANGE, "tire mesh: lugs >= 1 and 0 < lug_fraction < 1 required");
    double res = d->resolution;
    t.n_side = iround_min1(5.0 * res);
    t.n_arc = iround_min1(3.0 * res);
    t.n_flat = 2 * iround_min1(4.0 * res);
    if (t.n_flat < 4)
        t.n_flat = 4; /* room for the centre groove and a lug cell each side */
    t.n_s = 2 * t.n_side + 2 * t.n_arc + t.n_flat;
    /* The centre groove is a quarter of the crown at every integer
     * resolution (one cell each side at 1), so that resolutions 1, 2, 3, ...
     * mesh the same tire (uniform refinement; it was two cells at every
     * resolution, half the crown at 0.5 and an eighth at 2); other
     * resolutions round it: half the crown at 0.5, a third at 0.75 and 1.5. */
    t.n_groove = iround_min1(t.n_flat / 8.0);
    t.cpp = 2 * iround_min1(4.0 * res);
    t.n_theta = d->lugs * t.cpp;
    t.lug_cells = (int)lround(d->lug_fraction * t.cpp);
    if (t.lug_cells < 1)
        t.lug_cells = 1;
    if (t.lug_cells >= t.cpp)
        t.lug_cells = t.cpp - 1;
    if (d->layers < 0 || d->layers > 64)
        return cm_fail(err, CM_ERR_RANGE, "tire mesh: layers %d outside [0, 64] (0: round(resolution))", d->layers);
    t.n_wall = d->layers > 0 ? d->layers : iround_min1(res);
    t.n_lug = d->lug_depth > 0.0 ? t.n_wall : 0;
    fem_grid g = {t.n_theta, t.n_s, t.n_wall + t.n_lug, true, tire_map, tire_cell, &t};
    memset(m, 0, sizeof *m);
    snprintf(m->source, sizeof m->source, "tire mesh");
    rc = fem_mesh_from_grid(&g, m, err);
    if (rc)
        return rc;
    for (int n = 0; n < m->n_nodes; n++) {
        int j = m->node_ijk[3 * n + 1];
        if (j == 0 || j == t.n_s)
            m->node_tag[n] |= FEM_NODE_RIM;
    }
    /* Contact set: every outer face (not cavity, not rim) whose centroid lies
     * within contact_depth of the outer radius: lug tops, lug flanks, groove
     * bottoms and shoulders; the sidewalls below cannot reach the soil at the
     * sinkages of the paper (a few cm). */
    double r_min = d->outer_radius - d->contact_depth;
    for (int f = 0; f < m->n_faces; f++) {
        if (face_on_plane(m, f, 2, 0))
            m->face_tag[f] |= FEM_FACE_CAVITY;
        else if (face_on_plane(m, f, 1, 0) || face_on_plane(m, f, 1, t.n_s))
            m->face_tag[f] |= FEM_FACE_RIM;
        else {
            double c[3] = {0, 0, 0};
            for (int q = 0; q < 3; q++)
                for (int a = 0; a < 3; a++)
                    c[a] += m->x[3 * m->faces[3 * f + q] + a] / 3.0;
            if (sqrt(c[0] * c[0] + c[2] * c[2]) >= r_min)
                m->face_tag[f] |= FEM_FACE_CONTACT;
        }
    }
    return order == 2 ? fem_mesh_make_quadratic(m, &g, err) : CM_OK;
}

/* ---- Quadratic (10-node) meshes ----------------------------------------- */

int fem_mesh_tet_nodes(const fem_mesh *m, int e, int32_t nodes[10])
{
    memcpy(nodes, &m->tets[4 * (size_t)e], 4 * sizeof *nodes);
    if (!m->tet_mid)
        return 4;
    memcpy(nodes + 4, &m->tet_mid[6 * (size_t)e], 6 * sizeof *nodes);
    return 10;
}

int fem_mesh_face_nodes(const fem_mesh *m, int f, int32_t nodes[6])
{
    memcpy(nodes, &m->faces[3 * (size_t)f], 3 * sizeof *nodes);
    if (!m->face_mid)
        return 3;
    memcpy(nodes + 3, &m->face_mid[3 * (size_t)f], 3 * sizeof *nodes);
    return 6;
}

/* Mid-edge node of edge (a,b) of tet e, -1 when (a,b) is not one of its edges. */
static int32_t tet_edge_mid(const fem_mesh *m, int e, int32_t a, int32_t b)
{
    const int32_t *t = &m->tets[4 * (size_t)e];
    for (int k = 0; k < 6; k++) {
        int32_t p = t[fem_tet10_edges[k][0]], q = t[fem_tet10_edges[k][1]];
        if ((p == a && q == b) || (p == b && q == a))
            return m->tet_mid[6 * (size_t)e + (size_t)k];
    }
    return -1;
}

int fem_mesh_faces_quadratic(fem_mesh *m, cm_error *err)
{
    free(m->face_mid);
    m->face_mid = malloc((size_t)3 * (size_t)(m->n_faces ? m->n_faces : 1) * sizeof *m->face_mid);
    if (!m->face_mid)
        return cm_fail(err, CM_ERR_NOMEM, "%s: cannot allocate the faces' mid-edge nodes", m->source);
    for (int f = 0; f < m->n_faces; f++)
        for (int k = 0; k < 3; k++) {
            int32_t mid = tet_edge_mid(m, m->face_tet[f], m->faces[3 * f + k], m->faces[3 * f + (k + 1) % 3]);
            if (mid < 0)
                return cm_fail(err, CM_ERR_STATE, "%s: boundary face %d is not a face of its element %d", m->source,
                               f, m->face_tet[f]);
            m->face_mid[3 * f + k] = mid;
        }
    return CM_OK;
}

typedef struct edge_rec {
    int32_t lo, hi; /* corner nodes, lo < hi */
    int32_t slot;   /* 6 * tet + local edge */
} edge_rec;

static int edge_rec_cmp(const void *pa, const void *pb)
{
    const edge_rec *a = pa, *b = pb;
    if (a->lo != b->lo)
        return a->lo < b->lo ? -1 : 1;
    if (a->hi != b->hi)
        return a->hi < b->hi ? -1 : 1;
    return (a->slot > b->slot) - (a->slot < b->slot);
}

int fem_mesh_make_quadratic(fem_mesh *m, const fem_grid *g, cm_error *err)
{
    if (m->tet_mid)
        return CM_OK;
    if ((double)m->n_tets * 6.0 >= 2147483647.0)
        return cm_fail(err, CM_ERR_RANGE, "%s: %d tetrahedra are too many for 10-node elements", m->source,
                       m->n_tets);
    size_t ne = (size_t)6 * (size_t)m->n_tets;
    edge_rec *rec = malloc((ne ? ne : 1) * sizeof *rec);
    m->tet_mid = malloc((ne ? ne : 1) * sizeof *m->tet_mid);
    if (!rec || !m->tet_mid) {
        free(rec);
        return cm_fail(err, CM_ERR_NOMEM, "%s: cannot allocate the edge table", m->source);
    }
    for (int e = 0; e < m->n_tets; e++)
        for (int k = 0; k < 6; k++) {
            int32_t a = m->tets[4 * e + fem_tet10_edges[k][0]], b = m->tets[4 * e + fem_tet10_edges[k][1]];
            rec[6 * (size_t)e + (size_t)k] = (edge_rec){a < b ? a : b, a < b ? b : a, 6 * e + k};
        }
    qsort(rec, ne, sizeof *rec, edge_rec_cmp);
    size_t n_edges = 0;
    for (size_t i = 0; i < ne; i++)
        n_edges += i == 0 || rec[i].lo != rec[i - 1].lo || rec[i].hi != rec[i - 1].hi;
    if ((double)m->n_nodes + (double)n_edges >= 2147483647.0 / 3.0) {
        free(rec);
        return cm_fail(err, CM_ERR_RANGE, "%s: %zu edges: too many nodes for 10-node elements", m->source, n_edges);
    }
    int n_old = m->n_nodes, n_new = n_old + (int)n_edges;
    double *x = realloc(m->x, (size_t)3 * (size_t)n_new * sizeof *x);
    if (x)
        m->x = x;
    uint8_t *tag = x ? realloc(m->node_tag, (size_t)n_new) : NULL;
    if (tag)
        m->node_tag = tag;
    int32_t *ijk = NULL;
    if (tag && m->node_ijk) {
        ijk = realloc(m->node_ijk, (size_t)3 * (size_t)n_new * sizeof *ijk);
        if (ijk)
            m->node_ijk = ijk;
    }
    if (!x || !tag || (m->node_ijk && !ijk)) {
        free(rec);
        return cm_fail(err, CM_ERR_NOMEM, "%s: cannot allocate %d mid-edge nodes", m->source, (int)n_edges);
    }
    int32_t node = n_old - 1;
    for (size_t i = 0; i < ne; i++) {
        const edge_rec *r = &rec[i];
        if (i == 0 || r->lo != rec[i - 1].lo || r->hi != rec[i - 1].hi) {
            node++;
            const double *pa = &m->x[3 * r->lo], *pb = &m->x[3 * r->hi];
            double *p = &m->x[3 * node];
            if (g && m->node_ijk) {
                double idx[3];
                for (int a = 0; a < 3; a++) {
                    double ia = m->node_ijk[3 * r->lo + a], ib = m->node_ijk[3 * r->hi + a];
                    if (a == 0 && g->periodic_i && fabs(ia - ib) > 1.5) { /* across the seam: i = ni is i = 0 */
                        if (ia < ib)
                            ia += g->ni;
                        else
                            ib += g->ni;
                    }
                    idx[a] = 0.5 * (ia + ib);
                }
                g->map(g->ctx, idx[0], idx[1], idx[2], p);
            } else {
                for (int a = 0; a < 3; a++)
                    p[a] = 0.5 * (pa[a] + pb[a]);
            }
            m->node_tag[node] = 0;
            if (m->node_ijk)
                m->node_ijk[3 * node] = m->node_ijk[3 * node + 1] = m->node_ijk[3 * node + 2] = -1;
        }
        m->tet_mid[r->slot] = node;
    }
    free(rec);
    m->n_nodes = n_new;
    int rc = fem_mesh_faces_quadratic(m, err);
    if (rc)
        return rc;
    /* Tags: a mid-edge node is a rim node when its edge lies on a boundary
     * face whose corners are all rim nodes (an edge through the body between
     * two rim nodes is not on the rim). */
    for (int f = 0; f < m->n_faces; f++) {
        const int32_t *t = &m->faces[3 * f];
        uint8_t common = m->node_tag[t[0]] & m->node_tag[t[1]] & m->node_tag[t[2]];
        for (int k = 0; k < 3; k++)
            m->node_tag[m->face_mid[3 * f + k]] |= common;
    }
    return CM_OK;
}

int fem_mesh_face_load(const fem_mesh *m, int f, double an[6][3], double a[6])
{
    int32_t nd[6];
    int n = fem_mesh_face_nodes(m, f, nd);
    if (n == 3) {
        const double *p = &m->x[3 * nd[0]], *q = &m->x[3 * nd[1]], *r = &m->x[3 * nd[2]];
        double e1[3] = {q[0] - p[0], q[1] - p[1], q[2] - p[2]}, e2[3] = {r[0] - p[0], r[1] - p[1], r[2] - p[2]};
        double c[3] = {0.5 * (e1[1] * e2[2] - e1[2] * e2[1]), 0.5 * (e1[2] * e2[0] - e1[0] * e2[2]),
                       0.5 * (e1[0] * e2[1] - e1[1] * e2[0])};
        double A = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        for (int k = 0; k < 3; k++) {
            for (int d = 0; d < 3; d++)
                an[k][d] = c[d] / 3.0;
            a[k] = A / 3.0;
        }
        return 3;
    }
    /* 6-node triangle, x(s,t) = sum N_k x_k with L = (1-s-t, s, t); nodes
     * c0 c1 c2 m01 m12 m20. Strang-Fix/Dunavant 6-point rule, degree 4
     * (weights sum to 1, times the reference area 1/2). */
    static const double qa[2] = {0.445948490915965, 0.091576213509771};
    static const double qw[2] = {0.223381589678011, 0.109951743655322};
    memset(an, 0, 6 * sizeof an[0]);
    memset(a, 0, 6 * sizeof a[0]);
    for (int g = 0; g < 6; g++) {
        double u = qa[g / 3], L[3] = {u, u, u};
        L[g % 3] = 1.0 - 2.0 * u;
        double N[6] = {L[0] * (2 * L[0] - 1), L[1] * (2 * L[1] - 1), L[2] * (2 * L[2] - 1), 4 * L[0] * L[1],
                       4 * L[1] * L[2], 4 * L[2] * L[0]};
        /* dN/dL_i, then d/ds = d/dL1 - d/dL0, d/dt = d/dL2 - d/dL0 */
        double dL[6][3] = {{4 * L[0] - 1, 0, 0}, {0, 4 * L[1] - 1, 0}, {0, 0, 4 * L[2] - 1},
                           {4 * L[1], 4 * L[0], 0}, {0, 4 * L[2], 4 * L[1]}, {4 * L[2], 0, 4 * L[0]}};
        double xs[3] = {0, 0, 0}, xt[3] = {0, 0, 0};
        for (int k = 0; k < 6; k++)
            for (int d = 0; d < 3; d++) {
                xs[d] += (dL[k][1] - dL[k][0]) * m->x[3 * nd[k] + d];
                xt[d] += (dL[k][2] - dL[k][0]) * m->x[3 * nd[k] + d];
            }
        double c[3] = {xs[1] * xt[2] - xs[2] * xt[1], xs[2] * xt[0] - xs[0] * xt[2], xs[0] * xt[1] - xs[1] * xt[0]};
        double J = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]), w = 0.5 * qw[g / 3];
        for (int k = 0; k < 6; k++) {
            for (int d = 0; d < 3; d++)
                an[k][d] += w * N[k] * c[d];
            a[k] += w * N[k] * J;
        }
    }
    return 6;
}
