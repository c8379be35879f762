"""The sealed process of :mod:`fuelhm_bench.methods.sandbox` (``python -m fuelhm_bench.methods._sealed_child FD``).

It limits itself (CPU time, address space; Landlock on the file system, TCP and
signals where the kernel offers it), builds the method, then answers the
caller's operations one at a time with JSON. Tracebacks go to stderr (the
method's log); replies carry one-line messages.
"""

from __future__ import annotations

import ctypes
import json
import os
import resource
import sys
import time
import traceback

# --------------------------------------------------------------------------- Landlock (linux/landlock.h)
_SYS_CREATE, _SYS_ADD_RULE, _SYS_RESTRICT = 444, 445, 446  # same numbers on x86_64 and aarch64
_READ = (1 << 0) | (1 << 2) | (1 << 3)  # EXECUTE, READ_FILE, READ_DIR
_LIST = 1 << 3  # READ_DIR only: a directory around a denied path (names listed, no file read)
#: Writable besides the scratch directory: POSIX semaphores (``sem_open``) live in /dev/shm, and every
#: ``multiprocessing`` lock needs one, even a thread pool's (joblib's threading backend, hence
#: scikit-learn's ``n_jobs``); without it such a method failed with PermissionError in fit.
_SHARED_MEMORY = [d for d in ("/dev/shm",) if os.path.isdir(d)]
_FILE_RIGHTS = (1 << 0) | (1 << 1) | (1 << 2) | (1 << 14) | (1 << 15)


class _RulesetAttr(ctypes.Structure):
    _fields_ = [("handled_access_fs", ctypes.c_uint64), ("handled_access_net", ctypes.c_uint64),
                ("scoped", ctypes.c_uint64)]


class _PathBeneath(ctypes.Structure):
    _pack_ = 1
    _fields_ = [("allowed_access", ctypes.c_uint64), ("parent_fd", ctypes.c_int32)]


def _landlock(readable: list[str], writable: list[str], listable: list[str] = ()) -> str:
    """Restrict this process; returns a description of the sandbox applied."""
    if not sys.platform.startswith("linux"):
        return "no file-system restriction (not Linux)"
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        abi = libc.syscall(_SYS_CREATE, None, ctypes.c_size_t(0), ctypes.c_uint32(1))
    except (OSError, AttributeError):
        abi = -1
    if abi < 1:
        return "no file-system restriction (Landlock unavailable)"
    handled = (1 << 13) - 1
    if abi >= 2:
        handled |= 1 << 13
    if abi >= 3:
        handled |= 1 << 14
    if abi >= 5:
        handled |= 1 << 15
    attr = _RulesetAttr(handled, 0b11 if abi >= 4 else 0, 0b11 if abi >= 6 else 0)
    size = 24 if abi >= 6 else (16 if abi >= 4 else 8)
    fd = libc.syscall(_SYS_CREATE, ctypes.byref(attr), ctypes.c_size_t(size), ctypes.c_uint32(0))
    if fd < 0:
        return "no file-system restriction (Landlock ruleset refused)"
    try:
        for paths, rights in ((readable, _READ), (writable, handled), (listable, _LIST)):
            for p in paths:
                try:
                    pfd = os.open(p, os.O_PATH | os.O_CLOEXEC)
                except OSError:
                    continue
                try:
                    allowed = rights & handled
                    if not os.path.isdir(p):
                        allowed &= _FILE_RIGHTS
                    rule = _PathBeneath(allowed, pfd)
                    libc.syscall(_SYS_ADD_RULE, ctypes.c_int(fd), ctypes.c_int(1), ctypes.byref(rule),
                                 ctypes.c_uint32(0))
                finally:
                    os.close(pfd)
        if libc.prctl(38, 1, 0, 0, 0) != 0:  # PR_SET_NO_NEW_PRIVS
            return "no file-system restriction (no_new_privs refused)"
        if libc.syscall(_SYS_RESTRICT, ctypes.c_int(fd), ctypes.c_uint32(0)) != 0:
            return "no file-system restriction (Landlock restrict_self refused)"
    finally:
        os.close(fd)
    extra = (", TCP" if abi >= 4 else "") + (", signals" if abi >= 6 else "")
    return f"landlock abi {abi}: file system{extra}"


