"""``pyclpt bench --versus mitsuba``: pyclpt and Mitsuba 3 (``llvm_ad_rgb``) on the same scene files.

    pyclpt bench --versus mitsuba [--mitsuba-python PATH] [-o bench-versus] [--scenes ...]
                 [--resolution 128x128] [--spp 16] [--depths 8 65] [--repeats 3] [--quick]

pyclpt renders in this process (``pyclpt.Renderer``: megakernel and wavefront SoA); Mitsuba in a
subprocess of the Python of its own environment (``--mitsuba-python``, else ``$PYCLPT_MITSUBA_PYTHON``),
which runs ``bench/mitsuba_driver.py`` and answers one render per request. Both sides render the
same file with the same spp, max depth, resolution, a box reconstruction filter and Russian
roulette from bounce 3 (the driver's docstring says how Mitsuba's scene is edited). Compilation is
excluded on both sides (pyclpt when the renderer is made, Mitsuba by a warm-up render); then
``--repeats`` rounds alternate one render of every pyclpt integrator and one of Mitsuba, rotating
the order. Reported: median seconds, Msamples/s (pixels x spp / s), pyclpt / Mitsuba and the image
means per channel side by side with their relative difference. Written: ``versus.md`` and
``versus.json`` in the output folder.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from pyclpt.common import env

DRIVER = Path(__file__).resolve().parent / "mitsuba_driver.py"
SHARED = ["cornell-box", "classroom", "living-room", "staircase", "staircase2"]
DEFAULTS = {"scenes": ["builtin/cornell-box", *SHARED], "resolution": "128x128", "spp": 16, "depths": [8, 65],
            "cornell_resolution": "256x256", "cornell_spp": 64, "cornell_depth": 8, "repeats": 3,
            "methods": ["megakernel", "wavefront-soa"], "rr_depth": 3}
QUICK = {"resolution": "32x32", "spp": 2, "depths": [8], "cornell_resolution": "32x32", "cornell_spp": 2,
         "repeats": 1}


class MitsubaError(RuntimeError):
    """The Mitsuba side could not be started or failed (the message names the option and variable)."""


def build_parser() -> argparse.ArgumentParser:
    from .report import _positive, _resolution

    p = argparse.ArgumentParser(prog="pyclpt bench --versus mitsuba",
                                description="pyclpt against Mitsuba 3 llvm_ad_rgb on the same scene files "
                                "(docs/benchmarks.md, 'Versus Mitsuba 3').")
    p.add_argument("--versus", choices=("mitsuba",), required=True)
    p.add_argument("--mitsuba-python", default=None, metavar="PATH",
                   help="the python of an environment with mitsuba installed (default $PYCLPT_MITSUBA_PYTHON)")
    p.add_argument("-o", "--output", default="bench-versus", help="report folder (default bench-versus)")
    p.add_argument("--quick", action="store_true", help="tiny images, 2 spp, depth 8, one repeat")
    p.add_argument("--scenes", nargs="+", default=None,
                   help="builtin/cornell-box (pyclpt's built-in scene, JSON) and shared scene folders "
                        f"({', '.join(SHARED)}) or .xml/.json files")
    p.add_argument("--resolution", type=_resolution, default=None, help="WIDTHxHEIGHT of the shared scenes")
    p.add_argument("--spp", type=_positive, default=None, help="samples per pixel of the shared scenes")
    p.add_argument("--depths", nargs="+", type=_positive, default=None, help="max depths of the shared scenes")
    p.add_argument("--cornell-resolution", type=_resolution, default=None)
    p.add_argument("--cornell-spp", type=_positive, default=None)
    p.add_argument("--cornell-depth", type=_positive, default=None)
    p.add_argument("--repeats", type=_positive, default=None, help="timed rounds (medians over them)")
    p.add_argument("--methods", nargs="+", choices=("megakernel", "wavefront-aos", "wavefront-soa"), default=None)
    p.add_argument("--device", default=None, help="pyclpt's OpenCL device")
    return p


def mitsuba_python(option: str | None) -> str:
    """The Mitsuba environment's python: the option, else the variable; a clear error when neither works."""
    how = ("give --mitsuba-python PATH or set PYCLPT_MITSUBA_PYTHON to the python of a virtual environment "
           "with mitsuba installed (docs/benchmarks.md, 'Versus Mitsuba 3')")
    value = option or (str(env.path("PYCLPT_MITSUBA_PYTHON")) if env.get("PYCLPT_MITSUBA_PYTHON") else None)
    if not value:
        raise MitsubaError(f"no Mitsuba python: {how}")
    source = "--mitsuba-python" if option else "PYCLPT_MITSUBA_PYTHON"
    path = Path(value).expanduser()
    if not path.is_file() or not os.access(path, os.X_OK):
        raise MitsubaError(f"{source}={value!r}: not an executable file; {how}")
    return str(path)


