"""Two source trees, one scene: how much faster is the new one? Ratios in one run (docs/benchmarks.md, "The living
room's environment": 1.43x there).

    python -m bench.studies.trees_ab OLD NEW [--scene living-room] [--method megakernel] [--size 128]
        [--spp 16] [--depth 8] [--rounds 7] [--device intel]

OLD and NEW are checkouts of pyclpt (``git worktree add /tmp/old <rev>``, or the working tree itself). Each side
runs in a process of its own that imports that tree's pyclpt, builds its renderer and renders one warm-up sample
(compile and first launches excluded); then the two render ``--spp`` samples in alternation, the order swapped
every round, so that the load of a shared machine falls on both alike. Printed: each side's median seconds and
old / new, the speedup, with the machine's CPU model. ``--scene``: a shared scene folder (``living-room``), a
scene file or a built-in scene (``builtin/cornell-box``, as ``pyclpt bench --versus`` names them); the box
filter, as that sets it.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

METHODS = {"megakernel": ("megakernel", "soa"), "wavefront-soa": ("wavefront", "soa"),
           "wavefront-aos": ("wavefront", "aos")}


#: A side's program: python -c puts its working folder, the tree, first on the module path, so that
#: ``import pyclpt`` there is that tree's; it then runs this file's _serve.
SIDE = "import runpy, sys; runpy.run_path(sys.argv[1], run_name='trees_ab_side')"


def _serve(scene_spec: str, method: str, size: int, spp: int, depth: int, device: str | None) -> None:
    """One side: the working folder's pyclpt renders ``spp`` samples for each seed read from stdin, answering the
    seconds."""
    import pyclpt

    scene = pyclpt.load(scene_spec)  # a built-in scene's name or a scene file's absolute path (scene_file)
    scene.film.rfilter = pyclpt.ReconstructionFilter("box")
    integrator, layout = METHODS[method]
    r = pyclpt.Renderer(scene, integrator=integrator, layout=layout, max_depth=depth, width=size, height=size,
                        device=device)
    r.render(1, seed=0, progress=False)
    print(json.dumps({"ready": pyclpt.__file__}), flush=True)
    for line in sys.stdin:
        t = time.perf_counter()
        r.render(spp, seed=int(line), progress=False)
        r.device.queue.finish()
        print(json.dumps({"seconds": time.perf_counter() - t}), flush=True)


def scene_file(spec: str) -> str:
    """What a side loads for ``--scene`` (resolved here, as the sides run in the trees' folders): a built-in
    scene's name, else a scene file's absolute path (a shared scene folder's scene.xml, or the file given)."""
    from pyclpt.scene.library import scenes_root

    if spec.startswith("builtin/"):
        return spec.removeprefix("builtin/")  # an unknown name: the side's load lists the built-in ones
    root = scenes_root()
    if root is not None and (root / spec / "scene.xml").is_file():
        return str((root / spec / "scene.xml").resolve())
    if Path(spec).is_file():
        return str(Path(spec).resolve())
    raise SystemExit(f"--scene {spec}: neither builtin/NAME, a shared scene folder nor a scene file")


class Side:
    """A serving process of one tree."""

    def __init__(self, tree: Path, a: argparse.Namespace) -> None:
        cmd = [sys.executable, "-c", SIDE, str(Path(__file__).resolve()), scene_file(a.scene), a.method, str(a.size),
               str(a.spp), str(a.depth), a.device or ""]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=tree)
        ready = self._answer()
        self.module = ready["ready"]
        if not Path(self.module).resolve().is_relative_to(tree.resolve()):
            raise SystemExit(f"{tree}: the side imported pyclpt from {self.module}, not from this tree")

    def _answer(self) -> dict:
        line = self.proc.stdout.readline() if self.proc.stdout else ""
        if not line:
            raise SystemExit(f"a side stopped (exit status {self.proc.wait()}); its error is above")
        return json.loads(line)

    def render(self, seed: int) -> float:
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"{seed}\n")
        self.proc.stdin.flush()
        return float(self._answer()["seconds"])

    def close(self) -> None:
        if self.proc.stdin:
            self.proc.stdin.close()
        self.proc.wait()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--scene", default="living-room")
    ap.add_argument("--method", choices=tuple(METHODS), default="megakernel")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--depth", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--device", default=None)
    a = ap.parse_args(argv)
    for tree in (a.old, a.new):
        if not (tree / "pyclpt" / "__init__.py").is_file():
            ap.error(f"{tree}: not a pyclpt checkout (no pyclpt/__init__.py)")
    from bench.report.machine import cpu_model

    sides = {"old": Side(a.old, a), "new": Side(a.new, a)}
    times: dict[str, list[float]] = {"old": [], "new": []}
    try:
        for i in range(a.rounds):
            for name in ("old", "new") if i % 2 == 0 else ("new", "old"):
                times[name].append(sides[name].render(1 + i))
    finally:
        for side in sides.values():
            side.close()
    old, new = statistics.median(times["old"]), statistics.median(times["new"])
    print(f"{a.scene}, {a.method}, {a.size}x{a.size}, {a.spp} spp, depth {a.depth}, {a.rounds} rounds on "
          f"{cpu_model()}: old {old:.3f} s, new {new:.3f} s, speedup {old / new:.3f}x")
    return 0


if __name__ == "trees_ab_side":
    _scene, _method, _size, _spp, _depth, _device = sys.argv[2:8]
    _serve(_scene, _method, int(_size), int(_spp), int(_depth), _device or None)
elif __name__ == "__main__":
    raise SystemExit(main())
