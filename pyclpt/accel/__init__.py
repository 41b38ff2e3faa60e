"""The acceleration structure: Embree's builder (``rtcBuildBVH`` of the embreex wheel's
``libembree4``, through ctypes, :mod:`pyclpt.accel.embree`) makes a BVH over the scene's
triangles, flattened into plain arrays for ``cl/scene/bvh.h`` (:mod:`pyclpt.accel.bvh`) and
cached on disk.

May import: :mod:`pyclpt.common`. Works on numpy arrays, not on the scene model."""
