"""No module of the package over 600 lines, no function over 100 lines but compiled kernels.

Past those sizes a unit stops being something one reads whole before changing it; a compiled
kernel is exempt because numba cannot call back into a helper as cheaply as it runs a loop
inline; so is an ``@inline`` helper, which is compiled into the kernels that call it (two
kernels may share one long loop that way).
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "monoplane"
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 100


def _compiled(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Decorated with ``@kernel`` / ``@jit.kernel``, ``@inline`` or ``@numba.njit(...)``."""
    for d in fn.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        name = ast.unparse(target)
        if name.split(".")[-1] in ("kernel", "inline", "njit", "jit"):
            return True
    return False


def test_no_module_is_over_600_lines() -> None:
    long = {str(p.relative_to(PACKAGE.parent)): n for p in sorted(PACKAGE.rglob("*.py"))
            if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES}
    assert long == {}


def test_no_function_is_over_100_lines_but_compiled_kernels() -> None:
    long = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        for fn in ast.walk(ast.parse(path.read_text())):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)) and not _compiled(fn):
                lines = fn.end_lineno - fn.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long[f"{path.relative_to(PACKAGE.parent)}:{fn.name}"] = lines
    assert long == {}


def test_the_size_check_sees_a_long_function_and_exempts_a_kernel() -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES + 1))
    plain, kernel = (ast.parse(f"{d}def f():\n{body}\n").body[0]
                     for d in ("", "@kernel\n"))
    assert plain.end_lineno - plain.lineno + 1 > MAX_FUNCTION_LINES
    assert not _compiled(plain) and _compiled(kernel)
