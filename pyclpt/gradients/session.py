"""The device copies of scenes kept for gradients: :func:`replay_for` gives the :class:`PathReplay` of a scene at
a resolution and depth, kept between calls for the most recent scenes (:data:`CACHE_SIZE`) so that an optimisation
loop pays for the scene's buffers and kernels once; :meth:`SceneParameters.update` uploads changed values into them,
and so does the next call after a change made to the scene model directly (a field assigned, a list element
replaced, a numpy array edited in place: every call compares a digest of the scene's arrays,
:func:`pyclpt.scene.model.content_digest`). :func:`clear_cache` drops every copy.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

from pyclpt.buffers.scene import SceneBuffers
from pyclpt.common.checks import check_optional_int
from pyclpt.device.context import Device, get_device
from pyclpt.gradients.parameters import forget, on_update
from pyclpt.gradients.replay import PathReplay
from pyclpt.scene.model import Scene, content_digest, generation

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
