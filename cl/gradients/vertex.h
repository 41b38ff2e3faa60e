/* vertex.h: a vertex of a camera path as the boundary terms' kernels read it (path_vertices.cl writes the later
 * ones; pyclpt/gradients/shadows.py, shading_points): its barycentrics u, v on its triangle, then the world
 * direction back along the path (3), or, at the camera ray's first hit (depth 0), the film position x, y of that
 * ray and 0, whose direction is found again here. */
#ifndef PYCLPT_GRADIENT_VERTEX_H
#define PYCLPT_GRADIENT_VERTEX_H

#include "integrators/path.h"

/* The unit direction back along the path at the vertex whose record starts at q (above), of bounce `depth`. */
static inline vec3 vertex_back(const Scene* sc, RngKey key, __global const float* q, int depth) {
    if (depth != 0) return v3(q[2], q[3], q[4]);
    PathState cam; /* the camera ray through film position (q[2], q[3]) (pinhole or orthographic: no random numbers) */
    camera_ray(sc, key, q[2], q[3], &cam);
    return v3_neg(cam.dir);
}

#endif
