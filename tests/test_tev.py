"""Streaming to tev (``pyclpt render --tev HOST:PORT``, pyclpt.viewer.tev) against a fake tev: a TCP server
in a thread that speaks tev's IPC protocol as tevclient sends it (a packet: its length as a little-endian
uint32, counting itself, then its type byte) and records the images created and the tiles of pixels
updated. The image tev ends up with must be the image written, pixel for pixel."""
from __future__ import annotations

import socket
import struct
import sys
import threading
import time

import numpy as np
import pytest

import pyclpt
from pyclpt.viewer.tev import DEFAULT_PORT, TevStream, parse_address

pytest.importorskip("tevclient", reason="the tev extra (tevclient) is not installed: pip install \"pyclpt[tev]\"")

CREATE_IMAGE, UPDATE_IMAGE = 4, 6  # tev's IpcPacket::EType (tevclient.packet.IpcPacketType)


def _string(data: bytes, pos: int) -> tuple[str, int]:
    end = data.index(b"\0", pos)
    return data[pos:end].decode(), end + 1


def parse_packet(data: bytes) -> dict:
    """One packet (without its length) as a dict: create_image / update_image with their fields, or its type."""
    kind, pos = data[0], 1
    if kind == CREATE_IMAGE:
        grab_focus = bool(data[pos])
        name, pos = _string(data, pos + 1)
        width, height, n = struct.unpack_from("<iii", data, pos)
        pos += 12
        channels = []
        for _ in range(n):
            channel, pos = _string(data, pos)
            channels.append(channel)
        return {"type": "create", "name": name, "width": width, "height": height, "channels": channels,
                "grab_focus": grab_focus}
    if kind == UPDATE_IMAGE:
        name, pos = _string(data, pos + 1)
        (n,) = struct.unpack_from("<i", data, pos)
        pos += 4
        channels = []
        for _ in range(n):
            channel, pos = _string(data, pos)
            channels.append(channel)
        x, y, w, h = struct.unpack_from("<iiii", data, pos)
        pos += 16
        offsets = struct.unpack_from(f"<{n}q", data, pos)
        strides = struct.unpack_from(f"<{n}q", data, pos + 8 * n)
        pos += 16 * n
        pixels = np.frombuffer(data, "<f4", count=w * h * n, offset=pos)
        tile = np.stack([pixels[offsets[c]::strides[c]][: w * h] for c in range(n)], axis=-1).reshape(h, w, n)
        return {"type": "update", "name": name, "channels": channels, "x": x, "y": y, "tile": tile}
    return {"type": kind}


class FakeTev:
    """A TCP server on 127.0.0.1 (a free port) that records every packet of every connection."""

    def __init__(self) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.packets: list[dict] = []
        self.connections = 0
        self._threads: list[threading.Thread] = []
        self._accept = threading.Thread(target=self._serve, daemon=True)
        self._accept.start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.server.accept()
            except OSError:  # closed
                return
            self.connections += 1
            t = threading.Thread(target=self._read, args=(conn,), daemon=True)
            t.start()
            self._threads.append(t)

    def _read(self, conn: socket.socket) -> None:
        buffer = b""
        with conn:
            while True:
                chunk = conn.recv(1 << 16)
                if not chunk:
                    return
                buffer += chunk
                while len(buffer) >= 4:
                    (length,) = struct.unpack_from("<I", buffer)
                    if len(buffer) < length:
                        break
                    self.packets.append(parse_packet(buffer[4:length]))
                    buffer = buffer[length:]

    def wait(self, connections: int = 1, timeout: float = 30.0) -> None:
        """Until ``connections`` clients have connected and closed their connections: every packet read."""
        deadline = time.monotonic() + timeout
        while len(self._threads) < connections and time.monotonic() < deadline:
            time.sleep(0.01)
        for t in list(self._threads):
            t.join(max(deadline - time.monotonic(), 0.01))

    def close(self) -> None:
        self.server.close()

    def image(self, name: str) -> np.ndarray:
        """The image as tev would show it: created by the last create packet, then every update applied."""
        creates = [k for k, p in enumerate(self.packets) if p["type"] == "create" and p["name"] == name]
        assert creates, f"no image {name!r} created: {[p['type'] for p in self.packets]}"
        first = creates[-1]
        create = self.packets[first]
        image = np.full((create["height"], create["width"], len(create["channels"])), np.nan, np.float32)
        for p in self.packets[first + 1:]:
            if p["type"] == "update" and p["name"] == name:
                assert p["channels"] == create["channels"][: p["tile"].shape[2]]
                h, w = p["tile"].shape[:2]
                image[p["y"]:p["y"] + h, p["x"]:p["x"] + w] = p["tile"]
        return image


