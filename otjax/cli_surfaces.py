"""The surface commands of the ``otjax`` command line.

``otjax surface INPUT -n N -o out.ply`` reconstructs a surface from a 3D point
file; ``otjax surface --example staircase`` runs on a built-in shape.
``otjax recover POINTS MESH -o out.ply`` pulls a smooth mesh onto the sharp
features of its points; ``otjax recover --example rounded_box`` runs on a
built-in pair. Bad input follows ``otjax.cli``: one line ``otjax: error: ...``,
exit status 1, output paths checked before any work, all outputs or none.
"""

from __future__ import annotations

import argparse

from otjax import datasets3d
from otjax.io import check_output_paths, write_files
from otjax.io3d import read_mesh, read_points3d
from otjax.surfaces.bins import DEFAULT_DENSITY
from otjax.surfaces.features import recover_features
from otjax.surfaces.reconstruct import FINAL_DENSITY_FACTOR, reconstruct_surface, surface_solver
from otjax.surfaces.result import SAVE_EXTENSIONS
from otjax.validation import MAX_POINTS, check_number

#: Points and vertices of a built-in example unless --points / -n say otherwise.
EXAMPLE_POINTS = 2000
EXAMPLE_VERTICES = 30


def _outputs(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", action="append", default=[], metavar="OUT",
                   help=f"write the result; repeatable; extension one of {', '.join(SAVE_EXTENSIONS)}. "
                   "Without -o only a summary is printed. All outputs are written or none")
    p.add_argument("--mkdir", action="store_true",
                   help="create missing directories of the outputs (otherwise a missing one is an error)")
    p.add_argument("--density-threshold", type=float, metavar="T",
                   help="drop facets whose mass density is below T times the mean density")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (examples: also the sampling seed)")
    p.add_argument("--points", type=int, metavar="M", help=f"examples only: sampled points ({EXAMPLE_POINTS})")
    p.add_argument("--noise", type=float, default=0.0, metavar="F",
                   help="examples only: Gaussian noise, a fraction of the bounding-box diagonal")
    p.add_argument("--solver", choices=("batched", "exact"),
                   help="local LP solver: batched JAX (HiGHS for what it does not certify) or HiGHS alone "
                   "(default: HiGHS on a CPU, batched on an accelerator)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")


def add_surface_parsers(sub, helps: dict[str, str]) -> None:
    """Adds ``surface`` and ``recover`` to the ``otjax`` subcommands, with
    their one-line ``helps`` by name."""
    p = sub.add_parser("surface", help=helps["surface"],
                       description="Reconstruct a surface (triangles and isolated vertices) from 3D points by "
                       "optimal transport (Digne et al. 2014). Inputs: .xyz/.csv/.txt (x y z [...] per line) or "
                       ".ply point sets.")
    source = p.add_mutually_exclusive_group()
    source.add_argument("input", nargs="?", help="point file")
    source.add_argument("--example", choices=sorted(datasets3d.SURFACES), help="use a built-in shape instead")
    p.add_argument("-n", "--n-vertices", type=int, metavar="N",
                   help=f"target number of vertices (required for files; examples: {EXAMPLE_VERTICES})")
    p.add_argument("--queue", choices=("multiple-choice", "exhaustive", "parallel"), default="multiple-choice",
                   help="collapse order (default: multiple-choice, 40 half-edges a step)")
    p.add_argument("--bin-density", type=float, default=DEFAULT_DENSITY, metavar="B",
                   help=f"facet bins per squared bounding-box diagonal of area ({DEFAULT_DENSITY:g}); higher: "
                   "finer cost, sharper creases at small -n, slower")
    p.add_argument("--final-density-factor", type=float, default=FINAL_DENSITY_FACTOR, metavar="F",
                   help=f"the final relocation passes re-bin the facets at F times B ({FINAL_DENSITY_FACTOR:g}; "
                   "1: keep the decimation's bins)")
    p.add_argument("--background", choices=("auto", "none"), default="auto",
                   help="estimate uniform background noise and discount it (auto, the default) or not")
    p.add_argument("--no-feature-fit", dest="fit_features", action="store_false",
                   help="keep the decimation's output as the transport left it (default: drop facets across "
                   "their points' surface, fit crease and open-border vertices to the points' planes and ends)")
    _outputs(p)
    p.set_defaults(run=_run_surface, usage=p.error)

    p = sub.add_parser("recover", help=helps["recover"],
                       description="Feature recovery (Digne et al. 2014, section 5): move the vertices of a smooth "
                       "mesh (e.g. screened Poisson) onto the creases and boundaries of the points it was made "
                       "from, then drop the facets that receive little mass (holes the smooth method filled).")
    source = p.add_mutually_exclusive_group()
    source.add_argument("inputs", nargs="*", default=[], metavar="POINTS MESH", help="point file and mesh file")
    source.add_argument("--example", choices=sorted(datasets3d.RECOVERY), help="use a built-in pair instead")
    p.add_argument("--passes", type=int, default=3, metavar="K", help="relocation passes (3)")
    p.add_argument("--sequential", action="store_true",
                   help="relocate one vertex at a time (the paper's order) instead of colour classes")
    _outputs(p)
    p.set_defaults(run=_run_recover, usage=p.error)


