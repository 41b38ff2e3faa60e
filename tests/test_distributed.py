"""pyclpt.distributed on a LocalCluster of 2 worker processes (one cluster for the module): the merged
image equals the local render; a killed worker loses nothing; a scene a worker cannot open fails the
job with the worker and the file named; a sequence is one task per frame; the CLI's --workers and
--scheduler. Tiny images and few samples: the cluster's start is most of the time."""
from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

import numpy as np
import pytest

import pyclpt
from pyclpt.cli import main
from pyclpt.distributed import DistributedRenderer, PartialSum, WorkerError, local_cluster, merge, split_samples
from pyclpt.distributed.merge import merge_tiles
from pyclpt.distributed.tasks import tile_size
from pyclpt.film.crop import Crop
from pyclpt.rendering.renderer import Renderer
from pyclpt.scene.camera_path import CameraPath

distributed = pytest.importorskip("distributed")
dask = pytest.importorskip("dask")  # distributed's own dependency: its config

W, H = 16, 12
# The documented bound (docs/distributed.md): the merged mean against one machine's double sum.
MAX_RELATIVE = 1e-12
# seconds: a bug fails the test instead of hanging CI. A hang guard, not a timing: a cluster's first render compiles
# its kernels in the worker, which under the suite's two pytest-xdist workers on two cores took over a minute
JOB_TIMEOUT = 300
RELEASE_BOUND = 600  # seconds: a hang guard for the release of cancelled tasks, never a timing assertion


@pytest.fixture(scope="module")
def client():
    # one core a worker (PoCL), so that two workers and the test process share the machine evenly
    with local_cluster(2, env={"POCL_MAX_PTHREAD_COUNT": "1"}) as cluster, distributed.Client(cluster) as c:
        c.wait_for_workers(2, timeout=JOB_TIMEOUT)
        yield c


SMALL_SCENE = f"""<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="39"/>
        <transform name="to_world"><lookat origin="0, 1, 3.9" target="0, 1, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{W}"/><integer name="height" value="{H}"/>
            <rfilter type="box"/></film>
    </sensor>
    <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="2"/></transform>
        <bsdf type="diffuse"><texture type="checkerboard" name="reflectance"/></bsdf></shape>
    <shape type="sphere"><point name="center" x="0" y="0.6" z="0"/><float name="radius" value="0.6"/>
        <bsdf type="roughconductor"/></shape>
    <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/><translate y="2.5"/></transform>
        <emitter type="area"><rgb name="radiance" value="6"/></emitter></shape>
</scene>"""


def _render_tasks(dask_scheduler) -> list[str]:
    """The pyclpt tasks the scheduler may still run: waiting, queued or processing on a worker (run on the
    scheduler). Finished ones (in memory, erred) stay while the client holds their futures."""
    return sorted(str(k) for k, ts in dask_scheduler.tasks.items()
                  if str(k).startswith("pyclpt-") and ts.state not in ("memory", "erred", "forgotten"))


def _wait_released(client) -> None:
    """Wait for the event (the scheduler has released every pyclpt task: none queued, none processing on a
    worker), not for a clock: a loaded machine only makes it later. RELEASE_BOUND only stops a hang."""
    deadline = time.monotonic() + RELEASE_BOUND
    while (held := client.run_on_scheduler(_render_tasks)) or any(
            str(k).startswith("pyclpt-") for keys in client.processing().values() for k in keys):
        assert time.monotonic() < deadline, \
            f"{len(held)} tasks still to run {RELEASE_BOUND} s after the job ended: {held[:4]}"
        time.sleep(0.05)


def _ran(stream) -> int:
    """How many pyclpt tasks a worker executed, from a ``get_task_stream`` record."""
    return sum(1 for task in stream.data if str(task["key"]).startswith("pyclpt-"))


def _local(scene, spp, seed, **kw):
    """One machine's render: the float32 image and the double mean (sum / spp as the film keeps it)."""
    r = Renderer(scene, width=W, height=H, **kw)
    image = r.render(spp, seed)
    return image, r.film.accumulator.image(np.float64)


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), np.finfo(np.float64).tiny)))


