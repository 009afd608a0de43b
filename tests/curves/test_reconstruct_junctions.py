"""Acceptance of ``reconstruct_curve`` on an open polyline with T and X
junctions (2000 points, noise-free), in every queue configuration.

Each reconstruction runs once per module, and several tests read it.
"""

import functools

import pytest

from tests.curves.reconstruct_cases import (
    JUNCTION_POINTS,
    MODES,
    check_junctions,
    check_parallel_against_sequential,
    junction_case,
    mode_args,
)


@pytest.fixture(scope="module")
def junction_shape():
    return junction_case()


@functools.cache
def in_mode(name: str):
    return junction_case(**mode_args(name, JUNCTION_POINTS))


def test_junctions_and_open_ends(junction_shape):
    check_junctions(*junction_shape)


@pytest.mark.parametrize("mode", list(MODES))
def test_modes_pass_the_junction_acceptance(mode):
    check_junctions(*in_mode(mode))


def test_parallel_mode_costs_at_most_3_percent_more_in_5x_fewer_rounds(junction_shape):
    check_parallel_against_sequential("junctions", in_mode("parallel")[0], junction_shape[0])
