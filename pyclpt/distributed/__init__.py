"""Renders spread over a Dask cluster (``dask.distributed``; the ``[distributed]`` extra):
sample ranges, tiles of large images, frames of a sequence, merged exactly (docs/distributed.md).

    from dask.distributed import Client, LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1) as cluster, Client(cluster) as client:
        image = pyclpt.render("cornell-box", spp=64, client=client)

:mod:`.tasks` (what a task renders, the split), :mod:`.worker` (a task on a worker, its scene
cache), :mod:`.merge` (the partial sums added in order), :mod:`.renderer` (the client side),
:mod:`.cluster` (local clusters, connecting). dask is imported only when a cluster is used.

May import every layer below it: common, scene, accel, device, film, buffers, integrators, denoise,
gradients, rendering; nothing below imports it (``pyclpt.render(..., client=)`` reaches
:func:`~.renderer.render_on_cluster` by name: :data:`pyclpt.rendering.renderer.CLUSTER_RENDER`)."""
from __future__ import annotations

from pyclpt.distributed.cluster import connect, local_cluster
from pyclpt.distributed.merge import PartialSum, merge
from pyclpt.distributed.renderer import DistributedRenderer, render, render_on_cluster
from pyclpt.distributed.tasks import RenderTask, SceneSource, split_samples
from pyclpt.distributed.worker import WorkerError

# render: pyclpt.render (pyclpt.rendering.renderer), kept importable here, where it lived before
__all__ = ["connect", "DistributedRenderer", "local_cluster", "merge", "PartialSum", "render", "render_on_cluster",
           "RenderTask", "SceneSource", "split_samples", "WorkerError"]
