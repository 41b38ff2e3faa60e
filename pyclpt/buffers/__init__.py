"""Device buffers: the scene model and its BVH packed into flat arrays and uploaded for the
kernels: geometry in BVH leaf order (``scene``), materials and textures (``materials``, with the
rough-plastic tables of ``microfacet``), emitters and their sampling tables (``lights``).
The array layouts mirror ``cl/scene/*.h``.

May import: :mod:`pyclpt.common`, :mod:`pyclpt.scene`, :mod:`pyclpt.accel`, :mod:`pyclpt.device`."""