def test_split_and_merge_order():
    assert split_samples(10, 4) == [(0, 4), (4, 4), (8, 2)]
    assert split_samples(3, 8, first_sample=5) == [(5, 3)]
    parts = [PartialSum(s, n, np.full((1, 1, 3), float(s))) for s, n in split_samples(10, 4)]
    total, _ = merge(reversed(parts), 10)  # finished in any order, added in sample order
    assert total[0, 0, 0] == 0 + 4 + 8
    with pytest.raises(ValueError, match="gap"):
        merge(parts[::2], 10)


def test_equals_local_render(client):
    scene = pyclpt.load("cornell-box")
    ref32, ref = _local(scene, 24, seed=7, max_depth=4)
    dr = DistributedRenderer(client, "cornell-box", width=W, height=H, max_depth=4)
    total = dr.render_sum(24, seed=7, task_spp=5, timeout=JOB_TIMEOUT)  # 5 tasks: 5+5+5+5+4 samples
    assert len(dr.parts) == 5
    assert _relative(total / 24, ref) <= MAX_RELATIVE
    image = dr.render(24, seed=7, task_spp=5, timeout=JOB_TIMEOUT)
    assert image.dtype == np.float32 and image.shape == (H, W, 3)
    np.testing.assert_allclose(image, ref32, rtol=1e-6)
    # a Scene object (shipped to the workers once), through pyclpt.render(client=...)
    shipped = pyclpt.render(scene, spp=24, seed=7, width=W, height=H, max_depth=4, client=client, task_spp=3)
    np.testing.assert_array_equal(shipped, image)
    # a different seed is a different image (the seed reaches the workers)
    assert not np.array_equal(dr.render(24, seed=8, task_spp=5, timeout=JOB_TIMEOUT), image)


def test_tiles_equal_local_render(client, tmp_path):
    """Tiles (x sample ranges) put together are the local render: bit for bit when every tile is one
    task, within the documented bound when its samples are split too. The image size of a scene file
    comes from a worker."""
    scene_file = tmp_path / "small.xml"
    scene_file.write_text(SMALL_SCENE)
    scene = pyclpt.load(str(scene_file))
    assert (scene.film.width, scene.film.height) == (W, H)
    r = Renderer(scene, max_depth=4)
    ref = r.render_sum(12, seed=4)
    dr = DistributedRenderer(client, str(scene_file), max_depth=4)
    assert dr.image_size() == (W, H)
    total = dr.render_sum(12, seed=4, tile=(7, 5), task_spp=12, timeout=JOB_TIMEOUT)
    assert len(dr.parts) == 3 * 3 and {p.crop.width for p in dr.parts} == {7, 2}
    np.testing.assert_array_equal(total, ref)
    total = dr.render_sum(12, seed=4, tile=6, task_spp=5, timeout=JOB_TIMEOUT)
    assert len(dr.parts) == 3 * 2 * 3
    assert _relative(total, ref) <= MAX_RELATIVE
    assert dr.dropped_samples == 0
    # "auto" leaves a small image whole
    dr.render_sum(2, seed=4, timeout=JOB_TIMEOUT)
    assert all(p.crop is None for p in dr.parts)


def test_tile_sizes_and_cover():
    assert tile_size("auto", 1920, 1080) is None  # 2.07 Mpixels: whole
    assert tile_size("auto", 3840, 2160) == (512, 512)
    assert tile_size(64, 10, 10) == (64, 64) and tile_size((32, 8), 10, 10) == (32, 8) and tile_size(None, 9, 9) is None
    with pytest.raises(ValueError, match="tile height must be an integer >= 1"):
        tile_size((4, 0), 10, 10)
    with pytest.raises(ValueError, match="tile must be a size"):
        tile_size((4, 4, 4), 10, 10)
    one = np.ones((2, 2, 3))
    with pytest.raises(ValueError, match=r"cover pixel \(2, 0\) of the 4x2 image 0 times"):
        merge_tiles([PartialSum(0, 1, one, crop=Crop(0, 0, 2, 2))], 1, 4, 2)


