"""Regenerate ``bsdf-mitsuba3-eval.npz``: Mitsuba 3's own BSDFs evaluated (value including the cosine
of wo, and pdf) at random direction pairs, and sampled at given random numbers, for tests/test_bsdf.py
(pyclpt's cl/scene/bsdf.h against the plug-ins it follows).

    python -m venv /tmp/mts && /tmp/mts/bin/pip install mitsuba
    /tmp/mts/bin/python tests/data/make_bsdf_reference.py

Each material is a Mitsuba dict (scalar_rgb); tests/test_bsdf.py builds the same material with
pyclpt's scene model (MITSUBA_REFERENCE there). 120 pairs per material, half of them near the mirror
direction; the dielectrics' directions cover the sphere.
"""
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
HERE = Path(__file__).parent


def rgb(v):
    return {"type": "rgb", "value": list(v)}


MATERIALS = {
    "roughglass-ggx-0.3": {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.3, "int_ior": 1.5,
                           "ext_ior": 1.0, "specular_reflectance": rgb([0.9, 0.8, 0.7]),
                           "specular_transmittance": rgb([0.6, 0.7, 0.8])},
    "roughglass-beckmann-0.1": {"type": "roughdielectric", "distribution": "beckmann", "alpha": 0.1,
                                "int_ior": 1.5, "ext_ior": 1.0},
    "roughbubble-ggx-0.8": {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.8, "int_ior": 1.0,
                            "ext_ior": 1.333},
    "thin-1.5": {"type": "thindielectric", "int_ior": 1.5, "ext_ior": 1.0,
                 "specular_reflectance": rgb([0.9, 0.8, 0.7]), "specular_transmittance": rgb([0.6, 0.7, 0.8])},
    "plastic-lin": {"type": "plastic", "diffuse_reflectance": rgb([0.7, 0.4, 0.2]),
                    "specular_reflectance": rgb([1.0, 0.9, 0.6]), "int_ior": 1.6, "ext_ior": 1.1},
    "plastic-nl": {"type": "plastic", "diffuse_reflectance": rgb([0.7, 0.4, 0.2]), "int_ior": 1.5, "ext_ior": 1.0,
                   "nonlinear": True},
    "roughplastic-ggx-0.3": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3,
                             "diffuse_reflectance": rgb([0.7, 0.4, 0.2]), "int_ior": 1.5, "ext_ior": 1.0},
    "roughplastic-beckmann-0.1-nl": {"type": "roughplastic", "distribution": "beckmann", "alpha": 0.1,
                                     "diffuse_reflectance": rgb([0.7, 0.4, 0.2]), "int_ior": 1.5,
                                     "ext_ior": 1.0, "nonlinear": True},
    "roughplastic-ggx-0.8": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.8,
                             "diffuse_reflectance": rgb([0.9, 0.9, 0.9]),
                             "specular_reflectance": rgb([0.5, 0.5, 0.5]), "int_ior": 1.33, "ext_ior": 1.0},
    "roughconductor-beckmann-0.3": {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.3,
                                    "eta": rgb([0.2, 0.9, 1.1]), "k": rgb([3.9, 2.4, 2.2])},
    # anisotropic (the frame's s = (1, 0, 0) carries alpha_u)
    "roughconductor-ggx-0.05x0.4": {"type": "roughconductor", "distribution": "ggx", "alpha_u": 0.05, "alpha_v": 0.4,
                                    "eta": rgb([0.2, 0.9, 1.1]), "k": rgb([3.9, 2.4, 2.2])},
    "roughconductor-beckmann-0.4x0.1": {"type": "roughconductor", "distribution": "beckmann", "alpha_u": 0.4,
                                        "alpha_v": 0.1, "eta": rgb([0.2, 0.9, 1.1]), "k": rgb([3.9, 2.4, 2.2])},
    "roughglass-ggx-0.1x0.5": {"type": "roughdielectric", "distribution": "ggx", "alpha_u": 0.1, "alpha_v": 0.5,
                               "int_ior": 1.5, "ext_ior": 1.0, "specular_reflectance": rgb([0.9, 0.8, 0.7]),
                               "specular_transmittance": rgb([0.6, 0.7, 0.8])},
    "roughglass-beckmann-0.3x0.05": {"type": "roughdielectric", "distribution": "beckmann", "alpha_u": 0.3,
                                     "alpha_v": 0.05, "int_ior": 1.5, "ext_ior": 1.0},
}


def directions(rng, n, sphere):
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    if not sphere:
        v[:, 2] = np.abs(v[:, 2])
    return v


def main():
    rng = np.random.default_rng(0)
    out = {}
    n = 120
    ctx = mi.BSDFContext()
    for name, d in MATERIALS.items():
        bsdf = mi.load_dict(d)
        sphere = "glass" in name or "bubble" in name or "thin" in name
        wi, wo = directions(rng, n, sphere), directions(rng, n, sphere)
        k = n // 2
        wo[:k] = wi[:k] * [-1, -1, 1] + 0.3 * directions(rng, k, True)
        wo[:k] /= np.linalg.norm(wo[:k], axis=1, keepdims=True)
        u = rng.random((n, 3))
        wi, wo, u = (a.astype(np.float32) for a in (wi, wo, u))  # what the test passes to the device
        rec = {key: [] for key in ("value", "pdf", "s_wo", "s_weight", "s_pdf")}
        for i in range(n):
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.n = mi.Normal3f(0, 0, 1)
            si.sh_frame = mi.Frame3f(si.n)
            si.wi = mi.Vector3f(*wi[i])
            w = mi.Vector3f(*wo[i])
            rec["value"].append(np.array(bsdf.eval(ctx, si, w)))
            rec["pdf"].append(float(bsdf.pdf(ctx, si, w)))
            bs, weight = bsdf.sample(ctx, si, float(u[i, 0]), mi.Point2f(float(u[i, 1]), float(u[i, 2])))
            rec["s_wo"].append(np.array(bs.wo))
            rec["s_weight"].append(np.array(weight))
            rec["s_pdf"].append(float(bs.pdf))
        out.update({f"{name}/wi": wi, f"{name}/wo": wo, f"{name}/u": u})
        out.update({f"{name}/{key}": np.array(v, np.float32) for key, v in rec.items()})
    np.savez_compressed(HERE / "bsdf-mitsuba3-eval.npz", version=mi.__version__, **out)


if __name__ == "__main__":
    main()
