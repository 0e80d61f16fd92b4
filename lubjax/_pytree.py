"""How lubjax's value classes become JAX pytrees: one helper, :func:`register`.

A class names its ``data`` fields (leaves) and its ``static`` ones (structure). Unflattening
bypasses ``__init__``, whose checks must not see tracers (``register_dataclass`` calls it).
"""

from __future__ import annotations

import jax


def register(cls, data=(), static=(), leaf=None):
    """Register ``cls`` as a pytree with leaves ``data`` and structure ``static`` (field names).
    ``leaf``: {field: function} applied to a data field when flattening (a tuple stored on a
    checked instance that travels as one array leaf). Returns ``cls``."""
    data, static, leaf = tuple(data), tuple(static), dict(leaf or {})

    def flatten(obj):
        leaves = tuple(leaf[n](getattr(obj, n)) if n in leaf else getattr(obj, n) for n in data)
        return leaves, tuple(getattr(obj, n) for n in static)

    def unflatten(aux, children):
        obj = object.__new__(cls)
        for n, v in zip(data, children):
            object.__setattr__(obj, n, v)
        for n, v in zip(static, aux):
            object.__setattr__(obj, n, v)
        return obj

    jax.tree_util.register_pytree_node(cls, flatten, unflatten)
    return cls
