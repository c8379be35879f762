"""Format-agnostic table files: detection by suffix, safe reading, atomic writing.

This module knows nothing about flights; :mod:`fuelhm_bench.io.flights` builds
the flight and labels formats (docs/data-format.md) on top of it.

Supported formats, chosen by the (case-insensitive) file-name suffix:

===========  ==========================================================
suffix       format
===========  ==========================================================
``.parquet`` Apache Parquet (preferred: typed, compressed, fast)
``.csv``     comma-separated values with a header line
``.csv.gz``  the same, gzip-compressed
===========  ==========================================================

Reading never lets a raw pandas / pyarrow exception escape: every failure is
re-raised as :class:`~fuelhm_bench.errors.DataFormatError` naming the file.
Writing goes to a hidden temporary file in the target directory that is
atomically renamed onto the target only when the caller commits, so an
interrupted write never leaves a truncated file that looks complete.
"""

from __future__ import annotations

import gzip
import os
import zlib
from pathlib import Path
from collections.abc import Callable
from typing import IO, Literal

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from fuelhm_bench.errors import DataFormatError, OutputPathError
from fuelhm_bench.filetypes import FILE_TYPES, check_file_type
from fuelhm_bench.io.outputs import check_output_path, temporary_path

__all__ = [
    "SUPPORTED_SUFFIXES",
    "AtomicTableWriter",
    "TableFormat",
    "check_output_path",
    "read_table",
    "table_format",
]

TableFormat = Literal["parquet", "csv", "csv.gz"]

#: File-name suffixes understood by :func:`table_format`, in order of preference
#: (:data:`fuelhm_bench.filetypes.FILE_TYPES`, the one place that maps suffixes to file types).
SUPPORTED_SUFFIXES: tuple[str, ...] = FILE_TYPES["table"]

# Exceptions raised by pandas / pyarrow / gzip while parsing a bad file.
_READ_ERRORS: tuple[type[BaseException], ...] = (
    OSError,
    ValueError,  # includes pandas ParserError, UnicodeDecodeError, ArrowInvalid
    EOFError,
    zlib.error,
    pa.ArrowException,
)


def table_format(path: str | os.PathLike[str], what: str = "table file") -> TableFormat:
    """Return the table format implied by a file name's suffix.

    Parameters
    ----------
    path : str or path-like
        File name; only its suffix is examined (case-insensitive).
    what : str, default="table file"
        Noun used in the error message, e.g. ``"decisions file"``.

    Returns
    -------
    {"parquet", "csv", "csv.gz"}

    Raises
    ------
    DataFormatError
        If the suffix is not one of :data:`SUPPORTED_SUFFIXES`; the message
        names the file and lists the supported suffixes.

    Examples
    --------
    >>> table_format("runs/flights.csv.gz")
    'csv.gz'
    """
    return check_file_type(path, "table", what=what).lstrip(".")  # type: ignore[return-value]


