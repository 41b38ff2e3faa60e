"""Differentiable rendering: scene parameters by name (:func:`traverse`), reverse-mode gradients
(:func:`render_backward`) and forward-mode gradient images (:func:`render_forward`) by path replay,
an Adam optimiser (:mod:`pyclpt.gradients.optim`) and a PyTorch bridge
(:mod:`pyclpt.gradients.torch_bridge`). docs/differentiable.md explains the method.

Modules: ``parameters`` (names -> the scene model), ``layout`` (names -> device slots), ``replay``
(the kernels of cl/gradients/), ``differentiate`` (the API), ``optim``, ``torch_bridge``.

Beside the denoiser, under rendering: it may import integrators, buffers, film, accel, device, scene
and common (it launches its own kernels on the scene buffers and averages with the film).
"""
from __future__ import annotations

from pyclpt.gradients import optim
from pyclpt.gradients.differentiate import clear_cache, render_backward, render_forward
from pyclpt.gradients.parameters import SceneParameters, traverse

__all__ = ["clear_cache", "optim", "render_backward", "render_forward", "SceneParameters", "traverse"]
