/* Small 3-vector algebra used by both servers. Header-only so that the
 * compiler inlines it in the hot loops. Units are whatever the caller's are. */
#ifndef CM_VEC3_H
#define CM_VEC3_H

#include <math.h>

typedef struct vec3 {
    double x, y, z;
} vec3;

static inline vec3 v3(double x, double y, double z) { return (vec3){x, y, z}; }
static inline vec3 v3_add(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline vec3 v3_sub(vec3 a, vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline vec3 v3_scale(vec3 a, double s) { return v3(a.x * s, a.y * s, a.z * s); }
static inline vec3 v3_axpy(double s, vec3 a, vec3 b) { return v3(s * a.x + b.x, s * a.y + b.y, s * a.z + b.z); }
static inline double v3_dot(vec3 a, vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline vec3 v3_cross(vec3 a, vec3 b)
{
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline double v3_norm2(vec3 a) { return v3_dot(a, a); }
static inline double v3_norm(vec3 a) { return sqrt(v3_dot(a, a)); }
/* Unit vector along a; the zero vector stays zero. */
static inline vec3 v3_unit(vec3 a)
{
    double n = v3_norm(a);
    return n > 0.0 ? v3_scale(a, 1.0 / n) : a;
}
static inline vec3 v3_load(const double *p) { return v3(p[0], p[1], p[2]); }
static inline void v3_store(double *p, vec3 a) { p[0] = a.x; p[1] = a.y; p[2] = a.z; }

#endif
