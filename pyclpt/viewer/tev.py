"""Streaming a render to `tev <https://github.com/Tom94/tev>`_, the HDR image viewer, over its IPC protocol
(TCP) through the PyPI package ``tevclient`` (the ``tev`` extra): ``pyclpt render SCENE --tev HOST:PORT``
shows the image in tev as it converges, linear (tev applies its own exposure and tonemap).

:class:`TevStream` connects when it is made (so a tev that is not running is said before the render
starts), creates the image in tev at the first :meth:`TevStream.send` (again when its size changes) and
sends the pixels, at most every ``interval`` seconds unless forced (the last image always is). A tev that
goes away during the render stops the stream with one warning; the render goes on.
"""
from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np

log = logging.getLogger("pyclpt.viewer")

#: How to install what streaming to tev needs.
TEV_HINT = 'pip install "pyclpt[tev]"'
#: The port tev listens on unless told otherwise (tev's --hostname HOST:PORT).
DEFAULT_PORT = 14158
DEFAULT_HOST = "127.0.0.1"
#: Seconds between two images sent during a render (the last one is always sent).
DEFAULT_INTERVAL = 0.25


def require_tevclient() -> Any:
    """The ``tevclient`` module; ImportError naming the ``tev`` extra where it is missing."""
    try:
        import tevclient
    except ImportError as exc:
        raise ImportError(f"streaming to tev uses the tevclient package, which is not installed here ({exc}): "
                          f"{TEV_HINT}") from None
    return tevclient


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT``, ``HOST`` (port 14158) or ``:PORT`` (host 127.0.0.1) as (host, port); ValueError
    otherwise. An IPv6 host goes in brackets: ``[::1]:14158``."""
    text = str(text).strip()
    host, port = text, str(DEFAULT_PORT)
    if text.startswith("["):  # [IPv6]:PORT
        close = text.find("]")
        if close < 0:
            raise ValueError(f"tev address {text!r}: no closing bracket after the IPv6 host")
        host, rest = text[1:close], text[close + 1:]
        if rest:
            if not rest.startswith(":"):
                raise ValueError(f"tev address {text!r}: expected [HOST]:PORT")
            port = rest[1:]
    elif text.count(":") == 1:
        host, port = text.split(":")
    host = host or DEFAULT_HOST
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"tev address {text!r}: the port must be a number in 1..65535 (HOST:PORT; tev listens "
                         f"on {DEFAULT_PORT} by default)")
    return host, int(port)


class TevStream:
    """Images sent to the tev listening at ``address`` (``HOST:PORT``) as the image ``name``, channels
    R, G, B, linear. OSError, saying what to do, when nothing listens there."""

    def __init__(self, address: str, name: str, *, interval: float = DEFAULT_INTERVAL,
                 grab_focus: bool = True) -> None:
        tevclient = require_tevclient()
        self.host, self.port = parse_address(address)
        self.name = str(name)
        self.interval = float(interval)
        self.grab_focus = bool(grab_focus)
        self.sent = 0  # images sent
        self.failed: str | None = None  # why the stream stopped (tev went away), None while it runs
        self._shape: tuple[int, int] | None = None
        self._last: float | None = None
        try:
            self._ipc = tevclient.Ipc(self.host, self.port).__enter__()
        except OSError as exc:
            raise OSError(f"no tev listens at {self.host}:{self.port} ({exc.strerror or exc}): start tev (it "
                          f"listens on port {DEFAULT_PORT}; `tev --hostname HOST:PORT` picks another) or give "
                          f"its address") from None

    def due(self) -> bool:
        """Whether :meth:`send` would send an image now (so that a caller reads one back only then)."""
        return self.failed is None and (self._last is None or time.monotonic() - self._last >= self.interval)

    def send(self, image: np.ndarray, force: bool = False) -> bool:
        """Send ``image`` ((H, W, 3) linear) unless one was sent less than ``interval`` seconds ago (``force``:
        send it anyway). True when it was sent."""
        if self.failed is not None:
            return False
        now = time.monotonic()
        if not force and self._last is not None and now - self._last < self.interval:
            return False
        img = np.ascontiguousarray(np.asarray(image, np.float32)[:, :, :3])
        h, w = img.shape[:2]
        try:
            if self._shape != (h, w):
                self._ipc.create_image(self.name, w, h, ["R", "G", "B"], grab_focus=self.grab_focus)
                self._shape = (h, w)
            self._ipc.update_image(self.name, img, ["R", "G", "B"])
        except OSError as exc:
            self.failed = str(exc) or type(exc).__name__
            log.warning("tev at %s:%d went away (%s): no more images are sent; the render goes on", self.host,
                        self.port, self.failed)
            return False
        self._last = time.monotonic()
        self.sent += 1
        return True

    def close(self) -> None:
        """Close the connection (the image stays open in tev)."""
        try:
            self._ipc.__exit__(None, None, None)
        except OSError:
            pass

    def __enter__(self) -> TevStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
