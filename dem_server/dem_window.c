/* The terrain window (dem_window.h): removal behind the wheel, copies of the
 * settled sample appended in front, end walls following, far grains frozen. */
#include "dem_window.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dem_bed.h"
#include "dem_config.h"
#include "dem_world.h"
#include "log.h"

struct dem_window {
    dem_window_def def;
    dem_window_state st;
    int n_sample;
    dem_grain_state *sample; /* the stretch, x measured from its start s0 (0 <= x < len), sorted by x */
    double s0, len;          /* m, where the stretch was taken in the bed, and its length */
    double sample_reach;     /* m, largest x + r of the stretch (its ragged front end) */
    double line_mass;        /* kg/m, grain mass per metre of the stretch */
    double r_max;            /* m, largest radius of the sample bed */
    int *near;               /* world capacity: slots near the front wall (seam search) */
    double *saved;           /* world capacity x 9: v, omega, L by id, kept over a seam relaxation */
};

static int cmp_state_x(const void *a, const void *b)
{
    double xa = ((const dem_grain_state *)a)->x[0], xb = ((const dem_grain_state *)b)->x[0];
    return (xa > xb) - (xa < xb);
}

/* Index of the wall with unit normal (nx, ny, nz) (within 1e-9), or -1. */
static int find_wall(const dem_world *w, double nx, double ny, double nz)
{
    for (int k = 0; k < w->n_walls; k++)
        if (fabs(w->walls[k].n[0] - nx) < 1e-9 && fabs(w->walls[k].n[1] - ny) < 1e-9 &&
            fabs(w->walls[k].n[2] - nz) < 1e-9)
            return k;
    return -1;
}

