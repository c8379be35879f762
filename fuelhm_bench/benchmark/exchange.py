"""Data in and out: export a scenario's tables, score an externally produced decisions file.

``fuelhm-bench export`` writes what a method written in another language or
framework needs; ``fuelhm-bench score`` scores the decisions it produced (as
NAB scores detection files). The file formats are in docs/scoring.md
("External methods"). Both read the scenario through :func:`scenario_tables`,
the one place that asks the simulation cache.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError, ParameterError, show_value
from fuelhm_bench.methods.tables import DECISION_COLUMNS, GUILT_COLUMNS
from fuelhm_bench.scoring.run import LABEL_COLUMNS, UNKNOWN_ONSET_COLUMN
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["DECISION_FILE_COLUMNS", "EXPORT_LABEL_COLUMNS", "EXPORT_MANIFEST", "FILE_GUILT_SUM_TOLERANCE",
           "ScenarioTables", "check_calibration", "check_fingerprint", "check_flights", "export_scenario",
           "read_decisions", "scenario_tables", "score_decisions"]

#: Columns of the exported labels, at either fidelity: the seven modes' truth, then the fault outside them
#: (``unknown_fault``, its effect id or ""; ``onset_unknown``, its onset flight or -1).
EXPORT_LABEL_COLUMNS = (*LABEL_COLUMNS, "unknown_fault", UNKNOWN_ONSET_COLUMN)

#: Required columns of a decisions file (``guilt_<mode>`` are optional: zeros when absent).
DECISION_FILE_COLUMNS: tuple[str, ...] = ("split", "unit_id", "flight_index", "score", "alarm")

_SPLITS = ("test", "calibration")
_TRUE = {"1", "true", "True", "TRUE", "1.0"}
_FALSE = {"0", "false", "False", "FALSE", "0.0"}


@dataclasses.dataclass(frozen=True)
class ScenarioTables:
    """A scenario's tables as a method and the scorer see them.

    Attributes
    ----------
    training : pandas.DataFrame
        Healthy training indicators with ``split`` = ``"fit"`` or ``"calibration"``
        (held-out units whose scores set the thresholds ``mu + A sigma``).
    test : pandas.DataFrame
        Indicators of the scored fleet (``unit_id``, ``flight_index``, ...).
    labels : pandas.DataFrame
        Ground truth of the scored flights (:data:`EXPORT_LABEL_COLUMNS`).
    scenario : Scenario
        The scenario (seed and scale applied).
    fidelity : str
        Of the scored flights.
    flight_minutes : float
        Flight duration [min].
    """

    training: pd.DataFrame
    test: pd.DataFrame
    labels: pd.DataFrame
    scenario: Any
    fidelity: str = "physics"
    flight_minutes: float = float("nan")

    def fingerprint(self) -> dict:
        """What identifies these flights: the options that select them and a hash of their tables.

        ``export`` writes it (:data:`EXPORT_MANIFEST`) and ``score --exported`` compares it, so decisions
        made on one export are never scored against another fleet (a different ``--seed`` with the same
        number of units has the same flight keys).
        """
        from fuelhm_bench.datasets.cache import recipe_digest

        digest = hashlib.sha256()
        for table in (self.training, self.test, self.labels):
            _digest_table(digest, table)
        return {"scenario": self.scenario.id, "fidelity": self.fidelity, "seed": int(self.scenario.seeds.master),
                "scored_units": int(self.scenario.fleet.units), "flight_minutes": float(self.flight_minutes),
                "scenario_digest": recipe_digest(self.scenario)[:16], "tables_digest": digest.hexdigest()[:16],
                "digest_format": TABLES_DIGEST_FORMAT}


#: Version of :func:`_digest_table`'s canonical form; an export written with another one is told apart by it.
TABLES_DIGEST_FORMAT = 2


def _digest_table(digest, table: pd.DataFrame) -> None:
    """Feed ``digest`` with a canonical form of ``table``, the same for equal tables whatever the versions
    of pandas and numpy and the backends of their columns (object or Arrow strings, NumPy or nullable
    numbers), so that an export and a score made in different environments agree.

    Shape, then per column its name and values: booleans and integers without missing values as
    little-endian bytes, floats as little-endian float64 with one NaN pattern for every missing value,
    anything else value by value (``b``/``i``/``f`` (hex)/``s`` tokens, a missing value as ``\\0``).
    (``pandas.util.hash_pandas_object``, used before, hashes strings differently by backend.)
    """
    digest.update(f"{len(table)}x{len(table.columns)}".encode())
    for name in table.columns:
        column = table[name]
        digest.update(b"\0column\0" + str(name).encode("utf-8", "surrogatepass") + b"\0")
        kind = getattr(column.dtype, "kind", "O")
        exact = kind in "biu" and not column.isna().any()  # (a nullable column with a missing value: tokens)
        if kind == "b" and exact:
            digest.update(b"b" + column.to_numpy(dtype=np.uint8).tobytes())
        elif kind in "iu" and exact:
            digest.update(b"i" + column.to_numpy(dtype="<i8").tobytes())
        elif kind == "f":
            values = column.to_numpy(dtype="<f8", na_value=np.nan)
            canonical = np.where(np.isnan(values), np.nan, values)  # a copy: the table is untouched
            digest.update(b"f" + canonical.tobytes())
        else:
            digest.update(b"o" + "\x1f".join(map(_value_token, column.tolist())).encode("utf-8", "surrogatepass"))


def _value_token(value) -> str:
    """One value of a column of mixed or text values, in :func:`_digest_table`'s canonical form."""
    if value is None or value is pd.NA or value is pd.NaT:
        return "\0"
    if isinstance(value, (float, np.floating)) and value != value:  # NaN
        return "\0"
    if isinstance(value, (bool, np.bool_)):
        return "b1" if value else "b0"
    if isinstance(value, (int, np.integer)):
        return f"i{int(value)}"
    if isinstance(value, (float, np.floating)):
        return "f" + float(value).hex()
    return f"s{value}"


