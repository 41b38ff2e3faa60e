"""Instancing (Mitsuba ``shapegroup`` + ``instance``): loading, the two-level BVH (pyclpt/accel/instances.py,
cl/scene/instances.h), images against Mitsuba 3 and against the same scene flattened, memory, errors."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import pyclpt
from pyclpt.buffers.scene import pack_scene
from pyclpt.scene import transform as tf
from pyclpt.scene.mitsuba_dict import SceneDictError, load_dict
from pyclpt.scene.mitsuba_xml import load_xml

DATA = Path(__file__).parent / "data"


def _scene(n: int, *, mask: bool = False, extra: dict | None = None, anisotropic: bool = False) -> dict:
    """A sphere group instanced n times in a row over a floor, an area light and a constant environment."""
    bsdf = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.2]}}
    if anisotropic:  # its highlights follow the tangent frame, which the instances turn
        bsdf = {"type": "roughconductor", "material": "Au", "alpha_u": 0.04, "alpha_v": 0.4}
    if mask:
        bsdf = {"type": "mask", "opacity": 0.5, "bsdf": bsdf}
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 60, "to_world": tf.look_at([0, 3, 8], [0, 0.5, 0]),
                    "film": {"type": "hdrfilm", "width": 32, "height": 24}},
         "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.4, 0.4, 0.4]}},
         "group": {"type": "shapegroup", "id": "group",
                   "ball": {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5, "bsdf": bsdf},
                   "box": {"type": "cube", "to_world": tf.translate([0.6, 0.2, 0]) @ tf.scale(0.2)}},
         "floor": {"type": "rectangle", "to_world": tf.scale(6) @ tf.rotate([1, 0, 0], -90)},
         "light": {"type": "rectangle", "to_world": tf.translate([0, 4, 0]) @ tf.rotate([1, 0, 0], 90),
                   "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [6, 6, 6]}}}}
    for k in range(n):
        x = -0.5 * (n - 1) * 1.3 + 1.3 * k
        d[f"inst{k}"] = {"type": "instance", "shape": {"type": "ref", "id": "group"},
                         "to_world": tf.translate([x, 0, 0]) @ tf.rotate([0, 1, 0], 25 * k)
                         @ tf.scale([1.0, 1.0 + 0.2 * k, 1.0])}
    d.update(extra or {})
    return d


def test_instances_match_mitsuba():
    """tests/data/instances.xml (a group of a sphere, a plastic cube and a rough gold cylinder, instanced four
    times with rotations, a non-uniform scale and translations; an area light and a constant environment)
    against Mitsuba 3 (tests/data/make_plugin_reference.py, 16384 spp): mean within 1 %, pixel relMSE (our
    noise: it falls as 1/spp, and the flattened scene measures the same), and the megakernel equal to the
    wavefront."""
    ref = np.load(DATA / "instances-mitsuba.npy")
    scene = pyclpt.load(DATA / "instances.xml")
    assert len(scene.instances) == 4 and len(scene.groups["thing"].meshes) == 3 and len(scene.meshes) == 2
    img = pyclpt.render(scene, spp=256, seed=3)
    np.testing.assert_allclose(img.mean((0, 1)), ref.mean((0, 1)), rtol=0.01)
    assert np.mean((img - ref) ** 2) / np.mean(ref**2) < 5e-3  # 3.0e-3 measured, noise (7.6e-4 at 1024 spp)
    np.testing.assert_array_equal(pyclpt.render(scene, spp=2, seed=5, width=16, height=12),
                                  pyclpt.render(scene, spp=2, seed=5, width=16, height=12, integrator="wavefront"))


@pytest.mark.parametrize("mask, anisotropic", [(False, False), (True, False), (False, True)])
def test_instanced_scene_renders_as_flattened(mask, anisotropic):
    """The same scene with its instances expanded into plain meshes (Scene.flattened): the same image within
    noise (the same random numbers; paths part only where a hit differs by rounding, or, with an alpha mask
    in the group, where instances draw their own opacity decisions); an anisotropic rough conductor's
    tangent frame turned with its instance; megakernel == wavefront bit for bit."""
    scene = load_dict(_scene(3, mask=mask, anisotropic=anisotropic))
    flat = scene.flattened()
    assert not flat.instances and len(flat.meshes) == len(scene.meshes) + 3 * 2
    a = pyclpt.render(scene, spp=64, seed=1)
    b = pyclpt.render(flat, spp=64, seed=1)
    np.testing.assert_allclose(a.mean((0, 1)), b.mean((0, 1)), rtol=0.02)
    assert np.mean((a - b) ** 2) / np.mean(b**2) < (2e-2 if mask else 2e-3)
    if not mask:
        assert np.mean(np.abs(a - b).max(-1) > 1e-4) < 0.15  # most pixels identical
    np.testing.assert_array_equal(pyclpt.render(scene, spp=2, seed=5, integrator="wavefront"),
                                  pyclpt.render(scene, spp=2, seed=5))


def test_instanced_aovs_and_ids():
    """The G-buffer of an instanced scene: normals and albedo as the flattened scene's; prim_id and mesh_id
    name the group's triangle and mesh (the same for every instance)."""
    scene = load_dict(_scene(3))
    flat = scene.flattened()
    _, a = pyclpt.render(scene, spp=4, seed=1, aovs=["normal", "albedo", "mesh_id", "prim_id"])
    _, b = pyclpt.render(flat, spp=4, seed=1, aovs=["normal", "albedo"])
    assert np.mean(np.abs(a["normal"] - b["normal"]).max(-1) > 1e-3) < 0.05
    assert np.mean(np.abs(a["albedo"] - b["albedo"]).max(-1) > 1e-3) < 0.05
    names = [m.name for m in scene.meshes] + [m.name for m in scene.groups["group"].meshes]
    ids = np.unique(a["mesh_id"])
    assert set(ids) <= set(range(-1, len(names))) and {names.index("group.ball")} <= set(ids)
    assert a["prim_id"].max() < scene.triangle_count + scene.groups["group"].triangle_count


