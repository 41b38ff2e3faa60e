"""Image gradients: :func:`render_backward` (reverse mode, all parameters at once) and
:func:`render_forward` (forward mode, one parameter along a direction), by path replay.

Both render with the estimator of the image (``cl/integrators/path.h``): ``render_forward(scene, name,
d, spp, seed)`` is the derivative along ``d`` of ``pyclpt.render(scene, spp, seed=seed)``, path for
path. Sampling decisions (which lobe, which light, pdfs, MIS weights, roulette) are not
differentiated, as in Mitsuba 3's ``prb``; nor is visibility (docs/differentiable.md).

The scene's device copy, its compiled kernels and buffers are kept between calls
(:mod:`pyclpt.gradients.session`); :func:`clear_cache` drops every copy.

Geometry (``SHAPE.vertex_positions``, ``SHAPE.to_world``, ``INSTANCE.to_world``, a point light's ``position``, a
spot light's ``to_world``) is differentiated when named, in scenes with or without instances: the interior term
by the replay (``cl/gradients/geometry.h``: the material form, shading that follows the moving surfaces) plus the
boundary terms of camera silhouettes, seen directly and in planar mirrors
(:func:`pyclpt.gradients.edges.primary_boundary`), of what the first surface seen receives
(:func:`pyclpt.gradients.shadows.soft_shadow_boundary`) and of point and spot lights' hard shadows, at the first
surface seen (:func:`pyclpt.gradients.shadows.shadow_boundary`) and after a bounce
(:func:`pyclpt.gradients.shadows.delta_shadow_boundary`); an instanced scene's boundary terms are its flattened
scene's (:mod:`pyclpt.gradients.flatten`).
"""
from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Iterable, Sequence

import numpy as np

from pyclpt.common.checks import check_int
from pyclpt.device.context import Device
from pyclpt.gradients.edges import (
    mirrors_need_a_pinhole,
    primary_boundary,
    primary_boundary_forward,
    sensor_names,
    vertex_gradients,
    vertex_motion,
)
from pyclpt.gradients.flatten import flattened
from pyclpt.gradients.layout import (
    BUFFERS,
    buffer_sizes,
    instance_gradient,
    instance_tangent,
    parameter_slots,
    spot_gradient,
    spot_tangent,
    vertex_offset,
)
from pyclpt.gradients.mirrors import delta_lobes, mirror_planes
from pyclpt.gradients.normals import normals_backward, normals_chain, normals_forward
from pyclpt.gradients.parameters import Parameter, SceneParameters
from pyclpt.gradients.session import clear_cache, replay_for  # noqa: F401 (clear_cache: the public name)
from pyclpt.gradients.shadows import (
    delta_shadow_boundary,
    delta_shadow_boundary_forward,
    moving_light_names,
    shadow_boundary,
    shadow_boundary_forward,
    soft_shadow_boundary,
    soft_shadow_boundary_forward,
)
from pyclpt.scene.model import DirectionalLight, Instance, Mesh, PointLight, Scene, SpotLight

log = logging.getLogger("pyclpt")

def _check_seed(seed: int, name: str) -> int:
    return check_int(seed, name, lo=0, hi=2**32 - 1)


