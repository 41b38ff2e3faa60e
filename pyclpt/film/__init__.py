"""The film: the frame buffer integrators write one sample per pixel into (``film``) and the
accumulator that averages frames on the device in single, Kahan-compensated or double precision
(``accumulator``, ``cl/film/``).

May import: :mod:`pyclpt.common`, :mod:`pyclpt.device`."""