def test_killed_worker_loses_nothing(client):
    """Kill a worker process while its task runs: Dask reruns the task, the image is unchanged."""
    spp, task_spp = 96, 2  # 48 tasks of a few tens of ms each
    scene = pyclpt.load("cornell-box")
    _, ref = _local(scene, spp, seed=1, max_depth=6)
    dr = DistributedRenderer(client, "cornell-box", width=W, height=H, max_depth=6)
    dr.render(2, seed=1, task_spp=1, timeout=JOB_TIMEOUT)  # both workers have loaded the scene
    pids = client.run(os.getpid)
    result: dict = {}

    def job():
        try:
            result["total"] = dr.render_sum(spp, seed=1, task_spp=task_spp, timeout=JOB_TIMEOUT)
        except BaseException as exc:  # noqa: BLE001 - handed to the test thread
            result["error"] = exc

    thread = threading.Thread(target=job)
    thread.start()
    victim, deadline = None, time.monotonic() + JOB_TIMEOUT
    while victim is None and time.monotonic() < deadline:  # a worker busy with one of the render's tasks
        busy = [w for w, keys in client.processing().items() if any(str(k).startswith("pyclpt-") for k in keys)]
        victim = next((w for w in busy if w in pids), None)
        time.sleep(0.005)
    assert victim is not None, "no task started"
    os.kill(pids[victim], signal.SIGKILL)
    thread.join(JOB_TIMEOUT)
    assert not thread.is_alive(), "the render hung after a worker was killed"
    assert "error" not in result, result.get("error")
    assert _relative(result["total"] / spp, ref) <= MAX_RELATIVE
    client.wait_for_workers(2, timeout=JOB_TIMEOUT)  # the nanny restarted it
    assert pids[victim] not in client.run(os.getpid).values()


def test_missing_scene_file_names_worker_and_file(client, tmp_path):
    missing = tmp_path / "gone.xml"
    dr = DistributedRenderer(client, str(missing), width=W, height=H)
    with distributed.get_task_stream(client) as stream:
        with pytest.raises(WorkerError, match=rf"worker tcp://[\d.:]+: cannot open scene {missing}"):
            dr.render(8, task_spp=1, timeout=JOB_TIMEOUT)  # the first failure ends the job, not the timeout
        _wait_released(client)
    # the job's other tasks are cancelled, not left to run: each worker fails one and the rest never start
    assert _ran(stream) < 8


def test_worker_without_device_names_worker_and_scene():
    """A worker whose PYCLPT_DEVICE names no device fails the job with a clear error, not a hang."""
    with local_cluster(1, env={"PYCLPT_DEVICE": "no-such-gpu"}) as cluster, distributed.Client(cluster) as c:
        dr = DistributedRenderer(c, "cornell-box", width=W, height=H)
        with pytest.raises(WorkerError, match=r"worker tcp://[\d.:]+: no usable OpenCL device for scene "
                                              r"cornell-box: .*no-such-gpu"):
            dr.render(2, timeout=JOB_TIMEOUT)


def test_timeout_cancels_the_tasks(client):
    dr = DistributedRenderer(client, "cornell-box", width=W, height=H)
    with distributed.get_task_stream(client) as stream:
        with pytest.raises(TimeoutError, match=r"not finished within timeout=0.5 s: \d+ of 4096 tasks left"):
            dr.render(4096, task_spp=1, timeout=0.5)
        _wait_released(client)
    # Cancelled, not run to the end: uncancelled, the 4096 tasks would all have run before their release.
    assert _ran(stream) < 4096


def test_sequence_one_task_per_frame(client):
    scene = pyclpt.load("cornell-box")
    path = CameraPath.orbit(scene, 40, 4)
    cameras = [path.camera(k) for k in range(4)]
    dr = DistributedRenderer(client, scene, width=W, height=H, max_depth=3)
    frames = dr.render_frames(cameras, spp=2, seed=5, timeout=JOB_TIMEOUT)
    assert len(dr.parts) == 4 and [p.frame for p in dr.parts] == [0, 1, 2, 3]
    for k, camera in enumerate(cameras):
        scene.camera = camera
        _, ref = _local(scene, 2, seed=5, max_depth=3)
        assert _relative(frames[k].astype(np.float64), ref) <= 1e-7  # float32 image against the double mean
    assert not np.array_equal(frames[0], frames[3])


