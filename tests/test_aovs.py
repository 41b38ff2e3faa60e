"""The G-buffer (AOVs) both integrators record beside the radiance: analytic values on analytic scenes
(a plane's depth, a sphere's normals, the motion vectors of a known camera move), the same G-buffer
from the megakernel and the wavefront, the radiance unchanged by recording it, and the multi-layer
EXR of the command line."""
from __future__ import annotations

import numpy as np
import pytest
from closed_forms import camera_rays

import pyclpt
from pyclpt.cli import main, sequence_path
from pyclpt.common.image_io import read_layers
from pyclpt.film.aovs import AOV_NAMES, OFFSCREEN, check_aovs
from pyclpt.scene.camera_path import CameraPath, Keyframe
from scenes import FRONT_CAMERA, material_zoo, sensor  # tests/ is on sys.path (conftest.py)

W, H = 24, 16


def plane_and_sphere(camera=FRONT_CAMERA) -> pyclpt.Scene:
    """A diffuse wall (reflectance 0.3) in the plane z = 0, a smooth rough-conductor sphere of radius 0.5
    at (0.6, 0, 1) in front of it, a constant sky; camera at z = 4 looking down -z."""
    return pyclpt.load_dict({
        "type": "scene",
        "sensor": sensor(camera, fov=50.0, size=W),
        "sky": {"type": "constant", "radiance": 1.0},
        "wall": {"type": "rectangle", "to_world": [{"scale": [1.5, 1.0, 1.0]}],
                 "bsdf": {"type": "diffuse", "reflectance": 0.3}},
        "ball": {"type": "sphere", "center": [0.6, 0.0, 1.0], "radius": 0.5,
                 "bsdf": {"type": "roughconductor", "material": "Au", "alpha": 0.25}},
    }, name="plane-and-sphere")


@pytest.fixture(scope="module")
def scene() -> pyclpt.Scene:
    return plane_and_sphere()


@pytest.fixture(scope="module")
def gbuffer(device, scene) -> dict[str, np.ndarray]:
    r = pyclpt.Renderer(scene, width=W, height=H, device=device, aovs=True)
    r.render(8, seed=3)
    return r.aovs()


def ray_sphere(origin, d, center, radius):
    """Distance along unit directions d (..., 3) from origin to the sphere, inf on a miss."""
    oc = origin - np.asarray(center)
    b = d @ oc
    disc = b * b - (oc @ oc - radius * radius)
    return np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)


def sphere_hits(scene, center, radius, offsets=(0.5,)):
    """Distance along each pixel's rays through ``offsets`` x ``offsets`` to the sphere (inf on a miss),
    (H, W, len(offsets)^2), and the unit normal at the first ray's hit."""
    origin, dirs = camera_rays(scene, W, H, np.array(offsets))
    t = ray_sphere(origin, dirs, center, radius)
    with np.errstate(invalid="ignore"):
        p = origin + t[..., :1] * dirs[..., 0, :]
    return t, (p - np.asarray(center)) / radius


def wall_pixels(scene, sky: bool = False) -> np.ndarray:
    """Pixels whose whole footprint (the rays through its corners) sees the wall, not the sphere (sky:
    sees neither)."""
    origin, dirs = camera_rays(scene, W, H, np.array([0.0, 1.0]))
    t = -origin[2] / dirs[..., 2]
    p = origin + t[..., None] * dirs
    on_wall = (np.abs(p[..., 0]) <= 1.5) & (np.abs(p[..., 1]) <= 1.0)
    ball = np.isfinite(ray_sphere(origin, dirs, (0.6, 0.0, 1.0), 0.5))
    return (~on_wall & ~ball).all(axis=-1) if sky else (on_wall & ~ball).all(axis=-1)


