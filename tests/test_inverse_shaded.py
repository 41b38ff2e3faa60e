"""bench/evaluations/inverse_shaded.py at tiny sizes: a diffuse box's pose and the camera's translation, and a sphere
mesh's shape, recovered from SHADED images (an area light, soft shadows) with both terms of render_backward's
derivative. The older examples (inverse_pose.py, inverse_shape.py) differentiate silhouettes only, which is not the
derivative of these images (their shading and shadows move too)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # the examples of docs/differentiable.md: bench/evaluations/ beside pyclpt/
    sys.path.insert(0, str(REPO))
from bench.evaluations import inverse_shaded  # noqa: E402


def test_recover_a_shaded_pose_and_the_camera():
    """On the small floor (its edges in view): the box's translation within 0.08 and its angle within 6 degrees,
    the camera's translation within 0.03, in 100 Adam steps at 32x32, 8 spp, from errors of 0.3 / 0.25, 30 degrees
    and 0.25 / 0.2; the loss falls. The gradients are summed by float atomics, so a run on PoCL is not
    bit-reproducible and the optimisation amplifies the difference. Over about 150 runs on PoCL (2026-11-29) the box
    ended within 0.028 and 2.4 degrees in all but five, whose worst were 0.053 (a CI run) and 2.8, 3.4, 4.1 and
    4.4 degrees: its angle's gradient is the weakest, and a run that wanders at the high learning rate of the
    first half may not be back by the end (150 steps, or the mean of the last 20 steps, did no better); the camera
    ended within 0.014. (Bounds of 0.05 and 2.5 degrees failed in a few per cent of runs; at 60 steps the angle
    ended at 0.1-2.6 degrees.) (The example's large floor, whose edges are out of view, is the harder case: too
    slow for a test at this size.)
    The loss of each step's 8-spp render against the 128-spp target ends at its noise floor, 0.493-0.505 of the
    first step's in six runs (a bound of 0.5 failed in CI at 0.5035): it is bounded at 0.6. The image error itself
    is measured without that noise, the final and the starting pose rendered with the target's random numbers:
    0.2-0.7 % of the start's."""
    h = inverse_shaded.recover_pose(steps=100, width=32, height=32, spp=8, edge_samples=8192, target_spp=128,
                                    floor=1.8)
    pose, truth = np.array(h["pose"]), np.array(h["truth_pose"])
    assert np.abs(pose[:2] - truth[:2]).max() < 0.08, h["pose_error"][-1]
    assert abs(pose[2] - truth[2]) * inverse_shaded.DEGREES < 6.0, h["pose_error"][-1]
    assert np.abs(np.array(h["camera"]) - np.array(h["truth_camera"])).max() < 0.03, h["camera_error"][-1]
    assert np.mean(h["losses"][-5:]) < 0.6 * h["losses"][0]
    start, final = (np.mean((h[k] - h["target"]) ** 2) for k in ("start", "final"))
    assert final < 0.05 * start, (final, start)


def test_recover_a_shaded_shape():
    """A flat-shaded (8 x 16) sphere mesh moves towards the target ellipsoid's surface from five shaded views: the mean
    relative radial distance down to 0.55 of the sphere's in 60 steps at 32x32, 8 spp (0.42 measured; 0.18 at 40x40
    in 150 steps, docs/differentiable/shaded.json)."""
    h = inverse_shaded.recover_shape(steps=60, width=32, height=32, spp=8, edge_samples=4096, rings=8, segments=16,
                                     lr=0.04)
    assert h["vertex_error"][-1] < 0.55 * h["vertex_error"][0], h["vertex_error"][::10]
    assert np.mean(h["losses"][-5:]) < h["losses"][0]
