"""The front door as a user meets it: Ctrl-C on a running ``pyclpt render`` (a real SIGINT to a real
process), ``python -m pyclpt``, library calls that print nothing unless asked, and the frame loops
that wait for the device often enough for Ctrl-C to stop them."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import pyclpt
from pyclpt.rendering import frame_loop
from pyclpt.rendering.frame_loop import FramePacer, progress_bar

REPO = Path(__file__).resolve().parent.parent
SIZE = {"width": 16, "height": 16}


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    return env


def _sigint_default() -> None:
    # A child of a non-interactive shell may inherit SIGINT ignored; a user's terminal delivers it.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


# -- Ctrl-C ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("quiet", [True, False], ids=["quiet", "progress-bar"])
def test_sigint_stops_a_long_render_with_one_line(tmp_path, quiet):
    out = tmp_path / "x.png"
    cmd = [sys.executable, "-m", "pyclpt", "-v", "render", "cornell-box", "--spp", "100000", "--width", "64",
           "--height", "64", "-o", str(out)] + (["--quiet"] if quiet else [])
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(),
                            preexec_fn=_sigint_default)
    try:
        seen = []
        for line in proc.stderr:  # -v logs "rendering N frame(s) ..." just before the first frame
            seen.append(line)
            if "pyclpt: rendering 100000 frame(s)" in line:
                break
        else:
            pytest.fail(f"the render did not start: {''.join(seen)}")
        time.sleep(0.5)  # frames are running
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)  # 100000 frames would take many minutes
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    assert stderr.rstrip("\n").splitlines()[-1].split("\r")[-1] == "pyclpt: interrupted; nothing written"
    assert stdout == ""
    assert list(tmp_path.iterdir()) == []


# -- python -m pyclpt --------------------------------------------------------------------------------
def test_python_m_pyclpt():
    proc = subprocess.run([sys.executable, "-m", "pyclpt", "--version"], capture_output=True, text=True,
                          timeout=120, env=_env())
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == f"pyclpt {pyclpt.__version__}\n"
    proc = subprocess.run([sys.executable, "-m", "pyclpt", "scenes"], capture_output=True, text=True, timeout=120,
                          env=_env())
    assert proc.returncode == 0, proc.stderr
    assert "cornell-box" in proc.stdout


# -- library calls show no progress bar unless asked -------------------------------------------------
def test_library_calls_print_nothing_unless_asked(device, cornell_box, capfd, monkeypatch):
    monkeypatch.setattr(frame_loop, "PROGRESS_DELAY_S", 0.0)  # as if every render were long
    pyclpt.render(cornell_box, spp=2, device=device, **SIZE)
    pyclpt.Renderer(cornell_box, device=device, **SIZE).render(2)
    pr = pyclpt.ProgressiveRenderer(cornell_box, device=device, **SIZE)
    pr.run(2)
    pr.step(2)
    assert capfd.readouterr().err == ""
    pyclpt.render(cornell_box, spp=2, device=device, progress=True, **SIZE)
    assert "cornell-box megakernel" in capfd.readouterr().err


def test_progress_bar_only_when_asked():
    assert progress_bar(3, "x", "spp", None).disable
    assert progress_bar(3, "x", "spp", False).disable
    with progress_bar(3, "x", "spp", True) as bar:
        assert not bar.disable
        assert bar.delay == frame_loop.PROGRESS_DELAY_S > 0  # short renders stay clean


# -- pacing: the frame loops wait for the device ------------------------------------------------------
class _Queue:
    """A queue whose frames take ``frame_s`` of (simulated) device time each."""

    def __init__(self, frame_s: float) -> None:
        self.frame_s = frame_s
        self.finishes = 0

    def finish(self) -> None:
        self.finishes += 1


def test_pacer_waits_about_every_target_seconds(monkeypatch):
    clock = [0.0]
    monkeypatch.setattr(frame_loop.time, "perf_counter", lambda: clock[0])
    pacer = FramePacer(target_seconds=0.25, max_batch=256)
    queue = _Queue(0.01)
    done = 0
    batches = []
    for _ in range(1000):
        clock[0] += queue.frame_s  # the wait for a frame costs its device time
        n = pacer.frame(queue)
        if n:
            batches.append(n)
        done += n
    done += pacer.wait(queue)
    assert done == 1000
    assert batches[:5] == [1, 2, 4, 8, 16]  # grows from one frame, at most doubling
    assert max(batches) == 25  # then about 0.25 s of frames between waits, never more
    assert queue.finishes == len(batches) + 1


def test_pacer_batch_is_capped_and_shrinks_when_frames_slow_down(monkeypatch):
    clock = [0.0]
    monkeypatch.setattr(frame_loop.time, "perf_counter", lambda: clock[0])
    pacer, queue = FramePacer(target_seconds=0.25, max_batch=64), _Queue(1e-6)
    for _ in range(500):
        clock[0] += queue.frame_s
        pacer.frame(queue)
    assert pacer.batch == 64
    queue.frame_s = 1.0  # a frame now takes a second: wait after every one
    for _ in range(64):
        clock[0] += queue.frame_s
        pacer.frame(queue)
    assert pacer.batch == 1


class _SpyPacer(FramePacer):
    def __init__(self) -> None:
        super().__init__()
        self.waits = 0

    def wait(self, queue) -> int:
        self.waits += 1
        return super().wait(queue)


@pytest.mark.parametrize("progress", [None, False, True])
def test_render_loops_wait_for_the_device(device, cornell_box, progress):
    """Without waits a quiet render queued every frame and ignored Ctrl-C until all had run; waiting
    changes no pixel."""
    r = pyclpt.Renderer(cornell_box, device=device, max_depth=2, **SIZE)
    reference = r.render(8, seed=4, progress=False)
    r.pacer = spy = _SpyPacer()
    assert np.array_equal(r.render(8, seed=4, progress=progress), reference)
    assert spy.waits >= 1
    pr = pyclpt.ProgressiveRenderer(cornell_box, device=device, max_depth=2, seed=4, **SIZE)
    pr.renderer.pacer = spy = _SpyPacer()
    assert np.array_equal(pr.run(8, progress=progress), reference)
    assert spy.waits >= 1
    pr.reset()
    pr.renderer.pacer = spy = _SpyPacer()
    assert pr.step(8) == 8 and spy.waits >= 1
    assert np.array_equal(pr.image(), reference)
