"""Run an untrusted method in a sealed process: its own interpreter, limits, a log, no ground truth.

The isolation model (also in docs/methods.md):

* **Own process, from a clean zygote.** The method runs in its own Python
  process, in its own session and process group, with the working directory and
  ``HOME`` set to an empty scratch directory and a scrubbed environment. The
  process is forked from this process's zygote (:mod:`fuelhm_bench.methods._zygote`:
  an interpreter *started* with the same scrubbed environment, which imports the
  harness's dependencies once and never receives scenario data); without
  ``fork`` (or with ``FUELHM_BENCH_ZYGOTE=0``) it is a fresh interpreter
  (``python -m fuelhm_bench.methods._sealed_child``). Nothing of the caller's
  memory (environment, fault schedule, labels) exists in it.
* **Only what a method may see, over a pipe.** The caller sends the healthy
  training tables, the published knowledge and then one observation row per
  flight; the child answers with plain JSON (never pickle), which the caller
  validates. A method that declares ``needs_raw`` (the child reports it at
  start-up) also receives raw flights over the same pipe, as binary numpy
  buffers (pickle protocol 5 of float64 arrays, caller to child only), one
  flight at a time: with each decision the flight's full-rate samples, and
  during ``fit`` the healthy training flights *pulled* by the child one by one
  (the child asks for the next flight when the method's iterator advances),
  so neither process ever holds more than one raw flight of the stream. The
  raw flights come from the caller; the child never reads the simulation
  cache (denied) and sees no labels.
* **File system.** Where the kernel offers Landlock (Linux >= 5.13, no
  privilege needed) the child restricts itself before importing the method: it
  may read the Python installation, the directories on its import path that do
  not contain a denied path (the simulation cache, the output folder), the
  method's own source directory and system directories (``/etc`` without the
  host's secrets, :data:`HOST_SECRETS`); it may write only its
  scratch directory; TCP ``bind``/``connect`` and signals to processes outside
  its sandbox are refused (Landlock ABI >= 4 and >= 6). Without Landlock the
  child still never holds ground truth in memory, but the file system is not
  restricted (:attr:`SealedMethod.sandbox` says which).
* **Limits.** Wall time (enforced by the caller), CPU time (``RLIMIT_CPU``) and
  address space (``RLIMIT_AS``) per method (:class:`Limits`). Stdout and stderr
  go to a log file cut at ``log_kb``. When the run ends, the whole process
  group is killed: no orphans.

Every failure is reported as a :class:`SealedFailure` with a ``status``
(``"error"``, ``"crash"``, ``"timeout"``, ``"cpu_limit"``, ``"memory"``,
``"invalid"``) and a one-line ``message`` naming the phase.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fuelhm_bench.errors import ParameterError, show_value

__all__ = ["Limits", "SealedFailure", "SealedMethod", "locate_module", "source_hash"]

_MAX_REPLY = 256 * 1024 * 1024
_STARTUP_S = 300.0  # start-up of the interpreter and the harness's own imports (not the method's time)


@dataclass(frozen=True)
class Limits:
    """Resource limits of one sealed method run.

    Parameters
    ----------
    wall_s : float, default=900.0
        Wall-clock time of the whole run (start, fit, every decision) [s], > 0.
    cpu_s : float or None, default=None
        CPU time of the method's process [s], > 0; None: ``wall_s``.
    memory_mb : float, default=4096.0
        Address-space limit of the method's process [MiB], >= 256.
    log_kb : float, default=1024.0
        Size at which the method's stdout/stderr log is cut [KiB], > 0.
    """

    wall_s: float = 900.0
    cpu_s: float | None = None
    memory_mb: float = 4096.0
    log_kb: float = 1024.0

    def __post_init__(self) -> None:
        for name, low in (("wall_s", 0.0), ("cpu_s", 0.0), ("memory_mb", 256.0), ("log_kb", 0.0)):
            value = getattr(self, name)
            if name == "cpu_s" and value is None:
                continue
            high = LIMIT_MAX[name]
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            if not ok or value < low or (low == 0.0 and value <= 0) or value > high:
                bound = f"in [{low:g}, {high:g}]" if low else f"in (0, {high:g}]"
                raise ParameterError(f"The '{name}' parameter of Limits must be a finite number {bound}. "
                                     f"Got {value!r} instead.")

    @property
    def cpu_limit_s(self) -> float:
        """The effective CPU-time limit [s]."""
        return float(self.wall_s if self.cpu_s is None else self.cpu_s)

    @classmethod
    def coerce(cls, value: Any, owner: str = "limits") -> Limits:
        """A :class:`Limits` from None, a Limits or a mapping of its fields (errors name ``owner``)."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, dict):
            unknown = sorted(set(value) - {"wall_s", "cpu_s", "memory_mb", "log_kb"})
            if unknown:
                raise ParameterError(f"{owner}: unknown limit '{unknown[0]}'. Allowed: wall_s, cpu_s, memory_mb, "
                                     f"log_kb.")
            try:
                return cls(**{k: (float(v) if isinstance(v, int) and not isinstance(v, bool) else v)
                              for k, v in value.items()})
            except ParameterError as exc:
                raise ParameterError(f"{owner}: {exc}") from None
        raise ParameterError(f"{owner} must be a mapping of wall_s, cpu_s, memory_mb, log_kb. Got {value!r} instead.")


