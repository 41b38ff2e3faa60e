"""Mitsuba XML import (pyclpt.scene.mitsuba_xml) and the .serialized mesh reader (pyclpt.scene.serialized)."""
from __future__ import annotations

import logging
import struct
import warnings
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import pyclpt
from pyclpt import cli
from pyclpt.scene import transform as tf
from pyclpt.scene.mesh_io import MeshLoadError
from pyclpt.scene.mitsuba_dict import SceneDictError, load_dict
from pyclpt.scene.mitsuba_xml import (
    WHERE,
    SceneXMLError,
    blackbody_to_rgb,
    load_xml,
    spectrum_to_rgb,
    srgb_to_linear,
    to_snake_case,
    xml_to_dict,
)
from pyclpt.scene.serialized import read_serialized


def _write(folder: Path, body: str, version: str = "3.0.0", name: str = "scene.xml") -> Path:
    path = folder / name
    path.write_text(f'<scene version="{version}">\n{body}\n</scene>\n')
    return path


def _objects(d: Any) -> Iterator[dict]:
    """Every dict in a translated scene (objects, refs and colours), depth first."""
    if isinstance(d, dict):
        yield d
        for v in d.values():
            yield from _objects(v)


# -- names and versions ---------------------------------------------------------------------------

@pytest.mark.parametrize("camel, snake", [
    ("toWorld", "to_world"), ("maxDepth", "max_depth"), ("sampleCount", "sample_count"),
    ("intIOR", "int_ior"), ("extIOR", "ext_ior"), ("diffuseReflectance", "diffuse_reflectance"),
    ("specularReflectance", "specular_reflectance"), ("specularTransmittance", "specular_transmittance"),
    ("faceNormals", "face_normals"), ("flipNormals", "flip_normals"), ("fovAxis", "fov_axis"),
    ("filterType", "filter_type"), ("sunDirection", "sun_direction"), ("sunRadiusScale", "sun_radius_scale"),
    ("shapeIndex", "shape_index"), ("extEta", "ext_eta"), ("wrapMode", "wrap_mode"), ("uscale", "uscale"),
    ("kNN", "k_nn"), ("high_quality_edges", "high_quality_edges"),
])
def test_to_snake_case(camel, snake):
    assert to_snake_case(camel) == snake


def test_old_versions_are_upgraded(tmp_path):
    body = """
    <integrator type="path"><integer name="maxDepth" value="5"/></integrator>
    <sensor type="perspective">
        <string name="fovAxis" value="smaller"/>
        <transform name="toWorld"><lookAt origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    </sensor>
    <bsdf type="diffuse" id="d"><rgb name="diffuseReflectance" value="0.5"/></bsdf>
    <bsdf type="roughplastic" id="p"><rgb name="diffuseReflectance" value="0.5"/>
        <float name="intIOR" value="1.5"/></bsdf>"""
    d = xml_to_dict(_write(tmp_path, body, "0.5.0"))
    assert d["integrator"]["max_depth"] == 5
    assert d["sensor"]["fov_axis"] == "smaller"
    np.testing.assert_allclose(d["sensor"]["to_world"], tf.look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]))
    assert d["d"]["reflectance"]["value"] == [0.5, 0.5, 0.5]  # Mitsuba 3's rename for diffuse only
    assert set(d["p"]) >= {"diffuse_reflectance", "int_ior"}
    # Mitsuba 2/3 files are taken as written.
    d3 = xml_to_dict(_write(tmp_path, '<integrator type="path"><integer name="maxDepth" value="5"/></integrator>'))
    assert d3["integrator"]["maxDepth"] == 5


