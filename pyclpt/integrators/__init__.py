"""Integrators: the megakernel (one work-item runs one whole path, ``cl/integrators/megakernel.cl``)
and the wavefront (seven stage kernels, ``cl/integrators/wavefront/``, passing paths through
compacted queues, with the path state in SoA or AoS generated from one declaration,
``path_state``). Both run the same estimator (``cl/integrators/path.h``) on the same random
numbers and write one sample per pixel into a :class:`pyclpt.film.film.Film`.

May import: :mod:`pyclpt.common`, :mod:`pyclpt.device`, :mod:`pyclpt.buffers`, :mod:`pyclpt.film`."""
