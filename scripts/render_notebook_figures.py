"""Runs the research notebooks and saves their figures as PNGs.

Each notebook in ``notebooks/`` is executed with nbclient (the committed
notebooks stay stripped: the executed copy lives in memory only). The image
output of the cell tagged ``readme-figure`` is written to
``docs/notebooks/<notebook>.png``, and ``docs/notebooks/figures.json`` records,
per notebook, the figure, the size the notebook ran at, the wall time and the
text its last cell printed (the results in numbers).

Usage::

    python scripts/render_notebook_figures.py                 # full size (minutes)
    python scripts/render_notebook_figures.py --size small    # the size the tests use
    python scripts/render_notebook_figures.py --only gradient_relocation
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parent.parent
TAG = "readme-figure"


def run_notebook(path: Path, size: str, timeout: int) -> tuple[nbformat.NotebookNode, float]:
    """Executes ``path`` at ``size`` (``OTJAX_NOTEBOOK_SIZE``); returns it with outputs and its time."""
    os.environ["OTJAX_NOTEBOOK_SIZE"] = size
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, timeout=timeout, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    client.execute()
    return nb, time.perf_counter() - t0


def tagged_png(nb: nbformat.NotebookNode) -> bytes:
    """The first PNG output of the first cell tagged ``readme-figure``."""
    for cell in nb.cells:
        if TAG in cell.get("metadata", {}).get("tags", []):
            for out in cell.get("outputs", []):
                data = out.get("data", {})
                if "image/png" in data:
                    return base64.b64decode(data["image/png"])
            raise RuntimeError(f"the cell tagged {TAG!r} produced no PNG")
    raise RuntimeError(f"no cell is tagged {TAG!r}")


def last_text(nb: nbformat.NotebookNode) -> str:
    """What the last code cell printed."""
    code = [c for c in nb.cells if c.cell_type == "code"]
    return "".join(o.get("text", "") for o in code[-1].get("outputs", []) if o.get("output_type") == "stream")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", choices=("small", "full"), default="full")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "notebooks")
    parser.add_argument("--only", nargs="*", help="notebook names (without .ipynb); default: all")
    parser.add_argument("--timeout", type=int, default=1800, help="seconds per cell")
    args = parser.parse_args(argv)
    paths = sorted((ROOT / "notebooks").glob("*.ipynb"))
    if args.only:
        paths = [p for p in paths if p.stem in set(args.only)]
    args.out.mkdir(parents=True, exist_ok=True)
    index_path = args.out / "figures.json"
    index = json.loads(index_path.read_text()) if index_path.exists() else {}
    for path in paths:
        print(f"{path.name}: running at size {args.size} ...", flush=True)
        nb, seconds = run_notebook(path, args.size, args.timeout)
        png = args.out / f"{path.stem}.png"
        png.write_bytes(tagged_png(nb))
        index[path.stem] = {"figure": str(png.relative_to(ROOT)), "size": args.size,
                            "seconds": round(seconds, 1), "results": last_text(nb)}
        print(f"  {seconds:.1f} s -> {png.relative_to(ROOT)}", flush=True)
        index_path.write_text(json.dumps(index, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