def test_upgrade_renames_are_a_table_keyed_by_plugin(tmp_path, monkeypatch):
    """A per-plug-in rename of old files is one entry of upgrade.PARAMETER_RENAMES (keyed by tag and type)."""
    from pyclpt.scene.mitsuba_xml import upgrade

    assert upgrade.PARAMETER_RENAMES[("bsdf", "diffuse")] == {"diffuse_reflectance": "reflectance"}
    monkeypatch.setitem(upgrade.PARAMETER_RENAMES, ("emitter", "point"), {"position_ws": "position"})
    body = """<emitter type="point" id="a"><point name="positionWS" x="1" y="2" z="3"/></emitter>
    <emitter type="spot" id="b"><point name="positionWS" x="1" y="2" z="3"/></emitter>"""
    d = xml_to_dict(_write(tmp_path, body, "0.6.0"))
    assert d["a"]["position"] == [1.0, 2.0, 3.0] and d["b"]["position_ws"] == [1.0, 2.0, 3.0]
    assert xml_to_dict(_write(tmp_path, body, "3.0.0"))["a"]["positionWS"] == [1.0, 2.0, 3.0]  # not upgraded


def test_version_and_root_errors(tmp_path):
    (tmp_path / "a.xml").write_text('<scene>\n</scene>')
    with pytest.raises(SceneXMLError, match=r"a\.xml:1: .*version"):
        xml_to_dict(tmp_path / "a.xml")
    (tmp_path / "b.xml").write_text('<?xml version="1.0"?>\n<shape type="obj" version="3.0.0"/>')
    with pytest.raises(SceneXMLError, match=r"b\.xml:2: .*<shape>, expected <scene>"):
        xml_to_dict(tmp_path / "b.xml")
    with pytest.raises(SceneXMLError, match=r"c\.xml:1: .*three numbers"):
        xml_to_dict(_write(tmp_path, "", "3.0", "c.xml"))
    with pytest.raises(FileNotFoundError):
        xml_to_dict(tmp_path / "missing.xml")


def test_malformed_xml_names_file_and_line(tmp_path):
    path = tmp_path / "bad.xml"
    path.write_text('<scene version="3.0.0">\n  <shape type="cube">\n  </bsdf>\n</scene>\n')
    with pytest.raises(SceneXMLError, match=r"bad\.xml:3: malformed XML") as exc:
        xml_to_dict(path)
    assert isinstance(exc.value, SceneDictError) and isinstance(exc.value, ValueError)


# -- parameters -----------------------------------------------------------------------------------

DEFAULTS = """
    <default name="spp" value="64"/>
    <default name="integrator" value="path"/>
    <default name="r" value="0.25"/>
    <integrator type="$integrator"/>
    <sensor type="perspective">
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
    </sensor>
    <bsdf type="diffuse" id="d"><rgb name="reflectance" value="$r, $r, 0.5"/></bsdf>"""


def test_defaults_and_parameters(tmp_path):
    path = _write(tmp_path, DEFAULTS)
    d = xml_to_dict(path)
    assert d["integrator"]["type"] == "path"
    assert d["sensor"]["sampler"]["sample_count"] == 64
    assert d["d"]["reflectance"]["value"] == [0.25, 0.25, 0.5]
    d = xml_to_dict(path, {"spp": "16", "integrator": "volpath"})
    assert d["sensor"]["sampler"]["sample_count"] == 16 and d["integrator"]["type"] == "volpath"


def test_undefined_parameter_is_an_error(tmp_path):
    path = _write(tmp_path, '<integrator type="path">\n<integer name="max_depth" value="$depth"/></integrator>')
    with pytest.raises(SceneXMLError, match=r"scene\.xml:3: .*undefined parameter \$depth"):
        xml_to_dict(path)
    assert xml_to_dict(path, {"depth": "7"})["integrator"]["max_depth"] == 7


def test_unused_parameter_warns(tmp_path, caplog):
    path = _write(tmp_path, DEFAULTS)
    with warnings.catch_warnings(), caplog.at_level(logging.WARNING, logger="pyclpt"):
        warnings.simplefilter("error")  # through logging, never warnings
        xml_to_dict(path, {"spp": "4", "resx": "64"})
    (record,) = caplog.records
    assert record.name == "pyclpt.scene.mitsuba_xml" and record.levelno == logging.WARNING
    assert record.getMessage() == f"{path}: parameter resx not used by the scene"
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="pyclpt"):
        xml_to_dict(path, {"spp": "4"})
    assert not caplog.records, caplog.text


