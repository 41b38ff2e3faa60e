"""Regenerate ``sunsky-mitsuba3-eval.npz``: Mitsuba 3's ``sunsky`` emitter evaluated along directions,
for tests/test_lights.py (pyclpt's baked Hosek-Wilkie sky and Mitsuba 3's sun against Mitsuba's own).

    DRJIT_LIBLLVM_PATH=... /tmp/mitsuba-venv/bin/python tests/data/make_sunsky_reference.py

For each configuration (sun elevation and azimuth in Mitsuba 3's frame, +z up; turbidity; albedo; a
to_world rotation or none): the sky alone (``sun_scale = 0``) along 400 random directions of the upper
hemisphere (of the sky's frame); the sun alone (``sky_scale = 0``) at its centre, for the real aperture
and a wide one (5 degrees), and across the wide limb-darkened disk (``complex_sun``); and the sun's
position from a place and time (Mitsuba's defaults and one other) as a world direction.
"""
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
HERE = Path(__file__).parent
#: (elevation deg, azimuth deg, turbidity, albedo, to_world rotation (axis, angle) or None)
CONFIGS = [(5.0, 30.0, 2.0, 0.0, None), (24.6, 123.0, 3.0, 0.3, None), (45.0, 200.0, 5.0, 0.5, None),
           (60.0, -40.0, 9.0, 0.8, None), (15.0, 80.0, 7.5, 0.15, ([1.0, 0.0, 0.0], -90.0)),
           (80.0, 10.0, 1.0, 1.0, None)]
TIMES = [{}, {"latitude": -33.9, "longitude": 18.4, "timezone": 2.0, "year": 2021, "month": 12, "day": 3,
              "hour": 9.5, "minute": 12.0, "second": 30.0}]


def sph(elev_deg: float, azim_deg: float) -> np.ndarray:
    e, a = np.radians(elev_deg), np.radians(azim_deg)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def evaluate(emitter, dirs: np.ndarray) -> np.ndarray:
    out = []
    for d in dirs:
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = mi.Vector3f(-d)  # eval() looks up the direction -wi
        out.append(np.array(emitter.eval(si)))
    return np.array(out)


def main() -> None:
    rng = np.random.default_rng(1)
    arrays: dict[str, np.ndarray] = {}
    for k, (elev, azim, turb, alb, rot) in enumerate(CONFIGS):
        m = np.eye(4) if rot is None else np.array(mi.ScalarTransform4f().rotate(rot[0], rot[1]).matrix)
        sun_local = sph(elev, azim)
        sun_world = m[:3, :3] @ sun_local
        base = {"type": "sunsky", "turbidity": turb, "albedo": alb, "sun_direction": mi.ScalarVector3f(sun_world),
                "to_world": mi.ScalarTransform4f(m)}
        local = rng.normal(size=(400, 3))
        local[:, 2] = np.abs(local[:, 2])
        local /= np.linalg.norm(local, axis=1, keepdims=True)
        dirs = local @ m[:3, :3].T
        sky = evaluate(mi.load_dict({**base, "sun_scale": 0.0}), dirs)
        sun = []
        for aperture in (0.5358, 5.0):
            sun.append(evaluate(mi.load_dict({**base, "sky_scale": 0.0, "sun_aperture": aperture}), sun_world[None])[0])
        # across the wide limb-darkened disk: directions at 0..0.95 of its radius from the centre
        frame = mi.Frame3f(mi.Vector3f(sun_world))
        angles = np.radians(2.5) * np.linspace(0.0, 0.95, 8)
        across = np.array([np.array(frame.to_world(mi.Vector3f(np.sin(a), 0.0, np.cos(a)))) for a in angles])
        limb = evaluate(mi.load_dict({**base, "sky_scale": 0.0, "sun_aperture": 5.0, "complex_sun": True}), across)
        arrays.update({f"c{k}_params": np.array([elev, azim, turb, alb]), f"c{k}_to_world": m,
                       f"c{k}_sun": sun_world, f"c{k}_dirs": dirs, f"c{k}_sky": sky, f"c{k}_sun_rgb": np.array(sun),
                       f"c{k}_limb_dirs": across, f"c{k}_limb": limb})
    for k, t in enumerate(TIMES):
        e = mi.load_dict({"type": "sunsky", "sky_scale": 0.0, "sun_aperture": 20.0, **t})
        params = mi.traverse(e)
        arrays[f"t{k}_sun"] = np.array(params["sun_direction"]).ravel()
        arrays[f"t{k}_time"] = np.array([t.get(n, np.nan) for n in ("latitude", "longitude", "timezone", "year",
                                                                     "month", "day", "hour", "minute", "second")])
    np.savez_compressed(HERE / "sunsky-mitsuba3-eval.npz", **arrays)
    print(HERE / "sunsky-mitsuba3-eval.npz", mi.__version__)


if __name__ == "__main__":
    main()
