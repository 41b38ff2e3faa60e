"""One element of a Mitsuba XML scene file after reading (:class:`Node`), and the errors that name it.

Every message of :class:`SceneXMLError` starts with ``file:line:`` and the element as written
(``<float name="fov" value="abc">``), then says what is wrong.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from pyclpt.scene.mitsuba_dict import SceneDictError

#: A scene file's version, e.g. (3, 0, 0).
Version = tuple[int, int, int]


class SceneXMLError(SceneDictError):
    """A Mitsuba XML scene file that cannot be translated; the message starts with ``file:line:``."""


@dataclass
class Node:
    """One XML element after parameter substitution, version upgrade and include splicing."""

    tag: str
    attrs: dict[str, str]
    file: Path
    line: int
    version: Version
    children: list[Node] = field(default_factory=list)

    @property
    def where(self) -> str:
        return f"{self.file}:{self.line}"

    def describe(self) -> str:
        """The element as written, e.g. ``<float name="fov" value="abc">``."""
        attrs = "".join(f' {k}="{v}"' for k, v in self.attrs.items())
        return f"<{self.tag}{attrs}>"


def node_error(node: Node, msg: str) -> SceneXMLError:
    """The error to raise about ``node``."""
    return SceneXMLError(f"{node.where}: {node.describe()}: {msg}")


def expect_attrs(node: Node, allowed: set[str], required: Iterable[str] = ()) -> None:
    """Raise unless every attribute of ``node`` is ``allowed`` and every ``required`` one is there."""
    for attr in node.attrs:
        if attr not in allowed:
            raise node_error(node, f"unexpected attribute {attr!r} (allowed: {', '.join(sorted(allowed))})")
    for attr in sorted(required):
        if attr not in node.attrs:
            raise node_error(node, f"missing attribute {attr!r}")