# -- objects, ids, references ---------------------------------------------------------------------

def test_keys_ids_and_references(tmp_path):
    body = """
    <sensor type="perspective"><film type="hdrfilm"><rfilter name="rfilter" type="tent"/></film></sensor>
    <bsdf type="twosided" id="white"><bsdf type="diffuse"/></bsdf>
    <shape type="rectangle"><ref id="white"/></shape>
    <shape type="cube"><ref name="bsdf" id="white"/><emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>
    <shape type="disk" id="disk"><bsdf type="diffuse"/><bsdf type="conductor"/></shape>
    <emitter type="constant"/>
    <medium type="homogeneous" id="fog"><float name="sigma_t" value="0.5"/></medium>
    <shape type="sphere"><ref name="interior" id="fog"/></shape>"""
    d = xml_to_dict(_write(tmp_path, body))
    assert list(d) == ["type", WHERE, "sensor", "white", "shape_0", "shape_1", "disk", "emitter_0", "fog",
                       "shape_2"]
    assert d["sensor"]["film"]["rfilter"]["type"] == "tent"
    assert d["white"]["id"] == "white" and d["white"]["bsdf"]["type"] == "diffuse"
    ref = d["shape_0"]["bsdf"]
    assert {k: v for k, v in ref.items() if k != WHERE} == {"type": "ref", "id": "white"}
    assert d["shape_1"]["emitter"]["radiance"]["value"] == [1.0, 1.0, 1.0]
    assert [d["disk"]["bsdf"]["type"], d["disk"]["bsdf_1"]["type"]] == ["diffuse", "conductor"]
    # Unsupported elements are translated, not dropped (load_dict reports them).
    assert d["fog"] == {"type": "homogeneous", WHERE: d["fog"][WHERE], "id": "fog", "sigma_t": 0.5}
    assert d["shape_2"]["interior"]["id"] == "fog"


def test_every_object_has_its_location(tmp_path):
    path = _write(tmp_path, DEFAULTS)
    d = xml_to_dict(path)
    objects = list(_objects(d))
    assert len(objects) == 6
    assert all(o[WHERE].startswith(f"{path}:") for o in objects)
    assert d["sensor"]["sampler"][WHERE] == f"{path}:8"


@pytest.mark.parametrize("body, needle", [
    ('<shape type="cube">\n<ref id="nope"/></shape>', r":3: <ref id=\"nope\">: no object with id 'nope'"),
    ('<bsdf type="diffuse" id="a"/>\n<bsdf type="diffuse" id="a"/>', r":3: .*duplicate id 'a'.*scene\.xml:2"),
    ('<shape type="cube">\n<float name="x" value="1"/><float name="x" value="2"/></shape>',
     r":3: .*'x' is given twice"),
    ('<shape>\n</shape>', r":2: <shape>: missing attribute 'type'"),
    ('<shape type="cube">\n<flaot name="x" value="1"/></shape>', r":3: .*unknown element <flaot>"),
    ('<shape type="cube">\n<float value="1"/></shape>', r":3: .*missing attribute 'name'"),
    ('<sensor type="perspective">\n<float name="fov" value="abc"/></sensor>',
     r":3: <float name=\"fov\" value=\"abc\">: could not parse a number from 'abc'"),
    ('<sensor type="perspective">\n<integer name="n" value="1.5"/></sensor>', r":3: .*integer from '1\.5'"),
    ('<sensor type="perspective">\n<boolean name="b" value="yes"/></sensor>', r":3: .*\"true\" or \"false\""),
    ('<shape type="cube">\n<rgb name="c" value="1, 2"/></shape>', r":3: .*1 or 3 numbers, got 2"),
    ('<shape type="cube">\n<float name="x" value="1" foo="2"/></shape>', r":3: .*unexpected attribute 'foo'"),
    ('<shape type="cube">\n<float name="x">1</float></shape>', r":3: .*unexpected text '1'"),
    ('<shape type="cube">\n<translate x="1"/></shape>', r":3: .*must be inside a <transform>"),
    ('<shape type="cube"><transform name="to_world">\n<float name="x" value="1"/></transform></shape>',
     r":3: .*may only hold"),
    ('<shape type="cube"><transform name="to_world">\n<matrix value="1 2 3"/></transform></shape>',
     r":3: <matrix value=\"1 2 3\">: a matrix needs 16 or 9 numbers, got 3"),
    ('<shape type="cube"><transform name="to_world">\n<rotate x="1"/></transform></shape>',
     r":3: .*missing attribute 'angle'"),
    ('<sensor type="perspective"><transform name="to_world">\n<lookat origin="0,0,0" target="0,0,0"/>'
     '</transform></sensor>', r":3: .*origin and target are the same"),
    ('<shape type="obj">\n<string name="filename" value="no such.obj"/></shape>',
     r":3: .*file not found: .*no such\.obj"),
])
def test_errors_name_file_line_element_and_value(tmp_path, body, needle):
    with pytest.raises(SceneXMLError, match=r"scene\.xml" + needle):
        xml_to_dict(_write(tmp_path, body))


