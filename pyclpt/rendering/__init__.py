"""Rendering sessions: :class:`~pyclpt.rendering.renderer.Renderer` prepares a scene on a device
(buffers, integrator, film) and renders sample passes; :func:`~pyclpt.rendering.renderer.render`
is the one-call form (``pyclpt.render``; given a Dask ``client``, it hands the render to the distributed
layer above, which it names rather than imports: ``CLUSTER_RENDER``);
:class:`~pyclpt.rendering.progressive.ProgressiveRenderer` renders frame by frame with accumulation and
auto-reset.

May import every layer below it: common, scene, accel, device, film, buffers, integrators."""
