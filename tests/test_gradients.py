"""Differentiable rendering (pyclpt.gradients): parameters by name, reverse mode against central finite
differences with the same seed on both sides (within 5 %, Mitsuba's own bound), forward mode against
reverse mode, analytic furnaces, linearity in emission, seeds, memory, and inverse rendering."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pyopencl
import pytest
from gradient_scenes import filling_sphere, material_under_sky, sphere_under_envmap, textured_quad

import pyclpt
from pyclpt.buffers.scene import SceneBuffers
from pyclpt.gradients.differentiate import replay_for
from scenes import interior_furnace

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # the examples of docs/differentiable.md: bench/evaluations/ beside pyclpt/
    sys.path.insert(0, str(REPO))
from bench.evaluations import inverse_rendering  # noqa: E402

RED = "red.reflectance.value"
RED_TRUTH = np.array([0.570068, 0.0430135, 0.0443706], np.float32)


@pytest.fixture
def box() -> pyclpt.Scene:
    return pyclpt.load("cornell-box")


# ---- parameters by name ---------------------------------------------------------------------------


def test_traverse_names_as_mitsuba(box):
    params = pyclpt.traverse(box)
    for name in ("white.reflectance.value", "green.reflectance.value", RED, "light.emitter.radiance.value"):
        assert name in params.differentiable, name
        assert params[name].shape == (3,)
    np.testing.assert_allclose(params[RED], RED_TRUTH, rtol=1e-6)
    assert "floor.to_world" in params.differentiable  # where things are: differentiated when named
    assert "floor.vertex_positions" in params.differentiable  # smooth or flat: through the normals update() writes


def test_traverse_names_every_kind():
    scene = pyclpt.load_dict({
        "type": "scene",
        "env": {"type": "envmap", "data": np.ones((4, 8, 3), np.float32)},
        "lamp": {"type": "point", "position": [0, 3, 0], "intensity": 5.0},
        "a": {"type": "cube", "bsdf": {"type": "roughconductor", "id": "metal", "alpha": 0.2}},
        "b": {"type": "cube", "bsdf": {"type": "roughplastic", "id": "rp", "alpha": 0.2}},
        "c": {"type": "cube", "bsdf": {"type": "roughdielectric", "id": "glass", "alpha": 0.2}},
        "d": {"type": "cube", "bsdf": {"type": "twosided", "id": "two", "bsdf": {"type": "plastic"}}},
        "e": {"type": "cube", "bsdf": {"type": "diffuse", "reflectance": {
            "type": "bitmap", "data": np.full((2, 2, 3), 0.5, np.float32)}}},
        "f": {"type": "cube", "bsdf": {"type": "conductor", "id": "mirror"}},
        "g": {"type": "cube", "bsdf": {"type": "roughconductor", "id": "brushed", "alpha_u": 0.1, "alpha_v": 0.3}},
        "h": {"type": "cube", "bsdf": {"type": "twosided", "id": "pair", "f": {"type": "diffuse"},
                                       "b": {"type": "roughconductor", "alpha": 0.2}}},
    })
    params = pyclpt.traverse(scene)
    for name in ("env.data", "metal.alpha.value", "metal.specular_reflectance.value", "rp.alpha",
                 "rp.diffuse_reflectance.value", "rp.specular_reflectance.value", "glass.alpha.value",
                 "two.brdf_0.diffuse_reflectance.value", "e.bsdf.reflectance.data",
                 "mirror.specular_reflectance.value", "brushed.specular_reflectance.value",
                 "pair.brdf_0.reflectance.value"):
        assert name in params.differentiable, (name, list(params))
    assert params["env.data"].shape == (4, 8, 3)
    assert params["e.bsdf.reflectance.data"].shape == (2, 2, 3)
    unsupported = params.unsupported()
    for name in ("lamp.intensity.value", "glass.int_ior", "metal.eta.value", "env.scale",
                 "glass.specular_transmittance.value", "brushed.alpha_u.value", "brushed.alpha_v.value",
                 "pair.brdf_1.alpha.value", "pair.brdf_1.specular_reflectance.value"):
        assert name in unsupported and unsupported[name], name
    assert "anisotropic" in unsupported["brushed.alpha_v.value"] and "back" in unsupported["pair.brdf_1.alpha.value"]
    assert "brushed.alpha.value" not in params


def test_update_checks_values_and_keeps_the_scene(box):
    params = pyclpt.traverse(box)
    with pytest.raises(ValueError, match="red.reflectance.value"):
        params[RED] = [-0.5, 0.1, 0.1]
        params.update()
    np.testing.assert_allclose(params[RED], RED_TRUTH, rtol=1e-6)
    with pytest.raises(ValueError, match="expected shape"):
        params[RED] = np.ones(4)
    with pytest.raises(ValueError, match="finite"):
        params[RED] = [np.nan, 0, 0]
    with pytest.raises(KeyError, match="'red' has: red.reflectance.value"):
        params["red.reflectance.data"]
    with pytest.raises(ValueError, match="floor.vertex_positions: expected shape"):  # moving is allowed
        params["floor.vertex_positions"] = params["floor.vertex_positions"][:-1]


def test_roughness_must_stay_positive():
    scene = material_under_sky({"type": "roughconductor", "alpha": 0.3})
    params = pyclpt.traverse(scene)
    with pytest.raises(ValueError, match="m.alpha.value.*> 0"):
        params.update({"m.alpha.value": 0.0})
    assert params["m.alpha.value"][0] == pytest.approx(0.3)


def test_update_uploads_only_what_changed(box, device):
    buffers = SceneBuffers(box, device)
    nodes = buffers.args(8, 8)[0]
    params = pyclpt.traverse(box)
    params[RED] = [0.2, 0.3, 0.4]
    params.update()
    assert buffers.refresh_appearance() == ["materials"]
    assert buffers.args(8, 8)[0] is nodes  # the BVH stays
    params["light.emitter.radiance.value"] = [1.0, 2.0, 3.0]
    params.update()
    assert buffers.refresh_appearance() == ["lights"]


def test_update_reaches_the_gradient_renderer(box):
    replay = replay_for(box, width=8, height=8, max_depth=2)
    params = pyclpt.traverse(box)
    params.update({RED: [0.25, 0.5, 0.75]})
    material = next(int(k.split(":")[1]) for k, v in box.ids.items() if v == "red")
    np.testing.assert_allclose(replay.scene.arrays.materials[material, 2:5], [0.25, 0.5, 0.75])


def test_update_that_needs_new_kernels_is_refused():
    scene = interior_furnace(0.5)
    replay_for(scene, width=4, height=4, max_depth=2)
    params = pyclpt.traverse(scene)
    with pytest.raises(ValueError, match="SCENE_LIGHTS"):
        params.update({"shell.emitter.radiance.value": 0.0})  # the scene's only emitter would vanish
    assert params["shell.emitter.radiance.value"][0] == 1.0  # and the scene is as it was


# ---- finite differences ----------------------------------------------------------------------------

CASES = {
    # name: (scene, parameter, spp, max_depth, FD step relative to the value)
    "diffuse": (lambda: pyclpt.load("cornell-box"), RED, 16, 3, 0.01),
    "area-light": (lambda: pyclpt.load("cornell-box"), "light.emitter.radiance.value", 16, 3, 0.01),
    "constant-env": (lambda: material_under_sky({"type": "diffuse"}), "sky.radiance.value", 16, 3, 0.01),
    "bitmap": (lambda: textured_quad(np.random.default_rng(3).random((4, 4, 3)).astype(np.float32) * 0.6 + 0.2),
               "tex.reflectance.data", 16, 2, 0.01),
    "bitmap-nearest": (lambda: textured_quad(np.full((3, 5, 1), 0.4, np.float32), filter="nearest"),
                       "tex.reflectance.data", 16, 2, 0.01),
    "envmap": (lambda: sphere_under_envmap(np.random.default_rng(4).random((6, 12, 3)).astype(np.float32) + 0.2),
               "env.data", 32, 3, 0.01),
    "conductor-spec": (lambda: material_under_sky({"type": "conductor", "material": "Au",
                                                   "specular_reflectance": [0.5, 0.7, 0.9]}),
                       "m.specular_reflectance.value", 16, 3, 0.01),
    "roughconductor-spec": (lambda: material_under_sky({"type": "roughconductor", "alpha": 0.3}),
                            "m.specular_reflectance.value", 16, 3, 0.01),
    "roughconductor-alpha": (lambda: material_under_sky({"type": "roughconductor", "material": "Cu", "alpha": 0.3}),
                             "m.alpha.value", 512, 3, 0.05),
    "plastic-spec": (lambda: material_under_sky({"type": "plastic", "diffuse_reflectance": [0.3, 0.5, 0.2]}),
                     "m.specular_reflectance.value", 256, 3, 0.05),
    "plastic-diffuse-nonlinear": (lambda: material_under_sky({"type": "plastic", "nonlinear": True,
                                                              "diffuse_reflectance": [0.3, 0.5, 0.2]}),
                                  "m.diffuse_reflectance.value", 256, 3, 0.05),
    "roughplastic-spec": (lambda: material_under_sky({"type": "roughplastic", "alpha": 0.3}),
                          "m.specular_reflectance.value", 256, 3, 0.05),
    # h = 1 % of alpha: at 5 % the differences' truncation error was 5 % of the derivative (eight seeds: 0.95x,
    # backward over differences, against 1.02x at 1 %)
    "roughplastic-alpha": (lambda: material_under_sky({"type": "roughplastic", "alpha": 0.3}),
                           "m.alpha", 256, 3, 0.01),
    "roughdielectric-alpha": (lambda: material_under_sky({"type": "roughdielectric", "alpha": 0.3}),
                              "m.alpha.value", 1024, 3, 0.05),
    # the front of twosided pairs, whose backs (one a rough conductor) the camera sees too
    "twosided-front": (lambda: pyclpt.load(Path(__file__).parent / "data" / "twosided-pair.xml"),
                       "red-blue.brdf_0.reflectance.value", 16, 3, 0.01),
}
SIZE = 16
#: Seeds whose sums are compared, where one seed's differences are too noisy for 5 %: a roughness's derivative is
#: heavy-tailed per seed (the rough dielectric's at 1024 spp: -16 % to +21 % over seeds 11-26, -0.4 % summed over
#: them; as much before the bounce's random numbers moved to two blocks, and -8 % to +7 % over groups of four):
#: sixteen seeds for it, four for the others.
SEEDS = {"roughconductor-alpha": (11, 12, 13, 14), "roughplastic-alpha": (11, 12, 13, 14),
         "roughdielectric-alpha": tuple(range(11, 27))}


def test_moved_alpha_records_cover_the_back_materials():
    """The roughness-moved records the gradient kernels read by material id include a TwoSided's back
    records (ids past the scene's materials), with alpha moved and the anisotropic alpha_v kept."""
    from pyclpt.buffers.materials import MAT_ALPHA, MAT_ALPHA_V, pack_materials
    from pyclpt.gradients.replay import moved_alpha_records

    scene = pyclpt.load(Path(__file__).parent / "data" / "twosided-pair.xml")
    scene.materials.append(pyclpt.Conductor(alpha=0.2, alpha_v=0.4))
    recs = pack_materials(scene.materials).materials
    up, down = moved_alpha_records(scene)
    assert up.shape == down.shape == recs.shape and len(recs) > len(scene.materials)
    rough = recs[:, MAT_ALPHA] > 0
    assert rough[len(scene.materials):].any()  # the gold back
    np.testing.assert_allclose(up[rough, MAT_ALPHA] / recs[rough, MAT_ALPHA], 1 + 1 / 64, rtol=1e-6)
    brushed = len(scene.materials) - 1
    assert up[brushed, MAT_ALPHA_V] == down[brushed, MAT_ALPHA_V] == np.float32(0.4)


def _loss_weights(shape) -> np.ndarray:
    return np.random.default_rng(1).random(shape).astype(np.float32)


@pytest.mark.parametrize("case", sorted(CASES))
def test_backward_matches_finite_differences(case):
    """Central differences of sum(w * image) along a random direction d (of random signs for texels),
    with the same seed on both sides, against reverse mode's gradient . d (within 5 %) and forward
    mode's sum(w * dimage) (equal: the same paths)."""
    make, name, spp, depth, step = CASES[case]
    scene = make()
    params = pyclpt.traverse(scene)
    v0 = params[name]
    rng = np.random.default_rng(2)
    # texels: signs at random, so that a gradient given to the wrong texel does not average out
    d = (rng.standard_normal(v0.shape) if v0.size > 3 else rng.random(v0.shape) + 0.5).astype(np.float32)
    h = step * float(np.abs(v0).max())
    w = _loss_weights((SIZE, SIZE, 3))
    fd = backward = forward = 0.0
    for seed in SEEDS.get(case, (11,)):
        opts = dict(spp=spp, seed=seed, max_depth=depth, width=SIZE, height=SIZE)

        def loss(v, opts=opts):
            params.update({name: v})
            return float((w * pyclpt.render(scene, **opts)).sum(dtype=np.float64))

        fd += (loss(v0 + h * d) - loss(v0 - h * d)) / (2 * h)
        params.update({name: v0})
        grad = pyclpt.render_backward(scene, w, params=[name], **opts)[name]
        assert grad.shape == v0.shape
        backward += float((grad.astype(np.float64) * d).sum())
        forward += float((w * pyclpt.render_forward(scene, name, d, **opts)).sum(dtype=np.float64))
    assert abs(fd) > 1e-3
    assert backward == pytest.approx(fd, rel=0.05), (backward, fd)
    assert forward == pytest.approx(backward, rel=1e-3)


def test_each_texel_gets_its_bilinear_share_of_a_pixel():
    """The gradient of one pixel with respect to each texel of a bilinear bitmap is that texel's share of the pixel:
    every texel against central differences of it alone. The quad under a constant sky is linear in its texels, so
    with the same seed the differences are exact; a texel given its neighbour's weight is far off (the random loss
    weights of test_backward_matches_finite_differences average such a swap away)."""
    scene = textured_quad(np.random.default_rng(4).random((4, 4, 1)).astype(np.float32) * 0.6 + 0.2)
    name = "tex.reflectance.data"
    params = pyclpt.traverse(scene)
    v0 = np.array(params[name], np.float32)
    opts = dict(spp=16, seed=3, max_depth=2, width=SIZE, height=SIZE)
    w = np.zeros((SIZE, SIZE, 3), np.float32)
    w[5, 9] = 1.0  # a pixel between texel centres, nearer one column than one row
    grad = pyclpt.render_backward(scene, w, params=[name], **opts)[name]
    fd = np.zeros_like(v0)
    for idx in np.ndindex(v0.shape):
        loss = []
        for sign in (1.0, -1.0):
            v = v0.copy()
            v[idx] += sign * 0.05
            params.update({name: v})
            loss.append(float((w * pyclpt.render(scene, **opts)).sum(dtype=np.float64)))
        fd[idx] = (loss[0] - loss[1]) / 0.1
    params.update({name: v0})
    assert (fd > 1e-3 * fd.max()).sum() >= 3  # the pixel's samples read several texels
    np.testing.assert_allclose(grad, fd, rtol=0, atol=2e-3 * fd.max())


@pytest.mark.parametrize("deferred", [0, 2])
def test_replay_gives_the_gradients_of_the_deferred_pass(box, device, deferred):
    """Vertices past DEFERRED_VERTICES are done by replaying the path (0: all of them, Mitsuba's prb as
    published); the gradients are those of the one-pass default, up to the order of float atomics."""
    from pyclpt.buffers.scene import SceneBuffers
    from pyclpt.gradients.layout import BUFFERS
    from pyclpt.gradients.replay import PathReplay

    buffers = SceneBuffers(box, device)
    w = _loss_weights((16, 16, 3))
    kinds = ["color", "emission"]
    default = PathReplay(device, buffers, 16, 16, 8).backward(w, 8, 3, kinds)
    replayed = PathReplay(device, buffers, 16, 16, 8, deferred_vertices=deferred).backward(w, 8, 3, kinds)
    for name in BUFFERS:
        np.testing.assert_allclose(replayed[name], default[name], rtol=1e-4, atol=1e-7)
    assert np.abs(default["mats"]).max() > 0


# ---- analytic cases ---------------------------------------------------------------------------------


def test_convex_diffuse_sphere_in_uniform_light():
    """I = rho Le on a convex diffuse object in a uniform environment: dI/drho = Le, dI/dLe = rho."""
    rho, le = 0.4, 1.5
    scene = filling_sphere(rho, le)
    opts = dict(spp=256, seed=3, max_depth=-1)
    image = pyclpt.render(scene, **opts)
    assert image.mean() == pytest.approx(rho * le, rel=0.02)
    d_rho = pyclpt.render_forward(scene, "ball.reflectance.value", 1.0, **opts)
    np.testing.assert_allclose(d_rho, image / rho, rtol=1e-4)  # linear in rho, path for path
    assert d_rho.mean() == pytest.approx(le, rel=0.02)
    grads = pyclpt.render_backward(scene, np.ones_like(image) / image.size, spp=256, seed=4, max_depth=-1)
    assert grads["ball.reflectance.value"].sum() == pytest.approx(le, rel=0.02)
    assert grads["sky.radiance.value"].sum() == pytest.approx(rho, rel=0.02)


@pytest.mark.parametrize("rho", [0.3, 0.6])
def test_closed_furnace(rho):
    """Inside a closed emissive diffuse sphere: L = Le / (1 - rho), dL/drho = Le / (1 - rho)^2,
    dL/dLe = 1 / (1 - rho)."""
    le = 2.0
    scene = interior_furnace(rho, le)
    n = 8
    grads = pyclpt.render_backward(scene, np.full((n, n, 3), 1.0 / (3 * n * n), np.float32), spp=256, seed=5,
                                   max_depth=-1, width=n, height=n)
    assert grads["shell.bsdf.reflectance.value"].sum() == pytest.approx(le / (1 - rho) ** 2, rel=0.03)
    assert grads["shell.emitter.radiance.value"].sum() == pytest.approx(1 / (1 - rho), rel=0.03)
    d_rho = pyclpt.render_forward(scene, "shell.bsdf.reflectance.value", 1.0, spp=256, seed=6, max_depth=-1,
                                  width=n, height=n)
    assert d_rho.mean() == pytest.approx(le / (1 - rho) ** 2, rel=0.03)


def test_image_is_linear_in_emission(box):
    """Scaling every emitter scales the image, path for path: dI/dLe . Le = I (Euler's theorem)."""
    opts = dict(spp=4, seed=7, max_depth=8, width=24, height=24)
    image = pyclpt.render(box, **opts)
    le = pyclpt.traverse(box)["light.emitter.radiance.value"]
    d_image = pyclpt.render_forward(box, "light.emitter.radiance.value", le, **opts)
    np.testing.assert_allclose(d_image, image, rtol=1e-4, atol=1e-6)
    w = _loss_weights(image.shape)
    grad = pyclpt.render_backward(box, w, params=["light.emitter.radiance.value"], **opts)
    assert float(grad["light.emitter.radiance.value"] @ le) == pytest.approx(float((w * image).sum()), rel=1e-4)


# ---- seeds, errors, memory -----------------------------------------------------------------------------


def test_gradient_seed_must_differ_from_the_loss_seed(box):
    grad = np.zeros((8, 8, 3), np.float32)
    with pytest.raises(ValueError, match="biased"):
        pyclpt.render_backward(box, grad, spp=1, seed=3, loss_seed=3, width=8, height=8)
    pyclpt.render_backward(box, grad, spp=1, seed=4, loss_seed=3, width=8, height=8)


def test_bad_arguments_name_what_is_wrong(box):
    with pytest.raises(ValueError, match="expected shape \\(8, 8, 3\\)"):
        pyclpt.render_backward(box, np.zeros((4, 4, 3)), spp=1, width=8, height=8)
    with pytest.raises(ValueError, match="NaN"):
        pyclpt.render_backward(box, np.full((8, 8, 3), np.nan), spp=1, width=8, height=8)
    checkered = pyclpt.load_dict({"type": "scene", "floor": {"type": "rectangle", "bsdf": {
        "type": "diffuse", "reflectance": {"type": "checkerboard"}}}})
    with pytest.raises(ValueError, match="not differentiable: floor.vertex_positions \\(a checkerboard"):
        pyclpt.render_backward(checkered, np.zeros((8, 8, 3)), spp=1, width=8, height=8,
                               params=["floor.vertex_positions"])
    with pytest.raises(KeyError, match="no parameter"):
        pyclpt.render_forward(box, "nothing.value", 1.0, spp=1, width=8, height=8)
    with pytest.raises(ValueError, match="direction for red.reflectance.value"):
        pyclpt.render_forward(box, RED, np.ones(2), spp=1, width=8, height=8)


def test_zero_mean_gradient_at_the_optimum(box):
    """At the true value, the loss image and the gradient on separate seeds give gradients whose mean
    is zero: averaged over seeds, it is small next to the gradient away from the optimum."""
    n, spp = 24, 4
    opts = dict(width=n, height=n, max_depth=4)
    target = pyclpt.render(box, spp=64, seed=1000, **opts)
    params = pyclpt.traverse(box)

    def gradient(seed: int) -> np.ndarray:
        image = pyclpt.render(box, spp=spp, seed=2 * seed, **opts)
        g = 2 * (image - target) / image.size
        return pyclpt.render_backward(box, g, spp=spp, seed=2 * seed + 1, loss_seed=2 * seed, params=[RED],
                                      **opts)[RED]

    at_optimum = np.mean([gradient(k) for k in range(8)], axis=0)
    params.update({RED: RED_TRUTH + 0.2})
    away = gradient(0)
    params.update({RED: RED_TRUTH})
    assert np.all(np.abs(at_optimum) < 0.15 * np.abs(away)), (at_optimum, away)


def test_device_memory_does_not_grow_with_spp_or_depth(box):
    grad = np.ones((16, 16, 3), np.float32)
    replay = replay_for(box, width=16, height=16, max_depth=8)
    pyclpt.render_backward(box, grad, spp=1, seed=1, width=16, height=16, max_depth=8)
    small = replay.device_bytes
    pyclpt.render_backward(box, grad, spp=64, seed=1, width=16, height=16, max_depth=8)
    assert replay.device_bytes == small
    deep = replay_for(box, width=16, height=16, max_depth=64)
    pyclpt.render_backward(box, grad, spp=64, seed=1, width=16, height=16, max_depth=64)
    assert deep.device_bytes == small


def _pose_gradient(scene: pyclpt.Scene, device: pyclpt.Device, mode: str, seed: int = 5) -> np.ndarray:
    """The small box's pose gradient (backward) or the image's derivative along its x translation (forward), with
    both terms, 24 x 24, 4 spp, depth 3."""
    kw = dict(spp=4, seed=seed, max_depth=3, width=24, height=24, device=device)
    if mode == "backward":
        grad = np.ones((24, 24, 3), np.float32)
        return pyclpt.render_backward(scene, grad, params=["small-box.to_world"], **kw)["small-box.to_world"]
    along_x = np.zeros((4, 4))
    along_x[0, 3] = 1.0
    return pyclpt.render_forward(scene, "small-box.to_world", along_x, **kw)


@pytest.mark.parametrize("mode", ["backward", "forward"])
def test_boundary_terms_run_beside_the_replay(box, each_device, mode, monkeypatch):
    """render_backward and render_forward compute the boundary terms while the replay's kernel runs: their kernels go
    to a second queue where the device runs two queues at once (Intel's runtime), to the replay's own on PoCL (one
    command at a time). The gradient is the one the two give one after the other, and the pass's kernels, once
    recorded, are those of the last pass alone."""
    from pyclpt.gradients.replay import PathReplay

    beside = _pose_gradient(box, each_device, mode)
    replay = replay_for(box, width=24, height=24, max_depth=3, device=each_device)
    events = replay.profile.events
    main = each_device.queue.int_ptr
    queues = {name: {ev.get_info(pyopencl.event_info.COMMAND_QUEUE).int_ptr for ev in evs}
              for name, evs in events.items()}
    assert queues[mode] == {main}
    assert queues["vertex_radiance"] == ({main} if each_device.is_pocl else {replay.side_queue.int_ptr})
    launches = len(replay.profile.sequence)
    _pose_gradient(box, each_device, mode, seed=6)
    assert len(replay.profile.sequence) == launches  # the last pass's alone
    with monkeypatch.context() as m:  # one queue, one after the other
        m.setattr(PathReplay, "side_queue", property(lambda self: self.device.queue))
        after = _pose_gradient(box, each_device, mode)
    np.testing.assert_allclose(beside, after, rtol=1e-4, atol=1e-6 * np.abs(after).max())
    assert np.abs(after).max() > 0


def test_boundary_kernels_reuse_their_buffers(box, device, monkeypatch):
    """The boundary terms' kernels keep their arguments' buffers from pass to pass (a fresh buffer a launch cost the
    CPU device fresh pages each time): a second pass allocates none."""
    import pyclpt.gradients.replay as replay_module

    _pose_gradient(box, device, "backward")
    calls = []
    real = replay_module.alloc
    monkeypatch.setattr(replay_module, "alloc", lambda *a, **k: calls.append(a[2]) or real(*a, **k))
    _pose_gradient(box, device, "backward", seed=6)
    assert calls == []
    replay = replay_for(box, width=24, height=24, max_depth=3, device=device)
    held, scratch = replay.device_bytes, sum(b.size for b in replay._scratch_buffers.values())
    monkeypatch.setattr(replay, "_scratch_buffers", {})
    assert scratch > 0 and held - replay.device_bytes == scratch  # device_bytes counts them


def test_a_failing_boundary_term_leaves_the_replay_as_it_was(box, each_device, monkeypatch):
    """An error in the boundary terms propagates, after the replay's kernel is waited for, and the next pass is
    whole: the same gradient as before the error."""
    import pyclpt.gradients.differentiate as differentiate

    before = _pose_gradient(box, each_device, "backward")
    with monkeypatch.context() as m:
        def fail(*args, **kwargs):
            raise RuntimeError("boundary term failed")
        m.setattr(differentiate, "boundary_backward", fail)
        with pytest.raises(RuntimeError, match="boundary term failed"):
            _pose_gradient(box, each_device, "backward")
    replay = replay_for(box, width=24, height=24, max_depth=3, device=each_device)
    assert replay._queue is each_device.queue
    np.testing.assert_allclose(_pose_gradient(box, each_device, "backward"), before, rtol=1e-4,
                               atol=1e-6 * np.abs(before).max())


# ---- inverse rendering ------------------------------------------------------------------------------


def test_recover_the_red_wall():
    """The cornell box's red wall from (0.01, 0.2, 0.9) to within 0.005 of its reflectance, in at most 50
    Adam steps at 128x128, 4 spp."""
    history = inverse_rendering.recover_red_wall(steps=50)
    errors = [float(np.abs(v - RED_TRUTH).max()) for v in history["values"]]
    assert errors[0] > 0.5
    assert errors[-1] < 0.005, errors[-10:]


def test_recover_a_texture():
    """A 4x4 bitmap texture from grey, by its texels' gradients."""
    history = inverse_rendering.recover_texture(steps=40)
    truth = history["truth"]
    start, end = (float(np.abs(history["values"][k] - truth).mean()) for k in (0, -1))
    assert end < 0.1 * start, (start, end)


def test_adam_minimises_a_quadratic():
    opt = pyclpt.optim.Adam(lr=0.1, params={"x": np.array([3.0, -2.0])})
    for _ in range(200):
        opt.step({"x": 2 * (opt["x"] - np.array([1.0, 0.5]))})
    np.testing.assert_allclose(opt["x"], [1.0, 0.5], atol=1e-2)
    with pytest.raises(ValueError, match="shape"):
        opt.step({"x": np.ones(3)})
    with pytest.raises(ValueError, match="lr"):
        pyclpt.optim.Adam(lr=-1)


def test_primal_of_the_gradient_renderer_is_pyclpt_render(box):
    replay = replay_for(box, width=16, height=16, max_depth=8)
    np.testing.assert_array_equal(replay.primal(4, 9), pyclpt.render(box, spp=4, seed=9, width=16, height=16,
                                                                     max_depth=8))


def test_torch_bridge(box):
    torch = pytest.importorskip("torch")
    from pyclpt.gradients.torch_bridge import render_torch

    opts = dict(spp=4, seed=3, max_depth=8, width=16, height=16)
    red = torch.tensor(RED_TRUTH + 0.1, requires_grad=True)
    image = render_torch(box, {RED: red}, **opts)
    assert image.shape == (16, 16, 3)
    loss = (image ** 2).mean()
    loss.backward()
    expected = pyclpt.render_backward(box, 2 * image.detach().numpy() / image.numel(), spp=4, seed=4, max_depth=8,
                                      width=16, height=16, params=[RED])[RED]
    np.testing.assert_allclose(red.grad.numpy(), expected, rtol=1e-4)
    with pytest.raises(TypeError, match="torch tensor"):
        render_torch(box, {RED: RED_TRUTH}, **opts)


def test_a_change_made_to_the_model_reaches_the_gradient_renderer(box):
    """Not only update(): a material's field assigned directly, or a material replaced, is seen."""
    opts = dict(spp=2, seed=5, max_depth=3, width=8, height=8)
    before = pyclpt.render_forward(box, "light.emitter.radiance.value", 1.0, **opts)
    red = list(box.ids.values()).index("red")
    box.materials[red].reflectance = (0.9, 0.9, 0.9)
    after = pyclpt.render_forward(box, "light.emitter.radiance.value", 1.0, **opts)
    assert not np.array_equal(before, after)
    le = pyclpt.traverse(box)["light.emitter.radiance.value"]
    np.testing.assert_allclose(after, pyclpt.render(box, **opts) / le, rtol=1e-4, atol=1e-7)  # linear in Le
    box.materials[red] = pyclpt.Diffuse((0.1, 0.1, 0.1))
    replaced = pyclpt.render_forward(box, "light.emitter.radiance.value", 1.0, **opts)
    assert replaced.sum() < after.sum()
    box.camera = pyclpt.Camera.look_at((0.5, 0.2, 3.0), (0, 0, 0), fov=50)  # a new view, too
    moved = pyclpt.render_forward(box, "light.emitter.radiance.value", 1.0, **opts)
    np.testing.assert_allclose(moved, pyclpt.render(box, **opts) / le, rtol=1e-4, atol=1e-7)
