"""pyclpt's benchmarks; installed as the subpackage ``pyclpt.bench`` (``pyclpt bench`` runs
:mod:`.report`).

- :mod:`.runner`: timing frames of a renderer (warm-up, repeats, median/min/max, device time from
  profiling events) and counting the rays they trace;
- :mod:`.embree_ceiling`: Embree's own ray throughput on the same scene, on the host;
- :mod:`.scenes`: which scenes a report covers, loaded or skipped with the reason;
- :mod:`.machine`: the machine, OpenCL device and software versions a report records;
- :mod:`.analysis`: figures derived from raw results (FPS, speed-ups, rays/s);
- :mod:`.plots`: the report's matplotlib figures;
- :mod:`.document`: a report as blocks, written as Markdown and self-contained HTML;
- :mod:`.report`: the ``pyclpt bench`` command (runs everything, writes the report folder);
- :mod:`.versus`: ``pyclpt bench --versus mitsuba``, pyclpt against Mitsuba 3 on the same files,
  whose Mitsuba side ``mitsuba_driver.py`` runs in Mitsuba's own environment (never imported here);
- :mod:`.denoise_eval` (with :mod:`.denoise_metrics` and :mod:`.denoise_references`): the denoisers
  against 4096-spp references (relMSE, SSIM, FLIP, flicker, lag, cost at 1280x720; docs/denoising-eval.md);
  ``denoise_passes.py`` times and tunes the SVGF passes (docs/denoising-passes.md).

The scripts ``frame_time.py``, ``variants.py``, ``bvh_build.py`` and ``inline_math.py`` run from a checkout
(``python bench/frame_time.py``).

The top layer beside the CLI: may import every layer of pyclpt; nothing in pyclpt imports it.
"""
