"""Textures (cl/scene/texture.h, pyclpt/material_buffers.py), opacity masks (cl/scene/mask.h) and bump
maps (cl/scene/scene.h) on the device, checked against numpy references and analytic renders."""
from __future__ import annotations

import numpy as np
import pytest
from closed_forms import camera_rays, form_factor

import pyclpt
from pyclpt.buffers.materials import TextureTable
from pyclpt.device.program import build_program
from pyclpt.scene.model import Bitmap, Checkerboard, uv_matrix
from scenes import sensor

cl = pytest.importorskip("pyopencl")

KERNEL = r"""
#include "scene/texture.h"
__kernel void tex_lookup(__global const float* info, __global const uchar* t8, __global const float* t32,
                         int id, __global const float* uv, __global float* out) {
    int i = get_global_id(0);
    Textures tx = {info, t8, t32, 1};
    vec2 st = v2(uv[2 * i], uv[2 * i + 1]);
    vec4 c = tex_eval4(&tx, id, st);
    vstore4((float4)(c.x, c.y, c.z, c.w), i, out);
    out[4 * get_global_size(0) + i] = tex_opacity(&tx, id, st);
}
"""


def srgb_decode(x):
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def reference(tex: Bitmap, uv: np.ndarray) -> np.ndarray:
    """Mitsuba-style lookup in numpy: uv transform, rows from the top, wrap, decode, then filter."""
    rgba = tex.rgba().astype(np.float64)
    if tex.srgb:
        rgba[..., :3] = srgb_decode(np.round(rgba[..., :3] * 255) / 255)
    h, w = rgba.shape[:2]
    st = np.c_[uv, np.ones(len(uv))] @ uv_matrix(tex).T
    x = st[:, 0] * w - 0.5
    y = (1.0 - st[:, 1]) * h - 0.5

    def wrap(i, n):
        if tex.wrap_mode == "repeat":
            return i % n, np.ones_like(i, bool)
        if tex.wrap_mode == "mirror":
            r = i % (2 * n)
            return np.where(r < n, r, 2 * n - 1 - r), np.ones_like(i, bool)
        if tex.wrap_mode == "clamp":
            return np.clip(i, 0, n - 1), np.ones_like(i, bool)
        return np.clip(i, 0, n - 1), (i >= 0) & (i < n)

    def texel(ix, iy):
        cx, okx = wrap(ix, w)
        cy, oky = wrap(iy, h)
        return rgba[cy, cx] * (okx & oky)[:, None]

    if tex.filter == "nearest":
        out = texel(np.floor(x + 0.5).astype(int), np.floor(y + 0.5).astype(int))
    else:
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        ax, ay = (x - x0)[:, None], (y - y0)[:, None]
        out = ((1 - ay) * ((1 - ax) * texel(x0, y0) + ax * texel(x0 + 1, y0))
               + ay * ((1 - ax) * texel(x0, y0 + 1) + ax * texel(x0 + 1, y0 + 1)))
    out[:, :3] *= tex.scale
    return out


@pytest.fixture(scope="module")
def lookup(device):
    prog = build_program(device, source=KERNEL, name="test_textures.cl")
    kernel = cl.Kernel(prog, "tex_lookup")

    def run(textures: TextureTable, tid: int, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ctx, q = device.context, device.queue
        mf = cl.mem_flags
        bufs = [cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))
                for a in (textures.info(), textures.texels8(), textures.texels32(), uv.astype(np.float32))]
        n = uv.shape[0]
        out = np.empty(5 * n, np.float32)
        ob = cl.Buffer(ctx, mf.WRITE_ONLY, out.nbytes)
        kernel(q, (n,), None, bufs[0], bufs[1], bufs[2], np.int32(tid), bufs[3], ob)
        cl.enqueue_copy(q, out, ob)
        return out[:4 * n].reshape(n, 4), out[4 * n:]

    return run


def random_uv(n=4000, lo=-1.5, hi=2.5, seed=0):
    return np.random.default_rng(seed).uniform(lo, hi, (n, 2))


