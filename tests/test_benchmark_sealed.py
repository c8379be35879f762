"""Sealed submissions: every failure becomes a row, limits hold, no orphans, and a spy finds no ground truth."""

from __future__ import annotations

import os
import sys
import time

import numpy as np
import pandas as pd
import pytest

from fuelhm_bench.benchmark.harness import prepare_evaluation, run_in_env
from fuelhm_bench.envs import KnowledgeSize
from fuelhm_bench.errors import ParameterError
from fuelhm_bench.methods.sandbox import Limits, SealedMethod
from submissions import Chatty, Daemonizes, ForgesFitTime, Hogs, OpensSockets, IdleCurrent, Segfaults, Spins, Spy, SysExit
from test_runner import tiny


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("sealed-cache")


@pytest.fixture(scope="module")
def evaluation(cache_dir):
    return prepare_evaluation(tiny(), fidelity="surrogate", knowledge_size=KnowledgeSize.small(), cache_dir=cache_dir)


def test_a_spy_finds_no_ground_truth(evaluation, cache_dir, tmp_path, monkeypatch):
    """Frames, gc.get_objects(), loaded modules, the cache, the output folder, the parent's memory: nothing."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "labels.csv").write_text("flight_id,onset_internal_leakage,intensity_internal_leakage\n0,3,0.5\n")
    monkeypatch.setenv("FUELHM_BENCH_CACHE", str(cache_dir))
    log = tmp_path / "spy.log"
    dirs = (str(cache_dir), str(out), os.getcwd(), "/tmp")
    outcome = run_in_env(Spy(dirs=dirs, pids=(os.getpid(),)), evaluation, log_path=log, deny=[str(out)],
                         timeout_s=120)
    assert outcome.ok, outcome.message
    if outcome.sandbox.startswith("no file-system restriction"):  # no Landlock: memory probes only, then say so
        outcome = run_in_env(Spy(), evaluation, log_path=log, timeout_s=120)
        assert outcome.ok and "SPY FOUND: []" in log.read_text()
        pytest.skip(f"memory is clean, but the file system is not sealed here: {outcome.sandbox}")
    found = log.read_text()
    assert "SPY FOUND: []" in found, found[-2000:]
    assert not outcome.decisions["alarm"].any()
    # the spy does find the planted file when nothing is sealed: the probe itself works
    from submissions import _hunt

    assert any("labels.csv" in f for f in _hunt([str(out)]))


def test_every_failure_kind_is_a_row(evaluation, tmp_path):
    cases = {
        "SysExit": (SysExit(), {}, "error", "SystemExit(0)"),
        "Segfaults": (Segfaults(), {}, "crash", "signal SIGSEGV during fit"),
        "RaisesInInit": ("submissions:RaisesInInit", {}, "error", "cannot construct"),
        "BadModule": ("submissions_nowhere:X", {}, "error", "Cannot import the method module"),
        "Spins": (Spins(), {"cpu_s": 2.0, "wall_s": 60.0}, "cpu_limit", "CPU-time limit of 2 s during fit"),
        "Hogs": (Hogs(), {"memory_mb": 1024.0}, "memory", "out of memory"),
    }
    for name, (method, limits, status, text) in cases.items():
        outcome = run_in_env(method, evaluation, limits={"wall_s": 60.0, **limits})
        assert outcome.status == status and text in outcome.message, (name, outcome.status, outcome.message)
        assert "\n" not in outcome.message
    assert run_in_env(IdleCurrent(), evaluation).ok  # and the next method is unaffected


def test_logs_are_bounded_and_no_process_survives(evaluation, tmp_path):
    log = tmp_path / "chatty.log"
    outcome = run_in_env(Chatty(), evaluation, limits={"log_kb": 64.0, "wall_s": 60.0}, log_path=log)
    assert outcome.ok, outcome.message
    text = log.read_text()
    assert len(text) < 70 * 1024 and "log cut at 65536 bytes" in text
    pid = int(text.split("ORPHAN ")[1].split()[0])
    time.sleep(0.5)
    assert _gone(pid), f"process {pid} started by the method survived the run"


def test_a_daemon_that_left_the_process_group_does_not_survive(evaluation, tmp_path):
    """A double fork with setsid escaped the process-group kill and outlived the run (probe4); the zygote is now
    the subreaper of what methods start and kills what is left when a sealed process ends."""
    log = tmp_path / "daemon.log"
    outcome = run_in_env(Daemonizes(), evaluation, log_path=log, timeout_s=60)
    assert outcome.ok, outcome.message
    pid = int(log.read_text().split("DAEMON ")[1].split()[0])
    for _ in range(40):
        if _gone(pid):
            break
        time.sleep(0.05)
    assert _gone(pid), f"the daemon {pid} survived the run"


def test_internet_sockets_are_refused_unix_ones_work(evaluation, tmp_path):
    """Landlock fences TCP only: a probe sent data off the machine over UDP. A seccomp filter now refuses
    IPv4/IPv6 sockets; Unix sockets (multiprocessing, joblib) still work."""
    log = tmp_path / "sockets.log"
    outcome = run_in_env(OpensSockets(), evaluation, log_path=log, timeout_s=60)
    assert outcome.ok, outcome.message
    text = log.read_text()
    assert "UNIX ok" in text, text[-2000:]
    import platform
    import sys

    from fuelhm_bench.methods._sealed_child import _SECCOMP_ARCHES

    if not (sys.platform.startswith("linux") and platform.machine() in _SECCOMP_ARCHES):
        pytest.skip(f"no seccomp filter for {sys.platform} {platform.machine()}")
    if "IPv4/IPv6 sockets not filtered" in outcome.sandbox:  # the filter was tried and refused by this kernel
        pytest.skip(f"seccomp refused here: {outcome.sandbox}")
    assert "no IPv4/IPv6 sockets" in outcome.sandbox, outcome.sandbox
    for name in ("UDP4", "UDP6", "TCP4"):
        assert f"{name} refused PermissionError" in text, text[-2000:]


def test_an_unwritable_log_still_drains_the_method_output(evaluation, tmp_path):
    """The log file cannot be opened (its folder is missing): the method's megabytes of output are still drained.

    Before, the log thread died opening the file (an exception in a thread) and the method blocked on a
    full pipe until its wall-time limit.
    """
    outcome = run_in_env(Chatty(), evaluation, limits={"log_kb": 64.0, "wall_s": 30.0},
                         log_path=tmp_path / "missing" / "chatty.log")
    assert outcome.ok, outcome.message
    assert not (tmp_path / "missing").exists()


def _gone(pid: int) -> bool:
    """True when the process no longer exists or is a zombie (dead, waiting to be reaped by init)."""
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


def test_limits_are_validated():
    with pytest.raises(ParameterError, match=r"'memory_mb' parameter of Limits must be a finite number in \[256, "):
        Limits(memory_mb=10)
    # a limit past what clocks and setrlimit hold (was an OverflowError traceback from --timeout 1e300)
    for field in ("wall_s", "cpu_s", "memory_mb", "log_kb"):
        with pytest.raises(ParameterError, match=f"'{field}' parameter of Limits must be a finite number in"):
            Limits(**{field: 1e300})
    with pytest.raises(ParameterError, match="unknown limit 'cpu'"):
        Limits.coerce({"cpu": 3})
    with pytest.raises(ParameterError, match="'wall_s' parameter of Limits"):
        Limits(wall_s=float("nan"))


def test_a_reply_is_json_never_pickle(evaluation):
    """The harness reads plain JSON from the method: a decision's guilt comes back as floats."""
    with SealedMethod(IdleCurrent(), limits={"wall_s": 60.0}) as m:
        m.fit(evaluation.fit_indicators)
        scores = m.scores(evaluation.calibration_indicators)
        assert scores.dtype == np.float64 and np.all(np.isfinite(scores))
        assert m.sandbox.startswith(("landlock", "no file-system restriction"))


