/* light_contribution: adds the MIS-weighted light sample to the path's radiance.
 * Consumes: the light-contribution queue (unoccluded shadow rays) of this bounce.
 * Produces: updated radiance L.
 * Written on scalar components: a float3 operation stops PoCL's vectorizer. */
#include "integrators/wavefront/wavefront.h"

__kernel void light_contribution(PATH_PARAMS, QUEUE_ARGS, __global const int* light_queue) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_LIGHT)) return;
    PathStore P = PATH_INIT;
    int slot = light_queue[i];
    path_set_L_x(&P, slot, path_get_L_x(&P, slot) + path_get_shadow_contrib_x(&P, slot));
    path_set_L_y(&P, slot, path_get_L_y(&P, slot) + path_get_shadow_contrib_y(&P, slot));
    path_set_L_z(&P, slot, path_get_L_z(&P, slot) + path_get_shadow_contrib_z(&P, slot));
}
