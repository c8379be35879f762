"""The results store: one SQLite row per evaluation, keyed by a content hash (the one seam for outputs).

A row holds what one (method setting, scenario, seed) evaluation produced:
status, one-line message, every KPI, timings and provenance. The tables
needed to rebuild its report (decisions, labels, healthy scores, episodes and,
under drift, the nominal run) are stored beside it as Parquet blobs, so every
table, report and figure of a leaderboard is a view of the store
(:mod:`fuelhm_bench.benchmark.views`).

The key (:func:`evaluation_key`) is the SHA-256 of a canonical JSON of the
method's entry point, its hyperparameters as typed JSON, the hash of the
method's code and files, the scenario id (name and version) and the digest of
the loaded scenario's content, the seed, the fidelity, the scale and the
package version: a changed method, setting, scenario (even an edited copy
that keeps its name and version) or release is a new key, so a resumed run
never reuses a stale result.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import io
import json
import platform
import socket
import sqlite3
import subprocess
from pathlib import Path

import pandas as pd

from fuelhm_bench.errors import OutputPathError

__all__ = ["ResultStore", "default_store_path", "evaluation_key", "provenance", "typed_json"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS results (
    key TEXT PRIMARY KEY,
    method TEXT NOT NULL,
    params TEXT NOT NULL,
    source_hash TEXT NOT NULL,
    scenario TEXT NOT NULL,
    seed INTEGER,
    fidelity TEXT,
    scale REAL,
    package_version TEXT,
    status TEXT NOT NULL,
    message TEXT NOT NULL,
    kpis TEXT NOT NULL,
    method_params TEXT NOT NULL,
    fit_seconds REAL,
    decide_seconds REAL,
    seconds REAL,
    provenance TEXT NOT NULL,
    created TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS secret_seeds (
    position INTEGER PRIMARY KEY,
    seed INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS artifacts (
    key TEXT NOT NULL,
    name TEXT NOT NULL,
    data BLOB NOT NULL,
    PRIMARY KEY (key, name)
);
"""

_COLUMNS = ("key", "method", "params", "source_hash", "scenario", "seed", "fidelity", "scale", "package_version",
            "status", "message", "kpis", "method_params", "fit_seconds", "decide_seconds", "seconds", "provenance",
            "created")


def typed_json(value) -> str:
    """Canonical JSON of hyperparameters (sorted keys; numbers stay numbers, tuples become lists)."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=repr, allow_nan=True)


def evaluation_key(*, method: str, params: dict, source_hash: str, scenario: str, seed, fidelity: str,
                   scale: float, package_version: str, scenario_digest: str = "") -> str:
    """SHA-256 (hex) identifying one evaluation (see the module docstring)."""
    blob = typed_json({"method": method, "params": params, "source_hash": source_hash, "scenario": scenario,
                       "scenario_digest": scenario_digest, "seed": seed, "fidelity": fidelity, "scale": float(scale),
                       "package_version": package_version})
    return hashlib.sha256(blob.encode()).hexdigest()


def _git_commit() -> str:
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return ""
    try:
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=5, check=False)
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


_PROVENANCE: dict | None = None


def provenance() -> dict:
    """Package version, git commit (when available), host and library versions (timestamp added per row)."""
    global _PROVENANCE
    if _PROVENANCE is None:
        import numpy
        import sklearn

        from fuelhm_bench import __version__

        _PROVENANCE = {"package_version": __version__, "git_commit": _git_commit(), "host": socket.gethostname(),
                       "python": platform.python_version(), "numpy": numpy.__version__,
                       "scikit_learn": sklearn.__version__, "platform": platform.platform()}
    return dict(_PROVENANCE)


def _to_blob(df: pd.DataFrame) -> bytes:
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    return buf.getvalue()


class ResultStore:
    """An SQLite results store (created on first use; the writer is the one process that runs the leaderboard).

    Parameters
    ----------
    path : path-like
        The database file (its directory is created).
    """

    def __init__(self, path):
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.path, timeout=30)
            self._db.executescript(_SCHEMA)
        except (OSError, sqlite3.Error) as exc:
            raise OutputPathError(f"Cannot open the results store {self.path}: {exc}.") from None

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def secret_seeds(self, count: int) -> list[int]:
        """The store's first ``count`` secret master seeds, drawn from the operating system when missing.

        A leaderboard run with secret seeds (``secret_seeds`` in the leaderboard file, ``--secret-seeds``)
        evaluates on seeds no submission can know: a public seed lets a method rebuild the scored fleet's
        fault schedule from the public scenario file (docs/methods.md, isolation). They are drawn once,
        kept here (a folder sealed methods cannot read), and reused when the run resumes, so its results
        stay reproducible from the store.
        """
        import secrets

        from fuelhm_bench.scenarios.schema import MAX_SEED

        seeds = [s for (s,) in self._db.execute("SELECT seed FROM secret_seeds ORDER BY position")]
        with self._db:
            while len(seeds) < count:
                seed = secrets.randbelow(MAX_SEED + 1)
                if seed in seeds:
                    continue
                self._db.execute("INSERT INTO secret_seeds (position, seed) VALUES (?, ?)", (len(seeds), seed))
                seeds.append(seed)
        return seeds[:count]

    def has(self, key: str) -> bool:
        """Whether an evaluation with this key is stored."""
        return self._db.execute("SELECT 1 FROM results WHERE key = ?", (key,)).fetchone() is not None

    def keys(self) -> set[str]:
        """Every stored key."""
        return {k for (k,) in self._db.execute("SELECT key FROM results")}

    def put(self, record: dict, artifacts: dict[str, pd.DataFrame] | None = None) -> None:
        """Store one evaluation (replacing the row of the same key) and its tables, in one transaction."""
        row = dict(record)
        row.setdefault("created", _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
        for name in ("params", "kpis", "method_params", "provenance"):
            if not isinstance(row.get(name), str):
                row[name] = typed_json(row.get(name) or {})
        values = [row.get(c) for c in _COLUMNS]
        with self._db:
            self._db.execute(f"INSERT OR REPLACE INTO results ({', '.join(_COLUMNS)}) VALUES "
                             f"({', '.join('?' for _ in _COLUMNS)})", values)
            self._db.execute("DELETE FROM artifacts WHERE key = ?", (row["key"],))
            for name, df in (artifacts or {}).items():
                data = df if isinstance(df, bytes) else _to_blob(df)
                self._db.execute("INSERT INTO artifacts (key, name, data) VALUES (?, ?, ?)",
                                 (row["key"], name, data))

    def records(self, keys=None) -> pd.DataFrame:
        """Stored rows (JSON columns decoded), optionally restricted to ``keys``."""
        cur = self._db.execute(f"SELECT {', '.join(_COLUMNS)} FROM results ORDER BY created, key")
        rows = [dict(zip(_COLUMNS, r)) for r in cur]
        if keys is not None:
            keep = set(keys)
            rows = [r for r in rows if r["key"] in keep]
        for r in rows:
            for name in ("params", "kpis", "method_params", "provenance"):
                r[name] = json.loads(r[name])
        return pd.DataFrame(rows, columns=list(_COLUMNS))

    def artifact(self, key: str, name: str) -> pd.DataFrame | None:
        """A stored table of an evaluation, or None."""
        found = self._db.execute("SELECT data FROM artifacts WHERE key = ? AND name = ?", (key, name)).fetchone()
        return None if found is None else pd.read_parquet(io.BytesIO(found[0]))


def default_store_path(out) -> Path:
    """The store of an output folder: ``<out>/results.sqlite``."""
    return Path(out) / "results.sqlite"