#: File of ``export``'s output folder holding :meth:`ScenarioTables.fingerprint` (JSON).
EXPORT_MANIFEST = "export.json"


def check_fingerprint(tables: ScenarioTables, exported) -> None:
    """Refuse to score against flights other than those of the export folder ``exported``.

    Raises
    ------
    DataFormatError
        Naming the manifest and every field that differs (the export's value and the score's).
    """
    manifest = Path(exported) / EXPORT_MANIFEST
    try:
        recorded = json.loads(manifest.read_text())
    except FileNotFoundError:
        raise DataFormatError(f"--exported {exported}: no {EXPORT_MANIFEST} there; give the folder written by "
                              f"'fuelhm-bench export'.") from None
    except (OSError, ValueError) as exc:
        raise DataFormatError(f"{manifest}: cannot read it as JSON ({exc}).") from None
    if not isinstance(recorded, dict):
        raise DataFormatError(f"{manifest}: must hold a JSON object. Got {type(recorded).__name__} instead.")
    now = tables.fingerprint()
    differ = [f"{k} {recorded.get(k)!r} there, {v!r} here" for k, v in now.items() if recorded.get(k) != v]
    if differ:
        raise DataFormatError(f"{manifest}: these decisions were made on other flights than the ones scored: "
                              f"{'; '.join(differ)}. {SAME_OPTIONS}")