def test_alias(tmp_path):
    body = '<bsdf type="diffuse" id="a"/><alias id="a" as="b"/><shape type="cube"><ref id="b"/></shape>'
    d = xml_to_dict(_write(tmp_path, body))
    assert d["shape_0"]["bsdf"]["id"] == "a"


# -- includes -------------------------------------------------------------------------------------

def test_include_splices_children_relative_to_the_including_file(tmp_path):
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "mesh.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "parts" / "inner.xml").write_text(
        '<scene version="0.5.0"><bsdf type="diffuse" id="b2">'
        '<rgb name="diffuseReflectance" value="0.1"/></bsdf></scene>')
    (tmp_path / "parts" / "materials.xml").write_text(
        '<scene version="3.0.0">\n<bsdf type="diffuse" id="b1"/>\n<include filename="inner.xml"/>\n'
        '<shape type="obj"><string name="filename" value="mesh.obj"/><ref id="b2"/></shape></scene>')
    path = _write(tmp_path, '<include filename="parts/materials.xml"/>\n<shape type="cube"><ref id="b1"/></shape>')
    d = xml_to_dict(path)
    assert list(d)[2:] == ["b1", "b2", "shape_0", "shape_1"]
    assert d["b2"]["reflectance"]["value"] == [0.1] * 3  # the included file's own version is upgraded
    assert d["b1"][WHERE] == f"{tmp_path / 'parts' / 'materials.xml'}:2"
    assert d["shape_0"]["filename"] == str(tmp_path / "parts" / "mesh.obj")


def test_include_of_a_single_object(tmp_path):
    (tmp_path / "bsdf.xml").write_text('<bsdf type="diffuse" id="b" version="0.5.0">\n'
                                       '<rgb name="diffuseReflectance" value="0.2"/></bsdf>')
    d = xml_to_dict(_write(tmp_path, '<include filename="bsdf.xml"/>'))
    assert d["b"]["reflectance"]["value"] == [0.2] * 3 and d["b"][WHERE] == f"{tmp_path / 'bsdf.xml'}:1"


def test_include_errors(tmp_path):
    (tmp_path / "a.xml").write_text('<scene version="3.0.0">\n<include filename="scene.xml"/></scene>')
    path = _write(tmp_path, '<include filename="a.xml"/>')
    with pytest.raises(SceneXMLError, match=r"a\.xml:2: .*include cycle"):
        xml_to_dict(path)
    with pytest.raises(SceneXMLError, match=r"scene\.xml:3: <include filename=\"nope\.xml\">: included file "
                                            r"not found: .*nope\.xml"):
        xml_to_dict(_write(tmp_path, '\n<include filename="nope.xml"/>'))


# -- transforms -----------------------------------------------------------------------------------

def _to_world(tmp_path: Path, ops: str) -> np.ndarray:
    d = xml_to_dict(_write(tmp_path, f'<shape type="cube"><transform name="to_world">{ops}</transform></shape>'))
    m = d["shape_0"]["to_world"]
    assert isinstance(m, np.ndarray) and m.shape == (4, 4) and m.dtype == np.float64
    return m


