"""`sweep FILE --vary PATH=VALUES`: the numbers of a mechanism file (`kind = "mechanism"` or `"chain"`) that a
sweep maps.

A PATH names one number of the file as its tables and arrays nest, keys and (0-based) indices
joined by dots: `bodies.0.mass`, `bodies.0.friction.mu_s_fwd`, `links.1.k`, `links.1.waveform.omega`,
`links.2.waveform.cos.1`; in a chain file `chain.k`, `chain.masses.3`, `friction.mu_s_bwd`,
`waveform.phi` (a chain's per-spring or per-mass number swept alone is one value for every spring
or mass). A field the file leaves at its default may be named too (`bodies.1.c`,
`links.0.rest`). Several paths joined by commas take the same values (one dimension): the
waveforms of one mechanism share their base frequency, so `links.1.waveform.omega,links.2.waveform.omega`
sweeps it. VALUES is read as the other axes of `sweep` (`parse_axis`): `start:stop:count`, `v1,v2,...`
or one value (fixed, no dimension).

The file is read and checked once as it is ([`load`][locomotion_jax.cli._files.load]: errors name its
line and field). The builder given to `lj.sweep(axes, mechanism=...)` reads the same parsed file again
with each named number replaced by its values ([`Swept`][locomotion_jax.model._files.Swept]), so the
reader's constructors build the batch: no loop over configurations, and the mechanism is the one the
file describes with those numbers in it. It is built unchecked: `lj.sweep` checks every configuration
(`on_invalid="raise"`) or flags the invalid ones (`"flag"`).
"""

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


OPTION = "--vary"

STRUCTURE: dict[str, tuple[str, ...]] = {"bodies": ("carried_by",), "links": ("a", "b", "i")}
"""Integer fields of the arrays of tables that say which body, not how much: not swept."""


def split(text: str) -> tuple[list[str], str]:
    """`--vary`'s text `PATH[,PATH...]=VALUES` as the paths and the values' text.

    **Raises:** `ValueError` naming the option for text without `=` or with an empty path.
    """
    name, sep, values = text.partition("=")
    paths = [p.strip() for p in name.split(",")]
    if not sep or not all(paths) or not values.strip():
        raise ValueError(
            f"{OPTION} {text!r}: expected PATH=VALUES, e.g. {OPTION} links.1.k=5:20:4 or "
            f"{OPTION} bodies.0.mass=0.5,1,2."
        )
    return paths, values.strip()


def _fields(node: Any) -> str:
    if isinstance(node, dict):
        return "its fields are " + (", ".join(node) if node else "none")
    return f"its indices are 0 to {len(node) - 1}"


def _what(node: Any) -> str:
    if isinstance(node, dict):
        return "a table"
    if isinstance(node, list):
        return f"a list of {len(node)}"
    return repr(node)


def locate(data: dict[str, Any], path: str) -> tuple[Any, str | int]:
    """The container (table or list) of the parsed file `data` that holds `path`'s number, and its key.

    **Raises:** `ValueError` naming the option, the path and what exists where it goes wrong: a
    key or index the file does not have, a table, list or text where a number is expected, a body
    index or the schema version.
    """
    keys = path.split(".")
    node: Any = data
    for depth, key in enumerate(keys):
        here = ".".join(keys[:depth]) or "the file's top level"
        last = depth == len(keys) - 1
        if isinstance(node, list):
            if not (key.isdigit() and int(key) < len(node)):
                shown = "an empty list" if not node else f"a list of {len(node)} ({_fields(node)})"
                raise ValueError(f"{OPTION} {path}: {here} is {shown}; {key!r} is not one of its indices.")
            index: str | int = int(key)
        elif isinstance(node, dict):
            if key not in node and not last:
                raise ValueError(f"{OPTION} {path}: {here} has no field {key!r}; {_fields(node)}.")
            index = key
        else:
            where = ".".join(keys[:depth])
            raise ValueError(f"{OPTION} {path}: {where} is the number {node!r}; it has no field {key!r}.")
        if last:
            value = node.get(index) if isinstance(node, dict) else node[index]  # type: ignore[call-overload]
            if value is not None and not (isinstance(value, (int, float)) and not isinstance(value, bool)):
                hint = f" ({_fields(value)})" if isinstance(value, (dict, list)) and value else ""
                raise ValueError(f"{OPTION} {path}: this is {_what(value)}{hint}, not a number; name one number.")
            if (depth == 0 and key == "schema") or (depth == 2 and key in STRUCTURE.get(keys[0], ())):
                raise ValueError(f"{OPTION} {path}: {key!r} says which {'schema' if depth == 0 else 'body'} the file "
                                 "uses, not a number to sweep.")  # fmt: skip
            return node, index
        node = node[index]  # type: ignore[index]
    raise AssertionError("unreachable")  # pragma: no cover - the loop returns at its last key


def builder(file: Path, data: dict[str, Any], paths: dict[str, list[str]]) -> Callable[..., Any]:
    """`mechanism=` of `lj.sweep` for the file: called with one 1-D array (or one number) per name of
    `paths` (a dimension or fixed value: its paths), it returns the file's mechanism with those
    numbers, a batch. Errors of the reader (a field the schema does not have, values that do not
    fit together) come back as a `ValueError` naming the option and the paths."""
    from ..model._files import _Source, read_document, Swept

    source = _Source(str(file), file.read_text("utf-8"))

    def build(**values: Any) -> Any:
        doc = copy.deepcopy(data)
        for name, these in paths.items():
            for path in these:
                container, key = locate(doc, path)
                container[key] = Swept(np.atleast_1d(np.asarray(values[name], float)))
        try:
            return read_document(source, doc, check=False)[0]
        except ValueError as err:
            swept = [n for n in values if np.size(values[n]) > 1] or list(values)
            hint = ""
            if "base frequency" in str(err):
                hint = (" Sweep the frequencies of all waveforms together: their paths joined by commas, e.g. "
                        f"{OPTION} links.1.waveform.omega,links.2.waveform.omega=1:6:32.")  # fmt: skip
            raise ValueError(" ".join(f"{OPTION} {n}" for n in swept) + f": {err}{hint}") from None

    return build


def plan(file: Path, texts: list[str]) -> tuple[dict[str, float | np.ndarray], Callable[..., Any]]:
    """The values of each dimension or fixed value (named by its paths as given, in order) of the
    `--vary` options `texts`, and the builder of the file's mechanism (`builder`). Every path is
    checked against the file, and the mechanism built with each dimension's values in turn (the
    others at their first), before any computation. **Raises:** `ValueError` naming the option."""
    from ..model._files import tomllib
    from ._commands import parse_axis

    data = tomllib.loads(file.read_text("utf-8"))  # after `load`, which has checked the file
    values: dict[str, float | np.ndarray] = {}
    paths: dict[str, list[str]] = {}
    seen: dict[str, str] = {}
    for text in texts:
        these, numbers = split(text)
        name = ",".join(these)
        for path in these:
            locate(data, path)
            if path in seen:
                raise ValueError(f"{OPTION} {path}: given twice ({seen[path]!r} and {text!r}).")
            seen[path] = text
        values[name] = parse_axis(name, numbers, option=f"{OPTION} {name}={numbers}")
        paths[name] = these
    build = builder(file, data, paths)
    first = {n: np.ravel(v)[:1] for n, v in values.items()}
    for name, v in values.items():
        build(**{**first, name: np.atleast_1d(v)})
    return values, build
