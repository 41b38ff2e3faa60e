"""GPU predictions without a GPU: the instruction sets and occupancy of pyclpt's kernels on GPU targets
(:mod:`pyclpt.gpu.isa`, :mod:`pyclpt.gpu.targets`) and a SIMT model of the streaming paper's claim, from
the paths an instrumented megakernel traces (:mod:`pyclpt.gpu.simt`; docs/gpu.md).

May import: :mod:`pyclpt.rendering` and the layers below it (never :mod:`pyclpt.distributed`, the
command line or ``bench``)."""