@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp", "black"])
@pytest.mark.parametrize("filt", ["bilinear", "nearest"])
@pytest.mark.parametrize("srgb", [True, False])
def test_bitmap_lookup_matches_reference(lookup, wrap, filt, srgb):
    rng = np.random.default_rng(1)
    pixels = (rng.integers(0, 256, (5, 7, 4)) / 255.0).astype(np.float32)
    tex = Bitmap(pixels, srgb=srgb, filter=filt, wrap_mode=wrap, uv_scale=(1.5, 0.75), uv_offset=(0.1, -0.2),
                 uv_skew=(0.3, -0.4), scale=(1.0, 0.5, 2.0))
    table = TextureTable()
    table.add(Checkerboard())  # the bitmap is not texture 0: ids and offsets are exercised
    tid = table.add(tex)
    uv = random_uv()
    got, opacity = lookup(table, tid, uv)
    want = reference(tex, uv)
    np.testing.assert_allclose(got, want, atol=2e-5, rtol=1e-4)
    np.testing.assert_allclose(opacity, want[:, 3], atol=2e-5)  # 4 channels: opacity is alpha


def test_float_texture_and_gray_images(lookup):
    rng = np.random.default_rng(2)
    hdr = Bitmap(rng.uniform(0, 50, (6, 4, 3)).astype(np.float32), srgb=False)
    gray = Bitmap((rng.integers(0, 256, (3, 3)) / 255.0).astype(np.float32), srgb=True)
    table = TextureTable()
    ids = [table.add(hdr), table.add(gray)]
    assert table.add(hdr) == ids[0]  # each texture is stored once
    uv = random_uv(1000)
    for tid, tex in zip(ids, (hdr, gray)):
        got, opacity = lookup(table, tid, uv)
        want = reference(tex, uv)
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(opacity, want[:, :3].mean(1), rtol=1e-4, atol=1e-5)  # no alpha: mean rgb
    assert table.texels32().size == 6 * 4 * 4 and table.texels8().size == 3 * 3 * 4


def test_image_orientation(lookup):
    """Row 0 of the image is its top, at v = 1 (the OBJ convention, which Mitsuba's OBJ loader keeps)."""
    pixels = np.zeros((2, 2, 3), np.float32)
    pixels[0, 0] = (1, 0, 0)  # top left
    pixels[1, 1] = (0, 0, 1)  # bottom right
    table = TextureTable()
    tid = table.add(Bitmap(pixels, srgb=False, filter="nearest"))
    got, _ = lookup(table, tid, np.array([[0.25, 0.75], [0.75, 0.25]]))
    np.testing.assert_allclose(got[:, :3], [[1, 0, 0], [0, 0, 1]])


def test_checkerboard(lookup):
    tex = Checkerboard((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), uv_scale=(2.0, 2.0))
    table = TextureTable()
    tid = table.add(tex)
    uv = random_uv(500)
    got, _ = lookup(table, tid, uv)
    s, t_mitsuba = uv[:, 0] * 2.0, 1.0 - uv[:, 1] * 2.0  # Mitsuba's v runs down
    same = (s - np.floor(s) > 0.5) == (t_mitsuba - np.floor(t_mitsuba) > 0.5)
    np.testing.assert_allclose(got[:, :3], np.where(same[:, None], [1.0, 0, 0], [0, 1.0, 0]))


def test_load_bitmap_srgb_and_raw(tmp_path):
    pixels = np.random.default_rng(3).uniform(0, 1, (4, 6, 3)).astype(np.float32)
    pyclpt.write_image(tmp_path / "t.png", pixels)  # written sRGB-encoded, 8 bit
    from pyclpt.scene.textures import load_bitmap

    enc = load_bitmap(tmp_path / "t.png")
    raw = load_bitmap(tmp_path / "t.png", raw=True)
    assert enc.srgb and not raw.srgb
    np.testing.assert_allclose(srgb_decode(enc.pixels.astype(np.float64)), pixels, atol=0.01)
    with pytest.raises(OSError, match="missing.png"):
        load_bitmap(tmp_path / "missing.png")


# -- opacity masks and bump maps in renders -----------------------------------------------------

FRONT = [{"look_at": {"origin": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0]}}]