int dem_window_create(const dem_world *w, const dem_window_def *def, dem_window **out, cm_error *err)
{
    *out = NULL;
    const dem_grains *g = &w->g;
    int kb = find_wall(w, 1, 0, 0), kf = find_wall(w, -1, 0, 0);
    if (kb < 0 || kf < 0)
        return cm_fail(err, CM_ERR_STATE, "dem.window: the bed has no end walls (normals +x and -x); set "
                       "dem.bed.side_walls = true");
    double xb = w->walls[kb].p[0], xf = w->walls[kf].p[0];
    double s0 = xb + def->sample_margin, len = def->shift;
    if (s0 + len > xf - def->sample_margin)
        return cm_fail(err, CM_ERR_RANGE,
                       "dem.window: the sample stretch [%g, %g) m (dem.window.sample_margin + dem.window.shift) does "
                       "not fit inside the bed [%g, %g) m away from its end walls; shorten dem.window.shift",
                       s0, s0 + len, xb, xf);
    double r_max = 0.0;
    for (int i = 0; i < g->n; i++)
        r_max = fmax(r_max, g->r[i]);
    /* A stretch thinner than a few grains is mostly seam: its copies pack
     * loosely and the removals fire at every exchange. */
    if (len < 4.0 * r_max)
        return cm_fail(err, CM_ERR_RANGE,
                       "dem.window.shift = %g m is shorter than two grain diameters (%g m): the appended stretches "
                       "would be mostly seam; raise dem.window.shift",
                       len, 4.0 * r_max);
    dem_window *win = calloc(1, sizeof *win);
    if (!win)
        return cm_fail(err, CM_ERR_NOMEM, "dem.window: out of memory");
    int n = 0;
    for (int i = 0; i < g->n; i++) {
        n += g->x[i] >= s0 && g->x[i] < s0 + len;
        win->r_max = fmax(win->r_max, g->r[i]);
    }
    win->sample = malloc((size_t)(n ? n : 1) * sizeof *win->sample);
    win->near = malloc((size_t)g->cap * sizeof *win->near);
    win->saved = malloc((size_t)g->cap * 9 * sizeof *win->saved);
    if (!win->sample || !win->near || !win->saved) {
        dem_window_free(&win);
        return cm_fail(err, CM_ERR_NOMEM, "dem.window: out of memory for a sample of %d grains", n);
    }
    int k = 0;
    for (int id = 0; id < g->n; id++) {
        int i = g->slot_of[id];
        if (!(g->x[i] >= s0 && g->x[i] < s0 + len))
            continue;
        dem_grain_state *s = &win->sample[k++];
        dem_grain_get(w, id, s);
        s->x[0] -= s0;
        win->sample_reach = fmax(win->sample_reach, s->x[0] + s->radius);
        win->line_mass += s->mass / len;
    }
    qsort(win->sample, (size_t)n, sizeof *win->sample, cmp_state_x);
    if (n == 0) {
        dem_window_free(&win);
        return cm_fail(err, CM_ERR_RANGE, "dem.window: no grains in the sample stretch [%g, %g) m", s0, s0 + len);
    }
    win->n_sample = n;
    win->def = *def;
    win->s0 = s0;
    win->len = len;
    win->st.x_back = win->st.x_cut = xb;
    win->st.x_front = xf;
    win->st.wall_back = kb;
    win->st.wall_front = kf;
    win->st.x_freeze = NAN;
    win->st.seam_min_fraction = 1.0;
    /* its surface (mean over columns 2 r_max wide of the highest top, as
     * dem_bed_height) against the whole bed's, which the FEM gets for the
     * sinkage: the copies should not shift the reference */
    double h = 2.0 * win->r_max, tops = 0.0;
    int ncol = 0;
    for (double cx = 0.0; cx < len; cx += h)
        for (double cy = g->n ? w->walls[find_wall(w, 0, 1, 0) >= 0 ? find_wall(w, 0, 1, 0) : 0].p[1] : 0.0;; cy += h) {
            double top = -INFINITY;
            int any = 0;
            for (int q = 0; q < n; q++) {
                const dem_grain_state *st = &win->sample[q];
                if (st->x[0] >= cx && st->x[0] < cx + h && st->x[1] >= cy && st->x[1] < cy + h)
                    top = fmax(top, st->x[2] + st->radius), any = 1;
            }
            int ky = find_wall(w, 0, -1, 0);
            if (any)
                tops += top, ncol++;
            if (ky < 0 || cy + h >= w->walls[ky].p[1])
                break;
        }
    cm_log_info("window: behind %.3f m, ahead %.3f m, shift %.3f m; sample stretch x in [%.3f, %.3f) m of the bed: %d "
                "grains (%.1f kg/m), surface at z = %.4f m (whole bed %.4f m)%s",
                def->behind, def->ahead, def->shift, s0, s0 + len, n, win->line_mass, ncol ? tops / ncol : NAN,
                dem_bed_height(w), def->freeze_distance != 0 ? "" : "; no freezing");
    if (def->freeze_distance > 0)
        cm_log_info("window: grains farther than %.3f m from the wheel centre (along x) are frozen",
                    def->freeze_distance);
    else if (def->freeze_distance < 0)
        cm_log_info("window: grains more than %.3f m behind or %.3f m ahead of the wheel centre (along x) are "
                    "frozen (the window's own extents)", def->behind, def->ahead);
    *out = win;
    return CM_OK;
}

void dem_window_free(dem_window **wp)
{
    dem_window *win = *wp;
    if (!win)
        return;
    free(win->sample);
    free(win->near);
    free(win->saved);
    free(win);
    *wp = NULL;
}

const dem_window_state *dem_window_get_state(const dem_window *win) { return &win->st; }
void dem_window_set_state(dem_window *win, const dem_window_state *st) { win->st = *st; }

static void move_wall_x(dem_world *w, int k, double x)
{
    double p[3] = {x, w->walls[k].p[1], w->walls[k].p[2]};
    dem_wall_move(w, k, p);
}

/* Grain mass per metre with centres in [a, b), relative to the sample's. */
static double slab_fraction(const dem_window *win, const dem_world *w, double a, double b)
{
    const dem_grains *g = &w->g;
    double m = 0.0;
    for (int i = 0; i < g->n; i++)
        if (g->x[i] >= a && g->x[i] < b)
            m += 1.0 / g->inv_m[i];
    return m / ((b - a) * win->line_mass);
}

