"""PyTorch bridge: a rendered image as a differentiable function of scene parameters held in torch
tensors (extra ``[torch]``), so that pyclpt can sit inside a PyTorch model or loss.

    import torch, pyclpt
    from pyclpt.gradients.torch_bridge import render_torch
    red = torch.tensor([0.3, 0.3, 0.3], requires_grad=True)
    image = render_torch(scene, {"red.reflectance.value": red}, spp=4, seed=0)   # (H, W, 3) tensor
    loss = ((image - target) ** 2).mean()
    loss.backward()                                                              # red.grad

The forward pass writes the tensors' values into the scene (``traverse(scene).update``) and renders
the image (the megakernel integrator, as ``pyclpt.render``); the backward pass is
:func:`pyclpt.render_backward` on ``seed_grad`` (by default ``seed + 1``: the same seed would bias the
gradient). Tensors on any torch device are accepted: values and gradients go through host memory.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from pyclpt.gradients.differentiate import render_backward, replay_for
from pyclpt.gradients.parameters import traverse
from pyclpt.scene.model import Scene

try:
    import torch
except ModuleNotFoundError:  # the extra is not installed: render_torch says so when called
    torch = None


def _require_torch():
    if torch is None:
        raise ImportError("the PyTorch bridge needs torch: pip install 'pyclpt[torch]'")
    return torch


if torch is not None:

    class RenderFunction(torch.autograd.Function):
        """image = render(scene, *values): forward renders, backward runs render_backward."""

        @staticmethod
        def forward(ctx, scene: Scene, options: dict, names: tuple, *values):
            params = traverse(scene)
            params.update({n: v.detach().cpu().numpy() for n, v in zip(names, values)})
            replay = replay_for(scene, width=options["width"], height=options["height"],
                                max_depth=options["max_depth"], device=options["device"])
            image = replay.primal(options["spp"], options["seed"])
            ctx.scene, ctx.options, ctx.names = scene, options, names
            ctx.targets = [(v.device, v.dtype) for v in values]
            return torch.from_numpy(image)

        @staticmethod
        def backward(ctx, grad_image):
            o = ctx.options
            grads = render_backward(ctx.scene, grad_image.detach().cpu().numpy().astype(np.float32), spp=o["spp"],
                                    seed=o["seed_grad"], loss_seed=o["seed"], max_depth=o["max_depth"],
                                    width=o["width"], height=o["height"], device=o["device"], params=list(ctx.names))
            out = [torch.from_numpy(grads[n]).to(device=d, dtype=t) for n, (d, t) in zip(ctx.names, ctx.targets)]
            return (None, None, None, *out)


def render_torch(scene: Scene, params: Mapping[str, object], *, spp: int, seed: int = 0, seed_grad: int | None = None,
                 max_depth: int | None = None, width: int | None = None, height: int | None = None,
                 device=None):
    """The image of ``scene`` (an (H, W, 3) float32 torch tensor) with the parameters ``params`` (names as
    :func:`pyclpt.traverse` gives them, values torch tensors), differentiable with respect to them."""
    th = _require_torch()
    names = tuple(params)
    values = tuple(params[n] for n in names)
    for n, v in zip(names, values):
        if not isinstance(v, th.Tensor):
            raise TypeError(f"render_torch: {n} must be a torch tensor, got {type(v).__name__}")
    options = {"spp": spp, "seed": seed, "seed_grad": seed + 1 if seed_grad is None else seed_grad,
               "max_depth": max_depth, "width": width, "height": height, "device": device}
    return RenderFunction.apply(scene, options, names, *values)