def masked_scene(opacity, with_backdrop=True, light="sky") -> pyclpt.Scene:
    """A masked white quad in front of a black quad (or nothing), lit by a white sky."""
    d = {"type": "scene", "sensor": sensor(FRONT, fov=30.0, size=16),
         "front": {"type": "rectangle", "bsdf": {"type": "mask", "opacity": opacity,
                                                 "bsdf": {"type": "diffuse", "reflectance": 1.0}}}}
    if light == "sky":
        d["sky"] = {"type": "constant", "radiance": 1.0}
    if with_backdrop:
        d["back"] = {"type": "rectangle", "to_world": [{"translate": [0, 0, -1]}, {"scale": 5}],
                     "bsdf": {"type": "diffuse", "reflectance": 0.0}}
    return pyclpt.load_dict(d)


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_mask_opacity_in_closest_hit(integrator):
    """Camera rays see the white quad (under the sky: radiance 1) with probability `opacity`,
    else the black backdrop: the centre pixels average `opacity`."""
    full = pyclpt.render(masked_scene(1.0), spp=64, max_depth=2, integrator=integrator, progress=False)
    half = pyclpt.render(masked_scene(0.3), spp=256, max_depth=2, integrator=integrator, progress=False)
    none = pyclpt.render(masked_scene(0.0), spp=16, max_depth=2, integrator=integrator, progress=False)
    c = (slice(6, 10), slice(6, 10))
    assert full[c].mean() > 0.5
    assert none[c].max() == 0.0  # fully transparent: the black backdrop
    assert half[c].mean() == pytest.approx(0.3 * full[c].mean(), rel=0.08)


@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_mask_opacity_in_shadow_rays(integrator):
    """A masked quad between an area light and a white floor lets 1 - opacity of the light through."""
    def scene(opacity):
        return pyclpt.load_dict({
            "type": "scene",
            # the camera sits between the floor and the screen, so only light paths cross the screen
            "sensor": sensor([{"look_at": {"origin": [0, 0, 0.5], "target": [0, 0, 0], "up": [0, 1, 0]}}],
                             fov=20.0, size=8),
            "floor": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 1.0}},
            "screen": {"type": "rectangle", "to_world": [{"translate": [0, 0, 1]}, {"scale": 3}],
                       "bsdf": {"type": "mask", "opacity": opacity, "bsdf": {"type": "diffuse", "reflectance": 0.0}}},
            "lamp": {"type": "rectangle", "flip_normals": True, "to_world": [{"translate": [0, 0, 2]}, {"scale": 3}],
                     "emitter": {"type": "area", "radiance": 1.0}},
        })
    # depth 2: direct light only (NEE and BSDF-sampled hits of the lamp, both through the screen)
    open_ = pyclpt.render(scene(0.0), spp=64, max_depth=2, integrator=integrator, progress=False)
    part = pyclpt.render(scene(0.4), spp=256, max_depth=2, integrator=integrator, progress=False)
    closed = pyclpt.render(scene(1.0), spp=16, max_depth=2, integrator=integrator, progress=False)
    assert open_.mean() > 0.1
    assert closed.max() == 0.0
    assert part.mean() == pytest.approx(0.6 * open_.mean(), rel=0.04)


def test_mask_is_deterministic_and_same_on_both_integrators():
    scene = masked_scene(0.5)
    a = pyclpt.render(scene, spp=4, max_depth=3, seed=5, integrator="megakernel", progress=False)
    b = pyclpt.render(scene, spp=4, max_depth=3, seed=5, integrator="wavefront", progress=False)
    np.testing.assert_array_equal(a, b)



@pytest.mark.parametrize("integrator", ["megakernel", "wavefront"])
def test_mask_leaf_packets_match_scalar_leaves(monkeypatch, integrator):
    """Leaf packets (8 triangles tested at once) apply the opacity test per candidate in leaf order,
    like the scalar loop: the same image, bit for bit, in closest-hit and shadow rays."""
    from pyclpt.buffers import scene as scene_mod

    def render():
        return pyclpt.render(masked_scene(0.5, light="sky"), spp=8, max_depth=3, seed=5, integrator=integrator,
                             progress=False)

    assert scene_mod.LEAF_PACKETS
    a = render()
    monkeypatch.setattr(scene_mod, "LEAF_PACKETS", False)
    b = render()
    assert a.max() > 0
    np.testing.assert_array_equal(a, b)