def test_depth_of_a_plane_is_its_view_distance(scene, gbuffer):
    """Wall pixels: viewZ is 4, whatever the jitter; sky pixels have depth 0 and ids -1."""
    mat = gbuffer["material_id"]
    inner = wall_pixels(scene)
    assert np.all(mat[inner] == 0) and np.all(gbuffer["mesh_id"][inner] == 0)
    assert inner.sum() > 50
    np.testing.assert_allclose(gbuffer["depth"][inner], 4.0, rtol=1e-5)
    sky = wall_pixels(scene, sky=True)
    assert sky.sum() > 20 and np.all(mat[sky] == -1)
    assert np.all(gbuffer["depth"][sky] == 0) and np.all(gbuffer["prim_id"][sky] == -1)
    assert np.all(gbuffer["normal"][sky] == 0) and np.all(gbuffer["mesh_id"][sky] == -1)


def test_normals_of_a_sphere(scene, gbuffer):
    """Pixels well inside the sphere's disc: the averaged shading normal points along the analytic normal
    of the pixel-centre ray (the samples jitter within the pixel, the sphere is tessellated)."""
    centre, normal = sphere_hits(scene, (0.6, 0.0, 1.0), 0.5)
    normal = normal[:, :, 0] if normal.ndim == 4 else normal
    corners, _ = sphere_hits(scene, (0.6, 0.0, 1.0), 0.5, (0.0, 1.0))
    inside = np.isfinite(corners).all(axis=-1)  # the rays of the pixel's corners hit too
    assert inside.sum() > 10
    n = gbuffer["normal"][inside]
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    assert np.min(np.sum(n * normal[inside], axis=-1)) > 0.99
    assert np.all(gbuffer["mesh_id"][inside] == 1) and np.all(gbuffer["material_id"][inside] == 1)
    np.testing.assert_allclose(gbuffer["roughness"][inside], 0.25, rtol=1e-6)
    # the wall: diffuse, roughness 1, albedo its reflectance, normal +z
    wall = wall_pixels(scene)
    np.testing.assert_allclose(gbuffer["roughness"][wall], 1.0)
    np.testing.assert_allclose(gbuffer["albedo"][wall], 0.3, rtol=1e-6)
    np.testing.assert_allclose(gbuffer["normal"][wall], np.broadcast_to([0, 0, 1.0], (wall.sum(), 3)), atol=1e-6)


def test_hit_distance_of_the_second_ray(device):
    """A wall alone under the sky: every second ray leaves the scene (hitdist 0). Inside a closed sphere of
    radius 3 seen from its centre: every second ray hits, at a chord length in (0, 6]."""
    _, open_sky = pyclpt.render(plane_and_sphere(), spp=2, width=W, height=H, device=device, aovs=["hitdist"])
    wall_only = pyclpt.load_dict({
        "type": "scene", "sensor": sensor(FRONT_CAMERA, fov=20.0, size=W),
        "sky": {"type": "constant", "radiance": 1.0},
        "wall": {"type": "rectangle", "to_world": [{"scale": 5.0}], "bsdf": {"type": "diffuse"}}})
    _, aov = pyclpt.render(wall_only, spp=2, width=W, height=H, device=device, aovs=["hitdist", "depth"])
    assert np.all(aov["depth"] > 0) and np.all(aov["hitdist"] == 0)
    from scenes import interior_furnace

    _, inside = pyclpt.render(interior_furnace(0.5), spp=2, width=W, height=H, device=device, aovs=["hitdist"])
    assert np.all(inside["hitdist"] > 0) and np.all(inside["hitdist"] <= 6.0 + 1e-4)
    assert np.any(open_sky["hitdist"] > 0)  # the sphere's reflections reach the wall