# --------------------------------------------------------------------------- seccomp (linux/seccomp.h)
#: (audit architecture, socket syscall numbers) of the architectures the network filter knows.
_SECCOMP_ARCHES = {"x86_64": (0xC000003E, (41, 0x40000000 | 41)),  # native and x32 numbering
                   "aarch64": (0xC00000B7, (198,))}


class _SockFilter(ctypes.Structure):
    _fields_ = [("code", ctypes.c_uint16), ("jt", ctypes.c_uint8), ("jf", ctypes.c_uint8), ("k", ctypes.c_uint32)]


class _SockFprog(ctypes.Structure):
    _fields_ = [("len", ctypes.c_uint16), ("filter", ctypes.POINTER(_SockFilter))]


def _network_filter_program(machine: str) -> list[tuple[int, int, int, int]] | None:
    """The seccomp program refusing IPv4/IPv6 sockets (``EACCES``), or None for an unknown architecture.

    Landlock fences TCP ``bind``/``connect`` only; UDP stayed open and a probe sent data off the
    machine with ``sendto``. A sealed method needs no Internet socket (``multiprocessing`` and joblib
    use Unix sockets and pipes). System calls of another architecture (the 32-bit ``int 0x80`` entry on
    x86_64, whose ``socketcall`` would pass this filter) are refused too.
    """
    known = _SECCOMP_ARCHES.get(machine)
    if known is None:
        return None
    arch, numbers = known
    ld, jeq, ret = 0x20, 0x15, 0x06  # BPF_LD|BPF_W|BPF_ABS, BPF_JMP|BPF_JEQ|BPF_K, BPF_RET|BPF_K
    allow, deny = 0x7FFF0000, 0x00050000 | 13  # SECCOMP_RET_ALLOW, SECCOMP_RET_ERRNO | EACCES
    prog = [(ld, 0, 0, 4), (jeq, 1, 0, arch), (ret, 0, 0, deny), (ld, 0, 0, 0)]  # arch, then the call number
    # one test per socket number: on a match go to the domain test after them, else to the next one
    for i, nr in enumerate(numbers):
        left = len(numbers) - 1 - i
        prog.append((jeq, left, 0 if left else 3, nr))
    prog += [(ld, 0, 0, 16), (jeq, 2, 0, 2), (jeq, 1, 0, 10), (ret, 0, 0, allow), (ret, 0, 0, deny)]  # AF_INET(6)
    return prog


def _seccomp_no_inet() -> str:
    """Refuse IPv4/IPv6 sockets in this process and its children; returns what was applied ("" if nothing)."""
    import platform

    prog = _network_filter_program(platform.machine())
    if prog is None or not sys.platform.startswith("linux"):
        return ""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        filters = (_SockFilter * len(prog))(*[_SockFilter(*ins) for ins in prog])
        fprog = _SockFprog(len(prog), filters)
        if libc.prctl(38, 1, 0, 0, 0) != 0:  # PR_SET_NO_NEW_PRIVS (Landlock may have set it already)
            return ""
        if libc.prctl(22, 2, ctypes.byref(fprog), 0, 0) != 0:  # PR_SET_SECCOMP, SECCOMP_MODE_FILTER
            return ""
    except (OSError, AttributeError):
        return ""
    return "no IPv4/IPv6 sockets"


class _CapHeader(ctypes.Structure):
    _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]


class _CapData(ctypes.Structure):
    _fields_ = [("effective", ctypes.c_uint32), ("permitted", ctypes.c_uint32), ("inheritable", ctypes.c_uint32)]


