"""On-ground diagnosis: healthy model, indicator transformation laws, signatures.

Pure statistics over indicator tables (paper sections V and VI):

- :class:`HealthyModel` -- Gaussian model of healthy indicators, Z-scores
  (eq. 7) and the global Mahalanobis score;
- :func:`fit_itl` / :class:`ITL` -- indicator transformation laws
  ``dI = A * intensity`` fitted on a design of experiments (eqs. 2-5);
- :func:`signature_matrix` -- reference Z-score signatures (eq. 9, Table IV);
- :func:`collinearity_guilt` -- probability of guilt of each mode from the
  collinearity of a flight's signature with the references.
"""

from fuelhm_bench.diagnosis._validation import NotFittedError
from fuelhm_bench.diagnosis.healthy import HealthyModel, chi2_equivalent
from fuelhm_bench.diagnosis.itl import ITL, ITL_COLUMNS, fit_itl, fit_through_origin, paired_deltas, plot_itl
from fuelhm_bench.diagnosis.signatures import (
    collinearity_guilt,
    plot_signature_heatmap,
    signature_from_csv,
    signature_matrix,
    signature_to_csv,
    signature_to_markdown,
)

__all__ = [
    "HealthyModel",
    "ITL",
    "ITL_COLUMNS",
    "NotFittedError",
    "chi2_equivalent",
    "collinearity_guilt",
    "fit_itl",
    "fit_through_origin",
    "paired_deltas",
    "plot_itl",
    "plot_signature_heatmap",
    "signature_from_csv",
    "signature_matrix",
    "signature_to_csv",
    "signature_to_markdown",
]