def test_instances_add_records_not_meshes():
    """Device buffers: 2 and 8 instances of a group differ only in the node buffer, by the instance records
    and the top level's nodes; the flattened scene's triangles grow with every instance."""
    two, eight = (pack_scene(load_dict(_scene(n))) for n in (2, 8))
    sizes2, sizes8 = dict((k, a.nbytes) for k, a in two.device_arrays()), dict(
        (k, a.nbytes) for k, a in eight.device_arrays())
    for name in sizes2:
        if name != "BVH nodes":
            assert sizes2[name] == sizes8[name], name
    grow = sizes8["BVH nodes"] - sizes2["BVH nodes"]
    assert 0 < grow <= 6 * (36 * 4 + 2 * 256)  # six more records, at most two 8-wide nodes each
    flat8 = pack_scene(load_dict(_scene(8)).flattened())
    group_tris = load_dict(_scene(1)).groups["group"].triangle_count
    assert flat8.triangle_count - eight.triangle_count == 7 * group_tris
    assert flat8.nbytes > 4 * eight.nbytes
    assert eight.defines["SCENE_HAS_INSTANCES"] and "SCENE_HAS_INSTANCES" not in pack_scene(
        load_dict(_scene(0))).defines


def test_mitsuba_05_syntax_and_a_scene_of_instances_only(tmp_path):
    """Mitsuba 0.5's toWorld, a group before its use, and no plain meshes: the instances alone render."""
    xml = tmp_path / "old.xml"
    xml.write_text("""<scene version="0.5.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="toWorld"><lookat origin="0, 0, 6" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/></film>
  </sensor>
  <emitter type="constant"/>
  <shape type="shapegroup" id="g"><shape type="sphere"><float name="radius" value="0.5"/></shape></shape>
  <shape type="instance"><ref id="g"/><transform name="toWorld"><translate x="-1"/></transform></shape>
  <shape type="instance"><ref id="g"/><transform name="toWorld"><translate x="1"/></transform></shape>
</scene>""")
    scene = load_xml(xml)
    assert not scene.meshes and [i.to_world[0, 3] for i in scene.instances] == [-1.0, 1.0]
    img = pyclpt.render(scene, spp=4)
    assert img[6, 4].mean() < 0.6 and img[6, 8].mean() > 0.9  # a sphere at x = -1, the environment between


