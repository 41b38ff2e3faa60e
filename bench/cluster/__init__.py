"""Distributed rendering (pyclpt.distributed) on a local Dask cluster, docs/distributed.md: the speed-up of 2
workers and the fixed cost per task (:mod:`.speedup`), unequal workers (:mod:`.balance`), tiles
(:mod:`.tiles`)."""
