"""The one rule for writing outputs: never overwrite without ``--force``, publish atomically.

Every command that writes a file or a directory of results goes through this
module, so the rule and its messages are the same everywhere:

* an existing output is refused unless ``force`` (``--force``) is given;
* an output that is one of the command's input files (the same file, through
  symlinks or hard links too) is refused even with ``force``;
* an output of a fixed type must be named for it (``kind``: a model is
  ``.yaml``, a figure ``.png``/``.pdf``/``.svg``; :mod:`fuelhm_bench.filetypes`);
* missing parent directories are created; a parent path that is a *file*, a
  directory where a file is expected, or an unwritable directory is refused
  with a message naming the option, the path and the offending component;
* data is written to a hidden temporary file in the target directory and
  renamed onto the target only on success (:func:`atomic_output`), so an
  interrupted run (Ctrl-C, crash) never leaves a partial file that looks
  complete.

API
---
:func:`check_output_path`
    Check (and prepare the parents of) one output file.
:func:`check_output_dir`
    Check (and create) an output directory; with ``names`` it refuses
    existing files of those names unless ``force``.
:func:`atomic_output`
    Context manager yielding a temporary path to write to; renames it onto the
    target on success, deletes it on any exception (``KeyboardInterrupt`` too).
:func:`write_text`
    Atomic text file (e.g. JSON, YAML, Markdown).
:func:`atomic_directory`
    Context manager yielding a temporary sibling directory to fill; its
    content is published into the target directory on success, deleted on
    any exception (``KeyboardInterrupt`` too).

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> with atomic_output(d / "a.txt", force=False) as tmp:
...     _ = tmp.write_text("hello")
>>> (d / "a.txt").read_text()
'hello'
>>> try:
...     write_text(d / "a.txt", "again", force=False)
... except OutputPathError as exc:
...     print(exc)  # doctest: +ELLIPSIS
The output file '...a.txt' already exists; refusing to overwrite it (pass --force to replace it; overwrite=True from Python).
"""

from __future__ import annotations

import contextlib
import os
import uuid
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

from fuelhm_bench.errors import OutputPathError
from fuelhm_bench.filetypes import check_file_type

__all__ = ["MANIFEST", "atomic_directory", "atomic_output", "check_output_dir", "check_output_path", "claim",
           "refuse_foreign", "refuse_inputs", "temporary_path", "write_text", "written_by_us"]


def _label(option: str | None, what: str, path: Path) -> str:
    return f"{option} {path}" if option else f"the {what} '{path}'"


def _blocking_file(path: Path) -> Path | None:
    """The first ancestor of ``path`` that exists and is not a directory, if any."""
    for parent in reversed(path.parents):
        if parent.exists() and not parent.is_dir():
            return parent
    return None


def _make_parent(path: Path, option: str | None, what: str) -> None:
    blocker = _blocking_file(path)
    if blocker is not None:
        raise OutputPathError(
            f"Cannot write {_label(option, what, path)}: cannot create its directory '{path.parent}' "
            f"because '{blocker}' is a file, not a directory. Choose another path.")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPathError(
            f"Cannot write {_label(option, what, path)}: cannot create its directory "
            f"'{path.parent}' ({exc.strerror or exc}).") from None
    if not os.access(path.parent, os.W_OK):
        raise OutputPathError(f"Cannot write {_label(option, what, path)}: the directory '{path.parent}' is "
                              "not writable (permission denied).")


