"""Architecture figures of the packages: modules, sizes, long functions, ``Any`` in public
signatures and function-local imports.

A function's length counts its lines from its signature to its end without the docstring (a
long docstring is documentation, not complexity). ``Any`` is counted where it is bare (an
argument or return annotated ``Any``, or ``Any`` inside another type); the JSON aliases of
:mod:`predisat.jsontypes` (``JsonDict``) are reported apart, as justified.

Usage: ``python scripts/architecture_metrics.py [--json FILE]`` (prints a table per package).
The figures of ``docs/architecture.md`` come from here.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("predisat", "locator")
LONG_LINES = 80


def _module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _functions(tree: ast.AST) -> list[tuple[str, int, ast.FunctionDef | ast.AsyncFunctionDef]]:
    out = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + child.name
                n = (child.end_lineno or child.lineno) - child.lineno + 1
                first = child.body[0]
                if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                        and isinstance(first.value.value, str)):
                    n -= (first.end_lineno or first.lineno) - first.lineno + 1
                out.append((name, n, child))
                visit(child, name + ".")
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + ".")

    visit(tree, "")
    return out


def _is_any(node: ast.AST | None) -> bool:
    return node is not None and any(
        isinstance(n, ast.Name) and n.id == "Any" for n in ast.walk(node)
    )


def _public(name: str) -> bool:
    return not any(part.startswith("_") for part in name.split("."))


def measure(root: Path = ROOT) -> dict[str, object]:
    """The figures of the source tree at ``root``, as a JSON-serialisable dict."""
    modules: dict[str, dict[str, int]] = {}
    local_imports = 0
    any_public: list[str] = []
    long_funcs: list[tuple[str, int]] = []
    for pkg in PACKAGES:
        for path in sorted((root / pkg).rglob("*.py")):
            name = _module_name(path, root)
            text = path.read_text()
            tree = ast.parse(text)
            modules[name] = {"lines": len(text.splitlines())}
            for node in ast.walk(tree):
                if isinstance(node, (ast.Import, ast.ImportFrom)) and node.col_offset > 0:
                    if not _in_type_checking(tree, node):
                        local_imports += 1
            for fname, n_lines, fn in _functions(tree):
                if n_lines > LONG_LINES:
                    long_funcs.append((f"{name}.{fname}", n_lines))
                if _public(fname) and not fname.split(".")[-1].startswith("_"):
                    args = fn.args
                    params = args.posonlyargs + args.args + args.kwonlyargs
                    params += [a for a in (args.vararg, args.kwarg) if a is not None]
                    for a in params:
                        if _is_any(a.annotation):
                            any_public.append(f"{name}.{fname}({a.arg})")
                    if _is_any(fn.returns):
                        any_public.append(f"{name}.{fname} -> Any")
    by_pkg: dict[str, list[str]] = defaultdict(list)
    for m in modules:
        parts = m.split(".")
        by_pkg[".".join(parts[:2]) if len(parts) > 2 else parts[0]].append(m)
    return {
        "packages": {p: {"modules": len(ms), "lines": sum(int(modules[m]["lines"]) for m in ms)}
                     for p, ms in sorted(by_pkg.items())},
        "modules": len(modules),
        "largest_module": max(((m, int(v["lines"])) for m, v in modules.items()),
                              key=lambda x: x[1]),
        "functions_over_80_lines": sorted(long_funcs, key=lambda x: -x[1]),
        "any_in_public_signatures": any_public,
        "function_local_imports": local_imports,
    }


def _in_type_checking(tree: ast.AST, target: ast.AST) -> bool:
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            if any(n is target for n in ast.walk(node)):
                return True
    return False


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    ap.add_argument("--root", type=Path, default=ROOT,
                    help="source tree to measure (default: this checkout)")
    args = ap.parse_args(argv)
    m = measure(args.root)
    print(f"{'package':32} {'modules':>7} {'lines':>7}")
    for p, v in m["packages"].items():  # type: ignore[attr-defined]
        print(f"{p:32} {v['modules']:7d} {v['lines']:7d}")
    print(f"modules: {m['modules']}; largest: {m['largest_module']}")
    longs = m["functions_over_80_lines"]
    print(f"functions over {LONG_LINES} lines: {len(longs)}")  # type: ignore[arg-type]
    for f, n in longs:  # type: ignore[attr-defined]
        print(f"  {n:4d}  {f}")
    anys = m["any_in_public_signatures"]
    print(f"Any in public signatures: {len(anys)}")  # type: ignore[arg-type]
    for a in anys:  # type: ignore[attr-defined]
        print(f"  {a}")
    print(f"function-local imports: {m['function_local_imports']}")
    if args.json:
        args.json.write_text(json.dumps(m, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