def test_motion_of_a_camera_translation(device):
    """The camera moves by d along +x between two frames: every wall point's motion vector is
    d W / (2 z tan(fov/2)) pixels in x and 0 in y (z = 4, the wall's view distance); a point at infinity
    (the sky) does not move under a translation; a frame without a move has zero motion (the G-buffer
    averages the frames since the move's reset: half the motion after two)."""
    scene = plane_and_sphere()
    pr = pyclpt.ProgressiveRenderer(scene, width=W, height=H, device=device, aovs=["motion", "depth", "material_id"])
    pr.step()
    assert np.all(pr.aovs()["motion"] == 0)
    d = 0.1
    m = np.array(scene.camera.to_world)
    m[0, 3] += d
    pr.set_camera(pyclpt.Camera(m, scene.camera.fov, scene.camera.fov_axis))
    pr.step()
    a = pr.aovs()
    wall = (a["material_id"] == 0)
    tx = np.tan(np.radians(50.0) / 2)
    np.testing.assert_allclose(a["motion"][wall][:, 0], d * W / (2 * 4.0 * tx), rtol=1e-3)
    np.testing.assert_allclose(a["motion"][wall][:, 1], 0.0, atol=1e-3)
    sky = a["material_id"] == -1
    assert sky.any() and np.all(np.abs(a["motion"][sky]) < 1e-3)
    pr.step()
    np.testing.assert_array_equal(pr.aovs()["motion"], a["motion"] / 2)


def test_motion_of_a_rotation_matches_the_projection(device):
    """An orbit step of 30 degrees: each wall pixel's motion vector, averaged over 64 jittered samples
    (so over the pixel's footprint), equals the analytic projection through the previous camera of the
    wall point the pixel's centre ray sees, minus the pixel centre."""
    scene = plane_and_sphere()
    path = CameraPath.orbit(scene.camera, 30.0, 2, target=(0.0, 0.0, 0.0))
    scene.camera = path.camera(1)
    r = pyclpt.Renderer(scene, width=W, height=H, device=device, aovs=["motion", "material_id"])
    r.scene_buffers.refresh_camera(previous=path.camera(0))
    r.render(64, seed=2)
    a = r.aovs()
    prev, cur = path.camera(0), path.camera(1)
    origin, dirs = camera_rays(pyclpt.Scene(meshes=scene.meshes, materials=scene.materials, camera=cur), W, H,
                               np.array([0.5]))
    d = dirs[:, :, 0]
    t = -origin[2] / d[..., 2]
    p = origin + t[..., None] * d
    o, fwd, right, up = prev.basis(W, H)
    q = p - o
    z = q @ fwd
    px = ((q @ right) / (right @ right * z) + 1) * 0.5 * W
    py = (1 - (q @ up) / (up @ up * z)) * 0.5 * H
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    expected = np.stack([px - xs, py - ys], axis=-1)
    wall = wall_pixels(scene)
    assert wall.sum() > 50
    assert np.abs(expected[wall]).max() > 1.0  # the move is visible
    # 64 jittered samples estimate the footprint's mean to a few hundredths of a pixel
    np.testing.assert_allclose(a["motion"][wall], expected[wall], atol=0.06)
    assert np.abs(a["motion"][wall] - expected[wall]).mean() < 0.01


def test_behind_the_previous_camera_is_offscreen(device):
    """A point the previous camera had behind it gets AOV_OFFSCREEN."""
    scene = plane_and_sphere()
    pr = pyclpt.ProgressiveRenderer(scene, width=W, height=H, device=device, aovs=["motion", "material_id"])
    pr.step()
    pr.set_camera(pyclpt.Camera.look_at((0, 0, -4), (0, 0, 0), fov=50.0))  # the back of the wall
    pr.step()
    m = pr.aovs()["motion"]
    assert np.any(m == OFFSCREEN)


@pytest.mark.parametrize("variant", [dict(integrator="wavefront"), dict(integrator="wavefront", layout="aos"),
                                     dict(integrator="wavefront", tail_paths=0),
                                     dict(integrator="wavefront", wave_size=700, tail_paths=300)],
                         ids=["soa", "aos", "no-tail", "small-waves"])