#: Largest value of each limit: 30 days of wall or CPU time, 1 TiB of address space, 1 GiB of log
#: (beyond these, clocks and ``setrlimit`` overflow; a larger limit means none in practice).
LIMIT_MAX = {"wall_s": 30 * 86400.0, "cpu_s": 30 * 86400.0, "memory_mb": 1024.0 * 1024.0, "log_kb": 1024.0 * 1024.0}


class SealedFailure(Exception):
    """A sealed method failed; ``status`` says how and the message (one line) where."""

    def __init__(self, status: str, message: str):
        super().__init__(message)
        self.status = status
        self.message = message


def locate_module(name: str, path: list[str] | None = None) -> Path | None:
    """File of module ``name`` (``a.b.c``) *without executing any code*.

    The top-level name is looked up by every import finder (installed, editable
    or on the path; finding a spec runs no module code), the rest through the
    package directories.
    """
    import importlib.util
    from importlib.machinery import PathFinder

    search = list(sys.path if path is None else path)
    if os.getcwd() not in search:
        search.insert(0, os.getcwd())
    parts = name.split(".")
    try:
        spec = PathFinder.find_spec(parts[0], search) or importlib.util.find_spec(parts[0])
    except (ImportError, ValueError):
        return None
    for i in range(1, len(parts)):
        if spec is None or not spec.submodule_search_locations:
            return None
        spec = PathFinder.find_spec(".".join(parts[:i + 1]), list(spec.submodule_search_locations))
    if spec is None or spec.origin in (None, "built-in", "frozen"):
        return None
    return Path(spec.origin)


def _package_root(name: str) -> Path | None:
    origin = locate_module(name.split(".")[0])
    if origin is None:
        return None
    return origin.parent if origin.name == "__init__.py" else origin


_HASH_READ_BYTES = 256 * 1024 * 1024  # beyond this many bytes read, further files count by (size, mtime)


def source_hash(entry_point: str) -> str:
    """SHA-256 of the code of ``module:Class`` and the files shipped with it ('' when it cannot be found).

    What a method's results depend on is rarely one file: a package's other modules, a base class in
    a sibling module, a weights or thresholds file read through ``__file__``. So the hash covers,
    for a module inside a package, every file beneath its top-level package directory; for a
    top-level single-file module, every file of its directory (not the sub-directories). Bytecode
    caches and hidden entries (``.git``, ``.venv``...) are skipped; files beyond the first 256 MiB
    read count by size and modification time. A result store keys evaluations on it, so editing any
    of these files makes a resumed run evaluate the method again.
    """
    import hashlib

    name = entry_point.partition(":")[0]
    origin = locate_module(name.split(".")[0])
    if origin is None or not origin.is_file():
        return ""
    if origin.name == "__init__.py":
        root = origin.parent
        files = [p for p in root.rglob("*") if not any(part.startswith(".") or part == "__pycache__"
                                                       for part in p.relative_to(root).parts)]
    else:
        root = origin.parent
        files = [p for p in root.iterdir() if not p.name.startswith(".")]
    digest = hashlib.sha256()
    budget = _HASH_READ_BYTES
    for path in sorted(files, key=lambda p: p.relative_to(root).as_posix()):
        try:
            if not path.is_file() or path.suffix == ".pyc":
                continue
            stat = path.stat()
            digest.update(path.relative_to(root).as_posix().encode() + b"\0")
            if stat.st_size <= budget:
                budget -= stat.st_size
                digest.update(hashlib.sha256(path.read_bytes()).digest())
            else:
                digest.update(f"{stat.st_size}:{stat.st_mtime_ns}".encode())
        except OSError:
            continue  # unreadable or gone: not part of what the method can load either
    return digest.hexdigest()


