"""What a file is, from its name: the one place that maps name suffixes to file types.

Every reader of a user's file and every writer of an output of a fixed type asks here, so a
file is never read as a type its name does not say (``decisions.txt`` parsed as CSV) nor
written under a name that says another (YAML into ``cal.parquet``, a PNG into ``c.jpg``).

=========  ============================  ==============================================
type       suffixes (case-insensitive)   files
=========  ============================  ==============================================
table      .parquet, .csv, .csv.gz       flights, labels, decisions, indicator tables
yaml       .yaml, .yml                   scenarios, models, leaderboard files
image      .png, .pdf, .svg              figures
json       .json                         the scenario JSON Schema
sqlite     .sqlite, .sqlite3, .db        the results store of evaluate / leaderboard
=========  ============================  ==============================================
"""

from __future__ import annotations

import os
from pathlib import Path

from fuelhm_bench.errors import DataFormatError

__all__ = ["FILE_TYPES", "check_file_type", "suffix_of"]

#: File type -> the name suffixes that say it, in order of preference.
FILE_TYPES: dict[str, tuple[str, ...]] = {
    "table": (".parquet", ".csv", ".csv.gz"),
    "yaml": (".yaml", ".yml"),
    "image": (".png", ".pdf", ".svg"),
    "json": (".json",),
    "sqlite": (".sqlite", ".sqlite3", ".db"),
}


def suffix_of(path: str | os.PathLike[str], kind: str) -> str | None:
    """The suffix of ``FILE_TYPES[kind]`` that ends the name of ``path`` (the longest), or None.

    Examples
    --------
    >>> suffix_of("runs/flights.CSV.gz", "table")
    '.csv.gz'
    >>> suffix_of("decisions.txt", "table") is None
    True
    """
    name = Path(path).name.lower()
    found = [s for s in FILE_TYPES[kind] if name.endswith(s) and len(name) > len(s)]
    return max(found, key=len) if found else None


def check_file_type(path: str | os.PathLike[str], kind: str, *, what: str, option: str | None = None,
                    writing: bool = False, error: type[Exception] = DataFormatError) -> str:
    """Refuse a file whose name does not say the type ``kind``; return its suffix.

    Parameters
    ----------
    path : str or path-like
        The file (only its name is examined).
    kind : {"table", "yaml", "image", "json", "sqlite"}
        Key of :data:`FILE_TYPES`.
    what : str
        Noun of the file in messages ("decisions file", "model file").
    option : str or None, default=None
        Command-line option the path came from, named in messages.
    writing : bool, default=False
        The file is an output (the command writes that type there) rather than an input.
    error : exception class, default=DataFormatError
        Raised (e.g. :class:`~fuelhm_bench.errors.OutputPathError` for outputs).

    Returns
    -------
    str
        The matching suffix, lower case (``".csv.gz"``).

    Raises
    ------
    error
        Naming the option or file, the allowed suffixes and the one given.

    Examples
    --------
    >>> check_file_type("cal.parquet", "yaml", what="model file", option="--out", writing=True)
    Traceback (most recent call last):
    fuelhm_bench.errors.DataFormatError: --out cal.parquet: the name must end in .yaml or .yml (the model file written there is YAML). Got '.parquet' instead.
    """
    suffix = suffix_of(path, kind)
    if suffix is not None:
        return suffix
    allowed = FILE_TYPES[kind]
    allowed_text = ", ".join(allowed[:-1]) + f" or {allowed[-1]}" if len(allowed) > 1 else allowed[0]
    given = "".join(Path(path).suffixes[-2:]) if Path(path).name.lower().endswith(".gz") else Path(path).suffix
    given = f"'{given}'" if given else "no suffix"
    label = f"{option} {path}" if option else f"the {what} '{path}'"
    if writing:
        noun = {"table": "Parquet or CSV", "yaml": "YAML", "image": "an image", "json": "JSON",
                "sqlite": "an SQLite database"}[kind]
        raise error(f"{label}: the name must end in {allowed_text} (the {what} written there is {noun}). Got {given} "
                    f"instead.")
    raise error(f"Cannot tell the format of {label} from its name: the suffix must be one of "
                f"{', '.join(allowed)}. Got {given} instead.")