def _drop_capabilities() -> str:
    """Drop every Linux capability of this process for good; returns what was done ("" if it had none).

    A harness run as root gives its sealed process root's capabilities, and with ``CAP_SYS_PTRACE``
    it could read ``/proc/<pid>/environ`` and the memory of the harness and of the user's other
    processes (ptrace access needs no capability only towards a process whose capabilities are a
    subset of the caller's). The securebits stop ``execve`` from granting them back to uid 0, the
    bounding and ambient sets are emptied, then the effective, permitted and inheritable sets.
    """
    if not sys.platform.startswith("linux"):
        return ""
    try:
        with open("/proc/self/status") as f:
            had = next((int(line.split()[1], 16) for line in f if line.startswith("CapEff:")), 0)
        if not had:
            return ""
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(28, 0x3, 0, 0, 0)  # PR_SET_SECUREBITS, SECBIT_NOROOT | SECBIT_NOROOT_LOCKED
        with open("/proc/sys/kernel/cap_last_cap") as f:
            last = int(f.read())
        for cap in range(last + 1):
            libc.prctl(24, cap, 0, 0, 0)  # PR_CAPBSET_DROP
        libc.prctl(47, 4, 0, 0, 0)  # PR_CAP_AMBIENT, PR_CAP_AMBIENT_CLEAR_ALL
        if libc.capset(ctypes.byref(_CapHeader(0x20080522, 0)), (_CapData * 2)()) != 0:  # _LINUX_CAPABILITY_VERSION_3
            return ""
    except (OSError, AttributeError, ValueError):
        return ""
    return "no capabilities"