_OUTSIDER = '''
import multiprocessing.pool
import os
import sys

import numpy as np
from sklearn.ensemble import IsolationForest

from fuelhm_bench.methods import BaseMethod, Decision
from fuelhm_bench.taxonomy import INDICATOR_NAMES


def _try(what, fn):
    try:
        fn()
        print(what, "ok", flush=True)
    except OSError as exc:
        print(what, "denied", type(exc).__name__, flush=True)


class Outsider(BaseMethod):
    """What a researcher's own module does: lives in the working directory, uses n_jobs, a thread pool and joblib's
    process pool."""

    def _fit(self, table, *, knowledge, raw_flights, rng):
        x = np.nan_to_num(table[list(INDICATOR_NAMES)].to_numpy(dtype=float))
        self.forest_ = IsolationForest(n_estimators=20, n_jobs=2, random_state=0).fit(x)
        with multiprocessing.pool.ThreadPool(2) as pool:
            assert pool.map(abs, [-1, -2]) == [1, 2]
        from joblib import Parallel, delayed  # loky worker processes: psutil lists /proc (a /proc limited to
        assert Parallel(n_jobs=2)(delayed(abs)(-i) for i in range(3)) == [0, 1, 2]  # the method's pid broke it)
        print("POOL ok", flush=True)
        _try("NOTES", lambda: open(os.path.join(PROJECT, "notes.txt")).read())
        _try("LABELS", lambda: open(os.path.join(PROJECT, "results", "labels.csv")).read())
        _try("LISTING", lambda: os.listdir(PROJECT))

    def _decide(self, row):
        return Decision(score=0.0, alarm=False, guilt=np.zeros(7))
'''


