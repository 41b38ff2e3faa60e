"""Materials and textures -> the flat arrays of ``cl/scene/bsdf.h`` and ``cl/scene/texture.h``.

A material is MAT_STRIDE floats (offsets mirrored from ``cl/scene/bsdf.h``); a
parameter given as a texture stores 1 as its constant and the texture's id in
the slot beside it, so the device multiplies the two. Textures are
TEX_STRIDE-float records; 8-bit texels (sRGB or linear) and float texels live
in two separate buffers, RGBA, row 0 at the top of the image.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pyclpt.buffers.microfacet import RP_KNOTS, fresnel, roughplastic_tables
from pyclpt.scene.model import (
    Bitmap,
    BumpMap,
    Checkerboard,
    Color,
    Conductor,
    Dielectric,
    Diffuse,
    Mask,
    Material,
    Plastic,
    ThinDielectric,
    back_material,
    base_material,
    uv_matrix,
)

MAT_STRIDE = 32
MAT_TYPES = {"diffuse": 0, "conductor": 1, "roughconductor": 2, "dielectric": 3, "roughdielectric": 4,
             "thindielectric": 5, "plastic": 6, "roughplastic": 7}
# offsets (cl/scene/bsdf.h)
MAT_TYPE, MAT_FLAGS, MAT_COLOR, MAT_COLOR_TEX, MAT_SPEC, MAT_SPEC_TEX = 0, 1, 2, 5, 6, 9
MAT_TRANS, MAT_IOR, MAT_ETA, MAT_K, MAT_ALPHA = 10, 13, 14, 17, 20
MAT_OPACITY, MAT_OPACITY_TEX, MAT_BUMP_TEX, MAT_BUMP_SCALE, MAT_FDR_INT, MAT_TRANS_TEX = 21, 22, 23, 24, 25, 26
MAT_RP_TRANS = 27  # roughplastic: RP_KNOTS half floats of the coating's transmittance (slots 27..31)
MAT_ALPHA_V = 27  # anisotropic roughconductor / roughdielectric: alpha_v (MAT_ALPHA holds alpha_u)
MAT_BACK = 10  # the front record of a TwoSided: the back record's index (MAT_TRANS's slot, unused by it)
FLAG_TWOSIDED, FLAG_NONLINEAR, FLAG_BECKMANN, FLAG_MASKED = 1, 2, 4, 8
FLAG_ANISOTROPIC, FLAG_BACK, FLAG_UV_FRAME = 16, 32, 64

TEX_STRIDE = 20
TEX_UV, TEX_SCALE, TEX_COLOR1 = 8, 14, 17  # the (2, 3) uv matrix, row by row; rgb; rgb
TEX_BITMAP, TEX_CHECKER = 0, 1
TEXF_SRGB8, TEXF_LINEAR8, TEXF_FLOAT = 0, 1, 2
WRAP = {"repeat": 0, "mirror": 1, "clamp": 2, "black": 3}
FILTER = {"nearest": 0, "bilinear": 1}


def fresnel_dielectric(cos_i: np.ndarray, eta: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance from the outside (cos_i >= 0) of an interface int/ext = eta."""
    return fresnel(np.asarray(cos_i, np.float64), eta)[0]


def fresnel_diffuse_reflectance(eta: float, n: int = 20000) -> float:
    """Hemispherical (cosine-weighted) average of the Fresnel reflectance seen from the side of
    relative IOR ``eta`` (Mitsuba's fresnelDiffuseReflectance), by midpoint quadrature in cos^2."""
    x = (np.arange(n) + 0.5) / n  # x = cos^2(theta): cos sin dtheta = dx / 2
    return float(np.mean(fresnel_dielectric(np.sqrt(x), eta)))