def read_table(
    path: str | os.PathLike[str],
    *,
    what: str = "table file",
    csv_dtypes: dict[str, str] | None = None,
    csv_na_values: list[str] | None = None,
    csv_lines: bool = False,
) -> pd.DataFrame:
    """Read a Parquet / CSV / CSV.gz file into a DataFrame with a default index.

    Parameters
    ----------
    path : str or path-like
        File to read; its format comes from its suffix (see :func:`table_format`).
    what : str, default="table file"
        Noun used in error messages, e.g. ``"flight file"``.
    csv_dtypes : dict of str to str, optional
        ``dtype`` mapping passed to :func:`pandas.read_csv` (ignored for
        Parquet, whose columns are typed). Columns absent from the file are
        ignored.
    csv_na_values : list of str, optional
        The only CSV cells read as missing (e.g. ``[""]``, so a cell ``nan``
        stays text and can be reported as given); default: pandas' list.
    csv_lines : bool, default=False
        For a CSV file, store each row's line in the file (1-based, the header
        is line 1; blank lines, which pandas skips, counted) in
        ``frame.attrs["csv_line"]``, for messages that name a row's line.

    Returns
    -------
    pandas.DataFrame
        The table. A named index stored in Parquet pandas metadata is turned
        back into columns; the returned index is always a ``RangeIndex``.
        CSV floats are written with pandas' shortest round-trip representation
        and parsed back to the same float64 (tested bit-identical).

    Raises
    ------
    DataFormatError
        If the file does not exist, is a directory, is empty (0 bytes), has an
        unsupported suffix, or cannot be parsed. The message names the file.
    """
    path = Path(path)
    if not path.exists():
        raise DataFormatError(f"The {what} '{path}' does not exist.")
    if path.is_dir():
        raise DataFormatError(f"The {what} '{path}' is a directory, not a file.")
    fmt = table_format(path, what)
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise DataFormatError(f"Cannot access the {what} '{path}': {exc}.") from exc
    if size == 0:
        raise DataFormatError(f"The {what} '{path}' is empty (0 bytes).")
    try:
        if fmt == "parquet":
            frame = _read_parquet(path)
        else:
            frame = _read_csv(path, compressed=fmt == "csv.gz", dtypes=csv_dtypes or {}, na_values=csv_na_values)
            if csv_lines:
                frame.attrs["csv_line"] = _csv_lines(path, fmt == "csv.gz", len(frame))
    except pd.errors.EmptyDataError as exc:
        raise DataFormatError(f"The {what} '{path}' is empty: it has no header line.") from exc
    except DataFormatError:
        raise
    except _READ_ERRORS as exc:
        raise DataFormatError(
            f"Cannot read the {what} '{path}' as {fmt}: {type(exc).__name__}: {exc}"
        ) from exc
    return frame


def _csv_lines(path: Path, compressed: bool, n_rows: int) -> np.ndarray:
    """Line in the file (1-based) of each of the ``n_rows`` data rows pandas read (it skips blank lines).

    Counts the non-blank lines after the header; when that does not give ``n_rows`` lines (a quoted
    field spanning lines), falls back to ``row + 2``.
    """
    with (gzip.open(path, "rt", newline="") if compressed else open(path, newline="")) as f:
        lines = [n for n, text in enumerate(f, start=1) if text.strip("\r\n")]
    lines = lines[1:]  # the header
    return np.asarray(lines if len(lines) == n_rows else np.arange(n_rows) + 2, dtype=np.int64)


def _duplicate_columns(names) -> list[str]:
    seen, dup = set(), []
    for n in names:
        if n in seen and n not in dup:
            dup.append(n)
        seen.add(n)
    return dup


def _read_parquet(path: Path) -> pd.DataFrame:
    dup = _duplicate_columns(pq.read_schema(path).names)
    if dup:
        raise DataFormatError(f"'{path}': column names must be unique. Got {', '.join(map(repr, dup))} "
                              f"more than once.")
    frame = pq.read_table(path).to_pandas()
    if any(name is not None for name in frame.index.names):
        return frame.reset_index()
    return frame.reset_index(drop=True)


def _read_csv(path: Path, *, compressed: bool, dtypes: dict[str, str], na_values: list[str] | None = None
              ) -> pd.DataFrame:
    header = pd.read_csv(path, compression="gzip" if compressed else None, nrows=1, header=None, dtype=str)
    dup = _duplicate_columns(str(v) for v in header.iloc[0]) if len(header) else []
    if dup:  # (pandas would rename the second one 'name.1' without a word)
        raise DataFormatError(f"'{path}': column names must be unique. Got {', '.join(map(repr, dup))} "
                              f"more than once.")
    return pd.read_csv(
        path,
        compression="gzip" if compressed else None,
        dtype=dtypes or None,
        low_memory=False,
        **({} if na_values is None else {"keep_default_na": False, "na_values": na_values}),
    )


