"""The reference detectors of different inductive biases (full Gaussian, Gaussian mixture, one-class SVM,
nearest neighbour): conformance and behaviour. Written like ``tests/test_baselines.py``."""

from __future__ import annotations

import numpy as np
import pytest

import fuelhm_baselines as baselines
from fuelhm_baselines.gaussian_full import FullGaussianMethod
from fuelhm_baselines.gaussian_mixture import GaussianMixtureMethod
from fuelhm_baselines.nearest_neighbour import NearestNeighbourMethod
from fuelhm_baselines.one_class_svm import OneClassSVMMethod
from fuelhm_bench.methods import check_method, make_check_data, parametrize_with_checks
from fuelhm_bench.taxonomy import INDICATOR_NAMES

#: Small configurations (few folds, one or two components) keep the conformance checks fast.
CHECK_INSTANCES = [
    FullGaussianMethod(cv=2),
    GaussianMixtureMethod(n_components=1, cv=None),
    OneClassSVMMethod(cv=2, nu=0.2),
    NearestNeighbourMethod(cv=2, n_neighbors=3),
]
DETECTORS = [FullGaussianMethod, GaussianMixtureMethod, OneClassSVMMethod, NearestNeighbourMethod]


@pytest.mark.slow  # about 40 s on a quiet machine: the behavioural test below stays in the default run
@parametrize_with_checks(CHECK_INSTANCES)
def test_conformance(check):
    check()


@pytest.mark.slow
@pytest.mark.parametrize("cls", DETECTORS)
def test_conformance_default_configuration(cls):
    check_method(cls())


def test_registered_as_baselines():
    for name, cls in [("full-gaussian", FullGaussianMethod), ("gaussian-mixture", GaussianMixtureMethod),
                      ("one-class-svm", OneClassSVMMethod), ("nearest-neighbour", NearestNeighbourMethod)]:
        assert baselines.load(name) is cls


@pytest.mark.parametrize("cls", DETECTORS)
def test_calibrated_false_alarms_and_detects_a_shift(cls):
    data = make_check_data(0)
    method = cls(cv=5, quantile=0.9).fit(data.healthy, knowledge=data.knowledge, random_state=0)
    fresh = make_check_data(1).healthy  # new flights of the same healthy population (other_healthy is offset)
    alarms = method.decide_table(fresh)["alarm"].to_numpy()
    assert alarms.mean() <= 0.3  # about 10 % expected (quantile 0.9); 60 flights (0.07-0.2 measured)
    shifted = fresh.copy()
    x = shifted[list(INDICATOR_NAMES)].to_numpy(dtype=float)
    sd = np.nanstd(data.healthy[list(INDICATOR_NAMES)].to_numpy(dtype=float), axis=0)
    shifted[list(INDICATOR_NAMES)] = x + 8.0 * sd
    decisions = method.decide_table(shifted)
    assert decisions["alarm"].mean() >= 0.9
    guilt = decisions[[c for c in decisions.columns if c.startswith("guilt_")]].to_numpy()
    np.testing.assert_allclose(guilt[decisions["alarm"].to_numpy(bool)].sum(axis=1), 1.0, atol=1e-6)