def test_an_outsider_module_in_the_working_directory(evaluation, tmp_path, monkeypatch):
    """A method module beside the output folder imports (the folder stays sealed) and may use n_jobs / thread pools.

    Before: with ``--out`` inside the working directory the whole directory was left unreadable, so
    ``mymodule:Method`` failed with "No module named 'mymodule'"; and any ``multiprocessing`` lock (a
    thread pool's, hence scikit-learn's ``n_jobs``) failed with PermissionError (no /dev/shm).
    """
    project = tmp_path / "project"
    (project / "results").mkdir(parents=True)
    (project / "results" / "labels.csv").write_text("flight_id,onset_internal_leakage\n0,3\n")
    (project / "notes.txt").write_text("the researcher's own file\n")
    (project / "outsider_method.py").write_text(f"PROJECT = {str(project)!r}\n" + _OUTSIDER)
    monkeypatch.chdir(project)
    log = tmp_path / "outsider.log"
    outcome = run_in_env("outsider_method:Outsider", evaluation, log_path=log, deny=[str(project / "results")],
                         timeout_s=120)
    assert outcome.ok, (outcome.message, log.read_text()[-2000:])
    text = log.read_text()
    assert "POOL ok" in text and "NOTES ok" in text and "LISTING ok" in text, text[-2000:]
    if outcome.sandbox.startswith("no file-system restriction"):
        pytest.skip(f"the module imports and pools work, but the file system is not sealed here: {outcome.sandbox}")
    assert "LABELS denied PermissionError" in text, text[-2000:]