def test_progressive_sequence_equals_local(client):
    scene = pyclpt.load("cornell-box")
    pr = pyclpt.ProgressiveRenderer(scene, width=W, height=H, max_depth=3, seed=2)
    local = []
    for _ in range(5):
        pr.step()
        local.append(pr.image())
    dr = DistributedRenderer(client, "cornell-box", width=W, height=H, max_depth=3)
    frames = dr.render_progressive(5, seed=2, task_spp=2, timeout=JOB_TIMEOUT)
    for a, b in zip(frames, local):
        np.testing.assert_array_equal(a, b)  # the same adds in the same order


def test_splatting_film_split_render_equals_local(client):
    """A splatting film (gaussian, estimator="splat"): its image is a ratio of two sums, which the tasks
    return apart and the merge pools, so the split render is the local one within the documented bound
    (tiles too, each with its margin), and the running averages of a sequence and a denoised sequence
    (each frame's own samples and G-buffer) bit for bit."""
    from pyclpt.scene.model import ReconstructionFilter

    scene = pyclpt.load("cornell-box")
    scene.film.rfilter = ReconstructionFilter("gaussian", estimator="splat")
    r = Renderer(scene, width=W, height=H, max_depth=3)
    ref = r.render_sum(10, seed=6)
    image = r.render(10, seed=6)
    dr = DistributedRenderer(client, scene, width=W, height=H, max_depth=3)
    total = dr.render_sum(10, seed=6, task_spp=3, tile=None, timeout=JOB_TIMEOUT)
    assert len(dr.parts) == 4 and all(p.weights is not None for p in dr.parts)
    assert _relative(total, ref) <= MAX_RELATIVE
    np.testing.assert_allclose(dr.render(10, seed=6, task_spp=3, tile=None, timeout=JOB_TIMEOUT), image, rtol=1e-6)
    assert _relative(dr.render_sum(10, seed=6, task_spp=4, tile=(7, 5), timeout=JOB_TIMEOUT), ref) <= MAX_RELATIVE
    pr = pyclpt.ProgressiveRenderer(scene, width=W, height=H, max_depth=3, seed=2)
    local = []
    for _ in range(4):
        pr.step()
        local.append(pr.image())
    for a, b in zip(dr.render_progressive(4, seed=2, task_spp=3, timeout=JOB_TIMEOUT), local, strict=True):
        np.testing.assert_array_equal(a, b)
    # a denoised sequence: the frames' own samples and G-buffer, as the local denoiser gets them
    pr = pyclpt.ProgressiveRenderer(scene, width=W, height=H, max_depth=3, seed=2, denoiser="svgf")
    local = []
    for _ in range(3):
        pr.step()
        local.append(pr.denoised())
    for a, b in zip(dr.render_denoised(3, seed=2, denoiser="svgf", timeout=JOB_TIMEOUT), local, strict=True):
        np.testing.assert_array_equal(a, b)


def test_progressive_sequence_hands_frames_over_as_they_complete(client, monkeypatch):
    """With on_frame, each running-average frame is handed over (the CLI writes it) as soon as the samples
    before it are in: the first frame comes while most tasks are not even submitted (at most the window
    of two tasks a worker runs or waits), the frames held are bounded, and they equal the frames the
    sequence returns whole."""
    dr = DistributedRenderer(client, "cornell-box", width=W, height=H, max_depth=3)
    whole = dr.render_progressive(12, seed=2, task_spp=1, timeout=JOB_TIMEOUT)
    submitted = []
    submit = client.submit
    monkeypatch.setattr(client, "submit", lambda *a, **k: submitted.append(k.get("key")) or submit(*a, **k))
    seen = []
    assert dr.render_progressive(12, seed=2, task_spp=1, timeout=JOB_TIMEOUT,
                                 on_frame=lambda k, image: seen.append((k, image, len(submitted)))) == []
    assert [k for k, _, _ in seen] == list(range(12)) and len(submitted) == 12
    assert seen[0][2] <= dr.window == 4 < 12  # frame 0 handed over with 8 of the 12 tasks not yet submitted
    assert all(n <= k + 1 + dr.window for k, _, n in seen)
    assert 1 <= dr.held_tasks <= dr.window
    assert all(p.frames is None for p in dr.parts)  # not kept once handed over
    for (_, a, _), b in zip(seen, whole):
        np.testing.assert_array_equal(a, b)


