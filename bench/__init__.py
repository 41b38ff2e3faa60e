"""pyclpt's benchmarks, one folder per kind of question; installed as ``pyclpt.bench`` with only the
report generator (``pyclpt bench``). Run from a checkout's root as ``python -m bench.<folder>.<name>``.

- :mod:`.report`: the timing report generator, ``pyclpt bench`` (and ``--versus mitsuba``), the one
  package installed (``pyclpt.bench.report``); the other folders import its runner and machine records;
- ``peers/``: pyclpt against Mitsuba 3 scene by scene, and Mitsuba's sides of the evaluations (run by the
  Python of Mitsuba's own environment, never imported by pyclpt);
- ``evaluations/``: how good a feature is against exact answers, references or Mitsuba: gradients, the
  boundary terms, inverse rendering, pixel filters, the denoisers (``denoise_*.py``);
- ``cluster/``: distributed rendering on a local Dask cluster: speed-up, unequal workers, tiles;
- ``timing/``: measurements to re-run on a new machine or after a change: frame times, devices, scene
  loads, BVH builds, per-stage throughput, the viewer's overhead;
- ``gpu/``: where a GPU's frame time goes, and the SIMT model of the streaming paper's claim;
- ``studies/``: one-off studies that answered their question, kept runnable; each module's first lines
  state the question, the answer and its figure, and the doc that quotes them;
- ``tools/``: scripts that write files the repository ships (the sky tables, docs/gallery).

The top layer beside the CLI: may import every layer of pyclpt; nothing in pyclpt imports it, and the
report imports none of the other folders.
"""
from __future__ import annotations