def test_megakernel_and_wavefront_give_the_same_gbuffer(device, variant):
    """Every AOV, bit for bit, on the scene with every material (specular chains before the albedo,
    masks, textures, bump maps), and the radiance unchanged by recording the G-buffer."""
    scene = material_zoo(16)
    mega = pyclpt.Renderer(scene, device=device, aovs=True)
    ref = mega.render(3, seed=5)
    ref_aovs = mega.aovs()
    r = pyclpt.Renderer(scene, device=device, aovs=True, **variant)
    np.testing.assert_array_equal(r.render(3, seed=5), ref)
    got = r.aovs()
    for name in AOV_NAMES:
        np.testing.assert_array_equal(got[name], ref_aovs[name], err_msg=name)
    plain = pyclpt.Renderer(scene, device=device, **variant).render(3, seed=5)
    np.testing.assert_array_equal(plain, ref)
    # the specular chain: the smooth gold cube (material 2) has roughness 0 and passes the albedo on from
    # what it reflects (some of its pixels see the sky: albedo 0, others a surface); rough copper: 0.2
    # (by the median: a pixel on an object's edge averages samples of the object and of what is behind)
    gold, copper = ref_aovs["material_id"] == 2, ref_aovs["material_id"] == 3
    assert gold.sum() > 3 and copper.sum() > 3
    assert np.median(ref_aovs["roughness"][gold]) == 0
    assert np.median(ref_aovs["roughness"][copper]) == pytest.approx(0.2)
    assert np.any(ref_aovs["albedo"][gold].max(axis=-1) > 0)


