"""Degradation signatures (paper eq. 9, Table IV) and diagnosis by collinearity.

The reference signature of a mode is the vector of Z-scores its maximal
intensity produces: ``Sign_ref,deg[i] = A_i^deg * max_intensity / sigma_i^healthy``
(eq. 9 with the ITL of eq. 4). A flight's signature is its Z-score vector
(eq. 8); the diagnosis gives each mode a probability of guilt proportional
to the collinearity between the two (section VI.B.3 and VI.C.3).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from numbers import Real
from pathlib import Path

import numpy as np
import pandas as pd

from fuelhm_bench.diagnosis._validation import check_dataframe, check_output_path, param_error
from fuelhm_bench.diagnosis.healthy import HealthyModel
from fuelhm_bench.diagnosis.itl import ITL
from fuelhm_bench.errors import DataFormatError, UnknownNameError


def signature_matrix(itl: ITL, healthy_model: HealthyModel, *, max_intensity=1.0) -> pd.DataFrame:
    """Reference Z-score signatures of the modes at maximal intensity (eq. 9, Table IV).

    ``sig[deg, i] = A_i^deg * max_intensity[deg] / std_[i]``: the Z-score of
    indicator ``i`` (eq. 7) of a flight whose indicators are the healthy mean
    moved by the ITL at maximal intensity (eq. 4).

    Parameters
    ----------
    itl : ITL
        Indicator transformation laws; must have a law for every indicator of
        ``healthy_model.features_``.
    healthy_model : HealthyModel
        Fitted healthy model (supplies ``std_``).
    max_intensity : float or mapping of str to float, default=1.0
        Maximal intensity in (0, 1], one for all modes or one per mode of
        ``itl.modes``.

    Returns
    -------
    pandas.DataFrame
        Index: ``itl.modes`` (named ``mode``); columns:
        ``healthy_model.features_`` (named ``indicator``); dimensionless
        Z-scores, NaN where a law has no coefficient.

    Raises
    ------
    NotFittedError
        ``healthy_model`` is not fitted.
    DataFormatError
        The ITL lacks an indicator of the healthy model.
    ParameterError
        ``max_intensity`` is not in (0, 1] or misses a mode.

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> from fuelhm_bench.diagnosis import HealthyModel, ITL, signature_matrix
    >>> from fuelhm_bench.testing.diagnosis import make_healthy_table
    >>> model = HealthyModel(features=["X1", "Y1"]).fit(make_healthy_table(50, rng=np.random.default_rng(0)))
    >>> itl = ITL(pd.DataFrame({"mode": ["backlash"] * 2, "indicator": ["X1", "Y1"], "A": [0.5, 0.0],
    ...                         "r2": [1.0, 1.0], "residual_std": [0.0, 0.0], "n": [4, 4]}))
    >>> sig = signature_matrix(itl, model)
    >>> bool(np.isclose(sig.loc["backlash", "X1"], 0.5 / model.std_[0]))
    True
    """
    healthy_model._check_fitted()
    features = list(healthy_model.features_)
    missing = [f for f in features if f not in itl.indicators]
    if missing:
        raise DataFormatError(
            f"The ITL has no law for indicator(s) {missing} of the healthy model; "
            "fit the ITL on the same indicators or restrict HealthyModel(features=...)."
        )
    modes = list(itl.modes)
    if isinstance(max_intensity, Mapping):
        absent = [m for m in modes if m not in max_intensity]
        if absent:
            raise param_error("max_intensity", "signature_matrix", f"a float or a mapping with every mode of the ITL (missing {absent})", max_intensity)
        scale = [max_intensity[m] for m in modes]
    else:
        scale = [max_intensity] * len(modes)
    for value in scale:
        if isinstance(value, bool) or not isinstance(value, Real) or not 0.0 < value <= 1.0:
            raise param_error("max_intensity", "signature_matrix", "a float in (0, 1] (or a mapping of them)", max_intensity)
    coef = itl.matrix("A").loc[modes, features].to_numpy(dtype=np.float64)
    sig = coef * np.asarray(scale, dtype=np.float64)[:, None] / healthy_model.std_[None, :]
    return pd.DataFrame(sig, index=pd.Index(modes, name="mode"), columns=pd.Index(features, name="indicator"))


def _check_signature_table(sig: object) -> pd.DataFrame:
    sig = check_dataframe(sig, "signature matrix")
    try:
        values = sig.to_numpy(dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataFormatError(f"The signature matrix must hold numbers only ({exc}).") from None
    if np.isinf(values).any():
        raise DataFormatError("The signature matrix has an infinite value (use NaN for an unknown entry).")
    return sig


def signature_to_csv(sig: pd.DataFrame, path) -> Path:
    """Write a signature matrix to CSV (first column: the mode); returns the path."""
    sig = _check_signature_table(sig)
    path = Path(path)
    check_output_path(path)
    out = sig.copy()
    out.index.name = out.index.name or "mode"
    out.to_csv(path)
    return path


def signature_from_csv(path) -> pd.DataFrame:
    """Read a signature matrix written by :func:`signature_to_csv`."""
    path = Path(path)
    if not path.is_file():
        raise DataFormatError(f"Signature file {str(path)!r} does not exist.")
    sig = pd.read_csv(path, index_col=0)
    sig.columns.name = "indicator"
    return _check_signature_table(sig)


def signature_to_markdown(sig: pd.DataFrame, *, decimals: int = 1) -> str:
    """Format a signature matrix as a GitHub-flavoured markdown table (like Table IV).

    Parameters
    ----------
    sig : pandas.DataFrame
        Modes x indicators.
    decimals : int, default=1
        Digits after the decimal point; NaN is written ``-``.

    Returns
    -------
    str
        The table, one line per mode, ending with a newline.

    Examples
    --------
    >>> import pandas as pd
    >>> from fuelhm_bench.diagnosis import signature_to_markdown
    >>> print(signature_to_markdown(pd.DataFrame({"X1": [24.0], "Y1": [0.0]}, index=["null_bias_drift"]), decimals=0))
    | mode | X1 | Y1 |
    |---|---:|---:|
    | null_bias_drift | 24 | 0 |
    <BLANKLINE>
    """
    sig = _check_signature_table(sig)
    if isinstance(decimals, bool) or not isinstance(decimals, int) or decimals < 0:
        raise param_error("decimals", "signature_to_markdown", "an int >= 0", decimals)
    head = sig.index.name or "mode"
    lines = [
        "| " + " | ".join([str(head), *map(str, sig.columns)]) + " |",
        "|---|" + "---:|" * sig.shape[1],
    ]
    for label, row in zip(sig.index, sig.to_numpy(dtype=np.float64)):
        cells = ["-" if np.isnan(v) else f"{v:.{decimals}f}" for v in row]
        lines.append("| " + " | ".join([str(label), *cells]) + " |")
    return "\n".join(lines) + "\n"


def plot_signature_heatmap(sig: pd.DataFrame, out_path, *, decimals: int = 1) -> Path:
    """Heat map of a signature matrix with every cell annotated (like Table IV).

    Diverging colours symmetric about 0 (red: the indicator increases, blue:
    it decreases); NaN cells are grey and annotated ``-``. Rendered with the
    Agg backend (no pyplot state).

    Parameters
    ----------
    sig : pandas.DataFrame
        Modes x indicators, dimensionless Z-scores.
    out_path : str or path-like
        Image file (format from the suffix); its directory must exist.
    decimals : int, default=1
        Digits of the annotations.

    Returns
    -------
    pathlib.Path
        ``out_path``.
    """
    sig = _check_signature_table(sig)
    out_path = Path(out_path)
    check_output_path(out_path)
    values = sig.to_numpy(dtype=np.float64)
    finite = values[np.isfinite(values)]
    vmax = float(np.max(np.abs(finite))) if finite.size and np.any(finite != 0) else 1.0
    n_rows, n_cols = values.shape
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # imported to plot only (not by data builds)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(0.9 * n_cols + 3.5, 0.55 * n_rows + 1.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    image = ax.imshow(np.ma.masked_invalid(values), cmap="RdBu_r", vmin=-vmax, vmax=vmax, aspect="auto")
    ax.set_facecolor("0.85")
    for r in range(n_rows):
        for c in range(n_cols):
            v = values[r, c]
            text = "-" if np.isnan(v) else f"{v:.{decimals}f}"
            color = "white" if np.isfinite(v) and abs(v) > 0.6 * vmax else "black"
            ax.text(c, r, text, ha="center", va="center", fontsize=8, color=color)
    ax.set_xticks(range(n_cols), [str(c) for c in sig.columns], fontsize=8)
    ax.set_yticks(range(n_rows), [str(i) for i in sig.index], fontsize=8)
    ax.set_xlabel("indicator")
    fig.colorbar(image, ax=ax, label="Z-score at maximal intensity")
    ax.set_title("Signature matrix (paper eq. 9, Table IV)", fontsize=10)
    fig.savefig(out_path, dpi=110)
    return out_path


def collinearity_guilt(signatures, references, *, symmetric=False):
    """Probability of guilt of each mode, proportional to collinearity (section VI.B.3).

    Collinearity of a flight signature ``s`` with the reference ``r_m`` of mode
    ``m`` is their cosine similarity clipped at 0,
    ``c_m = max(0, s . r_m / (|s| |r_m|))``. A degradation moves the
    indicators in a signed direction (``dI = A * intensity`` with intensity
    >= 0), so a signature pointing *opposite* to ``r_m`` is evidence against
    ``m``, not for it. For a mode whose sign is not fixed (the null-bias drift
    may go either way, docs/physics.md §6 Degradation modes) list it in ``symmetric`` to use
    ``|cos|`` instead (equivalent to adding ``-r_m`` as a second reference and
    summing the two probabilities). Probabilities are ``c_m / sum(c)``; when
    every ``c_m`` is 0 (zero or all-NaN signature, or no positive collinearity)
    the result is uniform, ``1 / n_modes`` (no evidence for any mode).

    NaN entries: for each (flight, mode) pair, indicators that are NaN in
    either vector are dropped from both before the cosine.

    Parameters
    ----------
    signatures : array-like of shape (n_indicators,) or (n_flights, n_indicators), or pandas Series/DataFrame
        Z-score signatures (eq. 8), e.g. ``HealthyModel.zscores(table)``.
        With a DataFrame/Series and DataFrame ``references``, indicators are
        matched by name (the signatures must hold every reference column).
    references : array-like of shape (n_modes, n_indicators) or pandas.DataFrame
        Reference signatures, e.g. :func:`signature_matrix`.
    symmetric : bool or iterable of labels, default=False
        Modes scored with ``|cos|``: ``True`` for all, or labels of
        ``references.index`` (row positions for an array).

    Returns
    -------
    ndarray, pandas.Series or pandas.DataFrame
        Non-negative probabilities summing to 1 over modes: shape (n_modes,)
        for one signature, (n_flights, n_modes) for a batch. A DataFrame
        (index of ``signatures``, columns = modes) or Series for pandas
        signatures, an ndarray otherwise.

    Examples
    --------
    >>> import numpy as np
    >>> from fuelhm_bench.diagnosis import collinearity_guilt
    >>> drift = [24, 0, 26, 0, 28, 24, 0, 0, 0, 0]   # Table IV of the paper
    >>> leak = [0, 4, 0, 11, 0, 1, 0, 0, 0, 0]
    >>> np.round(collinearity_guilt(np.multiply(drift, 0.5), [drift, leak]), 2).tolist()
    [0.96, 0.04]
    """
    ref_labels = list(references.index) if isinstance(references, pd.DataFrame) else None
    if isinstance(references, pd.DataFrame) and isinstance(signatures, (pd.DataFrame, pd.Series)):
        labels = signatures.columns if isinstance(signatures, pd.DataFrame) else signatures.index
        missing = [c for c in references.columns if c not in labels]
        if missing:
            raise DataFormatError(f"The signatures lack indicator(s) {missing} of the reference signatures.")
        signatures_values = signatures[list(references.columns)]
    else:
        signatures_values = signatures
    try:
        s = np.array(signatures_values, dtype=np.float64)
        r = np.array(references, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataFormatError(f"Signatures and reference signatures must be numeric ({exc}).") from None
    if r.ndim != 2 or r.shape[0] == 0:
        raise DataFormatError(f"The reference signatures must have shape (n_modes, n_indicators). Got {r.shape} instead.")
    single = s.ndim == 1
    s2 = s[None, :] if single else s
    if s2.ndim != 2 or s2.shape[1] != r.shape[1]:
        raise DataFormatError(
            f"The signatures must have shape ({r.shape[1]},) or (n_flights, {r.shape[1]}) to match the "
            f"reference signatures. Got {s.shape} instead."
        )
    sym = _symmetric_mask(symmetric, ref_labels if ref_labels is not None else list(range(r.shape[0])))
    prob = _guilt(s2, r, sym)

    modes = ref_labels if ref_labels is not None else None
    if isinstance(signatures, pd.DataFrame):
        return pd.DataFrame(prob, index=signatures.index, columns=modes)
    if isinstance(signatures, pd.Series):
        return pd.Series(prob[0], index=modes, name=signatures.name)
    return prob[0] if single else prob


def _symmetric_mask(symmetric, labels: list) -> np.ndarray:
    if isinstance(symmetric, (bool, np.bool_)):
        return np.full(len(labels), bool(symmetric))
    if isinstance(symmetric, str) or not isinstance(symmetric, Iterable):
        raise param_error("symmetric", "collinearity_guilt", "a bool or an iterable of reference labels", symmetric)
    chosen = list(symmetric)
    unknown = [m for m in chosen if m not in labels]
    if unknown:
        raise UnknownNameError(
            f"Unknown label(s) {unknown} in the 'symmetric' parameter of collinearity_guilt; references are {labels}."
        )
    return np.array([m in chosen for m in labels])


def _guilt(s: np.ndarray, r: np.ndarray, symmetric: np.ndarray) -> np.ndarray:
    """Batched guilt probabilities, shapes (n, p) x (m, p) -> (n, m)."""
    fs, fr = np.isfinite(s), np.isfinite(r)
    s0, r0 = np.where(fs, s, 0.0), np.where(fr, r, 0.0)
    dot = s0 @ r0.T
    norm2_s = (s0**2) @ fr.T.astype(np.float64)  # |s|^2 over indicators finite in r_m
    norm2_r = fs.astype(np.float64) @ (r0**2).T  # |r_m|^2 over indicators finite in s
    denom = np.sqrt(norm2_s * norm2_r)
    cos = np.clip(np.divide(dot, denom, out=np.zeros_like(dot), where=denom > 0), -1.0, 1.0)
    score = np.where(symmetric[None, :], np.abs(cos), np.maximum(cos, 0.0))
    total = score.sum(axis=1, keepdims=True)
    return np.divide(score, total, out=np.full_like(score, 1.0 / r.shape[0]), where=total > 0)
