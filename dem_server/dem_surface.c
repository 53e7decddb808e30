#include "dem_surface.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "dem_contact.h"
#include "dem_shape.h"
#include "dem_world.h"
#include "log.h"
#include "vec3.h"

int dem_closest_on_triangle(const double p[3], const double a[3], const double b[3], const double c[3],
                            double bary[3], double cp[3])
{
    vec3 A = v3_load(a), B = v3_load(b), C = v3_load(c), P = v3_load(p);
    vec3 ab = v3_sub(B, A), ac = v3_sub(C, A), ap = v3_sub(P, A);
    double u, v, w;
    int region;
    double d1 = v3_dot(ab, ap), d2 = v3_dot(ac, ap);
    vec3 bp = v3_sub(P, B);
    double d3 = v3_dot(ab, bp), d4 = v3_dot(ac, bp);
    vec3 cpv = v3_sub(P, C);
    double d5 = v3_dot(ab, cpv), d6 = v3_dot(ac, cpv);
    double vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
    if (d1 <= 0.0 && d2 <= 0.0) {
        u = 1, v = 0, w = 0, region = 4;
    } else if (d3 >= 0.0 && d4 <= d3) {
        u = 0, v = 1, w = 0, region = 5;
    } else if (d6 >= 0.0 && d5 <= d6) {
        u = 0, v = 0, w = 1, region = 6;
    } else if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
        v = d1 / (d1 - d3), u = 1.0 - v, w = 0, region = 1;
    } else if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
        w = d2 / (d2 - d6), u = 1.0 - w, v = 0, region = 3;
    } else if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6)), v = 1.0 - w, u = 0, region = 2;
    } else if (va + vb + vc > 0.0) {
        double den = 1.0 / (va + vb + vc);
        v = vb * den, w = vc * den, u = 1.0 - v - w, region = 0;
    } else { /* degenerate (zero-area) triangle: its first vertex */
        u = 1, v = 0, w = 0, region = 4;
    }
    bary[0] = u, bary[1] = v, bary[2] = w;
    /* the contact point IS the barycentric combination, so that node forces
     * w_k F reproduce the contact's moment exactly (eq. 42) */
    for (int k = 0; k < 3; k++)
        cp[k] = u * a[k] + v * b[k] + w * c[k];
    return region;
}

/* ---- BVH --------------------------------------------------------------- */

/* Plain comparisons: fmin/fmax are library calls (NaN rules) and were 3 % of
 * a coupled run's DEM time in the refit; node positions are finite here. */
static inline double min2(double a, double b) { return a < b ? a : b; }
static inline double max2(double a, double b) { return a > b ? a : b; }

static void tri_bounds(const dem_surface *s, int t, double lo[3], double hi[3])
{
    const int *n = s->tri + 3 * t;
    for (int k = 0; k < 3; k++) {
        double a = s->x[3 * n[0] + k], b = s->x[3 * n[1] + k], c = s->x[3 * n[2] + k];
        lo[k] = min2(a, min2(b, c));
        hi[k] = max2(a, max2(b, c));
    }
}

static double centroid(const dem_surface *s, int t, int k)
{
    const int *n = s->tri + 3 * t;
    return (s->x[3 * n[0] + k] + s->x[3 * n[1] + k] + s->x[3 * n[2] + k]) / 3.0;
}

/* in-place median split of perm[lo..hi) on centroid axis (simple quickselect) */
static void select_median(const dem_surface *s, int *perm, int lo, int hi, int kth, int axis)
{
    while (hi - lo > 1) {
        double pivot = centroid(s, perm[(lo + hi) / 2], axis);
        int i = lo, j = hi - 1;
        while (i <= j) {
            while (centroid(s, perm[i], axis) < pivot)
                i++;
            while (centroid(s, perm[j], axis) > pivot)
                j--;
            if (i <= j) {
                int t = perm[i];
                perm[i] = perm[j];
                perm[j] = t;
                i++;
                j--;
            }
        }
        if (kth <= j)
            hi = j + 1;
        else if (kth >= i)
            lo = i;
        else
            return;
    }
}

static int bvh_build(dem_surface *s, int lo, int hi)
{
    int node = s->n_bvh++;
    dem_bvh_node *nd = &s->bvh[node];
    nd->right = -1;
    nd->first = lo;
    nd->count = hi - lo;
    if (hi - lo <= 2)
        return node;
    double clo[3] = {INFINITY, INFINITY, INFINITY}, chi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = lo; i < hi; i++)
        for (int k = 0; k < 3; k++) {
            double c = centroid(s, s->perm[i], k);
            clo[k] = fmin(clo[k], c);
            chi[k] = fmax(chi[k], c);
        }
    int axis = 0;
    for (int k = 1; k < 3; k++)
        if (chi[k] - clo[k] > chi[axis] - clo[axis])
            axis = k;
    int mid = (lo + hi) / 2;
    select_median(s, s->perm, lo, hi, mid, axis);
    bvh_build(s, lo, mid);
    int r = bvh_build(s, mid, hi);
    s->bvh[node].right = r;
    s->bvh[node].count = 0;
    return node;
}

void dem_surface_moved(dem_surface *s)
{
    dem_bvh_node *root = &s->bvh[0];
    const double *x = s->x;
    const int *bn = s->box_nodes;
    double lo[3] = {x[3 * bn[0]], x[3 * bn[0] + 1], x[3 * bn[0] + 2]}, hi[3] = {lo[0], lo[1], lo[2]};
    for (int k = 1; k < s->n_box_nodes; k++)
        for (int c = 0; c < 3; c++) {
            const double v = x[3 * bn[k] + c];
            lo[c] = min2(lo[c], v), hi[c] = max2(hi[c], v);
        }
    memcpy(root->lo, lo, sizeof lo);
    memcpy(root->hi, hi, sizeof hi);
    s->tree_stale = 1;
}

void dem_surface_refit(dem_surface *s)
{
    s->tree_stale = 0;
    for (int i = s->n_bvh - 1; i >= 0; i--) {
        dem_bvh_node *nd = &s->bvh[i];
        if (nd->right < 0) {
            tri_bounds(s, s->perm[nd->first], nd->lo, nd->hi);
            for (int t = 1; t < nd->count; t++) {
                double lo[3], hi[3];
                tri_bounds(s, s->perm[nd->first + t], lo, hi);
                for (int k = 0; k < 3; k++) {
                    nd->lo[k] = min2(nd->lo[k], lo[k]);
                    nd->hi[k] = max2(nd->hi[k], hi[k]);
                }
            }
        } else {
            const dem_bvh_node *a = &s->bvh[i + 1], *b = &s->bvh[nd->right];
            for (int k = 0; k < 3; k++) {
                nd->lo[k] = min2(a->lo[k], b->lo[k]);
                nd->hi[k] = max2(a->hi[k], b->hi[k]);
            }
        }
    }
}

/* ---- per-thread candidate buffers --------------------------------------- */

typedef struct cand {
    int tri, region;
    double bary[3], p[3], d2;
    int keep, near; /* near: index in the list of every triangle touched */
    int patch;      /* merge_patches: the kept contact whose patch this candidate shares */
    double w;       /* its share of that contact's reaction (unnormalised, kept one 1) */
} cand;

/* One thread's buffers for one grain's candidates, `cap` of each. They grow
 * (doubling) inside the surface pass when a grain meets more triangles: a
 * rare event, logged once per new size after the pass. */
