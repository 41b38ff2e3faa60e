"""The live viewer: ``pyclpt view SCENE`` and :func:`view` render a scene progressively in a browser page
served from 127.0.0.1, with camera controls, settings and readouts (docs/viewer.md); :func:`show` and
:class:`~pyclpt.viewer.display.ImageView` show an image in a Jupyter notebook.

* :mod:`pyclpt.viewer.display`: the tonemap, AOV colours, PNG encoding and the notebook image (numpy only);
* :mod:`pyclpt.viewer.camera`: orbit / pan / zoom / fly moves and the camera as Mitsuba XML;
* :mod:`pyclpt.viewer.session`: the render thread around a ProgressiveRenderer;
* :mod:`pyclpt.viewer.server`: the aiohttp server, its page and WebSocket (the ``viewer`` extra).

May import rendering and every layer below it.
"""
from __future__ import annotations

from typing import Any

from pyclpt.viewer.display import ImageView, show

#: How to install what the server needs.
VIEWER_HINT = 'pip install "pyclpt[viewer]"'


def require_server() -> None:
    """ImportError naming the ``viewer`` extra where aiohttp, the server's library, is missing."""
    try:
        import aiohttp  # noqa: F401
    except ImportError as exc:
        raise ImportError(f"the live viewer serves its page with aiohttp, which is not installed here ({exc}): "
                          f"{VIEWER_HINT}") from None


def view(scene: Any, **options: Any):
    """Render ``scene`` live in the browser; returns the :class:`~pyclpt.viewer.server.Viewer`
    (:func:`pyclpt.viewer.server.view` has the options). Needs the ``viewer`` extra."""
    require_server()
    from pyclpt.viewer.server import view as _view

    return _view(scene, **options)


__all__ = ["ImageView", "VIEWER_HINT", "require_server", "show", "view"]
