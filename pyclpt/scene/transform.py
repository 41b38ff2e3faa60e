"""4x4 affine transforms in Mitsuba's conventions (column vectors, angles in degrees).

A chain ``[translate, rotate, scale]`` means ``T @ R @ S``: the last operation
is applied to points first, as in Mitsuba's ``T().translate(..).rotate(..).scale(..)``.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np


def translate(v) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = _vec3(v, "translate")
    return m


def scale(v) -> np.ndarray:
    s = np.asarray(v, dtype=np.float64).reshape(-1)
    if s.size == 1:
        s = np.repeat(s, 3)
    return np.diag([*_vec3(s, "scale"), 1.0])


def rotate(axis, angle: float) -> np.ndarray:
    a = _vec3(axis, "rotate axis")
    n = np.linalg.norm(a)
    if n == 0:
        raise ValueError("rotate: the axis is zero")
    x, y, z = a / n
    t = np.radians(float(angle))
    c, s = np.cos(t), np.sin(t)
    r = np.array([
        [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
        [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
        [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
    ])
    m = np.eye(4)
    m[:3, :3] = r
    return m


def pose(translate=(0.0, 0.0, 0.0), rotate=(0.0, 0.0, 0.0), scale=1.0) -> np.ndarray:
    """A pose, ``T @ R @ S`` (4x4): ``scale`` (a number or per axis) first, then ``rotate``, a rotation
    vector in degrees (its direction the axis, its length the angle: ``(0, 30, 0)`` is 30 degrees about
    +y), then ``translate``. What ``<shape>.to_world`` and ``<instance>.to_world`` take
    (:func:`pyclpt.traverse`)."""
    r = _vec3(rotate, "pose rotate")
    angle = float(np.linalg.norm(r))
    m = _translate(translate)
    if angle > 0:
        m = m @ _rotate(r / angle, angle)
    return m @ _scale(scale)


_translate, _rotate, _scale = translate, rotate, scale  # for pose(), whose parameters have their names


def look_at(origin, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Mitsuba's look_at: columns (left, up, direction, origin)."""
    o, t, u = _vec3(origin, "look_at origin"), _vec3(target, "look_at target"), _vec3(up, "look_at up")
    d = t - o
    if np.linalg.norm(d) == 0:
        raise ValueError("look_at: origin and target are the same point")
    d = d / np.linalg.norm(d)
    left = np.cross(u, d)
    if np.linalg.norm(left) < 1e-12:
        raise ValueError("look_at: the up vector is parallel to the viewing direction")
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
    return m


def matrix(values) -> np.ndarray:
    m = np.asarray(values, dtype=np.float64).reshape(-1)
    if m.size == 9:
        out = np.eye(4)
        out[:3, :3] = m.reshape(3, 3)
        return out
    if m.size != 16 or not np.all(np.isfinite(m)):
        raise ValueError(f"matrix: expected 16 (or 9) finite numbers, got {values!r}")
    return m.reshape(4, 4)


def from_spec(spec: object) -> np.ndarray:
    """A transform from a 4x4 array, or a list of operations such as
    ``[{"translate": [0, 1, 0]}, {"rotate": {"axis": [1, 0, 0], "angle": 90}}, {"scale": 0.5}]``."""
    if spec is None:
        return np.eye(4)
    if isinstance(spec, np.ndarray) or (isinstance(spec, Sequence) and spec and not isinstance(spec[0], Mapping)):
        return matrix(spec)
    if hasattr(spec, "matrix"):  # a mitsuba ScalarTransform4f
        return matrix(np.array(spec.matrix))
    ops = [spec] if isinstance(spec, Mapping) else list(spec)  # type: ignore[arg-type]
    m = np.eye(4)
    for op in ops:
        if not isinstance(op, Mapping) or len(op) != 1:
            raise ValueError(f"transform operation must be a one-key mapping, got {op!r}")
        (kind, arg), = op.items()
        if kind == "translate":
            m = m @ translate(arg)
        elif kind == "scale":
            m = m @ scale(arg)
        elif kind == "rotate":
            m = m @ rotate(arg["axis"], arg["angle"])
        elif kind in ("look_at", "lookat"):
            m = m @ look_at(arg["origin"], arg["target"], arg.get("up", (0, 1, 0)))
        elif kind == "matrix":
            m = m @ matrix(arg)
        else:
            raise ValueError(f"unknown transform operation {kind!r} (translate, rotate, scale, look_at, matrix)")
    return m


def apply_points(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return (p @ m[:3, :3].T + m[:3, 3]).astype(np.float32)


def apply_normals(m: np.ndarray, n: np.ndarray) -> np.ndarray:
    inv_t = np.linalg.inv(m[:3, :3]).T
    out = n @ inv_t.T
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return (out / np.where(length > 0, length, 1)).astype(np.float32)


def _vec3(v, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.size != 3 or not np.all(np.isfinite(a)):
        raise ValueError(f"{what}: expected 3 finite numbers, got {v!r}")
    return a