def test_readable_around_a_denied_folder(tmp_path):
    """The read rules of a directory holding a denied folder: every entry but the way to it, no symlink into it."""
    from fuelhm_bench.methods.sandbox import _readable_around

    root = (tmp_path / "project").resolve()
    (root / "sub" / "out").mkdir(parents=True)
    (root / "sub" / "out" / "labels.csv").write_text("x")
    (root / "a.py").write_text("")
    (root / "sub" / "b.txt").write_text("")
    (root / "pkg").mkdir()
    (root / "link").symlink_to(root / "sub" / "out" / "labels.csv")
    (root / "dirlink").symlink_to(root / "sub")  # resolves to a directory that holds the denied one
    other = (tmp_path / "other").resolve()
    other.mkdir()
    readable, listable = _readable_around([str(root), str(other), str(root / "sub" / "out" / "x")],
                                          [str(root / "sub" / "out")])
    assert sorted(readable) == sorted([str(root / "a.py"), str(root / "pkg"), str(root / "sub" / "b.txt"), str(other)])
    assert len(set(readable)) == len(readable)
    assert listable == [str(root), str(root / "sub")]
    assert _readable_around([str(root)], []) == ([str(root)], [])


def test_a_cache_given_by_path_is_hidden_too(cache_dir, tmp_path, monkeypatch):
    """A simulation cache passed as ``cache_dir`` (here inside the working directory, which sealed methods
    may read) is hidden like the default one. Before, only the default cache was denied, so a project-local
    ``--cache-dir .cache`` was open to the method (the scored fleet's future flights)."""
    import shutil

    project = tmp_path / "project"
    project.mkdir()
    local = project / "cache"
    shutil.copytree(cache_dir, local)  # the module's products: loaded, not rebuilt
    (local / "labels.csv").write_text("flight_id,onset_internal_leakage\n0,3\n")
    monkeypatch.chdir(project)
    monkeypatch.setenv("FUELHM_BENCH_CACHE", str(tmp_path / "elsewhere"))  # the default cache is another folder
    ev = prepare_evaluation(tiny(), fidelity="surrogate", knowledge_size=KnowledgeSize.small(), cache_dir=local)
    assert ev.cache_dir == local
    log = tmp_path / "spy.log"
    outcome = run_in_env(Spy(dirs=(str(local), str(project))), ev, log_path=log, timeout_s=120)
    assert outcome.ok, outcome.message
    if outcome.sandbox.startswith("no file-system restriction"):
        pytest.skip(f"the file system is not sealed here: {outcome.sandbox}")
    found = log.read_text()
    assert "SPY FOUND: []" in found, found[-2000:]


def test_fit_time_is_measured_by_the_harness(evaluation):
    """The method's process reported its own fit time, and a method rewrote it (0.0001 s for 3 s of work)."""
    outcome = run_in_env(ForgesFitTime(seconds=0.5), evaluation, timeout_s=120)
    assert outcome.ok, outcome.message
    assert outcome.fit_seconds >= 0.5


def test_earlier_output_folders_in_the_working_directory_are_hidden(evaluation, cache_dir, tmp_path, monkeypatch):
    """The working directory is readable (it is on the import path), and an earlier run's output there held
    ground truth: an adversarial probe read a leaderboard report's delays.csv (fault onsets) and older results
    stores, and scored 100. Folders marked as fuelhm-bench output are now hidden too, wherever they sit."""
    from fuelhm_bench.benchmark.harness import earlier_outputs
    from fuelhm_bench.io.outputs import MANIFEST

    project = tmp_path / "project"
    old = project / "runs" / "old-board" / "paper_2012-v3"
    old.mkdir(parents=True)
    (project / "runs" / "old-board" / MANIFEST).write_text("paper_2012-v3\n")
    (old / "delays.csv").write_text("unit_id,onset_internal_leakage\n0,3\n")
    (project / "notes").mkdir()
    (project / "notes" / "mine.csv").write_text("a\n1\n")  # not an output: stays readable
    assert earlier_outputs(project) == [project / "runs" / "old-board"]
    monkeypatch.chdir(project)
    monkeypatch.setenv("FUELHM_BENCH_CACHE", str(cache_dir))
    log = tmp_path / "spy.log"
    outcome = run_in_env(Spy(dirs=(str(project),)), evaluation, log_path=log, timeout_s=120)
    assert outcome.ok, outcome.message
    if outcome.sandbox.startswith("no file-system restriction"):
        pytest.skip(f"the file system is not sealed here: {outcome.sandbox}")
    found = log.read_text()
    assert "SPY FOUND: []" in found, found[-2000:]
    from submissions import _hunt

    assert any("delays.csv" in f for f in _hunt([str(project)]))  # the probe finds it when nothing is sealed


