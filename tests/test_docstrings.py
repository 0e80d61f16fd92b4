"""Every public name's docstring is in Google style, as the API pages (mkdocstrings) parse it.

Public: the names in ``lubjax.__all__``, ``lubjax.stepper.__all__`` and ``fitting.__all__``, and
the public methods and properties the classes among them define. Each docstring is parsed with
griffe's Google parser, the one mkdocstrings uses, and checked:

* every parameter of the signature (but ``self``/``cls``, and ``*args``/``**kwargs`` unless
  documented) has its own entry in ``Args:`` (a class: in ``Args:`` or ``Attributes:``), and
  ``Args:`` names nothing the signature lacks;
* a function or method that returns a value has ``Returns:`` (one that yields, ``Yields:``);
* an exception the body raises by name is listed under ``Raises:``;
* a NamedTuple lists every field under ``Attributes:``;
* a constant or module has a docstring (a ``#:`` comment or a string after the assignment).
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import logging
import textwrap
from pathlib import Path
from typing import NamedTuple

import griffe
import pytest

import fitting
import lubjax
import lubjax.stepper

ROOT = Path(__file__).resolve().parent.parent
MODULES = {"lubjax": lubjax, "lubjax.stepper": lubjax.stepper, "fitting": fitting}

# griffe logs what it tolerates (entries without types, which these docstrings leave to the
# signature); the checks below are the ones this project holds its docstrings to.
logging.getLogger("griffe").setLevel(logging.ERROR)


def sections(doc: str) -> dict[str, list]:
    """The parsed sections of a docstring, by kind ("parameters", "returns", ...)."""
    parsed = griffe.parse_google(
        griffe.Docstring(inspect.cleandoc(doc)),
        warn_missing_types=False,
        warn_unknown_params=False,
        returns_named_value=False,
        returns_multiple_items=False,
    )
    found: dict[str, list] = {}
    for section in parsed:
        value = section.value if isinstance(section.value, list) else [section.value]
        found.setdefault(section.kind.value, []).extend(value)
    return found


def _own_nodes(function: ast.AST):
    """The nodes of a function's body, but not of the functions and classes defined in it."""
    stack = list(ast.iter_child_nodes(function))
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue
        yield node
        stack.extend(ast.iter_child_nodes(node))


def _syntax(function) -> ast.AST | None:
    try:
        source = textwrap.dedent(inspect.getsource(function))
    except (OSError, TypeError):
        return None
    tree = ast.parse(source)
    return tree.body[0] if tree.body else None


def body_facts(function) -> tuple[bool, bool, set[str]]:
    """(returns a value, yields, names of the exceptions raised) of a function's own body."""
    node = _syntax(function)
    if node is None:
        return False, False, set()
    returns = yields = False
    raised: set[str] = set()
    for child in _own_nodes(node):
        if isinstance(child, ast.Return) and child.value is not None:
            returns = returns or not (
                isinstance(child.value, ast.Constant) and child.value.value is None
            )
        elif isinstance(child, (ast.Yield, ast.YieldFrom)):
            yields = True
        elif isinstance(child, ast.Raise) and child.exc is not None:
            exc = child.exc.func if isinstance(child.exc, ast.Call) else child.exc
            if isinstance(exc, ast.Name) and exc.id[:1].isupper():
                raised.add(exc.id)
    return returns, yields, raised


def _parameters(signature: inspect.Signature, documented: set[str]) -> list[str]:
    names = []
    for p in signature.parameters.values():
        if p.name in ("self", "cls"):
            continue
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) and p.name not in documented:
            continue
        names.append(p.name)
    return names


def _is_type(text: str) -> bool:
    """Whether a Returns section's text before its first colon reads as a type (``Result``,
    ``tuple[float, float]``), not as prose ("The :class:", "A dict") the colon cuts short."""
    if text != text.strip() or text.startswith("(") or " " in text.replace(", ", ","):
        return False
    try:
        ast.parse(text, mode="eval")
    except SyntaxError:
        return False
    return True


def _entry_names(entries) -> list[str]:
    return [e.name.lstrip("*") for e in entries]