def test_textured_diffuse_quad_shows_the_texture():
    """A textured emitter-free quad under a white sky: each pixel = texel albedo (x sky 1)."""
    pixels = np.zeros((2, 2, 3), np.float32)
    pixels[0] = (0.8, 0.1, 0.1)  # top row red
    pixels[1] = (0.1, 0.1, 0.8)  # bottom row blue
    tex = Bitmap(pixels, srgb=False, filter="nearest")
    scene = pyclpt.load_dict({"type": "scene", "sensor": sensor(FRONT, fov=25.0, size=16),
                              "sky": {"type": "constant", "radiance": 1.0},
                              "q": {"type": "rectangle", "bsdf": {"type": "twosided", "bsdf": {
                                  "type": "diffuse", "reflectance": {"type": "rgb", "value": [1, 1, 1]}}}}})
    scene.materials[0].reflectance = tex  # dataclass API: any colour parameter may be a texture
    img = pyclpt.render(scene, spp=64, max_depth=2, progress=False)
    top, bottom = img[3:6, 5:11].mean((0, 1)), img[10:13, 5:11].mean((0, 1))
    # Each pixel shows albedo * Le (the quad sees the whole upper hemisphere of sky). Mitsuba's
    # rectangle has uv (0, 0) at its (-1, -1) corner and reads image rows at v, so the image's top
    # row lands at the bottom of the quad; Mitsuba 3.9 renders this scene as top [0.10 0.10 0.80],
    # bottom [0.79 0.10 0.10] (checked by hand), and so does pyclpt.
    np.testing.assert_allclose(top, pixels[1, 0], rtol=0.05)
    np.testing.assert_allclose(bottom, pixels[0, 0], rtol=0.05)


def test_bump_map_tilts_the_shading_normal():
    """A height ramp h = k u along x tilts the shading normal of a quad lit from one side by a square
    lamp: the normal is Blinn's cross(dp/du + n dh/du, dp/dv + n dh/dv) = (-2 dh/du, 0, 4) (the quad
    is 2 wide in u), and a diffuse quad with that normal shows albedo Le F, F the form factor from a
    differential area with the tilted normal to the lamp (closed form): brighter when tilted towards
    the lamp, darker when tilted away, unchanged without a ramp."""
    def scene(slope):
        ramp = np.tile(np.linspace(0, 1, 64, dtype=np.float32)[None, :, None] * slope, (4, 1, 3))
        d = {"type": "scene", "sensor": sensor(FRONT, fov=20.0, size=8),
             "q": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": 0.5}},
             "lamp": {"type": "rectangle", "emitter": {"type": "area", "radiance": 5.0},
                      # Mitsuba's chaining order: translate(rotate(scale(p)))
                      "to_world": [{"translate": [3, 0, 1]}, {"rotate": {"axis": [0, 1, 0], "angle": -90}},
                                   {"scale": 0.5}]}}
        sc = pyclpt.load_dict(d)
        sc.materials[0] = pyclpt.scene.model.BumpMap(Bitmap(ramp + 0.5 * abs(slope), srgb=False, wrap_mode="clamp"),
                                               sc.materials[0])
        return sc

    c = (slice(2, 6), slice(2, 6))
    results = {}
    for slope in (0.0, -0.5, 0.5):  # -0.5: the height falls towards +x, the lamp's side
        sc = scene(slope)
        (lamp,) = [m for m in sc.meshes if m.emission is not None]
        corners = lamp.positions.astype(np.float64)
        centre = corners.mean(0)
        polygon = corners[np.argsort(np.arctan2(corners[:, 2] - centre[2], corners[:, 1] - centre[1]))]
        # the ramp's texel centres (i + 1/2) / 64 hold slope * i / 63, so dh/du = slope * 64 / 63
        normal = np.array([-2.0 * slope * 64 / 63, 0.0, 4.0])
        normal /= np.linalg.norm(normal)
        origin, dirs = camera_rays(sc, 8, 8, (np.arange(8) + 0.5) / 8)
        points = origin + (-origin[2] / dirs[..., 2])[..., None] * dirs  # on the quad, z = 0
        f = form_factor(points[c].reshape(-1, 3), normal, polygon)
        expected = 0.5 * 5.0 * f.mean()
        img = pyclpt.render(sc, spp=2048, max_depth=2, seed=1, progress=False)
        results[slope] = img[c].mean(), expected
        assert img[c].mean() == pytest.approx(expected, rel=0.03), (slope, results[slope])
    (flat, _), (toward, _), (away, _) = results[0.0], results[-0.5], results[0.5]
    assert toward > 1.5 * flat > 3 * away > 0  # expected 0.039, 0.023, 0.0058