@pytest.fixture
def tev():
    server = FakeTev()
    yield server
    server.close()


def test_render_streams_the_image_to_tev(tev, tmp_path, capsys):
    from pyclpt.cli import main

    out = tmp_path / "box.exr"
    assert main(["render", "cornell-box", "--spp", "4", "--width", "40", "--height", "24", "-o", str(out), "--quiet",
                 "--tev", f"127.0.0.1:{tev.port}"]) == 0
    tev.wait()
    stdout = capsys.readouterr().out
    assert f"to tev at 127.0.0.1:{tev.port} as 'box.exr'" in stdout
    creates = [p for p in tev.packets if p["type"] == "create"]
    updates = [p for p in tev.packets if p["type"] == "update"]
    assert tev.connections == 1 and len(creates) == 1 and updates, [p["type"] for p in tev.packets]
    assert creates[0] == {"type": "create", "name": "box.exr", "width": 40, "height": 24,
                          "channels": ["R", "G", "B"], "grab_focus": True}
    shown = tev.image("box.exr")
    written = pyclpt.read_image(out)
    assert shown.shape == written.shape == (24, 40, 3)
    assert not np.isnan(shown).any()  # every pixel was sent
    np.testing.assert_allclose(shown, written, rtol=1e-3, atol=1e-4)  # the last image sent is the one written
    assert shown.mean() > 0.01


def test_a_large_image_is_sent_in_tiles(tev):
    """tevclient splits an image into tiles of 128 x 128: they add up to the image."""
    rng = np.random.default_rng(5)
    image = rng.random((150, 300, 3), np.float32)
    with TevStream(f"127.0.0.1:{tev.port}", "tiles") as stream:
        assert stream.send(image)
        assert not stream.send(image)  # within the interval: not sent
        assert stream.send(image * 2, force=True)
    tev.wait()
    assert sum(p["type"] == "update" for p in tev.packets) == 2 * 6
    np.testing.assert_array_equal(tev.image("tiles"), image * 2)


def test_no_tev_listening_is_one_line(tmp_path, capsys):
    from pyclpt.cli import main

    with socket.create_server(("127.0.0.1", 0)) as s:
        port = s.getsockname()[1]  # free once closed: nothing listens there
    assert main(["render", "cornell-box", "--spp", "1", "--width", "8", "--height", "8", "-o",
                 str(tmp_path / "x.png"), "--quiet", "--tev", f"127.0.0.1:{port}"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("pyclpt: error: no tev listens at 127.0.0.1:") and "Traceback" not in err
    assert not (tmp_path / "x.png").exists()


def test_without_tevclient_the_extra_is_named(monkeypatch, tmp_path, capsys):
    from pyclpt.cli import main

    monkeypatch.setitem(sys.modules, "tevclient", None)  # import tevclient raises ImportError
    assert main(["render", "cornell-box", "--spp", "1", "-o", str(tmp_path / "x.png"), "--tev"]) == 1
    assert 'pip install "pyclpt[tev]"' in capsys.readouterr().err


def test_a_tev_that_goes_away_stops_the_stream(tev, caplog):
    stream = TevStream(f"127.0.0.1:{tev.port}", "gone")

    class Broken:
        def create_image(self, *args, **kwargs):
            raise BrokenPipeError(32, "Broken pipe")

        def __exit__(self, *exc):
            pass

    stream._ipc = Broken()
    assert not stream.send(np.zeros((4, 4, 3), np.float32), force=True)
    assert stream.failed and "went away" in caplog.text and not stream.due()
    stream.close()


def test_parse_address():
    assert parse_address("localhost:1234") == ("localhost", 1234)
    assert parse_address("tev-host") == ("tev-host", DEFAULT_PORT)
    assert parse_address(":999") == ("127.0.0.1", 999)
    assert parse_address("[::1]:14000") == ("::1", 14000)
    for bad in ("host:port", "host:0", "host:70000", "[::1"):
        with pytest.raises(ValueError, match="tev address"):
            parse_address(bad)