/* Largest overlap (fraction of the smaller radius) of the pairs with an
 * active grain. */
static double seam_overlap(const dem_world *w)
{
    const dem_grains *g = &w->g;
    double m = 0.0;
    for (int p = 0; p < w->n_active_pairs; p++) {
        int i = w->pi[p], j = w->pj[p];
        double dx = g->x[i] - g->x[j], dy = g->y[i] - g->y[j], dz = g->z[i] - g->z[j];
        double delta = g->r[i] + g->r[j] - sqrt(dx * dx + dy * dy + dz * dz);
        if (delta > 0.0)
            m = fmax(m, delta / fmin(g->r[i], g->r[j]));
    }
    return m;
}

/* Pushes the overlapping grains of a seam apart: everything outside
 * [x_lo, x_hi] frozen, steps with the velocities zeroed after each (a
 * steepest descent of the contact energy, each grain moving F/m dt^2) until
 * no overlap exceeds 1 % of the smaller radius, or 400 steps. Stopping a
 * grain only when its force works against its motion (FIRE-like) relaxed
 * further but let the seam slump under gravity: the rigid wheel sank 1.7 mm
 * (12 %) deeper than on the long bed instead of 0.8 mm. The world's
 * clock is put back: this is set-up, not simulated time. *overlap: the
 * largest overlap left (fraction of the radius). Leaves every grain thawed
 * (the caller re-freezes). */
static int relax_seam(dem_window *win, dem_world *w, double x_lo, double x_hi, int *steps, double *overlap,
                      cm_error *err)
{
    dem_grains *g = &w->g;
    double t = w->time;
    long step = w->step;
    /* The rest of the bed only waits: its velocities (by id: a rebuild may
     * re-sort the slots) are put back afterwards, and the tire's contacts
     * are paused so that their springs and node forces stay as they are.
     * Paused, not taken out: a rebuild's re-sort still moves each grain's
     * surface springs with it (until session 32 the surface was detached,
     * the re-sort moved the grains' contact counts but not their springs,
     * and at every appended stretch the tire's springs were left behind on
     * whatever grains took the slots; test_dem_window's wheel checks them). */
    for (int id = 0; id < g->n; id++) {
        int i = g->slot_of[id];
        double *sv = win->saved + 9 * (size_t)id;
        sv[0] = g->vx[i], sv[1] = g->vy[i], sv[2] = g->vz[i];
        sv[3] = g->wx[i], sv[4] = g->wy[i], sv[5] = g->wz[i];
        memcpy(sv + 6, g->angmom + 3 * i, 3 * sizeof *sv);
    }
    w->surf_paused = 1;
    dem_freeze_outside_x(w, x_lo, x_hi);
    int k = 0, rc = CM_OK;
    for (; k < 400; k++) {
        if ((rc = dem_step(w, err))) {
            cm_fail_prefix(err, "window: relaxing the seam at x in [%.3f, %.3f] m: ", x_lo, x_hi);
            break;
        }
        for (int i = 0; i < g->n; i++)
            if (!g->frozen[i]) {
                g->vx[i] = g->vy[i] = g->vz[i] = g->wx[i] = g->wy[i] = g->wz[i] = 0.0;
                g->angmom[3 * i] = g->angmom[3 * i + 1] = g->angmom[3 * i + 2] = 0.0;
            }
        if (k % 10 == 9 && seam_overlap(w) < 0.01)
            break;
    }
    w->surf_paused = 0;
    w->time = t, w->step = step;
    *steps = k + 1;
    *overlap = seam_overlap(w);
    dem_freeze_outside_x(w, -INFINITY, INFINITY); /* the caller re-freezes as the window wants */
    for (int id = 0; id < g->n; id++) {
        int i = g->slot_of[id];
        if (g->x[i] >= x_lo && g->x[i] <= x_hi) {
            g->vx[i] = g->vy[i] = g->vz[i] = g->wx[i] = g->wy[i] = g->wz[i] = 0.0; /* the seam starts at rest */
            g->angmom[3 * i] = g->angmom[3 * i + 1] = g->angmom[3 * i + 2] = 0.0;
            continue;
        }
        const double *sv = win->saved + 9 * (size_t)id;
        g->vx[i] = sv[0], g->vy[i] = sv[1], g->vz[i] = sv[2];
        g->wx[i] = sv[3], g->wy[i] = sv[4], g->wz[i] = sv[5];
        memcpy(g->angmom + 3 * i, sv + 6, 3 * sizeof *sv);
    }
    return rc;
}