def test_a_method_module_inside_a_hidden_folder_is_refused_first(tmp_path, monkeypatch):
    """``--out .`` with the method's module in the working directory: the output folder is hidden from sealed
    methods, so the module could not be imported there. The run is refused before any data is built, naming
    the module, the folder and the option (before: every scenario's data were built, then "No module named")."""
    from fuelhm_bench.benchmark.leaderboard import evaluation_config, run_board

    (tmp_path / "mine.py").write_text("from fuelhm_baselines.trivial import NullMethod as Mine\n")
    monkeypatch.chdir(tmp_path)
    config = evaluation_config(["mine:Mine"], "paper_2012", scale=0.1, fidelity="surrogate")
    lines = []
    with pytest.raises(ParameterError) as info:
        run_board(config, tmp_path, log=lines.append)
    message = str(info.value)
    assert "mine:Mine" in message and str(tmp_path / "mine.py") in message and "--out" in message
    assert not (tmp_path / "results.sqlite").exists() and lines == []
    with pytest.raises(ParameterError, match="--cache-dir"):  # the same for a cache holding the module
        run_board(config, tmp_path / "results", cache_dir=tmp_path, log=lines.append)
    assert not (tmp_path / "results").exists()


def test_a_denied_file_access_says_what_the_sandbox_allows(evaluation, tmp_path, monkeypatch):
    """A method writing beside its module gets its PermissionError with a hint at the sandbox's rules
    (before: the bare PermissionError, which reads like a bug of the user's machine)."""
    project = tmp_path / "project"
    project.mkdir()
    (project / "writes_beside.py").write_text(
        "from pathlib import Path\nfrom fuelhm_baselines.trivial import NullMethod\n"
        "class WritesBeside(NullMethod):\n"
        "    def _fit(self, healthy, *, knowledge, raw_flights, rng):\n"
        "        (Path(__file__).parent / 'cache.bin').write_bytes(b'x')\n")
    monkeypatch.chdir(project)
    outcome = run_in_env("writes_beside:WritesBeside", evaluation, timeout_s=120)
    if outcome.sandbox.startswith("no file-system restriction"):
        pytest.skip(f"the file system is not sealed here: {outcome.sandbox}")
    assert outcome.status == "error"
    assert "PermissionError" in outcome.message and "write only its scratch directory" in outcome.message
    assert not (project / "cache.bin").exists()


