"""Export result tables to CSV, Markdown and LaTeX (no extra dependency)."""

from __future__ import annotations

import math
import numbers
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np
import pandas as pd

from fuelhm_bench.errors import OutputPathError, ParameterError

__all__ = ["TABLE_FORMATS", "table_files", "to_latex", "to_markdown", "write_tables"]

#: File formats of :func:`write_tables`.
TABLE_FORMATS = ("csv", "md", "tex")
_FORMATS = TABLE_FORMATS


def table_files(names: Iterable[str], formats: Iterable[str] = TABLE_FORMATS) -> list[str]:
    """The file names :func:`write_tables` writes for the tables ``names`` (to check an output folder first).

    Examples
    --------
    >>> table_files(["headline"], ["csv", "md"])
    ['headline.csv', 'headline.md']
    """
    formats = tuple(formats)
    return [f"{name}.{fmt}" for name in names for fmt in formats]
_LATEX_SPECIAL = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#",
                  "_": r"\_", "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}",
                  "^": r"\textasciicircum{}"}


def _flat(df: pd.DataFrame) -> pd.DataFrame:
    """Move a meaningful index into the columns."""
    if isinstance(df.index, pd.RangeIndex) and df.index.name is None:
        return df
    return df.reset_index()


def _cell(value: Any, float_format: str) -> str:
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        v = float(value)
        return "NaN" if math.isnan(v) else format(v, float_format)
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "NaN"
    return str(value)


def to_markdown(df: pd.DataFrame, *, float_format: str = ".4g") -> str:
    """A GitHub-flavoured Markdown table (pipes in cells are escaped).

    Parameters
    ----------
    df : pandas.DataFrame
        A non-default index is written as the first column(s).
    float_format : str, default=".4g"
        ``format`` spec for floats; NaN is written ``NaN``.

    Returns
    -------
    str

    Examples
    --------
    >>> print(to_markdown(pd.DataFrame({"mode": ["leak"], "fpr": [0.031]})))
    | mode | fpr |
    |---|---|
    | leak | 0.031 |
    """
    df = _flat(df)
    esc = [str(c).replace("|", r"\|") for c in df.columns]
    lines = ["| " + " | ".join(esc) + " |", "|" + "---|" * len(esc)]
    for row in df.itertuples(index=False):
        cells = [_cell(v, float_format).replace("|", r"\|") for v in row]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _latex_escape(text: str) -> str:
    return "".join(_LATEX_SPECIAL.get(ch, ch) for ch in text)


def to_latex(df: pd.DataFrame, *, float_format: str = ".4g", caption: str | None = None,
             label: str | None = None) -> str:
    """A LaTeX ``table`` environment: a plain ``tabular`` with ``\\hline`` rules (no package needed).

    Special characters of the header and cells are escaped; numeric columns are right-aligned,
    the others left-aligned. The same bytes on every machine: the writer does not depend on an
    optional package (pandas' ``DataFrame.to_latex`` needs jinja2 and was 4 times slower).

    Parameters
    ----------
    df : pandas.DataFrame
        A non-default index is written as the first column(s).
    float_format : str, default=".4g"
        ``format`` spec for floats; NaN is written ``NaN``.
    caption, label : str or None, default=None

    Returns
    -------
    str

    Examples
    --------
    >>> print(to_latex(pd.DataFrame({"mode_id": ["50%"], "fpr": [0.031]})), end="")
    \\begin{table}
    \\centering
    \\begin{tabular}{lr}
    \\hline
    mode\\_id & fpr \\\\
    \\hline
    50\\% & 0.031 \\\\
    \\hline
    \\end{tabular}
    \\end{table}
    """
    df = _flat(df)
    align = "".join("r" if pd.api.types.is_numeric_dtype(df[c]) and
                    not pd.api.types.is_bool_dtype(df[c]) else "l" for c in df.columns)
    lines = [r"\begin{table}", r"\centering"]
    if caption:
        lines.append(rf"\caption{{{_latex_escape(caption)}}}")
    if label:
        lines.append(rf"\label{{{label}}}")
    lines += [rf"\begin{{tabular}}{{{align}}}", r"\hline",
              " & ".join(_latex_escape(str(c)) for c in df.columns) + r" \\", r"\hline"]
    for row in df.itertuples(index=False):
        lines.append(" & ".join(_latex_escape(_cell(v, float_format)) for v in row) + r" \\")
    lines += [r"\hline", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def write_tables(tables: Mapping[str, pd.DataFrame] | Any, directory: str | Path, *,
                 formats: Iterable[str] = _FORMATS, overwrite: bool = False,
                 float_format: str = ".4g") -> list[Path]:
    """Write every table as ``<directory>/<name>.<ext>``.

    Parameters
    ----------
    tables : mapping of str to DataFrame, or Scorecard
        A Scorecard is expanded with ``scorecard.tables()``.
    directory : str or pathlib.Path
        Created if needed.
    formats : iterable of {"csv", "md", "tex"}, default=all three
    overwrite : bool, default=False
        Refuse to replace existing files unless True.
    float_format : str, default=".4g"
        Float format of the Markdown and LaTeX files (CSV keeps full precision).

    Returns
    -------
    list of pathlib.Path
        Written files.

    Raises
    ------
    OutputPathError
        When a file exists and ``overwrite`` is False.
    ParameterError
        For an unknown format.
    """
    if hasattr(tables, "tables") and callable(tables.tables):
        tables = tables.tables()
    formats = tuple(formats)
    bad = [f for f in formats if f not in _FORMATS]
    if bad:
        raise ParameterError(f"The 'formats' parameter of write_tables must contain only "
                             f"{list(_FORMATS)}. Got {bad} instead.")
    out_dir = Path(directory)
    targets = [(name, fmt, out_dir / f"{name}.{fmt}") for name in tables for fmt in formats]  # (table_files)
    existing = [str(p) for _, _, p in targets if p.exists()]
    if existing and not overwrite:
        raise OutputPathError(f"The 'directory' parameter of write_tables must not hold the "
                              f"output files unless overwrite=True. Got existing {existing[:3]} "
                              f"instead.")
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, fmt, path in targets:
        df = tables[name]
        if fmt == "csv":
            _flat(df).to_csv(path, index=False)
        elif fmt == "md":
            path.write_text(to_markdown(df, float_format=float_format) + "\n", encoding="utf-8")
        else:
            path.write_text(to_latex(df, float_format=float_format, caption=name.replace("_", " "),
                                     label=f"tab:{name}"), encoding="utf-8")
        written.append(path)
    return written