struct dem_surf_scratch {
    int cap;
    cand *cd, *cd2;
    int *near, *comp, *kidx;     /* every touched triangle; union-find parent; kept candidates */
    double (*sh_n)[3], *sh_depth, *sh_r, (*pu)[3]; /* shaped grains' side arrays */
    int *slot_of;
    vec3 *nrm, *peff;
    int n_shared;                /* candidates after the kept ones that share their reaction */
    int grew_grain;              /* slot of the grain that last grew them this pass, -1 none */
    int ccd_failed_grain, ccd_failed_tri; /* libccd failed on this grain and triangle this pass, -1 none */
    int nomem;                   /* a growth failed this pass */
    /* what the thread's contacts give the surface, in grain order, replayed
     * after the pass (surf_replay): per contact its totals (surf_rec), per
     * touched node the force added (node_add). Grown (doubling) when full. */
    struct surf_rec *rec;
    struct node_add *na;
    int n_rec, rec_cap, n_na, na_cap;
    /* the thread's triangle lists (surface neighbour lists, see
     * dem_surface_contacts): the grains of its range that have one, in
     * ascending slot order, list k in ltri[lstart[k] .. lstart[k + 1]) */
    int *lgrain, *lstart, *ltri;
    int n_lg, lg_cap, ls_cap, n_lt, lt_cap;
};
typedef struct dem_surf_scratch surf_scratch;

/* One contact's share of the surface totals (dem_surface_total). */
typedef struct surf_rec {
    double fs[3], mom[3]; /* reaction on the surface, its moment about the reference point */
    double along, overlap; /* reaction along the travel direction; overlap / radius */
    double energy;        /* J, the contact's stored Hertz energy */
    int n_nodes;          /* node_add entries of the contact, following the previous contact's */
    int grain, tri;       /* slot of the grain and the contact's triangle (the guard names them) */
} surf_rec;

/* A node's force from one contact (barycentric share, eq. 42). */
typedef struct node_add {
    int node;
    double f[3];
} node_add;

/* Room for one more contact with up to n_nodes node entries (0, or the
 * contact is dropped and nomem set). */
static int record_room(surf_scratch *sc, int n_nodes)
{
    if (sc->n_rec == sc->rec_cap) {
        int cap = sc->rec_cap ? 2 * sc->rec_cap : 256;
        surf_rec *r = realloc(sc->rec, (size_t)cap * sizeof *r);
        if (!r)
            return sc->nomem = 1, CM_ERR_NOMEM;
        sc->rec = r, sc->rec_cap = cap;
    }
    while (sc->n_na + n_nodes > sc->na_cap) {
        int cap = sc->na_cap ? 2 * sc->na_cap : 1024;
        node_add *a = realloc(sc->na, (size_t)cap * sizeof *a);
        if (!a)
            return sc->nomem = 1, CM_ERR_NOMEM;
        sc->na = a, sc->na_cap = cap;
    }
    return CM_OK;
}

static void scratch_free(surf_scratch *sc)
{
    free(sc->cd), free(sc->cd2), free(sc->near), free(sc->comp), free(sc->kidx), free(sc->sh_n), free(sc->sh_depth);
    free(sc->sh_r), free(sc->pu), free(sc->slot_of), free(sc->nrm), free(sc->peff);
    free(sc->rec), free(sc->na), free(sc->lgrain), free(sc->lstart), free(sc->ltri);
    memset(sc, 0, sizeof *sc);
}

/* Grows every buffer to cap entries, keeping their contents. */
static int scratch_grow(surf_scratch *sc, int cap)
{
    size_t n = (size_t)cap;
#define GROW(field)                                                  \
    do {                                                             \
        void *p_ = realloc(sc->field, n * sizeof *sc->field);        \
        if (!p_)                                                     \
            return CM_ERR_NOMEM;                                     \
        sc->field = p_;                                              \
    } while (0)
    GROW(cd);
    GROW(cd2);
    GROW(near);
    GROW(comp);
    GROW(kidx);
    GROW(peff);
    GROW(sh_n);
    GROW(sh_depth);
    GROW(sh_r);
    GROW(pu);
    GROW(slot_of);
    GROW(nrm);
#undef GROW
    sc->cap = cap;
    return CM_OK;
}

/* Room for candidate n of grain slot i: doubles the buffers when full.
 * Returns 0 when there is no room (out of memory, flagged). */
static int scratch_room(surf_scratch *sc, int n, int i)
{
    if (n < sc->cap)
        return 1;
    if (sc->cap > (1 << 24) || scratch_grow(sc, 2 * sc->cap)) {
        sc->nomem = 1;
        return 0;
    }
    sc->grew_grain = i;
    return 1;
}

int dem_surface_grow(dem_surface *s, int grain_cap)
{
    size_t sz = (size_t)grain_cap * DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE;
    double *h = realloc(s->hist, sz * sizeof *h);
    if (!h)
        return CM_ERR_NOMEM;
    s->hist = h;
    memset(h, 0, sz * sizeof *h);
    return CM_OK;
}

int dem_surface_create(int n_nodes, const double *x0, int n_tris, const int *tris, int material, int grain_cap,
                       int n_threads, dem_surface **out, cm_error *err)
{
    *out = NULL;
    if (n_nodes < 3 || n_tris < 1)
        return cm_fail(err, CM_ERR_RANGE, "dem_surface_set: %d nodes, %d triangles", n_nodes, n_tris);
    for (int t = 0; t < n_tris; t++)
        for (int k = 0; k < 3; k++)
            if (tris[3 * t + k] < 0 || tris[3 * t + k] >= n_nodes)
                return cm_fail(err, CM_ERR_RANGE, "dem_surface_set: triangle %d node %d out of range [0, %d)",
                               t, tris[3 * t + k], n_nodes);
    for (int i = 0; i < 3 * n_nodes; i++)
        if (!isfinite(x0[i]))
            return cm_fail(err, CM_ERR_NUMERIC, "dem_surface_set: node %d position is not finite", i / 3);
    dem_surface *s = calloc(1, sizeof *s);
    if (!s)
        return cm_fail(err, CM_ERR_NOMEM, "dem_surface_set: out of memory");
    s->n_nodes = n_nodes;
    s->n_tris = n_tris;
    s->material = material;
    s->n_threads = n_threads;
    s->x = malloc(3 * (size_t)n_nodes * sizeof *s->x);
    s->v = calloc(3 * (size_t)n_nodes, sizeof *s->v);
    s->x_lists = malloc(3 * (size_t)n_nodes * sizeof *s->x_lists);
    s->node_f = calloc(3 * (size_t)n_nodes, sizeof *s->node_f);
    s->tri = malloc(3 * (size_t)n_tris * sizeof *s->tri);
    s->tri_h = malloc((size_t)n_tris * sizeof *s->tri_h);
    s->bvh = calloc(2 * (size_t)n_tris + 1, sizeof *s->bvh);
    s->perm = malloc((size_t)n_tris * sizeof *s->perm);
    s->box_nodes = calloc((size_t)n_nodes, sizeof *s->box_nodes);
    s->scratch = calloc((size_t)n_threads, sizeof *s->scratch);
    int bad = !s->scratch;
    for (int t = 0; t < n_threads && !bad; t++)
        bad = scratch_grow(&s->scratch[t], DEM_SURF_CAND_INIT);
    s->cand_cap_logged = DEM_SURF_CAND_INIT;
    if (!s->x || !s->v || !s->x_lists || !s->node_f || !s->tri || !s->tri_h || !s->bvh || !s->perm ||
        !s->box_nodes || bad ||
        dem_surface_grow(s, grain_cap > 0 ? grain_cap : 1)) {
        dem_surface_free(&s);
        return cm_fail(err, CM_ERR_NOMEM, "dem_surface_set: out of memory for %d nodes", n_nodes);
    }
    memcpy(s->x, x0, 3 * (size_t)n_nodes * sizeof *s->x);
    memcpy(s->tri, tris, 3 * (size_t)n_tris * sizeof *s->tri);
    for (int t = 0; t < n_tris; t++) {
        s->perm[t] = t;
        const int *tn = tris + 3 * t;
        vec3 a = v3_load(x0 + 3 * tn[0]), b = v3_load(x0 + 3 * tn[1]), c = v3_load(x0 + 3 * tn[2]);
        s->tri_h[t] = sqrt(v3_norm(v3_cross(v3_sub(b, a), v3_sub(c, a)))); /* sqrt(2 area) */
    }
    int *used = s->box_nodes; /* first as flags, then the list (its prefix) */
    for (int k = 0; k < 3 * n_tris; k++)
        used[tris[k]] = 1;
    for (int i = 0; i < n_nodes; i++)
        if (used[i])
            used[s->n_box_nodes++] = i; /* n_box_nodes <= i: only flags already read are overwritten */
    bvh_build(s, 0, n_tris);
    dem_surface_refit(s);
    s->travel[0] = 1.0;
    *out = s;
    return CM_OK;
}

