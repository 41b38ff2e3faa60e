"""Gradient-descent optimisers over named numpy parameters: :class:`Adam` (as Mitsuba 3's
``mi.ad.Adam``)::

    params = pyclpt.traverse(scene)
    opt = pyclpt.optim.Adam(lr=0.05)
    opt["red.reflectance.value"] = params["red.reflectance.value"]
    for it in range(50):
        image = pyclpt.render(scene, spp=4, seed=2 * it)
        image_grad = 2 * (image - target) / image.size                       # d mean((I - T)^2) / dI
        grads = pyclpt.render_backward(scene, image_grad, spp=4, seed=2 * it + 1, params=list(opt))
        opt.step(grads)
        opt["red.reflectance.value"] = np.clip(opt["red.reflectance.value"], 0.0, 1.0)
        params.update(opt)
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping, MutableMapping

import numpy as np

from pyclpt.common.checks import check_float


class Adam(MutableMapping[str, np.ndarray]):
    """Adam (Kingma and Ba 2015): per element, m = b1 m + (1 - b1) g, v = b2 v + (1 - b2) g^2,
    x -= lr sqrt(1 - b2^t) / (1 - b1^t) m / (sqrt(v) + epsilon). Holds its parameters by name
    (``opt[name] = value``: a new parameter, or a new shape, starts with zero moments; a value
    assigned with the same shape, a clamped one, say, keeps them); :meth:`step` takes gradients by name."""

    def __init__(self, lr: float = 1e-2, beta_1: float = 0.9, beta_2: float = 0.999, epsilon: float = 1e-8,
                 params: Mapping[str, np.ndarray] | None = None) -> None:
        self.lr = check_float(lr, "lr", lo=0.0)
        self.beta_1 = check_float(beta_1, "beta_1", lo=0.0, hi=1.0)
        self.beta_2 = check_float(beta_2, "beta_2", lo=0.0, hi=1.0)
        if not (self.beta_1 < 1.0 and self.beta_2 < 1.0):
            raise ValueError(f"beta_1 and beta_2 must be < 1, got {beta_1}, {beta_2}")
        self.epsilon = check_float(epsilon, "epsilon", lo=0.0)
        if self.epsilon == 0.0:  # a zero gradient would divide 0 by 0: NaN parameters
            raise ValueError(f"epsilon must be a finite number > 0, got {epsilon}")
        self._values: dict[str, np.ndarray] = {}
        self._state: dict[str, tuple[int, np.ndarray, np.ndarray]] = {}
        for k, v in (params or {}).items():
            self[k] = v

    def __getitem__(self, name: str) -> np.ndarray:
        return self._values[name]

    def __setitem__(self, name: str, value: object) -> None:
        arr = np.array(value, np.float32)
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"Adam: {name} holds NaN or infinite values")
        old = self._values.get(name)
        self._values[name] = arr
        if old is None or old.shape != arr.shape:
            self._state[name] = (0, np.zeros(arr.shape, np.float64), np.zeros(arr.shape, np.float64))

    def __delitem__(self, name: str) -> None:
        del self._values[name]
        del self._state[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def reset(self, name: str | None = None) -> None:
        """Forget the moments (of one parameter, or all)."""
        for k in [name] if name is not None else list(self._values):
            self._state[k] = (0, np.zeros(self._values[k].shape), np.zeros(self._values[k].shape))

    def step(self, grads: Mapping[str, np.ndarray]) -> None:
        """One step for every parameter that has a gradient in ``grads`` (others are left alone)."""
        for name, g in grads.items():
            if name not in self._values:
                continue
            g64 = np.asarray(g, np.float64)
            if g64.shape != self._values[name].shape:
                raise ValueError(f"Adam: gradient of {name} has shape {g64.shape}, the parameter "
                                 f"{self._values[name].shape}")
            if not np.all(np.isfinite(g64)):
                raise ValueError(f"Adam: the gradient of {name} holds NaN or infinite values")
            t, m, v = self._state[name]
            t += 1
            m = self.beta_1 * m + (1.0 - self.beta_1) * g64
            v = self.beta_2 * v + (1.0 - self.beta_2) * g64 * g64
            lr_t = self.lr * np.sqrt(1.0 - self.beta_2**t) / (1.0 - self.beta_1**t)
            with np.errstate(over="ignore", invalid="ignore"):
                new = self._values[name] - lr_t * m / (np.sqrt(v) + self.epsilon)
                stored = new.astype(np.float32)
            if not np.all(np.isfinite(stored)):  # nothing changed: the parameter and its moments stay
                bad = np.flatnonzero(~np.isfinite(stored))[0]
                raise ValueError(f"Adam: step {t} of {name} gives a value not finite in float32 "
                                 f"({float(new.reshape(-1)[bad])!r} at index {int(bad)}) with lr={self.lr}: "
                                 f"lower lr")
            self._values[name] = stored
            self._state[name] = (t, m, v)

    def __repr__(self) -> str:
        return f"Adam(lr={self.lr}, params={list(self._values)})"