@pytest.mark.parametrize("change, message", [
    ({"bad": {"type": "instance", "shape": {"type": "ref", "id": "nothing"}}},
     "bad.shape: instance of unknown shapegroup 'nothing'"),
    ({"bad": {"type": "instance", "shape": {"type": "ref", "id": "group"}, "to_world": tf.scale([1, 0, 1])}},
     "bad: instance 'bad': degenerate to_world"),
    ({"g2": {"type": "shapegroup", "lamp": {"type": "sphere", "emitter": {"type": "area"}}},
      "bad": {"type": "instance", "shape": {"type": "ref", "id": "g2"}}},
     "an area emitter inside shapegroup 'g2'"),
    ({"g2": {"type": "shapegroup", "inner": {"type": "instance", "shape": {"type": "ref", "id": "group"}}}},
     "nested instancing is not supported"),
    ({"bad": {"type": "instance", "shape": {"type": "ref", "id": "floor"}}},
     "bad.shape: an instance must refer to a shapegroup, got type 'rectangle'"),
])
def test_instancing_errors_name_the_element(change, message):
    d = _scene(1, extra=change)
    d["floor"]["id"] = "floor"
    with pytest.raises(SceneDictError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_dict(d)


def test_model_checks_instances():
    scene = load_dict(_scene(1))
    with pytest.raises(ValueError, match="refers to shapegroup 'nope'"):
        scene.instances = [pyclpt.Instance("nope", np.eye(4), "i")]
    with pytest.raises(ValueError, match="degenerate to_world"):
        scene.instances[0].to_world = np.diag([1.0, 1.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="emitters inside a shapegroup"):
        pyclpt.ShapeGroup("g", [pyclpt.Mesh("m", np.eye(3), [[0, 1, 2]], 0, emission=(1, 1, 1))])


@pytest.mark.parametrize("width", [2, 4])
def test_two_level_traversal_of_every_node_width(width, monkeypatch):
    """The binary and 4-wide layouts (no leaf packets) traverse instances too: the flattened scene's image
    of the same width within noise, megakernel == wavefront."""
    from pyclpt.accel import bvh

    monkeypatch.setattr(bvh, "DEFAULT_SETTINGS", bvh.BuildSettings(width=width))
    scene = load_dict(_scene(2))
    assert pack_scene(scene).defines["BVH_WIDTH"] == width
    a = pyclpt.render(scene, spp=16, seed=1)
    b = pyclpt.render(scene.flattened(), spp=16, seed=1)
    assert np.mean((a - b) ** 2) / np.mean(b**2) < 2e-3
    np.testing.assert_array_equal(pyclpt.render(scene, spp=1, seed=5, integrator="wavefront"),
                                  pyclpt.render(scene, spp=1, seed=5))


def test_top_level_boxes_hold_every_instance():
    """The instances' world boxes (from the group's BVH boxes two levels down) contain every transformed
    vertex, and the top level's root box all of them."""
    from pyclpt.accel.bvh import build_bvh
    from pyclpt.accel.instances import build_instanced

    scene = load_dict(_scene(5))
    mesh = scene.groups["group"].meshes[0]
    blas = build_bvh(mesh.positions, mesh.indices)
    mats = np.array([i.to_world for i in scene.instances])
    inst = build_instanced([blas], np.zeros(5, int), mats)
    lo, hi, _ = type(blas)(inst.tlas_nodes, blas.tris[:1], blas.tri_order[:1], 0.0).children()
    world = np.einsum("kij,vj->kvi", mats[:, :3, :3], mesh.positions.astype(np.float64)) + mats[:, None, :3, 3]
    root_lo, root_hi = np.nanmin(np.where(np.isfinite(lo[0]), lo[0], np.nan), 0), hi[0].max(0)
    assert (world.reshape(-1, 3) >= root_lo).all() and (world.reshape(-1, 3) <= root_hi).all()
    assert (world.min(1) >= inst.bounds[0]).all() and (world.max(1) <= inst.bounds[1]).all()


def test_gradients_replay_instanced_paths():
    """render_backward replays paths through the two-level traversal: the material and emitter gradients of
    the instanced scene are the flattened scene's (up to paths parted by rounding)."""
    scene = load_dict(_scene(2))
    grad = np.ones((12, 16, 3), np.float32)
    a = pyclpt.render_backward(scene, grad, spp=4, width=16, height=12)
    b = pyclpt.render_backward(scene.flattened(), grad, spp=4, width=16, height=12)
    assert a.keys() == b.keys() and "group.ball.bsdf.reflectance.value" in a
    for k in a:
        np.testing.assert_allclose(a[k], b[k], rtol=0.02, atol=1e-3, err_msg=k)