void dem_surface_free(dem_surface **sp)
{
    dem_surface *s = *sp;
    if (!s)
        return;
    free(s->x);
    free(s->v);
    free(s->x_lists);
    free(s->node_f);
    free(s->inv_mass);
    free(s->tri);
    free(s->tri_h);
    free(s->bvh);
    free(s->box_nodes);
    free(s->perm);
    free(s->hist);
    for (int t = 0; s->scratch && t < s->n_threads; t++)
        scratch_free(&s->scratch[t]);
    free(s->scratch);
    free(s);
    *sp = NULL;
}

/* ---- contacts ---------------------------------------------------------- */

static int tri_has_node(const int *t, int node) { return t[0] == node || t[1] == node || t[2] == node; }

/* Nodes of the feature (edge or vertex) a candidate's closest point lies on. */
static int cand_feature(const dem_surface *s, const cand *c, int nodes[2])
{
    const int *t = s->tri + 3 * c->tri;
    switch (c->region) {
    case 1: nodes[0] = t[0], nodes[1] = t[1]; return 2;
    case 2: nodes[0] = t[1], nodes[1] = t[2]; return 2;
    case 3: nodes[0] = t[2], nodes[1] = t[0]; return 2;
    case 4: nodes[0] = t[0]; return 1;
    case 5: nodes[0] = t[1]; return 1;
    case 6: nodes[0] = t[2]; return 1;
    default: return 0;
    }
}

/* 1 if node nd's box and the box [lo, hi] are apart (no overlap along
 * some axis): nothing under nd lies in [lo, hi]. */
static inline int node_apart(const dem_bvh_node *nd, const double lo[3], const double hi[3])
{
    return nd->lo[0] > hi[0] || nd->hi[0] < lo[0] || nd->lo[1] > hi[1] || nd->hi[1] < lo[1] || nd->lo[2] > hi[2] ||
           nd->hi[2] < lo[2];
}

/* node_apart for the box around the sphere (c, r). */
static inline int sphere_apart(const dem_bvh_node *nd, vec3 c, double r)
{
    const double lo[3] = {c.x - r, c.y - r, c.z - r}, hi[3] = {c.x + r, c.y + r, c.z + r};
    return node_apart(nd, lo, hi);
}

/* Walks the BVH for the triangles whose closest point to p lies within r,
 * in a fixed order (depth first, left child first, leaf order), for both the
 * sphere and the shaped contact paths. A traversal stack deeper than 64
 * sets *overflow. */
typedef struct near_iter {
    const dem_surface *s;
    double p[3], lo[3], hi[3], r2;
    int stack[64], sp;
    const dem_bvh_node *leaf; /* leaf being read, NULL between leaves */
    int k;                    /* next triangle of the leaf */
    int *overflow;
    const int *list;          /* non-NULL: the grain's triangle list (BVH order) instead of the tree */
    int n_list;
} near_iter;

static inline void near_begin(near_iter *it, const dem_surface *s, vec3 c, double r, int *overflow)
{
    it->s = s;
    it->p[0] = c.x, it->p[1] = c.y, it->p[2] = c.z;
    it->lo[0] = c.x - r, it->lo[1] = c.y - r, it->lo[2] = c.z - r;
    it->hi[0] = c.x + r, it->hi[1] = c.y + r, it->hi[2] = c.z + r;
    it->r2 = r * r;
    it->sp = 0;
    it->stack[it->sp++] = 0;
    it->leaf = NULL;
    it->k = 0;
    it->overflow = overflow;
    it->list = NULL;
    it->n_list = 0;
}

/* Triangle tt if its closest point to the centre lies within r: 1 and its
 * region, barycentric weights, closest point and squared distance. */
static inline int near_tri(const near_iter *it, int tt, int *t, int *region, double bary[3], double cp[3],
                           double *d2)
{
    const dem_surface *s = it->s;
    const int *tn = s->tri + 3 * tt;
    int reg = dem_closest_on_triangle(it->p, s->x + 3 * tn[0], s->x + 3 * tn[1], s->x + 3 * tn[2], bary, cp);
    double dx = it->p[0] - cp[0], dy = it->p[1] - cp[1], dz = it->p[2] - cp[2];
    double dd = dx * dx + dy * dy + dz * dz;
    if (dd >= it->r2)
        return 0;
    *t = tt, *region = reg, *d2 = dd;
    return 1;
}

/* The next triangle t within r: its region, barycentric weights and closest
 * point cp, and the squared distance d2. Returns 0 when there is none left. */
static inline int near_next(near_iter *it, int *t, int *region, double bary[3], double cp[3], double *d2)
{
    const dem_surface *s = it->s;
    if (it->list) { /* the listed triangles, in the order the tree would give them */
        while (it->k < it->n_list)
            if (near_tri(it, it->list[it->k++], t, region, bary, cp, d2))
                return 1;
        return 0;
    }
    for (;;) {
        if (it->leaf && it->k < it->leaf->count) {
            if (near_tri(it, s->perm[it->leaf->first + it->k++], t, region, bary, cp, d2))
                return 1;
            continue;
        }
        it->leaf = NULL;
        if (it->sp == 0)
            return 0;
        const dem_bvh_node *nd = &s->bvh[it->stack[--it->sp]];
        if (node_apart(nd, it->lo, it->hi))
            continue;
        if (nd->right >= 0) {
            if (it->sp + 2 > 64) {
                *it->overflow = 1;
                continue;
            }
            it->stack[it->sp++] = nd->right;
            it->stack[it->sp++] = (int)(nd - s->bvh) + 1;
            continue;
        }
        it->leaf = nd;
        it->k = 0;
    }
}

/* Union-find root of triangle a in the touched list, with path halving. */
static int comp_find(int *comp, int a)
{
    while (comp[a] != a) {
        comp[a] = comp[comp[a]];
        a = comp[a];
    }
    return a;
}

/* Unit normal of a sphere's contact at closest point p: from p to the
 * centre, or the face normal when the centre lies on the triangle. */
static vec3 sphere_normal(const dem_surface *s, vec3 c, double r, const cand *q)
{
    double d = sqrt(q->d2);
    if (d > 1e-12 * r)
        return v3_scale(v3(c.x - q->p[0], c.y - q->p[1], c.z - q->p[2]), 1.0 / d);
    const int *tn = s->tri + 3 * q->tri;
    vec3 A = v3_load(s->x + 3 * tn[0]), B = v3_load(s->x + 3 * tn[1]), C = v3_load(s->x + 3 * tn[2]);
    return v3_unit(v3_cross(v3_sub(B, A), v3_sub(C, A)));
}

