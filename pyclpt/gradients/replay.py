"""Path replay on a device: the ``backward`` and ``forward`` kernels (``cl/gradients/``) for one scene,
resolution and depth.

:meth:`PathReplay.backward` runs reverse mode: every path of ``spp`` samples per pixel is traced twice
by one work-item (primal, then adjoint replay with the same random numbers), and the adjoints of the
parameters are added to gradient buffers laid out as the scene buffers (``cl/gradients/params.h``).
:meth:`PathReplay.forward` runs forward mode: the derivative of the image along a tangent in the
same layout, averaged by a film as an image is. Device memory: the scene, the gradient or tangent
buffers and one film batch; nothing grows with spp or depth (:attr:`PathReplay.device_bytes`).
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable
from typing import TypeVar

import numpy as np
import pyopencl as cl

from pyclpt.buffers.materials import MAT_STRIDE, pack_materials
from pyclpt.buffers.scene import SceneBuffers
from pyclpt.device.context import Device, alloc, fill_buffer, upload
from pyclpt.device.profile import KernelProfile
from pyclpt.device.program import build_program
from pyclpt.film.film import Film, frames_per_batch
from pyclpt.film.splat import SPLAT_FILTERS
from pyclpt.gradients.layout import BUFFERS, buffer_sizes
from pyclpt.gradients.parameters import KINDS
from pyclpt.integrators.megakernel import Megakernel
from pyclpt.scene.model import BumpMap, Mask, Scene, TwoSided

T = TypeVar("T")

LAUNCH = 1 << 18  # paths per launch (film slots)
LOCAL_SIZE = 64
BSDF_DIFF_STEP = 1.0 / 64.0  # cl/gradients/bsdf_derivative.h: the relative step of the roughness derivative
GRAD_DEFINES = {"color": "GRAD_COLOR", "spec": "GRAD_SPEC", "alpha": "GRAD_ALPHA", "emission": "GRAD_EMISSION",
                "env": "GRAD_ENV", "geometry": "GRAD_GEOMETRY", "camera": "GRAD_CAMERA",
                # with geometry: no mesh's vertices are moved apart (cl/gradients/geometry.h, geo_vertex_normals)
                "rigid": "GEO_NORMALS_FOLLOW_FACES",
                # an instance's to_world: the records' 12 floats of grad_inst (cl/gradients/geometry.h)
                "instance": "GRAD_INSTANCES"}


def moved_alpha_records(scene: Scene, step: float = BSDF_DIFF_STEP) -> tuple[np.ndarray, np.ndarray]:
    """The material records packed again with every roughness alpha moved to alpha (1 + step) and
    alpha (1 - step): what depends on alpha on the host (a rough plastic's coating tables) moves with
    it (cl/gradients/bsdf_derivative.h). Texture ids in them are not the scene's (unused)."""
    def moved(mat, factor: float):
        if isinstance(mat, (Mask, BumpMap)):
            return dataclasses.replace(mat, material=moved(mat.material, factor))
        if isinstance(mat, TwoSided):
            return dataclasses.replace(mat, front=moved(mat.front, factor), back=moved(mat.back, factor))
        alpha = getattr(mat, "alpha", 0.0)
        if not alpha > 0:
            return mat
        iso = getattr(mat, "alpha_v", None) == alpha  # an isotropic alpha_v moves along
        return dataclasses.replace(mat, alpha=alpha * factor, **({"alpha_v": alpha * factor} if iso else {}))

    # every record of the scene's (a TwoSided's back ones after the others), as pack_materials orders them
    up = pack_materials([moved(m, 1.0 + step) for m in scene.materials]).materials.reshape(-1, MAT_STRIDE)
    down = pack_materials([moved(m, 1.0 - step) for m in scene.materials]).materials.reshape(-1, MAT_STRIDE)
    return up, down


@dataclasses.dataclass
class DeltaSides:
    """The outputs of the delta_shadow_sides kernel (cl/gradients/delta_sides.h), per sample."""

    radiance: np.ndarray  # (N, 2, 3) f |cos| x the light's direct contribution either side of the outline
    receiver_prim: np.ndarray  # (N,) the leaf-order triangle of the outline's point (-1: no outline seen)
    receiver_hit: np.ndarray  # (N, 3) the light's ray's distance beyond the edge point, barycentrics there
    outline: np.ndarray  # (N, 5) the curve's measure per unit t, the distance to the outline's point, its normal


SIDE_OCCLUDER = -2  # SideSamples.first_prim of the side that meets the occluder at the edge (cl/gradients/incident.h)


@dataclasses.dataclass
class SideSamples:
    """The outputs of the vertex_radiance kernel (cl/gradients/incident.h), per sample."""

    radiance: np.ndarray  # (N, 2, 3) f |cos| L_i either side of the outline (minus, plus)
    # (N, 2) the leaf-order triangle each side's ray meets first (-1: none; SIDE_OCCLUDER: the occluder at the edge,
    # untraced)
    first_prim: np.ndarray
    first_hit: np.ndarray  # (N, 2, 3) its distance and barycentrics there
    pick: np.ndarray  # (N,) the edge picked, counted from the sample's first (-1: none)
    outline: np.ndarray  # (N, 5) the outline's measure per sample, the distance to the edge point, its normal n (3)

    def __iter__(self):
        return iter((self.radiance, self.first_prim, self.first_hit, self.pick, self.outline))


def _nothing() -> None:
    """Nothing to wait for."""


class PathReplay:
    """The gradient kernels of one scene on one device, at one resolution and depth limit."""

    def __init__(self, device: Device, scene: SceneBuffers, width: int, height: int, max_depth: int,
                 deferred_vertices: int | None = None) -> None:
        """``deferred_vertices``: vertices of a path whose BSDF term the primal pass keeps for the end of
        the path (-DDEFERRED_VERTICES, cl/gradients/backward.cl; None: the kernel's default, 8); the
        later ones are done by replaying the path, all of them with 0."""
        self.device, self.scene = device, scene
        self.deferred_vertices = deferred_vertices
        self.width, self.height = width, height
        self.max_depth = max_depth
        self.film = Film(device, width, height, precision="double",
                         batch=frames_per_batch(width * height, LAUNCH), rfilter=scene.scene.film.rfilter)
        self.profile = KernelProfile()  # the last pass's kernels (a backward or forward pass clears it)
        self.dropped = 0  # paths dropped by the last pass (NaN or inf radiance)
        self.boundary_dropped = 0  # the boundary kernels' samples dropped since the replay was made (the same)
        self._programs: dict[tuple[str, ...], cl.Kernel] = {}
        self._image_grad: cl.Buffer | None = None
        self._grads: dict[str, cl.Buffer] = {}
        self._queue = device.queue  # _batched's: the side queue while a backward pass runs (backward_started)
        self._side_queue: cl.CommandQueue | None = None
        self._scratch_buffers: dict[tuple[str, int], cl.Buffer] = {}  # _batched's, by (kernel, argument)
        self._alpha: tuple[bytes, cl.Buffer, cl.Buffer] | None = None
        self._primal: Megakernel | None = None
        self.compile_seconds = 0.0

    def kernel(self, name: str, kinds: Iterable[str] = ()) -> cl.Kernel:
        """Kernel ``backward`` or ``forward`` (specialised for the parameter kinds differentiated), or one of the
        boundary terms' (``edge_radiance``, ``path_vertices``, ``vertex_radiance``, ``delta_shadow_sides``)."""
        kinds = tuple(sorted(set(kinds)))
        key = (name, *kinds)
        if key not in self._programs:
            start = time.perf_counter()
            defines = {**self.scene.defines, **self.film.defines, **{GRAD_DEFINES[k]: 1 for k in kinds}}
            if self.deferred_vertices is not None:
                defines["DEFERRED_VERTICES"] = self.deferred_vertices
            if name == "backward" and self.film.splat is not None:  # the splat's adjoint (backward.cl)
                defines.update(FILM_SPLAT=1, SPLAT_FILTER=SPLAT_FILTERS[self.film.splat.rfilter.kind])
            program = build_program(self.device, [f"gradients/{name}.cl"], defines=defines)
            self._programs[key] = cl.Kernel(program, name)
            self.compile_seconds += time.perf_counter() - start
        return self._programs[key]

    @property
    def device_bytes(self) -> int:
        """Bytes of device memory this replay holds: scene, film batch, image gradient, gradient buffers, the
        boundary terms' kernels' arguments (at most LAUNCH items each, :meth:`_scratch`)."""
        film = self.film.pixels * (self.film.batch * (3 * 4 + 1) + 12) + self.film.accumulator.state_bytes
        grads = sum(b.size for b in self._grads.values())
        image = self._image_grad.size if self._image_grad is not None else 0
        scratch = sum(b.size for b in self._scratch_buffers.values())
        return self.scene.arrays.nbytes + film + grads + image + scratch

    def _alpha_records(self) -> tuple[cl.Buffer, cl.Buffer]:
        """alpha_up and alpha_down for the scene's current materials (packed again when they change)."""
        key = self.scene.arrays.materials.tobytes()
        if self._alpha is None or self._alpha[0] != key:
            up, down = moved_alpha_records(self.scene.scene)
            self._alpha = (key, upload(self.device, up, "materials, alpha moved up"),
                           upload(self.device, down, "materials, alpha moved down"))
        return self._alpha[1], self._alpha[2]

    def _buffers(self) -> dict[str, cl.Buffer]:
        """Zeroed gradient (or tangent) buffers in the scene's current layout."""
        q = self.device.queue
        for name, n in buffer_sizes(self.scene.arrays).items():
            buf = self._grads.get(name)
            if buf is None or buf.size != 4 * max(n, 1):
                buf = self._grads[name] = alloc(self.device, 4 * max(n, 1), f"gradient buffer {name}")
            fill_buffer(q, buf, np.float32(0), 0, buf.size)
        return self._grads

    def _launch(self, kernel: cl.Kernel, name: str, spp: int, seed: int, head: tuple, tail: tuple) -> None:
        """Launch ``kernel`` over samples [0, spp) of every pixel, a film batch of frames at a time."""
        args = self.scene.args(*self.film.view)
        self.dropped = 0
        s = 0
        while s < spp:
            frames = min(self.film.batch, spp - s)
            total = self.film.pixels * frames
            for offset in range(0, total, LAUNCH):
                count = min(LAUNCH, total - offset)
                g = -(-count // LOCAL_SIZE) * LOCAL_SIZE
                ev = kernel(self.device.queue, (g,), (LOCAL_SIZE,), *args, *head, np.uint32(seed), np.uint32(s),
                            np.int32(offset), np.int32(count), np.int32(self.max_depth), *tail)
                self.profile.record(name, ev)
            if name == "forward":
                self.film.add_frames(frames, seed, s)
            self.film.count_dropped(frames)
            s += frames

    def primal(self, spp: int, seed: int) -> np.ndarray:
        """The image (H, W, 3): the megakernel integrator on the same scene buffers, so exactly what
        ``pyclpt.render(scene, spp, seed=seed)`` gives at this resolution and depth."""
        if self._primal is None:
            self._primal = Megakernel(self.device, self.scene, self.film, self.max_depth)
        self.film.clear()
        s = 0
        while s < spp:
            frames = min(self.film.batch, spp - s)
            self._primal.render_frames(seed, s, frames)
            self.film.add_frames(frames, seed, s)
            s += frames
        self.dropped = self.film.dropped_samples()
        return self.film.image()

    def backward(self, image_grad: np.ndarray, spp: int, seed: int, kinds: Iterable[str],
                 moving: tuple[int, int] = (0, 2**31 - 1)) -> dict[str, np.ndarray]:
        """Reverse mode: the adjoints of every parameter of ``kinds`` (params.h) for dLoss/dImage
        ``image_grad`` (H, W, 3), as host copies of the gradient buffers by name (layout.py). ``moving``: the
        packed vertices [lo, hi) whose adjoints (``verts``, ``vnormals``) are wanted (the moving meshes': the
        kernel replays only the paths that meet their triangles and scatters no others', cl/gradients/geometry.h,
        geo_moving_prim); default: all."""
        return self.backward_started(image_grad, spp, seed, kinds, moving)()

    def backward_started(self, image_grad: np.ndarray, spp: int, seed: int, kinds: Iterable[str],
                         moving: tuple[int, int] = (0, 2**31 - 1)) -> Callable[[], dict[str, np.ndarray]]:
        """:meth:`backward`, its kernels enqueued and not waited for: returns the call that waits for them and
        gives the gradient buffers (call it exactly once). Until then the boundary terms' kernels (:meth:`_batched`)
        go to a second queue: on a device that runs two queues' commands at once (Intel's CPU runtime, GPUs) they
        and the host's share of the boundary terms run while the backward kernel does; PoCL runs one command at a
        time, in the order they came (the same as one queue). The scene's buffers are complete on the device
        before either starts."""
        kinds = [k for k in kinds if k in KINDS or k in ("rigid", "instance")]
        kernel = self.kernel("backward", kinds)
        self.profile.clear()  # this pass's kernels (and its boundary terms'), not every pass's since the first
        grads = self._buffers()
        if self.film.splat is not None:  # per pixel, over its mean sum of weights per frame (backward.cl)
            self.film.clear()
            norm = self.film.splat.mean_weights(self.film.frame, spp, seed)
            image_grad = np.asarray(image_grad, np.float64).reshape(self.height, self.width, 3)
            image_grad = np.divide(image_grad, norm[..., None], out=np.zeros_like(image_grad),
                                   where=norm[..., None] > 0)
        arr = np.ascontiguousarray(image_grad, np.float32).reshape(-1)
        if self._image_grad is None or self._image_grad.size != arr.nbytes:
            self._image_grad = upload(self.device, arr, "image gradient")
        else:
            cl.enqueue_copy(self.device.queue, self._image_grad, arr)
        self.film.clear()
        self.device.queue.finish()  # the scene's buffers complete: the second queue's kernels read them
        self._launch(kernel, "backward", spp, seed, (self._image_grad, self.film.drop_marks),
                     (np.float32(1.0 / spp), *(grads[b] for b in BUFFERS), *self._alpha_records(),
                      *(np.int32(min(max(v, 0), 2**31 - 1)) for v in moving)))

        def collect() -> dict[str, np.ndarray]:
            self.dropped = self.film.dropped_samples()
            out = {}
            for name in BUFFERS:
                host = np.empty(self._grads[name].size // 4, np.float32)
                cl.enqueue_copy(self.device.queue, host, self._grads[name])
                out[name] = host
            return out

        return self._beside(collect)

    def _beside(self, finish: Callable[[], T]) -> Callable[[], T]:
        """After a pass's kernels are enqueued: until the call returned is made (it gives ``finish()``),
        :meth:`_batched`'s kernels go to :attr:`side_queue`."""
        self.device.queue.flush()
        self._queue = self.side_queue

        def collect() -> T:
            self._queue = self.device.queue
            return finish()

        return collect

    def edge_radiance(self, points: np.ndarray, seed: int, eps: float) -> np.ndarray:
        """:meth:`edge_radiance_started`, waited for."""
        return self.edge_radiance_started(points, seed, eps)()

    def edge_radiance_started(self, points: np.ndarray, seed: int, eps: float) -> Callable[[], np.ndarray]:
        """The radiance (N, 2, 3) of the camera paths through film points ``points[:, :2]`` minus and plus
        ``eps`` times the unit film directions ``points[:, 2:]`` (the edge_radiance kernel; N, 4 float32),
        both with the random numbers of (seed, point), from the call returned (the kernel is enqueued, and that
        call waits for it). NaN or inf paths give 0 and are counted in :attr:`dropped`."""
        pts = np.ascontiguousarray(points, np.float32).reshape(-1, 4)
        out = np.zeros((len(pts), 2, 3), np.float32)
        marks = np.zeros((len(pts), 2), np.uint8)
        wait = self._batched("edge_radiance", len(pts), self.scene.args(self.width, self.height), [pts],
                             [out, marks],
                             lambda count: (np.uint32(seed), np.int32(count), np.int32(self.max_depth),
                                            np.float32(eps)), written=1)
        return self._collected(wait, out, marks)

    def vertex_radiance(self, prims: np.ndarray, samples: np.ndarray, depths: np.ndarray, moves: np.ndarray,
                        edges: np.ndarray, blocks: np.ndarray, spheres: np.ndarray, mesh_vertices: np.ndarray,
                        mesh_moving: np.ndarray, seed: int, eps: float) -> SideSamples:
        """:meth:`vertex_radiance_started`, waited for."""
        return self.vertex_radiance_started(prims, samples, depths, moves, edges, blocks, spheres, mesh_vertices,
                                            mesh_moving, seed, eps)()

    def vertex_radiance_started(self, prims: np.ndarray, samples: np.ndarray, depths: np.ndarray, moves: np.ndarray,
                                edges: np.ndarray, blocks: np.ndarray, spheres: np.ndarray,
                                mesh_vertices: np.ndarray, mesh_moving: np.ndarray, seed: int, eps: float
                                ) -> Callable[[], SideSamples]:
        """At vertices of camera paths (:meth:`path_vertices`: the camera rays' first hits, depth 0, and later
        vertices), the leaf-order triangles ``prims`` (N,), ``samples`` (N, 8) = barycentrics, the direction back
        along the path (at depth 0: the camera ray's film position x, y and 0), the uniforms of the edge's pick
        and of its point t, and the uniform of the pick's strategy, the vertices' bounces ``depths`` (N,) and
        whether each moves ``moves`` (N,): one edge that is a silhouette from the vertex x among the records of
        ``edges`` (E, EDGE_STRIDE: :meth:`pyclpt.gradients.shadows.MeshEdges.records`, the mesh's index last) in
        ``blocks`` (B, 3: first edge, count, 1 if the mesh moves) with bounding ``spheres`` (B, 4) (x's own mesh's
        included, but not the edges of x's triangle; a still x picks among the still meshes' edges near a moving
        mesh too: cl/gradients/edge_pick.h), picked in proportion to the angle it subtends, and f |cos| L_i
        either side of its point at t, both sides with the random numbers of (seed, sample) (the vertex_radiance
        kernel). ``mesh_vertices`` (M + 1,): the meshes' packed vertex ranges, ``mesh_moving`` (M,) whether each
        moves: the side that meets the edge's mesh at the edge's faces first gives 0 untraced (its ``first_prim``
        -2), and both do unless exactly one side meets it, or where nothing there moves (cl/gradients/incident.h).
        NaN or inf ones give 0 and are counted in :attr:`dropped`. The kernel is enqueued (:meth:`_batched`): the
        call returned waits for it and gives the samples."""
        n = len(prims)
        out = SideSamples(np.zeros((n, 2, 3), np.float32), np.full((n, 2), -1, np.int32),
                          np.zeros((n, 2, 3), np.float32), np.full(n, -1, np.int32), np.zeros((n, 5), np.float32))
        marks = np.zeros((n, 2), np.uint8)
        wait = _nothing
        if n and len(edges):
            tables = [upload(self.device, np.ascontiguousarray(a, dtype).reshape(-1), f"silhouette {what}")
                      for a, dtype, what in ((edges, np.float32, "edges"), (blocks, np.int32, "blocks"),
                                             (spheres, np.float32, "spheres"), (mesh_vertices, np.int32, "ranges"),
                                             (mesh_moving, np.int32, "motion"))]
            wait = self._batched("vertex_radiance", n, self.scene.args(self.width, self.height),
                          [np.ascontiguousarray(prims, np.int32).reshape(-1),
                           np.ascontiguousarray(samples, np.float32).reshape(-1, 8),
                           np.ascontiguousarray(depths, np.int32).reshape(-1),
                           np.ascontiguousarray(moves, np.int32).reshape(-1), *tables],
                          [out.radiance, out.first_prim, out.first_hit, marks, out.pick, out.outline],
                          lambda count: (np.uint32(seed), np.int32(count), np.int32(self.max_depth), np.float32(eps),
                                         np.int32(len(blocks)), np.int32(len(mesh_moving))),
                          written=3)
        return self._collected(wait, out, marks)

    def delta_shadow_sides(self, prims: np.ndarray, samples: np.ndarray, depths: np.ndarray, edge_ids: np.ndarray,
                           edges: np.ndarray, seed: int, eps: float) -> DeltaSides:
        """:meth:`delta_shadow_sides_started`, waited for."""
        return self.delta_shadow_sides_started(prims, samples, depths, edge_ids, edges, seed, eps)()

    def delta_shadow_sides_started(self, prims: np.ndarray, samples: np.ndarray, depths: np.ndarray,
                                   edge_ids: np.ndarray, edges: np.ndarray, seed: int, eps: float
                                   ) -> Callable[[], DeltaSides]:
        """At vertices of camera paths (as :meth:`vertex_radiance`'s: leaf-order triangles ``prims`` (N,), their
        bounces ``depths`` (N,), ``samples`` (N, 6) = barycentrics, the direction back along the path (at depth 0:
        the camera ray's film position x, y and 0) and the edge point's t), the outline that candidate edge
        ``edges[edge_ids]`` (E, DELTA_EDGE_STRIDE: its end points and the record of the point or spot light that
        sees it as a silhouette) casts, seen from there, and the vertex's BSDF and cosine times that light's
        direct contribution either side of it (the delta_shadow_sides kernel, cl/gradients/delta_sides.h). NaN or
        inf ones give 0 and are counted in :attr:`dropped`. The call returned waits for the kernel and gives them."""
        n = len(prims)
        out = DeltaSides(np.zeros((n, 2, 3), np.float32), np.full(n, -1, np.int32), np.zeros((n, 3), np.float32),
                         np.zeros((n, 5), np.float32))
        marks = np.zeros((n, 2), np.uint8)
        wait = _nothing
        if n and len(edges):
            e_buf = upload(self.device, np.ascontiguousarray(edges, np.float32).reshape(-1), "shadow edges")
            wait = self._batched("delta_shadow_sides", n, self.scene.args(self.width, self.height),
                          [np.ascontiguousarray(prims, np.int32).reshape(-1),
                           np.ascontiguousarray(samples, np.float32).reshape(-1, 6),
                           np.ascontiguousarray(depths, np.int32).reshape(-1),
                           np.ascontiguousarray(edge_ids, np.int32).reshape(-1), e_buf],
                          [out.radiance, out.receiver_prim, out.receiver_hit, marks, out.outline],
                          lambda count: (np.uint32(seed), np.int32(count), np.int32(self.max_depth), np.float32(eps)),
                          written=5)
        return self._collected(wait, out, marks)

    def path_vertices(self, film: np.ndarray, seed: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`path_vertices_started`, waited for."""
        return self.path_vertices_started(film, seed)()

    def path_vertices_started(self, film: np.ndarray, seed: int
                              ) -> Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """One later vertex of the camera path through each film position (N, 2) (the path_vertices kernel, random
        numbers of (seed, i)): its leaf-order triangle (N,) (-1: none), (N, 8) its barycentrics, the direction
        back along the path and its throughput over the probability of the choice, and its bounce (N,); and the
        camera ray's first hit: its leaf-order triangle (N,) (-1: none), (N, 3) its distance and barycentrics. The
        call returned waits for the kernel and gives them."""
        f = np.ascontiguousarray(film, np.float32).reshape(-1, 2)
        prims = np.full(len(f), -1, np.int32)
        vertex = np.zeros((len(f), 8), np.float32)
        depths = np.zeros(len(f), np.int32)
        first_prims = np.full(len(f), -1, np.int32)
        first_hits = np.zeros((len(f), 3), np.float32)
        wait = self._batched("path_vertices", len(f), self.scene.args(self.width, self.height), [f],
                             [prims, vertex, depths, first_prims, first_hits],
                             lambda count: (np.uint32(seed), np.int32(count), np.int32(self.max_depth)), written=5)
        return self._collected(wait, (prims, vertex, depths, first_prims, first_hits))

    def _collected(self, wait: Callable[[], None], out: T, marks: np.ndarray | None = None) -> Callable[[], T]:
        """The call that waits for a boundary kernel (``wait``, :meth:`_batched`'s) and gives its outputs ``out``;
        with ``marks`` (1 a NaN or inf sample, given 0) it counts them first: :attr:`dropped` of that call, added
        to :attr:`boundary_dropped`."""
        def collect() -> T:
            wait()
            if marks is not None:
                self.dropped = int(marks.astype(np.int64).sum())
                self.boundary_dropped += self.dropped
            return out

        return collect

    def _batched(self, name: str, n: int, head: tuple, inputs: list, outputs: list[np.ndarray],
                 tail: Callable[[int], tuple], written: int = 0) -> Callable[[], None]:
        """Launch kernel ``name`` over n items, LAUNCH a time, one work-item an item, with the arguments ``head``,
        then ``inputs`` (host arrays, first axis the item: that launch's items uploaded; a cl.Buffer: whole), then
        ``outputs`` (host arrays, first axis the item, zeroed on the device and filled from it; the first
        ``written`` ones are not zeroed: the kernel writes every item's), then ``tail(count)``. Everything is
        enqueued, nothing waited for: returns the call that waits until ``outputs`` are filled (call it before
        reading them). The kernel's buffers are :meth:`_scratch`'s, one per argument: on an in-order queue a
        launch's copies in run after the last one's copies out, so launches in flight together share them."""
        kernel = self.kernel(name)
        q = self._queue
        events: list[cl.Event] = []  # the copies' (a NannyEvent keeps its host array alive until it completes)
        for start in range(0, n, LAUNCH):
            count = min(LAUNCH, n - start)
            ins = [a if isinstance(a, cl.Buffer) else self._scratch_copy(name, k, a[start:start + count], events)
                   for k, a in enumerate(inputs)]
            outs = []
            for k, a in enumerate(outputs):
                nbytes = a[start:start + count].nbytes
                outs.append(self._scratch(name, len(inputs) + k, nbytes))
                if k >= written:
                    fill_buffer(q, outs[-1], np.uint8(0), 0, nbytes)
            g = -(-count // LOCAL_SIZE) * LOCAL_SIZE
            self.profile.record(name, kernel(q, (g,), (LOCAL_SIZE,), *head, *ins, *outs, *tail(count)))
            for a, b in zip(outputs, outs):
                events.append(cl.enqueue_copy(q, a[start:start + count], b, is_blocking=False))
        q.flush()

        def wait() -> None:
            if events:  # none where n is 0 (clWaitForEvents refuses an empty list)
                cl.wait_for_events(events)
            events.clear()

        return wait

    def _scratch(self, name: str, slot: int, nbytes: int) -> cl.Buffer:
        """Kernel ``name``'s device buffer for argument ``slot`` of :meth:`_batched`, at least ``nbytes``: kept
        and reused from pass to pass (a fresh buffer a launch cost the CPU device fresh pages each time: 0.09 s of
        ``vertex_radiance``'s 0.34 s a pass on a 2-core VM), grown when too small."""
        buf = self._scratch_buffers.get((name, slot))
        if buf is None or buf.size < nbytes:
            buf = self._scratch_buffers[(name, slot)] = alloc(self.device, max(nbytes, 4), f"{name} argument {slot}")
        return buf

    def _scratch_copy(self, name: str, slot: int, array: np.ndarray, events: list[cl.Event]) -> cl.Buffer:
        """:meth:`_scratch` with a copy of ``array`` enqueued into it (its event appended to ``events``)."""
        arr = np.ascontiguousarray(array)
        buf = self._scratch(name, slot, arr.nbytes)
        if arr.nbytes:
            events.append(cl.enqueue_copy(self._queue, buf, arr, is_blocking=False))
        return buf

    @property
    def side_queue(self) -> cl.CommandQueue:
        """A second in-order queue on the device: :meth:`_batched`'s while a backward pass runs
        (:meth:`backward_started`). PoCL's and Oclgrind's own queue: PoCL runs one command at a time whatever the
        queue, and Oclgrind's buffer fills are written from the host per queue (``fill_buffer``)."""
        if self.device.is_pocl or self.device.is_oclgrind:
            return self.device.queue
        if self._side_queue is None:
            self._side_queue = cl.CommandQueue(self.device.context, self.device.device,
                                               properties=cl.command_queue_properties.PROFILING_ENABLE)
        return self._side_queue

    def forward(self, tangent: dict[str, np.ndarray], spp: int, seed: int, kinds: Iterable[str] = ()) -> np.ndarray:
        """Forward mode: the derivative of the image (H, W, 3) along ``tangent`` (host arrays by buffer
        name, layout.py); ``kinds``: ``geometry`` when the tangent moves vertices or lights, ``camera`` when it moves
        the camera (-DGRAD_GEOMETRY, -DGRAD_CAMERA: the interior term of cl/gradients/geometry.h)."""
        return self.forward_started(tangent, spp, seed, kinds)()

    def forward_started(self, tangent: dict[str, np.ndarray], spp: int, seed: int, kinds: Iterable[str] = ()
                        ) -> Callable[[], np.ndarray]:
        """:meth:`forward`, started as :meth:`backward_started` starts a backward pass: the call returned gives
        the image."""
        kernel = self.kernel("forward", [k for k in kinds if k in ("geometry", "camera", "rigid", "instance")])
        self.profile.clear()
        bufs = self._buffers()
        for name in BUFFERS:
            data = np.ascontiguousarray(tangent[name], np.float32)
            if data.size:
                cl.enqueue_copy(self.device.queue, bufs[name], data)
        self.film.clear()
        self.device.queue.finish()  # the scene's buffers complete: the second queue's kernels read them
        self._launch(kernel, "forward", spp, seed, (self.film.frame, self.film.drop_marks),
                     (*(bufs[b] for b in BUFFERS), *self._alpha_records(), np.int32(0), np.int32(0)))

        def image() -> np.ndarray:
            self.dropped = self.film.dropped_samples()
            return self.film.image()

        return self._beside(image)
