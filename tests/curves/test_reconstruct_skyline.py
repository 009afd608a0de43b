"""Acceptance of ``reconstruct_curve`` on a noisy skyline (750 points, σ =
0.5% D, corners and open ends), with and without relocation, in every queue
configuration.

Each pair of reconstructions runs once per module, and several tests read it.
"""

import functools

import pytest

from tests.curves.reconstruct_cases import (
    MODES,
    SKYLINE_POINTS,
    check_parallel_against_sequential,
    check_skyline,
    mode_args,
    skyline_case,
    skyline_run,
)


@pytest.fixture(scope="module")
def skyline_pair():
    return skyline_case()


@functools.cache
def in_mode(name: str):
    return skyline_case(**mode_args(name, SKYLINE_POINTS))


def test_relocation_improves_skyline_corners(skyline_pair):
    check_skyline(*skyline_pair)


@pytest.mark.parametrize("mode", list(MODES))
def test_modes_pass_the_skyline_acceptance(mode):
    check_skyline(*in_mode(mode))


def test_parallel_mode_costs_at_most_3_percent_more_in_5x_fewer_rounds():
    # From every point: the default subset leaves under 300 collapses, where
    # rounds of at most round_fraction of the rest cannot be 5x fewer.
    every = {"initial_vertices": SKYLINE_POINTS}
    check_parallel_against_sequential("skyline", skyline_run(queue="parallel", **every), skyline_run(**every))
