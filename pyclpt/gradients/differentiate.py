"""Image gradients: :func:`render_backward` (reverse mode, all parameters at once) and
:func:`render_forward` (forward mode, one parameter along a direction), by path replay.

Both render with the estimator of the image (``cl/integrators/path.h``): ``render_forward(scene, name,
d, spp, seed)`` is the derivative along ``d`` of ``pyclpt.render(scene, spp, seed=seed)``, path for
path. Sampling decisions (which lobe, which light, pdfs, MIS weights, roulette) are not
differentiated, as in Mitsuba 3's ``prb``; nor is visibility (docs/differentiable.md).

The scene's device copy, its compiled kernels and buffers are kept between calls for the most recent
scenes (:data:`CACHE_SIZE`), so that an optimisation loop pays for them once; :meth:`SceneParameters.update`
uploads changed values into them, and so does the next call after a change made to the scene model
directly (a field assigned, a list element replaced, a numpy array edited in place: every call compares
a digest of the scene's arrays, :func:`pyclpt.scene.model.content_digest`, about 0.1 ms for the Cornell
box and a few ms for 100k triangles). A changed texel or emitter is uploaded again; changed geometry
(vertices moved in place) rebuilds the scene's device copy and BVH. Either way the scene is validated
again, so a NaN written into an array is the usual validation error. :func:`clear_cache` drops every
copy.
"""
from __future__ import annotations

import logging
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from pyclpt.buffers.scene import SceneBuffers
from pyclpt.common.checks import check_int, check_optional_int
from pyclpt.device.context import Device, get_device
from pyclpt.gradients.layout import BUFFERS, buffer_sizes, parameter_slots
from pyclpt.gradients.parameters import SceneParameters, forget, on_update
from pyclpt.gradients.replay import PathReplay
from pyclpt.scene.model import Scene, content_digest, generation

log = logging.getLogger("pyclpt")

CACHE_SIZE = 4  # scenes whose device copies are kept
UNLIMITED_DEPTH = 1024  # max_depth -1: paths end by Russian roulette, at most this many bounces


def appearance_key(scene: Scene) -> tuple:
    """What changes when the scene's materials, textures or emitters are changed through the model:
    any field assignment (model.generation), an element of a list replaced, the environment."""
    return (generation(), tuple(map(id, scene.materials)), tuple(map(id, scene.meshes)),
            tuple(map(id, scene.lights)), id(scene.environment))


@dataclass
class _Session:
    scene: Scene
    device: Device
    buffers: SceneBuffers
    key: tuple
    digest: tuple[bytes, bytes] = (b"", b"")  # content_digest of the arrays the buffers were built from
    replays: dict[tuple[int, int, int], PathReplay] = field(default_factory=dict)


_SESSIONS: OrderedDict[tuple[int, int], _Session] = OrderedDict()


def clear_cache() -> None:
    """Drop every scene's device copy kept for gradients."""
    for s in _SESSIONS.values():
        forget(s.scene)
    _SESSIONS.clear()


def replay_for(scene: Scene, *, width: int | None = None, height: int | None = None, max_depth: int | None = None,
               device: Device | str | None = None) -> PathReplay:
    """The :class:`PathReplay` of ``scene`` at that resolution and depth (cached; see the module)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a pyclpt.Scene, got {type(scene).__name__}")
    dev = get_device(device)
    width = check_optional_int(width, "width", lo=1, hi=65536) or scene.film.width
    height = check_optional_int(height, "height", lo=1, hi=65536) or scene.film.height
    depth = check_optional_int(max_depth, "max_depth", lo=-1, note=" (-1 = unlimited)")
    depth = scene.max_depth if depth is None else depth
    depth = UNLIMITED_DEPTH if depth == -1 else depth
    key = (id(scene), id(dev))
    session = _SESSIONS.get(key)
    digest = content_digest(scene, values=False)  # arrays edited in place (checked every call)
    if session is not None and session.scene is scene and session.digest[0] != digest[0]:
        try:  # the geometry changed in place: its BVH refitted or built again, the scene checked again
            scene.validate()
            session.buffers.refresh_geometry()
            session.key, session.digest = appearance_key(scene), digest
        except ValueError:  # it needs other kernels (or is invalid: validated again below, raising)
            forget(scene)
            session = None
    if session is None or session.scene is not scene:
        scene.validate()
        session = _Session(scene, dev, SceneBuffers(scene, dev), appearance_key(scene), digest)
        _SESSIONS[key] = session

        def refresh(areas: frozenset[str], s: _Session = session) -> None:
            if "geometry" in areas:
                s.buffers.refresh_geometry()
            else:
                s.buffers.refresh_appearance()
            if "camera" in areas:
                s.buffers.refresh_camera()
            s.key = appearance_key(s.scene)
            s.digest = content_digest(s.scene, values=False)

        on_update(scene, refresh)
        while len(_SESSIONS) > CACHE_SIZE:
            _, old = _SESSIONS.popitem(last=False)
            forget(old.scene)
    elif session.key != appearance_key(scene) or session.digest != digest:
        # the model was changed directly, not through update(): a field assigned, or an array (texels,
        # emission) edited in place; refresh_appearance validates the scene again
        session.buffers.refresh_appearance()
        session.key = appearance_key(scene)
        session.digest = digest
    _SESSIONS.move_to_end(key)
    rkey = (width, height, depth)
    if rkey not in session.replays:
        session.replays[rkey] = PathReplay(dev, session.buffers, width, height, depth)
    return session.replays[rkey]


def _check_seed(seed: int, name: str) -> int:
    return check_int(seed, name, lo=0, hi=2**32 - 1)


def render_backward(scene: Scene, image_grad: np.ndarray, spp: int | None = None, seed: int = 0,
                    max_depth: int | None = None, params: Sequence[str] | SceneParameters | None = None, *,
                    loss_seed: int | None = None, width: int | None = None, height: int | None = None,
                    device: Device | str | None = None) -> dict[str, np.ndarray]:
    """Reverse mode: the gradient of a loss with respect to scene parameters, given the loss's gradient
    with respect to the image, ``image_grad`` (H, W, 3) (dLoss/dI of ``pyclpt.render(scene, ...)``).

    ``params``: the names to differentiate, or one name (default: every differentiable one; see
    :func:`pyclpt.traverse`). Returns ``{name: gradient}``, each shaped as the parameter's value.
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
    names = table.differentiable if params is None or isinstance(params, SceneParameters) else list(params)
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
    buffers = replay.backward(grad, spp, seed, {p.kind for p in chosen})
    if replay.dropped:
        log.warning("%s: render_backward dropped %d paths with NaN/inf radiance", scene.name, replay.dropped)
    out = {}
    for p in chosen:
        value_shape = p.get().shape
        exact = np.ldexp(parameter_slots(scene, replay.scene.arrays, p).gather(buffers), shift)
        _check_float32(exact, p.name, peak)
        out[p.name] = exact.astype(np.float32).reshape(value_shape)
    return out


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
                   height: int | None = None, device: Device | str | None = None) -> np.ndarray:
    """Forward mode: the derivative of ``pyclpt.render(scene, spp, seed=seed)`` along ``direction`` in
    parameter ``param`` (an array of the parameter's shape, or a number for every element): an
    (H, W, 3) float32 gradient image, rendered with the same paths as the image."""
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
    parameter_slots(scene, replay.scene.arrays, p).scatter(tangent, d)
    image = replay.forward({b: tangent[b] for b in BUFFERS}, spp, seed)
    if replay.dropped:
        log.warning("%s: render_forward dropped %d NaN/inf samples", scene.name, replay.dropped)
    return image