/* Appends one copy of the sample stretch in front: copies follow each other
 * at the stretch's period (the first one starts where the grains against
 * the front wall end), as if the sample went on. Copied grains that would
 * overlap a grain already there by more than 40 % of the smaller radius are
 * left out, the rest are pushed apart by relax_seam. Measured on the rigid
 * wheel test: leaving out every overlapping grain left seam slabs at
 * 65-80 % of the sample's density and the wheel sank 25 % deeper. */
static int append_stretch(dem_window *win, dem_world *w, int *added, double *fraction, double *overlap_left,
                          cm_error *err)
{
    const dem_grains *g = &w->g;
    const double F = win->st.x_front, rm = win->r_max;
    const double D = win->st.shifts_front == 0 ? F - rm : win->st.next_offset;
    int nn = 0;
    for (int i = 0; i < g->n; i++)
        if (g->x[i] > D - 3.0 * rm)
            win->near[nn++] = i;
    int count = 0;
    double reach = D;
    for (int j = 0; j < win->n_sample; j++) {
        const dem_grain_state *s = &win->sample[j];
        double x = s->x[0] + D;
        int clash = 0;
        if (s->x[0] < 3.0 * rm) /* beyond, the old grains are out of reach */
            for (int a = 0; a < nn && !clash; a++) {
                int i = win->near[a];
                double dx = x - g->x[i], dy = g->y[i] - s->x[1], dz = g->z[i] - s->x[2];
                double deep = g->r[i] + s->radius - 0.4 * fmin(g->r[i], s->radius);
                clash = dx * dx + dy * dy + dz * dz < deep * deep;
            }
        if (clash)
            continue;
        double off[3] = {D, 0.0, 0.0};
        int rc = dem_grains_add_states(w, 1, s, off, err);
        if (rc) {
            cm_fail_prefix(err, "window: appending the sample stretch at x = %.3f m (dem.max_grains?): ", D);
            return rc;
        }
        count++;
        reach = fmax(reach, x + s->radius);
    }
    win->st.next_offset = D + win->len;
    win->st.x_front = fmax(reach, D + win->len);
    move_wall_x(w, win->st.wall_front, win->st.x_front);
    int steps = 0;
    int rc = relax_seam(win, w, D - 3.0 * rm, D + 3.0 * rm, &steps, overlap_left, err);
    if (rc)
        return rc;
    *added = count;
    *fraction = slab_fraction(win, w, D - 2.0 * rm, D + 2.0 * rm);
    return CM_OK;
}

/* What the wheel at wheel_x asks of the window, the conditions that
 * dem_window_update acts on and dem_window_pending reports: grains to
 * remove behind, a stretch to append in front, the frozen grains to
 * renew (after a change, or when the wheel moved a grain's size). */
static int cut_due(const dem_window *win, double wheel_x)
{
    return wheel_x - win->def.behind - win->st.x_cut >= win->def.shift;
}

static int front_due(const dem_window *win, double wheel_x) { return win->st.x_front - wheel_x < win->def.ahead; }

static int freeze_due(const dem_window *win, double wheel_x, int changed)
{
    return win->def.freeze_distance != 0.0 && (changed || !(fabs(wheel_x - win->st.x_freeze) < win->r_max));
}

