"""Mitsuba 3's side of ``pyclpt bench --versus mitsuba``: run by the Python of a separate Mitsuba
environment (never imported by pyclpt; imports only mitsuba and drjit).

    python mitsuba_driver.py --scene FILE --spp 64 --max-depth 8 --width 256 --height 256
                             [--rr-depth 3] [--variant llvm_ad_rgb] [--warmup 1] [--repeats N]

The scene is set up exactly as pyclpt renders it:

- a ``.json`` file is a Mitsuba 3 dictionary (pyclpt's built-in scenes): its ``to_world`` lists of
  operations (translate, rotate, scale, look_at, matrix, left to right as pyclpt composes them)
  become ``ScalarTransform4f`` and the dictionary goes to ``mi.load_dict``;
- an ``.xml`` file is edited before ``mi.load_string`` (relative paths resolve against its folder):
  every ``<integrator>`` becomes ``path`` with ``max_depth`` and ``rr_depth``; the sensor's film
  becomes an ``hdrfilm`` of ``--width`` x ``--height`` with a ``box`` reconstruction filter, its
  sampler ``independent`` with ``--spp`` samples.

The integrator is Mitsuba's ``path`` with ``--rr-depth`` (default 3, pyclpt's ``RR_DEPTH``:
Mitsuba's default is 5) so both sides do the same work per sample.

Protocol (one JSON object per line on stdout; Mitsuba's own log lines may come between them):
``--probe`` only imports Mitsuba and prints the ready line; after loading and ``--warmup`` untimed renders
(which include Dr.Jit's kernel compilation) it prints ``{"event": "ready", "mitsuba_version",
"variant", "load_s", "warmup_s": [...]}``. Without ``--repeats`` it then reads commands from
stdin: ``render SEED [NPY]`` answers ``{"event": "render", "seed", "seconds", "mean": [r, g, b]}``
(``seconds``: ``mi.render`` and evaluation of the image, the wall time a user waits; with ``NPY``
the image, (H, W, 3) float32, is then written to that .npy file, untimed), ``reference PASSES SEED
NPY`` renders ``PASSES`` passes of ``--spp`` samples (seeds SEED, SEED + 1, ...: the compiled
kernels are reused), writes their average to ``NPY`` and answers ``{"event": "reference",
"passes", "spp", "seconds", "mean"}`` (a converged image for ``pyclpt bench --versus mitsuba``'s
relMSE), ``quit`` ends. With ``--repeats N`` it renders seeds 1..N itself and exits (``--save NPY``: the last image
as an .npy file, for bench/peers/mitsuba_agreement.py). Errors: ``{"event": "error",
"message"}`` and exit status 1.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path


def _emit(obj: dict) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def _image(img):
    """A Mitsuba image tensor as an (H, W, 3) float32 numpy array."""
    import numpy as np

    return np.array(img, dtype=np.float32)[..., :3]


def _save(path: str, img) -> None:
    """Write an image (Mitsuba tensor or numpy array) to ``path`` as (H, W, 3) float32 .npy."""
    import numpy as np

    np.save(path, _image(img) if not isinstance(img, np.ndarray) else img)


def _transform(mi, spec):
    """pyclpt's ``to_world`` (a 4x4 nested list or a list of one-key operations) as a ScalarTransform4f."""
    T = mi.ScalarTransform4f
    if isinstance(spec, dict):
        spec = [spec]
    if spec and not isinstance(spec[0], dict):
        flat = [float(x) for row in spec for x in (row if isinstance(row, list) else [row])]
        return T([flat[4 * i:4 * i + 4] for i in range(4)])
    t = T()
    for op in spec:
        (kind, arg), = op.items()
        if kind == "translate":
            t = t.translate(arg)
        elif kind == "scale":
            t = t.scale(arg if isinstance(arg, list) else [arg] * 3)
        elif kind == "rotate":
            t = t.rotate(arg["axis"], arg["angle"])
        elif kind in ("look_at", "lookat"):
            t = t.look_at(origin=arg["origin"], target=arg["target"], up=arg.get("up", [0, 1, 0]))
        elif kind == "matrix":
            t = t @ _transform(mi, arg)
        else:
            raise ValueError(f"unknown transform operation {kind!r}")
    return t