def test_cli_progressive_sequence_on_a_cluster_writes_frames_as_it_goes(client, tmp_path, capsys, monkeypatch):
    """A running-average --sequence on a cluster writes each frame when it is complete, in frame order: Ctrl-C
    (here: in the write of frame 3 of 40) leaves frames 0..2 on disk and cancels the rest."""
    from pyclpt.common import image_io

    args = ["render", "cornell-box", "--spp", "40", "--sequence", "--width", str(W), "--height", str(H),
            "--max-depth", "2", "--quiet", "--scheduler", client.scheduler.address, "--task-spp", "1"]
    write = image_io.write_image
    order = []

    def interrupted(path, image, exposure=0.0):
        order.append(os.path.basename(str(path)))
        if len(order) == 4:
            raise KeyboardInterrupt
        return write(path, image, exposure)

    monkeypatch.setattr(image_io, "write_image", interrupted)
    assert main([*args, "-o", str(tmp_path / "d_##.exr")]) != 0
    assert "interrupted" in capsys.readouterr().err
    assert order == ["d_00.exr", "d_01.exr", "d_02.exr", "d_03.exr"]
    assert sorted(f.name for f in tmp_path.iterdir()) == ["d_00.exr", "d_01.exr", "d_02.exr"]
    _wait_released(client)
    monkeypatch.setattr(image_io, "write_image", write)
    assert main([*args[:2], "--spp", "3", *args[4:], "-o", str(tmp_path / "e_#.exr")]) == 0
    pr = pyclpt.ProgressiveRenderer(pyclpt.load("cornell-box"), width=W, height=H, max_depth=2, seed=0)
    for k in range(3):
        pr.step()
        np.testing.assert_array_equal(pyclpt.read_image(tmp_path / f"e_{k}.exr")[..., :3], pr.image())


@pytest.mark.parametrize("mode,orbit", [("svgf", 30), ("blend", None)])
def test_denoised_sequence_equals_local(client, mode, orbit):
    """A denoised sequence, a frame a task, denoised on the client in frame order: the local progressive
    renderer's denoised frames bit for bit (the camera path's motion vectors and the denoiser's history
    included)."""
    scene = pyclpt.load("cornell-box")
    path = CameraPath.orbit(scene, orbit, 5) if orbit else None
    pr = pyclpt.ProgressiveRenderer(scene, width=W, height=H, max_depth=3, seed=2, denoiser=mode, camera_path=path)
    local = []
    for _ in range(5):
        pr.step()
        local.append(pr.denoised())
    dr = DistributedRenderer(client, "cornell-box", width=W, height=H, max_depth=3)
    seen = []
    assert dr.render_denoised(5, seed=2, camera_path=path, denoiser=mode, timeout=JOB_TIMEOUT,
                              on_frame=lambda k, image: seen.append((k, image))) == []
    assert [k for k, _ in seen] == [0, 1, 2, 3, 4] and len(dr.parts) == 5
    assert all(p.gbuffer is None and p.frames is None for p in dr.parts)  # not kept once denoised
    for (_, a), b in zip(seen, local):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(seen[0][1], seen[4][1])
    frames = dr.render_denoised(2, seed=2, camera_path=path, denoiser=mode, timeout=JOB_TIMEOUT)
    np.testing.assert_array_equal(frames[1], local[1])
    with pytest.raises(ValueError, match="'oidn' denoises the running average"):
        dr.render_denoised(2, denoiser="oidn")


def test_denoise_gbuffer_checks_shapes(device):
    dn = pyclpt.Denoiser(device, W, H, mode="svgf")
    with pytest.raises(ValueError, match=r"color must be \(12, 16, 3\)"):
        dn.denoise_gbuffer(np.zeros((H, W + 1, 3), np.float32), None)
    with pytest.raises(ValueError, match=r"gbuffer must be \(\d+, 12, 16\)"):
        dn.denoise_gbuffer(np.zeros((H, W, 3), np.float32), np.zeros((3, H, W), np.float32))