def test_row_labels_travel_once_and_every_row_arrives_whole(evaluation, monkeypatch):
    """decide_values sends the row labels with the first row and again only when they change;
    the sealed process rebuilds each Series with the right labels and values."""
    from submissions import EchoesRow

    from fuelhm_bench.taxonomy import OBSERVATION_COLUMNS

    sent = []
    with SealedMethod(EchoesRow(), limits={"wall_s": 60.0}) as m:
        m.fit(evaluation.fit_indicators)
        rows = evaluation.calibration_indicators[list(OBSERVATION_COLUMNS)]
        rows = rows[rows["unit_id"] == rows["unit_id"].iloc[0]].head(3)
        m.start_unit(rows["unit_id"].iloc[0])
        original = m._send
        monkeypatch.setattr(m, "_send", lambda op, payload, phase: (sent.append((op, dict(payload))),
                                                                     original(op, payload, phase))[1])
        labels = tuple(OBSERVATION_COLUMNS)
        at = OBSERVATION_COLUMNS.index("flight_index")

        def values(i, f):  # row i of the table, as flight f
            v = rows.iloc[i].tolist()
            v[at] = f
            return v

        for f in range(3):
            d = m.decide_values(labels, values(f, f))
            assert not d.alarm and d.score == pytest.approx(float(rows.iloc[f]["I0"]) + 1000.0 * f)
        # a Series with other labels (reversed) in between, then the first labels again
        other = pd.Series(values(0, 3), index=list(OBSERVATION_COLUMNS), dtype=object)[list(reversed(OBSERVATION_COLUMNS))]
        d = m.decide(other)
        assert d.alarm and d.score == pytest.approx(float(rows.iloc[0]["I0"]) + 3000.0)
        d = m.decide_values(labels, values(1, 4))
        assert not d.alarm and d.score == pytest.approx(float(rows.iloc[1]["I0"]) + 4000.0)
    with_labels = [p for op, p in sent if op == "decide" and "row_index" in p]
    assert [op for op, _ in sent] == ["decide"] * 5 and len(with_labels) == 3  # first, other, first again


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux /proc")
def test_the_system_paths_leave_out_the_hosts_secrets():
    """``/etc`` is readable entry by entry, without the password hashes, sudo rules or SSH host keys."""
    from fuelhm_bench.methods.sandbox import HOST_SECRETS, SYSTEM_READABLE, _inside, _readable_around

    readable, listable = _readable_around(SYSTEM_READABLE, list(HOST_SECRETS))
    for secret in HOST_SECRETS:
        assert not any(_inside(r, secret) for r in readable), secret
    assert "/etc" in listable and "/etc" not in readable
    assert os.path.realpath("/etc/passwd") in readable and "/usr" in readable


def test_a_method_cannot_read_the_hosts_secrets():
    """A sealed method reads ordinary configuration in /etc but not /etc/shadow. Before, /etc was readable
    whole, and a harness run as root (as CI is) let its methods read the password hashes."""
    import pandas as pd

    from fuelhm_bench.methods.sandbox import SealedFailure, SealedMethod
    from submissions import ReadsHostFiles

    with SealedMethod(ReadsHostFiles(), limits={"wall_s": 60.0}) as m:
        with pytest.raises(SealedFailure) as info:
            m.fit(pd.DataFrame({"I0": [0.0]}))
        sandbox = m.sandbox
    text = str(info.value)
    assert "passwd ok" in text and "listing ok" in text, text
    if sandbox.startswith("no file-system restriction"):
        pytest.skip(f"the file system is not sealed here: {sandbox}")
    if os.path.exists("/etc/shadow"):
        assert "shadow denied PermissionError" in text, text


def test_a_method_cannot_read_the_environment_of_the_harness(tmp_path):
    """The harness's environment (an automated run's tokens) is out of a sealed method's reach: the
    harness is not dumpable and the method has no capability (a harness run as root gave it
    CAP_SYS_PTRACE). Before, a method read /proc/<harness>/environ and could print it to its log."""
    import subprocess

    tests = os.path.dirname(os.path.abspath(__file__))
    code = ("import sys\n"
            f"sys.path.insert(0, {tests!r})\n"
            "import pandas as pd\n"
            "from fuelhm_bench.methods.sandbox import SealedFailure, SealedMethod\n"
            "from submissions import ReadsEnvirons\n"
            "with SealedMethod(ReadsEnvirons(), limits={'wall_s': 60.0}) as m:\n"
            "    try:\n"
            "        m.fit(pd.DataFrame({'I0': [0.0]}))\n"
            "    except SealedFailure as exc:\n"
            "        print(exc)\n"
            "    print('SANDBOX', m.sandbox)\n")
    env = {**os.environ, "FUELHM_TEST_SECRET": "s3cr3t"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=180,
                         cwd=tmp_path)
    assert "ENVIRONS readable" in out.stdout, out.stdout + out.stderr
    readable = int(out.stdout.split("ENVIRONS readable ")[1].split()[0])
    assert readable >= 1  # its own (/proc/self), so the scan itself worked
    assert "secret 0" in out.stdout, out.stdout