/* One contact per surface patch (issue 16). The kept candidates cd[0..k)
 * (deepest first) are local minima of the distance; on a dented, concave
 * surface there is one on nearly every facet of the dent, and each used to
 * push with a full sphere–plane force (an elastic impact into a rigid dent
 * left with up to 17 % more energy than it brought). A candidate joins a
 * deeper kept one when it is in the same patch: its normal within 45°
 * (DEM_SURF_PATCH_COS) and the two connected through triangles that all
 * touch the grain (sharing a node). The contact has the patch's largest
 * overlap; minima within DEM_SURF_SHARE of it share the reaction (fading
 * linearly), so that the load on a soft FE surface does not jump from facet
 * to facet of the dent it makes (the explicit FEM pumps energy then). A
 * lug's root (normals 90° apart) or a grain bridging a groove (the bottom
 * out of reach, no connection) keeps one contact per face.
 * On return cd[0..m) are the contacts, cd[m..m+n_shared) the sharing minima
 * (patch: their contact, w: their weight, the contact's own being 1). */
static int merge_patches(const dem_surface *s, vec3 c, double r, surf_scratch *sc, int n, int k)
{
    cand *cd = sc->cd;
    int *comp = sc->comp;
    const int *near = sc->near;
    for (int a = 0; a < n; a++)
        comp[a] = a;
    for (int a = 0; a < n; a++) {
        const int *ta = s->tri + 3 * near[a];
        for (int b = a + 1; b < n; b++) {
            const int *tb = s->tri + 3 * near[b];
            if (!tri_has_node(tb, ta[0]) && !tri_has_node(tb, ta[1]) && !tri_has_node(tb, ta[2]))
                continue;
            int ra = comp_find(comp, a), rb = comp_find(comp, b);
            if (ra != rb)
                comp[ra > rb ? ra : rb] = ra < rb ? ra : rb;
        }
    }
    vec3 *nrm = sc->nrm;
    int *kidx = sc->kidx, m = 0;
    for (int a = 0; a < k; a++) {
        vec3 na = sphere_normal(s, c, r, &cd[a]);
        int root = comp_find(comp, cd[a].near);
        cd[a].patch = -1;
        for (int b = 0; b < m && cd[a].patch < 0; b++)
            if (comp_find(comp, cd[kidx[b]].near) == root && v3_dot(na, nrm[b]) > DEM_SURF_PATCH_COS)
                cd[a].patch = b;
        if (cd[a].patch >= 0)
            continue;
        cd[a].patch = m, cd[a].w = 1.0;
        nrm[m] = na;
        kidx[m++] = a;
    }
    /* the kept contacts first, then the shallower minima of their patches
     * that share the reaction: weight 1 - (delta_max - delta)/(s delta_max),
     * s = DEM_SURF_SHARE, nothing below */
    cand *out = sc->cd2;
    for (int b = 0; b < m; b++)
        out[b] = cd[kidx[b]];
    int e = m;
    for (int a = 0; a < k; a++) {
        const cand *kc = &cd[kidx[cd[a].patch]];
        if (kc == &cd[a])
            continue;
        double dmax = r - sqrt(kc->d2), da = r - sqrt(cd[a].d2);
        double w = dmax > 0.0 ? 1.0 - (dmax - da) / (DEM_SURF_SHARE * dmax) : 0.0;
        if (w > 0.0) {
            out[e] = cd[a];
            out[e++].w = w;
        }
    }
    memcpy(cd, out, (size_t)e * sizeof *cd);
    sc->n_shared = e - m;
    return m;
}

/* The tread's compliance counted once (issue 16 item 2; DEM_SURF_FE_A0 in
 * dem_surface.h has the measurements). Hertz's approach delta_H under a force
 * F is the grain's and the tread's compliance together (E*, eq. 21); an FE
 * tread whose nodes carry the contact's force deflects by a share
 * s = x / (x + A0) of it itself, x = a_H / h (a_H = sqrt(R delta_H), h the
 * contact triangle's size). The contact law keeps Hertz's form with the
 * modulus raised so that its own overlap is the rest, delta = (1 - s) delta_H:
 *   F = 4/3 k E* sqrt(R) delta^(3/2),  k = (1 - s)^(-3/2) = (1 + x/A0)^(3/2).
 * With y = sqrt(R delta) / h the contact's own radius over h, delta =
 * (1 - s) delta_H gives y^2 = x^2 A0 / (x + A0), so
 *   x = (y^2 + y sqrt(y^2 + 4 A0^2)) / (2 A0)
 * and F depends on delta alone (conservative for a fixed triangle). Limits:
 * a coarse mesh (h >> a: the default tire, a/h ~ 0.17, k ~ 1.5) keeps nearly
 * Hertz with the tread's modulus; a mesh that resolves the patch (x -> inf)
 * leaves the contact the grain's own modulus, k E* <= e_grain =
 * E_grain / (1 - nu_grain^2), the FE carrying the tread's compliance. A
 * surface whose nodes do not yield (rigid, or no masses: inv_ms = 0) keeps
 * k = 1. The same k scales the Mindlin stiffness G* (the tread's tangential
 * compliance is in the FE's deflection too). Returns k. */
static double surface_contact_stiffening(double R, double delta, double h, double E, double e_grain)
{
    if (!(delta > 0.0) || !(h > 0.0))
        return 1.0;
    const double a0 = DEM_SURF_FE_A0;
    double y = sqrt(R * delta) / h;
    double x = (y * y + y * sqrt(y * y + 4.0 * a0 * a0)) / (2.0 * a0);
    double q = 1.0 + x / a0, k = q * sqrt(q);
    return k * E > e_grain ? fmax(e_grain / E, 1.0) : k;
}

/* Contacts of one grain (slot i) with the surface; returns the number kept.
 * De-duplication: the contact points that count are the local minima of the
 * distance from the grain centre to the whole surface. A face point always is
 * one. An edge (vertex) point is not when another triangle containing that
 * edge (vertex) is strictly closer — the distance keeps falling into it — so
 * those are dropped. Of the rest, points that coincide (the same edge or
 * vertex reported by each of its triangles, or a face point on an edge) are
 * merged, deepest first. A grain on a flat triangulated plane then has exactly
 * one contact wherever it sits. Local minima of one surface patch (a dent)
 * are then merged into its deepest (merge_patches). */
static int grain_candidates(const dem_surface *s, int i, vec3 c, double r, const int *list, int n_list,
                            surf_scratch *sc, int *overflow)
{
    int n = 0;
    sc->n_shared = 0;
    near_iter it;
    near_begin(&it, s, c, r, overflow);
    it.list = list, it.n_list = n_list;
    cand q;
    while (near_next(&it, &q.tri, &q.region, q.bary, q.p, &q.d2)) {
        if (!scratch_room(sc, n, i))
            break;
        q.keep = 1;
        q.near = n;
        sc->near[n] = q.tri;
        sc->cd[n++] = q;
    }
    cand *cd = sc->cd;
    /* drop edge/vertex points that are not local minima */
    double tol = 1e-12 * r * r;
    for (int a = 0; a < n; a++) {
        int nodes[2];
        int nf = cand_feature(s, &cd[a], nodes);
        if (nf == 0)
            continue;
        for (int b = 0; b < n && cd[a].keep; b++) {
            if (b == a || !(cd[b].d2 < cd[a].d2 - tol))
                continue;
            const int *tb = s->tri + 3 * cd[b].tri;
            if (tri_has_node(tb, nodes[0]) && (nf == 1 || tri_has_node(tb, nodes[1])))
                cd[a].keep = 0;
        }
    }
    /* compact, sort by depth (insertion sort, stable: ties keep BVH order) */
    int m = 0;
    for (int a = 0; a < n; a++)
        if (cd[a].keep)
            cd[m++] = cd[a];
    for (int a = 1; a < m; a++) {
        cand t = cd[a];
        int b = a - 1;
        while (b >= 0 && (cd[b].d2 > t.d2 || (cd[b].d2 == t.d2 && cd[b].tri > t.tri))) {
            cd[b + 1] = cd[b];
            b--;
        }
        cd[b + 1] = t;
    }
    /* merge coincident points */
    double mtol = 1e-6 * r;
    int k = 0;
    for (int a = 0; a < m; a++) {
        int dup = 0;
        for (int b = 0; b < k && !dup; b++) {
            double dx = cd[a].p[0] - cd[b].p[0], dy = cd[a].p[1] - cd[b].p[1], dz = cd[a].p[2] - cd[b].p[2];
            dup = dx * dx + dy * dy + dz * dz < mtol * mtol;
        }
        if (!dup)
            cd[k++] = cd[a];
    }
    return k > 1 ? merge_patches(s, c, r, sc, n, k) : k;
}

