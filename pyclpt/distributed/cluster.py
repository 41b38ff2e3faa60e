"""Dask clusters for pyclpt: a local one of worker processes, or an existing one by address.

pyclpt runs on any ``dask.distributed`` cluster; it has no scheduler of its own. Clusters on several
machines are started as Dask's documentation says (``dask scheduler`` / ``dask worker`` over SSH,
``dask.distributed.SSHCluster``, dask-jobqueue, dask-kubernetes; docs/distributed.md), and
:func:`connect` joins one by its scheduler's address. Every worker needs pyclpt (with the
``[distributed]`` extra) and the scene files at the same path, or the scenes are shipped with the
tasks.
"""
from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from pyclpt.common.checks import check_int

INSTALL_HINT = "pyclpt's distributed rendering needs dask.distributed: pip install 'pyclpt[distributed]'"


def import_distributed() -> Any:
    """The ``distributed`` module, or ImportError saying how to install it."""
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(f"{INSTALL_HINT} ({exc})") from None
    return distributed


def local_cluster(workers: int, *, threads_per_worker: int = 1, env: dict[str, str] | None = None,
                  **options: Any) -> Any:
    """A ``LocalCluster`` of ``workers`` worker processes on this machine (each one loads the scene and
    opens its own OpenCL device; ``env``: environment variables of the workers, e.g.
    ``{"PYCLPT_DEVICE": "gpu"}`` or PoCL's ``{"POCL_MAX_PTHREAD_COUNT": "1"}``). The dashboard (with bokeh) on
    a free port unless ``dashboard_address`` is given. Close it (or use it in ``with``) when done."""
    workers = check_int(workers, "workers", lo=1)
    threads_per_worker = check_int(threads_per_worker, "threads_per_worker", lo=1)
    distributed = import_distributed()
    options.setdefault("dashboard_address", ":0")  # any free port: clusters side by side do not collide
    options.setdefault("silence_logs", logging.CRITICAL)  # the workers' own logs: the job re-raises their errors
    return distributed.LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker, processes=True,
                                    env=dict(env or {}), **options)


@contextmanager
def connect(scheduler: str | None = None, workers: int | None = None, *,
            env: dict[str, str] | None = None) -> Iterator[Any]:
    """A ``dask.distributed.Client``: of the cluster whose scheduler is at ``scheduler``
    (``tcp://host:8786``), or of a new local cluster of ``workers`` processes (closed on exit)."""
    if (scheduler is None) == (workers is None):
        raise ValueError("give either a scheduler address or a number of local workers")
    distributed = import_distributed()
    if scheduler is not None:
        with distributed.Client(scheduler) as client:
            yield client
        return
    with local_cluster(workers, env=env) as cluster, distributed.Client(cluster) as client:
        yield client