/* The live stretch [lo, hi] around the wheel centre: the window's own
 * (behind, ahead), or +-freeze_distance when one is given. */
static void live_stretch(const dem_window *win, double wheel_x, double *lo, double *hi)
{
    const dem_window_def *d = &win->def;
    const int own = d->freeze_distance < 0.0;
    *lo = wheel_x - (own ? d->behind : d->freeze_distance);
    *hi = wheel_x + (own ? d->ahead : d->freeze_distance);
}

int dem_window_pending(const dem_window *win, double wheel_x, double *freeze_lo, double *freeze_hi)
{
    const int shift = cut_due(win, wheel_x) || front_due(win, wheel_x);
    live_stretch(win, wheel_x, freeze_lo, freeze_hi);
    return shift ? DEM_WINDOW_SHIFT : freeze_due(win, wheel_x, shift) ? DEM_WINDOW_FREEZE : DEM_WINDOW_NONE;
}

int dem_window_update(dem_window *win, dem_world *w, double wheel_x, cm_error *err)
{
    const dem_window_def *d = &win->def;
    dem_window_state *st = &win->st;
    int changed = 0;
    if (cut_due(win, wheel_x)) {
        double cut = wheel_x - d->behind;
        st->x_cut = cut;
        int removed = 0;
        if (dem_grains_remove_below_x(w, cut, &removed))
            return cm_fail(err, CM_ERR_NOMEM, "window: removing the grains behind x = %.3f m: out of memory for the "
                           "contact history", cut);
        const dem_grains *g = &w->g;
        double lo = cut;
        for (int i = 0; i < g->n; i++)
            lo = fmin(lo, g->x[i] - g->r[i]);
        st->x_back = lo;
        move_wall_x(w, st->wall_back, lo);
        st->shifts_back++;
        st->removed += removed;
        changed = 1;
        cm_log_info("window: wheel at x = %.3f m: removed %d grains behind x = %.3f m, back wall to %.3f m; %d grains",
                    wheel_x, removed, cut, lo, g->n);
    }
    while (front_due(win, wheel_x)) {
        int added = 0;
        double fraction = 1.0, f_old = st->x_front, overlap = 0.0;
        int rc = append_stretch(win, w, &added, &fraction, &overlap, err);
        if (rc)
            return rc;
        st->shifts_front++;
        st->added += added;
        st->seam_min_fraction = fmin(st->seam_min_fraction, fraction);
        changed = 1;
        cm_log_info("window: wheel at x = %.3f m: appended %d grains (the sample stretch) from x = %.3f m, front wall "
                    "to %.3f m; seam solid fraction %.0f %% of the sample's (overlaps relaxed to %.1f %% of a radius); "
                    "%d grains",
                    wheel_x, added, f_old, st->x_front, 100.0 * fraction, 100.0 * overlap, w->g.n);
    }
    if (freeze_due(win, wheel_x, changed)) {
        double lo, hi;
        live_stretch(win, wheel_x, &lo, &hi);
        st->x_freeze = wheel_x;
        dem_freeze_outside_x(w, lo, hi);
    }
    return CM_OK;
}

