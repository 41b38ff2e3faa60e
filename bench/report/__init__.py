"""The timing report generator, ``pyclpt bench`` (installed as ``pyclpt.bench.report``; in a checkout also
``python -m bench.report``):

- :mod:`.report`: the command (runs everything, writes the report folder), :mod:`.options` its option types;
- :mod:`.runner`: timing frames of a renderer (warm-up, repeats, median/min/max, device time from
  profiling events) and counting the rays they trace;
- :mod:`.embree_ceiling`: Embree's own ray throughput on the same scene, on the host;
- :mod:`.scenes`: which scenes a report covers, loaded or skipped with the reason;
- :mod:`.machine`: the machine, OpenCL device and software versions a report records;
- :mod:`.analysis`: figures derived from raw results (FPS, speed-ups, rays/s);
- :mod:`.plots`: the report's matplotlib figures;
- :mod:`.document`: a report as blocks, written as Markdown and self-contained HTML;
- :mod:`.versus`: ``pyclpt bench --versus mitsuba``, pyclpt against Mitsuba 3 on the same files, whose
  Mitsuba side ``mitsuba_driver.py`` runs in Mitsuba's own environment (never imported here).

Imports nothing on its own (Mitsuba's Python imports this package to reach ``mitsuba_driver``);
:func:`main` (and the option types of :mod:`.options`) load on first use.
"""
from __future__ import annotations

import importlib
from typing import Any

#: Names read from the package, loaded on first use: name -> (module, its name there).
_LAZY = {"main": ("report", "main")}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        module, attr = _LAZY[name]
        return getattr(importlib.import_module(f"{__name__}.{module}"), attr)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