def _json_in(line: str) -> object:
    """The JSON object on a driver's output line (after any colour codes Mitsuba's log left), else None."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", line)
    start = text.find("{")
    try:
        return json.loads(text[start:]) if start >= 0 else None
    except json.JSONDecodeError:
        return None


def probe(python: str) -> dict:
    """Check that ``python`` runs the driver with Mitsuba (its version and variant), else MitsubaError."""
    cmd = [python, str(DRIVER), "--probe"]
    try:
        done = subprocess.run(cmd, input="", capture_output=True, text=True, timeout=300)
    except (OSError, subprocess.SubprocessError) as exc:
        raise MitsubaError(f"cannot run the Mitsuba python {python!r} ({exc}); check --mitsuba-python / "
                           "PYCLPT_MITSUBA_PYTHON") from None
    for line in done.stdout.splitlines():
        msg = _json_in(line)
        if isinstance(msg, dict) and msg.get("event") == "ready":
            return msg
        if isinstance(msg, dict) and msg.get("event") == "error":
            break
    detail = (done.stdout.strip() + " " + done.stderr.strip()).strip()[-600:] or f"exit status {done.returncode}"
    raise MitsubaError(f"{shlex.join(cmd)} failed: {detail}; --mitsuba-python / PYCLPT_MITSUBA_PYTHON must be the "
                       "python of an environment with mitsuba 3 (and DRJIT_LIBLLVM_PATH set for its LLVM backend)")


def cases(s: dict) -> list[dict]:
    """(label, file, width, height, spp, depth) of every configuration asked for."""
    from pyclpt.scene.library import builtin_dir, scenes_root

    def wh(text: str) -> tuple[int, int]:
        w, h = (int(x) for x in text.split("x"))
        return w, h

    out = []
    root = scenes_root()
    for name in s["scenes"]:
        if name.startswith("builtin/"):
            path = builtin_dir() / f"{name.removeprefix('builtin/')}.json"
            w, h = wh(s["cornell_resolution"])
            out.append({"scene": name, "file": str(path), "width": w, "height": h, "spp": s["cornell_spp"],
                        "depth": s["cornell_depth"]})
            continue
        path = Path(name)
        if not path.suffix:
            if root is None:
                raise ValueError(f"{name}: the shared scene folder (PYCLPT_SCENES) was not found")
            path = root / name / "scene.xml"
        if not path.is_file():
            raise ValueError(f"{name}: {path} does not exist")
        w, h = wh(s["resolution"])
        for depth in s["depths"]:
            out.append({"scene": name, "file": str(path), "width": w, "height": h, "spp": s["spp"], "depth": depth})
    return out


class MitsubaSide:
    """The driver subprocess for one configuration: started (scene loaded, warm-up render done), then
    one render per :meth:`render`."""

    def __init__(self, python: str, case: dict, rr_depth: int) -> None:
        self.cmd = [python, str(DRIVER), "--scene", case["file"], "--spp", str(case["spp"]), "--max-depth",
                    str(case["depth"]), "--width", str(case["width"]), "--height", str(case["height"]),
                    "--rr-depth", str(rr_depth)]
        try:
            self.proc = subprocess.Popen(self.cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                         stderr=subprocess.PIPE, text=True, bufsize=1)
        except OSError as exc:
            raise MitsubaError(f"cannot run the Mitsuba python {python!r} ({exc}); check --mitsuba-python / "
                               "PYCLPT_MITSUBA_PYTHON") from None
        self.log: list[str] = []
        self.ready = self._answer("ready")

    def _answer(self, event: str) -> dict:
        msg, line = None, ""
        while self.proc.stdout:  # Mitsuba logs to stdout too: pass its lines on, up to the next JSON answer
            line = self.proc.stdout.readline()
            if not line:
                break
            msg = _json_in(line)
            if isinstance(msg, dict) and "event" in msg:
                break
            print(f"mitsuba: {line.rstrip()}", file=sys.stderr)
            self.log.append(line.rstrip())
        if not isinstance(msg, dict) or msg.get("event") != event:
            self.proc.kill()
            err = self.proc.stderr.read() if self.proc.stderr else ""
            detail = msg.get("message") if isinstance(msg, dict) and msg.get("event") == "error" else \
                (line.strip() or err.strip()[-600:] or f"exit status {self.proc.wait()}")
            raise MitsubaError(f"Mitsuba failed on {self.cmd[3]}: {detail}")
        return msg

    def render(self, seed: int) -> dict:
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"render {seed}\n")
        self.proc.stdin.flush()
        return self._answer("render")

    def close(self) -> None:
        try:
            if self.proc.stdin:
                self.proc.stdin.write("quit\n")
                self.proc.stdin.close()
            self.proc.wait(timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()


def _pyclpt_render(renderer, spp: int, seed: int) -> dict:
    t = time.perf_counter()
    image = renderer.render(spp, seed=seed, progress=False)
    renderer.device.queue.finish()
    seconds = time.perf_counter() - t
    return {"seconds": seconds, "mean": [float(x) for x in image.reshape(-1, image.shape[-1])[:, :3].mean(axis=0)]}


def measure(case: dict, s: dict, python: str, device) -> dict:
    """One configuration: pyclpt's renderers and Mitsuba warmed up, then alternating timed rounds."""
    import pyclpt

    from .runner import make_renderer

    scene = pyclpt.load(case["file"])
    scene.film.rfilter = pyclpt.ReconstructionFilter("box")  # as the driver makes Mitsuba's (the shared scenes: tent)
    renderers, info = {}, {}
    for m in s["methods"]:
        r = make_renderer(scene, m, case["depth"], case["width"], case["height"], device)
        r.render(1, seed=0, progress=False)  # warm-up (first launches)
        renderers[m] = r
        info[m] = {"compile_s": r.stats.compile_seconds, "setup_s": r.stats.setup_seconds}
    mitsuba = MitsubaSide(python, case, s["rr_depth"])
    names = [*s["methods"], "mitsuba"]
    runs: dict[str, list[dict]] = {n: [] for n in names}
    try:
        for i in range(s["repeats"]):
            k = i % len(names)
            for n in names[k:] + names[:k]:
                runs[n].append(mitsuba.render(1 + i) if n == "mitsuba" else
                               _pyclpt_render(renderers[n], case["spp"], 1 + i))
    finally:
        mitsuba.close()
    samples = case["width"] * case["height"] * case["spp"]
    out = dict(case, samples=samples, methods={})
    for n in names:
        secs = [r["seconds"] for r in runs[n]]
        med = statistics.median(secs)
        mean = [statistics.fmean(r["mean"][c] for r in runs[n]) for c in range(3)]
        out["methods"][n] = {"seconds": secs, "median_s": med, "msamples_per_s": samples / med / 1e6,
                             "mean": mean, **info.get(n, {})}
    out["mitsuba"] = {k: v for k, v in mitsuba.ready.items() if k != "event"}
    return out


