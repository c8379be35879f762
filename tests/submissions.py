"""Misbehaving and spying submissions for the sealed-harness tests (a light module: the sealed process imports it).

Each class is what an outside researcher (or an attacker) might submit; the harness must turn every one
into a row with a status and a one-line message, and the spies must find no ground truth.
"""

from __future__ import annotations

import contextlib
import gc
import inspect
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from fuelhm_bench.methods import BaseMethod, Decision
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, INDICATOR_NAMES


class IdleCurrent(BaseMethod):
    """Alarms when I0 leaves its healthy band; blames null-bias drift."""

    def __init__(self, *, a=4.0):
        self.a = a

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        self.mu_, self.sd_ = healthy["I0"].mean(), healthy["I0"].std()

    def _decide(self, row):
        z = 0.0 if np.isnan(row["I0"]) else abs(row["I0"] - self.mu_) / self.sd_
        return Decision(score=z, alarm=z > self.a, guilt=np.eye(7)[1] if z > self.a else np.zeros(7))


class Raises(IdleCurrent):
    def _decide(self, row):
        if row["flight_index"] == 3:
            raise RuntimeError("boom at flight 3")
        return super()._decide(row)


class Hangs(IdleCurrent):
    def _decide(self, row):
        time.sleep(3600)


class NaNScore(IdleCurrent):
    def _decide(self, row):
        return Decision(score=float("nan"), alarm=False)


class NotADecision:
    """Duck-typed method (no BaseMethod) whose decide returns a float."""

    def fit(self, healthy, *, knowledge=None, random_state=None):
        return self

    def start_unit(self, unit_id):
        pass

    def decide(self, row):
        return 0.5


class Exits(IdleCurrent):
    def _decide(self, row):
        os._exit(7)


class SysExit(IdleCurrent):
    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        sys.exit(0)


class Segfaults(IdleCurrent):
    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        os.kill(os.getpid(), signal.SIGSEGV)


class RaisesInInit(IdleCurrent):
    def __init__(self, *, a=4.0):
        raise ValueError("cannot construct")


class Spins(IdleCurrent):
    """Burns CPU in fit."""

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        x = 0
        while True:
            x += 1


