"""Count the size figures that issue 44 targets, from the source tree (AST based).

Definitions
-----------
physical lines
    Every line of every ``tubejax/**/*.py`` file, as ``wc -l`` counts them.
code lines
    Lines that hold part of a statement or expression: blank lines, comment-only lines and docstrings
    (a string literal that is the first statement of a module, class or function) are not counted.
function length
    Physical lines from ``def`` (decorators excluded) to the function's last line, and code lines inside one function's ``def`` ... last line (the same definition); nested functions are
    counted both in themselves and inside the function that holds them.
parameters
    All parameters of a function (positional, keyword-only, ``*args`` and ``**kwargs`` each counting one),
    ``self`` and ``cls`` excluded.

Usage: ``python scripts/house_counts.py [ROOT] [--top N]``.
"""

from __future__ import annotations

import argparse
import ast
import io
import tokenize
from pathlib import Path

LONG_FUNCTION = 80
WIDE_SIGNATURE = 8


def _docstring_lines(tree: ast.AST) -> set[int]:
    """Line numbers covered by module, class and function docstrings."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                lines.update(range(body[0].lineno, body[0].end_lineno + 1))
    return lines


def _code_lines(source: str, tree: ast.AST) -> set[int]:
    """Line numbers that carry a token other than a comment, a newline or a docstring."""
    skip = {tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
            tokenize.ENCODING, tokenize.ENDMARKER}
    lines: set[int] = set()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type not in skip:
            lines.update(range(token.start[0], token.end[0] + 1))
    return lines - _docstring_lines(tree)


def _parameters(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    args = node.args
    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
    names += [a.arg for a in (args.vararg, args.kwarg) if a is not None]
    return sum(name not in ("self", "cls") for name in names)


def count(root: Path) -> dict:
    """Count lines, long functions and wide signatures under ``root / 'tubejax'``."""
    physical = code = 0
    functions = []
    for path in sorted((root / "tubejax").rglob("*.py")):
        source = path.read_text()
        tree = ast.parse(source, filename=str(path))
        physical += len(source.splitlines())
        lines = _code_lines(source, tree)
        code += len(lines)
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                span = range(node.lineno, node.end_lineno + 1)
                functions.append({
                    "where": f"{path.relative_to(root)}:{node.lineno}",
                    "name": node.name,
                    "physical_lines": len(span),
                    "code_lines": sum(line in lines for line in span),
                    "parameters": _parameters(node),
                })
    return {"physical": physical, "code": code, "functions": functions}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", nargs="?", default=".", type=Path)
    parser.add_argument("--top", type=int, default=10, help="how many of the worst to list")
    args = parser.parse_args()
    result = count(args.root)
    long = sorted((f for f in result["functions"] if f["code_lines"] > LONG_FUNCTION),
                  key=lambda f: -f["code_lines"])
    long_physical = sorted((f for f in result["functions"] if f["physical_lines"] > LONG_FUNCTION),
                           key=lambda f: -f["physical_lines"])
    wide = sorted((f for f in result["functions"] if f["parameters"] > WIDE_SIGNATURE),
                  key=lambda f: -f["parameters"])
    print(f"library physical lines (wc -l): {result['physical']}")
    print(f"library code lines (no blank, comment or docstring lines): {result['code']}")
    print(f"functions: {len(result['functions'])}")
    print(f"functions over {LONG_FUNCTION} physical lines: {len(long_physical)}")
    print(f"functions over {LONG_FUNCTION} code lines: {len(long)}")
    print("  (code / physical lines; the longest by physical lines)")
    for f in long_physical[:args.top]:
        print(f"  {f['code_lines']:4d} / {f['physical_lines']:4d}  {f['name']}  {f['where']}")
    print(f"functions with more than {WIDE_SIGNATURE} parameters (self/cls excluded): {len(wide)}")
    for f in wide[:args.top]:
        print(f"  {f['parameters']:4d}  {f['name']}  {f['where']}")


if __name__ == "__main__":
    main()