# -- report -----------------------------------------------------------------------------------------
def _rel(a: float, b: float) -> float | None:
    """(a - b) / |b|; None when b is 0 (and a is not)."""
    if b == 0:
        return 0.0 if a == 0 else None
    return (a - b) / abs(b)


def rows(res: dict) -> list[list[str]]:
    from .report import _n

    table = []
    for c in res["cases"]:
        if "error" in c:
            table.append([c["scene"], str(c.get("depth", "-")), "-", "-", "-", "-", "-", "-", "-", c["error"]])
            continue
        ms = c["methods"]["mitsuba"]
        best = max((n for n in c["methods"] if n != "mitsuba"), key=lambda n: c["methods"][n]["msamples_per_s"])
        for n, m in c["methods"].items():
            if n == "mitsuba":
                continue
            ratio = m["msamples_per_s"] / ms["msamples_per_s"]
            rels = [_rel(m["mean"][k], ms["mean"][k]) for k in range(3)]
            diff = "Mitsuba's image is black" if None in rels else f"{100 * max(abs(r) for r in rels):.1f}%"
            table.append([c["scene"], str(c["depth"]), f"{c['width']}x{c['height']}, {c['spp']} spp",
                          n + (" (fastest)" if n == best else ""), _n(m["median_s"]), _n(ms["median_s"]),
                          _n(m["msamples_per_s"]), _n(ms["msamples_per_s"]), f"{ratio:.2f}x",
                          f"{' '.join(f'{x:.4f}' for x in m['mean'])} / "
                          f"{' '.join(f'{x:.4f}' for x in ms['mean'])} ({diff})"])
    return table


