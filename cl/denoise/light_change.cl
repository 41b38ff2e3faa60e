/* light_change: how many pixels saw an emitter change this frame. One work-item per LIGHT_CHUNK
 * pixels, 1D range; after reproject.
 *
 * reproject marks a pixel whose history holds where a light changed (light_changed: the emitting
 * samples of one material in this frame's 3x3 and the previous frame's apart by a factor). Their count
 * tells light_age whether the lighting changed in view this frame, and the anti-lag then cuts more
 * readily for a few frames (DenoiserSettings.antilag_changed). One work-item sums LIGHT_CHUNK marks
 * and adds the sum to the counter (one atomic per chunk, none per pixel); integer sums do not depend
 * on the order the work-items run in.
 *
 * Consumes: lit[0 .. pixels-1] (uchar, reproject: 1 where a light changed).
 * Produces: changed[0] += their sum; lit zeroed. */
#include "denoise/svgf.h"
#include "film/marks.h"

__kernel void light_change(__global uchar* lit, int pixels, volatile __global int* changed) {
    int begin = (int)get_global_id(0) * LIGHT_CHUNK;
    if (begin >= pixels) return;
    int sum = take_marks(lit, begin, min(begin + LIGHT_CHUNK, pixels));
    if (sum != 0) atomic_add(changed, sum);
}