def render_backward(scene: Scene, image_grad: np.ndarray, spp: int | None = None, seed: int = 0,
                    max_depth: int | None = None, params: Sequence[str] | SceneParameters | None = None, *,
                    loss_seed: int | None = None, width: int | None = None, height: int | None = None,
                    device: Device | str | None = None, boundary: bool = True, edge_samples: int = 65536,
                    edge_spp: int = 4) -> dict[str, np.ndarray]:
    """Reverse mode: the gradient of a loss with respect to scene parameters, given the loss's gradient
    with respect to the image, ``image_grad`` (H, W, 3) (dLoss/dI of ``pyclpt.render(scene, ...)``).

    ``params``: the names to differentiate, or one name (default: every differentiable one but those of where
    things are; see :func:`pyclpt.traverse`). Returns ``{name: gradient}``, each shaped as the parameter's value.
    Where things are (a mesh's ``vertex_positions`` or ``to_world``, a point light's ``position``: named in
    ``params``): the interior term by the replay plus, with ``boundary``, the boundary terms of visibility (see the
    module): ``edge_samples`` points on camera silhouettes and on hard-shadow outlines, ``edge_spp`` shading points
    a pixel for the outlines in the light the first surfaces receive; outlines seen after the first bounce are
    left out, but for those the camera sees in a planar mirror (docs/differentiable.md).
    ``seed`` must differ from the seed of the image the loss was computed on (``loss_seed``, when
    given, is checked): the same random numbers in both make the gradient biased (the error of the
    image and the paths that carry its gradient would be correlated).
    Memory: independent of spp and depth (the paths are traced twice, nothing stored per path)."""
    seed = _check_seed(seed, "seed")
    if loss_seed is not None and _check_seed(loss_seed, "loss_seed") == seed:
        raise ValueError(f"render_backward: seed {seed} is the seed of the image the loss was computed on; "
                         f"use another seed for the gradient (the same random numbers make it biased: "
                         f"the image's noise and the paths that carry its gradient are correlated)")
    spp = check_int(scene.spp if spp is None else spp, "spp", lo=1, hi=2**32 - 1)
    if isinstance(params, str):  # one name, not its letters
        params = [params]
    elif params is not None and not isinstance(params, SceneParameters):
        names = list(params) if isinstance(params, Iterable) else None
        if names is None or not all(isinstance(n, str) for n in names):
            raise TypeError(f"params must be a parameter name, a sequence of names, a SceneParameters or "
                            f"None, got {type(params).__name__} {params!r:.60}")
        params = names
    replay = replay_for(scene, width=width, height=height, max_depth=max_depth, device=device)
    grad = np.asarray(image_grad, np.float32)
    expected = (replay.height, replay.width, 3)
    if grad.shape != expected:
        raise ValueError(f"image_grad: expected shape {expected} (the rendered image's), got {grad.shape}")
    if not np.all(np.isfinite(grad)):
        raise ValueError("image_grad holds NaN or infinite values")
    # the scene was checked by replay_for (when packed, and again when it changed): no traverse() check here
    table = params if isinstance(params, SceneParameters) else SceneParameters(scene)
    if params is None or isinstance(params, SceneParameters):
        names = [n for n in table.differentiable if table.parameter(n).kind not in ("geometry", "camera")]
    else:
        names = list(params)
    chosen = [table.parameter(n) for n in names]
    bad = [f"{p.name} ({p.reason})" for p in chosen if not p.differentiable]
    if bad:
        raise ValueError(f"not differentiable: {'; '.join(bad)}")
    # The gradient is linear in image_grad: a large one (3e38 is finite in float32) is scaled down by a power
    # of two for the kernels, whose float32 products and sums would overflow to inf (and drop paths), and the
    # result scaled back in double. A power of two changes no rounding, so the gradient of an image_grad of
    # at most 1 in magnitude is unchanged, bit for bit.
    peak = float(np.max(np.abs(grad), initial=0.0))
    shift = int(np.ceil(np.log2(peak))) if peak > 1.0 else 0
    if shift:
        grad = np.ldexp(grad, -shift).astype(np.float32)
    if boundary and replay.max_depth != 0 and any(p.kind in ("geometry", "camera") for p in chosen):
        mirrors_need_a_pinhole(scene)  # before the replay's work (an orthographic camera's outlines in mirrors)
    _warn_delta_outlines(scene, chosen)
    moving = [p.name for p in chosen if p.kind in ("geometry", "camera")]
    collect = replay.backward_started(grad, spp, seed, _kinds(chosen), _moving_vertices(scene, chosen))
    try:  # the boundary terms while the backward kernel runs (their kernels on a second queue)
        terms = boundary_backward(scene, image_grad, moving, table, seed=seed, max_depth=replay.max_depth,
                                  device=device, samples=edge_samples, spp=edge_spp) if moving and boundary else {}
    finally:
        buffers = collect()
    if replay.dropped:
        log.warning("%s: render_backward dropped %d paths with NaN/inf radiance", scene.name, replay.dropped)
    out = {}
    for p in chosen:
        value_shape = p.get().shape
        if p.kind == "camera":  # through the camera's origin and basis
            g12 = np.ldexp(buffers["camera"][:12].astype(np.float64), shift)
            exact = camera_jacobian(scene, replay.width, replay.height, p.name).T @ g12
        elif p.kind == "geometry" and isinstance(p.target, Mesh):  # through its vertices (a pose: chained)
            first, count = vertex_offset(scene, p.target), p.target.positions.shape[0]
            gv = np.ldexp(buffers["verts"][3 * first:3 * (first + count)].astype(np.float64), shift).reshape(-1, 3)
            pose: dict[str, np.ndarray] = {}
            vertex_gradients(table, scene, scene.meshes.index(p.target), [p.name], gv, pose)
            exact = pose[p.name].astype(np.float64)
            if p.target.normals is not None:  # smooth shading: through the normals update() writes
                gn = np.ldexp(buffers["vnormals"][3 * first:3 * (first + count)].astype(np.float64), shift)
                exact = exact + _normals(p, table, gn, normals_backward).reshape(exact.shape)
        elif p.kind == "geometry" and isinstance(p.target, SpotLight):  # its position and axis
            exact = np.ldexp(spot_gradient(scene, replay.scene.arrays, p.target, buffers["lightpos"]), shift)
        elif p.kind == "geometry" and isinstance(p.target, Instance):  # its record's 12 floats
            k = _instance_index(scene, p.target)
            exact = np.ldexp(instance_gradient(replay.scene.arrays, k, buffers["inst"]), shift)
        else:
            exact = np.ldexp(parameter_slots(scene, replay.scene.arrays, p).gather(buffers), shift)
        _check_float32(exact, p.name, peak)
        out[p.name] = exact.astype(np.float32).reshape(value_shape)
    for name, g in terms.items():
        out[name] = (out[name] + g.reshape(out[name].shape)).astype(np.float32)
    return out