def test_cli_scheduler_equals_local(client, tmp_path, capsys):
    args = ["render", "cornell-box", "--spp", "6", "--width", str(W), "--height", str(H), "--max-depth", "3",
            "--quiet"]
    assert main([*args, "-o", str(tmp_path / "local.exr")]) == 0
    assert main([*args, "-o", str(tmp_path / "dist.exr"), "--scheduler", client.scheduler.address,
                 "--task-spp", "2"]) == 0
    out = capsys.readouterr().out
    assert "on 2 workers at tcp://" in out and "3 tasks" in out
    np.testing.assert_allclose(pyclpt.read_image(tmp_path / "dist.exr"), pyclpt.read_image(tmp_path / "local.exr"),
                               rtol=1e-6)
    # tiles of 8x6: 2 x 2 tiles, each one task (all 6 samples)
    assert main([*args, "-o", str(tmp_path / "tiles.exr"), "--scheduler", client.scheduler.address,
                 "--tile", "8x6", "--task-spp", "6"]) == 0
    assert "4 tasks" in capsys.readouterr().out
    np.testing.assert_array_equal(pyclpt.read_image(tmp_path / "tiles.exr"), pyclpt.read_image(tmp_path / "local.exr"))


def test_cli_denoised_sequence_equals_local(client, tmp_path, capsys):
    args = ["render", "cornell-box", "--frames", "3", "--orbit", "20", "--denoise", "--sequence", "--width", str(W),
            "--height", str(H), "--max-depth", "3", "--quiet"]
    assert main([*args, "-o", str(tmp_path / "l_#.exr")]) == 0
    assert main([*args, "-o", str(tmp_path / "d_#.exr"), "--scheduler", client.scheduler.address]) == 0
    assert "3 tasks" in capsys.readouterr().out
    for k in range(3):
        np.testing.assert_array_equal(pyclpt.read_image(tmp_path / f"d_{k}.exr"),
                                      pyclpt.read_image(tmp_path / f"l_{k}.exr"))


def test_cli_workers_orbit_sequence(tmp_path, capsys):
    """--workers N starts its own LocalCluster; an orbit --sequence is one task per frame, each frame the
    local CLI's."""
    args = ["render", "cornell-box", "--frames", "3", "--orbit", "30", "--sequence", "--width", str(W),
            "--height", str(H), "--max-depth", "3", "--quiet"]
    assert main([*args, "-o", str(tmp_path / "l_##.exr")]) == 0
    assert main([*args, "-o", str(tmp_path / "d_##.exr"), "--workers", "2"]) == 0
    out = capsys.readouterr().out
    assert "a local cluster of 2 workers: 3 tasks" in out
    for k in range(3):
        np.testing.assert_array_equal(pyclpt.read_image(tmp_path / f"d_{k:02d}.exr"),
                                      pyclpt.read_image(tmp_path / f"l_{k:02d}.exr"))


@pytest.mark.parametrize("args, needle", [
    (["--workers", "2", "--scheduler", "tcp://x:1"], "not both"),
    (["--workers", "2", "--denoise", "oidn"], "--denoise oidn does not combine"),
    (["--workers", "2", "--device", "pocl"], "PYCLPT_DEVICE"),
    (["--workers", "2", "--orbit", "10"], "needs --sequence"),
    (["--task-spp", "4"], "--task-spp splits a render over a cluster: give --workers N or --scheduler"),
    (["--tile", "64"], "--tile splits a render over a cluster"),
])
def test_cli_refuses_bad_combinations(tmp_path, capsys, args, needle):
    assert main(["render", "cornell-box", "--spp", "1", "-o", str(tmp_path / "x.exr"), *args]) == 1
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "x.exr").exists()


def test_cli_bad_tile_named(capsys):
    with pytest.raises(SystemExit):
        main(["render", "cornell-box", "--workers", "2", "--tile", "8y8"])
    assert "--tile: expected N or WxH pixels (0: no tiles), got '8y8'" in capsys.readouterr().err


