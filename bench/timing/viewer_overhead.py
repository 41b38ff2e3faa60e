"""The live viewer's overhead (docs/viewer.md): frames per second of the same progressive render of
cornell-box at 320x180, one sample per pixel a frame, without the viewer (``ProgressiveRenderer.step`` in
a loop) and with it (the viewer's render thread: read-back, tonemap, PNG, WebSocket to a page that
receives every picture it is sent), in alternating windows (the shared machine's load drifts over both),
with the denoiser off and with svgf; and, with svgf, the time from a camera move to the first picture
that shows it.

    python -m bench.timing.viewer_overhead [--rounds 6] [--seconds 1.5] [--width 320 --height 180] [--device DEVICE]
    python -m bench.timing.viewer_overhead --screenshot docs/viewer/viewer.png   # the page in headless Chromium

``--screenshot`` takes a picture of the page instead (playwright and Debian's /usr/bin/chromium): the
viewer at 320x180 with the denoiser, after two seconds of a slow orbit.
"""
from __future__ import annotations

import argparse
import asyncio
import copy
import json
import statistics
import time

import pyclpt
from pyclpt.viewer.server import Viewer
from pyclpt.viewer.session import RenderSession


def without_viewer(pr: pyclpt.ProgressiveRenderer, seconds: float) -> float:
    """Frames per second of ``pr.step(1)`` in a loop for ``seconds``."""
    pr.image()
    frames, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        frames += pr.step(1)
    pr.image()  # waits for the device to finish
    return frames / (time.perf_counter() - start)


async def with_viewer(viewer: Viewer, seconds: float, moves: int) -> tuple[float, float, list[float]]:
    """A page connected for ``seconds``: (frames rendered per second, pictures it received per second,
    the times from each of ``moves`` camera moves sent to the first picture that shows it)."""
    import aiohttp

    session = viewer.session
    async with aiohttp.ClientSession() as http, http.ws_connect(viewer.url + "ws") as ws:
        async def pictures(count: int) -> dict:
            """The status of the count-th next picture."""
            status: dict = {}
            async for msg in ws:
                if msg.type == aiohttp.WSMsgType.TEXT:
                    status = json.loads(msg.data)
                elif msg.type == aiohttp.WSMsgType.BINARY:
                    count -= 1
                    if count <= 0:
                        return status
            raise ConnectionError("the viewer closed the connection")

        await pictures(2)  # the session wakes up from idling
        start, first, received = time.perf_counter(), session.pr.frame_index, 0
        while time.perf_counter() - start < seconds:
            await pictures(1)
            received += 1
        elapsed = time.perf_counter() - start
        rates = (session.pr.frame_index - first) / elapsed, received / elapsed
        lags = []
        for _ in range(moves):
            before = (await pictures(1))["reprojections"]
            sent = time.perf_counter()
            await ws.send_json({"type": "camera", "op": "orbit", "yaw": 2.0, "pitch": 0.0})
            while (await pictures(1))["reprojections"] <= before:  # a picture's status is the one it was made with
                pass
            lags.append(time.perf_counter() - sent)
    return rates[0], rates[1], lags


def measure(scene, width: int, height: int, denoiser: str | None, seconds: float, rounds: int, device) -> dict:
    """Rounds of a window without the viewer then one with it (the viewer idles while no page is connected),
    so that the load of a shared machine drifts over both; medians over the rounds."""
    pr = pyclpt.ProgressiveRenderer(copy.deepcopy(scene), width=width, height=height, denoiser=denoiser,
                                    device=device)
    pr.step(2)  # warm-up
    session = RenderSession(copy.deepcopy(scene), width=width, height=height, denoiser=denoiser or "off",
                            device=device, idle_after=0.05)
    viewer = Viewer(session).start()
    base, viewed, shown, lags = [], [], [], []
    try:
        for _ in range(rounds):
            time.sleep(0.2)  # the viewer has paused
            base.append(without_viewer(pr, seconds))
            rendered, pictures, lag = asyncio.run(with_viewer(viewer, seconds, 3 if denoiser else 0))
            viewed.append(rendered)
            shown.append(pictures)
            lags += lag
    finally:
        viewer.close()
    med = statistics.median
    return {"base": med(base), "viewed": med(viewed), "shown": med(shown),
            "overhead": 1 - med([v / b for v, b in zip(viewed, base)]), "lag": med(lags) if lags else None,
            "base_range": (min(base), max(base))}


def screenshot(scene, path: str, device) -> None:
    from playwright.sync_api import sync_playwright

    session = RenderSession(copy.deepcopy(scene), width=320, height=180, denoiser="svgf", device=device)
    viewer = Viewer(session).start()
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=["--no-sandbox"])
            page = browser.new_page(viewport={"width": 1000, "height": 520})
            page.goto(viewer.url)
            page.wait_for_function("Number(document.getElementById('frame').dataset.frame || 0) > 2")
            for _ in range(10):  # a slow orbit: the denoiser keeps its history across the moves
                session.move("orbit", yaw=-1.5, pitch=0.5)
                page.wait_for_timeout(100)
            page.wait_for_timeout(1000)
            page.screenshot(path=path)
            browser.close()
    finally:
        viewer.close()
    print(f"wrote {path}")


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default="cornell-box")
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=180)
    p.add_argument("--seconds", type=float, default=1.5, help="each window's length")
    p.add_argument("--rounds", type=int, default=6, help="pairs of windows without and with the viewer")
    p.add_argument("--device", default=None)
    p.add_argument("--screenshot", default=None, metavar="PNG", help="take a picture of the page instead")
    a = p.parse_args(argv)
    scene = pyclpt.load(a.scene)
    device = pyclpt.get_device(a.device) if a.device else pyclpt.default_device()
    if a.screenshot:
        return screenshot(scene, a.screenshot, device)
    print(f"{a.scene} {a.width}x{a.height} on {device.name.strip()}: {a.rounds} rounds of {a.seconds:g} s without "
          f"and {a.seconds:g} s with the viewer (medians)")
    print("| denoiser | without the viewer (fps) | with the viewer: rendered (fps) | pictures shown (fps) "
          "| overhead (median of the rounds' ratios) | camera move to its first picture |")
    print("| --- | --- | --- | --- | --- | --- |")
    for denoiser in (None, "svgf"):
        m = measure(scene, a.width, a.height, denoiser, a.seconds, a.rounds, device)
        lag = "–" if m["lag"] is None else f"{m['lag'] * 1e3:.0f} ms = {m['lag'] * m['viewed']:.1f} frames"
        lo, hi = m["base_range"]
        print(f"| {denoiser or 'off'} | {m['base']:.1f} ({lo:.0f} to {hi:.0f}) | {m['viewed']:.1f} | {m['shown']:.1f} "
              f"| {100 * m['overhead']:.0f} % | {lag} |", flush=True)


if __name__ == "__main__":
    main()