def test_transform_operations_apply_in_order(tmp_path):
    m = _to_world(tmp_path, '<translate x="1" y="2"/><rotate y="1" angle="90"/><scale value="2"/>')
    np.testing.assert_allclose(m, tf.scale(2) @ tf.rotate([0, 1, 0], 90) @ tf.translate([1, 2, 0]), atol=1e-12)
    m = _to_world(tmp_path, '<scale y="3"/><translate value="1 2 3"/><rotate value="0, 0, 1" angle="45"/>')
    np.testing.assert_allclose(m, tf.rotate([0, 0, 1], 45) @ tf.translate([1, 2, 3]) @ tf.scale([1, 3, 1]))
    values = np.arange(16.0)
    np.testing.assert_allclose(_to_world(tmp_path, f'<matrix value="{" ".join(map(str, values))}"/>'),
                               values.reshape(4, 4))
    m = _to_world(tmp_path, '<matrix value="1 0 0 0 0 -1 0 1 0"/><translate z="5"/>')
    np.testing.assert_allclose(m, tf.translate([0, 0, 5]) @ tf.matrix([1, 0, 0, 0, 0, -1, 0, 1, 0]))


def test_lookat(tmp_path):
    m = _to_world(tmp_path, '<lookat origin="1, 2, 3" target="0 0 0" up="0, 0, 1"/>')
    np.testing.assert_allclose(m, tf.look_at([1, 2, 3], [0, 0, 0], [0, 0, 1]))
    # Camera space: +z looks at the target, +y is (close to) up.
    np.testing.assert_allclose(m[:3, 2], -np.array([1, 2, 3]) / np.sqrt(14))
    m = _to_world(tmp_path, '<lookat origin="0, 5, 0" target="0, 0, 0"/>')  # no up: any perpendicular one
    np.testing.assert_allclose(m[:3, 2], [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-12)


# -- values ---------------------------------------------------------------------------------------

def test_plain_values(tmp_path):
    body = """<shape type="cube">
        <float name="f" value="1e-3"/><integer name="i" value=" 42 "/><boolean name="b" value="True"/>
        <string name="s" value="a b"/><vector name="v" x="1" z="3"/><point name="p" value="1, 2, 3"/>
        <vector name="w" value="2"/></shape>"""
    d = xml_to_dict(_write(tmp_path, body))["shape_0"]
    assert (d["f"], d["i"], d["b"], d["s"]) == (1e-3, 42, True, "a b")
    assert isinstance(d["i"], int) and isinstance(d["f"], float)
    assert (d["v"], d["p"], d["w"]) == ([1.0, 0.0, 3.0], [1.0, 2.0, 3.0], [2.0, 2.0, 2.0])


def test_colors(tmp_path):
    body = """<bsdf type="diffuse" id="x">
        <rgb name="a" value="0.1, 0.2, 0.3"/><rgb name="b" value="0.1 0.2 0.3"/><rgb name="c" value="0.5"/>
        <srgb name="d" value="0.5, 1, 0"/><srgb name="e" value="#ff8000"/>
        <spectrum name="f" value="0.4"/><spectrum name="g" value="360:1, 830:1"/>
        <spectrum name="h" value="600:1, 700:1"/><blackbody name="i" temperature="6500K" multiplier="1e-4"/>
        <spectrum name="j" type="blackbody"><float name="temperature" value="3000"/></spectrum>
        <spectrum name="k" type="d65"/></bsdf>"""
    d = xml_to_dict(_write(tmp_path, body, "0.6.0"))["x"]
    val = {k: v["value"] for k, v in d.items() if isinstance(v, dict) and v["type"] == "rgb"}
    assert all(d[k][WHERE] for k in val)
    assert val["a"] == val["b"] == [0.1, 0.2, 0.3] and val["c"] == [0.5] * 3
    np.testing.assert_allclose(val["d"], [0.2140411, 1.0, 0.0], rtol=1e-5)
    np.testing.assert_allclose(val["e"], [1.0, srgb_to_linear(128 / 255), 0.0])
    assert val["f"] == [0.4] * 3
    np.testing.assert_allclose(val["g"], [1, 1, 1], rtol=1e-9)  # constant 1 is white
    assert val["h"][0] > 5 * val["h"][2]  # long wavelengths are red
    r, g, b = val["i"]
    assert 0.9 < r / g < 1.1 and 0.9 < b / g < 1.1 and 3.5 < g < 4.5  # 6500 K: near white, ~4.2e4 * 1e-4
    r, g, b = val["j"]
    assert r > g > b > 0  # 3000 K is orange
    assert d["k"]["type"] == "d65"  # other spectrum plug-ins stay objects
    assert spectrum_to_rgb([400, 700], [2, 2])[1] == pytest.approx(2 * spectrum_to_rgb([400, 700], [1, 1])[1])
    np.testing.assert_allclose(blackbody_to_rgb(5000, 2.0), 2 * np.array(blackbody_to_rgb(5000)))


def test_mitsuba_0x_three_value_spectrum_is_rgb(tmp_path):
    body = '<bsdf type="diffuse" id="x"><spectrum name="reflectance" value="0.1, 0.2, 0.3"/></bsdf>'
    assert xml_to_dict(_write(tmp_path, body, "0.5.0"))["x"]["reflectance"]["value"] == [0.1, 0.2, 0.3]
    with pytest.raises(SceneXMLError, match="wavelength:value pairs"):
        xml_to_dict(_write(tmp_path, body))


def test_file_names_resolve_to_absolute_paths(tmp_path):
    (tmp_path / "textures").mkdir()
    (tmp_path / "textures" / "Sky 19.exr").write_bytes(b"")
    body = """<emitter type="envmap"><string name="filename" value="textures/Sky 19.exr"/></emitter>
    <bsdf type="diffuse" id="t"><texture name="reflectance" type="bitmap">
        <string name="filename" value="textures\\Sky 19.exr"/><string name="filterType" value="bilinear"/>
    </texture></bsdf>"""
    d = xml_to_dict(_write(tmp_path, body, "0.5.0"))
    want = str(tmp_path / "textures" / "Sky 19.exr")
    assert d["emitter_0"]["filename"] == want
    tex = d["t"]["reflectance"]
    assert tex["type"] == "bitmap" and tex["filename"] == want and tex["filter_type"] == "bilinear"


# -- shared scenes --------------------------------------------------------------------------------

SHARED = ("cornell-box", "staircase2", "living-room", "staircase", "classroom")


@pytest.fixture(scope="module")
def shared_dicts(shared_scenes) -> dict[str, dict]:
    return {name: xml_to_dict(shared_scenes / name / "scene.xml") for name in SHARED}


def _shapes(d: dict) -> list[dict]:
    return [v for v in d.values() if isinstance(v, dict) and v["type"] in ("obj", "rectangle", "disk", "cube")]


def test_shared_scenes_translate(shared_dicts):
    counts = {name: len(_shapes(d)) for name, d in shared_dicts.items()}
    assert counts == {"cornell-box": 8, "staircase2": 32, "living-room": 65, "staircase": 775, "classroom": 79}
    for d in shared_dicts.values():
        assert d["type"] == "scene" and d["sensor"]["type"] == "perspective"
        assert isinstance(d["sensor"]["to_world"], np.ndarray)
        for shape in _shapes(d):
            if "filename" in shape:
                assert Path(shape["filename"]).is_absolute() and Path(shape["filename"]).is_file()


def test_shared_scene_details(shared_dicts, shared_scenes):
    emitters = [s["emitter"] for s in _shapes(shared_dicts["staircase2"]) if "emitter" in s]
    assert len(emitters) == 13 and {e["type"] for e in emitters} == {"area"}
    assert shared_dicts["staircase2"]["integrator"]["max_depth"] == 65
    assert shared_dicts["staircase2"]["Glass"]["int_ior"] == 1.5
    sky = [v for v in shared_dicts["classroom"].values() if isinstance(v, dict) and v["type"] == "sunsky"]
    assert len(sky) == 1 and sky[0]["turbidity"] == 3 and sky[0]["sun_direction"][1] == pytest.approx(0.416766)
    env = shared_dicts["living-room"]["emitter_0"]
    assert env["type"] == "envmap" and env["filename"].endswith("textures/Sky 19.exr")
    cb = shared_dicts["cornell-box"]
    assert cb["sensor"]["fov"] == 19.5
    assert (cb["sensor"]["film"]["width"], cb["sensor"]["film"]["height"]) == (1024, 1024)
    assert cb["integrator"] == {"type": "path_guiding_integrator", WHERE: cb["integrator"][WHERE], "max_depth": 30}
    assert cb["Light"]["emitter"]["radiance"]["value"] == [17.0, 12.0, 4.0]
    small = xml_to_dict(shared_scenes / "cornell-box" / "scene.xml", {"resx": "64", "integrator": "path"})
    assert small["sensor"]["film"]["width"] == 64 and small["integrator"]["type"] == "path"


# -- loading --------------------------------------------------------------------------------------

TINY = """
    <default name="spp" value="8"/>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/></film>
    </sensor>
    <bsdf type="twosided" id="grey"><bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf></bsdf>
    <shape type="rectangle"><ref id="grey"/></shape>
    <shape type="cube"><transform name="to_world"><scale value="0.3"/></transform><ref id="grey"/></shape>
    <shape type="obj"><string name="filename" value="tri.obj"/>
        <emitter type="area"><rgb name="radiance" value="5"/></emitter></shape>"""


@pytest.fixture
def tiny_xml(tmp_path) -> Path:
    try:  # the lead teaches load_dict that __where__ is metadata
        load_dict({"type": "scene", WHERE: "x:1", "s": {"type": "rectangle", WHERE: "x:2"}})
    except SceneDictError:
        pytest.skip("load_dict does not accept the __where__ meta key yet")
    (tmp_path / "tri.obj").write_text("v 0 0 1\nv 1 0 1\nv 0 1 1\nf 1 2 3\n")
    return _write(tmp_path, TINY, name="tiny.xml")


def test_load_xml(tiny_xml):
    scene = load_xml(tiny_xml, spp=4)
    assert scene.name == "tiny" and scene.source == tiny_xml and scene.spp == 4
    assert (scene.film.width, scene.film.height) == (32, 24)
    assert [len(m.indices) for m in scene.meshes] == [2, 12, 1]
    assert scene.meshes[2].emission == (5.0, 5.0, 5.0)
    assert pyclpt.load(str(tiny_xml), spp=2).spp == 2


def test_load_rejects_parameters_for_json_scenes():
    with pytest.raises(ValueError, match="only to Mitsuba .xml"):
        pyclpt.load("cornell-box", spp=4)


def test_cli_define(monkeypatch, capsys):
    seen = {}

    def fake_load(name, **params):
        seen.update(params, scene=name)
        raise ValueError("stop here")

    monkeypatch.setattr("pyclpt.scene.library.load", fake_load)
    assert cli.main(["render", "x.xml", "-D", "spp=16", "--define", "resx=64", "-D", "s=a=b"]) == 1
    assert seen == {"scene": "x.xml", "spp": "16", "resx": "64", "s": "a=b"}
    with pytest.raises(SystemExit) as exc:
        cli.main(["render", "x.xml", "-D", "spp"])
    assert exc.value.code == 2 and "NAME=VALUE" in capsys.readouterr().err


# -- .serialized ----------------------------------------------------------------------------------

def write_serialized(path: Path, shapes: list[dict], version: int = 4, double: bool = False) -> None:
    """A Mitsuba .serialized file from the format description (shapes: positions, indices and
    optionally normals, uvs, colors, face_normals, name)."""
    out, offsets = bytearray(), []
    real = "<f8" if double else "<f4"
    for s in shapes:
        offsets.append(len(out))
        flags = 0x2000 if double else 0x1000
        flags |= (0x0001 if "normals" in s else 0) | (0x0002 if "uvs" in s else 0)
        flags |= (0x0008 if "colors" in s else 0) | (0x0010 if s.get("face_normals") else 0)
        body = struct.pack("<I", flags)
        if version == 4:
            body += s.get("name", "mesh").encode() + b"\0"
        body += struct.pack("<QQ", len(s["positions"]), len(s["indices"]))
        for key in ("positions", "normals", "uvs", "colors"):
            if key in s:
                body += np.asarray(s[key], real).tobytes()
        body += np.asarray(s["indices"], "<u4").tobytes()
        out += struct.pack("<HH", 0x041C, version) + zlib.compress(body)
    for offset in offsets:
        out += struct.pack("<Q" if version == 4 else "<I", offset)
    out += struct.pack("<I", len(shapes))
    path.write_bytes(bytes(out))


QUAD = {"positions": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.5]], "indices": [[0, 1, 2], [0, 2, 3]]}


