"""Camera motion: a camera path of keyframes, interpolated frame by frame.

    path = CameraPath([Keyframe(0, cam_a), Keyframe(30, cam_b)], interpolation="catmull-rom")
    path.camera(12.5)                       # the Camera at frame 12.5
    orbit = CameraPath.orbit(scene, degrees=90, frames=16)   # around the look-at target

A pose is the camera-to-world matrix split into its origin and its rotation (a unit quaternion;
the matrix's column lengths, Mitsuba's handedness flips included, are kept from the first
keyframe). Between keyframes the origin moves linearly or along a centripetal-free uniform
Catmull-Rom spline through the neighbouring keyframes, the rotation by spherical linear
interpolation, the field of view linearly. Frame times are frame indices, as
:class:`~pyclpt.rendering.progressive.ProgressiveRenderer` uses them: frame k of a run is
``camera(k)``; before the first keyframe and after the last the path holds still.

An orbit turns the camera about its look-at target, around the camera's up axis, by ``degrees``
over ``frames`` frames (frame 0 at the start pose, frame ``frames - 1`` at the full angle), one
exact keyframe per frame. A Camera stores no target: given a scene, the target is the point of the
viewing axis nearest to the centre of the scene's bounding box.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pyclpt.common.checks import check_choice, check_float, check_int
from pyclpt.scene import transform as tf
from pyclpt.scene.model import Camera, Scene

INTERPOLATIONS = ("linear", "catmull-rom")


@dataclass(frozen=True)
class Keyframe:
    """The camera at frame ``time`` (a frame index; fractions allowed)."""

    time: float
    camera: Camera

    def __post_init__(self) -> None:
        t = check_float(self.time, "keyframe time")
        if not isinstance(self.camera, Camera):
            raise TypeError(f"keyframe at frame {t:g}: camera must be a pyclpt.Camera, "
                            f"got {type(self.camera).__name__}")
        object.__setattr__(self, "time", t)


def _quat_from_matrix(r: np.ndarray) -> np.ndarray:
    """A unit quaternion (w, x, y, z) of a proper rotation matrix (Shepperd's method)."""
    t = np.trace(r)
    if t > 0:
        s = np.sqrt(t + 1.0) * 2
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k]) * 2
        q = np.zeros(4)
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    q = np.asarray(q, np.float64)
    return q / np.linalg.norm(q)