class Hogs(IdleCurrent):
    """Allocates 3 GiB in fit."""

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        self.block_ = np.ones(3 * 1024 ** 3 // 8)


class Chatty(IdleCurrent):
    """Prints megabytes and starts a child that would outlive the run."""

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        super()._fit(healthy, knowledge=knowledge, raw_flights=raw_flights, rng=rng)
        proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
        self.orphan_ = proc.pid
        print(f"ORPHAN {proc.pid}", file=sys.stderr, flush=True)
        sys.stdout.write("x" * 4_000_000)
        sys.stdout.flush()


class Daemonizes(IdleCurrent):
    """Leaves a daemon behind: a double fork with ``setsid``, out of its process group (probe4)."""

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        super()._fit(healthy, knowledge=knowledge, raw_flights=raw_flights, rng=rng)
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.setsid()
            daemon = os.fork()
            if daemon == 0:
                time.sleep(600)
                os._exit(0)
            os.write(write, str(daemon).encode())
            os._exit(0)
        os.waitpid(pid, 0)
        print(f"DAEMON {os.read(read, 32).decode()}", file=sys.stderr, flush=True)


class OpensSockets(IdleCurrent):
    """Tries an IPv4 UDP socket (data off the machine, probe4), an IPv6 one, and a Unix socket pair."""

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        import socket

        super()._fit(healthy, knowledge=knowledge, raw_flights=raw_flights, rng=rng)
        for name, family, kind in (("UDP4", socket.AF_INET, socket.SOCK_DGRAM),
                                   ("UDP6", socket.AF_INET6, socket.SOCK_DGRAM),
                                   ("TCP4", socket.AF_INET, socket.SOCK_STREAM)):
            try:
                with socket.socket(family, kind) as s:
                    if kind == socket.SOCK_DGRAM:
                        s.sendto(b"labels?", ("127.0.0.1", 9) if family == socket.AF_INET else ("::1", 9))
                print(name, "open", file=sys.stderr, flush=True)
            except OSError as exc:
                print(name, "refused", type(exc).__name__, file=sys.stderr, flush=True)
        a, b = socket.socketpair()
        a.sendall(b"x")
        print("UNIX", "ok" if b.recv(1) == b"x" else "broken", file=sys.stderr, flush=True)
        a.close()
        b.close()


class Peeks(IdleCurrent):
    """Fails unless every row holds exactly the observation columns."""

    def _decide(self, row):
        names = (*INDICATOR_NAMES, *EXTENDED_INDICATOR_NAMES)
        allowed = {"flight_id", "unit_id", "flight_index", *names, *(f"{n}_valid" for n in names)}
        if set(row.index) != allowed:
            raise AssertionError(f"unexpected columns {set(row.index) ^ allowed}")
        return super()._decide(row)


_GROUND_TRUTH = ("episode_truth", "schedule", "onset_", "intensity_", "ActuationLoopEnv", "UnitSchedule",
                 "max_intensity")


def _hunt(start_dirs, pids=()) -> list[str]:
    """Everything a submission can reach that smells of ground truth."""
    found = []
    frame = inspect.currentframe()
    while frame is not None:  # the call stack, every local and global of every frame
        for scope in (frame.f_locals, frame.f_globals):
            for name, value in list(scope.items()):
                if type(value).__name__ in ("ActuationLoopEnv", "EnvEvaluation", "UnitSchedule"):
                    found.append(f"frame {frame.f_code.co_name}: {name}")
        frame = frame.f_back
    for obj in gc.get_objects():  # every object of the process
        kind = type(obj).__name__
        if kind in ("ActuationLoopEnv", "EnvEvaluation", "UnitSchedule", "SurrogateModel"):
            found.append(f"gc: {kind}")
        elif kind == "DataFrame" and any(str(c).startswith(("onset_", "intensity_", "max_intensity_"))
                                         for c in getattr(obj, "columns", [])):
            found.append("gc: a labels table")
    for module in ("fuelhm_bench.envs.actuation_loop", "fuelhm_bench.benchmark.harness"):
        if module in sys.modules:
            found.append(f"module {module} is loaded")
    for root in start_dirs:  # files: the cache, the output folder, the parent's working directory, /tmp
        try:
            for dirpath, _dirs, files in os.walk(root):
                for f in files:
                    if f.endswith((".parquet", ".sqlite", ".json", ".csv")):
                        try:
                            text = Path(dirpath, f).read_bytes()[:2_000_000]
                        except OSError:
                            continue
                        if b"onset_" in text or b"intensity_" in text:
                            found.append(f"file {dirpath}/{f}")
        except OSError:
            continue
    for pid in {os.getppid(), *pids}:  # the parent process's memory (the zygote's), and the harness's
        with contextlib.suppress(OSError):  # unreadable memory is what the sandbox promises
            with open(f"/proc/{pid}/mem", "rb") as mem:
                mem.read(1)
            found.append(f"memory of process {pid} readable")
    return found


class ForgesFitTime(IdleCurrent):
    """Spends ``seconds`` of CPU in ``fit`` and rewrites the fit time its sealed process reports (probe4)."""

    def __init__(self, *, a=4.0, seconds=0.5):
        self.a = a
        self.seconds = seconds

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        super()._fit(healthy, knowledge=knowledge, raw_flights=raw_flights, rng=rng)
        child = next((o for o in gc.get_objects() if type(o).__name__ == "_Child"), None)
        if child is not None:
            original = child.reply

            def reply(**data):
                if "wall_s" in data:
                    data.update(wall_s=0.0001, cpu_s=0.0001)
                return original(**data)

            child.reply = reply
        t, self.spins_ = time.process_time(), 0
        while time.process_time() - t < self.seconds:  # CPU-bound work the harness must see
            self.spins_ += 1


class Spy(IdleCurrent):
    """Walks its call stack and the heap, reads files and the parent's memory, looking for the ground truth.

    It alarms on every flight if it finds anything, and stores what it found in its guilt (so the
    harness can see it): a clean run is all-zero guilt with no alarm.
    """

    def __init__(self, *, a=4.0, dirs=(), pids=()):
        self.a = a
        self.dirs = dirs
        self.pids = pids

    def _fit(self, healthy, *, knowledge, raw_flights, rng):
        super()._fit(healthy, knowledge=knowledge, raw_flights=raw_flights, rng=rng)
        self.found_ = _hunt(self.dirs, self.pids)
        print("SPY FOUND:", self.found_, file=sys.stderr, flush=True)

    def _decide(self, row):
        if row["flight_index"] == 0:
            self.found_ += _hunt(())
        if self.found_:
            return Decision(score=float(len(self.found_)), alarm=True, guilt=np.eye(7)[0])
        return Decision(score=0.0, alarm=False)


class EchoesRow(IdleCurrent):
    """Scores a flight by what its row holds: ``score = I0 + 1000 * flight_index``, and alarms when the
    row's labels are not the observation columns (so a test sees what arrived in the sealed process)."""

    def _decide(self, row):
        from fuelhm_bench.taxonomy import OBSERVATION_COLUMNS

        odd = tuple(row.index) != OBSERVATION_COLUMNS
        return Decision(score=float(row["I0"]) + 1000.0 * float(row["flight_index"]), alarm=odd,
                        guilt=np.full(7, 1 / 7) if odd else np.zeros(7))


class ReadsHostFiles:
    """Tries to read the host's password hashes and an ordinary configuration file, then fails in ``fit``
    saying what it could read (``/etc/shadow`` is readable by a harness run as root)."""

    def fit(self, table, *, knowledge=None, random_state=None, raw_flights=None):
        said = []
        for name, what in (("/etc/shadow", "shadow"), ("/etc/passwd", "passwd")):
            try:
                with open(name, "rb") as f:
                    f.read(1)
                said.append(f"{what} ok")
            except OSError as exc:
                said.append(f"{what} denied {type(exc).__name__}")
        try:
            os.listdir("/etc")
            said.append("listing ok")
        except OSError:
            said.append("listing denied")
        raise RuntimeError("HOST " + "; ".join(said))

    def start_unit(self, unit_id):
        """Never reached: ``fit`` always raises."""

    def decide(self, row):
        return Decision(score=0.0, alarm=False, guilt=np.zeros(7))


class ReadsEnvirons:
    """Reads every ``/proc/<pid>/environ`` it can, then fails in ``fit`` saying how many it read and how
    many hold the marker ``FUELHM_TEST_SECRET`` (a token in the environment of an automated run)."""

    def fit(self, table, *, knowledge=None, random_state=None, raw_flights=None):
        readable = found = 0
        for pid in os.listdir("/proc"):
            if not pid.isdigit():
                continue
            try:
                with open(f"/proc/{pid}/environ", "rb") as f:
                    data = f.read()
            except OSError:
                continue
            readable += 1
            found += b"FUELHM_TEST_SECRET=" in data
        raise RuntimeError(f"ENVIRONS readable {readable} secret {found}")

    def start_unit(self, unit_id):
        """Never reached: ``fit`` always raises."""

    def decide(self, row):
        return Decision(score=0.0, alarm=False, guilt=np.zeros(7))