def _moving_vertices(scene: Scene, chosen: Sequence) -> tuple[int, int]:
    """The packed vertices [lo, hi) that hold every moved mesh's: the backward kernel scatters no others, and
    replays only the paths that meet one of their triangles (cl/gradients/geometry.h, geo_moving_prim). Every vertex
    when the camera, a light or an instance moves (every path can move then)."""
    moving = [p for p in chosen if p.kind in ("geometry", "camera")]
    if any(p.kind == "camera" or not isinstance(p.target, Mesh) for p in moving):
        return 0, 2**31 - 1
    spans = [(vertex_offset(scene, p.target), p.target.positions.shape[0]) for p in moving]
    if not spans:
        return 0, 0
    return min(lo for lo, _ in spans), max(lo + n for lo, n in spans)


def boundary_backward(scene: Scene, image_grad: np.ndarray, names: Sequence[str], parameters: SceneParameters, *,
                      seed: int, max_depth: int, device: Device | str | None, samples: int = 65536, spp: int = 4
                      ) -> dict[str, np.ndarray]:
    """The boundary terms of visibility for ``names`` (meshes' ``vertex_positions`` and ``to_world``, point lights'
    ``position``, the sensor's ``to_world`` and ``x_fov``): camera silhouettes, outlines in the light the first
    surfaces receive (soft shadows, at max_depth 2 or more) and point, spot and directional lights' hard shadows (at
    the first surface seen and after a bounce); see the module. An instanced scene's are its flattened scene's
    (:mod:`pyclpt.gradients.flatten`: instances' meshes in world space; an instance's to_world the sum of its meshes'
    poses')."""
    if scene.instances:
        flat = flattened(scene)
        terms = boundary_backward(flat.scene, image_grad, flat.names(names), flat.parameters(parameters), seed=seed,
                                  max_depth=max_depth, device=device, samples=samples, spp=spp)
        return flat.fold(names, terms)
    g = np.asarray(image_grad, np.float64)
    replay = replay_for(scene, width=g.shape[1], height=g.shape[0], max_depth=max_depth, device=device)
    dropped = replay.boundary_dropped
    cameras = [n for n in names if n in sensor_names(scene)]
    lights = moving_light_names(scene)
    meshes = [n for n in names if n.endswith((".vertex_positions", ".to_world")) and n not in cameras + list(lights)]
    delta = any(isinstance(light, (PointLight, SpotLight, DirectionalLight)) for light in scene.lights)
    bounce = max_depth < 0 or max_depth >= 2
    out: dict[str, np.ndarray] = {}

    def add(terms: dict[str, np.ndarray]) -> None:
        for name, v in terms.items():
            out[name] = out.get(name, 0.0) + np.asarray(v, np.float64)

    common = dict(seed=seed, max_depth=max_depth, parameters=parameters, device=device)
    if (meshes or cameras) and max_depth != 0:
        add(primary_boundary(scene, g, meshes + cameras, samples=samples, **common))
    if (meshes or cameras) and bounce:
        add(soft_shadow_boundary(scene, g, meshes + cameras, spp=spp, **common))
    if delta and bounce:
        add(shadow_boundary(scene, g, list(names), samples=samples, **common))
    if delta and (max_depth < 0 or max_depth > 2):  # seen after a bounce
        add(delta_shadow_boundary(scene, g, list(names), spp=spp, **common))
    _warn_dropped(scene, replay.boundary_dropped - dropped)
    return out


