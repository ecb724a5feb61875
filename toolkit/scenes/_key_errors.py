"""A constructor's refusal named by the scene key that set the value: the
:class:`~toolkit.errors.ParameterError` of a constructor becomes a
:class:`~toolkit.errors.SceneError` that keeps its rule and value and adds the key.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager

from ..errors import ParameterError, ParameterTypeError, SceneError


@contextmanager
def _scene_keys(section: str, keys: Mapping[str, str | tuple[str, ...]]) -> Iterator[None]:
    """Turn a constructor's parameter error into a SceneError naming the scene key.

    ``keys`` maps the constructor's parameter names to the scene key (or keys) that set them;
    the message keeps the constructor's rule and value (one template everywhere) and adds
    the key.
    """
    try:
        yield
    except SceneError:
        raise
    except (ParameterError, ParameterTypeError) as error:
        found = keys.get(error.parameter, ()) if error.parameter is not None else ()
        names = (found,) if isinstance(found, str) else found
        where = names[0].split(".")[0] if names else section
        suffix = (f" (scene keys {' and '.join(map(repr, names))})" if len(names) > 1
                  else f" (scene key {names[0]!r})" if names else "")
        raise SceneError(f"In [{where}]: {error}{suffix}") from None


def _same_keys(section: str, names: tuple[str, ...]) -> dict[str, str]:
    return {name: f"{section}.{name}" for name in names}
