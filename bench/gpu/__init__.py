"""GPUs (docs/gpu.md): where a GPU's frame time goes (:mod:`.diagnostics`, on a GPU machine) and a SIMT model of
the streaming paper's claim from the paths pyclpt traces (:mod:`.simt_model`, on any device)."""
