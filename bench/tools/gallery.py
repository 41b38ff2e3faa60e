"""Render the gallery of docs/gallery.md: every shared scene (Mitsuba XML) at a modest size.

    python -m bench.tools.gallery [--width 384] [--spp 64] [--max-depth 8] [--out docs/gallery]

Writes one JPEG per scene (sRGB, small) and prints the markdown table (scene, resolution,
spp, depth, load / compile / render seconds) that docs/gallery.md shows.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

SCENES = {
    "cornell-box": "Cornell Box, Benedikt Bitterli (CC0)",
    "staircase2": "Modern Hall, NewSee2l035 (CC-BY 3.0)",
    "living-room": "Grey & White Room, Wig42 (CC-BY 3.0)",
    "staircase": "Wooden Staircase, Wig42 (CC-BY 3.0)",
    "classroom": "Classroom, NovaZeeke (CC-BY 3.0)",
}


def main(argv: list[str] | None = None) -> int:
    import pyclpt
    from pyclpt.scene.library import scenes_root

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="*", default=list(SCENES))
    p.add_argument("--width", type=int, default=384, help="longer image side in pixels")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--integrator", default="megakernel")
    p.add_argument("--out", type=Path, default=Path("docs/gallery"))
    a = p.parse_args(argv)
    root = scenes_root()
    if root is None:
        print("the shared scene folder was not found (PYCLPT_SCENES)", file=sys.stderr)
        return 1
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in a.scenes:
        t0 = time.perf_counter()
        scene = pyclpt.load(root / name / "scene.xml")  # what it does not support: one logged line
        load_s = time.perf_counter() - t0
        fw, fh = scene.film.width, scene.film.height
        scale = a.width / max(fw, fh)
        w, h = max(1, round(fw * scale)), max(1, round(fh * scale))
        r = pyclpt.Renderer(scene, integrator=a.integrator, max_depth=a.max_depth, width=w, height=h)
        image = r.render(a.spp, seed=0, progress=True)
        out = a.out / f"{name}.jpg"
        pyclpt.write_image(out, image)
        st = r.stats
        rows.append(f"| ![{name}](gallery/{out.name}) | {name} | {SCENES.get(name, '')} | {scene.triangle_count:,} "
                    f"| {w}x{h} | {a.spp} | {a.max_depth} | {load_s:.1f} | {st.setup_seconds:.1f} "
                    f"| {st.compile_seconds:.1f} | {st.seconds:.1f} |")
        print(rows[-1], flush=True)
    print()
    print("| image | scene | author (licence) | triangles | resolution | spp | max depth | load s | BVH+upload s "
          "| compile s | render s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