def _same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name the same file (symlinks and hard links resolved)."""
    try:
        return os.path.samefile(a, b)
    except OSError:  # one does not exist (yet)
        return a.resolve() == b.resolve()


def refuse_inputs(path: str | os.PathLike[str], inputs: Mapping | None, *, option: str | None = None,
                  what: str = "output file") -> None:
    """Refuse to write ``path`` when it is one of the command's input files, whatever ``--force`` says.

    Parameters
    ----------
    path : str or path-like
        The output file.
    inputs : mapping of str to (path-like or None), or None
        The command's input files by how the user gave them (``{"FLIGHTS": "a.csv", "--model": None}``).
    option, what
        As for :func:`check_output_path`.

    Raises
    ------
    OutputPathError
        Naming the output, the input it would replace and how it was given.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()); _ = (d / "a.csv").write_text("x")
    >>> refuse_inputs(d / "b.csv", {"FLIGHTS": d / "a.csv"})
    >>> try:
    ...     refuse_inputs(d / "." / "a.csv", {"FLIGHTS": d / "a.csv"}, option="--out")
    ... except OutputPathError as exc:
    ...     print(str(exc).split(": ", 1)[1])
    it is the input file FLIGHTS (...a.csv); an input is never overwritten, even with --force. Choose another --out.
    """
    path = Path(path)
    for given_as, source in (inputs or {}).items():
        if source is not None and _same_file(path, Path(source)):
            raise OutputPathError(f"Cannot write {_label(option, what, path)}: it is the input file {given_as} "
                                  f"({source}); an input is never overwritten, even with --force. "
                                  f"Choose another {option or 'output file'}.")


def check_output_path(path: str | os.PathLike[str], *, overwrite: bool, what: str = "output file",
                      option: str | None = None, kind: str | None = None, inputs: Mapping | None = None) -> Path:
    """Check that ``path`` may be written and create its parent directories.

    Parameters
    ----------
    path : str or path-like
        Target file.
    overwrite : bool
        Whether an existing file may be replaced (``--force``).
    what : str, default="output file"
        Noun used in messages when no option is given.
    option : str or None, default=None
        Command-line option the path came from (e.g. ``"--out"``), named in messages.
    kind : {"table", "yaml", "image", "json", "sqlite"} or None, default=None
        Type of what is written: the name must end in one of its suffixes
        (:data:`fuelhm_bench.filetypes.FILE_TYPES`); None: any name.
    inputs : mapping of str to path-like or None, default=None
        The command's input files (:func:`refuse_inputs`).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    OutputPathError
        ``path`` is not named for ``kind``, is one of ``inputs``, is a
        directory, exists while ``overwrite`` is false, lies below a file, or
        its directory cannot be created or written.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputPathError(f"Cannot write {_label(option, what, path)}: it is a directory; give a file name.")
    if kind is not None:
        check_file_type(path, kind, what=what, option=option, writing=True, error=OutputPathError)
    refuse_inputs(path, inputs, option=option, what=what)
    if path.exists() and not overwrite:
        raise OutputPathError(f"The {what} '{path}' already exists; refusing to overwrite it (pass --force to "
                              "replace it; overwrite=True from Python).")
    _make_parent(path, option, what)
    return path


def check_output_dir(path: str | os.PathLike[str], *, force: bool = True, names: Iterable[str] = (),
                     option: str | None = "--out", inputs: Mapping | None = None) -> Path:
    """Check and create an output directory.

    Parameters
    ----------
    path : str or path-like
        The directory.
    force : bool, default=True
        Whether files listed in ``names`` that already exist may be replaced.
    names : iterable of str, default=()
        Files the command will write in the directory; without ``force`` any
        that exists is refused (all of them named in one message).
    option : str or None, default="--out"
        Option named in messages.
    inputs : mapping of str to path-like or None, default=None
        The command's input files: none may be one of ``names`` in ``path``
        (:func:`refuse_inputs`), even with ``force``.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    OutputPathError
        ``path`` (or an ancestor) is a file, cannot be created or written,
        would replace an input, or holds one of ``names`` while ``force`` is
        false.
    """
    path = Path(path)
    names = tuple(names)
    for name in names:
        refuse_inputs(path / name, inputs, option=option, what="output file")
    label = _label(option, "output directory", path)
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"Cannot use {label}: it is a file, not a directory.")
    blocker = _blocking_file(path / "x")
    if blocker is not None:
        raise OutputPathError(f"Cannot use {label}: '{blocker}' is a file, not a directory.")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPathError(f"Cannot create {label}: {exc.strerror or exc}.") from None
    if not os.access(path, os.W_OK):
        raise OutputPathError(f"Cannot write to {label} (permission denied).")
    existing = [n for n in names if (path / n).exists()]
    if existing and not force:
        shown = ", ".join(existing[:5]) + (f" and {len(existing) - 5} more" if len(existing) > 5 else "")
        raise OutputPathError(f"{_label(option, 'output directory', path)} already holds {shown}; refusing to "
                              f"overwrite (pass --force, or choose another {option or 'folder'}).")
    return path


