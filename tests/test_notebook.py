"""The notebook of the docs (docs/notebook.ipynb) runs as written: nbclient executes it on an IPython
kernel (the test extra brings nbclient, nbformat and ipykernel) in a temporary folder, every cell without an
error, and the images it shows are PNGs of the sizes it renders (``pyclpt.show`` and ``ImageView``'s
``_repr_png_``). Skipped only where no kernel can start."""
from __future__ import annotations

import base64
from pathlib import Path

import nbformat
import numpy as np
import OpenImageIO as oiio
import pytest
from jupyter_client.kernelspec import NoSuchKernel
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parent.parent / "docs" / "notebook.ipynb"


def _pixels(png: bytes, tmp_path: Path, name: str) -> np.ndarray:
    path = tmp_path / name
    path.write_bytes(png)
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    try:
        return np.asarray(inp.read_image("uint8"))
    finally:
        inp.close()


def test_the_docs_notebook_runs(tmp_path):
    nb = nbformat.read(NOTEBOOK, as_version=4)
    for cell in nb.cells:  # what the stored outputs said must come back from this run, not from the file
        if cell.cell_type == "code":
            cell.outputs = []
    client = NotebookClient(nb, timeout=300, kernel_name="python3", record_timing=False,
                            resources={"metadata": {"path": str(tmp_path)}})
    client.create_kernel_manager()
    try:
        client.start_new_kernel()
        client.start_new_kernel_client()
    except (NoSuchKernel, RuntimeError, TimeoutError, OSError) as exc:
        if client.km is not None and client.km.has_kernel:
            client.km.shutdown_kernel(now=True)
        pytest.skip(f"no IPython kernel could start here ({type(exc).__name__}: {exc})")
    client.execute()  # a cell's error raises CellExecutionError, naming the cell and its traceback
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and all(c.execution_count for c in code)
    outputs = [o for c in code for o in c.outputs]
    pngs = [base64.b64decode(o["data"]["image/png"]) for o in outputs if "image/png" in o.get("data", {})]
    # pyclpt.show once, the ImageView of the cell's last line, then three pictures of the progressive render
    assert len(pngs) == 5, [o.get("output_type") for o in outputs]
    images = [_pixels(png, tmp_path, f"out{k}.png") for k, png in enumerate(pngs)]
    assert all(img.shape == (32, 32, 3) for img in images)
    assert images[0].mean() > 10  # the Cornell box, not a black picture
    assert images[1].mean() > images[0].mean()  # the ImageView shows it one stop brighter
    assert not [o for o in outputs if o["output_type"] == "error"]