class TextureTable:
    """Collects the textures of a scene (each once) and packs them for the device."""

    def __init__(self) -> None:
        self.records: list[np.ndarray] = []
        self._ids: dict[int, int] = {}
        self._texels8: list[np.ndarray] = []
        self._texels32: list[np.ndarray] = []
        self._n8 = 0
        self._n32 = 0

    def __len__(self) -> int:
        return len(self.records)

    def add(self, tex: Bitmap | Checkerboard) -> int:
        key = id(tex)
        if key in self._ids:
            return self._ids[key]
        rec = np.zeros(TEX_STRIDE, np.float32)
        rec[TEX_UV:TEX_UV + 6] = uv_matrix(tex).reshape(-1)
        if isinstance(tex, Checkerboard):
            rec[0] = TEX_CHECKER
            rec[TEX_SCALE:TEX_SCALE + 3] = np.multiply(tex.color0, tex.scale)
            rec[TEX_COLOR1:TEX_COLOR1 + 3] = np.multiply(tex.color1, tex.scale)
        else:
            rgba = tex.rgba()
            rec[0] = TEX_BITMAP
            rec[2], rec[3] = tex.width, tex.height
            rec[5] = WRAP[tex.wrap_mode]
            rec[6] = FILTER[tex.filter]
            rec[7] = tex.pixels.shape[2]
            rec[TEX_SCALE:TEX_SCALE + 3] = tex.scale
            q = rgba * 255.0
            eight_bit = tex.srgb or (rgba.min() >= 0 and rgba.max() <= 1 and np.all(q == np.round(q)))
            if eight_bit:
                rec[1] = TEXF_SRGB8 if tex.srgb else TEXF_LINEAR8
                rec[4] = np.int32(self._n8).view(np.float32)
                data = np.clip(np.round(q), 0, 255).astype(np.uint8).reshape(-1)
                self._texels8.append(data)
                self._n8 += rgba.shape[0] * rgba.shape[1]
            else:
                rec[1] = TEXF_FLOAT
                rec[4] = np.int32(self._n32).view(np.float32)
                self._texels32.append(rgba.astype(np.float32).reshape(-1))
                self._n32 += rgba.shape[0] * rgba.shape[1]
            if max(self._n8, self._n32) >= 2**31 // 4:
                raise ValueError("the scene's textures exceed 2^29 texels, more than pyclpt can address")
        self.records.append(rec)
        self._ids[key] = len(self.records) - 1
        return self._ids[key]

    def index(self, tex: Bitmap | Checkerboard) -> int | None:
        """The id of a texture added to the table, None if it was not."""
        return self._ids.get(id(tex))

    def info(self) -> np.ndarray:
        return np.stack(self.records) if self.records else np.zeros((1, TEX_STRIDE), np.float32)

    def texels8(self) -> np.ndarray:
        return np.concatenate(self._texels8) if self._texels8 else np.zeros(4, np.uint8)

    def texels32(self) -> np.ndarray:
        return np.concatenate(self._texels32) if self._texels32 else np.zeros(4, np.float32)


def _color(rec: np.ndarray, at: int, tex_at: int, value: Color, textures: TextureTable) -> None:
    if isinstance(value, (Bitmap, Checkerboard)):
        rec[at:at + 3] = 1.0
        rec[tex_at] = textures.add(value)
    else:
        rec[at:at + 3] = value
        rec[tex_at] = -1


def _anisotropy(rec: np.ndarray, base: Conductor | Dielectric) -> int:
    """alpha_v of an anisotropic rough material into its record; its flags."""
    if not (base.anisotropic and base.alpha > 0):
        return 0
    rec[MAT_ALPHA_V] = base.alpha_v
    return FLAG_ANISOTROPIC | FLAG_UV_FRAME


