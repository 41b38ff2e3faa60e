"""The viewer's camera: orbit, pan, zoom and fly moves applied to a :class:`~pyclpt.scene.model.Camera`,
the camera written back as a Mitsuba XML ``<lookat>`` sensor, and the keyframes recorded on the page
as a :class:`~pyclpt.scene.camera_path.CameraPath` in JSON (:func:`camera_path_to_json`,
:func:`camera_path_from_json`).

An :class:`OrbitCamera` holds the camera's matrix and a look-at target: the point of the scene camera's
viewing axis nearest to the centre of the scene's bounds (as ``CameraPath.orbit`` chooses it). Every move
multiplies the matrix on the left by a rigid motion, so the matrix's column lengths (Mitsuba's handedness
flips) stay as the scene had them. Orbiting turns about the target, around the scene camera's up axis
(yaw) and the camera's own horizontal axis (pitch, kept 2 degrees away from the poles).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from pyclpt.scene import transform as tf
from pyclpt.scene.camera_path import CameraPath, Keyframe, orbit_target
from pyclpt.scene.model import Camera, Scene

# Pitch is stopped this many degrees short of looking straight along the up axis.
POLE_MARGIN = 2.0


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-30)


def _finite(value: object, name: str) -> float:
    v = float(value)  # type: ignore[arg-type]
    if not np.isfinite(v):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return v


class OrbitCamera:
    """The camera of ``scene`` as the viewer moves it. :meth:`camera` is the current Camera."""

    def __init__(self, scene: Scene) -> None:
        self.base = scene.camera
        self.matrix = np.array(scene.camera.to_world, np.float64)
        self.target = np.asarray(orbit_target(scene), np.float64)
        lo = np.min([m.positions.min(0) for m in scene.meshes], axis=0).astype(np.float64)
        hi = np.max([m.positions.max(0) for m in scene.meshes], axis=0).astype(np.float64)
        self.scene_size = max(float(np.linalg.norm(hi - lo)), 1e-6)
        self.up = _unit(self.matrix[:3, 1])  # the yaw axis: the scene camera's up
        self.home = (self.matrix.copy(), self.target.copy())

    # -- the camera's frame ------------------------------------------------------------------------
    @property
    def origin(self) -> np.ndarray:
        return self.matrix[:3, 3].copy()

    @property
    def forward(self) -> np.ndarray:
        return _unit(self.matrix[:3, 2])

    @property
    def right(self) -> np.ndarray:
        return _unit(-self.matrix[:3, 0])  # as Camera.basis: the image's right is -column 0

    @property
    def camera_up(self) -> np.ndarray:
        return _unit(self.matrix[:3, 1])

    @property
    def distance(self) -> float:
        """From the camera to the target."""
        return float(np.linalg.norm(self.target - self.origin))

    def camera(self) -> Camera:
        """The current camera: the scene's, with the moved matrix."""
        return dataclasses.replace(self.base, to_world=self.matrix.copy())

    # -- moves -----------------------------------------------------------------------------------
    def _about_target(self, rotation: np.ndarray) -> None:
        self.matrix = tf.translate(self.target) @ rotation @ tf.translate(-self.target) @ self.matrix

    def orbit(self, yaw: float, pitch: float) -> None:
        """Turn about the target by ``yaw`` degrees around the up axis and ``pitch`` degrees around the
        camera's horizontal axis (positive: the camera moves right / up)."""
        yaw, pitch = _finite(yaw, "orbit yaw"), _finite(pitch, "orbit pitch")
        if yaw:
            self._about_target(tf.rotate(self.up, yaw))
        if pitch:
            # the angle between the viewing direction and the up axis stays within the margin of 0 and 180
            angle = float(np.degrees(np.arccos(np.clip(np.dot(self.forward, self.up), -1.0, 1.0))))
            pitch = float(np.clip(pitch, POLE_MARGIN - angle, 180.0 - POLE_MARGIN - angle))
            self._about_target(tf.rotate(self.right, -pitch))

    def pan(self, dx: float, dy: float) -> None:
        """Move the camera and its target sideways by ``dx``, ``dy`` (fractions of the image's width;
        positive: the scene follows the mouse right / down)."""
        dx, dy = _finite(dx, "pan dx"), _finite(dy, "pan dy")
        extent = 2.0 * self.distance * np.tan(np.radians(min(self.base.fov, 170.0)) / 2)
        shift = extent * (-dx * self.right + dy * self.camera_up)
        self.target = self.target + shift
        self.matrix = tf.translate(shift) @ self.matrix

    def zoom(self, factor: float) -> None:
        """Scale the distance to the target by ``factor`` (< 1: nearer), down to a thousandth of the scene."""
        factor = _finite(factor, "zoom factor")
        if factor <= 0:
            raise ValueError(f"zoom factor must be > 0, got {factor}")
        d = self.distance
        new = max(d * factor, 1e-3 * self.scene_size)
        self.matrix = tf.translate(self.forward * (d - new)) @ self.matrix

    def fly(self, forward: float, right: float, up: float) -> None:
        """Move the camera and its target by ``forward``, ``right``, ``up`` scene sizes (the diagonal
        of its bounds): along the viewing direction, the camera's right and the up axis."""
        f, r, u = _finite(forward, "fly forward"), _finite(right, "fly right"), _finite(up, "fly up")
        shift = self.scene_size * (f * self.forward + r * self.right + u * self.up)
        self.target = self.target + shift
        self.matrix = tf.translate(shift) @ self.matrix

    def look(self, camera: Camera) -> None:
        """Take ``camera``'s matrix (a camera path's frame); the target stays as far ahead as it was."""
        d = self.distance
        self.matrix = np.array(camera.to_world, np.float64)
        self.target = self.origin + d * self.forward

    def reset(self) -> None:
        """Back to the scene's camera."""
        self.matrix, self.target = self.home[0].copy(), self.home[1].copy()

    def lookat_xml(self) -> str:
        """The camera as a Mitsuba XML sensor (:func:`lookat_xml`), its target the orbit target's distance ahead."""
        return lookat_xml(self.camera(), self.distance)