def test_aovs_average_the_samples_in_sample_order(device, scene):
    """render(N) averages the N samples' records; the ids are the first sample's."""
    r = pyclpt.Renderer(scene, width=W, height=H, device=device, aovs=["depth", "prim_id"])
    r.render(4, seed=9)
    four = r.aovs()
    singles = []
    for s in range(4):
        r.render(1, seed=9, first_sample=s)
        singles.append(r.aovs())
    np.testing.assert_allclose(four["depth"], np.mean([x["depth"] for x in singles], axis=0), rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(four["prim_id"], singles[0]["prim_id"])


def test_aov_names_are_checked(device, scene):
    assert check_aovs(True) == AOV_NAMES
    assert check_aovs("albedo, depth,albedo") == ("albedo", "depth")
    with pytest.raises(ValueError, match="unknown AOV 'colour'.*albedo"):
        pyclpt.Renderer(scene, width=W, height=H, device=device, aovs=["colour"])
    with pytest.raises(TypeError, match="AOV names are strings"):
        check_aovs([3])
    with pytest.raises(ValueError, match="records no AOVs"):
        pyclpt.Renderer(scene, width=W, height=H, device=device).aovs()


def test_cli_writes_a_multilayer_exr(tmp_path, device, capsys):
    out = tmp_path / "g.exr"
    assert main(["render", "cornell-box", "--spp", "2", "--width", "20", "--height", "16", "--device", "pocl",
                 "--aov", "albedo,normal,depth,motion,material_id", "-o", str(out), "--quiet"]) == 0
    layers = read_layers(out)
    assert {"R", "G", "B", "albedo.R", "albedo.G", "albedo.B", "normal.X", "normal.Y", "normal.Z", "depth.Z",
            "motion.X", "motion.Y", "material_id.Y"} == set(layers)
    _, api = pyclpt.render("cornell-box", spp=2, width=20, height=16, device=device, aovs=["depth", "normal"])
    np.testing.assert_array_equal(layers["depth.Z"], api["depth"])
    np.testing.assert_array_equal(layers["normal.Y"], api["normal"][..., 1])
    assert main(["render", "cornell-box", "--spp", "1", "--width", "8", "--height", "8", "--aov", "albedo",
                 "-o", str(tmp_path / "g.png")]) == 1
    assert "multi-layer OpenEXR" in capsys.readouterr().err
    assert main(["render", "cornell-box", "--spp", "1", "--width", "8", "--height", "8", "--aov", "albedo,speed",
                 "-o", str(out)]) == 1
    assert "unknown AOV 'speed'" in capsys.readouterr().err


def test_cli_orbit_sequence(tmp_path, device):
    """--orbit over --frames with --sequence writes one image per frame; the frames differ (the camera
    moved), and the last equals a render from the orbit's last camera."""
    out = tmp_path / "orbit_##.exr"
    assert main(["render", "cornell-box", "--frames", "3", "--orbit", "20", "--sequence", "--width", "16",
                 "--height", "12", "--device", "pocl", "-o", str(out), "--quiet"]) == 0
    files = [tmp_path / f"orbit_{k:02d}.exr" for k in range(3)]
    assert all(f.is_file() for f in files)
    imgs = [pyclpt.read_image(f) for f in files]
    assert not np.array_equal(imgs[0], imgs[2])
    scene = pyclpt.load("cornell-box")
    last = CameraPath.orbit(scene, 20, 3).camera(2)
    scene.camera = last
    # frame 2 of the run is sample index 0 after the reset the move made (no denoiser)
    np.testing.assert_array_equal(imgs[2], pyclpt.render(scene, spp=1, width=16, height=12, device=device))
    assert sequence_path("a.exr", 7) == "a_0007.exr" and sequence_path("x_###_y.png", 12) == "x_012_y.png"


def test_camera_path_interpolation():
    a = pyclpt.Camera.look_at((0, 0, 4), (0, 0, 0), fov=40.0)
    b = pyclpt.Camera.look_at((4, 0, 0), (0, 0, 0), fov=60.0)
    path = CameraPath([Keyframe(0, a), Keyframe(10, b)])
    np.testing.assert_allclose(path.camera(0).to_world, a.to_world, atol=1e-12)
    np.testing.assert_allclose(path.camera(10).to_world, b.to_world, atol=1e-12)
    np.testing.assert_allclose(path.camera(25).to_world, b.to_world, atol=1e-12)
    mid = path.camera(5)
    assert mid.fov == pytest.approx(50.0)
    np.testing.assert_allclose(mid.to_world[:3, 3], (2, 0, 2))
    # the rotation half way: looking along the mean of the two directions (slerp of 90 degrees)
    fwd = mid.to_world[:3, 2]
    np.testing.assert_allclose(fwd, -np.array([1, 0, 1]) / np.sqrt(2), atol=1e-9)
    assert len(path) == 11
    orbit = CameraPath.orbit(a, 90.0, 4, target=(0, 0, 0))
    np.testing.assert_allclose(orbit.camera(3).to_world[:3, 3], (4, 0, 0), atol=1e-9)
    for k in range(4):  # the orbit keeps its distance to the target and looks at it
        m = orbit.camera(k).to_world
        assert np.linalg.norm(m[:3, 3]) == pytest.approx(4.0)
        np.testing.assert_allclose(m[:3, 2], -m[:3, 3] / 4.0, atol=1e-9)
    with pytest.raises(ValueError, match="times must increase"):
        CameraPath([Keyframe(1, a), Keyframe(1, b)])
    with pytest.raises(ValueError, match="no look-at target"):
        CameraPath.orbit(a, 10, 3)
    with pytest.raises(ValueError, match="interpolation"):
        CameraPath([Keyframe(0, a)], interpolation="cubic")


def test_emission_is_what_the_first_vertex_gathers(device):
    """max_depth 1 renders exactly what the camera ray's first vertex emits (or the sky it sees), which is
    the emission AOV, bit for bit, on both integrators."""
    for integrator in ("megakernel", "wavefront"):
        image, aov = pyclpt.render("cornell-box", spp=1, max_depth=1, width=W, height=H, device=device,
                                   integrator=integrator, aovs=["emission"])
        assert image.max() > 1.0  # the light is in view
        np.testing.assert_array_equal(aov["emission"], image)
    _, lit = pyclpt.render(plane_and_sphere(), spp=1, width=W, height=H, device=device, aovs=["emission", "depth"])
    sky = lit["depth"] == 0
    assert sky.any() and np.all(lit["emission"][sky] == 1.0) and np.all(lit["emission"][~sky] == 0.0)


def test_layout_matches_the_header():
    """pyclpt/film/aovs.py and cl/film/aovs.h describe the same channels."""
    import re

    from pyclpt.device.program import cl_dir
    from pyclpt.film import aovs

    header = dict(re.findall(r"#define (AOV_\w+) (\d+)\b", (cl_dir() / "film" / "aovs.h").read_text()))
    for name in ("AOV_ALBEDO", "AOV_NORMAL", "AOV_ROUGHNESS", "AOV_DEPTH", "AOV_HITDIST", "AOV_MOTION",
                 "AOV_EMISSION", "AOV_PRIM", "AOV_MATERIAL", "AOV_COUNT", "AOV_FLOATS"):
        assert int(header[name]) == getattr(aovs, name), name


def test_albedo_of_a_twosided_pair_is_the_side_seen(device):
    """twosided with two BSDFs: the albedo (and the material id) of the side the camera sees. Two rectangles
    with the same pair, the left one facing the camera (red front), the right one facing away (blue back)."""
    pair = {"type": "twosided", "id": "pair", "f": {"type": "diffuse", "reflectance": [0.8, 0.1, 0.1]},
            "b": {"type": "diffuse", "reflectance": [0.1, 0.2, 0.8]}}
    scene = pyclpt.load_dict({
        "type": "scene",
        "sensor": sensor(FRONT_CAMERA, fov=50.0, size=W),
        "sky": {"type": "constant", "radiance": 1.0},
        "pair": pair,
        "left": {"type": "rectangle", "bsdf": {"type": "ref", "id": "pair"},
                 "to_world": [{"scale": [0.7, 1.0, 1.0]}, {"translate": [-0.8, 0, 0]}]},
        "right": {"type": "rectangle", "bsdf": {"type": "ref", "id": "pair"}, "flip_normals": True,
                  "to_world": [{"scale": [0.7, 1.0, 1.0]}, {"translate": [0.8, 0, 0]}]},
    })
    for integrator in ("megakernel", "wavefront"):
        img, aov = pyclpt.render(scene, spp=1, width=W, height=W, device=device, integrator=integrator,
                                 aovs=["albedo", "material_id"])
        row = W // 2
        np.testing.assert_allclose(aov["albedo"][row, W // 2 - 5], (0.8, 0.1, 0.1), rtol=1e-6)
        np.testing.assert_allclose(aov["albedo"][row, W // 2 + 5], (0.1, 0.2, 0.8), rtol=1e-6)
        ids = aov["material_id"][row]
        assert ids[W // 2 - 5] == 0 and ids[W // 2 + 5] == 1  # 1: the back's record, after the scene's one
        left, right = img[row, W // 2 - 5], img[row, W // 2 + 5]  # the sky lights both sides alike
        np.testing.assert_allclose(left / left[0], (1.0, 0.125, 0.125), rtol=1e-5)
        np.testing.assert_allclose(right / right[2], (0.125, 0.25, 1.0), rtol=1e-5)


def test_roughness_of_an_anisotropic_material(device):
    """The G-buffer's roughness of an anisotropic rough conductor: sqrt(alpha_u alpha_v)."""
    scene = pyclpt.load_dict({
        "type": "scene", "sensor": sensor(FRONT_CAMERA, fov=20.0, size=8),
        "wall": {"type": "rectangle", "bsdf": {"type": "roughconductor", "alpha_u": 0.1, "alpha_v": 0.4}},
    })
    _, aov = pyclpt.render(scene, spp=1, width=8, height=8, device=device, aovs=["roughness"])
    np.testing.assert_allclose(aov["roughness"], 0.2, rtol=1e-6)
