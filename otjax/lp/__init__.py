"""Local optimal-transport LPs, shared by every dimension; knows no mesh.

- :mod:`otjax.lp.problem` -- a member (:class:`LocalLP`), a padded batch
  (:class:`TransportLP`) in a few capacity classes (:class:`BatchShape`), the solution
  (:class:`LPSolution`) and its status codes.
- :mod:`otjax.lp.exact` -- HiGHS, one member at a time: the oracle and the fallback.
- :mod:`otjax.lp.batched` -- damped Newton on the entropic semi-dual, ``jit`` + ``vmap``,
  a fixed step budget, rounded to exactly feasible plans with a certified gap.
- :mod:`otjax.lp.solve` -- one entry point: batched, then HiGHS for the members it
  did not certify.
"""

from otjax.lp.batched import NewtonOptions, solve_batched
from otjax.lp.exact import MemberSolution, solve_exact, solve_member
from otjax.lp.problem import (CONVERGED, FAILED, INFEASIBLE, ITERATION_LIMIT, BatchShape, LocalLP, LPSolution,
                              TransportLP, check_local, group_by_class, lower_bound, member, member_plan, pack)
from otjax.lp.solve import MembersResult, SolveResult, solve, solve_members

__all__ = [
    "CONVERGED",
    "FAILED",
    "INFEASIBLE",
    "ITERATION_LIMIT",
    "BatchShape",
    "LPSolution",
    "LocalLP",
    "MemberSolution",
    "MembersResult",
    "NewtonOptions",
    "SolveResult",
    "TransportLP",
    "check_local",
    "group_by_class",
    "lower_bound",
    "member",
    "member_plan",
    "pack",
    "solve",
    "solve_batched",
    "solve_exact",
    "solve_member",
    "solve_members",
]