/* Contacts of a shaped grain (slot i, bounding radius r about c) with the
 * surface: every triangle whose closest point is within r goes to libccd
 * (MPR, started from the triangle's closest point to the centre; normal from
 * the triangle to the grain). The contact point is the grain's deepest point
 * along -n (polyhedra: the weighted mean of the vertices in the overlap)
 * moved by the depth onto the triangle, then its closest point on the
 * triangle (barycentric weights for eq. 42). De-duplication: an edge or
 * vertex contact is dropped when a triangle sharing that feature is deeper
 * (as for spheres); then, deepest first, a contact is dropped when a kept one
 * has a normal within 45° (cos > 0.7). A grain on a flat or gently curved
 * patch overlaps several triangles (the edge of a triangle two cells away
 * still cuts a flat ellipsoid's underside, and MPR reports it with a normal
 * tilted by ~25°) but gets one contact; in a groove with flanks at more than
 * 45°, one per flank. */
static int shaped_candidates(const dem_world *w, int i, vec3 c, double r, const int *list, int n_list,
                             surf_scratch *sc, int *overflow)
{
    const dem_surface *s = w->surf;
    int n = 0;
    sc->n_shared = 0;
    double p[3] = {c.x, c.y, c.z}, inv_l = 1.0 / r, zero[3] = {0, 0, 0};
    dem_body gb;
    dem_grain_body(w, i, p, inv_l, &gb);
    near_iter it;
    near_begin(&it, s, c, r, overflow);
    it.list = list, it.n_list = n_list;
    int tri_id, region;
    double bary_c[3], cp_c[3], d2;
    while (near_next(&it, &tri_id, &region, bary_c, cp_c, &d2)) {
        const int *tn = s->tri + 3 * tri_id;
        double v[3][3];
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                v[a][b] = (s->x[3 * tn[a] + b] - p[b]) * inv_l;
        dem_body tb;
        dem_body_triangle(v[0], v[1], v[2], zero, &tb);
        double dep, nn[3], pc[3];
        int pr = dem_body_penetration(&tb, &gb, 0, &dep, nn, pc);
        if (pr < 0 && sc->ccd_failed_grain < 0) /* libccd failed: reported after the pass */
            sc->ccd_failed_grain = i, sc->ccd_failed_tri = tri_id;
        if (pr != 1)
            continue;
        if (!scratch_room(sc, n, i))
            break;
        /* the buffers may have moved */
        cand *cd = sc->cd;
        double(*nr)[3] = sc->sh_n, *depth = sc->sh_depth, *rc = sc->sh_r, (*pu)[3] = sc->pu;
        double mn[3] = {-nn[0], -nn[1], -nn[2]}, deep[3];
        dem_body_contact_point(&gb, nn, dep, 1.0, deep);
        for (int b = 0; b < 3; b++)
            deep[b] = p[b] + deep[b] * r;
        memcpy(pu[n], deep, sizeof deep);
        cand q;
        q.region = dem_closest_on_triangle(deep, s->x + 3 * tn[0], s->x + 3 * tn[1], s->x + 3 * tn[2], q.bary, q.p);
        q.tri = tri_id;
        q.d2 = -dep; /* sorts deepest first */
        q.keep = 1;
        q.near = n;
        memcpy(nr[n], nn, sizeof nn);
        depth[n] = dep * r;
        rc[n] = dem_shape_contact_radius(gb.s, w->g.sc[i], gb.R, mn);
        cd[n++] = q;
    }
    cand *cd = sc->cd;
    double(*nr)[3] = sc->sh_n, *depth = sc->sh_depth, *rc = sc->sh_r, (*pu)[3] = sc->pu;
    /* as for spheres: a contact whose point lies on an edge or vertex is
     * dropped when a triangle sharing that feature has a deeper contact (the
     * grain overlaps the neighbour of the face it really rests on) */
    for (int a = 0; a < n; a++) {
        int nodes[2];
        int nf = cand_feature(s, &cd[a], nodes);
        if (nf == 0)
            continue;
        for (int b = 0; b < n && cd[a].keep; b++) {
            if (b == a || !(cd[b].d2 < cd[a].d2 - 1e-12 * r))
                continue;
            const int *tb = s->tri + 3 * cd[b].tri;
            if (tri_has_node(tb, nodes[0]) && (nf == 1 || tri_has_node(tb, nodes[1])))
                cd[a].keep = 0;
        }
    }
    /* deepest first (selection by index: the side arrays move along) */
    int m = 0;
    for (int a = 0; a < n; a++) {
        int best = -1;
        for (int b = 0; b < n; b++)
            if (cd[b].keep == 1 && (best < 0 || cd[b].d2 < cd[best].d2 || (cd[b].d2 == cd[best].d2 && cd[b].tri < cd[best].tri)))
                best = b;
        if (best < 0)
            break;
        cd[best].keep = 2; /* taken in this round */
        int dup = 0;
        for (int b = 0; b < m && !dup; b++)
            dup = nr[best][0] * nr[b][0] + nr[best][1] * nr[b][1] + nr[best][2] * nr[b][2] > DEM_SURF_PATCH_COS;
        if (dup)
            continue;
        /* move best to position m (swap, including the side arrays) */
        cand t = cd[m];
        cd[m] = cd[best], cd[best] = t;
        double tn[3];
        memcpy(tn, nr[m], sizeof tn), memcpy(nr[m], nr[best], sizeof tn), memcpy(nr[best], tn, sizeof tn);
        double td = depth[m];
        depth[m] = depth[best], depth[best] = td;
        td = rc[m], rc[m] = rc[best], rc[best] = td;
        memcpy(tn, pu[m], sizeof tn), memcpy(pu[m], pu[best], sizeof tn), memcpy(pu[best], tn, sizeof tn);
        m++;
    }
    /* a kept contact is carried by the triangle of its group (normals
     * within 45°) that holds its point: a cube face lying on several
     * triangles is pushed through its middle, not at the edge of the
     * deepest triangle */
    for (int a = 0; a < m; a++) {
        int bt = -1;
        double bd = INFINITY, bb[3], bp[3];
        for (int b = 0; b < n; b++) {
            if (b != a && nr[a][0] * nr[b][0] + nr[a][1] * nr[b][1] + nr[a][2] * nr[b][2] <= DEM_SURF_PATCH_COS)
                continue;
            const int *tn = s->tri + 3 * cd[b].tri;
            double bary[3], cp[3];
            int reg = dem_closest_on_triangle(pu[a], s->x + 3 * tn[0], s->x + 3 * tn[1], s->x + 3 * tn[2], bary, cp);
            double dd = (cp[0] - pu[a][0]) * (cp[0] - pu[a][0]) + (cp[1] - pu[a][1]) * (cp[1] - pu[a][1]) +
                        (cp[2] - pu[a][2]) * (cp[2] - pu[a][2]);
            if (dd < bd * (1.0 - 1e-12)) {
                bd = dd, bt = b;
                memcpy(bb, bary, sizeof bb), memcpy(bp, cp, sizeof bp);
                cd[a].region = reg;
            }
        }
        if (bt >= 0 && bt != a) {
            cd[a].tri = cd[bt].tri;
            memcpy(cd[a].bary, bb, sizeof bb);
            memcpy(cd[a].p, bp, sizeof bp);
        }
    }
    return m;
}

/* 1 if the box [lo, hi] overlaps a leaf's box of the tree (or the walk's
 * stack would overflow): a sphere inside the box can come near a triangle
 * only then, as every triangle lies inside its leaf's box. */
