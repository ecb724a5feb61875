"""Resolve a Python cross-reference to the one public place its object is documented.

The toolkit defines most names in private modules and exports them from ``toolkit`` (and a
few subpackages); the reference documents each name once, where users import it. A docstring
that says ``:class:`toolkit.model.Plant``` or, inside :mod:`toolkit.sweeps`, ``:class:`RunKeys```
means the object documented as ``toolkit.Plant`` or ``toolkit.sweeps.RunKeys``. When Sphinx
finds no object under the written name, this extension looks for documented objects whose
dotted name ends with the same trailing names: a qualified reference resolves when exactly
one object matches; an unqualified one only to a match inside the module or class it was
written in. Anything else stays unresolved, and the nitpicky build reports it.
"""

from __future__ import annotations

from collections import defaultdict

from sphinx.util.nodes import make_refnode


def _index(env) -> dict[str, list[str]]:
    index = getattr(env, "_api_alias_index", None)
    objects = env.get_domain("py").objects
    if index is None or index[0] != len(objects):
        suffixes: dict[str, list[str]] = defaultdict(list)
        for name in objects:
            parts = name.split(".")
            for k in range(1, len(parts) + 1):
                suffixes[".".join(parts[-k:])].append(name)
        index = (len(objects), suffixes)
        env._api_alias_index = index
    return index[1]


def _missing_reference(app, env, node, contnode):
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~.")
    if not target:
        return None
    index = _index(env)
    parts = target.split(".")
    context = ".".join(p for p in (node.get("py:module"), node.get("py:class")) if p)
    for k in range(len(parts), 0, -1):
        candidates = index.get(".".join(parts[-k:]), [])
        if len(parts) == 1 or k < len(parts) - 1:
            # unqualified, or only the last name left: stay within the reference's own context
            candidates = [c for c in candidates if context and c.startswith(context.rsplit(".", 1)[0] + ".")]
        if len(candidates) == 1:
            entry = env.get_domain("py").objects[candidates[0]]
            return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode,
                                candidates[0])
        if len(candidates) > 1:
            near = [c for c in candidates if context and c.startswith(context + ".")]
            if len(near) != 1:
                return None
            candidates = near
        if len(candidates) == 1:
            entry = env.get_domain("py").objects[candidates[0]]
            return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode,
                                candidates[0])
    return None


def setup(app):
    app.connect("missing-reference", _missing_reference, priority=900)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