#: A folder's record of the entries fuelhm-bench wrote into it (one name per line): those a later run
#: of a command may replace without ``--force``; anything else there is the user's.
MANIFEST = ".fuelhm-bench-outputs"


def written_by_us(folder: Path) -> set[str]:
    """Names of the entries of ``folder`` that fuelhm-bench wrote (its :data:`MANIFEST`)."""
    try:
        return {line for line in (Path(folder) / MANIFEST).read_text(encoding="utf-8").splitlines() if line}
    except (OSError, UnicodeDecodeError):
        return set()


def claim(folder: Path, names: Iterable[str]) -> None:
    """Record ``names`` as written by fuelhm-bench in ``folder`` (atomic rewrite of its :data:`MANIFEST`)."""
    folder = Path(folder)
    entries = sorted(written_by_us(folder) | {str(n) for n in names})
    tmp = temporary_path(folder / MANIFEST)
    tmp.write_text("".join(f"{n}\n" for n in entries), encoding="utf-8")
    os.replace(tmp, folder / MANIFEST)


def refuse_foreign(folder: Path, names: Iterable[str], *, force: bool, option: str | None = "--out") -> None:
    """Refuse, unless ``force``, to replace an entry of ``folder`` in ``names`` that fuelhm-bench did not write.

    Output of an earlier run (listed in the folder's :data:`MANIFEST`) is replaced freely: a command
    run again refreshes its own files. A file of the same name that the user made is not.
    """
    folder = Path(folder)
    ours = written_by_us(folder)
    foreign = sorted(n for n in names if (folder / n).exists() and n not in ours)
    if foreign and not force:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise OutputPathError(f"{_label(option, 'output directory', folder)} already holds {shown}, not written by "
                              f"fuelhm-bench; refusing to replace (pass --force, or choose another {option or 'folder'}).")


