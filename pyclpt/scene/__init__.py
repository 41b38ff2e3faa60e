"""The scene: a scene file (Mitsuba XML, a Mitsuba 3 dictionary / JSON, a built-in name) becomes
the scene model, plain dataclasses (:mod:`pyclpt.scene.model`) holding meshes, materials,
textures, emitters, camera and film.

Modules: ``model`` (the dataclasses, validated on construction and on change), ``library``
(built-in names, scene files, the shared scene folder), ``mitsuba_xml`` (XML -> dictionary),
``mitsuba_dict`` (dictionary -> model, one module per plug-in kind), ``mesh_io`` and
``serialized`` (mesh files), ``shapes`` (analytic shapes as meshes), ``textures`` (bitmap
files), ``sunsky`` (sky and sun baked to an environment map), ``transform``.

May import: :mod:`pyclpt.common`. Knows nothing of OpenCL."""
