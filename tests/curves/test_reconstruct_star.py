"""Acceptance of ``reconstruct_curve`` on a noisy star (2000 points, σ = 1% D,
10 vertices), in every queue configuration; its JSON output.

Each reconstruction runs once per module, and several tests read it.
"""

import functools
import json

import jsonschema
import numpy as np
import pytest

import otjax
from otjax.curves.result import json_schema
from tests.curves.reconstruct_cases import (
    MODES,
    STAR_POINTS,
    check_noisy_star,
    check_parallel_against_sequential,
    mode_args,
    noisy_star_case,
)


@pytest.fixture(scope="module")
def noisy_star():
    return noisy_star_case()


@functools.cache
def in_mode(name: str):
    return noisy_star_case(**mode_args(name, STAR_POINTS))


def test_noisy_star_corners_and_hausdorff(noisy_star):
    check_noisy_star(*noisy_star)


def test_saved_json_validates_and_round_trips(noisy_star, tmp_path):
    result, _ = noisy_star
    path = tmp_path / "star.json"
    result.save(path)
    doc = json.loads(path.read_text())
    jsonschema.validate(doc, json_schema())
    back = otjax.CurveResult.load(path)
    np.testing.assert_array_equal(back.vertices, result.vertices)
    np.testing.assert_array_equal(back.edges, result.edges)
    np.testing.assert_array_equal(back.edge_relevance, result.edge_relevance)
    assert back.total_cost == result.total_cost
    assert back.params == result.params


@pytest.mark.parametrize("mode", list(MODES))
def test_modes_pass_the_noisy_star_acceptance(mode):
    check_noisy_star(*in_mode(mode))


def test_parallel_mode_costs_at_most_3_percent_more_in_5x_fewer_rounds(noisy_star):
    check_parallel_against_sequential("star", in_mode("parallel")[0], noisy_star[0])