def _example_size(args) -> int:
    n = EXAMPLE_POINTS if args.points is None else args.points
    check_number("--points", n, minimum=100, integer=True)
    if n > MAX_POINTS:
        raise ValueError(f"--points must be at most {MAX_POINTS}, got {n}")
    check_number("--noise", args.noise)
    return n


def _run_surface(args, usage) -> int:
    if args.input is None and args.example is None:
        usage("give an INPUT file or --example NAME")
    if args.example is None and (args.points is not None or args.noise):
        usage("--points and --noise apply to --example only")
    if args.example is None and args.n_vertices is None:
        usage("-n/--n-vertices is required for a file")
    outputs = check_output_paths(args.output, SAVE_EXTENSIONS, inputs=[args.input] if args.input else [],
                                 mkdir=args.mkdir)
    if args.example is not None:
        points, masses = datasets3d.SURFACES[args.example](_example_size(args), noise=args.noise,
                                                           seed=args.seed).points, None
    else:
        points, masses = read_points3d(args.input)
    n_vertices = EXAMPLE_VERTICES if args.n_vertices is None else args.n_vertices
    solver = surface_solver(args.solver)
    params = {"n_vertices": n_vertices, "queue": args.queue, "seed": args.seed, "solver": solver,
              "bin_density": args.bin_density, "final_density_factor": args.final_density_factor,
              "background": args.background, "fit_features": args.fit_features}
    run = reconstruct_surface(points, masses, n_vertices, queue=args.queue, seed=args.seed, solver=solver,
                              bin_density=args.bin_density, final_density_factor=args.final_density_factor,
                              background=args.background, fit_features=args.fit_features,
                              progress=not args.quiet)
    result = run.to_result(params)
    return _finish(result, args, outputs)


def _run_recover(args, usage) -> int:
    if args.example is None and len(args.inputs) != 2:
        usage("give POINTS and MESH files, or --example NAME")
    if args.example is None and (args.points is not None or args.noise):
        usage("--points and --noise apply to --example only")
    outputs = check_output_paths(args.output, SAVE_EXTENSIONS, inputs=args.inputs, mkdir=args.mkdir)
    if args.example is not None:
        sample = datasets3d.RECOVERY[args.example](_example_size(args), noise=args.noise, seed=args.seed)
        points, masses, mesh = sample.points, None, sample.mesh
    else:
        (points, masses), mesh = read_points3d(args.inputs[0]), read_mesh(args.inputs[1])
    options = {"passes": args.passes, "order": "sequential" if args.sequential else "colouring", "seed": args.seed,
               "solver": {None: None, "batched": "auto", "exact": "exact"}[args.solver]}
    if args.density_threshold is not None:
        options["density_threshold"] = args.density_threshold
    result = recover_features(points, mesh, masses, progress=not args.quiet, **options)
    return _finish(result, args, outputs, filtered=True)


def _finish(result, args, outputs, filtered: bool = False) -> int:
    if args.density_threshold is not None and not filtered:
        result = result.filtered(args.density_threshold)
    write_files([(path, result.render(path)) for path in outputs], mkdir=args.mkdir)
    if not args.quiet:
        edges = f"{len(result.edges)} edges, " if len(result.edges) else ""
        print(f"{len(result.vertices)} vertices, {len(result.triangles)} triangles, {edges}"
              f"{len(result.isolated)} isolated; transport cost {result.total_cost:.6g}")
        for path in outputs:
            print(f"wrote {path}")
    return 0