def scenario_tables(scenario, *, fidelity: str | None = None, seed: int | None = None,
                    scale: float = 1.0, flight_minutes: float | None = None,
                    cache_dir=None, progress: Callable[[int], object] | None = None,
                    knowledge_size=None) -> ScenarioTables:
    """Training, test and label tables of a scenario, from the simulation cache.

    Parameters
    ----------
    scenario : str, Path or Scenario
    fidelity : {"physics", "surrogate"} or None, default=None
        Of the scored flights (the training flights are always physics); None:
        the scenario's.
    seed : int or None, default=None
        Overrides the scenario's master seed.
    scale : float, default=1.0
        Fraction of the scored units (every mode kept, see ``--scale``).
    flight_minutes : float or None, default=None
    cache_dir : path-like, False or None, default=None
    progress : callable, optional
    knowledge_size : KnowledgeSize, dict or None, default=None
        Size of the surrogate's knowledge build (surrogate fidelity only).

    Returns
    -------
    ScenarioTables
    """
    from fuelhm_bench.datasets.cache import resolve_scenario, scored_indicators, training_indicators
    from fuelhm_bench.flights.fleet import build_units
    from fuelhm_bench.flights.scale import scaled_unit_count
    from fuelhm_bench.datasets.checks import check_training_indicators, scenario_label
    from fuelhm_bench.benchmark.harness import split_training as _split_training
    from fuelhm_bench.envs import KnowledgeSize

    sc = resolve_scenario(scenario)
    if seed is not None:
        sc = dataclasses.replace(sc, seeds=dataclasses.replace(sc.seeds, master=int(seed),
                                                               training=None, test=None))
    fidelity = sc.fidelity if fidelity is None else fidelity
    if fidelity not in ("physics", "surrogate"):
        raise ParameterError(f"The 'fidelity' parameter of scenario_tables must be 'physics', "
                             f"'surrogate' or None. Got {fidelity!r} instead.")
    common = {"flight_minutes": flight_minutes, "cache_dir": cache_dir, "progress": progress}
    table = training_indicators(sc, **common)
    size = KnowledgeSize.coerce(knowledge_size, "scenario_tables")  # (the same rule as evaluate's)
    check_training_indicators(table, scenario_label(scenario, sc), fidelity=fidelity,
                              knowledge_flights=size.healthy_units * size.healthy_flights, flight_minutes=flight_minutes)
    fit_part, cal_part = _split_training(table)
    training = pd.concat([fit_part.assign(split="fit"), cal_part.assign(split="calibration")],
                         ignore_index=True)
    config = sc.test_fleet_config()
    n_units = scaled_unit_count(config, scale)
    if fidelity == "physics":
        test = scored_indicators(sc, units=n_units, **common)
        config = dataclasses.replace(config, n_units=n_units)
        labels = _schedule_labels(config, build_units(config))
    else:
        test, labels = _surrogate_tables(sc, n_units, flight_minutes, cache_dir, knowledge_size)
    sc = dataclasses.replace(sc, fleet=dataclasses.replace(sc.fleet, units=n_units))
    minutes = float(sc.mission.duration_min if flight_minutes is None else flight_minutes)
    return ScenarioTables(training, test, labels, sc, fidelity, minutes)


def _schedule_labels(config, units) -> pd.DataFrame:
    """Labels of a fleet flown without maintenance, from its drawn schedules (no simulation)."""
    from fuelhm_bench.flights.fleet import label_row

    rows = [label_row(unit, k, unit.schedule.intensities(k)) for unit in units for k in range(config.n_flights)]
    return pd.DataFrame(rows, columns=list(EXPORT_LABEL_COLUMNS))


def _surrogate_tables(sc, n_units, flight_minutes, cache_dir,
                      knowledge_size) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Scored fleet of the surrogate fidelity: the environment's observations, maintenance off."""
    from fuelhm_bench.benchmark.harness import observation_row
    from fuelhm_bench.envs.actuation_loop import ActuationLoopEnv

    env = ActuationLoopEnv(scenario=sc, fidelity="surrogate", maintenance=False,
                           flight_minutes=flight_minutes, cache_dir=cache_dir,
                           knowledge_size=knowledge_size)
    none = {"alarm": 0, "guilt": np.zeros(len(MODE_IDS), dtype=np.float32)}
    ind_rows, lab_parts = [], []
    for k in range(n_units):
        obs, _ = env.reset(options={"unit": k})
        for f in range(env.n_flights):
            ind_rows.append(observation_row(obs, k, f, k * env.n_flights + f).to_dict())
            obs, _, terminated, _, info = env.step(none)
        truth = info["episode_truth"]
        lab = {"unit_id": np.full(env.n_flights, k), "flight_index": truth["flight_index"]}
        for j, m in enumerate(MODE_IDS):
            lab[f"intensity_{m}"] = truth["intensity"][:, j]
            lab[f"max_intensity_{m}"] = truth["max_intensity"][j]
            lab[f"onset_{m}"] = truth["onset"][j]
        lab["unknown_fault"] = truth.get("unknown_fault", "")  # a fault outside the seven modes ("" none)
        lab[UNKNOWN_ONSET_COLUMN] = truth.get("unknown_onset", -1)
        lab_parts.append(pd.DataFrame(lab, columns=list(EXPORT_LABEL_COLUMNS)))
    return pd.DataFrame(ind_rows), pd.concat(lab_parts, ignore_index=True)


def _write(frame: pd.DataFrame, path: Path, force: bool) -> Path:
    if path.exists() and not force:
        from fuelhm_bench.errors import OutputPathError

        raise OutputPathError(f"{path} exists; refusing to overwrite it (pass --force).")
    frame.to_parquet(path, index=False)
    return path


