/* Free rotation of a shaped grain's rigid body (eq. 8; see dem_shape.h). */
#include "dem_shape.h"

#include <math.h>

#include "dem_shape_algebra.h"

/* ---- rotation -------------------------------------------------------------- */

/* q <- q (cos φ/2, sin φ/2 e_k): rotation by φ about body axis k; the body
 * components of the (world-constant) angular momentum turn by -φ. */
static inline void rotate_axis(double q[4], double pi[3], int k, double phi)
{
    double c = cos(0.5 * phi), s = sin(0.5 * phi);
    double r[4] = {c, 0, 0, 0};
    r[1 + k] = s;
    double w = q[0] * r[0] - q[1] * r[1] - q[2] * r[2] - q[3] * r[3];
    double x = q[0] * r[1] + q[1] * r[0] + q[2] * r[3] - q[3] * r[2];
    double y = q[0] * r[2] - q[1] * r[3] + q[2] * r[0] + q[3] * r[1];
    double z = q[0] * r[3] + q[1] * r[2] - q[2] * r[1] + q[3] * r[0];
    q[0] = w, q[1] = x, q[2] = y, q[3] = z;
    int a = (k + 1) % 3, b = (k + 2) % 3;
    double cp = cos(phi), sp = sin(phi);
    double pa = pi[a], pb = pi[b];
    pi[a] = cp * pa + sp * pb;
    pi[b] = -sp * pa + cp * pb;
}

void dem_rotate_free(double q[4], const double L[3], const double I[3], double dt, double omega[3])
{
    double R[9], pi[3];
    dem_quat_to_mat(q, R);
    mat_tvec(R, L, pi);
    const int axis[5] = {2, 1, 0, 1, 2};
    const double frac[5] = {0.5, 0.5, 1.0, 0.5, 0.5};
    for (int s = 0; s < 5; s++) {
        int k = axis[s];
        rotate_axis(q, pi, k, frac[s] * dt * pi[k] / I[k]);
    }
    double qn = 1.0 / sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int k = 0; k < 4; k++)
        q[k] *= qn;
    dem_quat_to_mat(q, R);
    double wb[3] = {pi[0] / I[0], pi[1] / I[1], pi[2] / I[2]};
    mat_vec(R, wb, omega);
}
