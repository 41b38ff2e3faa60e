"""The derivatives of a smooth-shaded mesh's vertex normals, which the gradient kernels differentiate the shading by
(``vnormals``, cl/gradients/geometry.h), with respect to what moves them: the normals that
:meth:`pyclpt.traverse`'s ``update()`` writes (pyclpt/gradients/placement.py).

- ``vertex_positions``: the angle-weighted normals of the new positions (Thürmer and Wüthrich; Mitsuba's
  ``recompute_vertex_normals``): n_v = m_v / |m_v|, m_v = sum over the triangles at v of the corner's angle times
  the triangle's unit normal. :func:`angle_weighted_jvp` and :func:`angle_weighted_vjp` differentiate it in closed
  form (float64): the unit normals through their cross products, the angles through atan2 of the corner's two
  edges.
- ``to_world``: the normals at the pose's moment carried by the inverse transpose, n = A^T r / |A^T r|,
  A = M^-1 (3x3): :func:`transformed_jvp` and :func:`transformed_vjp`.

A degenerate triangle (zero area) contributes nothing to a vertex's normal, nor to its derivative; a vertex whose
normal is not defined (all its triangles degenerate) has none.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

# a triangle's corners k, the next and the previous (the corner's two edges)
_NEXT = (1, 2, 0)
_PREV = (2, 0, 1)


def _faces(p: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per triangle: the cross product c of its edges (T, 3), |c| (T,) and the unit normal (T, 3) (0 where
    degenerate)."""
    t = p[f]
    c = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    length = np.linalg.norm(c, axis=1)
    unit = np.divide(c, length[:, None], out=np.zeros_like(c), where=length[:, None] > 0)
    return c, length, unit