def export_scenario(scenario, out_dir, *, raw: bool = False, force: bool = False,
                    **kwargs) -> dict[str, Path]:
    """Write a scenario's tables as Parquet files into ``out_dir``.

    Files: ``training.parquet`` (healthy training indicators, ``split`` =
    fit / calibration), ``test.parquet`` (scored indicators), ``labels.parquet``
    (ground truth of the scored flights: never show it to the method) and, with
    ``raw``, ``raw_training.parquet`` and ``raw_test.parquet`` (full-rate
    samples: ``unit_id, flight_index, time_s, current_mA, position_mm,
    demand_mm, n2_pct``... written one batch of flights at a time).

    Parameters
    ----------
    scenario : str, Path or Scenario
    out_dir : path-like
        Created if needed; existing files are not overwritten without ``force``.
    raw : bool, default=False
        Also write the raw flights (physics fidelity only; simulated again).
    force : bool, default=False
    **kwargs
        ``fidelity, seed, scale, flight_minutes, cache_dir, progress`` of
        :func:`scenario_tables`.

    Returns
    -------
    dict of str to Path
    """
    out = Path(out_dir)
    names = ["training", "test", "labels"] + (["raw_training", "raw_test"] if raw else [])
    clash = [f"{n}.parquet" for n in names if (out / f"{n}.parquet").exists()]
    clash += [EXPORT_MANIFEST] if (out / EXPORT_MANIFEST).exists() else []
    if clash and not force:
        from fuelhm_bench.errors import OutputPathError

        raise OutputPathError(f"{out / clash[0]} exists; refusing to overwrite it (pass --force).")
    if raw and kwargs.get("fidelity") == "surrogate":
        raise ParameterError("The '--raw' option of export needs the physics fidelity: the "
                             "surrogate draws indicators, not flights. Got --fidelity surrogate.")
    tables = scenario_tables(scenario, **kwargs)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"training": _write(tables.training, out / "training.parquet", True),
             "test": _write(tables.test, out / "test.parquet", True),
             "labels": _write(tables.labels, out / "labels.parquet", True)}
    manifest = out / EXPORT_MANIFEST  # what 'score --exported' checks the scored flights against
    manifest.write_text(json.dumps(tables.fingerprint(), indent=2) + "\n")
    paths["manifest"] = manifest
    if raw:
        sc = tables.scenario
        minutes = kwargs.get("flight_minutes")
        for name, config in (("raw_training", sc.training_fleet_config()),
                             ("raw_test", sc.test_fleet_config())):
            if minutes is not None:
                config = dataclasses.replace(config, mission=dataclasses.replace(
                    config.mission, duration_s=60.0 * float(minutes)))
            paths[name] = _write_raw(config, out / f"{name}.parquet", kwargs.get("progress"))
    return paths