HEADER = ["scene", "depth", "setting", "pyclpt", "pyclpt s", "Mitsuba s", "pyclpt Msamples/s",
          "Mitsuba Msamples/s", "pyclpt / Mitsuba", "image mean RGB pyclpt / Mitsuba (max rel. diff.)"]


def to_markdown(res: dict) -> str:
    meta, st = res["meta"], res["settings"]
    lines = ["# pyclpt versus Mitsuba 3", "",
             f"- CPU: {meta['cpu']} ({meta['cores']} cores); load average at start {meta.get('load_average')}",
             f"- pyclpt device: {meta['device']}",
             f"- Mitsuba {meta.get('mitsuba_version')}, variant {meta.get('variant')}",
             f"- command: `{meta['command']}`",
             f"- {st['repeats']} alternating rounds per configuration (pyclpt integrators and Mitsuba, order "
             "rotating), medians; compile excluded on both sides; box filter, Russian roulette from bounce "
             f"{st['rr_depth']} on both sides; elapsed {meta.get('elapsed_s', 0):.0f} s",
             "- Msamples/s = width x height x spp / median seconds; the ratio > 1 means pyclpt is faster",
             "", "| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in rows(res)]
    return "\n".join(lines) + "\n"


def settings_from(a: argparse.Namespace) -> dict:
    s = dict(DEFAULTS)
    if a.quick:
        s.update(QUICK)
    for key in ("scenes", "resolution", "spp", "depths", "cornell_resolution", "cornell_spp", "cornell_depth",
                "repeats", "methods"):
        v = getattr(a, key)
        if v is not None:
            s[key] = v
    for key in ("resolution", "cornell_resolution"):
        if s[key] == "scene":
            raise ValueError(f"--{key.replace('_', '-')} needs WIDTHxHEIGHT here (both sides get the same)")
    return s


def main(argv: Sequence[str]) -> int:
    a = build_parser().parse_args(list(argv))
    try:
        import pyclpt

        from . import machine

        python = mitsuba_python(a.mitsuba_python)
        s = settings_from(a)
        version = probe(python)
        todo = cases(s)
        out_dir = Path(a.output)
        out_dir.mkdir(parents=True, exist_ok=True)
        device = pyclpt.get_device(a.device)
        t0 = time.perf_counter()
        res = {"settings": s, "meta": {"cpu": machine.cpu_model(), "cores": os.cpu_count(),
                                       "load_average": machine.load_average(),
                                       "device": str(device.describe().get("device", device)),
                                       "command": "pyclpt bench " + shlex.join(list(argv)),
                                       "mitsuba_version": version.get("mitsuba_version"),
                                       "variant": version.get("variant")},
               "cases": []}
        for case in todo:
            print(f"{case['scene']} depth {case['depth']} {case['width']}x{case['height']} {case['spp']} spp ...",
                  file=sys.stderr, flush=True)
            try:
                c = measure(case, s, python, device)
            except Exception as exc:  # noqa: BLE001 - a scene one side cannot render is a row, not the end
                from .scenes import reason

                c = dict(case, error=reason(exc))
            if "mitsuba" in c:
                res["meta"].update(mitsuba_version=c["mitsuba"].get("mitsuba_version"),
                                   variant=c["mitsuba"].get("variant"))
            res["cases"].append(c)
            res["meta"]["elapsed_s"] = time.perf_counter() - t0
            (out_dir / "versus.json").write_text(json.dumps(res, indent=1))
        res["meta"]["load_average_end"] = machine.load_average()
        (out_dir / "versus.json").write_text(json.dumps(res, indent=1))
        md = to_markdown(res)
        (out_dir / "versus.md").write_text(md)
        print(md)
        if not any("methods" in c for c in res["cases"]):
            print("pyclpt bench: error: nothing was measured (every configuration failed)", file=sys.stderr)
            return 1
        return 0
    except (OSError, ValueError, RuntimeError) as exc:
        print(f"pyclpt bench --versus mitsuba: error: {exc}", file=sys.stderr)
        return 1