def _imported_roots() -> list[str]:
    """Roots of the top-level packages imported in this process (editable installs live outside sys.path).

    A method instance built here (a notebook, a script) may import packages that an editable install
    serves through an import hook from a source folder: the sealed process must be able to read them.
    """
    roots = []
    for name, module in list(sys.modules.items()):
        origin = getattr(module, "__file__", None) if "." not in name else None
        if origin:
            p = Path(origin)
            roots.append(str(p.parent if p.name == "__init__.py" else p))
    return roots


#: System paths a sealed method may read (shared libraries, configuration, ``/proc``, random numbers).
SYSTEM_READABLE = ("/usr", "/lib", "/lib64", "/etc", "/proc", "/sys", "/dev/urandom", "/dev/null", "/dev/zero")
#: Host secrets beneath :data:`SYSTEM_READABLE` that no method reads: password hashes (readable by a harness
#: run as root, whose owner read bit needs no capability), sudo rules, SSH host keys, TLS private keys,
#: old passwords, systemd credentials. Denied like the simulation cache (:func:`_readable_around`).
HOST_SECRETS = ("/etc/shadow", "/etc/shadow-", "/etc/gshadow", "/etc/gshadow-", "/etc/sudoers", "/etc/sudoers.d",
                "/etc/ssh", "/etc/ssl/private", "/etc/security/opasswd", "/etc/credstore",
                "/etc/credstore.encrypted")


def _python_roots() -> list[str]:
    roots = {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix,
             str(Path(sys.executable).resolve().parent)}
    import sysconfig

    for key in ("stdlib", "platstdlib", "purelib", "platlib"):
        p = sysconfig.get_paths().get(key)
        if p:
            roots.add(p)
    return sorted(roots)


def _inside(root: str, path: str) -> bool:
    """Whether ``path`` is ``root`` or lies beneath it (both resolved)."""
    return path == root or path.startswith(root.rstrip(os.sep) + os.sep)


def _readable_around(roots, deny: list[str]) -> tuple[list[str], list[str]]:
    """The Landlock read rules for ``roots`` minus the ``deny`` hierarchies (all paths resolved there).

    A root inside a denied path is dropped. A root that *contains* a denied path (a working
    directory holding the output folder, a home directory holding the simulation cache) is not
    dropped whole, which would make a method's own module unimportable: its entries are granted one
    by one, descending only along the way to the denied path, and the directories on that way are
    returned as *listable* (their names may be listed, which Python's import system needs; no file
    beneath a denied path can be read). An entry whose resolved target (a symbolic link) lies in,
    or contains, a denied path is left out.

    Returns
    -------
    readable, listable : list of str
    """
    deny = [d.rstrip(os.sep) or os.sep for d in deny]
    readable: list[str] = []
    listable: list[str] = []

    def visit(path: str) -> None:
        try:
            real = str(Path(path).resolve())
        except (OSError, RuntimeError):
            return
        if any(_inside(d, real) for d in deny):
            return  # the denied path itself, or beneath it
        if not any(_inside(real, d) for d in deny):
            readable.append(real)
            return
        if not os.path.isdir(real):
            return
        listable.append(real)
        try:
            entries = sorted(os.scandir(real), key=lambda e: e.name)
        except OSError:
            return
        for entry in entries:
            visit(entry.path)

    for root in roots:
        visit(str(root))
    return list(dict.fromkeys(readable)), list(dict.fromkeys(listable))


def _import_path() -> list[str]:
    """The import path a sealed process gets: this process's working directory and ``sys.path``."""
    return [os.path.abspath(p) for p in ([os.getcwd()] + sys.path) if p]