def pack_material(mat: Material, textures: TextureTable | None = None) -> np.ndarray:
    """The MAT_STRIDE-float record of a material (its textures added to ``textures``); of a
    :class:`TwoSided`'s front (:func:`pack_materials` adds the back's record and links the two)."""
    textures = textures if textures is not None else TextureTable()
    rec = np.zeros(MAT_STRIDE, np.float32)
    for slot in (MAT_COLOR_TEX, MAT_SPEC_TEX, MAT_TRANS_TEX, MAT_OPACITY_TEX, MAT_BUMP_TEX):
        rec[slot] = -1
    rec[MAT_OPACITY] = 1.0
    rec[MAT_SPEC:MAT_SPEC + 3] = 1.0
    rec[MAT_TRANS:MAT_TRANS + 3] = 1.0
    flags = 0
    wrapper = mat
    while isinstance(wrapper, (Mask, BumpMap)):
        if isinstance(wrapper, Mask):
            flags |= FLAG_MASKED
            if isinstance(wrapper.opacity, (Bitmap, Checkerboard)):
                rec[MAT_OPACITY] = 1.0
                rec[MAT_OPACITY_TEX] = textures.add(wrapper.opacity)
            else:
                rec[MAT_OPACITY] = float(np.mean(wrapper.opacity))
        else:
            rec[MAT_BUMP_TEX] = textures.add(wrapper.height)
            rec[MAT_BUMP_SCALE] = wrapper.scale
        wrapper = wrapper.material
    base = base_material(mat)
    if isinstance(base, Diffuse):
        kind = "diffuse"
        _color(rec, MAT_COLOR, MAT_COLOR_TEX, base.reflectance, textures)
    elif isinstance(base, Conductor):
        kind = "roughconductor" if base.alpha > 0 else "conductor"
        _color(rec, MAT_SPEC, MAT_SPEC_TEX, base.specular_reflectance, textures)
        rec[MAT_ETA:MAT_ETA + 3] = base.eta
        rec[MAT_K:MAT_K + 3] = base.k
        rec[MAT_ALPHA] = base.alpha
        flags |= _anisotropy(rec, base)
    elif isinstance(base, (Dielectric, ThinDielectric)):
        rough = isinstance(base, Dielectric) and base.alpha > 0
        kind = "thindielectric" if isinstance(base, ThinDielectric) else (
            "roughdielectric" if rough else "dielectric")
        _color(rec, MAT_SPEC, MAT_SPEC_TEX, base.specular_reflectance, textures)
        _color(rec, MAT_TRANS, MAT_TRANS_TEX, base.specular_transmittance, textures)
        rec[MAT_IOR] = base.int_ior / base.ext_ior
        rec[MAT_ALPHA] = getattr(base, "alpha", 0.0)
        if isinstance(base, Dielectric):
            flags |= _anisotropy(rec, base)
    elif isinstance(base, Plastic):
        kind = "roughplastic" if base.alpha > 0 else "plastic"
        _color(rec, MAT_COLOR, MAT_COLOR_TEX, base.diffuse_reflectance, textures)
        _color(rec, MAT_SPEC, MAT_SPEC_TEX, base.specular_reflectance, textures)
        eta = base.int_ior / base.ext_ior
        rec[MAT_IOR] = eta
        rec[MAT_ALPHA] = base.alpha
        if base.alpha > 0:  # Mitsuba's rough-coating tables (pyclpt/microfacet.py)
            knots, internal = roughplastic_tables(base.alpha, eta, base.distribution == "beckmann")
            rec[MAT_FDR_INT] = internal
            rec[MAT_RP_TRANS:MAT_RP_TRANS + RP_KNOTS // 2] = knots.view(np.float32)
        else:
            rec[MAT_FDR_INT] = fresnel_diffuse_reflectance(1.0 / eta)
        if base.nonlinear:
            flags |= FLAG_NONLINEAR
    else:
        raise TypeError(f"unsupported material {mat!r}")
    if getattr(base, "twosided", False) or back_material(mat) is not None:
        flags |= FLAG_TWOSIDED
    if getattr(base, "distribution", "ggx") == "beckmann":
        flags |= FLAG_BECKMANN
    rec[MAT_TYPE] = MAT_TYPES[kind]
    rec[MAT_FLAGS] = flags
    return rec


@dataclass
class MaterialArrays:
    materials: np.ndarray  # (M, MAT_STRIDE) float32
    textures: TextureTable
    masked: np.ndarray  # (M,) bool: material has an opacity
    has_bumpmaps: bool
    has_textures: bool  # a reflectance or transmittance is textured (-DSCENE_HAS_TEXTURES)
    kinds: int  # bit MAT_TYPES[kind] set for every material kind present (-DSCENE_MATERIALS)
    has_anisotropy: bool = False  # an anisotropic rough material (-DSCENE_HAS_ANISOTROPY)
    has_back_materials: bool = False  # a TwoSided with two materials (-DSCENE_HAS_BACK_MATERIALS)


def pack_materials(materials: list[Material], textures: TextureTable | None = None) -> MaterialArrays:
    """The records of ``materials``, one each at its index, then the back materials of the TwoSided ones
    (the front record has FLAG_BACK and the back one's index in MAT_BACK; both are two-sided)."""
    textures = textures if textures is not None else TextureTable()
    front = [pack_material(m, textures) for m in materials]
    backs = []
    for rec, mat in zip(front, materials):
        back = back_material(mat)
        if back is None:
            continue
        brec = pack_material(back, textures)
        brec[MAT_FLAGS] = int(brec[MAT_FLAGS]) | FLAG_TWOSIDED
        rec[MAT_BACK] = len(materials) + len(backs)
        flags = int(rec[MAT_FLAGS]) | FLAG_BACK
        if int(brec[MAT_FLAGS]) & FLAG_UV_FRAME:  # the frame is the hit's, chosen before the side
            flags |= FLAG_UV_FRAME
        rec[MAT_FLAGS] = flags
        backs.append(brec)
    recs = np.stack(front + backs)
    flags = recs[:, MAT_FLAGS].astype(np.int32)
    masked = (recs[:, MAT_FLAGS].astype(np.int32) & FLAG_MASKED) != 0
    textured = bool(np.any(recs[:, [MAT_COLOR_TEX, MAT_SPEC_TEX, MAT_TRANS_TEX]] >= 0))
    kinds = 0
    for t in np.unique(recs[:, MAT_TYPE].astype(np.int64)):
        kinds |= 1 << int(t)
    return MaterialArrays(recs, textures, masked, bool(np.any(recs[:, MAT_BUMP_TEX] >= 0)), textured, kinds,
                          bool(np.any(flags & FLAG_ANISOTROPIC)), bool(np.any(flags & FLAG_BACK)))
