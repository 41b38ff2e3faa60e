"""Plug-ins by kind, one place each: a material is one registry entry of the dict loader
(pyclpt.scene.mitsuba_dict.bsdfs.BSDFS), one type id of the packing (pyclpt.buffers.materials.MAT_TYPES)
and one header of the device (cl/scene/bsdfs/<name>.h) with its lines in the dispatch of cl/scene/bsdf.h."""
from __future__ import annotations

import logging
import re

import pytest

from pyclpt.buffers.materials import MAT_TYPES
from pyclpt.device.program import cl_dir
from pyclpt.scene.mitsuba_dict import BSDFS, EMITTERS, SENSORS, SHAPES, TEXTURES, load_dict
from pyclpt.scene.mitsuba_dict import bsdfs as bsdf_plugins
from pyclpt.scene.model import Diffuse

RECT = {"type": "rectangle"}


def _bsdf_h() -> str:
    return (cl_dir() / "scene" / "bsdf.h").read_text()


def _function_body(text: str, name: str) -> str:
    start = re.search(rf"static inline \w+ {name}\(", text)
    assert start, name
    return text[start.start():text.index("\n}\n", start.start())]


@pytest.mark.parametrize("name", sorted(MAT_TYPES))
def test_every_device_material_has_its_header_type_id_loader_and_dispatch(name):
    text = _bsdf_h()
    m = re.search(rf"#define MAT_{name.upper()} (\d+)", text)
    assert m and int(m.group(1)) == MAT_TYPES[name], f"MAT_{name.upper()} in cl/scene/bsdf.h"
    header = cl_dir() / "scene" / "bsdfs" / f"{name}.h"
    assert header.is_file(), header
    assert f'#include "scene/bsdfs/{name}.h"' in text
    source = header.read_text()
    assert source.startswith(f"/* {name}.h: "), f"{header}: starts with a comment saying what it holds"
    assert re.search(rf"static inline bool {name}_sample\(", source), f"{header}: {name}_sample"
    assert f"{name}_sample(" in _function_body(text, "bsdf_sample")
    if re.search(rf"static inline vec3 {name}_eval\(", source):  # a material with non-delta lobes
        assert f"{name}_eval(" in _function_body(text, "bsdf_eval")
    assert name in BSDFS, f"the dict loader's BSDFS has no {name!r}"


def test_every_bsdf_header_says_what_it_holds_and_is_included():
    text = _bsdf_h()
    headers = sorted((cl_dir() / "scene" / "bsdfs").glob("*.h"))
    assert {h.stem for h in headers} >= set(MAT_TYPES) | {"fresnel", "microfacet"}
    for header in headers:
        assert header.read_text().startswith(f"/* {header.name}: "), header
        assert f'#include "scene/bsdfs/{header.name}"' in text, header


def test_registries_name_the_mitsuba_plugins():
    assert {"diffuse", "roughconductor", "twosided", "mask", "bumpmap"} <= set(BSDFS)
    assert set(TEXTURES) == {"bitmap", "checkerboard", "scale"}
    assert {"rectangle", "cube", "sphere", "obj", "ply", "serialized", "mesh"} <= set(SHAPES)
    assert {"point", "constant", "envmap", "sunsky"} <= set(EMITTERS)
    assert set(SENSORS) == {"perspective", "thinlens"}
    assert not set(BSDFS) & bsdf_plugins.UNSUPPORTED


def test_a_registry_entry_is_all_the_loader_needs(monkeypatch, caplog):
    """A new BSDF plug-in: one loader in BSDFS, and the scene loads it (nested, referenced, by id)."""
    def load_velvet(ctx, d, where):
        ctx.note_unused(where, d, {"sheen"})
        return Diffuse(ctx.constant_color(d.get("sheen", 0.3), f"{where}.sheen", d))

    monkeypatch.setitem(BSDFS, "velvet", load_velvet)
    scene = load_dict({"type": "scene",
                       "cloth": {"type": "velvet", "id": "cloth", "sheen": [0.1, 0.2, 0.3]},
                       "a": {**RECT, "bsdf": {"type": "ref", "id": "cloth"}},
                       "b": {**RECT, "bsdf": {"type": "velvet", "fuzz": 2}}})
    assert scene.materials == [Diffuse((0.1, 0.2, 0.3)), Diffuse((0.3, 0.3, 0.3))]
    assert "b.bsdf.fuzz" in caplog.text and "cloth" not in caplog.text  # referenced: not reported unused


def test_unsupported_plugins_share_one_warning_line(caplog):
    with caplog.at_level(logging.WARNING, logger="pyclpt"):
        scene = load_dict({"type": "scene", "a": {**RECT, "bsdf": {"type": "phong"}}, "c": {"type": "cylinder"},
                           "s": {"type": "spot"}}, origin="o.json")
    assert scene.materials == [Diffuse()] and len(scene.meshes) == 1
    (record,) = caplog.records
    assert record.getMessage() == ("o.json: not used by pyclpt (3): a.bsdf: BSDF type 'phong' not supported, "
                                   "grey diffuse (0.5) used; c: shape type 'cylinder' not supported, shape "
                                   "skipped; s: emitter type 'spot' not supported, ignored")
