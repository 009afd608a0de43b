"""The ``otjax`` command line.

``otjax curve INPUT -n N -o out.json -o out.svg`` reconstructs a curve from a
point file or a grayscale image; ``otjax curve --example star`` runs on a
built-in synthetic shape, so the command works with no data at all. The
surface commands, ``otjax surface`` and ``otjax recover``, are in
:mod:`otjax.cli_surfaces`.

Bad input (unreadable file, NaN, duplicates, too many vertices, unknown output
extension, missing output directory, ...) ends with one line ``otjax: error:
<what is wrong>`` on stderr and exit status 1; output paths are checked before
any work, and the outputs are written all or nothing, so a failed run leaves no
file behind. Command-line usage errors exit with status 2 (argparse's
convention).
"""

from __future__ import annotations

import argparse
import gc
import sys

from otjax import datasets
from otjax.compile_cache import default_cache_dir, enable_compilation_cache
from otjax.curves.decimate import QUEUES
from otjax.curves.reconstruct import EXHAUSTIVE_COLLAPSES, LAZY_COLLAPSES, reconstruct_curve
from otjax.curves.result import SAVE_EXTENSIONS
from otjax.io import IMAGE_EXTENSIONS, TEXT_EXTENSIONS, check_output_paths, read_points, write_files
from otjax.validation import MAX_POINTS, check_points, check_target


def _curve_parser(sub) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "curve",
        help="reconstruct a 2D curve from points or an image",
        description=(
            "Reconstruct a curve (vertices + edges) from 2D points by optimal transport "
            "(de Goes et al. 2011). Inputs: "
            + " ".join(TEXT_EXTENSIONS)
            + " text (x y [mass] per line) or images "
            + " ".join(IMAGE_EXTENSIONS)
            + " (pixel intensity = mass)."
        ),
    )
    source = p.add_mutually_exclusive_group()
    source.add_argument("input", nargs="?", help="point file or image")
    source.add_argument("--example", metavar="NAME", help="use a built-in example instead of a file")
    source.add_argument("--list-examples", action="store_true", help="list the built-in examples and exit")
    p.add_argument(
        "-n",
        "--n-vertices",
        type=int,
        metavar="N",
        help="target number of vertices (required for files unless --tolerance is given; "
        "an example has its own default)",
    )
    p.add_argument(
        "-o",
        "--output",
        action="append",
        default=[],
        metavar="OUT",
        help=f"write the result; repeatable; extension one of {', '.join(SAVE_EXTENSIONS)}. "
        "Without -o only a summary is printed. All outputs are written or none",
    )
    p.add_argument("--mkdir", action="store_true",
                   help="create missing directories of the outputs (otherwise a missing one is an error)")
    p.add_argument("--tolerance", type=float, metavar="T",
                   help="tolerance mode: no collapse may push an edge's RMS normal or tangential transport "
                   "distance above T (input units). An RMS over the edge's points, not a maximum: single "
                   "points can end up farther than T")
    p.add_argument("--relevance", type=float, metavar="R", help="drop edges less relevant than R")
    p.add_argument("--density", type=float, metavar="F",
                   help="drop edges whose mass per length is below F (0..1) times the largest")
    p.add_argument("--background", choices=("auto", "none"),
                   help="estimate uniform background noise and discount it (auto, the default) or not")
    p.add_argument("--keep-chords", action="store_true", default=None,
                   help="keep the redundant chords of 3-cycles and spurs at junctions that noise leaves")
    p.add_argument("--keep-ends", action="store_true", default=None,
                   help="leave the open ends where the transport puts them (by default they move to where "
                   "their points end)")
    p.add_argument("--relocation", type=int, metavar="K",
                   help="relocate during the last K collapses only (default: 100)")
    p.add_argument("--final-relocations", type=int, metavar="P", help="relocation passes at the end")
    p.add_argument("--refine", action="store_true", default=None, help="refine vertices by gradient descent")
    p.add_argument("--queue", choices=QUEUES,
                   help="collapse order: exhaustive, multiple-choice, parallel, lazy (default by collapses: exhaustive "
                   f"up to {LAZY_COLLAPSES}, lazy up to {EXHAUSTIVE_COLLAPSES} with a target, multiple-choice above)")
    p.add_argument("--choices", type=int, metavar="K", help="multiple-choice: half-edges drawn per step (15)")
    p.add_argument("--initial-vertices", type=int, metavar="V",
                   help="initial vertices, a random subset (default: a third of noisy points, 300-2000)")
    p.add_argument("--round-fraction", type=float, metavar="F",
                   help="parallel: a round collapses at most this fraction of what is left (0.05)")
    p.add_argument("--seed", type=int, metavar="S", help="random seed (examples: also the sampling seed)")
    p.add_argument("--points", type=int, metavar="M", help="examples only: number of sampled points")
    p.add_argument("--invert", action="store_true", help="images only: dark drawing on light background")
    p.add_argument("--threshold", type=float, metavar="X", help="images only: drop pixels of mass <= X")
    p.add_argument(
        "--merge-duplicates",
        action="store_true",
        default=None,
        help="merge repeated points (summing masses) instead of refusing them",
    )
    p.add_argument("--compile-cache", metavar="DIR",
                   help="keep compiled kernels in DIR for later runs (default: $OTJAX_COMPILE_CACHE, "
                   "else ~/.cache/otjax/jax)")
    p.add_argument("--no-compile-cache", action="store_true", help="compile the kernels afresh, keep nothing")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(run=_run_curve, usage=p.error)  # p.error prints the usage and exits with status 2
    return p