def test_merge_refuses_a_cancelled_task_s_exception():
    """A cancelled future's exception (what as_completed yields for it) is not a partial sum: a clear
    TypeError, never AttributeError 'no attribute first_sample'."""
    cancelled = distributed.client.FutureCancelledError("pyclpt-x", "scheduler-connection-lost")
    good = PartialSum(0, 1, np.ones((1, 1, 3)))
    for parts in ([good, cancelled], [cancelled]):
        with pytest.raises(TypeError, match="FutureCancelledError .*cancelled or failed task's exception"):
            merge(parts, 2)
        with pytest.raises(TypeError, match="cancelled or failed task's exception"):
            merge_tiles(parts, 2, 1, 1)


def _processing(scheduler, prefix: str) -> bool:
    """Whether a task whose key starts with ``prefix`` is running, read from the in-process scheduler of a
    LocalCluster (its loop's thread may change the table meanwhile: then it is read again). Not the client's
    ``processing()``, a call to the scheduler without a timeout, which hung once in a full run."""
    while True:
        try:
            return any(str(ts.key).startswith(prefix) and ts.state == "processing"
                       for ts in list(scheduler.tasks.values()))
        except RuntimeError:  # dictionary changed size during iteration
            continue


def test_lost_scheduler_is_a_clear_error_at_once():
    """The scheduler closes mid-render: ConnectionError naming its address and the lost connection (the
    tasks are cancelled then), not an AttributeError, nor the job's TimeoutError, after the whole job."""
    cluster = local_cluster(1, env={"POCL_MAX_PTHREAD_COUNT": "1"})
    c = distributed.Client(cluster, timeout="5s")  # 5 s: its reconnect attempts at the end
    try:
        c.wait_for_workers(1, timeout=JOB_TIMEOUT)
        address = c.scheduler.address
        dr = DistributedRenderer(c, "cornell-box", width=8, height=8)
        dr.render(1, task_spp=1, timeout=JOB_TIMEOUT)  # the worker has loaded the scene
        result: dict = {}

        def job():
            try:
                dr.render(4096, task_spp=1, timeout=JOB_TIMEOUT)
            except BaseException as exc:  # noqa: BLE001 - handed to the test thread
                result["error"] = exc

        thread = threading.Thread(target=job)
        thread.start()
        deadline = time.monotonic() + JOB_TIMEOUT
        while not _processing(cluster.scheduler, "pyclpt-"):
            assert time.monotonic() < deadline, "no task started"
            time.sleep(0.005)
        cluster.sync(cluster.scheduler.close)
        thread.join(JOB_TIMEOUT)  # a hang guard only: the error below is not the job's TimeoutError
        assert not thread.is_alive(), "the render hung after the scheduler was lost"
        error = result.get("error")
        assert isinstance(error, ConnectionError), repr(error)
        assert f"lost the connection to the Dask scheduler at {address}" in str(error)
    finally:
        # Cleanup, after the checks, and not part of them: the scheduler is gone on purpose, so the client's and
        # the cluster's close may race Dask's own teardown (a RuntimeError "dictionary changed size during
        # iteration" in the client's close was seen once in a full run) or find the connection closed (OSError,
        # CommClosedError). The cluster's close asks the closed scheduler to terminate, retrying its address for
        # Dask's whole connect timeout (30 s) before giving up; a closed port refuses at once.
        with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
            for close in (c.close, cluster.close):
                with contextlib.suppress(RuntimeError, OSError):
                    close()


def _quad_obj(path, x0: float) -> None:
    """A square (two triangles) facing the camera, its left edge at x = x0."""
    path.write_text(f"v {x0} 0.2 0.5\nv {x0 + 0.8} 0.2 0.5\nv {x0 + 0.8} 1.4 0.5\nv {x0} 1.4 0.5\n"
                    "f 1 2 3\nf 1 3 4\n")


