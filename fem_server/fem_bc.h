/* Supports and dead loads by named set (fem.supports, fem.loads; the sets:
 * fem_set in fem.h). Internal to fem/. */
#ifndef FEM_BC_H
#define FEM_BC_H

#include "error.h"
#include "fem.h"
#include "fem_mesh.h"
#include "fem_solver.h"

/* Fixes the dofs the supports name at their values (no supports: the rim
 * set clamped, as fem_solver_constrain_rim). */
int fem_bc_constrain(fem_solver *s, const fem_mesh *m, const fem_config *cfg, cm_error *err);
/* Adds the consistent nodal loads of cfg->loads to f (3 per node, rim frame). */
int fem_bc_loads(const fem_mesh *m, const fem_config *cfg, double *f, cm_error *err);

#endif
