"""The live viewer (pyclpt.viewer, ``pyclpt view``): the notebook image and its PNG, the camera moves and
their Mitsuba XML, and the server end to end through its own WebSocket with aiohttp's client: the page is
served, pictures stream, a camera move and a change of view change them, the frame counter rises, a
closed page pauses the render, Ctrl-C ends ``pyclpt view`` within a second, bad input says what is wrong."""
from __future__ import annotations

import asyncio
import copy
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

import pyclpt
from pyclpt.viewer.camera import OrbitCamera, lookat_xml
from pyclpt.viewer.display import (
    SAMPLES_WHITE,
    ImageView,
    aov_to_display,
    encode_png,
    samples_to_display,
    show,
    tonemap,
    tonemap_fast,
)

W, H = 48, 27  # the frames of the server tests: small, so that a picture takes milliseconds


def decode_png(data: bytes, tmp_path: Path) -> np.ndarray:
    """The pixels of PNG bytes, read back by OpenImageIO (a decoder that is not ours)."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    path = tmp_path / f"decode_{time.monotonic_ns()}.png"
    path.write_bytes(data)
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    try:
        return np.asarray(inp.read_image("uint8"))
    finally:
        inp.close()


# -- images in notebooks ------------------------------------------------------------------------------

def test_png_encoder_round_trips(tmp_path):
    rng = np.random.default_rng(1)
    pixels = rng.integers(0, 256, size=(17, 23, 3), dtype=np.uint8)
    assert np.array_equal(decode_png(encode_png(pixels), tmp_path), pixels)


def test_repr_png_is_write_images_png(tmp_path):
    """ImageView's PNG holds the pixels write_image's PNG holds: the same exposure and sRGB tonemap."""
    rng = np.random.default_rng(2)
    image = (rng.random((12, 20, 3)) * 2.0).astype(np.float32)
    view = ImageView(image, exposure=0.5)
    png = view._repr_png_()
    pyclpt.write_image(tmp_path / "ref.png", image, exposure=0.5)
    ref = decode_png((tmp_path / "ref.png").read_bytes(), tmp_path)
    assert np.array_equal(decode_png(png, tmp_path), ref)
    assert view._repr_html_().startswith('<img src="data:image/png;base64,')
    assert np.asarray(view) is view.image and view.shape == (12, 20, 3)


def test_show_outside_ipython_returns_the_view():
    image = np.full((4, 4, 3), 0.5, np.float32)
    shown = show(image)
    assert isinstance(shown, ImageView)
    assert np.array_equal(shown.pixels(), tonemap(image))
    with pytest.raises(ValueError, match="expected an"):
        ImageView(np.zeros((4, 4, 2)))


def test_fast_tonemap_is_within_one_step():
    rng = np.random.default_rng(3)
    image = (rng.random((40, 50, 3)) * 3.0).astype(np.float32)
    image[0, 0] = [np.nan, np.inf, -1.0]
    for exposure in (0.0, -1.5, 2.0):
        diff = np.abs(tonemap_fast(image, exposure).astype(int) - tonemap(image, exposure).astype(int))
        assert diff.max() <= 1 and (diff > 0).mean() < 0.01
    assert tonemap_fast(image)[0, 0].tolist() == [0, 255, 0]


def test_aov_displays():
    normal = np.zeros((2, 2, 3), np.float32)
    normal[..., 2] = 1.0
    assert aov_to_display("normal", normal)[0, 0].tolist() == [128, 128, 255]
    depth = np.array([[1.0, 2.0], [0.0, 3.0]], np.float32)[:, :, None]
    grey = aov_to_display("depth", depth)[..., 0]
    assert grey[0, 0] == 255 and grey[1, 0] == 0 and grey[0, 1] > grey[1, 1] > 0
    motion = np.array([[[2.0, 0.0], [0.0, -1.0]], [[0.0, 0.0], [1e6, 1e6]]], np.float32)
    shown = aov_to_display("motion", motion)
    assert shown[0, 0].tolist() == [255, 128, 128] and shown[0, 1].tolist() == [128, 64, 128]
    assert shown[1, 0].tolist() == [128, 128, 128] and shown[1, 1].tolist() == [0, 0, 0]


def test_samples_display():
    """Black without a sample, dark blue for one, brighter with more (a log scale), white from SAMPLES_WHITE on."""
    counts = np.array([[0, 1, 4, 64, 1024, SAMPLES_WHITE, 10 * SAMPLES_WHITE]])
    shown = samples_to_display(counts)
    assert shown.shape == (1, 7, 3) and shown.dtype == np.uint8
    assert shown[0, 0].tolist() == [0, 0, 0] and shown[0, 5].tolist() == [255, 255, 255] == shown[0, 6].tolist()
    r, g, b = shown[0, 1]
    assert b > 90 and b > 3 * r
    brightness = shown[0].astype(int).sum(axis=1)
    assert all(brightness[k] < brightness[k + 1] for k in range(5))
    with pytest.raises(ValueError, match="sample counts"):
        samples_to_display(np.zeros((2, 2, 3)))


# -- the camera ---------------------------------------------------------------------------------------

def test_orbit_camera_moves(cornell_box):
    cam = OrbitCamera(cornell_box)
    start, right, d = cam.origin, cam.right, cam.distance
    cam.orbit(10.0, 0.0)
    assert np.dot(cam.origin - start, right) > 0 and cam.distance == pytest.approx(d)
    cam.reset()
    cam.orbit(0.0, 1000.0)  # stopped short of the pole
    angle = np.degrees(np.arccos(np.dot(cam.forward, cam.up)))
    assert angle == pytest.approx(178.0)
    cam.reset()
    cam.zoom(0.5)
    assert cam.distance == pytest.approx(d / 2)
    target = cam.target.copy()
    cam.fly(0.1, 0.0, 0.0)
    assert np.allclose(cam.target - target, 0.1 * cam.scene_size * cam.forward)
    with pytest.raises(ValueError, match="finite"):
        cam.orbit(float("nan"), 0.0)


def test_lookat_xml_loads_back_as_the_same_camera(tmp_path, cornell_box):
    cam = OrbitCamera(cornell_box)
    cam.orbit(25.0, -10.0)
    cam.pan(0.1, 0.05)
    flipped = cam.camera()
    flipped.to_world = flipped.to_world @ np.diag([-1.0, 1.0, 1.0, 1.0])  # a handedness flip: a <scale>
    for camera in (cam.camera(), flipped):
        sensor = lookat_xml(camera, cam.distance)
        (tmp_path / "scene.xml").write_text(
            f'<scene version="3.0.0">\n{sensor}<shape type="sphere"/>\n</scene>\n')
        loaded = pyclpt.load_xml(tmp_path / "scene.xml").camera
        assert np.allclose(loaded.to_world, camera.to_world, atol=1e-5), sensor
        assert loaded.fov == pytest.approx(camera.fov, rel=1e-5) and loaded.fov_axis == camera.fov_axis
    assert "<scale value=\"-1, 1, 1\"/>" in lookat_xml(flipped)


# -- the server ---------------------------------------------------------------------------------------

aiohttp = pytest.importorskip("aiohttp")
from pyclpt.viewer.server import Viewer, default_size, frame_size  # noqa: E402
from pyclpt.viewer.session import RenderSession  # noqa: E402


@pytest.fixture(scope="module")
def viewer(tmp_path_factory, cornell_box, device):
    session = RenderSession(copy.deepcopy(cornell_box), width=W, height=H, device=device, denoiser="svgf",
                            output_dir=tmp_path_factory.mktemp("viewer-out"), idle_after=60.0)
    v = Viewer(session).start()
    yield v
    v.close()


class Page:
    """A page of the viewer, as a test sees it: a WebSocket client that keeps the latest status and picture."""

    def __init__(self, ws) -> None:
        self.ws = ws
        self.status: dict = {}
        self.png: bytes | None = None
        self.pictures = 0
        self.replies: list[dict] = []

    async def next_picture(self, timeout: float = 20.0) -> bytes:
        """The next picture after those seen (its status is self.status)."""
        async with asyncio.timeout(timeout):
            async for msg in self.ws:
                if msg.type == aiohttp.WSMsgType.TEXT:
                    data = json.loads(msg.data)
                    if data["type"] == "status":
                        self.status = data
                    else:
                        self.replies.append(data)
                elif msg.type == aiohttp.WSMsgType.BINARY:
                    self.png = msg.data
                    self.pictures += 1
                    return msg.data
                else:
                    raise ConnectionError(f"the WebSocket closed: {msg}")
        raise ConnectionError("the WebSocket closed")

    async def picture_where(self, check, timeout: float = 20.0) -> bytes:
        """The first next picture whose status passes ``check``."""
        deadline = time.monotonic() + timeout
        while True:
            png = await self.next_picture(max(deadline - time.monotonic(), 0.01))
            if check(self.status):
                return png

    async def reply(self, kind: str, timeout: float = 20.0) -> dict:
        deadline = time.monotonic() + timeout
        while not any(r["type"] == kind for r in self.replies):
            await self.next_picture(max(deadline - time.monotonic(), 0.01))
        return next(r for r in self.replies if r["type"] == kind)


def on_page(viewer: Viewer, script) -> object:
    """Run ``await script(page)`` against a fresh WebSocket connection to ``viewer``."""
    async def main():
        async with aiohttp.ClientSession() as http:
            async with http.ws_connect(viewer.url + "ws") as ws:
                return await script(Page(ws))
    return asyncio.run(main())


def test_page_and_script_are_served(viewer):
    assert viewer.url.startswith("http://127.0.0.1:") and viewer.port > 0
    page = urllib.request.urlopen(viewer.url, timeout=10).read().decode()
    assert "<title>pyclpt viewer</title>" in page and 'src="static/viewer.js"' in page
    script = urllib.request.urlopen(viewer.url + "static/viewer.js", timeout=10).read().decode()
    assert 'op: "orbit"' in script and "new WebSocket" in script
    status = json.loads(urllib.request.urlopen(viewer.url + "status", timeout=10).read())
    assert status["width"] == W and status["height"] == H and status["scene"] == "cornell-box"


def test_frames_stream_and_the_counter_rises(viewer, tmp_path):
    async def script(page):
        first = await page.next_picture()
        s0 = dict(page.status)
        for _ in range(3):
            await page.next_picture()
        return first, s0, dict(page.status)

    first, s0, s1 = on_page(viewer, script)
    assert decode_png(first, tmp_path).shape == (H, W, 3)
    assert s1["frame"] > s0["frame"] and s1["sample_index"] > s0["sample_index"]
    assert s1["rendering"] and s1["clients"] == 1 and s1["fps"] > 0 and s1["shown"] == "denoised"
    kernels = {row["kernel"]: row["ms"] for row in s1["kernels"]}  # the time bars: renderer and denoiser
    assert kernels.get("megakernel", 0) > 0 and "atrous" in kernels, kernels
    assert not viewer.session.pr.renderer.integrator.profile.sequence or len(
        viewer.session.pr.renderer.integrator.profile.sequence) < 1000  # profiling events do not pile up
    png = urllib.request.urlopen(viewer.url + "frame.png", timeout=10).read()
    assert decode_png(png, tmp_path).shape == (H, W, 3)


def test_camera_move_changes_the_picture_without_a_reset(viewer, tmp_path):
    async def script(page):
        await page.next_picture()
        before = await page.next_picture()
        s_before = dict(page.status)
        await page.ws.send_json({"type": "camera", "op": "orbit", "yaw": 30.0, "pitch": 0.0})
        after = await page.picture_where(lambda s: s["reprojections"] > s_before["reprojections"])
        return before, s_before, after, dict(page.status)

    before, s0, after, s1 = on_page(viewer, script)
    a, b = decode_png(before, tmp_path).astype(float), decode_png(after, tmp_path).astype(float)
    assert np.abs(a - b).mean() > 5.0  # the view turned: the walls moved across the picture
    assert s1["resets"] == s0["resets"]  # the denoiser reprojected its history: no restart from black
    assert b.mean() > 0.5 * a.mean()


def test_switching_to_normals_changes_the_pixels(viewer, tmp_path):
    async def script(page):
        await page.picture_where(lambda s: s["shown"] == "denoised")
        color = page.png
        await page.ws.send_json({"type": "camera", "op": "reset"})  # the scene's own camera
        await page.ws.send_json({"type": "set", "name": "view", "value": "normal"})
        normal = await page.picture_where(lambda s: s["shown"] == "normal")
        await page.ws.send_json({"type": "set", "name": "view", "value": "denoised"})
        await page.picture_where(lambda s: s["shown"] == "denoised")
        return color, normal

    color, normal = on_page(viewer, script)
    c, n = decode_png(color, tmp_path).astype(float), decode_png(normal, tmp_path).astype(float)
    assert np.abs(c - n).mean() > 10.0
    # 0.5 + 0.5 n: the ceiling faces down (green 0), the floor up (green 255), the back wall the camera (blue)
    assert n[2, W // 2, 1] < 40 and n[H - 2, W // 2, 1] > 215 and n[H // 2, W // 2, 2] > 200


def test_settings_save_and_lookat(viewer):
    async def script(page):
        await page.next_picture()
        await page.ws.send_json({"type": "set", "name": "spp_per_frame", "value": 2})
        await page.picture_where(lambda s: s["settings"]["spp_per_frame"] == 2)
        await page.ws.send_json({"type": "set", "name": "spp_per_frame", "value": 0})
        bad = await page.reply("error")
        await page.ws.send_json({"type": "set", "name": "spp_per_frame", "value": 1})
        await page.ws.send_json({"type": "save"})
        saved = await page.reply("saved")
        await page.ws.send_json({"type": "lookat"})
        lookat = await page.reply("lookat")
        await page.ws.send_json({"type": "keyframe", "op": "add"})
        keyframes = await page.reply("keyframes")
        await page.ws.send_json({"type": "keyframe", "op": "clear"})
        await page.ws.send_json({"type": "camera", "op": "spin", "yaw": 1})
        page.replies.clear()
        unknown = await page.reply("error")
        return bad, saved, lookat, unknown, keyframes

    bad, saved, lookat, unknown, keyframes = on_page(viewer, script)
    assert keyframes["op"] == "add" and keyframes["count"] >= 1
    assert "spp_per_frame" in bad["message"] and "1..64" in bad["message"]
    exr, png = map(Path, saved["paths"])
    assert exr.suffix == ".exr" and png.suffix == ".png" and exr.is_file() and png.is_file()
    assert pyclpt.read_image(exr).shape == (H, W, 3)
    assert "<lookat origin=" in lookat["xml"] and Path(lookat["path"]).read_text() == lookat["xml"]
    assert "unknown camera move 'spin'" in unknown["message"]


def test_two_pages_share_the_session(viewer):
    async def main():
        async with aiohttp.ClientSession() as http:
            async with http.ws_connect(viewer.url + "ws") as a, http.ws_connect(viewer.url + "ws") as b:
                pa, pb = Page(a), Page(b)
                await pa.picture_where(lambda s: s["clients"] == 2)
                await pb.next_picture()
                await pa.ws.send_json({"type": "set", "name": "exposure", "value": 1.0})
                await pb.picture_where(lambda s: s["settings"]["exposure"] == 1.0)
                await pa.ws.send_json({"type": "set", "name": "exposure", "value": 0.0})
                await pb.picture_where(lambda s: s["settings"]["exposure"] == 0.0)
                return True

    assert asyncio.run(main())


def test_a_closed_page_pauses_and_close_is_prompt(cornell_box, device):
    session = RenderSession(copy.deepcopy(cornell_box), width=16, height=9, device=device, denoiser=None,
                            idle_after=0.3)
    v = Viewer(session).start()
    try:
        on_page(v, lambda page: page.next_picture())
        deadline = time.monotonic() + 10
        while session.rendering and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not session.rendering and session.clients == 0
        frames = session.frames
        time.sleep(0.3)
        assert session.frames == frames  # paused: nothing rendered without a page
        assert on_page(v, lambda page: page.next_picture())  # a new page wakes it
    finally:
        v.close()  # (it returns within a second; timings are measured in bench/, not asserted here)
    assert not session.running
    with pytest.raises(urllib.error.URLError):
        urllib.request.urlopen(v.url, timeout=2)


def test_keyframes_play_and_save_as_a_camera_path(cornell_box, device, tmp_path):
    from pyclpt.viewer.camera import camera_path_from_json

    session = RenderSession(cornell_box, width=16, height=9, device=device, denoiser="blend", output_dir=tmp_path,
                            idle_after=60.0)
    with pytest.raises(ValueError, match="no keyframes recorded"):
        session.keyframe("save").result(timeout=10)
    session.start()
    try:
        assert session.keyframe("add").result(timeout=10)["count"] == 1
        with pytest.raises(ValueError, match="a path to play needs two or more"):
            session.keyframe("play").result(timeout=10)
        first = session.orbit.camera()
        session.move("orbit", yaw=40.0, pitch=0.0)
        assert session.keyframe("add").result(timeout=10)["count"] == 2
        moves = session.pr.reprojections
        session.keyframe("play", spacing=4).result(timeout=10)
        deadline = time.monotonic() + 20
        while session.status()["playing"] and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not session.status()["playing"] and session.pr.reprojections >= moves + 4
        assert np.allclose(session.orbit.matrix, session.keyframes[-1].to_world)  # the path ends at the last
        saved = session.keyframe("save", spacing=4).result(timeout=10)
        path = camera_path_from_json(json.loads(Path(saved["path"]).read_text()))
        assert [k.time for k in path.keyframes] == [0.0, 4.0]
        assert np.allclose(path.camera(0).to_world, first.to_world)
        with pytest.raises(ValueError, match="unknown keyframe operation"):
            session.keyframe("rewind")
        session.keyframe("clear").result(timeout=10)
        assert session.status()["keyframes"] == 0
    finally:
        session.close()


def test_a_port_in_use_is_an_os_error(viewer, cornell_box, device):
    session = RenderSession(cornell_box, width=8, height=8, device=device, denoiser=None)
    with pytest.raises(OSError, match="address already in use"):
        Viewer(session, port=viewer.port).start()
    assert not session.running


def test_a_failing_frame_is_reported_and_a_change_retries(cornell_box, device, caplog):
    session = RenderSession(cornell_box, width=16, height=9, device=device, denoiser=None, idle_after=60.0)
    assert session.scene is not cornell_box  # the caller's scene keeps its camera
    real_step = session.pr.step
    session.pr.step = lambda frames: (_ for _ in ()).throw(RuntimeError("the device went away"))
    session.start()
    try:
        deadline = time.monotonic() + 10
        while session.error is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert session.error == "the device went away" and session.status()["error"] == session.error
        assert "rendering failed: the device went away" in caplog.text
        session.pr.step = real_step
        session.set("exposure", 1.0).result(timeout=10)
        session.wait_frame(session.frames, timeout=10)
        assert session.error is None
    finally:
        session.close()
    assert not session.running


def test_default_size_keeps_the_aspect(cornell_box):
    assert default_size(1280, 720) == (640, 360)
    assert default_size(256, 256) == (256, 256)
    scene = copy.copy(cornell_box)
    scene.film = dataclasses.replace(scene.film, width=1920, height=1080)
    assert frame_size(scene, None, None) == (640, 360)
    assert frame_size(scene, 320, None) == (320, 180) and frame_size(scene, None, 90) == (160, 90)
    assert frame_size(scene, 10, 20) == (10, 20)


def test_fit_size_keeps_the_aspect_within_the_maximum():
    from pyclpt.viewer.session import MIN_SIDE, fit_size

    assert fit_size(256, 256, 500, 400, 640) == (400, 400)
    assert fit_size(256, 256, 500, 400, 64) == (64, 64)  # the maximum caps it
    assert fit_size(1920, 1080, 800, 800, 640) == (640, 360)
    assert fit_size(1920, 1080, 300, 600, 640) == (300, 169)  # the width limits it
    assert fit_size(1920, 1080, 1, 1, 640) == (14, MIN_SIDE)  # a tiny window still gets a picture
    assert fit_size(256, 256, 4000, 4000, 10) == (10, 10)


def _other_device(session) -> str:
    """A device to switch to: another one than the session's (not the Oclgrind simulator), else the same."""
    current = session.settings["device"]
    others = [d["id"] for d in session.devices() if d["id"] != current and "oclgrind" not in d["name"].lower()]
    return others[0] if others else current