@pytest.mark.parametrize("version", [3, 4])
@pytest.mark.parametrize("double", [False, True])
def test_serialized_round_trip(tmp_path, version, double):
    full = {**QUAD, "normals": [[0, 0, 1]] * 4, "uvs": [[0, 0], [1, 0], [1, 1], [0, 1]],
            "colors": [[1, 0, 0]] * 4, "name": "quad"}
    tri = {"positions": [[0, 0, 0], [2, 0, 0], [0, 2, 0.1]], "indices": [[0, 1, 2]]}
    path = tmp_path / "m.serialized"
    write_serialized(path, [QUAD, full, tri], version=version, double=double)
    plain = read_serialized(path)
    np.testing.assert_array_equal(plain.positions, np.float32(QUAD["positions"]))
    np.testing.assert_array_equal(plain.indices, QUAD["indices"])
    assert plain.normals is None and plain.uvs is None and plain.positions.dtype == np.float32
    assert list(plain.material_ids) == [0, 0] and plain.material_names == ("",)
    m = read_serialized(path, shape_index=1)
    np.testing.assert_array_equal(m.normals, np.float32(full["normals"]))
    np.testing.assert_array_equal(m.uvs, np.float32(full["uvs"]))
    np.testing.assert_array_equal(read_serialized(path, 2).positions, np.float32(tri["positions"]))


