"""Write a synthetic point set and its ground truth to disk.

    python scripts/make_data.py NAME [-n N] [--noise S] [--outliers K] [--seed S] -o OUT.xy

NAME is a shape (star, skyline, junctions, circle; defaults: clean, no
outliers) or a built-in example (noisy-star, star-outliers, ...; defaults:
the example's own n, noise and outliers). Options override those defaults.

OUT.xy gets one ``x y mass`` line per point (unit masses, outliers last);
OUT.truth.json gets the truth arrays as nested lists plus the parameters used.
Both are written atomically (temporary file, then rename).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

import numpy as np

from otjax import datasets


def _write_atomic(path: str, text: str) -> None:
    """Write ``text`` to ``path`` so that readers never see a partial file."""
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)), prefix=".tmp-")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def truth_path(out: str) -> str:
    """``OUT.xy`` -> ``OUT.truth.json`` (any extension is replaced)."""
    return os.path.splitext(out)[0] + ".truth.json"


def _to_json(truth: dict) -> str:
    plain = {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in truth.items()}
    return json.dumps(plain, indent=1)


def main(argv=None) -> int:
    names = sorted(set(datasets.SHAPES) | set(datasets.EXAMPLES))
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("name", choices=names, metavar="NAME", help=f"one of: {', '.join(names)}")
    parser.add_argument("-n", type=int, help="number of shape samples (outliers not included)")
    parser.add_argument("--noise", type=float, help="Gaussian noise std, as a fraction of the diagonal")
    parser.add_argument("--outliers", type=int, help="number of uniform outliers")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("-o", "--output", required=True, metavar="OUT.xy")
    args = parser.parse_args(argv)
    if args.n is not None and args.n < 1:
        parser.error(f"-n must be >= 1, got {args.n}")
    if args.noise is not None and not args.noise >= 0:
        parser.error(f"--noise must be >= 0, got {args.noise}")
    if args.outliers is not None and args.outliers < 0:
        parser.error(f"--outliers must be >= 0, got {args.outliers}")
    folder = os.path.dirname(os.path.abspath(args.output))
    if not os.path.isdir(folder):
        parser.error(f"output folder does not exist: {folder}")

    points, truth = datasets.generate(args.name, args.n, args.noise, args.outliers, args.seed)
    rows = np.column_stack([points, np.ones(len(points))])
    _write_atomic(args.output, "".join(f"{x:.17g} {y:.17g} {m:g}\n" for x, y, m in rows))
    _write_atomic(truth_path(args.output), _to_json(truth))
    print(f"wrote {len(points)} points to {args.output} and truth to {truth_path(args.output)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