def test_samples_view_window_size_and_device_switch(cornell_box, device, tmp_path):
    """The samples view shows the count of the plain average, uniform; the frame follows the window within
    max_size, the scene's aspect kept; the device setting offers `pyclpt devices`' list and rebuilds the
    renderer on the one chosen, and a device that fails leaves the previous renderer rendering."""
    session = RenderSession(copy.deepcopy(cornell_box), width=24, height=24, device=device, denoiser=None,
                            idle_after=60.0, max_size=40)
    ids = [d["id"] for d in session.devices()]
    assert ids == [f"{p}:{i}" for p, i, _ in pyclpt.list_devices()] and session.settings["device"] in ids
    assert session.status()["settings"]["device"] == session.settings["device"]
    session.start()
    try:
        session.set("view", "samples").result(timeout=30)
        frame = session.wait_frame(session.frames, timeout=30)
        while frame.status["spp"] < 2:
            frame = session.wait_frame(frame.index, timeout=30)
        assert frame.status["shown"] == "samples"
        px = decode_png(frame.png, tmp_path)
        assert (px == px[0, 0]).all()  # uniform: the renderer is not adaptive
        assert px[0, 0].tolist() == samples_to_display(np.array([[frame.status["spp"]]]))[0, 0].tolist()
        assert session.sample_counts().shape == (session.pr.height, session.pr.width)

        assert session.fit(30, 20).result(timeout=30) == (20, 20)  # the scene's square, in the window
        assert session.fit(400, 300, scale=2.0).result(timeout=30) == (40, 40)  # at most max_size
        frame = session.wait_frame(session.frames, timeout=30)
        while (frame.width, frame.height) != (40, 40):
            frame = session.wait_frame(frame.index, timeout=30)
        assert session.status()["max_size"] == 40
        with pytest.raises(ValueError, match="viewport width"):
            session.fit(float("nan"), 10)

        with pytest.raises(ValueError, match="setting device: '99:99' is not one of the OpenCL devices"):
            session.set("device", "99:99").result(timeout=30)
        before, pr = session.settings["device"], session.pr
        real_make = session._make_renderer
        session._make_renderer = lambda: (_ for _ in ()).throw(RuntimeError("no kernels for this device"))
        target = _other_device(session)
        if target != before:
            with pytest.raises(RuntimeError, match="no kernels for this device"):
                session.set("device", target).result(timeout=30)
            assert session.pr is pr and session.settings["device"] == before  # the previous one goes on
            session.wait_frame(session.frames, timeout=30)
        session._make_renderer = real_make
        session.set("device", target).result(timeout=300)  # compiles the programs there (cached after)
        assert session.settings["device"] == target
        name = next(d["name"] for d in session.devices() if d["id"] == target)
        assert session.pr.device.name == name and (session.pr.width, session.pr.height) == (40, 40)
        frame = session.wait_frame(session.frames, timeout=60)
        assert frame.status["device"] == name and session.error is None
    finally:
        session.close()