def function_problems(function, name: str, *, documented_elsewhere=()) -> list[str]:
    """What the docstring of a function or method lacks or gets wrong."""
    doc = inspect.getdoc(function)
    if not doc:
        return [f"{name}: no docstring"]
    found = sections(doc)
    problems = []
    args = _entry_names(found.get("parameters", []))
    for entry in args:
        if "," in entry or " " in entry:
            problems.append(f"{name}: Args entry {entry!r} names more than one parameter")
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):
        signature = None
    if signature is not None:
        wanted = _parameters(signature, set(args))
        for p in wanted:
            if p not in args and p not in documented_elsewhere:
                problems.append(f"{name}: parameter {p!r} not under Args")
        for entry in args:
            if entry not in signature.parameters and "," not in entry:
                problems.append(f"{name}: Args names {entry!r}, which is not a parameter")
    returns, yields, raised = body_facts(function)
    if returns and not found.get("returns"):
        problems.append(f"{name}: returns a value but has no Returns section")
    for entry in found.get("returns", []):
        if entry.annotation is not None and not _is_type(str(entry.annotation)):
            problems.append(f"{name}: Returns starts with {str(entry.annotation)!r} and a colon, "
                            "which the API page shows as the type: write 'Type: description'")
    if yields and not found.get("yields"):
        problems.append(f"{name}: yields but has no Yields section")
    listed = {str(e.annotation).split(".")[-1] for e in found.get("raises", [])}
    for exc in sorted(raised - listed):
        problems.append(f"{name}: raises {exc} but Raises does not list it")
    return problems


def _own_members(cls):
    """The public methods and properties a class defines itself (not inherited from tuple)."""
    for attr, value in vars(cls).items():
        if attr.startswith("_"):
            continue
        if isinstance(value, property):
            yield attr, value
        elif isinstance(value, (staticmethod, classmethod)):
            yield attr, value.__func__
        elif inspect.isfunction(value):
            yield attr, value


def _is_namedtuple(cls) -> bool:
    return issubclass(cls, tuple) and hasattr(cls, "_fields")


def class_problems(cls, name: str) -> list[str]:
    """What the docstrings of a class and of its public methods and properties lack."""
    doc = inspect.getdoc(cls) if cls.__doc__ else None
    if not doc or (_is_namedtuple(cls) and doc.startswith(f"{cls.__name__}(")):
        return [f"{name}: no docstring"]
    found = sections(doc)
    attributes = _entry_names(found.get("attributes", []))
    problems = []
    if _is_namedtuple(cls):
        for field in cls._fields:
            if field not in attributes:
                problems.append(f"{name}: field {field!r} not under Attributes")
        for entry in attributes:
            if entry not in cls._fields and not hasattr(cls, entry):
                problems.append(f"{name}: Attributes names {entry!r}, which is not a field")
    elif dataclasses.is_dataclass(cls):
        args = _entry_names(found.get("parameters", []))
        fields = [f.name for f in dataclasses.fields(cls) if f.init]
        for field in fields:
            if field not in attributes + args:
                problems.append(f"{name}: field {field!r} not under Attributes or Args")
        for entry in args:
            if entry not in fields:
                problems.append(f"{name}: Args names {entry!r}, which is not a field")
    if not issubclass(cls, BaseException) and not _is_namedtuple(cls):
        # The constructor's parameters, merged into the class's page (merge_init_into_class).
        init = cls.__dict__.get("__init__")
        if init is not None and not dataclasses.is_dataclass(cls):
            merged = inspect.getdoc(init) if init.__doc__ else None
            text = doc if not merged else merged
            problems += [
                p.replace(f"{name}.__init__", name)
                for p in function_problems(
                    _with_doc(init, text), f"{name}.__init__", documented_elsewhere=attributes
                )
                if "Returns" not in p
            ]
    for attr, member in _own_members(cls):
        member_name = f"{name}.{attr}"
        if isinstance(member, property):
            if not (member.fget and member.fget.__doc__ and member.fget.__doc__.strip()):
                problems.append(f"{member_name}: no docstring")
            continue
        problems += function_problems(member, member_name)
    return problems


def _with_doc(function, doc):
    """A stand-in with ``function``'s signature and source but another docstring."""

    def stand_in(*args, **kwargs):
        pass

    stand_in.__signature__ = inspect.signature(function)
    stand_in.__doc__ = doc
    stand_in.__wrapped__ = function
    return stand_in


def problems_of(module, name: str) -> list[str]:
    obj = getattr(module, name)
    full = f"{module.__name__}.{name}"
    if inspect.ismodule(obj):
        return [] if (obj.__doc__ or "").strip() else [f"{full}: no module docstring"]
    if inspect.isclass(obj):
        return class_problems(obj, full)
    if callable(obj):
        return function_problems(obj, full)
    return constant_problems(module, name)


_LOADED: dict[str, griffe.Object] = {}