def _warn_dropped(scene: Scene, dropped: int) -> None:
    """Say how many of the boundary terms' samples had NaN or inf radiance (each counted as 0)."""
    if dropped:
        log.warning("%s: the boundary terms dropped %d samples with NaN/inf radiance (counted as 0)", scene.name,
                    dropped)


def boundary_forward(scene: Scene, name: str, tangent: np.ndarray, parameters: SceneParameters, *, width: int,
                     height: int, seed: int, max_depth: int, device: Device | str | None, samples: int = 65536,
                     spp: int = 4) -> np.ndarray:
    """Forward mode of :func:`boundary_backward`: the boundary terms of d image (H, W, 3) along ``tangent``."""
    if scene.instances:
        flat = flattened(scene)
        return sum((boundary_forward(flat.scene, part, tangent, flat.parameters(parameters), width=width,
                                     height=height, seed=seed, max_depth=max_depth, device=device, samples=samples,
                                     spp=spp) for part in flat.names([name])), np.zeros((height, width, 3)))
    common = dict(width=width, height=height, seed=seed, max_depth=max_depth, parameters=parameters, device=device)
    replay = replay_for(scene, width=width, height=height, max_depth=max_depth, device=device)
    dropped = replay.boundary_dropped
    image = np.zeros((height, width, 3), np.float64)
    camera = name in sensor_names(scene)
    mesh = name.endswith((".vertex_positions", ".to_world")) and not camera and name not in moving_light_names(scene)
    bounce = max_depth < 0 or max_depth >= 2
    if (mesh or camera) and max_depth != 0:
        image += primary_boundary_forward(scene, name, tangent, samples=samples, **common)
    if (mesh or camera) and bounce:
        image += soft_shadow_boundary_forward(scene, name, tangent, spp=spp, **common)
    if bounce and any(isinstance(light, (PointLight, SpotLight, DirectionalLight)) for light in scene.lights):
        image += shadow_boundary_forward(scene, name, tangent, samples=samples, **common)
        if max_depth < 0 or max_depth > 2:  # seen after a bounce
            image += delta_shadow_boundary_forward(scene, name, tangent, spp=spp, **common)
    _warn_dropped(scene, replay.boundary_dropped - dropped)
    return image