def test_serialized_face_normals_flag_drops_normals(tmp_path):
    path = tmp_path / "f.serialized"
    write_serialized(path, [{**QUAD, "normals": [[0, 0, 1]] * 4, "face_normals": True}])
    assert read_serialized(path).normals is None


def test_serialized_errors(tmp_path):
    path = tmp_path / "m.serialized"
    write_serialized(path, [QUAD])
    with pytest.raises(MeshLoadError, match=r"m\.serialized \(shape 3\): shape index 3 is out of range .*1 shape"):
        read_serialized(path, 3)
    data = path.read_bytes()
    (tmp_path / "bad.serialized").write_bytes(b"\x1d\x04" + data[2:])
    with pytest.raises(ValueError, match=r"bad\.serialized \(shape 0\): not a Mitsuba .serialized file"):
        read_serialized(tmp_path / "bad.serialized")
    (tmp_path / "v5.serialized").write_bytes(data[:2] + b"\x05\x00" + data[4:])
    with pytest.raises(ValueError, match="version 5"):
        read_serialized(tmp_path / "v5.serialized")
    (tmp_path / "cut.serialized").write_bytes(data[:30])
    with pytest.raises(ValueError, match=r"cut\.serialized \(shape 0\): (truncated|corrupt)"):
        read_serialized(tmp_path / "cut.serialized")
    body = struct.pack("<I", 0x1000) + b"m\0" + struct.pack("<QQ", 3, 1) + bytes(36) + bytes(8)
    (tmp_path / "short.serialized").write_bytes(struct.pack("<HH", 0x041C, 4) + zlib.compress(body))
    with pytest.raises(ValueError, match=r"truncated data while reading triangle indices"):
        read_serialized(tmp_path / "short.serialized")
    write_serialized(tmp_path / "range.serialized", [{**QUAD, "indices": [[0, 1, 9]]}])
    with pytest.raises(ValueError, match="index 9 out of range for 4 vertices"):
        read_serialized(tmp_path / "range.serialized")
