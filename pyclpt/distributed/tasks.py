"""The tasks of a distributed render: what a worker renders (a sample range of one view of a scene)
and how a render is split into them.

A task names its scene by a :class:`SceneSource` (a file path or built-in name that every worker
opens from shared storage, or the Scene itself, shipped with the task), the renderer settings, the
seed and the sample range ``[first_sample, first_sample + count)``. By the seed contract
(:mod:`pyclpt.rendering.renderer`) sample ``s`` of pixel ``p`` is the same whichever worker renders
it, so any split of the sample range renders exactly the samples of one machine.
"""
from __future__ import annotations

import dataclasses
import uuid
from dataclasses import dataclass, field
from typing import Any

from pyclpt.common.checks import check_int
from pyclpt.film.crop import Crop
from pyclpt.scene.model import Camera, Scene

# Settings of pyclpt.rendering.renderer.Renderer a distributed render passes on (device: each worker's own).
RENDERER_SETTINGS = ("integrator", "layout", "max_depth", "width", "height", "wave_size", "precision")


@dataclass(frozen=True)
class SceneSource:
    """Where a worker gets the scene: ``path`` (a scene file on storage every worker sees, or a built-in
    scene name) with Mitsuba ``-D`` parameters ``defines``, or ``scene`` (a Scene shipped with the task,
    for small scenes or scenes made in Python). ``token`` tells shipped scenes apart in the workers'
    caches (a fresh one for every source made from a Scene)."""

    path: str | None = None
    defines: tuple[tuple[str, str], ...] = ()
    scene: Scene | None = None
    token: str = ""

    @staticmethod
    def of(scene: Scene | str, defines: dict[str, object] | None = None) -> SceneSource:
        if isinstance(scene, Scene):
            if defines:
                raise ValueError("defines apply to scene files; this scene is already loaded")
            return SceneSource(scene=scene, token=uuid.uuid4().hex)
        if not isinstance(scene, str) or not scene:
            raise TypeError(f"scene must be a pyclpt.Scene, a scene file path or a built-in scene name, "
                            f"got {type(scene).__name__} {scene!r:.60}")
        return SceneSource(path=scene, defines=tuple(sorted((str(k), str(v)) for k, v in (defines or {}).items())))

    @property
    def name(self) -> str:
        """How errors and logs name it: the file, or the shipped scene's name."""
        return self.path if self.path is not None else f"<shipped scene {self.scene.name!r}>"


@dataclass(frozen=True)
class RenderTask:
    """Samples [first_sample, first_sample + count) of every pixel of one view: the worker returns their
    sum (:class:`~pyclpt.distributed.merge.PartialSum`); ``per_sample``: every sample's own frame instead
    (a sequence whose frames accumulate, merged by prefix sums). ``camera``: the view, when not the
    scene's (a frame of a sequence); ``previous``: the camera of the frame before, which the motion vectors
    point back to (None: no motion); ``frame``: that frame's number; ``crop``: the tile (x, y, width,
    height) of the image to render, None for all of it (:mod:`pyclpt.film.crop`); ``gbuffer``: one frame
    of a denoised sequence, returned with its G-buffer (the settings ask for AOVs)."""

    source: SceneSource
    settings: tuple[tuple[str, Any], ...]
    seed: int
    first_sample: int
    count: int
    camera: Camera | None = None
    previous: Camera | None = None
    frame: int = 0
    per_sample: bool = False
    crop: Crop | None = None
    gbuffer: bool = False
    key: str = field(default_factory=lambda: uuid.uuid4().hex[:12])

    def with_range(self, first_sample: int, count: int) -> RenderTask:
        return dataclasses.replace(self, first_sample=first_sample, count=count, key=uuid.uuid4().hex[:12])


def split_samples(spp: int, task_spp: int, first_sample: int = 0) -> list[tuple[int, int]]:
    """[first_sample, first_sample + spp) in ranges of ``task_spp`` samples (the last one shorter):
    (first, count) pairs in sample order."""
    spp = check_int(spp, "spp", lo=1, hi=2**32)
    task_spp = check_int(task_spp, "task_spp", lo=1)
    return [(s, min(task_spp, first_sample + spp - s)) for s in range(first_sample, first_sample + spp, task_spp)]


def default_task_spp(spp: int, workers: int, tasks_per_worker: int = 4, tiles: int = 1) -> int:
    """Samples per task when none is given: about ``tasks_per_worker`` tasks a worker over all ``tiles``
    of the image, so that a faster worker (a GPU) takes more of them and a lost one costs little, while
    each task stays long enough for its fixed cost (a film sum sent back) to stay small
    (docs/distributed.md)."""
    ranges = -(-max(1, int(workers)) * int(tasks_per_worker) // max(1, int(tiles)))  # sample ranges a tile
    return max(1, -(-int(spp) // ranges))


# Images of more pixels than this are split into tiles when no tile size is given: a task's double
# sum of the whole image (24 bytes a pixel) would pass 48 MiB, and a 4K worker film several times that.
AUTO_TILE_PIXELS = 1 << 21
AUTO_TILE = 512  # pixels a side of those tiles


def tile_size(tile: int | tuple[int, int] | str | None, width: int, height: int) -> tuple[int, int] | None:
    """The (width, height) of the tiles of a width x height image: ``tile`` as given (one size for both
    sides, or two), None for no tiles, or ``"auto"``: AUTO_TILE-pixel tiles for an image of more than
    AUTO_TILE_PIXELS pixels, else none."""
    if tile == "auto":
        return (AUTO_TILE, AUTO_TILE) if width * height > AUTO_TILE_PIXELS else None
    if tile is None:
        return None
    sides = (tile, tile) if not isinstance(tile, (tuple, list)) else tuple(tile)
    if len(sides) != 2:
        raise ValueError(f"tile must be a size, (width, height), 'auto' or None, got {tile!r}")
    return check_int(sides[0], "tile width", lo=1), check_int(sides[1], "tile height", lo=1)