def _sealed_env(scratch: str, path: list[str]) -> dict:
    """The scrubbed environment of a sealed process whose scratch directory is ``scratch``."""
    env = {k: v for k, v in os.environ.items() if k in ("PATH", "LANG", "LC_ALL", "LC_CTYPE", "TZ", "SYSTEMROOT")}
    env.update({"HOME": scratch, "TMPDIR": scratch, "PYTHONPATH": os.pathsep.join(dict.fromkeys(path)),
                "PYTHONDONTWRITEBYTECODE": "1", "PYTHONHASHSEED": "0", "MPLBACKEND": "Agg",
                "MPLCONFIGDIR": scratch, "NUMBA_CACHE_DIR": scratch,
                "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})
    return env


class _LogPump(threading.Thread):
    """Copy the child's stdout/stderr to a file, cut at ``limit`` bytes (the rest is drained and dropped)."""

    def __init__(self, stream, path: Path | None, limit: int):
        super().__init__(daemon=True)
        self.stream, self.path, self.limit = stream, path, limit
        self.dropped = 0

    def run(self) -> None:
        written = 0
        sink = None
        if self.path is not None:
            try:
                sink = open(self.path, "wb")
            except OSError:  # no log then, but the pipe is still drained: a full pipe would block the method
                sink = None
        try:
            while True:
                chunk = self.stream.read1(65536) if hasattr(self.stream, "read1") else self.stream.read(65536)
                if not chunk:
                    break
                if sink is not None and written < self.limit:
                    part = chunk[: self.limit - written]
                    sink.write(part)
                    written += len(part)
                    self.dropped += len(chunk) - len(part)
                else:
                    self.dropped += len(chunk)
        except (OSError, ValueError):
            pass
        finally:
            if sink is not None:
                with contextlib.suppress(OSError):
                    if self.dropped:
                        sink.write(f"\n[log cut at {self.limit} bytes; {self.dropped} more bytes dropped]\n".encode())
                    sink.close()


def _raw_payload(flight: Any) -> dict:
    """A RawFlight as plain float64 arrays (pickled as binary buffers over the pipe)."""
    from fuelhm_bench.methods.raw import RAW_SIGNALS

    out = {name: np.ascontiguousarray(getattr(flight, name), dtype=np.float64) for name in RAW_SIGNALS}
    unit = flight.unit_id
    out["unit_id"] = unit.item() if isinstance(unit, np.generic) else unit
    out["flight_index"] = int(flight.flight_index)
    return out


class _ForkedProcess:
    """A sealed process forked by the zygote, seen from the harness as the part of ``Popen`` it uses.

    The zygote is its parent (it reaps it and writes its wait status to ``status_fd``); its
    stdout/stderr come through ``stdout``; ``pid`` is also its process group.
    """

    def __init__(self, pid: int, stdout, status_fd: int):
        self.pid = pid
        self.stdout = stdout
        self.returncode: int | None = None
        self._status_fd = status_fd

    def wait(self, timeout: float | None = None) -> int | None:
        """The exit code (negative: killed by that signal), as ``Popen.wait``; ``TimeoutExpired`` after ``timeout``."""
        import select

        if self._status_fd < 0:
            return self.returncode
        ready, _, _ = select.select([self._status_fd], [], [], timeout)
        if not ready:
            raise subprocess.TimeoutExpired(f"sealed process {self.pid}", timeout)
        data = os.read(self._status_fd, 64)
        os.close(self._status_fd)
        self._status_fd = -1
        try:
            self.returncode = os.waitstatus_to_exitcode(int(data))
        except ValueError:  # the zygote ended first: the process was killed with it
            self.returncode = -signal.SIGKILL
        return self.returncode

    def __del__(self):
        if self._status_fd >= 0:
            with contextlib.suppress(OSError):
                os.close(self._status_fd)


class _Zygote:
    """The harness's side of :mod:`fuelhm_bench.methods._zygote` (one per harness process)."""

    def __init__(self, env: dict):
        self._scratch = tempfile.TemporaryDirectory(prefix="fuelhm-zygote-")
        mine, theirs = socket.socketpair()
        env = {**env, "HOME": self._scratch.name, "TMPDIR": self._scratch.name,
               "MPLCONFIGDIR": self._scratch.name, "NUMBA_CACHE_DIR": self._scratch.name}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fuelhm_bench.methods._zygote", str(theirs.fileno())],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=self._scratch.name,
            env=env, pass_fds=(theirs.fileno(),), start_new_session=True, close_fds=True)
        theirs.close()
        self.owner = os.getpid()
        self._sock = mine
        self._buffer = b""
        self._ready = False
        self.lock = threading.Lock()

    def _line(self, timeout: float) -> dict:
        self._sock.settimeout(timeout)
        while b"\n" not in self._buffer:
            chunk = self._sock.recv(65536)
            if not chunk:
                raise OSError("the zygote ended")
            self._buffer += chunk
        line, _, self._buffer = self._buffer.partition(b"\n")
        return json.loads(line.decode("utf-8"))

    def alive(self) -> bool:
        return self.owner == os.getpid() and self.proc.poll() is None

    def spawn(self, scratch: str, env: dict, child_sock: socket.socket) -> _ForkedProcess | None:
        """Fork a sealed process (None when the zygote cannot: the caller starts an interpreter)."""
        log_r, log_w = os.pipe()
        status_r, status_w = os.pipe()
        try:
            with self.lock:
                if not self._ready:
                    if self._line(_STARTUP_S).get("status") != "ready":
                        raise OSError("the zygote did not start")
                    self._ready = True
                request = json.dumps({"scratch": scratch, "env": env}).encode("utf-8")
                self._sock.settimeout(_STARTUP_S)
                socket.send_fds(self._sock, [request], [child_sock.fileno(), log_w, status_w])
                reply = self._line(_STARTUP_S)
            pid = int(reply["pid"])
        except (OSError, ValueError, KeyError, TypeError):
            os.close(log_r)
            os.close(status_r)
            self.close()
            return None
        finally:
            os.close(log_w)
            os.close(status_w)
        return _ForkedProcess(pid, os.fdopen(log_r, "rb"), status_r)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._sock.close()
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(5)
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        self._scratch.cleanup()


_ZYGOTE: dict[str, _Zygote] = {}
_ZYGOTE_LOCK = threading.Lock()


def _zygote(env: dict) -> _Zygote | None:
    """This process's zygote, started on first use (None where ``fork`` or descriptor passing is missing).

    ``env`` is the scrubbed environment of a sealed process (the zygote gets its own scratch
    directory as ``HOME``/``TMPDIR``). The zygote is a fresh interpreter: whenever it is started,
    it holds nothing of this process's memory.
    """
    if not (hasattr(os, "fork") and hasattr(socket, "send_fds") and sys.platform.startswith("linux")):
        return None
    if os.environ.get("FUELHM_BENCH_ZYGOTE", "1") == "0":
        return None
    with _ZYGOTE_LOCK:
        z = _ZYGOTE.get("z")
        if z is not None and not z.alive():
            if z.owner == os.getpid():
                z.close()
            z = None
        if z is None:
            try:
                z = _ZYGOTE["z"] = _Zygote({k: v for k, v in env.items()
                                            if k not in ("HOME", "TMPDIR", "MPLCONFIGDIR", "NUMBA_CACHE_DIR")})
            except OSError:
                return None
        return z


def protect_process() -> bool:
    """Make this process unreadable to sealed methods: not dumpable (``prctl(PR_SET_DUMPABLE, 0)``).

    A harness process holds the user's environment (tokens of an automated run, say) and the scored
    fleet. A process of the same user may read another's ``/proc/<pid>/environ``, ``mem`` and
    ``fd`` unless that one is not dumpable; a sealed method also has no capability left
    (``_sealed_child``), which covers a harness run as root. Core dumps of this process are off
    too. ``/proc/<pid>/cmdline`` and ``stat`` stay readable (they hold nothing secret: seeds
    to hide are kept in the results store, docs/methods.md section 7). Idempotent; returns whether it
    applied (Linux only).
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl(4, 0, 0, 0, 0) == 0  # PR_SET_DUMPABLE
    except (OSError, AttributeError):
        return False


def prestart_zygote() -> None:
    """Start this process's zygote now (it imports its modules while the caller builds data)."""
    _zygote(_sealed_env(tempfile.gettempdir(), _import_path()))


@atexit.register
def _stop_zygote() -> None:
    z = _ZYGOTE.pop("z", None)
    if z is not None and z.owner == os.getpid():
        z.close()


class SealedMethod:
    """A method running in its own sealed process; the caller drives it call by call.

    Parameters
    ----------
    method : str or BaseMethod
        ``"module:Class"`` (imported only in the sealed process) or an unfitted
        instance (sent by pickle: its class is re-imported there).
    params : dict, optional
        Hyperparameters of ``module:Class`` (typed values).
    shared_params : dict, optional
        Hyperparameters applied when the method has them.
    limits : Limits or dict, optional
        Resource limits.
    log_path : path-like, optional
        Where the method's stdout/stderr go (cut at ``limits.log_kb``); None: dropped.
    deny : sequence of path-like, default=()
        Paths the method must not read (simulation cache, output folder). An
        import-path directory that contains one stays readable around it
        (:func:`_readable_around`): a method's module in the working directory
        imports even when the output folder is inside it.
    zygote : bool, default=True
        Fork the sealed process from this process's zygote (a clean interpreter
        with the harness's dependencies imported, see
        :mod:`fuelhm_bench.methods._zygote`) instead of starting a fresh
        interpreter; the isolation is the same. Ignored where ``fork`` is not
        available.

    Examples
    --------
    >>> with SealedMethod("fuelhm_bench.methods:NullMethod") as m:  # doctest: +SKIP
    ...     m.fit(table)
    """

    def __init__(self, method: Any, *, params: dict | None = None, shared_params: dict | None = None,
                 limits: Limits | dict | None = None, log_path=None, deny=(), zygote: bool = True):
        self.method = method
        self.params = dict(params or {})
        self.shared_params = dict(shared_params or {})
        self.limits = Limits.coerce(limits, "limits")
        self.log_path = None if log_path is None else Path(log_path)
        self.deny = [str(Path(d).resolve()) for d in deny if d]
        self.name = method if isinstance(method, str) else type(method).__name__
        self.zygote = bool(zygote)
        self.info: dict = {}
        self.sandbox = "not started"
        self._proc = None
        self._conn = None
        self._pump = None
        self._scratch = None
        self._deadline = math.inf
        self._row_index = (None, ())  # (the last row's Index, its labels as a tuple): one conversion per table
        self._labels_sent = None  # the row labels the sealed process holds (decide_values)

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> dict:
        """Start the process, import and build the method; returns ``{"repr", "params", "sandbox"}``."""
        from multiprocessing.connection import Connection

        protect_process()  # this process (the harness) holds what a method must not read
        self._scratch = tempfile.TemporaryDirectory(prefix="fuelhm-sealed-")
        scratch = self._scratch.name
        parent_sock, child_sock = socket.socketpair()
        path = _import_path()
        env = _sealed_env(scratch, path)
        self._deadline = time.monotonic() + _STARTUP_S  # the interpreter and the harness's imports
        zygote = _zygote(env) if self.zygote else None
        self._proc = zygote.spawn(scratch, env, child_sock) if zygote is not None else None
        if self._proc is None:  # no zygote here (not POSIX, disabled, or it could not start): a fresh interpreter
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "fuelhm_bench.methods._sealed_child", str(child_sock.fileno())],
                stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, cwd=scratch, env=env,
                pass_fds=(child_sock.fileno(),), start_new_session=True, close_fds=True)
        child_sock.close()
        self._conn = Connection(parent_sock.detach())
        self._labels_sent = None
        self._pump = _LogPump(self._proc.stdout, self.log_path, int(self.limits.log_kb * 1024))
        self._pump.start()
        readable = list(_python_roots())
        module = self.method.partition(":")[0] if isinstance(self.method, str) else type(self.method).__module__
        for name in (module, "fuelhm_bench"):
            root = _package_root(name)
            if root is not None:
                readable.append(str(root))
        readable += [p for p in path if os.path.isdir(p)]
        if not isinstance(self.method, str):  # an instance: the packages its module needed are imported here
            readable += [r for r in _imported_roots() if not any(self._contains(d, r) for d in self.deny)]
        readable, listable = _readable_around(dict.fromkeys([*readable, *SYSTEM_READABLE]),
                                              [*self.deny, *HOST_SECRETS])
        method = self.method
        if not isinstance(method, str):  # by value when its class is not importable (a notebook, a script)
            try:
                import cloudpickle

                module = sys.modules.get(type(method).__module__)
                by_value = (module is not None and module.__name__ != "__main__"
                            and locate_module(module.__name__) is None)  # built in memory: no file to import
                if by_value:
                    cloudpickle.register_pickle_by_value(module)
                try:
                    method = cloudpickle.dumps(method)
                finally:
                    if by_value:
                        cloudpickle.unregister_pickle_by_value(module)
            except ImportError:
                import pickle

                method = pickle.dumps(method)
        ready = self._receive("start-up of the sealed process")
        if ready.get("status") != "ready":
            self.close()
            raise SealedFailure("crash", f"{self.name}: the sealed process did not start.")
        self._deadline = time.monotonic() + self.limits.wall_s  # the method's clock starts here
        init = {"method": method, "params": self.params, "shared_params": self.shared_params,
                "cpu_s": self.limits.cpu_limit_s, "memory_bytes": int(self.limits.memory_mb * 1024 * 1024),
                "readable": readable, "listable": listable, "scratch": scratch, "sys_path": path}
        self.info = self._call("start", init, phase="import and construction")
        self.sandbox = self.info.get("sandbox", "")
        return self.info

    @staticmethod
    def _contains(root: str, path: str) -> bool:
        return _inside(str(Path(root).resolve()), path)

    def close(self) -> None:
        """Kill the method's whole process group and remove its scratch directory."""
        if self._proc is not None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(self._proc.pid, signal.SIGKILL)
            with contextlib.suppress(subprocess.TimeoutExpired):
                self._proc.wait(5)
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._pump is not None:
            self._pump.join(5)
        if self._scratch is not None:
            self._scratch.cleanup()
            self._scratch = None

    def __enter__(self) -> SealedMethod:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def pid(self) -> int | None:
        """Process id (= process group id) of the sealed process."""
        return None if self._proc is None else self._proc.pid

    # ------------------------------------------------------------------ the calls
    @property
    def needs_raw(self) -> bool:
        """True when the started method declares ``needs_raw`` (reported by the sealed process)."""
        return bool(self.info.get("needs_raw", False))

    def fit(self, healthy_indicators, *, knowledge=None, random_state=None, raw_flights=None) -> dict:
        """``method.fit`` in the sealed process; returns ``{"wall_s", "cpu_s", "raw_flights_read"}`` measured there.

        ``raw_flights``: an iterable of :class:`~fuelhm_bench.methods.raw.RawFlight`, pulled one flight
        at a time by the sealed process while the method iterates over ``fit(raw_flights=...)``.
        """
        payload = {"table": healthy_indicators, "knowledge": knowledge, "random_state": random_state,
                   "raw_stream": raw_flights is not None}
        if raw_flights is None:
            return self._call("fit", payload, phase="fit")
        flights = iter(raw_flights)
        self._send("fit", payload, "fit")
        while True:
            reply = self._receive("fit")
            if reply.get("request") != "raw_next":
                return self._checked(reply, "fit")
            flight = next(flights, None)
            self._send("raw", None if flight is None else _raw_payload(flight), "fit")

    def scores(self, indicators) -> np.ndarray:
        """Scores of ``run_table(method, indicators)`` (unit by unit, causal), validated finite floats."""
        reply = self._call("scores", {"table": indicators}, phase="calibration scores")
        values = reply.get("scores")
        if not isinstance(values, list) or len(values) != len(indicators):
            raise SealedFailure("invalid", f"{self.name} returned {len(values) if isinstance(values, list) else 0} "
                                           f"calibration scores for {len(indicators)} healthy flights.")
        try:
            return np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            raise SealedFailure("invalid", f"{self.name} returned non-numeric calibration scores.") from None

    def start_unit(self, unit_id) -> None:
        """``method.start_unit`` in the sealed process."""
        self._call("start_unit", {"unit_id": unit_id}, phase=f"start_unit({show_value(unit_id)})")

    def decide(self, row, *, raw=None, where: str = "decide"):
        """``method.decide(row)``; returns a validated :class:`~fuelhm_bench.methods.Decision`.

        ``raw``: the flight's :class:`~fuelhm_bench.methods.raw.RawFlight`, for a method with
        ``needs_raw`` (sent as binary float64 buffers).
        """
        if hasattr(row, "index") and hasattr(row, "tolist"):  # a Series travels as plain tuples (cheap to pickle)
            if row.index is not self._row_index[0]:  # rows of one table share their Index; a str Index iterates slowly
                self._row_index = (row.index, tuple(row.index))
            return self.decide_values(self._row_index[1], row.tolist(), raw=raw, where=where)
        return self._decide({"row": row}, raw, where)

    def decide_values(self, labels: tuple, values, *, raw=None, where: str = "decide"):
        """``method.decide(pandas.Series(values, index=labels, dtype=object))``, the Series built in
        the sealed process; returns a validated :class:`~fuelhm_bench.methods.Decision`.

        The labels travel only when they are not the tuple sent last (compared by identity: pass one
        tuple object for every row of a table), so a row costs its values alone.
        """
        payload = {"row_values": tuple(values)}
        if labels is not self._labels_sent:
            payload["row_index"] = labels
            self._labels_sent = labels
        return self._decide(payload, raw, where)

    def _decide(self, payload: dict, raw, where: str):
        from fuelhm_bench.methods.decision import Decision, decision_problem

        if raw is not None:
            payload["raw"] = _raw_payload(raw)
        reply = self._call("decide", payload, phase=where)
        try:
            decision = Decision(score=float(reply["score"]), alarm=bool(reply["alarm"]),
                                guilt=np.asarray(reply["guilt"], dtype=np.float64))
        except Exception as exc:  # noqa: BLE001 - the reply is untrusted
            raise SealedFailure("invalid", f"{self.name} returned an invalid decision in {where}: "
                                           f"{type(exc).__name__}: {exc}") from None
        problem = decision_problem(decision)
        if problem is not None:
            raise SealedFailure("invalid", f"{self.name} returned an invalid decision in {where}: {problem}.")
        return decision

    def call(self, op: str, payload: dict, *, phase: str, timeout_s: float | None = None) -> dict:
        """A custom operation of the child (the conformance checks); ``timeout_s`` restarts the clock."""
        if timeout_s is not None:
            self._deadline = time.monotonic() + float(timeout_s)
        return self._call(op, payload, phase=phase)

    def _send(self, op: str, payload: Any, phase: str) -> None:
        if self._proc is None or self._conn is None:
            raise SealedFailure("error", f"{self.name}: the sealed process is not running ({phase}).")
        try:
            self._conn.send((op, payload))
        except (BrokenPipeError, ConnectionResetError, OSError):
            raise self._dead(phase) from None

    def _call(self, op: str, payload: dict, *, phase: str) -> dict:
        self._send(op, payload, phase)
        return self._checked(self._receive(phase), phase)

    def _checked(self, reply: dict, phase: str) -> dict:
        if reply.get("request") is not None:
            raise SealedFailure("invalid", f"{self.name}: unexpected request {str(reply['request'])[:40]!r} "
                                           f"during {phase}.")
        if reply.get("status", "ok") != "ok":
            status = reply.get("status") if reply.get("status") in ("error", "memory", "invalid") else "error"
            message = str(reply.get("message", "")).splitlines()[0][:500] if reply.get("message") else ""
            raise SealedFailure(status, f"{self.name} failed in {phase}: {message}")
        return reply

    def _receive(self, phase: str) -> dict:
        remaining = self._deadline - time.monotonic()
        try:
            ready = remaining > 0 and self._conn.poll(remaining)
        except (OSError, EOFError):
            ready = True
        if not ready:
            self.close()
            limit = self.limits.wall_s if phase != "start-up of the sealed process" else _STARTUP_S
            raise SealedFailure("timeout", f"{self.name} did not finish within {limit:g} s "
                                           f"(stopped during {phase}).")
        try:
            data = self._conn.recv_bytes(_MAX_REPLY)
        except (EOFError, OSError):
            raise self._dead(phase) from None
        try:
            reply = json.loads(data.decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            raise SealedFailure("invalid", f"{self.name}: unreadable reply during {phase}.") from None
        if not isinstance(reply, dict):
            raise SealedFailure("invalid", f"{self.name}: unreadable reply during {phase}.")
        return reply

    def _dead(self, phase: str) -> SealedFailure:
        code = None
        with contextlib.suppress(subprocess.TimeoutExpired):
            code = self._proc.wait(5)
        self.close()
        if code is not None and code < 0:
            sig = -code
            name = signal.Signals(sig).name if sig in signal.Signals._value2member_map_ else str(sig)
            if sig == signal.SIGXCPU:
                return SealedFailure("cpu_limit", f"{self.name} exceeded its CPU-time limit of "
                                                  f"{self.limits.cpu_limit_s:g} s during {phase}.")
            return SealedFailure("crash", f"{self.name} was killed by signal {name} during {phase}.")
        return SealedFailure("crash", f"{self.name} exited (exit code {code}) during {phase} "
                                      f"without reporting (os._exit or a crash).")
