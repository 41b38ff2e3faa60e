"""The film: the frame buffer integrators write one sample per pixel into (``film``) and the
accumulator that averages frames on the device in single, Kahan-compensated or double precision
(``accumulator``, ``cl/film/``), and the G-buffer (AOVs) the integrators record beside the
radiance, averaged per pixel (``aovs``), and the splatting film's gather (``splat``: the tent and gaussian
by Mitsuba's estimator).

May import: :mod:`pyclpt.common`, :mod:`pyclpt.device` (and :mod:`pyclpt.scene`'s model for types)."""
