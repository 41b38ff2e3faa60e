/* light_contribution: adds the MIS-weighted light sample to the path's radiance.
 * Consumes: the light-contribution queue (unoccluded shadow rays) of this bounce.
 * Produces: updated radiance L. */
#include "integrators/wavefront/wavefront.h"

__kernel void light_contribution(PATH_PARAMS, QUEUE_ARGS, __global const int* light_queue) {
    int i = get_global_id(0);
    if (i >= queue_count(counters, bounce, Q_LIGHT)) return;
    PathStore P = PATH_INIT;
    int slot = light_queue[i];
    path_set_L(&P, slot, path_get_L(&P, slot) + path_get_shadow_contrib(&P, slot));
}
