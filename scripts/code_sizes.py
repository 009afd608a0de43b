"""Sizes a reader can hold: the largest module, class and function of a package.

Prints the largest modules (lines), classes and functions (lines, from the
``def``/``class`` line to the last line of the body) and every ``return``
or ``yield`` of a tuple literal with more than three elements (those should
be NamedTuples), and writes the same as JSON with ``--json``. Exits 1 when a
limit is exceeded.

    python scripts/code_sizes.py            # otjax/
    python scripts/code_sizes.py --top 5 --json sizes.json
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from pathlib import Path

LIMITS = {"module": 500, "class": 300, "function": 80}


def measure(root: Path) -> dict:
    modules, classes, functions, tuples = [], [], [], []
    for path in sorted(root.rglob("*.py")):
        text = path.read_text()
        name = str(path)
        modules.append((len(text.splitlines()), name))
        tree = ast.parse(text)
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                classes.append((node.end_lineno - node.lineno + 1, f"{name}:{node.lineno} {node.name}"))
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                functions.append((node.end_lineno - node.lineno + 1, f"{name}:{node.lineno} {node.name}"))
            elif isinstance(node, (ast.Return, ast.Yield)) and isinstance(node.value, ast.Tuple):
                if len(node.value.elts) > 3:
                    tuples.append((len(node.value.elts), f"{name}:{node.lineno}"))
    return {kind: sorted(items, reverse=True) for kind, items in
            (("module", modules), ("class", classes), ("function", functions), ("tuple", tuples))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", nargs="?", default="otjax", help="package directory (default: otjax)")
    parser.add_argument("--top", type=int, default=3, help="rows per kind (default: 3)")
    parser.add_argument("--json", help="also write the measurements here")
    args = parser.parse_args(argv)
    root = Path(args.root)
    if not root.is_dir():
        parser.error(f"{root} is not a directory")
    sizes = measure(root)
    over = False
    for kind in ("module", "class", "function"):
        print(f"largest {kind}s (limit {LIMITS[kind]} lines):")
        for n, where in sizes[kind][: args.top]:
            flag = "  <-- over" if n > LIMITS[kind] else ""
            over |= n > LIMITS[kind]
            print(f"  {n:5d}  {where}{flag}")
    print(f"tuples of more than three fields returned or yielded: {len(sizes['tuple'])}")
    for n, where in sizes["tuple"]:
        print(f"  {n:5d}  {where}")
    if args.json:
        Path(args.json).write_text(json.dumps(sizes, indent=1))
    return 1 if over or sizes["tuple"] else 0


if __name__ == "__main__":
    sys.exit(main())