def constant_problems(module, name: str) -> list[str]:
    """A constant's docstring, as griffe (and so the API page) finds it."""
    package = module.__name__.split(".")[0]
    if package not in _LOADED:
        _LOADED[package] = griffe.load(package, resolve_aliases=True)
    found = _LOADED[package][module.__name__.removeprefix(package).lstrip(".") or name]
    if module.__name__ != package:
        found = found[name]
    elif found.name != name:
        found = _LOADED[package][name]
    target = found.final_target if found.is_alias else found
    if target.docstring is None or not target.docstring.value.strip():
        return [f"{module.__name__}.{name}: no docstring"]
    return []


PUBLIC = [(label, name) for label, module in MODULES.items() for name in module.__all__]


@pytest.mark.parametrize(("label", "name"), PUBLIC, ids=[f"{a}.{b}" for a, b in PUBLIC])
def test_public_docstring_follows_the_style(label, name):
    problems = problems_of(MODULES[label], name)
    assert not problems, "\n".join(problems)


def test_every_public_name_has_its_api_entry():
    pages = "".join(p.read_text() for p in (ROOT / "docs" / "api").glob("*.md"))
    missing = [f"{a}.{b}" for a, b in PUBLIC if f"::: {a}.{b}\n" not in pages and b != "stepper"]
    assert not missing, f"not on an API page (docs/api/*.md): {missing}"


# The checker itself: each broken docstring below must be caught, the sound one passed.


def _sound(beta, z0, *, settings=None):
    """Do a thing.

    Args:
        beta: β, dimensionless, > 0.
        z0: z̄0, dimensionless.
        settings: accuracy.

    Returns:
        F̄.

    Raises:
        ValueError: β ≤ 0.
    """
    if beta <= 0:
        raise ValueError("beta")
    return beta * z0


def _missing_parameter(beta, z0):
    """Do a thing.

    Args:
        beta: β.

    Returns:
        F̄.
    """
    return beta * z0


def _unknown_parameter(beta):
    """Do a thing.

    Args:
        beta: β.
        gamma: not a parameter.

    Returns:
        F̄.
    """
    return beta


def _two_in_one_entry(beta, z0):
    """Do a thing.

    Args:
        beta, z0: β and z̄0.

    Returns:
        F̄.
    """
    return beta * z0


def _no_returns(beta):
    """Do a thing.

    Args:
        beta: β.
    """
    return 2 * beta


def _raise_unlisted(beta):
    """Do a thing.

    Args:
        beta: β.
    """
    if beta < 0:
        raise ValueError("beta")


def _prose_before_colon(beta):
    """Do a thing.

    Args:
        beta: β.

    Returns:
        The :class:`Result`: F̄.
    """
    return beta


def _numpy_style(beta):
    """Do a thing.

    Parameters
    ----------
    beta : float
        β.

    Returns
    -------
    float
    """
    return beta


class _Fields(NamedTuple):
    """A pair.

    Attributes:
        a: the first.
    """

    a: float
    b: float


class _FieldsLost(NamedTuple):
    """Fields documented, but not declared.

    Attributes:
        a: the first.
    """


class _Plain:
    """A thing.

    Args:
        x: the x.
    """

    def __init__(self, x, y):
        self.x, self.y = x, y

    @property
    def z(self):
        return self.x

    def total(self):
        """The sum."""
        return self.x + self.y


def test_the_checker_passes_a_sound_docstring():
    assert function_problems(_sound, "sound") == []


@pytest.mark.parametrize(
    ("function", "words"),
    [
        (_missing_parameter, "parameter 'z0' not under Args"),
        (_unknown_parameter, "Args names 'gamma', which is not a parameter"),
        (_two_in_one_entry, "names more than one parameter"),
        (_no_returns, "returns a value but has no Returns section"),
        (_raise_unlisted, "raises ValueError but Raises does not list it"),
        (_numpy_style, "parameter 'beta' not under Args"),
        (_prose_before_colon, "which the API page shows as the type"),
    ],
)
def test_the_checker_catches_a_broken_docstring(function, words):
    problems = function_problems(function, "broken")
    assert any(words in p for p in problems), problems


def test_the_checker_catches_undocumented_fields_parameters_and_members():
    assert class_problems(_Fields, "fields") == ["fields: field 'b' not under Attributes"]
    assert class_problems(_FieldsLost, "lost") == [
        "lost: Attributes names 'a', which is not a field"]
    problems = class_problems(_Plain, "plain")
    assert "plain: parameter 'y' not under Args" in problems
    assert "plain.z: no docstring" in problems
    assert "plain.total: returns a value but has no Returns section" in problems
