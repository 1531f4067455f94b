"""The documentation's Python blocks, read from its pages, so that the tests run the classes a
reader copies (`docs/mechanisms.md`'s friction law, waveform and actuator, `docs/index.md`'s
dynamics) rather than copies of them."""

import ast
import re
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import locomotion_jax as lj
import numpy as np


DOCS = Path(__file__).resolve().parents[1] / "docs"


def block(page: str, name: str) -> ast.Module:
    """The one fenced Python block of `docs/<page>` that defines the class `name`, parsed."""
    blocks = re.findall(r"```python\n(.*?)```", (DOCS / page).read_text(), re.S)
    found = [b for b in blocks if re.search(rf"^class {name}\(", b, re.M)]
    assert len(found) == 1, f"docs/{page}: {len(found)} Python blocks define the class {name}"
    return ast.parse(found[0])


def _namespace(page: str) -> dict[str, Any]:
    """What the pages' blocks take as imported (`docs/index.md`'s first block imports them)."""
    return {"__name__": f"docs.{page}", "jax": jax, "jnp": jnp, "np": np, "lj": lj}


def doc_class(page: str, name: str) -> Any:
    """The class `name` as `docs/<page>` writes it: its class statement alone, without the lines
    of the block that use it."""
    (node,) = [n for n in block(page, name).body if isinstance(n, ast.ClassDef) and n.name == name]
    scope = _namespace(page)
    exec(compile(ast.Module([node], []), f"docs/{page}", "exec"), scope)
    return scope[name]


def run_block(page: str, name: str) -> tuple[Any, dict[str, Any]]:
    """Runs the whole block that defines `name`, as a reader would: the value of its last line
    (an expression) and the names it defined."""
    *body, last = block(page, name).body
    assert isinstance(last, ast.Expr), f"docs/{page}: the block of {name} ends in a statement"
    scope = _namespace(page)
    exec(compile(ast.Module(body, []), f"docs/{page}", "exec"), scope)
    return eval(compile(ast.Expression(last.value), f"docs/{page}", "eval"), scope), scope