def _corner(p: np.ndarray, f: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Corner k of each triangle: its two edges e1 (to the next corner), e2 (to the previous), s = |e1 x e2| and
    d = e1 . e2 (the angle is atan2(s, d))."""
    e1 = p[f[:, _NEXT[k]]] - p[f[:, k]]
    e2 = p[f[:, _PREV[k]]] - p[f[:, k]]
    return e1, e2, np.linalg.norm(np.cross(e1, e2), axis=1), np.einsum("ij,ij->i", e1, e2)


def angle_weighted(positions: np.ndarray, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(m, n): the unnormalised angle-weighted sums (V, 3) and the unit normals (V, 3; 0 where m is), float64."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    f = np.asarray(indices, np.int64).reshape(-1, 3)
    _, length, unit = _faces(p, f)
    m = np.zeros_like(p)
    for k in range(3):
        _, _, s, d = _corner(p, f, k)
        np.add.at(m, f[:, k], np.where(length > 0, np.arctan2(s, d), 0.0)[:, None] * unit)
    norm = np.linalg.norm(m, axis=1, keepdims=True)
    return m, np.divide(m, norm, out=np.zeros_like(m), where=norm > 0)


def _unit_jvp(u: np.ndarray, du: np.ndarray) -> np.ndarray:
    """The tangent of u / |u| (rows) along du; 0 where u is 0."""
    norm = np.linalg.norm(u, axis=1, keepdims=True)
    n = np.divide(u, norm, out=np.zeros_like(u), where=norm > 0)
    dn = du - n * np.einsum("ij,ij->i", n, du)[:, None]
    return np.divide(dn, norm, out=np.zeros_like(dn), where=norm > 0)


# the adjoint of u / |u| is the same projection as its tangent (symmetric Jacobian)
_unit_vjp = _unit_jvp


def angle_weighted_jvp(positions: np.ndarray, indices: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """(V, 3): the tangent of :func:`angle_weighted`'s unit normals along the positions' tangent (V, 3)."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    dp = np.asarray(tangent, np.float64).reshape(p.shape)
    f = np.asarray(indices, np.int64).reshape(-1, 3)
    c, length, unit = _faces(p, f)
    dt = dp[f]
    dc = np.cross(dt[:, 1] - dt[:, 0], p[f[:, 2]] - p[f[:, 0]]) + np.cross(p[f[:, 1]] - p[f[:, 0]],
                                                                            dt[:, 2] - dt[:, 0])
    dunit = _unit_jvp(c, dc)
    m = np.zeros_like(p)
    dm = np.zeros_like(p)
    for k in range(3):
        e1, e2, s, d = _corner(p, f, k)
        de1 = dp[f[:, _NEXT[k]]] - dp[f[:, k]]
        de2 = dp[f[:, _PREV[k]]] - dp[f[:, k]]
        cross = np.cross(e1, e2)
        ds = np.divide(np.einsum("ij,ij->i", cross, np.cross(de1, e2) + np.cross(e1, de2)), s,
                       out=np.zeros_like(s), where=s > 0)
        dd = np.einsum("ij,ij->i", de1, e2) + np.einsum("ij,ij->i", e1, de2)
        r2 = s * s + d * d
        dtheta = np.divide(d * ds - s * dd, r2, out=np.zeros_like(r2), where=r2 > 0)
        ok = length > 0
        theta = np.where(ok, np.arctan2(s, d), 0.0)
        np.add.at(m, f[:, k], theta[:, None] * unit)
        np.add.at(dm, f[:, k], np.where(ok, dtheta, 0.0)[:, None] * unit + theta[:, None] * dunit)
    return _unit_jvp(m, dm)


def angle_weighted_vjp(positions: np.ndarray, indices: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """(V, 3): the gradient with respect to the positions of a loss whose gradient with respect to
    :func:`angle_weighted`'s unit normals is ``gradient`` (V, 3); the adjoint of :func:`angle_weighted_jvp`."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    f = np.asarray(indices, np.int64).reshape(-1, 3)
    m, _ = angle_weighted(p, f)
    gm = _unit_vjp(m, np.asarray(gradient, np.float64).reshape(p.shape))
    c, length, unit = _faces(p, f)
    ok = length > 0
    gunit = np.zeros_like(c)
    gp = np.zeros_like(p)
    for k in range(3):
        e1, e2, s, d = _corner(p, f, k)
        g_corner = gm[f[:, k]]
        theta = np.where(ok, np.arctan2(s, d), 0.0)
        gunit += theta[:, None] * g_corner
        gtheta = np.where(ok, np.einsum("ij,ij->i", g_corner, unit), 0.0)
        # theta = atan2(s, d): dtheta = (d ds - s dd) / (s^2 + d^2), ds = u . (de1 x e2 + e1 x de2), dd = ...
        r2 = s * s + d * d
        a = np.divide(d * gtheta, r2, out=np.zeros_like(r2), where=r2 > 0)  # the adjoint of s
        b = np.divide(-s * gtheta, r2, out=np.zeros_like(r2), where=r2 > 0)  # the adjoint of d
        u = np.divide(np.cross(e1, e2), s[:, None], out=np.zeros_like(e1), where=s[:, None] > 0)
        ge1 = a[:, None] * np.cross(e2, u) + b[:, None] * e2
        ge2 = a[:, None] * np.cross(u, e1) + b[:, None] * e1
        np.add.at(gp, f[:, _NEXT[k]], ge1)
        np.add.at(gp, f[:, _PREV[k]], ge2)
        np.add.at(gp, f[:, k], -(ge1 + ge2))
    gc = _unit_vjp(c, gunit)
    a1 = p[f[:, 1]] - p[f[:, 0]]
    a2 = p[f[:, 2]] - p[f[:, 0]]
    ga1 = np.cross(a2, gc)  # c = a1 x a2: the adjoint of a1 is a2 x gc, of a2 is gc x a1
    ga2 = np.cross(gc, a1)
    np.add.at(gp, f[:, 1], ga1)
    np.add.at(gp, f[:, 2], ga2)
    np.add.at(gp, f[:, 0], -(ga1 + ga2))
    return gp


def transformed_jvp(matrix: np.ndarray, rest: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """(V, 3): the tangent of n = A^T r / |A^T r| (A = M^-1, the 3x3 of ``matrix``; r: the rows of ``rest``) along
    a tangent (4, 4) of M."""
    a = np.linalg.inv(np.asarray(matrix, np.float64).reshape(4, 4)[:3, :3])
    dm = np.asarray(tangent, np.float64).reshape(4, 4)[:3, :3]
    r = np.asarray(rest, np.float64).reshape(-1, 3)
    da = -a @ dm @ a
    return _unit_jvp(r @ a, r @ da)


def transformed_vjp(matrix: np.ndarray, rest: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """(4, 4): the gradient with respect to M of a loss whose gradient with respect to the normals of
    :func:`transformed_jvp` is ``gradient`` (V, 3); its translation column is 0."""
    a = np.linalg.inv(np.asarray(matrix, np.float64).reshape(4, 4)[:3, :3])
    r = np.asarray(rest, np.float64).reshape(-1, 3)
    gu = _unit_vjp(r @ a, np.asarray(gradient, np.float64).reshape(r.shape))
    ga = r.T @ gu  # u = r A (rows): the adjoint of A
    out = np.zeros((4, 4))
    out[:3, :3] = -a.T @ ga @ a.T  # A = M^-1: dA = -A dM A
    return out


def pose_rest(matrix: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """The normals at a pose's moment (the rows r with normals = A^T r / |A^T r|, up to length) from the normals
    now and the pose now: r = n M (3x3)."""
    return np.asarray(normals, np.float64).reshape(-1, 3) @ np.asarray(matrix, np.float64).reshape(4, 4)[:3, :3]


def normals_backward(kind: str, positions: np.ndarray, indices: np.ndarray, normals: np.ndarray,
                     matrix: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """The gradient (float64) of a mesh's ``vertex_positions`` (V, 3) or ``to_world`` (4, 4; pose ``matrix``), by
    ``kind``, from its vertex normals' (V, 3), through the normals ``update()`` writes."""
    if kind == "vertex_positions":
        return angle_weighted_vjp(positions, indices, gradient)
    return transformed_vjp(matrix, pose_rest(matrix, normals), gradient)


def normals_forward(kind: str, positions: np.ndarray, indices: np.ndarray, normals: np.ndarray,
                    matrix: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """(V, 3) float64: the tangent of a mesh's vertex normals along a tangent of its ``vertex_positions`` (V, 3) or
    ``to_world`` (4, 4; pose ``matrix``), by ``kind``: :func:`normals_backward`'s forward mode."""
    if kind == "vertex_positions":
        return angle_weighted_jvp(positions, indices, tangent)
    return transformed_jvp(matrix, pose_rest(matrix, normals), tangent)


def normals_chain(name: str, positions: np.ndarray, indices: np.ndarray, normals: np.ndarray, value: np.ndarray,
                  matrix: np.ndarray, chain: Callable[..., np.ndarray]) -> np.ndarray:
    """``chain`` (:func:`normals_backward` or :func:`normals_forward`) for a mesh's parameter ``name`` (its
    ``vertex_positions`` or ``to_world``, whose value ``matrix`` is), with ``value`` its vertex normals' gradient
    or the parameter's tangent: through the normals ``update()`` writes."""
    kind = name.rpartition(".")[2]
    pose = np.asarray(matrix, np.float64) if kind == "to_world" else np.eye(4)
    return chain(kind, positions, indices, normals, pose, np.asarray(value, np.float64))