class AtomicTableWriter:
    """Append DataFrame chunks to one table file, published atomically.

    Rows go to a hidden temporary file ``.<name>.<random>.tmp`` in the target's
    directory. :meth:`commit` closes it and renames it onto the target
    (``os.replace``, atomic on POSIX and Windows within a filesystem);
    :meth:`abort` deletes it. Until :meth:`commit`, the target path is never
    touched. Peak memory is one chunk: nothing but the Parquet schema / CSV
    column list is retained between chunks.

    Parameters
    ----------
    path : str or path-like
        Target file; format from the suffix (see :func:`table_format`).
        Missing parent directories are created.
    overwrite : bool, default=False
        Whether an existing target may be replaced. Checked on construction
        (fail early, before any work) and again just before the rename.
    what : str, default="output file"
        Noun used in error messages, e.g. ``"flight file"``.

    Attributes
    ----------
    path : pathlib.Path
        The target path.
    n_rows : int
        Rows appended so far.

    Raises
    ------
    OutputPathError
        If the target exists and ``overwrite`` is false, is a directory, or
        its directory cannot be created or written to.
    """

    def __init__(
        self, path: str | os.PathLike[str], *, overwrite: bool = False, what: str = "output file"
    ) -> None:
        self.path = Path(path)
        self.n_rows = 0
        self._format: TableFormat = table_format(self.path)
        self._overwrite = overwrite
        self._what = what
        self._columns: list[str] | None = None
        self._schema: pa.Schema | None = None
        self._parquet: pq.ParquetWriter | None = None
        self._text: IO[str] | None = None
        self._closed = False
        self._prepared = False
        check_output_path(self.path, overwrite=overwrite, what=what)
        self._tmp = temporary_path(self.path)
        try:
            # Create the temporary file now, so an unwritable directory fails early.
            with open(self._tmp, "xb"):
                pass
        except OSError as exc:
            raise OutputPathError(
                f"Cannot write the {what} '{self.path}': cannot create a file in "
                f"'{self.path.parent}' ({exc.strerror or exc})."
            ) from exc

    @property
    def columns(self) -> list[str] | None:
        """Column names fixed by the first non-empty chunk, or None before it."""
        return None if self._columns is None else list(self._columns)

    def append(self, chunk: pd.DataFrame) -> None:
        """Append the rows of ``chunk`` (its index is not written).

        Parameters
        ----------
        chunk : pandas.DataFrame
            Rows to append. The first non-empty chunk fixes the column names
            and order (and, for Parquet, the column types); later chunks must
            have the same column names, in any order. Empty chunks are skipped.

        Raises
        ------
        DataFormatError
            If the columns differ from the first chunk's, or (Parquet) a column
            cannot be converted to the type fixed by the first chunk.
        OutputPathError
            If the writer is closed or the file system refuses the write.
        """
        if self._closed or self._prepared:
            raise OutputPathError(f"The writer of '{self.path}' is already closed.")
        if len(chunk) == 0:
            return
        if self._columns is None:
            self._columns = [str(c) for c in chunk.columns]
        else:
            chunk = self._conform(chunk)
        try:
            if self._format == "parquet":
                self._append_parquet(chunk)
            else:
                self._append_csv(chunk)
        except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError) as exc:
            raise DataFormatError(
                f"Cannot append rows to the {self._what} '{self.path}': a column cannot be "
                f"stored as Parquet, or does not match the type fixed by the first chunk ({exc})."
            ) from exc
        except OSError as exc:
            raise OutputPathError(f"Cannot write the {self._what} '{self.path}': {exc}.") from exc
        self.n_rows += len(chunk)

    def _conform(self, chunk: pd.DataFrame) -> pd.DataFrame:
        assert self._columns is not None
        given = [str(c) for c in chunk.columns]
        missing = [c for c in self._columns if c not in given]
        extra = [c for c in given if c not in self._columns]
        if missing or extra:
            raise DataFormatError(
                f"Cannot append rows to the {self._what} '{self.path}': the columns must be "
                f"those of the first chunk {self._columns}. Missing {missing}, unexpected {extra}."
            )
        return chunk[self._columns]

    def _append_parquet(self, chunk: pd.DataFrame) -> None:
        if self._parquet is None:
            table = pa.Table.from_pandas(chunk, preserve_index=False)
            self._schema = table.schema
            self._parquet = pq.ParquetWriter(self._tmp, self._schema)
        else:
            table = pa.Table.from_pandas(chunk, schema=self._schema, preserve_index=False)
        self._parquet.write_table(table)

    def _append_csv(self, chunk: pd.DataFrame) -> None:
        header = self._text is None
        if self._text is None:
            if self._format == "csv.gz":
                self._text = gzip.open(self._tmp, "wt", encoding="utf-8", newline="")
            else:
                self._text = open(self._tmp, "w", encoding="utf-8", newline="")
        chunk.to_csv(self._text, header=header, index=False, lineterminator="\n")

    def _close_handles(self) -> None:
        try:
            if self._parquet is not None:
                self._parquet.close()
            if self._text is not None:
                self._text.close()
        finally:
            self._parquet = None
            self._text = None

    def commit(self) -> Path:
        """Finish the file and atomically move it onto the target path.

        Equivalent to :meth:`prepare` then :meth:`publish`.

        Returns
        -------
        pathlib.Path
            The target path.

        Raises
        ------
        DataFormatError
            If no row was ever appended (an empty table is not a valid file);
            the temporary file is removed and the target left untouched.
        OutputPathError
            If the target appeared meanwhile and ``overwrite`` is false, or the
            file cannot be finished or renamed; the temporary file is removed.
        """
        self.prepare()
        return self.publish()

    def prepare(self) -> None:
        """Finish the temporary file without publishing it.

        Lets a caller finish several files before renaming any of them.

        Raises
        ------
        DataFormatError, OutputPathError
            As :meth:`commit`; the temporary file is then removed.
        """
        if self._closed or self._prepared:
            raise OutputPathError(f"The writer of '{self.path}' is already closed.")
        self._guarded(self._finish)

    def publish(self) -> Path:
        """Rename the finished temporary file onto the target path.

        Returns
        -------
        pathlib.Path
            The target path.

        Raises
        ------
        OutputPathError
            If :meth:`prepare` was not called, the target appeared meanwhile
            and ``overwrite`` is false, or the rename fails; the temporary file
            is then removed.
        """
        if self._closed or not self._prepared:
            raise OutputPathError(f"The writer of '{self.path}' is not prepared for publishing.")
        self._guarded(self._rename)
        self._closed = True
        return self.path

    def _finish(self) -> None:
        self._close_handles()
        if self.n_rows == 0:
            raise DataFormatError(
                f"No rows were written to the {self._what} '{self.path}'; "
                "an empty table is not created."
            )
        self._prepared = True

    def _rename(self) -> None:
        check_output_path(self.path, overwrite=self._overwrite, what=self._what)
        os.replace(self._tmp, self.path)

    def _guarded(self, step: Callable[[], None]) -> None:
        """Run ``step``; on any failure discard the temporary file and re-raise."""
        try:
            step()
        except OutputPathError:
            self.abort()
            raise
        except OSError as exc:
            self.abort()
            raise OutputPathError(f"Cannot write the {self._what} '{self.path}': {exc}.") from exc
        except BaseException:
            self.abort()
            raise

    def abort(self) -> None:
        """Discard everything written; the target path is left untouched.

        Safe to call more than once and after a failed :meth:`commit`.
        """
        try:
            self._close_handles()
        except (OSError, pa.ArrowException):
            pass  # the file is being discarded anyway
        finally:
            self._closed = True
            self._tmp.unlink(missing_ok=True)
