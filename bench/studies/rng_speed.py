"""Is Philox on scalar, unrolled rounds faster than the uint4 loop it replaced? Yes: 51x on PoCL (21.4 -> 1089
Mdraws/s, vectorized), 1.1x on Intel's runtime (docs/wavefront.md, "Vectorized stages").

Philox4x32-10 draws per second: cl/core/rng.h's scalar, unrolled rounds against the form it replaced
(a uint4 state, a rolled loop and OpenCL's mul_hi), in one run on one device.

    python -m bench.studies.rng_speed [--device pocl|intel|...] [--items 1048576] [--repeats 5]

Each work-item draws 8 numbers (bounces 0..7 of one dimension, as a path does) and writes their sum.
Prints Mdraws/s of each form (median of the repeats, compile excluded), their ratio, and the vectorizer's
verdict is in ``POCL_VECTORIZER_REMARKS=1 POCL_KERNEL_CACHE=0`` runs of this script.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np
import pyopencl as cl

from bench.report.machine import cpu_model
from pyclpt.device.context import alloc, get_device
from pyclpt.device.program import build_program

DRAWS = 8

KERNELS = r"""
#include "core/rng.h"

/* The form before: a uint4 state, a rolled loop, mul_hi. */
static inline uint4 philox_before(uint4 c, uint2 k) {
    const uint M0 = 0xD2511F53u, M1 = 0xCD9E8D57u;
    const uint W0 = 0x9E3779B9u, W1 = 0xBB67AE85u;
    for (int r = 0; r < 10; ++r) {
        uint hi0 = mul_hi(M0, c.x), lo0 = M0 * c.x;
        uint hi1 = mul_hi(M1, c.z), lo1 = M1 * c.z;
        c = (uint4)(hi1 ^ c.y ^ k.x, lo1, hi0 ^ c.w ^ k.y, lo0);
        k.x += W0;
        k.y += W1;
    }
    return c;
}

__kernel void draws_before(__global float* out, uint seed) {
    int i = get_global_id(0);
    float sum = 0.0f;
    for (uint b = 0; b < DRAWS; ++b) {
        uint4 r = philox_before((uint4)(1u, b, 3u, 0u), (uint2)(seed, (uint)i));
        sum += (float)(r.x >> 8) * 0x1.0p-24f;
    }
    out[i] = sum;
}

__kernel void draws_now(__global float* out, uint seed) {
    int i = get_global_id(0);
    RngKey key = rng_key(seed, (uint)i, 1u);
    float sum = 0.0f;
#pragma unroll
    for (uint b = 0; b < DRAWS; ++b) sum += rng_1d(key, b, 3u);
    out[i] = sum;
}
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None)
    ap.add_argument("--items", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    dev = get_device(a.device)
    prog = build_program(dev, source=KERNELS, defines={"DRAWS": DRAWS}, name="bench_rng_speed")
    out = alloc(dev, 4 * a.items, "rng output")
    q = dev.queue
    results = {}
    sums = {}
    for name in ("draws_before", "draws_now"):
        kernel = getattr(prog, name)
        kernel(q, (a.items,), None, out, np.uint32(7)).wait()  # first launch: PoCL generates code
        times = []
        for _ in range(a.repeats):
            start = time.perf_counter()
            kernel(q, (a.items,), None, out, np.uint32(7)).wait()
            times.append(time.perf_counter() - start)
        host = np.empty(a.items, np.float32)
        cl.enqueue_copy(q, host, out)
        sums[name] = host
        results[name] = a.items * DRAWS / statistics.median(times) / 1e6
    if not np.array_equal(sums["draws_before"], sums["draws_now"]):
        print("the two forms drew different numbers", file=sys.stderr)
        return 1
    print(f"{dev.name} on {cpu_model()}: {a.items} items x {DRAWS} draws, median of {a.repeats}")
    print(f"  before (uint4, loop, mul_hi): {results['draws_before']:8.1f} Mdraws/s")
    print(f"  now (scalar, unrolled):       {results['draws_now']:8.1f} Mdraws/s")
    print(f"  now / before: {results['draws_now'] / results['draws_before']:.1f}x (same numbers)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
