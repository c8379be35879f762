"""--scale keeps every degradation mode of a scenario's scored fleet."""

from __future__ import annotations

import dataclasses

import pytest

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.flights.scale import modes_by_unit, scaled_unit_count
from fuelhm_bench.scenarios import load_scenario


@pytest.mark.parametrize("name", ["all_modes", "incipient", "multi_fault", "paper_2012"])
def test_every_mode_stays_at_scale(name):
    cfg = load_scenario(name).test_fleet_config()
    modes = modes_by_unit(cfg)
    everything = frozenset().union(*modes)
    for scale in (0.05, 0.3, 0.5):
        n = scaled_unit_count(cfg, scale)
        assert frozenset().union(*modes[:n]) == everything
        assert round(cfg.n_units * scale) <= n <= cfg.n_units
        # the smallest such prefix: one unit fewer would lose a mode (or be below the request)
        if n > max(1, round(cfg.n_units * scale)):
            assert frozenset().union(*modes[:n - 1]) != everything


def test_a_plain_prefix_misses_modes_the_scaled_count_keeps():
    """The rule of release 0.1 (the first round(scale * units) units) missed modes (all_modes at 0.3 kept 4
    of 7 with its 42 units); at a scale keeping 4 units of today's all_modes it still would."""
    cfg = load_scenario("all_modes").test_fleet_config()
    modes = modes_by_unit(cfg)
    scale = 4 / cfg.n_units
    plain = round(scale * cfg.n_units)
    assert len(frozenset().union(*modes[:plain])) < 7 == len(frozenset().union(*modes))
    assert len(frozenset().union(*modes[:scaled_unit_count(cfg, scale)])) == 7


def test_scale_one_and_minimum():
    cfg = load_scenario("paper_2012").test_fleet_config()
    assert scaled_unit_count(cfg, 1.0) == scaled_unit_count(cfg, 3.0) == cfg.n_units
    healthy = dataclasses.replace(cfg, schedules=())
    assert scaled_unit_count(healthy, 0.01) == 1
    assert scaled_unit_count(healthy, 0.01, minimum=2) == 2


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), True, "0.3"])
def test_bad_scale(bad):
    cfg = load_scenario("paper_2012").test_fleet_config()
    with pytest.raises(ParameterError, match="The 'scale' parameter of scaled_unit_count"):
        scaled_unit_count(cfg, bad)