# The surface commands and their one-line help. Their full parsers load the
# 3D half of the package, so they are built only for a surface command: the
# others list them by name (``otjax --help``) and never import it.
SURFACE_COMMANDS = {"surface": "reconstruct a 3D surface from points",
                    "recover": "pull a smooth mesh onto the sharp features of its points"}


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The ``otjax`` argument parser (subcommands: ``curve``, ``surface``, ``recover``).

    ``argv`` (default ``sys.argv[1:]``) decides only whether the surface
    commands get their full parsers or are listed by name.
    """
    from otjax import __version__

    parser = argparse.ArgumentParser(prog="otjax", description="Shape reconstruction by optimal transport.")
    parser.add_argument("--version", action="version", version=f"otjax {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _curve_parser(sub)
    args = sys.argv[1:] if argv is None else argv
    command = next((a for a in args if not a.startswith("-")), None)
    if command in SURFACE_COMMANDS:
        from otjax.cli_surfaces import add_surface_parsers

        add_surface_parsers(sub, SURFACE_COMMANDS)
    else:
        for name, text in SURFACE_COMMANDS.items():
            sub.add_parser(name, help=text)
    return parser


def _load(args, usage) -> tuple:
    """``(points, masses, kwargs)`` for :func:`reconstruct_curve` from the parsed arguments."""
    kwargs = {}
    if args.example is not None:
        if args.invert or args.threshold is not None:
            usage("--invert and --threshold apply to image inputs, not to --example")
        if args.example not in datasets.EXAMPLES:
            raise ValueError(f"unknown example {args.example!r}; choose from {', '.join(datasets.EXAMPLES)}")
        extra = {} if args.points is None else {"n": args.points}
        if args.points is not None and not 3 <= args.points <= MAX_POINTS:
            raise ValueError(f"--points must be between 3 and {MAX_POINTS}, got {args.points}")
        points, masses, _, defaults = datasets.load_example(
            args.example, seed=0 if args.seed is None else args.seed, **extra
        )
        kwargs.update(defaults)
        if args.tolerance is not None and args.n_vertices is None:
            kwargs.pop("n_vertices", None)  # --tolerance alone means: stop by tolerance, not count
    else:
        if args.points is not None:
            usage("--points applies to --example only")
        if args.n_vertices is None and args.tolerance is None:
            usage("-n/--n-vertices is required (or --tolerance)")
        points, masses = read_points(
            args.input,
            invert=args.invert,
            threshold=0.0 if args.threshold is None else args.threshold,
        )
    given = {
        "n_vertices": args.n_vertices,
        "tolerance": args.tolerance,
        "relevance": args.relevance,
        "density": args.density,
        "background": args.background,
        "chords": None if args.keep_chords is None else not args.keep_chords,
        "fit_ends": None if args.keep_ends is None else not args.keep_ends,
        "relocation": args.relocation,
        "final_relocations": args.final_relocations,
        "refine": args.refine,
        "queue": args.queue,
        "choices": args.choices,
        "initial_vertices": args.initial_vertices,
        "round_fraction": args.round_fraction,
        "seed": args.seed,
        "merge_duplicates": args.merge_duplicates,
    }
    # Only what the user (or the example) set; everything else keeps the library's default.
    kwargs.update({k: v for k, v in given.items() if v is not None})
    kwargs["progress"] = not (args.no_progress or args.quiet)
    return points, masses, kwargs


def _run_curve(args, usage) -> int:
    if args.list_examples:
        width = max(map(len, datasets.EXAMPLES), default=0)
        for name, description in datasets.EXAMPLES.items():
            print(f"{name:<{width}}  {description}")
        return 0
    if args.input is None and args.example is None:
        usage("give an INPUT file, --example NAME or --list-examples")
    # All of them, before any work: a run must not fail at its end on a typo.
    outputs = check_output_paths(args.output, SAVE_EXTENSIONS, inputs=[args.input] if args.input else [],
                                 mkdir=args.mkdir)
    points, masses, kwargs = _load(args, usage)
    # Fail fast with the input's own message, before the reconstruction starts
    # (reconstruct_curve checks again; this costs one sort of the points).
    pts, _ = check_points(points, masses, merge_duplicates=bool(kwargs.get("merge_duplicates")))
    if kwargs.get("n_vertices") is not None:
        check_target(kwargs["n_vertices"], len(pts))
    cache = None if args.no_compile_cache else (args.compile_cache or default_cache_dir())
    if cache is not None:
        try:
            enable_compilation_cache(cache)
        except OSError as err:  # a read-only home costs compile time, not the run
            if not args.quiet:
                print(f"otjax: warning: no compile cache ({err})", file=sys.stderr)
    result = reconstruct_curve(points, masses, **kwargs)
    write_files([(path, _render(result, path)) for path in outputs], mkdir=args.mkdir)
    if not args.quiet:
        print(result.summary())
        if "cost_exponent" in result.params:
            print(f"(the total cost in input units is {result.total_cost:.6g} x 2^{result.params['cost_exponent']})")
        for path in outputs:
            print(f"wrote {path}")
    return 0


def _render(result, path):
    """The file :meth:`CurveResult.save` would write at ``path``, in memory (``str`` or ``bytes``)."""
    ext = path.suffix.lower()
    if ext == ".json":
        return result.to_json(indent=1) + "\n"
    return result.to_svg() if ext == ".svg" else result.to_png()


def main(argv: list[str] | None = None) -> int:
    """Runs the command line; returns the exit status (0 ok, 1 bad input, 2 usage, 130 interrupted)."""
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    try:
        return args.run(args, args.usage)
    except (ValueError, OSError) as err:
        message = " ".join(str(err).split()) or type(err).__name__  # one line, whatever the message
        print(f"otjax: error: {message}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("otjax: interrupted", file=sys.stderr)
        return 130


def entry() -> int:
    """The ``otjax`` process: :func:`main`, then a quick exit.

    Freezing the collector's objects before the interpreter shuts down
    spares it a last sweep over every object JAX and SciPy made at import
    (docs/decisions.md#quick_exit).
    Only for a process that ends here: a caller of :func:`main` keeps its
    collector as it was.
    """
    status = main()
    gc.freeze()
    return status


if __name__ == "__main__":
    sys.exit(entry())
