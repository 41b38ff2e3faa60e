"""Sun and sky emitters (Mitsuba's ``sunsky``, and Mitsuba 0.5's ``sky`` and ``sun``), baked into a
lat-long environment map that pyclpt's envmap emitter renders and importance-samples.

* :mod:`~pyclpt.scene.sky.hosek_wilkie`: the Hosek-Wilkie 2012 clear-sky model, RGB (its data tables);
* :mod:`~pyclpt.scene.sky.sun`: the sun's radiance, Mitsuba 0.5's (Preetham/Iqbal) and Mitsuba 3's
  (Hosek-Wilkie 2013, optionally limb-darkened);
* :mod:`~pyclpt.scene.sky.sun_position`: the sun's position for a place and time (PSA), per Mitsuba's frame;
* :mod:`~pyclpt.scene.sky.bake`: :func:`sunsky_envmap`, the baking, for either Mitsuba version.

What differs from Mitsuba: the sky is point-sampled at the map's texel centres and the sun is spread
over the texels it covers (its power exact, its shape blurred to about a texel); a sun below the horizon
is an error (Mitsuba 0.5 errs, Mitsuba 3 warns and emits nothing); negative RGB values of the fits are
clamped to 0 (Mitsuba 3 leaves them). Mitsuba 0.5's directional sun (``sunRadiusScale = 0``) is a
directional light beside the map (:func:`directional_sun_05`), as in Mitsuba 0.5.
"""
from pyclpt.scene.sky.bake import CONVENTIONS, directional_sun_05, sunsky_envmap, texel_directions
from pyclpt.scene.sky.sun_position import SunTime

__all__ = ["CONVENTIONS", "SunTime", "directional_sun_05", "sunsky_envmap", "texel_directions"]
