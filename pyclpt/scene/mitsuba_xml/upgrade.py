"""Mitsuba 3's upgrade of scene files older than 2.0.0, as tables: parameter names go from camelCase
to snake_case (:func:`to_snake_case`), some tags are renamed (:data:`TAG_RENAMES`), and some
parameters are renamed per plug-in kind (:data:`PARAMETER_RENAMES`, keyed by tag and type). Plug-ins
that mean something else in Mitsuba 3 (:data:`VERSIONED_PLUGINS`) keep the file's version.
"""
from __future__ import annotations

from pyclpt.scene.mitsuba_xml.node import Node, Version

#: Files older than this are upgraded.
CURRENT: Version = (2, 0, 0)
#: Elements renamed in old files.
TAG_RENAMES: dict[str, str] = {"lookAt": "lookat"}
#: Parameters renamed in old files (after the snake_case conversion), per plug-in (tag, type).
PARAMETER_RENAMES: dict[tuple[str, str], dict[str, str]] = {
    ("bsdf", "diffuse"): {"diffuse_reflectance": "reflectance"},
}
#: Plug-ins (tag, type) of old files whose meaning changed in Mitsuba 3 beyond their parameters' names
#: (Mitsuba 0.5's ``sunsky`` has another sky frame and sun model than Mitsuba 3's; ``sky`` and ``sun``
#: exist in 0.5 only): their dictionaries carry the file's version (``__version__``).
VERSIONED_PLUGINS = frozenset({("emitter", "sunsky"), ("emitter", "sky"), ("emitter", "sun")})
#: Tags whose every plug-in carries an old file's version: a ``shape`` (an area emitter's shape without
#: a BSDF is grey diffuse in Mitsuba 0.5, black in Mitsuba 3).
VERSIONED_TAGS = frozenset({"shape"})


def to_snake_case(name: str) -> str:
    """Mitsuba 3's upgrade of a pre-2.0 parameter name: a lowercase letter followed by an uppercase
    one starts a new word, and the whole uppercase run is lowercased (``toWorld`` -> ``to_world``,
    ``intIOR`` -> ``int_ior``, ``sunRadiusScale`` -> ``sun_radius_scale``, ``kNN`` -> ``k_nn``)."""
    out: list[str] = []
    i = 0
    while i < len(name):
        c = name[i]
        out.append(c)
        i += 1
        if c.islower() and i < len(name) and name[i].isupper():
            out.append("_")
            while i < len(name) and name[i].isupper():
                out.append(name[i].lower())
                i += 1
    return "".join(out)


def upgrade_element(tag: str, attrs: dict[str, str], version: Version) -> str:
    """The element's tag as Mitsuba 3 reads it; its ``name`` attribute upgraded in place."""
    if version >= CURRENT:
        return tag
    tag = TAG_RENAMES.get(tag, tag)
    if "name" in attrs and tag != "default":
        attrs["name"] = to_snake_case(attrs["name"])
    return tag


def legacy_version(node: Node) -> str | None:
    """The file's version (``"0.6.0"``) for a plug-in of :data:`VERSIONED_PLUGINS` or :data:`VERSIONED_TAGS` in
    an old file, else None."""
    if node.version >= CURRENT or ((node.tag, node.attrs.get("type", "")) not in VERSIONED_PLUGINS
                                   and node.tag not in VERSIONED_TAGS):
        return None
    return ".".join(str(v) for v in node.version)


def upgrade_parameters(node: Node) -> None:
    """Rename the parameters (children) of plug-in ``node`` as :data:`PARAMETER_RENAMES` says."""
    if node.version >= CURRENT:
        return
    renames = PARAMETER_RENAMES.get((node.tag, node.attrs.get("type", "")))
    if not renames:
        return
    for child in node.children:
        name = child.attrs.get("name")
        if name in renames:
            child.attrs["name"] = renames[name]