# --------------------------------------------------------------------------- JSON helpers
def _json_value(v):
    import numpy as np

    if v is None or isinstance(v, (bool, str)):
        return v
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if isinstance(v, (list, tuple)):
        return [_json_value(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _json_value(x) for k, x in v.items()}
    return repr(v)


_SANDBOX_HINT = (" (the sealed process may read its import path, its package and the Python installation, and "
                 "write only its scratch directory, which is also $HOME and $TMPDIR: docs/methods.md section 7)")


def _one_line(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}".replace("\n", " ")[:400]
    if isinstance(exc, (PermissionError, FileNotFoundError)) and getattr(exc, "filename", None):
        text += _SANDBOX_HINT  # a file outside what the sandbox allows, or a path under the scratch $HOME
    return text


class _Child:
    def __init__(self, conn):
        self.conn = conn
        self.method = None
        self._index = {}
        self._row_index = None  # the labels of the rows (op_decide)

    def reply(self, **data) -> None:
        data.setdefault("status", "ok")
        self.conn.send_bytes(json.dumps(data, allow_nan=True).encode("utf-8"))

    # ------------------------------------------------------------------ operations
    def op_start(self, p: dict) -> None:
        import pickle

        cpu = max(1, int(p["cpu_s"] + 0.999))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))
        mem = int(p["memory_bytes"])
        resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        sys.path[:] = [x for x in p["sys_path"]] + [x for x in sys.path if x not in p["sys_path"]]
        import numpy  # noqa: F401 - imported before the sandbox closes the file system
        import pandas  # noqa: F401

        import fuelhm_bench.methods  # noqa: F401
        from fuelhm_bench.methods.loading import accepted_params, load_method

        # p["readable"] holds the system paths too (sandbox.SYSTEM_READABLE, without the host's secrets)
        sandbox = _landlock(p["readable"], [p["scratch"], "/dev/null", *_SHARED_MEMORY], p.get("listable", []))
        network = _seccomp_no_inet()
        sandbox += f"; {network}" if network else "; IPv4/IPv6 sockets not filtered (no seccomp here)"
        dropped = _drop_capabilities()
        sandbox += f"; {dropped}" if dropped else ""
        method = p["method"]
        if isinstance(method, str):  # shared params its constructor takes are passed to it
            self.method = load_method(method, p["params"], p["shared_params"])
        else:
            self.method = method if not isinstance(method, bytes) else pickle.loads(method)
            cls = type(self.method)
            if cls.__module__ not in sys.modules:  # a class built in memory by the caller: same module here
                import types

                module = types.ModuleType(cls.__module__)
                setattr(module, cls.__qualname__.split(".")[0], cls)
                sys.modules[cls.__module__] = module
        get_params = getattr(self.method, "get_params", None)
        params = get_params() if callable(get_params) else {}
        shared = {k: v for k, v in p["shared_params"].items() if k in params and k not in (p["params"] or {})}
        built = accepted_params(type(self.method), shared) if isinstance(method, str) else {}  # (constructor)
        late = {k: v for k, v in shared.items() if k not in built}
        if late:
            self.method.set_params(**late)
            params = get_params()
        self.reply(repr=repr(self.method)[:2000], params=_json_value(params),
                   shared_applied=sorted(shared), sandbox=sandbox,
                   needs_raw=bool(getattr(type(self.method), "needs_raw", False)))

    def _pull_raw(self, counter: list):
        """The raw training flights, asked from the caller one at a time as the method iterates."""
        from fuelhm_bench.methods.raw import RawFlight

        while True:
            self.reply(request="raw_next")
            op, payload = self.conn.recv()
            if op != "raw" or payload is None:
                return
            counter[0] += 1
            yield RawFlight(**payload)

    def op_fit(self, p: dict) -> None:
        t0, c0 = time.perf_counter(), time.process_time()
        counter = [0]
        kwargs = {"raw_flights": self._pull_raw(counter)} if p.get("raw_stream") else {}
        self.method.fit(p["table"], knowledge=p["knowledge"], random_state=p["random_state"], **kwargs)
        self.reply(wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0, raw_flights_read=counter[0])

    def op_scores(self, p: dict) -> None:
        from fuelhm_bench.methods.base import run_table

        scores = run_table(self.method, p["table"])["score"].to_numpy(dtype=float)
        self.reply(scores=[float(s) for s in scores])

    def op_start_unit(self, p: dict) -> None:
        self.method.start_unit(p["unit_id"])
        self.reply()

    def op_decide(self, p: dict) -> None:
        from fuelhm_bench.methods.decision import Decision, decision_problem

        if "row_values" in p:
            import pandas as pd

            if "row_index" in p:  # sent when it changes (SealedMethod.decide_values), kept until then
                index = self._index.get(p["row_index"])
                if index is None:
                    index = self._index[p["row_index"]] = pd.Index(p["row_index"])
                self._row_index = index
            row = pd.Series(p["row_values"], index=self._row_index, dtype=object)
        else:
            row = p["row"]
        if "raw" in p:
            from fuelhm_bench.methods.raw import RawFlight

            d = self.method.decide(row, raw=RawFlight(**p["raw"]))
        else:
            d = self.method.decide(row)
        if not isinstance(d, Decision):
            problem = decision_problem(d) or f"expected a Decision, got {type(d).__name__}"
            self.reply(status="invalid", message=problem)
            return
        self.reply(score=float(d.score), alarm=bool(d.alarm), guilt=[float(g) for g in d.guilt])

    def op_check(self, p: dict) -> None:
        from fuelhm_bench.methods.checks import _run_one_check

        if p["data"] is not None:  # sent with the first check, kept for the next ones
            self._check_data = p["data"]
        self.reply(**_run_one_check(self.method, p["name"], self._check_data))

    # ------------------------------------------------------------------ loop
    def serve(self) -> None:
        while True:
            try:
                op, payload = self.conn.recv()
            except (EOFError, OSError):
                return
            handler = getattr(self, f"op_{op}", None)
            try:
                if handler is None:
                    self.reply(status="error", message=f"unknown operation {op!r}")
                else:
                    handler(payload)
            except MemoryError as exc:
                traceback.print_exc()
                self.reply(status="memory", message=f"out of memory (address-space limit): {_one_line(exc)}")
            except SystemExit as exc:
                self.reply(status="error", message=f"SystemExit({exc.code!r}) raised")
            except BaseException as exc:  # noqa: BLE001 - the method is untrusted code
                traceback.print_exc()
                from fuelhm_bench.errors import MethodError

                status = "invalid" if isinstance(exc, MethodError) and op in ("decide", "scores") else "error"
                try:
                    self.reply(status=status, message=_one_line(exc))
                except (OSError, ValueError):
                    return
            sys.stdout.flush()
            sys.stderr.flush()


def main(argv: list[str]) -> None:
    from multiprocessing.connection import Connection

    conn = Connection(int(argv[1]))
    import numpy  # noqa: F401 - the harness's own imports, before the method's clock starts
    import pandas  # noqa: F401

    import fuelhm_bench.methods  # noqa: F401
    import fuelhm_bench.methods.loading  # noqa: F401

    child = _Child(conn)
    child.reply(status="ready")
    child.serve()
    os._exit(0)


if __name__ == "__main__":
    main(sys.argv)