def _write_raw(config, path: Path, progress) -> Path:
    """Full-rate flights of a fleet, one batch at a time (bounded memory)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from fuelhm_bench.flights.fleet import flights_frame, iter_flights

    writer = None
    try:
        for batch in iter_flights(config, progress=progress):
            frame = flights_frame(batch)
            index = {f.flight_id: f.flight_index for f in batch}
            frame.insert(2, "flight_index", frame["flight_id"].map(index).astype(np.int64))
            if "phase" in frame.columns:
                frame["phase"] = frame["phase"].astype(str)
            table = pa.Table.from_pandas(frame, preserve_index=False)
            if writer is None:
                writer = pq.ParquetWriter(path, table.schema)
            writer.write_table(table)
    finally:
        if writer is not None:
            writer.close()
    return path


# --------------------------------------------------------------------------- decisions
#: Said with every mismatch between a decisions file and the scenario's flights.
SAME_OPTIONS = ("Score with the --scenario, --fidelity, --seed, --scale and --minutes given to 'fuelhm-bench "
                "export' (--exported DIR checks them against its export.json).")


def read_decisions(path) -> tuple[pd.DataFrame, np.ndarray]:
    """Read and validate a decisions file (Parquet, CSV or CSV.gz, by its suffix).

    Returns
    -------
    decisions : pandas.DataFrame
        The ``test`` rows as a decisions table (:data:`DECISION_COLUMNS`).
    healthy_scores : numpy.ndarray
        Scores of the ``calibration`` rows.

    Raises
    ------
    DataFormatError
        Naming the file, the column and the first bad row (1-based line of a CSV).
    """
    test, calibration, _ = _read_decisions(path)
    healthy = calibration["score"].to_numpy(dtype=float)
    return test.reset_index(drop=True), healthy


def _read_decisions(path):
    """:func:`read_decisions`, the ``test`` rows indexed by their row in the file, and ``line(row)``."""
    from fuelhm_bench.io.tables import read_table, table_format

    path = Path(path)
    if not path.exists():
        raise DataFormatError(f"{path}: no such decisions file.")
    frame = read_table(path, what="decisions file", csv_dtypes={"split": "str", "alarm": "str"},
                       csv_na_values=[""], csv_lines=True)  # (a directory, a name not saying the format: refused)
    csv = table_format(path) != "parquet"
    lines = frame.attrs.get("csv_line")  # (pandas skips blank lines: a row's line is not row + 2)
    line = (lambda i: f"line {lines[i]}") if csv else (lambda i: f"row {i}")
    missing = [c for c in DECISION_FILE_COLUMNS if c not in frame.columns]
    if missing:
        raise DataFormatError(f"{path}: the decisions file must have the columns "
                              f"{list(DECISION_FILE_COLUMNS)} (and optionally guilt_<mode>). "
                              f"Missing {missing}.")
    unknown = [c for c in frame.columns if c not in DECISION_FILE_COLUMNS and c not in GUILT_COLUMNS]
    if unknown:
        raise DataFormatError(f"{path}: unknown column(s) {unknown}; allowed: "
                              f"{list(DECISION_FILE_COLUMNS) + list(GUILT_COLUMNS)}.")
    split = frame["split"].astype(str).str.strip()
    bad = ~split.isin(_SPLITS)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataFormatError(f"{path}, {line(i)}: column 'split' must be 'test' or "
                              f"'calibration'. Got {show_value(frame['split'].iloc[i])} instead.")
    for col in ("unit_id", "flight_index", "score"):
        values = pd.to_numeric(frame[col], errors="coerce")
        bad = ~np.isfinite(values.to_numpy(dtype=float))
        if col != "score":
            bad |= (values.fillna(-1) < 0).to_numpy() | (values.fillna(0) % 1 != 0).to_numpy()
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            what = f"an integer >= 0 (the {col} of test.parquet)" if col != "score" else "a finite number"
            raise DataFormatError(f"{path}, {line(i)}: column {col!r} must be {what}. Got "
                                  f"{show_value(frame[col].iloc[i])} instead.")
        frame[col] = values.astype(np.float64 if col == "score" else np.int64)
    alarm_text = frame["alarm"].astype(str).str.strip()
    bad = ~alarm_text.isin(_TRUE | _FALSE)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataFormatError(f"{path}, {line(i)}: column 'alarm' must be 0/1 or true/false. Got "
                              f"{show_value(frame['alarm'].iloc[i])} instead.")
    frame["alarm"] = alarm_text.isin(_TRUE)
    for col in GUILT_COLUMNS:
        if col not in frame.columns:
            frame[col] = 0.0
        blank = frame[col].isna().to_numpy()  # an empty cell is 0 (e.g. on calibration rows)
        values = pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype=float)
        values = np.where(blank, 0.0, values)
        bad = ~np.isfinite(values) | (values < 0) | (values > 1 + 1e-6)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataFormatError(f"{path}, {line(i)}: column {col!r} must be a number in [0, 1]. "
                                  f"Got {show_value(frame[col].iloc[i])} instead.")
        frame[col] = values
    test = frame[split == "test"].copy()
    calibration = frame.loc[split == "calibration", ["unit_id", "flight_index", "score"]]
    if len(calibration) < 2:
        raise DataFormatError(f"{path}: the decisions file must hold the scores of at least 2 "
                              f"'calibration' flights (the held-out healthy training units of "
                              f"training.parquet); they set the thresholds mu + A sigma. Got "
                              f"{len(calibration)} instead.")
    test[list(GUILT_COLUMNS)] = _file_guilt(test, path, line)
    return test[list(DECISION_COLUMNS)], calibration, line


#: How far a file's guilt row may sum from 1 (probabilities written rounded, e.g. 0.3333 x 3); such a
#: row is divided by its sum. Methods run by the harness keep the tighter ``GUILT_SUM_TOLERANCE``.
FILE_GUILT_SUM_TOLERANCE = 1e-3


def _file_guilt(test: pd.DataFrame, path, line) -> np.ndarray:
    """The guilt of the ``test`` rows as the scorer takes it, or the first row that breaks the rule.

    On an alarm the guilt sums to 1 (within :data:`FILE_GUILT_SUM_TOLERANCE`; none at all: uniform
    guilt, the alarm without a diagnosis); without an alarm it is all 0 or sums to 1, as a method's
    decision (:func:`~fuelhm_bench.methods.decision.decision_problem`).
    """
    guilt = test[list(GUILT_COLUMNS)].to_numpy(dtype=float, copy=True)
    alarm = test["alarm"].to_numpy()
    total = guilt.sum(axis=1)
    near_one = np.abs(total - 1.0) <= FILE_GUILT_SUM_TOLERANCE
    bad = (total != 0.0) & ~near_one
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        rule = "1 on an alarm (or all 0: uniform guilt)" if alarm[i] else "0 or 1 without an alarm"
        raise DataFormatError(f"{path}, {line(test.index[i])}: columns guilt_<mode> must sum to {rule}, within "
                              f"{FILE_GUILT_SUM_TOLERANCE:g}. Got a sum of {total[i]:.6g} instead "
                              f"({int(bad.sum())} row(s) like it).")
    guilt[near_one] /= total[near_one, None]
    guilt[alarm & (total == 0.0)] = 1.0 / len(MODE_IDS)  # an alarm without a diagnosis: uniform guilt
    return guilt


def check_flights(decisions: pd.DataFrame, labels: pd.DataFrame, path, line) -> None:
    """Refuse ``test`` rows that name a unit or flight the scenario's scored fleet does not have, or miss one.

    Parameters
    ----------
    decisions : pandas.DataFrame
        The ``test`` rows, indexed by their row in the file.
    labels : pandas.DataFrame
        The scored flights (``unit_id``, ``flight_index``).
    path : path-like
        The decisions file, named in messages.
    line : callable
        Row -> its place in the file (``"line 7"``).

    Raises
    ------
    DataFormatError
        Naming the file, the line and column of the first unknown unit or flight (and every unknown
        unit), or how many scored flights have no row, with the fleet's units and flights.
    """
    units = labels.groupby("unit_id")["flight_index"].max()
    fleet = (f"the scored fleet has {len(units)} unit(s), {units.index.min()} to {units.index.max()}, of "
             f"{units.max() + 1} flight(s) (flight_index 0 to {units.max()})")
    unknown = ~decisions["unit_id"].isin(units.index)
    if unknown.any():
        i = decisions.index[np.flatnonzero(unknown.to_numpy())[0]]
        named = sorted(set(decisions.loc[unknown, "unit_id"].tolist()))
        raise DataFormatError(f"{path}, {line(i)}: column 'unit_id' names {len(named)} unit(s) the scenario does "
                              f"not have: {show_value(named)}; {fleet}. {SAME_OPTIONS}")
    scored = pd.MultiIndex.from_frame(labels[list(_KEYS)])
    extra, repeated, missing = _key_mismatch(decisions, scored)
    if extra.any():
        i = decisions.index[np.flatnonzero(extra)[0]]
        unit, k = decisions.loc[i, "unit_id"], decisions.loc[i, "flight_index"]
        raise DataFormatError(f"{path}, {line(i)}: column 'flight_index' must be a scored flight of unit {unit}, "
                              f"0 to {units[unit]}. Got {k} instead ({int(extra.sum())} row(s) name flights the "
                              f"scenario does not have). {SAME_OPTIONS}")
    _refuse_repeated(decisions, repeated, "test", "test.parquet", path, line)
    if missing.any():
        unit, k = scored[np.flatnonzero(missing)[0]]
        raise DataFormatError(f"{path}: {int(missing.sum())} scored flight(s) have no 'test' row, e.g. flight {k} "
                              f"of unit {unit}; the 'test' rows must cover exactly the flights of test.parquet "
                              f"({fleet}). {SAME_OPTIONS}")


_KEYS = ("unit_id", "flight_index")


def _key_mismatch(rows: pd.DataFrame, expected: pd.MultiIndex) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masks of ``rows`` naming a flight not in ``expected`` and repeating an earlier row, and of ``expected``
    flights no row names."""
    given = pd.MultiIndex.from_frame(rows[list(_KEYS)])
    return ~given.isin(expected), given.duplicated(), ~expected.isin(given)