static int box_meets_leaf(const dem_surface *s, const double lo[3], const double hi[3])
{
    int stack[64], sp = 0;
    stack[sp++] = 0;
    while (sp > 0) {
        const dem_bvh_node *nd = &s->bvh[stack[--sp]];
        if (node_apart(nd, lo, hi))
            continue;
        if (nd->right < 0 || sp + 2 > 64)
            return 1;
        stack[sp++] = nd->right;
        stack[sp++] = (int)(nd - s->bvh) + 1;
    }
    return 0;
}

/* Grains whose lists are built together (surf_lists_build). */
enum { SURF_LIST_GROUP = 32 };

/* The triangle lists of grains [lo, hi): every triangle whose closest point
 * lies within r + margin of the grain's centre, in the tree's order. A grain
 * without one cannot touch the surface before the lists are rebuilt: its
 * springs are cleared now. The grains are taken in groups of consecutive
 * slots: where the group's box (each grain's r + margin around it) meets no
 * leaf of the tree, no grain of it walks the tree, and its lists are empty
 * as the walks would leave them. Slots are in cell order after a re-sort,
 * so a group is a few cells of one column: the soil under the tire's box
 * but away from its tread (most of the grains inside the tire's box) is
 * passed over a group at a time. Returns the slot of a grain whose tree walk
 * overflowed, or -1; sets sc->nomem when a list cannot grow. */
static int surf_lists_build(const dem_surface *s, dem_grains *g, int lo, int hi, double margin, surf_scratch *sc)
{
    const dem_bvh_node *root = &s->bvh[0];
    int overflow_slot = -1, near = 0;
    sc->n_lg = sc->n_lt = 0;
    for (int i = lo; i < hi; i++) {
        if ((i - lo) % SURF_LIST_GROUP == 0) { /* the next group: does it come near a leaf? */
            const int e = hi - i > SURF_LIST_GROUP ? i + SURF_LIST_GROUP : hi;
            double blo[3] = {INFINITY, INFINITY, INFINITY}, bhi[3] = {-INFINITY, -INFINITY, -INFINITY};
            for (int k = i; k < e; k++) {
                const double rk = g->r[k] + margin;
                blo[0] = min2(blo[0], g->x[k] - rk), bhi[0] = max2(bhi[0], g->x[k] + rk);
                blo[1] = min2(blo[1], g->y[k] - rk), bhi[1] = max2(bhi[1], g->y[k] + rk);
                blo[2] = min2(blo[2], g->z[k] - rk), bhi[2] = max2(bhi[2], g->z[k] + rk);
            }
            near = box_meets_leaf(s, blo, bhi);
        }
        double r = g->r[i] + margin;
        vec3 c = v3(g->x[i], g->y[i], g->z[i]);
        int start = sc->n_lt;
        if (near && !sphere_apart(root, c, r)) {
            int overflow = 0, t, reg;
            double bary[3], cp[3], d2;
            near_iter it;
            near_begin(&it, s, c, r, &overflow);
            while (near_next(&it, &t, &reg, bary, cp, &d2)) {
                if (dem_grow_ints(&sc->ltri, &sc->lt_cap, sc->n_lt + 1)) {
                    sc->nomem = 1;
                    return overflow_slot;
                }
                sc->ltri[sc->n_lt++] = t;
            }
            if (overflow && overflow_slot < 0)
                overflow_slot = i;
        }
        if (sc->n_lt > start) {
            if (dem_grow_ints(&sc->lgrain, &sc->lg_cap, sc->n_lg + 1) ||
                dem_grow_ints(&sc->lstart, &sc->ls_cap, sc->n_lg + 2)) {
                sc->nomem = 1;
                return overflow_slot;
            }
            sc->lgrain[sc->n_lg] = i;
            sc->lstart[sc->n_lg++] = start;
        } else if (g->surf_count[i]) { /* out of reach: its springs go */
            memset(s->hist + (size_t)i * DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE, 0,
                   DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE * sizeof *s->hist);
            g->surf_count[i] = 0;
        }
    }
    if (dem_grow_ints(&sc->lstart, &sc->ls_cap, sc->n_lg + 1))
        sc->nomem = 1;
    else
        sc->lstart[sc->n_lg] = sc->n_lt;
    return overflow_slot;
}

/* Adds one recorded contact's totals (its node forces are added before, by
 * the caller): the one place where they are summed, for a process's own
 * contacts and for every rank's packed ones alike. */
static inline void replay_totals(const surf_rec *rc, dem_surface_total *tot)
{
    v3_store(tot->force, v3_add(v3_load(tot->force), v3_load(rc->fs)));
    v3_store(tot->moment, v3_add(v3_load(tot->moment), v3_load(rc->mom)));
    if (rc->along > 0.0)
        tot->traction_pos += rc->along;
    else
        tot->traction_neg += rc->along;
    tot->contacts++;
    if (rc->overlap > tot->max_overlap)
        tot->max_overlap = rc->overlap, tot->worst_grain = rc->grain, tot->worst_tri = rc->tri;
    tot->energy += rc->energy;
}

static inline void add_node_force(double *node_f, int node, double fx, double fy, double fz)
{
    double *f = node_f + 3 * node;
    f[0] += fx;
    f[1] += fy;
    f[2] += fz;
}

/* Adds a thread's recorded contacts into the node forces and the totals. */
static void surf_replay(const surf_scratch *sc, double *node_f, dem_surface_total *tot)
{
    const node_add *na = sc->na;
    for (int r = 0; r < sc->n_rec; r++) {
        for (int k = 0; k < sc->rec[r].n_nodes; k++, na++)
            add_node_force(node_f, na->node, na->f[0], na->f[1], na->f[2]);
        replay_totals(&sc->rec[r], tot);
    }
}

/* Packed contact: fs[3], mom[3], along, overlap, energy, n_nodes, then per
 * node its index and force (DEM_SURF_PACK_NODE doubles); integers exactly. */
enum { PACK_REC = 10 };

long dem_surface_packed_size(const dem_world *w)
{
    const dem_surface *s = w->surf;
    long n = 0;
    for (int t = 0; s && t < s->n_threads; t++)
        n += PACK_REC * (long)s->scratch[t].n_rec + DEM_SURF_PACK_NODE * (long)s->scratch[t].n_na;
    return n;
}

long dem_surface_pack(const dem_world *w, double *buf)
{
    const dem_surface *s = w->surf;
    double *b = buf;
    for (int t = 0; s && t < s->n_threads; t++) { /* thread ranges ascend: grain order */
        const surf_scratch *sc = &s->scratch[t];
        const node_add *na = sc->na;
        for (int r = 0; r < sc->n_rec; r++) {
            const surf_rec *rc = &sc->rec[r];
            const double h[PACK_REC] = {rc->fs[0],   rc->fs[1],    rc->fs[2],  rc->mom[0], rc->mom[1],
                                        rc->mom[2],  rc->along,    rc->overlap, rc->energy, (double)rc->n_nodes};
            memcpy(b, h, sizeof h);
            b += PACK_REC;
            for (int k = 0; k < rc->n_nodes; k++, na++) {
                b[0] = (double)na->node, b[1] = na->f[0], b[2] = na->f[1], b[3] = na->f[2];
                b += DEM_SURF_PACK_NODE;
            }
        }
    }
    return (long)(b - buf);
}