def _num(v: float) -> str:
    return f"{float(v):.6g}"


def _vec(v: np.ndarray) -> str:
    return ", ".join(_num(x) for x in v)


def lookat_xml(camera: Camera, distance: float = 1.0) -> str:
    """``camera`` as a Mitsuba XML ``<sensor>``: fov, fov_axis and a ``to_world`` with ``<lookat>`` (origin,
    the target ``distance`` ahead, up), after a ``<scale>`` where the matrix's columns are scaled or flipped
    (Mitsuba's look_at gives columns left, up, forward). Paste it over a scene's sensor, keeping its film
    and sampler."""
    m = np.asarray(camera.to_world, np.float64)
    origin, forward, up = m[:3, 3], _unit(m[:3, 2]), _unit(m[:3, 1])
    target = origin + max(float(distance), 1e-6) * forward
    look = tf.look_at(origin, target, up)
    scale = np.linalg.solve(look[:3, :3], m[:3, :3])  # look @ scale == m where the columns are only scaled
    lines = [f'<sensor type="{camera.kind}">']
    if camera.kind != "orthographic":
        lines += [f'    <float name="fov" value="{_num(camera.fov)}"/>',
                  f'    <string name="fov_axis" value="{camera.fov_axis}"/>']
    if camera.kind == "thinlens":
        lines += [f'    <float name="aperture_radius" value="{_num(camera.aperture_radius)}"/>',
                  f'    <float name="focus_distance" value="{_num(camera.focus_distance)}"/>']
    lines.append('    <transform name="to_world">')
    diag = np.diag(scale)
    if not np.allclose(scale, np.diag(diag), atol=1e-6):
        lines.append(f'        <matrix value="{" ".join(_num(x) for x in m.reshape(-1))}"/>')
    else:
        if not np.allclose(diag, 1.0, atol=1e-6):
            lines.append(f'        <scale value="{_vec(diag)}"/>')
        lines.append(f'        <lookat origin="{_vec(origin)}" target="{_vec(target)}" up="{_vec(up)}"/>')
    lines += ["    </transform>", "</sensor>"]
    return "\n".join(lines) + "\n"


def camera_path_to_json(path: CameraPath) -> dict:
    """A camera path as JSON-ready data: its interpolation and, per keyframe, the time and the camera
    (kind, to_world, fov, fov_axis, aperture_radius, focus_distance)."""
    return {"interpolation": path.interpolation,
            "keyframes": [{"time": k.time, "kind": k.camera.kind,
                           "to_world": np.asarray(k.camera.to_world, np.float64).tolist(),
                           "fov": k.camera.fov, "fov_axis": k.camera.fov_axis,
                           "aperture_radius": k.camera.aperture_radius, "focus_distance": k.camera.focus_distance}
                          for k in path.keyframes]}


def camera_path_from_json(data: dict) -> CameraPath:
    """The :class:`~pyclpt.scene.camera_path.CameraPath` of :func:`camera_path_to_json`'s data (ValueError
    naming what is wrong), for ``ProgressiveRenderer(camera_path=...)`` or ``pyclpt.CameraPath`` use."""
    try:
        keys = [Keyframe(float(k["time"]), Camera(to_world=np.array(k["to_world"], np.float64), fov=k["fov"],
                                                 fov_axis=k["fov_axis"], kind=k.get("kind", "perspective"),
                                                 aperture_radius=k.get("aperture_radius", 0.0),
                                                 focus_distance=k.get("focus_distance", 0.0)))
                for k in data["keyframes"]]
        return CameraPath(keys, interpolation=data.get("interpolation", "linear"))
    except (KeyError, TypeError) as exc:
        raise ValueError(f"not a camera path (interpolation, keyframes of time, to_world, fov, fov_axis): "
                         f"{type(exc).__name__}: {exc}") from None
