"""Resolve a Python cross-reference to the one public place its object is documented.

The toolkit defines most names in private modules and exports them from ``toolkit`` (and a
few subpackages); the reference documents each name once, where users import it. A docstring
that says ``:class:`toolkit.model.Plant``` or, inside :mod:`toolkit.sweeps`, ``:class:`RunKeys```
means the object documented as ``toolkit.Plant`` or ``toolkit.sweeps.RunKeys``. When Sphinx
finds no object under the written name, this extension looks for documented objects whose
dotted name ends with the same trailing names: a qualified reference resolves when exactly
one object matches; an unqualified one to a match inside the module or class it was written
in, or else to the only object of its name and kind. Anything else stays unresolved, and the
nitpicky build reports it.
"""

from __future__ import annotations

from collections import defaultdict

from sphinx.util.nodes import make_refnode


def _index(env) -> dict[str, list[str]]:
    index = getattr(env, "_api_alias_index", None)
    objects = env.get_domain("py").objects
    if index is None or index[0] != len(objects):
        suffixes: dict[str, list[str]] = defaultdict(list)
        for name, entry in objects.items():
            if getattr(entry, "aliased", False):
                continue                  # a canonical alias of an object documented elsewhere
            parts = name.split(".")
            for k in range(1, len(parts) + 1):
                suffixes[".".join(parts[-k:])].append(name)
        index = (len(objects), suffixes)
        env._api_alias_index = index
    return index[1]


#: The object types each role may resolve to.
_TYPES = {"func": {"function", "method", "staticmethod", "classmethod"}, "meth": {"method", "function",
          "staticmethod", "classmethod", "property"}, "class": {"class", "exception"}, "exc": {"exception", "class"},
          "data": {"data", "attribute"}, "attr": {"attribute", "property", "data"}, "mod": {"module"},
          "const": {"data"}, "obj": None}


#: The object type a role means first, where names of several kinds match.
_FIRST = {"func": "function", "meth": "method", "class": "class", "data": "data", "attr": "attribute"}


def _closest(candidates: list[str], near: str, objects, first: str | None) -> list[str]:
    """The candidates of the role's first kind, then those sharing the longest dotted prefix
    with ``near`` (the written name, or the context it was written in)."""
    typed = [c for c in candidates if objects[c].objtype == first]
    candidates = typed or candidates
    if len(candidates) > 1 and near:
        def shared(name: str) -> int:
            n = 0
            for a, b in zip(name.split("."), near.split(".")):
                if a != b:
                    break
                n += 1
            return n
        best = max(map(shared, candidates))
        candidates = [c for c in candidates if shared(c) == best]
    return candidates


def _missing_reference(app, env, node, contnode):
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~.")
    if not target:
        return None
    objects = env.get_domain("py").objects
    index = _index(env)
    parts = target.split(".")
    types = _TYPES.get(node.get("reftype"))
    context = ".".join(p for p in (node.get("py:module"), node.get("py:class")) if p)
    qualified = len(parts) > 1 and parts[0] == "toolkit"
    exact = objects.get(target)
    if exact is not None and getattr(exact, "aliased", False):
        # the canonical name of an object documented under its public name
        return make_refnode(app.builder, node["refdoc"], exact.docname, exact.node_id, contnode, target)
    for k in range(len(parts), 0, -1):
        candidates = [c for c in index.get(".".join(parts[-k:]), [])
                      if types is None or objects[c].objtype in types]
        if not qualified and k < len(parts) or len(parts) == 1:
            # an unqualified name: within the module or class it was written in, else the one
            # object of that name and kind in the whole reference
            local = [c for c in candidates if context and c.startswith(context.rsplit(".", 1)[0] + ".")]
            candidates = local or (candidates if types is not None else [])
        if len(candidates) > 1:
            candidates = _closest(candidates, target if qualified else context, objects,
                                  _FIRST.get(node.get("reftype")))
            if len(candidates) > 1:
                return None                   # ambiguous: left for the build to report
        if len(candidates) == 1:
            entry = objects[candidates[0]]
            return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode,
                                candidates[0])
    return None


def setup(app):
    app.connect("missing-reference", _missing_reference, priority=900)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
