"""Write ``pyclpt/scene/sky/hosek_wilkie_rgb.npz``, the data tables of pyclpt's sky and sun, from the
copy that Mitsuba 3 ships (``mitsuba/data/sunsky/sunsky_datasets.bin`` and ``sampling_data.bin``,
Mitsuba's ``TensorFile`` format: raw little-endian arrays at the offsets its header lists).

    python -m bench.tools.make_sky_tables /path/to/site-packages/mitsuba/data/sunsky

Tables (Hosek & Wilkie, 3-clause BSD, see ``pyclpt/scene/sky/HOSEK_WILKIE_LICENSE.txt``):

* ``sky_params`` (turbidity 1-10, albedo 0/1, 6 quintic control points, R/G/B, 9 coefficients) and
  ``sky_rad`` (the same without the coefficients): ``datasetRGB1-3`` and ``datasetRGBRad1-3`` of
  ``ArHosekSkyModelData_RGB.h`` (Hosek & Wilkie 2012, version 1.4), reordered; checked below against
  values of the published header.
* ``sun_irradiance`` (turbidity 1-10, sun elevation 2-89 degrees in 3 degree steps, 11 wavelengths
  320-720 nm): the solar irradiance of the Hosek & Wilkie 2013 sun model, as Mitsuba 3 tabulates it.
* ``sun_rad_rgb`` (turbidity, 45 elevation segments, R/G/B, 4 polynomial degrees, 6 limb-darkening
  powers): Mitsuba 3's RGB fit of that sun with limb darkening (its ``complex_sun``).
* ``srgb_rec`` (R/G/B, 11 wavelengths): Mitsuba 3's ``linear_rgb_rec`` (the CIE 1931 curves times the
  XYZ -> linear sRGB matrix) at the 11 wavelengths, to turn the sun's irradiance into RGB as Mitsuba 3 does.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[2] / "pyclpt" / "scene" / "sky" / "hosek_wilkie_rgb.npz"
# Spot values of ArHosekSkyModelData_RGB.h: datasetRGBRad3, albedo 1, turbidity 10 (all six control
# points) and datasetRGB3, albedo 1, turbidity 10, last control point (its nine coefficients).
HEADER_RGBRAD3_A1_T10 = [7.754116e-01, 7.709245e-01, 2.200201e+00, -7.487661e+00, 5.436622e+01, 2.893432e+01]
HEADER_RGB3_A1_T10_LAST = [-9.621043e-01, -1.991406e-01, 6.531287e-01, 3.925839e+00, -3.596904e+00,
                           6.317332e-01, 1.531334e-01, 1.457846e+00, 6.966285e-01]
WAVELENGTHS = np.arange(320.0, 721.0, 40.0)


def read_tensor_file(path: Path) -> dict[str, np.ndarray]:
    """The fields of a Mitsuba ``TensorFile`` (its text header names dtype, offset and shape)."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    text = str(mi.TensorFile(str(path)))
    raw = path.read_bytes()
    out = {}
    for name, dtype, offset, shape in re.findall(
            r'"(\w+)" => \[\s*dtype = (\w+),\s*offset = (\d+),\s*shape = \[([\d, ]+)\]', text):
        shp = tuple(int(s) for s in shape.split(","))
        out[name] = np.frombuffer(raw, "<" + {"float64": "f8", "float32": "f4"}[dtype], int(np.prod(shp)),
                                  int(offset)).reshape(shp).copy()
    return out


def main(folder: str) -> None:
    import mitsuba as mi

    data = read_tensor_file(Path(folder) / "sunsky_datasets.bin")
    sampling = read_tensor_file(Path(folder) / "sampling_data.bin")
    np.testing.assert_array_equal(data["sky_rad_rgb"][9, 1, :, 2], HEADER_RGBRAD3_A1_T10)
    np.testing.assert_array_equal(data["sky_params_rgb"][9, 1, 5, 2], HEADER_RGB3_A1_T10_LAST)
    rec = np.array([np.array(mi.linear_rgb_rec(float(w))) for w in WAVELENGTHS]).T
    np.savez_compressed(OUT, sky_params=data["sky_params_rgb"], sky_rad=data["sky_rad_rgb"],
                        sun_irradiance=sampling["sun_irradiance"], sun_rad_rgb=data["sun_rad_rgb"],
                        srgb_rec=rec)
    print(OUT, OUT.stat().st_size, "bytes")


if __name__ == "__main__":
    main(sys.argv[1])