int dem_window_check_footprint(const dem_window *win, const dem_world *w, const dem_window_def *def, double wheel_x,
                               double expected_sinkage)
{
    const dem_surface *s = w->surf;
    if (!s || s->n_nodes == 0)
        return 0;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int k = 0; k < s->n_nodes; k++)
        for (int c = 0; c < 3; c++)
            lo[c] = fmin(lo[c], s->x[3 * k + c]), hi[c] = fmax(hi[c], s->x[3 * k + c]);
    double R = 0.5 * (hi[2] - lo[2]), z = fmin(expected_sinkage, R);
    double lc = 2.0 * sqrt(fmax(2.0 * R * z - z * z, 0.0)); /* chord of a circle sunk by z */
    double b = hi[1] - lo[1];
    int warnings = 0;
    cm_log_info("footprint: tire radius %.3f m, width %.3f m, contact length %.3f m at %.1f mm sinkage "
                "(dem.window.expected_sinkage)",
                R, b, lc, 1e3 * z);
    double ahead, behind;
    const char *k_ahead, *k_behind;
    if (win) {
        ahead = def->ahead, behind = def->behind;
        k_ahead = "dem.window.ahead", k_behind = "dem.window.behind";
    } else {
        int kb = find_wall(w, 1, 0, 0), kf = find_wall(w, -1, 0, 0);
        ahead = kf >= 0 ? w->walls[kf].p[0] - wheel_x : INFINITY;
        behind = kb >= 0 ? wheel_x - w->walls[kb].p[0] : INFINITY;
        k_ahead = "dem.bed.box_max[0] (or a dem.window)", k_behind = "wheel.center[0] or dem.bed.box_min[0]";
    }
    if (ahead < 2.0 * lc) {
        cm_log_warn("the bed reaches only %.3f m ahead of the wheel centre%s, less than 2 contact lengths (%.3f m): "
                    "its end stiffens the soil the wheel pushes; raise %s",
                    ahead, win ? "" : " at its start", 2.0 * lc, k_ahead);
        warnings |= DEM_FOOTPRINT_AHEAD;
    }
    if (behind < lc) {
        cm_log_warn("the bed reaches only %.3f m behind the wheel centre, less than a contact length (%.3f m); raise %s",
                    behind, lc, k_behind);
        warnings |= DEM_FOOTPRINT_BEHIND;
    }
    int ky0 = find_wall(w, 0, 1, 0), ky1 = find_wall(w, 0, -1, 0);
    double left = ky0 >= 0 ? lo[1] - w->walls[ky0].p[1] : INFINITY;
    double right = ky1 >= 0 ? w->walls[ky1].p[1] - hi[1] : INFINITY;
    if (fmin(left, right) < 0.5 * b) {
        cm_log_warn("the tire runs %.3f m / %.3f m from the bed's side walls, less than half its width (%.3f m): "
                    "traction reads low in too narrow a soil bin; widen dem.bed.box_min[1] / box_max[1] or centre the "
                    "wheel (wheel.center[1])",
                    left, right, 0.5 * b);
        warnings |= DEM_FOOTPRINT_SIDES;
    }
    /* The floor: by Boussinesq's solution for a uniformly loaded circle of
     * radius a, the vertical stress at depth a under its centre is still
     * 1 - 2^(-3/2) = 65 % of the contact pressure, so a rigid floor nearer
     * than a (a circle of the footprint's area lc x b) carries the wheel
     * rather than the soil, and it stiffens the bed. */
    int kz = find_wall(w, 0, 0, 1);
    double depth = kz >= 0 ? dem_bed_height(w) - w->walls[kz].p[2] - z : INFINITY, a = sqrt(lc * b / M_PI);
    if (depth < a) {
        cm_log_warn("the soil under the tire is %.3f m deep at %.1f mm sinkage, less than the footprint's "
                    "equivalent radius %.3f m: the floor bears %.0f %% of the contact pressure there (Boussinesq) "
                    "and stiffens the bed; deepen the bed (dem.bed.layers)",
                    depth, 1e3 * z, a, 100.0 * (1.0 - pow(1.0 + a * a / fmax(depth * depth, 1e-12), -1.5)));
        warnings |= DEM_FOOTPRINT_FLOOR;
    }
    if (win && def->freeze_distance > 0 && def->freeze_distance < 2.0 * lc) {
        cm_log_warn("dem.window.freeze_distance = %.3f m is shorter than 2 contact lengths (%.3f m): the frozen soil "
                    "ahead stiffens the bed (measured: 22-30 %% less sinkage at 1.1 contact lengths); raise "
                    "dem.window.freeze_distance",
                    def->freeze_distance, 2.0 * lc);
        warnings |= DEM_FOOTPRINT_FREEZE;
    }
    return warnings;
}