def _refuse_repeated(rows: pd.DataFrame, repeated: np.ndarray, split: str, flights: str, path, line) -> None:
    """Refuse the first of ``rows`` that repeats an earlier row's flight, with its line."""
    if repeated.any():
        i = rows.index[np.flatnonzero(repeated)[0]]
        raise DataFormatError(f"{path}, {line(i)}: a {split!r} row repeats flight {rows.loc[i, 'flight_index']} of "
                              f"unit {rows.loc[i, 'unit_id']}; one row per flight of {flights}.")


def check_calibration(calibration: pd.DataFrame, training: pd.DataFrame, path, line) -> None:
    """Refuse ``calibration`` rows that are not exactly the calibration flights of the exported training table.

    Their scores set the thresholds ``mu + A sigma``; a file free to choose them (two rows, made-up
    units, the scored flights copied) would set the ``*_thr`` KPIs itself.

    Parameters
    ----------
    calibration : pandas.DataFrame
        The ``calibration`` rows (``unit_id``, ``flight_index``), indexed by their row in the file.
    training : pandas.DataFrame
        The scenario's training table with its ``split`` column (``training.parquet``).
    path : path-like
        The decisions file, named in messages.
    line : callable
        Row -> its place in the file.

    Raises
    ------
    DataFormatError
        Naming the file, and the line of the first unknown or repeated flight, or how many
        calibration flights have no row.
    """
    expected = pd.MultiIndex.from_frame(training.loc[training["split"] == "calibration", list(_KEYS)].astype(np.int64))
    extra, repeated, missing = _key_mismatch(calibration, expected)
    where = (f"the calibration flights of training.parquet: {len(expected)} flights of units "
             f"{expected.get_level_values(0).min()} to {expected.get_level_values(0).max()}")
    if extra.any():
        i = calibration.index[np.flatnonzero(extra)[0]]
        raise DataFormatError(f"{path}, {line(i)}: a 'calibration' row names flight {calibration.loc[i, 'flight_index']} "
                              f"of unit {calibration.loc[i, 'unit_id']}, which is not one of {where} "
                              f"({int(extra.sum())} row(s) like it). {SAME_OPTIONS}")
    _refuse_repeated(calibration, repeated, "calibration", where, path, line)
    if missing.any():
        unit, k = expected[np.flatnonzero(missing)[0]]
        raise DataFormatError(f"{path}: {int(missing.sum())} of {where} have no 'calibration' row, e.g. flight {k} "
                              f"of unit {unit}; their scores set the thresholds, so every one is needed. "
                              f"{SAME_OPTIONS}")