def test_the_page_gets_the_devices_and_its_window_size(viewer):
    """The server sends the device list first; a viewport message answers with the frame size (fixed here:
    the module's viewer was made with a width and height)."""
    async def script(page):
        first = await page.ws.receive_json(timeout=20)
        await page.ws.send_json({"type": "viewport", "width": 300, "height": 200, "scale": 1})
        size = await page.reply("size")
        await page.ws.send_json({"type": "viewport", "width": -1, "height": 200})
        bad = await page.reply("error")
        return first, size, bad

    first, size, bad = on_page(viewer, script)
    assert first["type"] == "devices" and first["devices"] == viewer.session.devices()
    assert size == {"type": "size", "width": W, "height": H, "follows_window": False}
    assert "viewport width must be a positive number" in bad["message"]


# -- the command line ---------------------------------------------------------------------------------

def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(Path(__file__).resolve().parent.parent) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def test_cli_view_serves_and_ctrl_c_ends_it_within_a_second(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "pyclpt", "view", "cornell-box", "--no-browser", "--width", "32",
                             "--height", "18", "--denoiser", "off", "--output-dir", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    try:
        line = proc.stdout.readline()
        assert "http://127.0.0.1:" in line, (line, proc.stderr.read() if proc.poll() is not None else "")
        url = line[line.index("http://"):].split()[0]
        deadline = time.monotonic() + 60
        while True:
            try:
                png = urllib.request.urlopen(url + "frame.png", timeout=5).read()
                break
            except urllib.error.HTTPError as exc:  # 503 until the first picture
                assert exc.code == 503 and time.monotonic() < deadline
                time.sleep(0.1)
        assert decode_png(png, tmp_path).shape == (18, 32, 3)
        proc.send_signal(signal.SIGINT)
        rc = proc.wait(timeout=30)  # a hang guard: Ctrl-C ends it within a second on an idle machine
        assert rc == 130, proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_cli_view_bad_scene_is_one_line(tmp_path, capsys):
    from pyclpt.cli import main

    bad = tmp_path / "bad.xml"
    bad.write_text("<scene version='3.0.0'><shape type='nosuchshape'/></scene>")
    assert main(["view", str(bad), "--no-browser"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("pyclpt: error: ") and "nosuchshape" in err and "Traceback" not in err


def test_cli_view_without_aiohttp_names_the_extra(monkeypatch, capsys):
    from pyclpt.cli import main

    monkeypatch.setitem(sys.modules, "aiohttp", None)  # import aiohttp raises ImportError
    assert main(["view", "cornell-box", "--no-browser"]) == 1
    assert 'pip install "pyclpt[viewer]"' in capsys.readouterr().err


# -- a real browser -----------------------------------------------------------------------------------

CHROMIUM = Path("/usr/bin/chromium")


def _browser_or_skip():
    """playwright's sync API with Debian's Chromium; skips without them unless PYCLPT_REQUIRE_BROWSER=1."""
    from pyclpt.common import env

    why = None
    try:
        from playwright.sync_api import sync_playwright
    except ImportError as exc:
        why = f"playwright is not installed ({exc})"
    if why is None and not CHROMIUM.is_file():
        why = f"no Chromium at {CHROMIUM} (Debian: apt-get install chromium)"
    if why is not None:
        if env.flag("PYCLPT_REQUIRE_BROWSER"):
            pytest.fail(f"PYCLPT_REQUIRE_BROWSER=1 but {why}", pytrace=False)
        pytest.skip(why)
    return sync_playwright


def test_in_chromium(cornell_box, device, tmp_path):
    """The page in headless Chromium: the first picture appears, a mouse drag turns the camera and the
    picture changes, the W key flies, the normals view changes the pixels, the frame counter rises, closing the page
    pauses the render."""
    sync_playwright = _browser_or_skip()
    session = RenderSession(copy.deepcopy(cornell_box), width=64, height=36, device=device, denoiser="svgf",
                            output_dir=tmp_path, idle_after=0.5)
    viewer = Viewer(session).start()
    frame_of = "Number(document.getElementById('frame').dataset.frame || 0)"
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
            try:
                page = browser.new_page(viewport={"width": 800, "height": 400})
                page.goto(viewer.url)
                page.wait_for_function(f"{frame_of} > 2 && document.getElementById('frame').complete", timeout=30000)
                img = page.locator("#frame")
                first_count = page.evaluate(frame_of)
                before = decode_png(img.screenshot(), tmp_path).astype(float)
                box = img.bounding_box()
                x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
                page.mouse.move(x, y)
                page.mouse.down()
                page.mouse.move(x + 80, y, steps=4)
                page.mouse.up()
                page.wait_for_function("Number(document.getElementById('reprojections').textContent) > 0",
                                       timeout=10000)
                page.wait_for_function(f"{frame_of} > {page.evaluate(frame_of) + 2}", timeout=10000)
                turned = decode_png(img.screenshot(), tmp_path).astype(float)
                assert np.abs(turned - before).mean() > 3.0
                moves = int(page.text_content("#reprojections"))
                page.keyboard.down("w")  # fly forward (the picture has the focus since the drag)
                page.wait_for_timeout(300)
                page.keyboard.up("w")
                page.wait_for_function(f"Number(document.getElementById('reprojections').textContent) > {moves}",
                                       timeout=10000)
                page.select_option("#view", "normal")
                page.wait_for_function("document.getElementById('frame').dataset.shown === 'normal'", timeout=10000)
                page.wait_for_function(f"{frame_of} > {page.evaluate(frame_of) + 2}", timeout=10000)
                normal = decode_png(img.screenshot(), tmp_path).astype(float)
                assert np.abs(normal - turned).mean() > 5.0
                assert page.evaluate(frame_of) > first_count
                assert session.clients == 1
                page.close()
            finally:
                browser.close()
        deadline = time.monotonic() + 10
        while (session.clients or session.rendering) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert session.clients == 0 and not session.rendering
    finally:
        viewer.close()


def test_in_chromium_window_size_samples_and_devices(cornell_box, device, tmp_path):
    """The page in headless Chromium, with a frame that follows the window (max_size 64): the frame fills the
    picture area up to 64 pixels and shrinks with the window; the samples view shows a uniform picture; the
    device select lists the devices, an unknown one is refused on the page, and choosing another renders there."""
    sync_playwright = _browser_or_skip()
    session = RenderSession(copy.deepcopy(cornell_box), width=32, height=32, device=device, denoiser=None,
                            output_dir=tmp_path, idle_after=0.5, max_size=64)
    viewer = Viewer(session).start()
    frame_of = "Number(document.getElementById('frame').dataset.frame || 0)"
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
            try:
                stage = "[document.getElementById('stage').clientWidth, document.getElementById('stage').clientHeight]"
                page = browser.new_page(viewport={"width": 800, "height": 400})  # a picture area over 64 x 64
                page.goto(viewer.url)
                page.wait_for_function("document.getElementById('size').textContent.startsWith('64 × 64')",
                                       timeout=30000)
                assert "follows the window, ≤ 64" in page.text_content("#size")
                page.set_viewport_size({"width": 370, "height": 300})  # beside the panel: under 64 pixels wide
                area = page.evaluate(stage)
                side = min(area)  # the scene is square
                assert 8 <= side < 64, area
                page.wait_for_function(f"document.getElementById('size').textContent.startsWith('{side} × {side}')",
                                       timeout=30000)
                assert (session.pr.width, session.pr.height) == (side, side)

                page.select_option("#view", "samples")
                page.wait_for_function("document.getElementById('frame').dataset.shown === 'samples'", timeout=10000)
                page.wait_for_function(f"{frame_of} > {page.evaluate(frame_of) + 2}", timeout=10000)
                # the picture itself, as the page decoded it: its size and one colour (the renderer is not adaptive).
                # Read in one task once a frame has loaded (the next frame may be loading: naturalWidth 0 meanwhile).
                size, colours = page.evaluate("""async () => {
                    const img = document.getElementById('frame');
                    for (let k = 0; k < 200 && !(img.complete && img.naturalWidth > 0); k++)
                        await new Promise(r => setTimeout(r, 25));
                    const c = document.createElement('canvas');
                    c.width = img.naturalWidth; c.height = img.naturalHeight;
                    const g = c.getContext('2d'); g.drawImage(img, 0, 0);
                    const d = g.getImageData(0, 0, c.width, c.height).data, seen = new Set();
                    for (let i = 0; i < d.length; i += 4) seen.add(d[i] + ',' + d[i + 1] + ',' + d[i + 2]);
                    return [[c.width, c.height], [...seen]];
                }""")
                assert size == [side, side]
                assert len(colours) == 1 and colours[0] != "0,0,0", colours

                listed = page.eval_on_selector_all("#device option", "els => els.map(e => e.value)")
                assert listed == [d["id"] for d in session.devices()]
                assert page.input_value("#device") == session.settings["device"]
                page.evaluate("""() => { const o = document.createElement('option');
                                          o.value = '99:99'; o.textContent = 'no such device';
                                          document.getElementById('device').append(o); }""")
                page.select_option("#device", "99:99")
                page.wait_for_function("document.getElementById('notice').textContent.includes('setting device')",
                                       timeout=10000)
                target = _other_device(session)
                name = next(d["name"] for d in session.devices() if d["id"] == target)
                page.select_option("#device", target)
                page.wait_for_function("document.getElementById('notice').textContent === ''", timeout=10000)
                page.wait_for_function(f"document.getElementById('device-name').textContent === {json.dumps(name)}",
                                       timeout=300000)  # the programs compile there first (cached after)
                page.wait_for_function(f"{frame_of} > {page.evaluate(frame_of) + 2}", timeout=30000)
                assert session.settings["device"] == target and session.error is None
                page.close()
            finally:
                browser.close()
    finally:
        viewer.close()