def _convert(mi, node):
    if isinstance(node, dict):
        return {k: (_transform(mi, v) if k == "to_world" else _convert(mi, v)) for k, v in node.items()
                if k != "description"}
    return node


def load_json(mi, path: Path, a: argparse.Namespace, optimize: bool = True):
    """The scene of a pyclpt JSON file as Mitsuba 3 loads it (see the module docstring); ``optimize`` False: each
    shape stays its own (Mitsuba merges the meshes that share a BSDF otherwise)."""
    d = _convert(mi, json.loads(path.read_text()))
    d["integrator"] = {"type": "path", "max_depth": a.max_depth, "rr_depth": a.rr_depth}
    sensor = d["sensor"]
    sensor["film"] = {"type": "hdrfilm", "width": a.width, "height": a.height, "pixel_format": "rgb",
                      "rfilter": {"type": "box"}}
    sensor["sampler"] = {"type": "independent", "sample_count": a.spp}
    return mi.load_dict(d) if optimize else mi.load_dict(d, optimize=False)


# Parameters of Mitsuba 0.5/0.6 plug-ins that Mitsuba 3 no longer has (it refuses unused ones): dropped.
SUN_APERTURE = 0.5358  # Mitsuba 3's default sun_aperture (sunsky.h; its documentation says 0.5338), degrees
OBSOLETE = {"conductor": {"extEta", "ext_eta"}, "roughconductor": {"extEta", "ext_eta"}}


def edit_xml(text: str, a: argparse.Namespace) -> str:
    """The scene XML with the integrator, film and sampler replaced (see the module docstring), the
    parameters of :data:`OBSOLETE` dropped and texture filters Mitsuba 3 lacks made bilinear; a
    ``sunsky``'s ``sunRadiusScale`` becomes ``sun_aperture``, and in a pre-2.0 file its frame turns
    from +y up (Mitsuba 0.5) to Mitsuba 3's +z up by a rotation prepended to its ``toWorld`` (a
    ``sunDirection`` is a world direction and stays; a sun from a place and time keeps its elevation,
    not its azimuth: the two versions' azimuths differ by a mirror) and its albedo defaults to 0.5's 0.2
    (Mitsuba 3's is 0.3). The sun model stays Mitsuba 3's."""
    root = ET.fromstring(text)
    for bsdf in root.iter("bsdf"):
        for child in list(bsdf):
            if child.get("name") in OBSOLETE.get(bsdf.get("type", ""), ()):
                bsdf.remove(child)
    for texture in root.iter("texture"):  # trilinear/EWA (0.5/0.6) -> bilinear, as pyclpt filters
        for child in texture.findall("string"):
            if child.get("name") in ("filterType", "filter_type") and child.get("value") not in ("nearest", "bilinear"):
                child.set("value", "bilinear")
    old_file = tuple(int(v) for v in root.get("version", "3.0.0").split(".")) < (2, 0, 0)
    for emitter in root.iter("emitter"):  # 0.5's sun radius scale -> Mitsuba 3's sun aperture (degrees)
        if emitter.get("type") != "sunsky":
            continue
        for child in emitter.findall("float"):
            if child.get("name") in ("sunRadiusScale", "sun_radius_scale"):
                child.set("name", "sun_aperture")
                child.set("value", str(SUN_APERTURE * float(child.get("value", "1"))))
        if old_file:  # 0.5's sky is +y up, Mitsuba 3's +z up: its to_world gets a rotation first
            to_world = next((t for t in emitter.findall("transform") if t.get("name") in ("toWorld", "to_world")),
                            None)
            if to_world is None:
                to_world = ET.SubElement(emitter, "transform", name="toWorld")
            to_world.insert(0, ET.Element("rotate", x="1", angle="-90"))
            if not any(c.get("name") == "albedo" for c in emitter):  # 0.5's default ground albedo (sky.cpp)
                ET.SubElement(emitter, "float", name="albedo", value="0.2")
    for old in root.findall("integrator"):
        root.remove(old)
    integ = ET.Element("integrator", type="path")
    ET.SubElement(integ, "integer", name="max_depth", value=str(a.max_depth))
    ET.SubElement(integ, "integer", name="rr_depth", value=str(a.rr_depth))
    root.insert(0, integ)
    sensors = root.findall("sensor")
    if not sensors:
        raise ValueError("the scene has no <sensor>")
    sensor = sensors[0]
    for tag in ("film", "sampler"):
        for old in sensor.findall(tag):
            sensor.remove(old)
    sampler = ET.SubElement(sensor, "sampler", type="independent")
    ET.SubElement(sampler, "integer", name="sample_count", value=str(a.spp))
    film = ET.SubElement(sensor, "film", type="hdrfilm")
    ET.SubElement(film, "integer", name="width", value=str(a.width))
    ET.SubElement(film, "integer", name="height", value=str(a.height))
    ET.SubElement(film, "string", name="pixel_format", value="rgb")
    ET.SubElement(film, "rfilter", type="box")
    return ET.tostring(root, encoding="unicode")