def _warn_delta_outlines(scene: Scene, chosen: Sequence[Parameter]) -> None:
    """Where things move in a scene with mirrors or smooth glass, say which outlines seen through them the boundary
    terms leave out (docs/differentiable.md, "What is not differentiated yet"): those seen through curved mirrors
    and refracting glass; after two or more mirror bounces; in mirrors by other surfaces than the camera. The
    camera's outlines seen in one planar mirror are in (:func:`pyclpt.gradients.edges.silhouette_edges`), as they
    move with the meshes, the camera and the mirror itself."""
    if not any(p.kind in ("geometry", "camera") for p in chosen):
        return
    lobes = [delta_lobes(scene.materials[mesh.material]) for mesh in scene.meshes]
    if not any(lobes):
        return
    flat = sorted({plane.mesh for plane in mirror_planes(scene)})
    bent = [mesh.name for i, (mesh, kind) in enumerate(zip(scene.meshes, lobes))
            if "refract" in kind or ("reflect" in kind and i not in flat)]
    planar = [scene.meshes[i].name for i in flat]

    def names(items: Sequence[str]) -> str:
        return ", ".join(items[:4]) + (" ..." if len(items) > 4 else "")

    parts = [f"through curved mirrors or refracting glass ({names(bent)})"] if bent else []
    parts += ["after two or more mirror bounces", "in mirrors by other surfaces than the camera (the soft and "
              "indirect terms)"]
    have = f"; they have the camera's outlines seen in one planar mirror ({names(planar)})" if planar else ""
    log.warning("%s: the boundary terms leave out the outlines seen %s%s", scene.name, "; ".join(parts), have)


def _kinds(chosen: Sequence[Parameter]) -> set[str]:
    """The kernels' specialisation for the parameters ``chosen``: their kinds, ``rigid`` where geometry is
    differentiated but no mesh's vertex_positions (then a face's vertex normals equal to its own stay so), and
    ``instance`` where an instance's to_world is (-DGRAD_INSTANCES)."""
    kinds = {p.kind for p in chosen}
    if kinds & {"geometry", "camera"} and not any(p.name.endswith(".vertex_positions") for p in chosen):
        kinds.add("rigid")
    if any(isinstance(p.target, Instance) for p in chosen):
        kinds.add("instance")
    return kinds


def _instance_index(scene: Scene, inst: Instance) -> int:
    """The index of ``inst`` in ``scene.instances`` (by identity)."""
    return next(k for k, other in enumerate(scene.instances) if other is inst)


def _normals(p: Parameter, table: SceneParameters, value: np.ndarray, chain: Callable[..., np.ndarray]
             ) -> np.ndarray:
    """``chain`` (normals_backward or normals_forward) for a mesh parameter ``p``, with ``value`` the normals'
    gradient or the parameter's tangent."""
    mesh = p.target
    return normals_chain(p.name, mesh.positions, mesh.indices, mesh.normals, value, table[p.name], chain)


#: Steps of the central differences of the camera's basis with respect to its matrix (entries) and its fov
#: (degrees), in float64.
CAMERA_STEPS = {"to_world": 1e-6, "x_fov": 1e-5}


def camera_jacobian(scene: Scene, width: int, height: int, name: str) -> np.ndarray:
    """(12, P): d(origin, forward, right, up of the camera's basis at width x height) / d(parameter ``name``,
    the sensor's ``to_world`` (P = 16, row-major) or ``x_fov`` (P = 1, degrees)), by central differences in
    float64 (the basis is a closed form: exact to about 1e-9 relative)."""
    cam = scene.camera
    kind = name.rpartition(".")[2]
    if kind == "to_world":
        value = np.asarray(cam.to_world, np.float64).reshape(-1)

        def basis(v: np.ndarray) -> np.ndarray:
            return np.concatenate(dataclasses.replace(cam, to_world=v.reshape(4, 4)).basis(width, height))
    else:
        _, _, right, _ = cam.basis(width, height)
        value = np.array([2 * np.degrees(np.arctan(np.linalg.norm(right)))])

        def basis(v: np.ndarray) -> np.ndarray:
            return np.concatenate(dataclasses.replace(cam, fov=float(v[0]), fov_axis="x").basis(width, height))
    h = CAMERA_STEPS[kind]
    jac = np.zeros((12, value.size))
    for k in range(value.size):
        step = np.zeros(value.size)
        step[k] = h
        jac[:, k] = (basis(value + step) - basis(value - step)) / (2 * h)
    return jac


