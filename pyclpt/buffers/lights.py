"""Emitters -> the `lights` and `light_data` buffers of ``cl/scene/lights.h``, and the
per-resolution constants (camera, environment) of ``cl/scene/scene.h``.

Emitters are the emissive triangles (leaf order), then the scene's other lights (point,
directional, spot, in their order), then the environment (constant or map). One is chosen by the
rule ``SELECTION`` names (:func:`selection_pmf`); the default, "distant-uniform": each distant emitter
(directional light, environment) is as likely as in Mitsuba 3's uniform choice (1 / the number of
emitters, an emitting shape counting once), and the finite emitters (shapes, point and spot lights)
share the rest in proportion to an estimate of their power. A distant emitter's power is what crosses
the scene's bounding sphere, which says little of what it sends where the camera looks (measured: 3x
to 7x Mitsuba's noise where power alone chose, bench/evaluations/light_noise.py); a finite emitter's
estimate is its emitted power, which uniform choice would throw away (1.4x the noise on the 13 lights
of the shared staircase2). The estimates:
- triangle: area * luminance of the radiance (times the mean of its texture, when it has one);
- point light (intensity I, W/sr): 4 pi * luminance(I);
- directional light (irradiance E): pi r^2 * luminance(E), r the radius of the scene's bounding
  sphere (the power through the scene's cross-section, as Mitsuba estimates it);
- spot light: luminance(I) times the solid angle of a cone halfway between beam and cutoff (times
  the mean of its texture);
- environment (constant or map): pi^2 r^2 * mean radiance over the sphere, r the
  radius of the scene's bounding sphere (the power a distant emitter sends through
  the scene's cross-section, ~ pi r^2 * pi L for a constant L).

(For each, the larger of luminance and the mean of rgb, so that a saturated
colour with little luminance is still sampled.)

Environment maps follow Mitsuba 3's lat-long convention; the layout of their
sampling tables is documented in ``cl/scene/lights.h``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pyclpt.buffers.materials import TextureTable
from pyclpt.buffers.rfilter import CONST_FILTER_RADIUS, FILTER_CONSTS, filter_consts
from pyclpt.scene.model import Bitmap, Camera, Checkerboard, DirectionalLight, Envmap, Scene, SpotLight

#: How an emitter is chosen (:func:`selection_pmf`): "distant-uniform" (the default, the module docstring),
#: "power" or "uniform" (Mitsuba 3's rule). Measured against Mitsuba 3: bench/evaluations/light_noise.py,
#: docs/architecture.md "Light selection".
SELECTION = "distant-uniform"
SELECTIONS = ("distant-uniform", "power", "uniform")

LIGHT_STRIDE = 12
CONST_COUNT = 169  # CONST_COUNT of cl/scene/scene.h
CONST_CROP = 164  # CONST_CROP_X, _Y, _WIDTH, _HEIGHT
CONST_FILM_PAD = 168  # a splatting film's margin (ReconstructionFilter.splat_reach)
CAMERA_KINDS = {"perspective": 0, "thinlens": 1, "orthographic": 2}  # CAMERA_* of cl/scene/scene.h


def camera_kind(camera: Camera) -> int:
    """The CAMERA_* the kernels compile for (-DSCENE_CAMERA): a thin lens without aperture is a pinhole."""
    if camera.kind == "thinlens" and not camera.aperture_radius > 0:
        return CAMERA_KINDS["perspective"]
    return CAMERA_KINDS[camera.kind]
# record offsets and types (cl/scene/lights.h)
LIGHT_PRIM, LIGHT_PMF, LIGHT_AREA, LIGHT_RADIANCE, LIGHT_CDF, LIGHT_TYPE, LIGHT_TEXTURE = 0, 1, 2, 3, 6, 7, 8
LIGHT_TRIANGLE, LIGHT_POINT, LIGHT_CONSTANT, LIGHT_ENVMAP, LIGHT_DIRECTIONAL, LIGHT_SPOT = 0, 1, 2, 3, 4, 5
ENV_HEADER = 16
ENV_TEXTURE = 11  # the texture id of an environment map's texels in its light_data block
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])


def luminance(c) -> float:
    r, g, b = (float(x) for x in c)  # in double: radiance near FLT_MAX must not overflow
    return 0.212671 * r + 0.715160 * g + 0.072169 * b


@dataclass
class LightArrays:
    lights: np.ndarray  # (L, LIGHT_STRIDE) float32
    light_data: np.ndarray  # float32 tables (point-light positions, environment-map CDFs)
    env_light: int  # index of the environment in lights, or -1
    tri_light: np.ndarray  # (T,) int32: light index of each leaf-order triangle, or -1
    has_textures: bool = False  # an emitter's radiance is textured (-DSCENE_HAS_EMITTER_TEXTURES)

    @property
    def kinds(self) -> int:
        """Bit LIGHT_* set for every emitter kind present (-DSCENE_LIGHTS)."""
        kinds = 0
        for t in np.unique(self.lights[:, LIGHT_TYPE].astype(np.int64)):
            kinds |= 1 << int(t)
        return kinds


def _int_bits(i: int) -> np.float32:
    return np.array([i], np.int32).view(np.float32)[0]


def texture_mean(tex: Bitmap | Checkerboard) -> np.ndarray:
    """The mean linear rgb of a texture over its image (or its two squares), its scale applied."""
    if isinstance(tex, Checkerboard):
        return 0.5 * (np.asarray(tex.color0, np.float64) + np.asarray(tex.color1, np.float64)) * tex.scale
    rgb = tex.rgba()[..., :3].astype(np.float64)
    if tex.srgb:
        rgb = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return rgb.mean(axis=(0, 1)) * tex.scale


def spot_frame(direction) -> np.ndarray:
    """A frame (3, 3), columns x, y, z, with z the spot light's axis (for a texture given without one)."""
    z = np.asarray(direction, np.float64)
    x = np.cross([0.0, 1.0, 0.0] if abs(z[1]) < 0.9 else [1.0, 0.0, 0.0], z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def envmap_rotation(env: Envmap) -> np.ndarray:
    """The rotation (3x3) of an environment map's ``to_world``: a uniform scale is divided out
    (a reflection is kept); a shear, a non-uniform scale or a singular matrix is an error."""
    m = np.asarray(env.to_world, np.float64)[:3, :3]
    where = f"environment map {env.name!r}"
    if not np.all(np.isfinite(m)):
        raise ValueError(f"{where}: to_world holds NaN or infinite values")
    s = np.linalg.svd(m, compute_uv=False)
    if not s[-1] > 1e-12 * max(s[0], 1e-300):
        raise ValueError(f"{where}: to_world is singular")
    if s[0] - s[-1] > 1e-4 * s[0]:
        raise ValueError(f"{where}: to_world must be a rotation (with at most a uniform scale), "
                         f"its singular values are {np.round(s, 6).tolist()}")
    u, _, vt = np.linalg.svd(m)
    return u @ vt


def envmap_cells(pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sampling cells of a lat-long map (H, W, 3) under Mitsuba 3's convention (cl/scene/lights.h).

    Returns (lum_weight (H-1, W), rgb_weight (H-1, W, 3), cell_omega (H-1,)): the mean of the 4 corner
    texels of each cell times the cell's solid angle (luminance, rgb), and the solid angle of one
    cell of each row. Their sums approximate the integral of the map over the sphere."""
    px = np.asarray(pixels, np.float64)
    h, w = px.shape[:2]
    theta = np.pi * np.arange(h) / (h - 1)
    # solid angle of a cell between rows r and r+1: (2 pi / W) (cos t_r - cos t_{r+1}), in a stable form
    mid, half = 0.5 * (theta[1:] + theta[:-1]), 0.5 * (theta[1:] - theta[:-1])
    cell_omega = (2.0 * np.pi / w) * 2.0 * np.sin(mid) * np.sin(half)
    nxt = np.roll(px, -1, axis=1)  # column c + 1 (periodic)
    corners = 0.25 * (px[:-1] + nxt[:-1] + px[1:] + nxt[1:])  # (H-1, W, 3)
    rgb_weight = corners * cell_omega[:, None, None]
    lum_weight = rgb_weight @ LUMINANCE
    return lum_weight, rgb_weight, cell_omega


def _cdf(weights: np.ndarray) -> np.ndarray:
    """Inclusive CDF along the last axis (float64 sums); all-zero rows become uniform."""
    c = np.cumsum(weights, axis=-1)
    total = c[..., -1:]
    n = weights.shape[-1]
    uniform = np.arange(1, n + 1, dtype=np.float64) / n
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(total > 0, c / np.where(total > 0, total, 1.0), uniform)
    out[..., -1] = 1.0
    return out


def guide_size(n: int) -> int:
    """The number of intervals of a CDF's guide table (cdf_guide): a power of two near n / 8, 1 to 1024."""
    return 1 << int(np.clip(np.round(np.log2(max(n, 1) / 8.0)), 0, 10))


def cdf_guide(cdf: np.ndarray, g: int) -> np.ndarray:
    """The guide table (..., g + 1) of inclusive float32 CDFs ``cdf`` (..., n): entry k is the bin that u = k / g
    falls in (the first i with u < cdf[i], the last bin where none), so a u in [k / g, (k + 1) / g) falls in a bin
    between entries k and k + 1 (cl/scene/lights.h, cdf_search_guided): the binary search of an environment map's
    marginal CDF shrinks to its few bins there, with the same result."""
    c = np.asarray(cdf, np.float32)
    n = c.shape[-1]
    u = (np.arange(g + 1, dtype=np.float64) / g).astype(np.float32)  # exact: g is a power of two
    flat = c.reshape(-1, n)
    out = np.empty((flat.shape[0], g + 1), np.int32)
    for r in range(flat.shape[0]):
        out[r] = np.minimum(np.searchsorted(flat[r], u, side="right"), n - 1)
    return out.reshape(*c.shape[:-1], g + 1)


def alias_tables(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Walker alias tables of each row of ``weights`` (R, n), >= 0: (q (R, n), alias (R, n) int32, pmf (R, n)), all
    float64 but alias. Cell i of a row is drawn as u n = i + f: i itself where f < q[i], else alias[i], which gives
    cell i the probability pmf[i] (an all-zero row is uniform). Vose's construction, every row at once: the cells
    below the mean (deficit 1 - n pmf) and those above it (excess n pmf - 1) are laid out in index order along one
    axis each, a deficit is aliased to the cell whose excess holds its start, and a cell above the mean whose excess
    a deficit overruns owes the overrun to the next one (its own q is 1 - overrun)."""
    wts = np.asarray(weights, np.float64)
    rows, n = wts.shape
    total = wts.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        pmf = np.where(total > 0, wts / np.where(total > 0, total, 1.0), 1.0 / n)
    scaled = pmf * n
    q = np.ones((rows, n))
    alias = np.tile(np.arange(n, dtype=np.int32), (rows, 1))
    small = scaled < 1.0
    big_r, big_c = np.nonzero(~small)
    small_r, small_c = np.nonzero(small)
    if small_r.size == 0 or big_r.size == 0:
        return q, alias, pmf
    off = (np.arange(rows) * (n + 2.0))[:, None]  # the rows apart on one axis: each sums to less than n
    deficit_end = (np.cumsum(np.where(small, 1.0 - scaled, 0.0), axis=1) + off)[small_r, small_c]
    excess_end = (np.cumsum(np.where(small, 0.0, scaled - 1.0), axis=1) + off)[big_r, big_c]
    last = np.full(rows, -1)
    last[big_r] = np.arange(big_r.size)  # each row's last cell above the mean (rows without one keep q = 1)
    start = deficit_end - (1.0 - scaled[small_r, small_c])
    j = np.minimum(np.searchsorted(excess_end, start, side="right"), last[small_r])
    ok = j >= 0
    q[small_r[ok], small_c[ok]] = scaled[small_r[ok], small_c[ok]]
    alias[small_r[ok], small_c[ok]] = big_c[j[ok]]
    k = np.searchsorted(deficit_end, excess_end, side="right")  # the deficit that holds each excess's end
    kk = np.minimum(k, small_r.size - 1)
    nxt = np.searchsorted(excess_end, excess_end, side="right")
    over = (k < small_r.size) & (small_r[kk] == big_r) & (start[kk] < excess_end) & (nxt <= last[big_r])
    i = np.flatnonzero(over)
    q[big_r[i], big_c[i]] = 1.0 - (deficit_end[kk[i]] - excess_end[i])
    alias[big_r[i], big_c[i]] = big_c[nxt[i]]
    return q, alias, pmf


def pack_envmap(env: Envmap, textures: TextureTable) -> tuple[np.ndarray, float]:
    """The light_data block of an environment map (cl/scene/lights.h) and its estimated mean radiance
    over the sphere (for the light-selection power); the texels go to ``textures``."""
    px = np.asarray(env.pixels)
    where = f"environment map {env.name!r}"
    if px.ndim != 3 or px.shape[2] != 3 or px.shape[0] < 2 or px.shape[1] < 2:
        raise ValueError(f"{where}: expected an (H, W, 3) image with H, W >= 2, got shape {px.shape}")
    if not np.all(np.isfinite(px)) or px.min() < 0:
        raise ValueError(f"{where}: values must be finite and >= 0")
    scale = float(env.scale)
    if not (np.isfinite(scale) and scale >= 0):
        raise ValueError(f"{where}: scale must be finite and >= 0, got {env.scale}")
    rot = envmap_rotation(env)
    h, w = px.shape[:2]
    lum_w, rgb_w, cell_omega = envmap_cells(px)
    marginal = _cdf(lum_w.sum(axis=1))
    q, alias, pmf = alias_tables(lum_w)
    row_cos = np.cos(np.pi * np.arange(h) / (h - 1))
    row_cos[0], row_cos[-1] = 1.0, -1.0
    tex = textures.add(Bitmap(px.astype(np.float32), name=env.name, srgb=False, filter="bilinear",
                              wrap_mode="repeat"))
    header = np.zeros(ENV_HEADER, np.float64)
    header[0:9] = rot.reshape(-1)
    g_rows = guide_size(h - 1)
    header[9], header[10], header[11], header[12], header[13] = w, h, tex, scale, g_rows
    # each cell's alias entry: q, the alias (int bits), its pmf and the alias's, 16 bytes (one cache line's quarter)
    entries = np.empty((h - 1, w, 4), np.float32)
    entries[..., 0] = q
    entries[..., 1] = alias.view(np.float32)
    entries[..., 2] = pmf
    entries[..., 3] = np.take_along_axis(pmf, alias, axis=1)
    rest = np.concatenate([marginal, cell_omega, row_cos]).astype(np.float32)
    block = np.concatenate([header.astype(np.float32), entries.reshape(-1), rest,
                            cdf_guide(marginal, g_rows).view(np.float32)])  # cdf_guide: of the float32 CDF
    integral = scale * max(float(lum_w.sum()), float(rgb_w.sum()) / 3.0)
    return block, integral / (4.0 * np.pi)


def pack_lights(scene: Scene, tris: np.ndarray, tri_emission: np.ndarray, bounds: np.ndarray,
                textures: TextureTable, tri_mesh: np.ndarray | None = None) -> LightArrays:
    """Emitters of ``scene``: ``tris`` (T, 9) and ``tri_emission`` (T, 3) are in leaf order, as is
    ``tri_mesh`` (T,), the mesh of each triangle (for emission textures; None: none)."""
    tri_light = np.full(tris.shape[0], -1, np.int32)
    emissive = np.flatnonzero(tri_emission.max(axis=1) > 0)
    area = 0.5 * np.linalg.norm(np.cross(tris[emissive, 3:6], tris[emissive, 6:9]), axis=1)
    keep = area > 0
    emissive, area = emissive[keep], area[keep]
    em64 = tri_emission[emissive].astype(np.float64)  # double: radiance near FLT_MAX must not overflow
    tri_tex = np.full(len(emissive), -1, np.int32)
    if tri_mesh is not None:
        for i, mesh in enumerate(scene.meshes):
            if mesh.emission_texture is not None:
                mine = tri_mesh[emissive] == i
                tri_tex[mine] = textures.add(mesh.emission_texture)
                em64[mine] *= texture_mean(mesh.emission_texture)
    lum = np.maximum(em64 @ LUMINANCE, em64.mean(axis=1))
    tri_records = np.zeros((len(emissive), LIGHT_STRIDE), np.float32)
    tri_records[:, LIGHT_PRIM] = emissive.astype(np.int32).view(np.float32)
    tri_records[:, LIGHT_AREA] = area
    tri_records[:, LIGHT_RADIANCE:LIGHT_RADIANCE + 3] = tri_emission[emissive]
    tri_records[:, LIGHT_TYPE] = LIGHT_TRIANGLE
    tri_records[:, LIGHT_TEXTURE] = tri_tex.view(np.float32)
    has_textures = bool((tri_tex >= 0).any())
    tri_light[emissive] = np.arange(len(emissive), dtype=np.int32)
    records: list[np.ndarray] = []  # the emitters after the triangles
    power: list[float] = list(area * lum)
    # the emitter each record belongs to (a triangle's mesh, else itself) and whether it is distant
    group: list[int] = list(tri_mesh[emissive]) if tri_mesh is not None else list(range(len(emissive)))
    next_group = (max(group) + 1) if group else 0
    distant: list[bool] = [False] * len(group)
    data: list[np.ndarray] = []
    data_size = 0

    def add_data(block: np.ndarray, align: int = 1) -> np.float32:
        """``block`` appended to light_data at an offset that is a multiple of ``align`` floats; the offset."""
        nonlocal data_size
        if data_size % align:
            data.append(np.zeros(align - data_size % align, np.float32))
            data_size += data[-1].size
        offset = data_size
        data.append(np.asarray(block, np.float32).reshape(-1))
        data_size += data[-1].size
        if data_size >= 2**31:
            raise ValueError("the scene's emitter tables exceed 2^31 floats")
        return _int_bits(offset)

    radius = max(0.5 * float(np.linalg.norm(np.asarray(bounds[1], np.float64) - bounds[0])), 1e-3)
    for k, light in enumerate(scene.lights):
        rec = np.zeros(LIGHT_STRIDE, np.float32)
        rec[LIGHT_TEXTURE] = _int_bits(-1)
        if isinstance(light, DirectionalLight):
            value = np.asarray(light.irradiance, np.float64)
            p = np.pi * radius**2 * max(luminance(value), float(value.mean()))  # Mitsuba: the bounding disk
            rec[LIGHT_PRIM] = add_data(np.asarray(light.direction, np.float64))
            rec[LIGHT_TYPE] = LIGHT_DIRECTIONAL
        elif isinstance(light, SpotLight):
            value = np.asarray(light.intensity, np.float64)
            cutoff, beam = np.radians(light.cutoff_angle), np.radians(light.beam_width)
            solid_angle = 2 * np.pi * (1 - np.cos(0.5 * (cutoff + beam)))
            p = solid_angle * max(luminance(value), float(value.mean()))
            inv_transition = 1.0 / (cutoff - beam) if cutoff > beam else 0.0
            block = [light.position, light.direction, [np.cos(cutoff), np.cos(beam), cutoff, inv_transition]]
            if light.texture is not None:
                frame = light.to_world if light.to_world is not None else spot_frame(light.direction)
                block += [np.linalg.inv(frame).reshape(-1), [np.tan(cutoff)]]  # SPOT_TO_LOCAL, SPOT_UV_FACTOR
                rec[LIGHT_TEXTURE] = _int_bits(textures.add(light.texture))
                p *= max(float(texture_mean(light.texture) @ LUMINANCE), float(texture_mean(light.texture).mean()))
                has_textures = True
            rec[LIGHT_PRIM] = add_data(np.concatenate(block))
            rec[LIGHT_TYPE] = LIGHT_SPOT
        else:
            value = np.asarray(light.intensity, np.float64)
            pos = np.asarray(light.position, np.float64)
            if not (np.all(np.isfinite(value)) and value.min() >= 0 and np.all(np.isfinite(pos))):
                raise ValueError(f"point light {k}: position and intensity must be finite, intensity >= 0")
            p = 4.0 * np.pi * max(luminance(value), float(value.mean()))
            rec[LIGHT_PRIM] = add_data(pos)
            rec[LIGHT_TYPE] = LIGHT_POINT
        if not p > 0:
            continue
        rec[LIGHT_RADIANCE:LIGHT_RADIANCE + 3] = value
        records.append(rec)
        power.append(p)
        group.append(next_group)
        next_group += 1
        distant.append(isinstance(light, DirectionalLight))

    env_light = -1
    env = scene.environment
    if isinstance(env, Envmap):
        block, mean_radiance = pack_envmap(env, textures)
        if mean_radiance > 0:
            rec = np.zeros(LIGHT_STRIDE, np.float32)
            rec[LIGHT_TEXTURE] = _int_bits(-1)
            rec[LIGHT_PRIM] = add_data(block, 16)  # 64 bytes: no alias entry straddles two cache lines
            rec[LIGHT_TYPE] = LIGHT_ENVMAP
            env_light = len(tri_records) + len(records)
            records.append(rec)
            power.append(np.pi * np.pi * radius**2 * mean_radiance)
            group.append(next_group)
            distant.append(True)
    elif env is not None and max(env) > 0:
        rec = np.zeros(LIGHT_STRIDE, np.float32)
        rec[LIGHT_PRIM] = _int_bits(-1)
        rec[LIGHT_TEXTURE] = _int_bits(-1)
        rec[LIGHT_RADIANCE:LIGHT_RADIANCE + 3] = env
        rec[LIGHT_TYPE] = LIGHT_CONSTANT
        env_light = len(tri_records) + len(records)
        records.append(rec)
        power.append(np.pi * np.pi * radius**2 * max(luminance(env), float(np.mean(env, dtype=np.float64))))
        group.append(next_group)
        distant.append(True)

    lights = np.concatenate([tri_records, *[r[None] for r in records]])
    if len(lights):
        pmf = selection_pmf(np.asarray(power, np.float64), np.asarray(group, np.int64), np.asarray(distant, bool),
                            SELECTION)
        cdf = np.cumsum(pmf)
        cdf[-1] = 1.0
        lights[:, LIGHT_PMF] = pmf
        lights[:, LIGHT_CDF] = cdf
    light_data = np.concatenate(data) if data else np.zeros(1, np.float32)
    return LightArrays(lights, light_data, env_light, tri_light, has_textures)


def selection_pmf(power: np.ndarray, group: np.ndarray, distant: np.ndarray, rule: str = "distant-uniform"
                  ) -> np.ndarray:
    """The probability of choosing each emitter record, by ``rule`` (the module docstring): "power", in
    proportion to ``power``; "uniform", each emitter (``group``: the emitter of each record) alike and an
    emitter's records in proportion to their power; "distant-uniform", each ``distant`` record (its own
    emitter) as under "uniform" and the others the rest in proportion to their power. Powers beyond
    double range count alike."""
    if rule not in SELECTIONS:
        raise ValueError(f"light selection rule {rule!r}: expected one of {', '.join(SELECTIONS)}")
    if not np.all(np.isfinite(power)) or not power.sum() > 0:
        power = np.ones_like(power)
    if rule == "power":
        return power / power.sum()
    _, emitter = np.unique(group, return_inverse=True)
    count = int(emitter.max()) + 1
    if rule == "uniform":
        return power / np.bincount(emitter, weights=power)[emitter] / count
    pmf = np.where(distant, 1.0 / count, 0.0)
    finite = power * ~distant
    if finite.sum() > 0:
        pmf += finite / finite.sum() * (1.0 - np.count_nonzero(distant) / count)
    return pmf


def camera_consts(scene: Scene, lights: LightArrays, width: int, height: int,
                  previous: Camera | None = None, crop: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """The CONST_* block of cl/scene/scene.h for an image of width x height; ``previous``: the previous
    frame's camera, for motion vectors (None: the scene's camera, no motion); ``crop``: the film's window
    (x, y, width, height) of the image (read with -DFILM_CROP)."""
    c = np.zeros(CONST_COUNT, np.float32)
    origin, forward, right, up = scene.camera.basis(width, height)
    c[0:3], c[3:6], c[6:9], c[9:12] = origin, forward, right, up
    c[20:23], c[23:26], c[26:29], c[29:32] = (previous or scene.camera).basis(width, height)
    c[32], c[33] = scene.camera.aperture_radius, scene.camera.focus_distance
    c[12], c[13] = width, height
    if scene.environment is not None and not isinstance(scene.environment, Envmap):
        c[14:17] = scene.environment
    c[17] = lights.env_light
    c[18] = lights.lights.shape[0]
    c[19] = 1.0  # CONST_UNIT: the stride of record reads, opaque to the compiler (rgb_at, cl/core/common.h)
    c[CONST_FILTER_RADIUS:CONST_FILTER_RADIUS + FILTER_CONSTS] = filter_consts(scene.film.rfilter)
    c[CONST_CROP:CONST_CROP + 4] = crop or (0, 0, width, height)
    c[CONST_FILM_PAD] = scene.film.rfilter.splat_reach
    return c
