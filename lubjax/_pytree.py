"""How lubjax's value classes become JAX pytrees: one helper, :func:`register`.

A class names its ``data`` fields (leaves: traced, differentiated, batched) and its ``static``
fields (part of the tree's structure: a change compiles a new program). Unflattening bypasses
``__init__``: under ``jit``/``vmap`` the leaves are tracers or placeholders, which the class's
checks (run when it was built from concrete values, lubjax/_checks.py) must not see.
(``jax.tree_util.register_dataclass`` calls ``__init__``, so it serves only classes without
checks.)
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