def score_decisions(path, scenario, *, config=None, exported=None, on_tables=None, **kwargs):
    """Score a decisions file against a scenario's labels.

    Parameters
    ----------
    path : path-like
        Decisions file (docs/scoring.md, "External methods"); read and checked first, so a bad file
        is refused before any flight is simulated.
    scenario : str, Path or Scenario
    config : ScoringConfig or None, default=None
    exported : path-like or None, default=None
        The folder ``export`` wrote the decisions' flights into: its :data:`EXPORT_MANIFEST` must
        match the flights scored (:func:`check_fingerprint`).
    on_tables : callable or None, default=None
        Called with the :class:`ScenarioTables` scored against (e.g. to print their fingerprint).
    **kwargs
        ``fidelity, seed, scale, flight_minutes, cache_dir`` of :func:`scenario_tables`
        (the same as at export).

    Returns
    -------
    Scorecard

    Raises
    ------
    DataFormatError
        Naming the file, for an invalid file or flights that do not match the scenario's.
    """
    from fuelhm_bench.scoring import Run, score_run

    decisions, calibration, line = _read_decisions(path)
    tables = scenario_tables(scenario, **kwargs)
    if exported is not None:
        check_fingerprint(tables, exported)
    if on_tables is not None:
        on_tables(tables)
    check_flights(decisions, tables.labels, path, line)
    check_calibration(calibration, tables.training, path, line)
    healthy = calibration["score"].to_numpy(dtype=float)
    decisions = decisions.reset_index(drop=True)
    try:
        run = Run(labels=tables.labels, decisions=decisions, healthy_scores=healthy, name=Path(path).stem)
    except DataFormatError as exc:
        raise DataFormatError(f"{path}: {exc}") from None
    return score_run(run, config)