int dem_surface_sum_packed(dem_world *w, const double *buf, long n, cm_error *err)
{
    dem_surface *s = w->surf;
    if (!s)
        return cm_fail(err, CM_ERR_STATE, "dem_surface_sum_packed at step %ld: no surface installed", w->step);
    memset(s->node_f, 0, 3 * (size_t)s->n_nodes * sizeof *s->node_f);
    memset(&s->tot, 0, sizeof s->tot);
    for (long at = 0; at < n;) {
        const double *h = buf + at;
        if (at + PACK_REC > n)
            return cm_fail(err, CM_ERR_RANGE, "step %ld: packed surface contacts cut short at %ld of %ld", w->step,
                           at, n);
        at += PACK_REC;
        if (!(h[9] >= 0.0 && h[9] * DEM_SURF_PACK_NODE <= (double)(n - at)))
            return cm_fail(err, CM_ERR_RANGE, "step %ld: a packed surface contact has %g node entries", w->step, h[9]);
        surf_rec rc = {.along = h[6], .overlap = h[7], .energy = h[8], .n_nodes = (int)h[9],
                       .grain = -1, .tri = -1}; /* another rank's slot: not named here */
        memcpy(rc.fs, h, 3 * sizeof *h);
        memcpy(rc.mom, h + 3, 3 * sizeof *h);
        for (int k = 0; k < rc.n_nodes; k++, at += DEM_SURF_PACK_NODE) {
            const double *e = buf + at;
            if (!(e[0] >= 0.0 && e[0] < s->n_nodes))
                return cm_fail(err, CM_ERR_RANGE, "step %ld: a packed surface contact names node %g of %d", w->step,
                               e[0], s->n_nodes);
            add_node_force(s->node_f, (int)e[0], e[1], e[2], e[3]);
        }
        replay_totals(&rc, &s->tot);
    }
    return CM_OK;
}