def _check_float32(gradient: np.ndarray, name: str, peak: float) -> None:
    """OverflowError naming the element and its value when a gradient (float64) exceeds float32's range:
    the result is returned as float32, where it would be inf."""
    big = np.flatnonzero(np.abs(gradient) > np.finfo(np.float32).max)
    if big.size:
        i = int(big[0])
        raise OverflowError(f"render_backward: the gradient of {name}[{i}] is {float(gradient.flat[i]):.6g}, "
                            f"beyond float32's range (max {float(np.finfo(np.float32).max):.6g}; the largest "
                            f"image_grad value is {peak:.6g}): scale the loss down")


def render_forward(scene: Scene, param: str, direction: np.ndarray | float | Iterable[float], spp: int | None = None,
                   seed: int = 0, max_depth: int | None = None, *, width: int | None = None,
                   height: int | None = None, device: Device | str | None = None, boundary: bool = True,
                   edge_samples: int = 65536, edge_spp: int = 4) -> np.ndarray:
    """Forward mode: the derivative of ``pyclpt.render(scene, spp, seed=seed)`` along ``direction`` in
    parameter ``param`` (an array of the parameter's shape, or a number for every element): an
    (H, W, 3) float32 gradient image, rendered with the same paths as the image. Where things are: the interior
    term plus, with ``boundary``, the boundary terms (:func:`render_backward`'s, the same samples for a seed)."""
    seed = _check_seed(seed, "seed")
    spp = check_int(scene.spp if spp is None else spp, "spp", lo=1, hi=2**32 - 1)
    replay = replay_for(scene, width=width, height=height, max_depth=max_depth, device=device)
    p = SceneParameters(scene).parameter(param)
    if not p.differentiable:
        raise ValueError(f"{param} is not differentiable: {p.reason}")
    shape = p.get().shape
    d = np.asarray(direction, np.float32)
    if d.size == 1:
        d = np.full(shape, d.reshape(-1)[0], np.float32)
    if d.shape != shape:
        raise ValueError(f"direction for {param}: expected shape {shape}, got {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ValueError(f"direction for {param} holds NaN or infinite values")
    tangent = {name: np.zeros(n, np.float32) for name, n in buffer_sizes(replay.scene.arrays).items()}
    table = SceneParameters(scene)
    if p.kind == "camera":  # the camera's origin and basis
        tangent["camera"][:] = camera_jacobian(scene, replay.width, replay.height, param) @ d.reshape(-1)
    elif p.kind == "geometry" and isinstance(p.target, Mesh):  # the vertices' velocities (a pose's: chained)
        _, dp = vertex_motion(table, scene, param, d)
        first = 3 * vertex_offset(scene, p.target)
        tangent["verts"][first:first + dp.size] = dp.reshape(-1)
        if p.target.normals is not None:  # smooth shading: the normals update() writes move too
            tangent["vnormals"][first:first + dp.size] = _normals(p, table, d, normals_forward).reshape(-1)
    elif p.kind == "geometry" and isinstance(p.target, SpotLight):
        spot_tangent(scene, replay.scene.arrays, p.target, d, tangent["lightpos"])
    elif p.kind == "geometry" and isinstance(p.target, Instance):
        instance_tangent(replay.scene.arrays, _instance_index(scene, p.target), d, tangent["inst"])
    else:
        parameter_slots(scene, replay.scene.arrays, p).scatter(tangent, d)
    geometry = p.kind in ("geometry", "camera")
    if geometry and boundary and replay.max_depth != 0:
        mirrors_need_a_pinhole(scene)  # before the replay's work (an orthographic camera's outlines in mirrors)
    _warn_delta_outlines(scene, [p])
    collect = replay.forward_started({b: tangent[b] for b in BUFFERS}, spp, seed, kinds=_kinds([p]))
    try:  # the boundary terms while the forward kernel runs (their kernels on a second queue)
        terms = boundary_forward(scene, param, d, table, width=replay.width, height=replay.height, seed=seed,
                                 max_depth=replay.max_depth, device=device, samples=edge_samples,
                                 spp=edge_spp) if geometry and boundary else None
    finally:
        image = collect()
    if replay.dropped:
        log.warning("%s: render_forward dropped %d NaN/inf samples", scene.name, replay.dropped)
    return image if terms is None else (image + terms).astype(np.float32)
