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
import os
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any
from urllib.parse import urlsplit

from pyclpt.common.checks import check_int

INSTALL_HINT = "pyclpt's distributed rendering needs dask.distributed: pip install 'pyclpt[distributed]'"
# A local cluster of more worker processes than this many per core is refused: each process opens its own
# OpenCL device and runs its kernels on every core, so they only wait on each other (12 workers on 2 cores
# took 107 s for a sub-second render); more workers than cores is allowed with a warning.
MAX_WORKERS_PER_CORE = 4
# Seconds to wait for a TCP connection to a scheduler's address before handing it to Dask (a hang guard:
# a refused connection answers at once; one that is slow to answer is left to Dask's own timeout).
PROBE_TIMEOUT_S = 5.0

log = logging.getLogger("pyclpt")


def cores() -> int:
    """The CPU cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def check_workers(workers: object) -> int:
    """``workers`` local worker processes: ValueError naming the value above MAX_WORKERS_PER_CORE times the
    cores, a warning (the ``pyclpt`` logger) above the cores."""
    workers = check_int(workers, "workers", lo=1)
    n = cores()
    if workers > MAX_WORKERS_PER_CORE * n:
        raise ValueError(f"workers={workers}: a local cluster of {workers} worker processes on {n} CPU cores "
                         f"(at most {MAX_WORKERS_PER_CORE * n}: {MAX_WORKERS_PER_CORE} a core) only makes them "
                         f"wait on each other; use at most {n}, or a cluster of several machines (--scheduler)")
    if workers > n:
        log.warning("%d local workers on %d CPU cores: each renders on every core, so more workers than cores "
                    "render slower, not faster (use at most %d)", workers, n, n)
    return workers


def probe_scheduler(address: str, timeout: float = PROBE_TIMEOUT_S) -> None:
    """ConnectionError naming ``address`` at once when nothing listens there (the connection is refused),
    instead of Dask's retries for its whole connect timeout (30 s). A slow answer (no reply within
    ``timeout`` seconds) or an address that is not TCP is left to Dask."""
    if not isinstance(address, str):
        raise TypeError(f"scheduler must be an address string (tcp://host:8786), got {type(address).__name__}")
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme not in ("tcp", "tls"):
        return
    try:
        host, port = parts.hostname, parts.port
    except ValueError as exc:
        raise ValueError(f"scheduler address {address!r}: {exc}") from None
    if not host or port is None:
        return
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except ConnectionRefusedError:
        raise ConnectionError(f"the Dask scheduler at {address} refused the connection: nothing listens on "
                              f"{host}:{port} (is the scheduler running? `dask scheduler` starts one)") from None
    except OSError:  # slow, unreachable or unresolvable: Dask's connect says why, after its timeout
        return


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
    workers = check_workers(workers)
    threads_per_worker = check_int(threads_per_worker, "threads_per_worker", lo=1)
    distributed = import_distributed()
    options.setdefault("dashboard_address", ":0")  # any free port: clusters side by side do not collide
    options.setdefault("silence_logs", logging.CRITICAL)  # the workers' own logs: the job re-raises their errors
    return distributed.LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker, processes=True,
                                    env=dict(env or {}), **options)


@contextmanager
def connect(scheduler: str | None = None, workers: int | None = None, *,
            env: dict[str, str] | None = None, probe_timeout: float = PROBE_TIMEOUT_S) -> Iterator[Any]:
    """A ``dask.distributed.Client``: of the cluster whose scheduler is at ``scheduler``
    (``tcp://host:8786``), or of a new local cluster of ``workers`` processes (closed on exit).
    ConnectionError at once when the scheduler's address refuses the connection (:func:`probe_scheduler`;
    ``probe_timeout``: seconds that probe waits for an answer)."""
    if (scheduler is None) == (workers is None):
        raise ValueError("give either a scheduler address or a number of local workers")
    distributed = import_distributed()
    if scheduler is not None:
        probe_scheduler(scheduler, probe_timeout)
        with distributed.Client(scheduler) as client:
            yield client
        return
    with local_cluster(workers, env=env) as cluster, distributed.Client(cluster) as client:
        yield client