def test_worker_cache_sees_an_edited_mesh_file(client, tmp_path):
    """A persistent cluster keys its renderers on every file the scene reads, not the XML's mtime
    alone: an edited OBJ renders the new geometry (the same image as a fresh local render)."""
    obj = tmp_path / "quad.obj"
    _quad_obj(obj, -0.9)
    xml = tmp_path / "scene.xml"
    xml.write_text(SMALL_SCENE.replace(
        '<shape type="sphere"><point name="center" x="0" y="0.6" z="0"/><float name="radius" value="0.6"/>',
        '<shape type="obj"><string name="filename" value="quad.obj"/>'))
    assert str(obj) in map(str, pyclpt.load(str(xml)).files)
    dr = DistributedRenderer(client, str(xml), width=W, height=H, max_depth=3)
    before = dr.render(4, seed=2, task_spp=2, timeout=JOB_TIMEOUT)
    _quad_obj(obj, 0.05)  # moved (and a file of another size): the XML is untouched
    after = dr.render(4, seed=2, task_spp=2, timeout=JOB_TIMEOUT)
    assert not np.array_equal(after, before)
    ref32, _ = _local(pyclpt.load(str(xml)), 4, seed=2, max_depth=3)
    np.testing.assert_allclose(after, ref32, rtol=1e-6, atol=1e-7)


def test_shipped_scene_is_sent_again_after_an_edit(client):
    """DistributedRenderer(client, scene): a Scene changed after it was sent (vertices moved in place,
    a field assigned) is sent again before the next render, never the first copy rendered."""
    scene = pyclpt.load("cornell-box")
    dr = DistributedRenderer(client, scene, width=W, height=H, max_depth=3)
    before = dr.render(4, seed=5, task_spp=2, timeout=JOB_TIMEOUT)
    token = dr.source.token
    again = dr.render(4, seed=5, task_spp=2, timeout=JOB_TIMEOUT)
    assert dr.source.token == token  # unchanged: not sent again
    np.testing.assert_array_equal(again, before)
    next(m for m in scene.meshes if m.name == "small-box").positions[:, 0] += 0.3  # in place
    after = dr.render(4, seed=5, task_spp=2, timeout=JOB_TIMEOUT)
    assert dr.source.token != token and not np.array_equal(after, before)
    np.testing.assert_allclose(after, _local(scene, 4, seed=5, max_depth=3)[0], rtol=1e-6, atol=1e-7)
    dr.close()


def test_local_workers_beyond_the_cores_warn_and_absurd_counts_are_refused(monkeypatch, caplog, tmp_path, capsys):
    from pyclpt.distributed import cluster

    monkeypatch.setattr(cluster, "cores", lambda: 2)
    with caplog.at_level("WARNING", logger="pyclpt"):
        assert cluster.check_workers(2) == 2
    assert not caplog.records
    with caplog.at_level("WARNING", logger="pyclpt"):
        assert cluster.check_workers(3) == 3
    assert "3 local workers on 2 CPU cores" in caplog.text
    with pytest.raises(ValueError, match=r"workers=9: a local cluster of 9 worker processes on 2 CPU cores \(at "
                                         r"most 8"):
        cluster.local_cluster(9)
    rc = main(["render", "cornell-box", "--spp", "1", "--workers", "12", "--width", "4", "--height", "4",
               "--quiet", "-o", str(tmp_path / "x.exr")])
    assert rc == 1 and "workers=12: a local cluster of 12 worker processes" in capsys.readouterr().err
    assert not (tmp_path / "x.exr").exists()


def _closed_port() -> int:
    """A local TCP port nothing listens on (bound, then closed)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_refused_scheduler_connection_fails_at_once_naming_the_address(tmp_path, capsys):
    """Nothing listens at the address: ConnectionError naming it and saying it refused, from the probe (its
    timeout only guards against a hang), not Dask's 30 s of retries."""
    from pyclpt.distributed import connect

    address = f"tcp://127.0.0.1:{_closed_port()}"
    with pytest.raises(ConnectionError, match=f"the Dask scheduler at {address} refused the connection"):
        with connect(address, probe_timeout=JOB_TIMEOUT):
            pass
    rc = main(["render", "cornell-box", "--spp", "1", "--scheduler", address, "--width", "4", "--height", "4",
               "--quiet", "-o", str(tmp_path / "x.exr")])
    assert rc == 1 and f"the Dask scheduler at {address} refused the connection" in capsys.readouterr().err
    from pyclpt.distributed.cluster import probe_scheduler

    probe_scheduler("inproc://nothing")  # not TCP: left to Dask
