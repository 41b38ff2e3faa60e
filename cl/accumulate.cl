/* accumulate: adds one frame (one sample per pixel) to the film's running sum.
 * Consumes: frame[n] floats. Produces: sum[n] += frame[n]. */
__kernel void accumulate(__global float* sum, __global const float* frame, int n) {
    int i = get_global_id(0);
    if (i < n) sum[i] += frame[i];
}
