"""Reference methods of fuelhm-bench, written like any outside submission.

Every baseline is a :class:`fuelhm_bench.methods.BaseMethod` built only on the
public API (``fuelhm_bench.methods``, ``fuelhm_bench.diagnosis``,
``fuelhm_bench.taxonomy``) plus numpy, pandas and scikit-learn, and passes
``fuelhm_bench.methods.check_method``. Leaderboard entries refer to them by
entry point ``"module:Class"`` (see :data:`ENTRY_POINTS`); a module is only
imported when one of its entry points is loaded. See ``baselines/README.md``.
"""

from __future__ import annotations

import importlib

__all__ = ["ENTRY_POINTS", "load"]

#: Short name -> entry point ``"module:Class"`` of every baseline.
ENTRY_POINTS: dict[str, str] = {
    "null": "fuelhm_baselines.trivial:NullMethod",
    "random": "fuelhm_baselines.trivial:RandomMethod",
    "paper-mahalanobis": "fuelhm_baselines.paper_mahalanobis:PaperMahalanobis",
    "isolation-forest": "fuelhm_baselines.isolation_forest:IsolationForestMethod",
    "itl-classifier": "fuelhm_baselines.itl_classifier:ITLClassifierMethod",
    "full-gaussian": "fuelhm_baselines.gaussian_full:FullGaussianMethod",
    "gaussian-mixture": "fuelhm_baselines.gaussian_mixture:GaussianMixtureMethod",
    "one-class-svm": "fuelhm_baselines.one_class_svm:OneClassSVMMethod",
    "nearest-neighbour": "fuelhm_baselines.nearest_neighbour:NearestNeighbourMethod",
}


def load(entry_point: str) -> type:
    """Import and return the class named by an entry point or a short name.

    Parameters
    ----------
    entry_point : str
        ``"module:Class"`` (e.g. ``"fuelhm_baselines.trivial:NullMethod"``) or a key of
        :data:`ENTRY_POINTS` (e.g. ``"paper-mahalanobis"``).

    Returns
    -------
    type
        The method class (instantiate it with keyword hyperparameters).

    Raises
    ------
    KeyError
        An unknown short name.
    ValueError
        An entry point without exactly one ``":"``.

    Examples
    --------
    >>> from fuelhm_baselines import load
    >>> load("paper-mahalanobis")(a=3.0).get_params()["a"]
    3.0
    >>> load("fuelhm_baselines.trivial:NullMethod")()
    NullMethod()
    """
    if ":" not in entry_point:
        if entry_point not in ENTRY_POINTS:
            raise KeyError(f"Unknown baseline {entry_point!r}; known: {sorted(ENTRY_POINTS)}.")
        entry_point = ENTRY_POINTS[entry_point]
    module_name, sep, class_name = entry_point.partition(":")
    if not module_name or not class_name or ":" in class_name:
        raise ValueError(f"An entry point must look like 'module:Class'. Got {entry_point!r} "
                         f"instead.")
    return getattr(importlib.import_module(module_name), class_name)