int dem_surface_contacts(dem_world *w, cm_error *err)
{
    dem_surface *s = w->surf;
    dem_grains *g = &w->g;
    const int nt = w->n_threads;
    const double dt = w->def.dt;
    const int nn3 = 3 * s->n_nodes;
    const int g0 = w->dist ? w->own_lo : 0, n_own = (w->dist ? w->own_hi : g->n) - g0;
    memset(s->node_f, 0, (size_t)nn3 * sizeof *s->node_f);
    for (int t = 0; t < nt; t++)
        s->scratch[t].grew_grain = -1, s->scratch[t].nomem = 0, s->scratch[t].n_rec = s->scratch[t].n_na = 0,
        s->scratch[t].ccd_failed_grain = -1;
    const dem_bvh_node *root = &s->bvh[0];
    const vec3 ref = v3_load(s->ref), dir = v3_load(s->travel);
    int overflow_slot = -1;
    /* Surface neighbour lists: each grain's triangles within r + 2 skin,
     * built by the tree walk and then read instead of it while they hold.
     * They hold while no grain moved more than one skin since they were
     * built (the grain list is rebuilt before any grain moves skin/2 from its
     * last rebuild, and the triangle lists with it) and no surface node moved
     * more than one skin (a point of a triangle moves no more than its
     * fastest node): a triangle within r now was within r + 2 skin then. The
     * list keeps the tree's order, so the contacts are found in the same
     * order and the results are the same bits as a walk every step. */
    const double margin = w->skin;
    int use_lists = s->lists_valid && s->lists_rebuild == w->rebuild_count && !w->need_rebuild &&
                    s->lists_n == g->n;
    if (use_lists) {
        double moved2 = 0.0;
        for (int k = 0; k < s->n_nodes; k++) {
            double dx = s->x[3 * k] - s->x_lists[3 * k], dy = s->x[3 * k + 1] - s->x_lists[3 * k + 1],
                   dz = s->x[3 * k + 2] - s->x_lists[3 * k + 2];
            double d2 = dx * dx + dy * dy + dz * dz;
            moved2 = d2 > moved2 ? d2 : moved2;
        }
        use_lists = moved2 <= margin * margin;
    }
    if (!use_lists) {
        if (s->tree_stale) /* the tree is walked: its boxes brought up to date */
            dem_surface_refit(s);
        memcpy(s->x_lists, s->x, (size_t)nn3 * sizeof *s->x);
        s->lists_rebuild = w->rebuild_count;
        s->lists_n = g->n;
        w->prof.surface_lists++;
    }

#ifdef _OPENMP
#pragma omp parallel num_threads(nt)
#endif
    {
        int tid = dem_thread_id();
        /* distributed: the owned grains only (a ghost's contacts are its owner's) */
        int lo = g0 + (int)((long)n_own * tid / nt), hi = g0 + (int)((long)n_own * (tid + 1) / nt);
        surf_scratch *sc = &s->scratch[tid];
        if (!use_lists) {
            int ov = surf_lists_build(s, g, lo, hi, 2.0 * margin, sc);
            if (ov >= 0) {
#ifdef _OPENMP
#pragma omp critical(dem_surface_overflow)
#endif
                if (overflow_slot < 0 || ov < overflow_slot)
                    overflow_slot = ov;
            }
        }
        for (int gk = 0; gk < sc->n_lg && !sc->nomem; gk++) {
            const int i = sc->lgrain[gk];
            const int *list = sc->ltri + sc->lstart[gk], n_list = sc->lstart[gk + 1] - sc->lstart[gk];
            double r = g->r[i];
            vec3 c = v3(g->x[i], g->y[i], g->z[i]);
            double *hs = s->hist + (size_t)i * DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE;
            /* A grain holds used history slots only if it touched the surface
             * in the last step (unused slots are cleared below), so most
             * grains, far from the tire, never read their 224 bytes of history. */
            const int had_contacts = g->surf_count[i];
            g->surf_count[i] = 0;
            if (sphere_apart(root, c, r)) {
                if (had_contacts)
                    memset(hs, 0, DEM_SURF_SLOTS * DEM_SURF_SLOT_SIZE * sizeof *hs);
                continue;
            }
            int overflow = 0;
            const int shaped = g->shape[i] >= 0;
            int m = shaped ? shaped_candidates(w, i, c, r, list, n_list, sc, &overflow)
                           : grain_candidates(s, i, c, r, list, n_list, sc, &overflow);
            /* the buffers may have grown: read them after the search */
            const cand *cd = sc->cd;
            const double(*sh_n)[3] = (const double(*)[3])sc->sh_n, *sh_depth = sc->sh_depth, *sh_r = sc->sh_r;
            if (overflow) {
#ifdef _OPENMP
#pragma omp critical(dem_surface_overflow)
#endif
                if (overflow_slot < 0 || i < overflow_slot)
                    overflow_slot = i;
            }
            int taken[DEM_SURF_SLOTS] = {0};
            int *slot_of = sc->slot_of;
            vec3 *nrm = sc->nrm, *peff = sc->peff;
            const int ns = sc->n_shared; /* cd[m .. m+ns): shares of the kept contacts' reactions */
            for (int a = 0; a < m; a++) {
                nrm[a] = shaped ? v3_load(sh_n[a]) : sphere_normal(s, c, r, &cd[a]);
                peff[a] = v3_load(cd[a].p);
                if (ns > 0) { /* a shared patch: the contact point is the weighted mean of its minima */
                    double wsum = 1.0;
                    for (int j = m; j < m + ns; j++)
                        if (cd[j].patch == a)
                            peff[a] = v3_axpy(cd[j].w, v3_load(cd[j].p), peff[a]), wsum += cd[j].w;
                    if (wsum > 1.0) {
                        peff[a] = v3_scale(peff[a], 1.0 / wsum);
                        vec3 l = v3_sub(c, peff[a]);
                        double ll = v3_norm(l);
                        if (ll > 1e-12 * r)
                            nrm[a] = v3_scale(l, 1.0 / ll);
                    }
                }
                /* history slot: the used one with the closest normal (keyed
                 * by grain and patch, not by triangle: the spring survives
                 * the contact point crossing triangle edges) */
                int best = -1;
                double bd = DEM_SURF_PATCH_COS;
                for (int k = 0; k < DEM_SURF_SLOTS; k++) {
                    const double *h = hs + k * DEM_SURF_SLOT_SIZE;
                    if (taken[k] || h[DEM_SURF_SLOT_USED] == 0.0)
                        continue;
                    const double *hn = h + DEM_SURF_SLOT_N;
                    double dd = nrm[a].x * hn[0] + nrm[a].y * hn[1] + nrm[a].z * hn[2];
                    if (dd > bd)
                        bd = dd, best = k;
                }
                slot_of[a] = best;
                if (best >= 0)
                    taken[best] = 1;
            }
            for (int a = 0; a < m; a++) /* new contacts take free slots */
                if (slot_of[a] < 0)
                    for (int k = 0; k < DEM_SURF_SLOTS; k++)
                        if (!taken[k]) {
                            double *h = hs + k * DEM_SURF_SLOT_SIZE;
                            h[0] = h[1] = h[2] = 0.0;
                            taken[k] = 1;
                            slot_of[a] = k;
                            break;
                        }
            for (int k = 0; k < DEM_SURF_SLOTS; k++)
                if (!taken[k])
                    memset(hs + k * DEM_SURF_SLOT_SIZE, 0, DEM_SURF_SLOT_SIZE * sizeof *hs);

            const dem_pair_coef *cf = &w->coef[g->mat[i]][s->material];
            const dem_material *mg = &w->mat[g->mat[i]];
            const double e_grain = mg->young / (1.0 - mg->poisson * mg->poisson); /* the grain's own modulus */
            double m_i = 1.0 / g->inv_m[i];
            vec3 vi = v3(g->vx[i], g->vy[i], g->vz[i]), wi = v3(g->wx[i], g->wy[i], g->wz[i]);
            vec3 fsum = v3(0, 0, 0), tsum = v3(0, 0, 0);
            for (int a = 0; a < m; a++) {
                /* the triangles carrying the contact: its own and, in a
                 * shared patch, those of its shallower minima, weights
                 * normalised */
                double wsum = 1.0;
                for (int j = m; j < m + ns; j++)
                    if (cd[j].patch == a)
                        wsum += cd[j].w;
                /* each node's share bk, kept in the contact's node
                 * records (f[0] holds bk until the force is known) */
                if (record_room(sc, 3 * (1 + ns)))
                    continue;
                node_add *share = sc->na + sc->n_na;
                int n_share = 0;
                vec3 vs = v3(0, 0, 0);
                double inv_ms = 0.0;
                for (int j = a; j < m + ns; j = j == a ? m : j + 1) {
                    if (j != a && cd[j].patch != a)
                        continue;
                    const int *tn = s->tri + 3 * cd[j].tri;
                    double wj = (j == a ? 1.0 : cd[j].w) / wsum;
                    for (int k = 0; k < 3; k++) {
                        double bk = wj * cd[j].bary[k];
                        vs = v3_axpy(bk, v3_load(s->v + 3 * tn[k]), vs);
                        if (s->inv_mass)
                            inv_ms += bk * bk * s->inv_mass[tn[k]];
                        share[n_share].node = tn[k];
                        share[n_share++].f[0] = bk;
                    }
                }
                vec3 p = peff[a];
                vec3 lever = v3_sub(p, c);
                vec3 vrel = v3_sub(v3_add(vi, v3_cross(wi, lever)), vs);
                double xi_tmp[3] = {0, 0, 0};
                double *xi = slot_of[a] >= 0 ? hs + slot_of[a] * DEM_SURF_SLOT_SIZE : xi_tmp;
                /* Effective mass of the pair: the grain and the surface point,
                 * whose apparent mass under a force spread with weights w_k
                 * is 1 / sum(w_k^2 / m_k). With the grain's mass alone the
                 * dashpot over-damps light FE nodes and the explicit exchange
                 * goes unstable (c dt / m_node > 2). */
                double m_pair = s->inv_mass ? 1.0 / (1.0 / m_i + inv_ms) : m_i;
                double fn;
                double delta = shaped ? sh_depth[a] : r - sqrt(cd[a].d2), Rc = shaped ? sh_r[a] : r;
                /* the tread's compliance once: the FE's share taken out of the law */
                dem_pair_coef cs = *cf;
                if (inv_ms > 0.0) {
                    double k = surface_contact_stiffening(Rc, delta, s->tri_h[cd[a].tri], cf->E, e_grain);
                    cs.E *= k, cs.G *= k;
                }
                vec3 F = dem_hm_force(&cs, nrm[a], delta, Rc, m_pair, vrel, dt, xi, &fn);
                if (slot_of[a] >= 0) {
                    v3_store(xi + DEM_SURF_SLOT_N, nrm[a]);
                    xi[DEM_SURF_SLOT_USED] = 1.0;
                }
                fsum = v3_add(fsum, F);
                tsum = v3_add(tsum, v3_cross(lever, F));
                tsum = v3_add(tsum, dem_rolling_torque(cf, Rc, fn, wi, 1.0 / g->inv_i[i], dt));
                /* reaction on the surface, to the nodes by barycentric weights
                 * (eq. 42), times the shares in a shared patch: the contact
                 * point is the same weighted mean, so force and moment
                 * balance. Recorded, summed in grain order after the pass. */
                vec3 Fs = v3_scale(F, -1.0);
                for (int q = 0; q < n_share; q++) {
                    double bk = share[q].f[0];
                    share[q].f[0] = bk * Fs.x, share[q].f[1] = bk * Fs.y, share[q].f[2] = bk * Fs.z;
                }
                sc->n_na += n_share;
                surf_rec *rc = &sc->rec[sc->n_rec++];
                rc->n_nodes = n_share;
                v3_store(rc->fs, Fs);
                v3_store(rc->mom, v3_cross(v3_sub(p, ref), Fs));
                rc->along = v3_dot(Fs, dir);
                rc->overlap = delta / Rc;
                rc->grain = i;
                rc->tri = cd[a].tri;
                rc->energy = dem_hertz_energy(&cs, Rc, delta); /* with k frozen: an estimate (the guard's energy scale) */
            }
            g->surf_count[i] = m;
            g->fx[i] += fsum.x, g->fy[i] += fsum.y, g->fz[i] += fsum.z;
            g->tx[i] += tsum.x, g->ty[i] += tsum.y, g->tz[i] += tsum.z;
        }
    }
    s->lists_valid = 1;
    for (int t = 0; t < nt; t++)
        s->lists_valid &= !s->scratch[t].nomem;
    /* the threads' grain ranges ascend with the thread number: replaying
     * their records in that order adds every node force and total in grain
     * order, as one thread does (the same bits for any thread count) */
    memset(&s->tot, 0, sizeof s->tot);
    for (int t = 0; t < nt; t++)
        surf_replay(&s->scratch[t], s->node_f, &s->tot);
    for (int t = 0; t < nt; t++) {
        const surf_scratch *sc = &s->scratch[t];
        if (sc->ccd_failed_grain >= 0)
            return cm_fail(err, CM_ERR_NUMERIC, "step %ld: grain %d against surface triangle %d: libccd's MPR failed",
                           w->step, g->id[sc->ccd_failed_grain], sc->ccd_failed_tri);
        if (sc->nomem)
            return cm_fail(err, CM_ERR_NOMEM, "step %ld: out of memory growing the surface candidate buffer beyond %d",
                           w->step, sc->cap);
        if (sc->grew_grain >= 0 && sc->cap > s->cand_cap_logged) {
            s->cand_cap_logged = sc->cap;
            cm_log_info("step %ld: grain %d touches more than %d surface triangles: candidate buffer grown to %d",
                        w->step, g->id[sc->grew_grain], sc->cap / 2, sc->cap);
        }
    }
    if (overflow_slot >= 0)
        return cm_fail(err, CM_ERR_RANGE, "step %ld: grain %d: surface tree deeper than the search stack (64)", w->step,
                       g->id[overflow_slot]);
    return CM_OK;
}