def load_xml(mi, path: Path, a: argparse.Namespace):
    mi.file_resolver().prepend(str(path.resolve().parent))
    return mi.load_string(edit_xml(path.read_text(), a))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--probe", action="store_true", help="only check that mitsuba loads: print the ready line")
    p.add_argument("--scene", default=None)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--max-depth", type=int, default=8)
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--rr-depth", type=int, default=3)
    p.add_argument("--variant", default="llvm_ad_rgb")
    p.add_argument("--warmup", type=int, default=1)
    p.add_argument("--repeats", type=int, default=None)
    p.add_argument("--save", default=None, metavar="NPY",
                   help="with --repeats: write the last render's image (H, W, 3 float32) to this .npy file")
    a = p.parse_args(argv)
    try:
        import drjit as dr
        import mitsuba as mi

        mi.set_variant(a.variant)
        if a.probe or not a.scene:
            _emit({"event": "ready", "mitsuba_version": mi.__version__, "variant": mi.variant()})
            return 0
        t0 = time.perf_counter()
        path = Path(a.scene)
        scene = load_json(mi, path, a) if path.suffix == ".json" else load_xml(mi, path, a)
        load_s = time.perf_counter() - t0

        last = []

        def render(seed: int) -> tuple[float, list[float]]:
            t = time.perf_counter()
            img = mi.render(scene, spp=a.spp, seed=dr.opaque(mi.UInt32, seed))
            dr.eval(img)
            dr.sync_thread()
            seconds = time.perf_counter() - t
            last[:] = [img]
            flat, n = img.array, img.shape[0] * img.shape[1]
            channels = img.shape[2]
            idx = dr.arange(mi.UInt32, n) * channels
            mean = [dr.sum(dr.gather(mi.Float, flat, idx + c)) / n for c in range(3)]
            return seconds, [float(m[0] if hasattr(m, "__len__") else m) for m in mean]

        warm = [render(0)[0] for _ in range(a.warmup)]
        _emit({"event": "ready", "mitsuba_version": mi.__version__, "variant": mi.variant(), "load_s": load_s,
               "warmup_s": warm, "scene": str(path)})
        if a.repeats is not None:
            for seed in range(1, a.repeats + 1):
                s, m = render(seed)
                _emit({"event": "render", "seed": seed, "seconds": s, "mean": m})
            if a.save and last:
                _save(a.save, last[0])
            return 0
        for line in sys.stdin:
            words = line.split()
            if not words:
                continue
            if words[0] == "quit":
                return 0
            if words[0] == "render":
                seed = int(words[1])
                s, m = render(seed)
                if len(words) > 2:
                    _save(words[2], last[0])
                _emit({"event": "render", "seed": seed, "seconds": s, "mean": m})
            elif words[0] == "reference":
                passes, seed0, out = int(words[1]), int(words[2]), words[3]
                t = time.perf_counter()
                total = None
                for i in range(passes):
                    render(seed0 + i)
                    img = _image(last[0])
                    total = img.astype("float64") if total is None else total + img
                mean_img = (total / passes).astype("float32")
                _save(out, mean_img)
                _emit({"event": "reference", "passes": passes, "spp": passes * a.spp,
                       "seconds": time.perf_counter() - t,
                       "mean": [float(mean_img[..., c].mean()) for c in range(3)]})
            else:
                _emit({"event": "error", "message": f"unknown command {line.strip()!r}"})
                return 1
        return 0
    except Exception as exc:  # noqa: BLE001 - reported to the bench as JSON
        _emit({"event": "error", "message": f"{type(exc).__name__}: {exc}"})
        return 1


if __name__ == "__main__":
    sys.exit(main())
