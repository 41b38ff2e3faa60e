"""What the frame loops of :class:`~pyclpt.rendering.renderer.Renderer` and
:class:`~pyclpt.rendering.progressive.ProgressiveRenderer` share: pacing the frames they enqueue,
and their progress bar.

Pacing: enqueueing a frame returns at once, so a loop that never waits could queue every frame
of a long render and then block in one OpenCL call until all of them ran; Python delivers Ctrl-C
(KeyboardInterrupt) only between bytecodes, never inside that call, so the render could not be
stopped. :class:`FramePacer` waits for the queue (``finish``) every ``batch`` frames, with
``batch`` adapted to the measured frame time so that about ``target_seconds`` of work is queued
at most: Ctrl-C stops a render within about that much plus one frame, and a fast device still
gets long runs of frames without a host round trip. Waiting changes no result.
"""
from __future__ import annotations

import time
from typing import Any

from tqdm.auto import tqdm

# A bar appears only after this many seconds, so short renders stay clean.
PROGRESS_DELAY_S = 2.0


class FramePacer:
    """Counts the frames enqueued on a queue and waits for it every ``batch`` of them."""

    def __init__(self, target_seconds: float = 0.25, max_batch: int = 256) -> None:
        self.target_seconds = float(target_seconds)
        self.max_batch = int(max_batch)
        self.batch = 1  # frames between waits: grows (at most doubling) to about target_seconds of work
        self.pending = 0  # frames enqueued since the last wait
        self._since = time.perf_counter()

    def frame(self, queue: Any, count: int = 1) -> int:
        """Call after enqueueing ``count`` frames on ``queue``. Waits for the queue when ``batch`` frames
        are pending; returns how many frames that wait completed (0 when it did not wait)."""
        self.pending += count
        return self.wait(queue) if self.pending >= self.batch else 0

    def wait(self, queue: Any) -> int:
        """Wait for every frame enqueued so far (``queue.finish()``); returns how many there were."""
        queue.finish()
        now = time.perf_counter()
        done, elapsed = self.pending, now - self._since
        if done:
            fit = int(self.target_seconds * done / elapsed) if elapsed > 0 else self.max_batch
            self.batch = max(1, min(fit, 2 * self.batch, self.max_batch))
        self.pending, self._since = 0, now
        return done


def progress_bar(total: int, desc: str, unit: str, progress: bool | None) -> tqdm:
    """The frame loops' bar (on stderr): shown only when ``progress`` is true, and then only once a
    render has run for PROGRESS_DELAY_S; ``None`` and False show none."""
    return tqdm(total=int(total), desc=desc, unit=unit, disable=not progress, delay=PROGRESS_DELAY_S, leave=False)