def temporary_path(path: Path) -> Path:
    """A hidden, unique sibling of ``path`` that keeps its full suffix (``.x.csv.gz``)."""
    return path.with_name(f".tmp-{uuid.uuid4().hex[:12]}-{path.name}")


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str], *, force: bool, what: str = "output file",
                  option: str | None = None, kind: str | None = None, inputs: Mapping | None = None) -> Iterator[Path]:
    """Write ``path`` atomically: yield a temporary path, rename it onto ``path`` on success.

    Parameters
    ----------
    path : str or path-like
        Target file (checked by :func:`check_output_path` first).
    force : bool
        Whether an existing target may be replaced.
    what, option, kind, inputs
        As for :func:`check_output_path`.

    Yields
    ------
    pathlib.Path
        Temporary file in the target directory, with the target's suffixes (so
        writers that choose a format by suffix work). The caller writes it.

    Raises
    ------
    OutputPathError
        As :func:`check_output_path`, or when nothing was written to the
        temporary path, or the rename fails. On any exception (including
        ``KeyboardInterrupt``) the temporary file is deleted and the target is
        left as it was.
    """
    target = check_output_path(path, overwrite=force, what=what, option=option, kind=kind, inputs=inputs)
    tmp = temporary_path(target)
    try:
        yield tmp
        if not tmp.exists():
            raise OutputPathError(f"Nothing was written to {_label(option, what, target)}.")
        check_output_path(target, overwrite=force, what=what, option=option)  # appeared meanwhile?
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OutputPathError):
            raise
        raise OutputPathError(f"Cannot write {_label(option, what, target)}: {exc.strerror or exc}.") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text(path: str | os.PathLike[str], text: str, *, force: bool, what: str = "output file",
               option: str | None = None, kind: str | None = None) -> Path:
    """Write a text file atomically (UTF-8) under the overwrite rule.

    Parameters
    ----------
    path : str or path-like
        Target file.
    text : str
        Content.
    force : bool
        Whether an existing file may be replaced.
    what, option, kind
        As for :func:`check_output_path`.

    Returns
    -------
    pathlib.Path
    """
    with atomic_output(path, force=force, what=what, option=option, kind=kind) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike[str], *, force: bool = False, names: Iterable[str] = (),
                     expected: Iterable[str] = (), option: str | None = "--out",
                     inputs: Mapping | None = None) -> Iterator[Path]:
    """Fill an output directory atomically: yield a temporary sibling, publish its content on success.

    The command writes every file into the yielded directory (a hidden
    ``.tmp-<random>-<name>`` next to ``path``). On success, a new ``path`` is
    the temporary directory renamed (one atomic step); into an existing
    ``path`` each written file is renamed onto its target (each one atomic),
    and files of ``path`` the command did not write are left alone. On any
    exception, ``KeyboardInterrupt`` included, the temporary directory is
    deleted and ``path`` is left as it was: an interrupted run publishes
    nothing. The entries published are recorded in the folder's
    :data:`MANIFEST`: a later run replaces them freely, but an entry of the same
    name that fuelhm-bench did not write (the user's ``table.md``) is replaced
    only with ``force``.

    Parameters
    ----------
    path : str or path-like
        The output directory.
    force : bool, default=False
        Whether existing entries may be replaced: those listed in ``names``,
        and those fuelhm-bench did not write.
    names : iterable of str, default=()
        Files the command will write; without ``force`` any that exists is refused.
    expected : iterable of str, default=()
        Entries the command will write that a run of it again may refresh: checked
        now, before the command's work, against the user's entries of the same
        names (:func:`refuse_foreign`); unlike ``names``, an entry fuelhm-bench
        wrote there earlier is replaced without ``force``.
    option : str or None, default="--out"
        Option named in messages.
    inputs : mapping of str to path-like or None, default=None
        The command's input files: none may be replaced (checked for ``names``
        first, and for every written file at publication), even with ``force``.

    Yields
    ------
    pathlib.Path
        The temporary directory to write into.

    Raises
    ------
    OutputPathError
        As :func:`check_output_dir` (checked before and again at publication).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()) / "out"
    >>> with atomic_directory(d) as tmp:
    ...     _ = (tmp / "a.txt").write_text("hello")
    ...     d.exists()
    False
    >>> sorted(p.name for p in d.iterdir())  # and the record of what fuelhm-bench wrote there
    ['.fuelhm-bench-outputs', 'a.txt']
    """
    target = Path(path)
    names = tuple(names)
    label = _label(option, "output directory", target)
    for name in names:
        refuse_inputs(target / name, inputs, option=option)
    if target.exists():
        check_output_dir(target, force=force, names=names, option=option)
        refuse_foreign(target, (*names, *expected), force=force, option=option)
    else:
        blocker = _blocking_file(target)
        if blocker is not None:
            raise OutputPathError(f"Cannot use {label}: '{blocker}' is a file, not a directory.")
        _make_parent(target, option, "output directory")
    tmp = temporary_path(target)
    try:
        tmp.mkdir()
    except OSError as exc:
        raise OutputPathError(f"Cannot write {label}: {exc.strerror or exc}.") from None
    try:
        yield tmp
        written = sorted(p.name for p in tmp.iterdir())
        for name in written:
            refuse_inputs(target / name, inputs, option=option)
        if target.exists():
            check_output_dir(target, force=force, names=names, option=option)  # appeared meanwhile?
            refuse_foreign(target, written, force=force, option=option)
            _merge(tmp, target)
        else:
            os.replace(tmp, target)
        claim(target, written)
    except OSError as exc:
        if isinstance(exc, OutputPathError):
            raise
        raise OutputPathError(f"Cannot write {label}: {exc.strerror or exc}.") from None
    finally:
        if tmp.exists():
            import shutil

            shutil.rmtree(tmp, ignore_errors=True)


def _merge(source: Path, target: Path) -> None:
    """Move every entry of ``source`` into ``target`` (files renamed onto theirs; folders merged)."""
    for entry in sorted(source.iterdir()):
        dest = target / entry.name
        if entry.is_dir() and not entry.is_symlink():
            if dest.is_dir() and not dest.is_symlink():
                _merge(entry, dest)
                continue
            if dest.exists() or dest.is_symlink():
                raise OutputPathError(f"Cannot publish '{dest}': it is a file where a folder goes.")
        elif dest.is_dir() and not dest.is_symlink():
            raise OutputPathError(f"Cannot publish '{dest}': it is a folder where a file goes.")
        os.replace(entry, dest)