def _matrix_from_quat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _slerp(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    d = float(np.dot(a, b))
    if d < 0:  # the shorter way round
        b, d = -b, -d
    if d > 0.9995:
        q = a + t * (b - a)
        return q / np.linalg.norm(q)
    theta = np.arccos(d)
    return (np.sin((1 - t) * theta) * a + np.sin(t * theta) * b) / np.sin(theta)


@dataclass(frozen=True)
class _Pose:
    origin: np.ndarray
    rotation: np.ndarray  # quaternion of the normalised, right-handed columns
    columns: np.ndarray  # the column scales, signed (a mirrored camera: Mitsuba's -x)
    fov: float
    fov_axis: str
    kind: str = "perspective"
    aperture_radius: float = 0.0
    focus_distance: float = 0.0

    @staticmethod
    def of(camera: Camera) -> _Pose:
        m = np.asarray(camera.to_world, np.float64)
        lengths = np.linalg.norm(m[:3, :3], axis=0)
        if np.any(lengths == 0):
            raise ValueError(f"camera to_world has a zero axis: {m.tolist()}")
        r = m[:3, :3] / lengths
        sign = np.sign(np.linalg.det(r))
        r = r * np.array([sign, 1, 1])  # a mirror becomes a flipped first column's scale
        return _Pose(m[:3, 3].copy(), _quat_from_matrix(r), lengths * np.array([sign, 1, 1]),
                     float(camera.fov), camera.fov_axis, camera.kind, camera.aperture_radius, camera.focus_distance)

    def camera(self) -> Camera:
        m = np.eye(4)
        m[:3, :3] = _matrix_from_quat(self.rotation) * self.columns
        m[:3, 3] = self.origin
        return Camera(m, self.fov, self.fov_axis, self.kind, self.aperture_radius, self.focus_distance)


class CameraPath:
    """Keyframes in time order and their interpolation; :meth:`camera` gives the pose at a frame."""

    def __init__(self, keyframes: Sequence[Keyframe], interpolation: str = "linear") -> None:
        keys = list(keyframes)
        if not keys:
            raise ValueError("a camera path needs at least one keyframe")
        for k in keys:
            if not isinstance(k, Keyframe):
                raise TypeError(f"camera path keyframes must be pyclpt.Keyframe, got {type(k).__name__}")
        times = [k.time for k in keys]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError(f"camera path keyframe times must increase, got {times}")
        axes = {k.camera.fov_axis for k in keys}
        if len(axes) > 1:
            raise ValueError(f"camera path keyframes mix fov axes {sorted(axes)}: give every camera the same")
        self.interpolation = check_choice(interpolation, "camera path interpolation", INTERPOLATIONS)
        self.keyframes = keys
        self._poses = [_Pose.of(k.camera) for k in keys]
        for (ka, a), (kb, b) in zip(zip(keys, self._poses), zip(keys[1:], self._poses[1:])):
            # The column scales are interpolated linearly: between a mirrored camera (det < 0) and an
            # unmirrored one a scale passes through 0, a degenerate camera (det 0) that smears the image.
            if np.any(np.sign(a.columns) != np.sign(b.columns)):
                def hand(p: _Pose) -> str:
                    return "mirrored (det < 0)" if np.prod(np.sign(p.columns)) < 0 else "unmirrored (det > 0)"
                raise ValueError(f"camera path keyframes at frames {ka.time:g} and {kb.time:g} differ in handedness: "
                                 f"{hand(a)} and {hand(b)}; the frames between them would pass through a "
                                 f"degenerate camera (det 0): give both keyframes the same handedness")

    def __len__(self) -> int:
        """Frames from the first keyframe to the last, both included (rounded up)."""
        return int(np.ceil(self.keyframes[-1].time - self.keyframes[0].time)) + 1

    @property
    def start(self) -> float:
        """The first keyframe's time."""
        return self.keyframes[0].time

    def camera(self, time: float) -> Camera:
        """The camera at frame ``time``."""
        t = check_float(time, "camera path time")
        keys, poses = self.keyframes, self._poses
        if t <= keys[0].time or len(keys) == 1:
            return poses[0].camera()
        if t >= keys[-1].time:
            return poses[-1].camera()
        i = int(np.searchsorted([k.time for k in keys], t, side="right")) - 1
        a, b = poses[i], poses[i + 1]
        u = (t - keys[i].time) / (keys[i + 1].time - keys[i].time)
        if self.interpolation == "catmull-rom":
            p0 = poses[max(i - 1, 0)].origin
            p3 = poses[min(i + 2, len(poses) - 1)].origin
            origin = 0.5 * ((2 * a.origin) + (-p0 + b.origin) * u + (2 * p0 - 5 * a.origin + 4 * b.origin - p3) * u * u
                            + (-p0 + 3 * a.origin - 3 * b.origin + p3) * u ** 3)
        else:
            origin = (1 - u) * a.origin + u * b.origin
        pose = _Pose(origin, _slerp(a.rotation, b.rotation, u), (1 - u) * a.columns + u * b.columns,
                     (1 - u) * a.fov + u * b.fov, a.fov_axis, a.kind,
                     (1 - u) * a.aperture_radius + u * b.aperture_radius,
                     (1 - u) * a.focus_distance + u * b.focus_distance)
        return pose.camera()

    @staticmethod
    def orbit(view: Camera | Scene, degrees: float, frames: int, target: Sequence[float] | None = None,
              up: Sequence[float] | None = None) -> CameraPath:
        """The camera of ``view`` (a Camera, or a Scene's camera) turned about ``target`` by ``degrees``
        over ``frames`` frames, around ``up`` (default: the camera's up axis). ``target`` defaults, for a
        Scene, to the point of the viewing axis nearest to the centre of the scene's bounds."""
        degrees = check_float(degrees, "orbit degrees")
        frames = check_int(frames, "orbit frames", lo=1)
        camera = view.camera if isinstance(view, Scene) else view
        if not isinstance(camera, Camera):
            raise TypeError(f"orbit needs a pyclpt.Camera or Scene, got {type(view).__name__}")
        if target is None:
            if not isinstance(view, Scene):
                raise ValueError("orbit: a Camera has no look-at target; give target=(x, y, z) or the Scene")
            target = orbit_target(view)
        centre = np.asarray(target, np.float64).reshape(-1)
        if centre.size != 3 or not np.all(np.isfinite(centre)):
            raise ValueError(f"orbit target must be 3 finite numbers, got {target!r}")
        m = np.asarray(camera.to_world, np.float64)
        axis = m[:3, 1] if up is None else np.asarray(up, np.float64)
        keys = []
        for k in range(frames):
            angle = degrees * k / (frames - 1) if frames > 1 else 0.0
            turn = tf.translate(centre) @ tf.rotate(axis, angle) @ tf.translate(-centre)
            keys.append(Keyframe(float(k), dataclasses.replace(camera, to_world=turn @ m)))
        return CameraPath(keys)


def orbit_target(scene: Scene) -> np.ndarray:
    """The point of the scene camera's viewing axis nearest to the centre of the scene's bounds."""
    lo = np.min([mesh.positions.min(0) for mesh in scene.meshes], axis=0).astype(np.float64)
    hi = np.max([mesh.positions.max(0) for mesh in scene.meshes], axis=0).astype(np.float64)
    m = np.asarray(scene.camera.to_world, np.float64)
    origin, forward = m[:3, 3], m[:3, 2] / np.linalg.norm(m[:3, 2])
    distance = max(float(np.dot((lo + hi) / 2 - origin, forward)), 1e-3 * float(np.linalg.norm(hi - lo)))
    return origin + distance * forward
