"""Instanced scenes for the boundary terms of visibility (:mod:`pyclpt.gradients.edges`, :mod:`.shadows`): the
host-side edge sampling and Embree ray casts work on a scene's plain meshes, so an instanced scene is handed to them
flattened (as :meth:`pyclpt.Scene.flattened`): every instance's shapegroup meshes become plain meshes in world space
(positions by the instance's ``to_world``, normals by its inverse transpose, the winding reversed under a mirroring
one, as the kernels place them), named ``INSTANCE#k`` (the k-th mesh of
its group), each posed by the instance's ``to_world``, so that the boundary term of ``INSTANCE.to_world`` is the sum
of its meshes' ``INSTANCE#k.to_world`` terms (their outlines move as a mesh's under a pose: dT T^-1 x). The flat
scene shares the instanced one's materials, lights and camera; it is kept (with its device copy, for the
boundary kernels) while nothing in the instanced scene changes (:func:`flattened`).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from pyclpt.scene.model import Scene, content_digest, generation


@dataclass
class Flat:
    """An instanced scene flattened for the boundary terms."""

    scene: Scene  # the plain meshes, then every instance's meshes in world space
    poses: dict[str, np.ndarray]  # INSTANCE#k.to_world -> the instance's to_world (4x4 float64)
    parts: dict[str, list[str]]  # INSTANCE.to_world -> its meshes' INSTANCE#k.to_world

    def parameters(self, parameters: Mapping[str, np.ndarray]) -> Mapping[str, np.ndarray]:
        """What the boundary functions read of a SceneParameters (``params[name]``): the instanced scene's values,
        and the flattened meshes' poses."""
        return _Values(parameters, self.poses)

    def names(self, names: Sequence[str]) -> list[str]:
        """``names`` of the instanced scene as the flat scene's (an instance's to_world: its meshes' poses)."""
        return [f for n in names for f in self.parts.get(n, [n])]

    def fold(self, names: Sequence[str], terms: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The flat scene's terms back to ``names`` of the instanced scene (an instance's: its meshes' summed)."""
        out: dict[str, np.ndarray] = {}
        for n in names:
            parts = [terms[f] for f in self.parts.get(n, [n]) if f in terms]
            if parts:
                out[n] = np.sum([np.asarray(p, np.float64) for p in parts], axis=0)
        return out


class _Values(Mapping[str, np.ndarray]):
    def __init__(self, base: Mapping[str, np.ndarray], poses: dict[str, np.ndarray]) -> None:
        self.base, self.poses = base, poses

    def __getitem__(self, name: str) -> np.ndarray:
        return self.poses[name].copy() if name in self.poses else self.base[name]

    def __iter__(self):
        yield from self.poses
        yield from self.base

    def __len__(self) -> int:
        return len(self.poses) + len(self.base)


def instance_names(scene: Scene) -> list[str]:
    """The parameter prefix of each of ``scene.instances`` (pyclpt.traverse's: its name, ``NAME_k`` when several
    instances share it)."""
    names = [i.name for i in scene.instances]
    return [inst.name if names.count(inst.name) == 1 else f"{inst.name}_{k}" for k, inst in enumerate(scene.instances)]


def flatten(scene: Scene) -> Flat:
    """The flat scene of ``scene`` (see the module)."""
    meshes = list(scene.meshes)
    poses: dict[str, np.ndarray] = {}
    parts: dict[str, list[str]] = {}
    taken = {m.name for m in meshes}
    for prefix, inst in zip(instance_names(scene), scene.instances):
        m = np.asarray(inst.to_world, np.float64)
        for k, mesh in enumerate(scene.groups[inst.group].meshes):
            name = f"{prefix}#{k}"
            if name in taken:
                raise ValueError(f"instance {prefix!r}: a mesh is named {name!r} (the flattened instance's name)")
            taken.add(name)
            meshes.append(mesh.placed(m, name))
            poses[f"{name}.to_world"] = m.copy()
            parts.setdefault(f"{prefix}.to_world", []).append(f"{name}.to_world")
    flat = dataclasses.replace(scene, meshes=meshes, groups={}, instances=[])
    return Flat(flat, poses, parts)


_CACHE: dict[int, tuple[tuple, Scene, Flat]] = {}


def flattened(scene: Scene) -> Flat:
    """:func:`flatten`, kept for ``scene`` while nothing in it changes (its content and every field assignment:
    :func:`pyclpt.scene.model.content_digest`, :func:`pyclpt.scene.model.generation`), so that its device copy
    (pyclpt.gradients.session) is reused."""
    key = (content_digest(scene), generation(), id(scene.camera), tuple(map(id, scene.lights)))
    hit = _CACHE.get(id(scene))
    if hit is not None and hit[1] is scene and hit[0] == key:
        return hit[2]
    flat = flatten(scene)
    _CACHE.clear()  # one flat scene at a time: the boundary kernels' device copy of the last one
    _CACHE[id(scene)] = (key, scene, flat)
    return flat
