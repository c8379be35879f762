"""The zygote of :mod:`fuelhm_bench.methods.sandbox` (``python -m fuelhm_bench.methods._zygote FD``).

A sealed method process used to be a fresh interpreter that imported numpy,
pandas, scikit-learn and the package before the method's own imports: about
0.4-2 s of CPU per evaluation. The zygote pays that once: it is itself a fresh
interpreter (started, not forked, from the harness, with the same scrubbed
environment as a sealed process and no inherited file descriptor), imports the
harness's trusted dependencies (:data:`PRELOAD`, never a method's module), and
then, on request, **forks** one sealed process per method run.

What the zygote holds is what it was started with: its imports and the spawn
requests (a scratch directory, an environment, three file descriptors). It
never receives scenario data, training tables, observations or labels: those
travel later, harness to sealed process, over the socket whose end the zygote
passes on without reading it. A forked sealed process therefore starts in the
same state as a fresh interpreter would after the same imports, and then does
exactly what one does (:mod:`fuelhm_bench.methods._sealed_child`): its own
session, working directory and ``HOME`` in its scratch directory, its limits,
Landlock, the method.

Protocol on the control socket (harness side: ``sandbox._Zygote``): the zygote
sends ``ready``; each request is one JSON message ``{"scratch", "env"}`` with
three descriptors attached (the sealed process's end of its socket, the write
end of its log pipe, the write end of its status pipe); the reply is
``{"pid": N}``. When the sealed process ends, the zygote (its parent) reaps it
and writes its wait status (decimal) to the status pipe. The zygote is the
subreaper of what the methods start (Linux): a daemon that left its method's
process group (``setsid``) is re-parented to it and killed when a sealed process
ends. When the harness closes the control socket, the zygote kills the process
groups of the sealed processes still running, and every orphan, and exits.
"""

from __future__ import annotations

import array
import contextlib
import importlib
import json
import os
import selectors
import signal
import socket
import sys

#: Modules imported by the zygote before any fork: the harness's own dependencies and the
#: libraries most methods use. Trusted code only: a method's module is imported in the sealed process.
PRELOAD = ("numpy", "pandas", "scipy.stats", "scipy.linalg", "sklearn.base", "sklearn.utils.validation",
           "sklearn.covariance", "threadpoolctl", "fuelhm_bench.methods", "fuelhm_bench.methods.loading",
           "fuelhm_bench.methods.base", "fuelhm_bench.methods.decision", "fuelhm_bench.methods.raw",
           "fuelhm_bench.diagnosis")

_MAX_REQUEST = 1 << 20


def _preload() -> None:
    for name in PRELOAD:
        try:
            importlib.import_module(name)
        except ImportError:  # an optional library missing: the sealed process imports what it needs itself
            continue


def _child(conn_fd: int, log_fd: int, scratch: str, env: dict, close: list[int]) -> None:
    """In the forked process: become a sealed process (never returns)."""
    code = 1
    try:
        os.setsid()  # its own session and process group, as start_new_session=True gives a started one
        signal.set_wakeup_fd(-1)
        for sig in (signal.SIGCHLD, signal.SIGINT, signal.SIGTERM, signal.SIGPIPE):
            signal.signal(sig, signal.SIG_DFL)
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)  # as a Python interpreter starts
        for fd in close:
            os.close(fd)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.dup2(log_fd, 1)
        os.dup2(log_fd, 2)
        os.close(null)
        os.close(log_fd)
        os.chdir(scratch)
        os.environ.clear()
        os.environ.update(env)
        import random
        import tempfile

        tempfile.tempdir = None  # TMPDIR is this process's scratch directory
        random.seed()  # a fresh interpreter seeds its global generators from the OS, so does every fork
        if "numpy" in sys.modules:
            sys.modules["numpy"].random.seed()
        importlib.invalidate_caches()  # modules written after the zygote started must be found
        from fuelhm_bench.methods import _sealed_child

        _sealed_child.main(["_sealed_child", str(conn_fd)])
        code = 0
    except BaseException:  # noqa: BLE001 - nothing may return into the zygote's loop
        import traceback

        traceback.print_exc()
    finally:
        os._exit(code)


def _await_session(pid: int, timeout_s: float = 5.0) -> None:
    """Wait until the forked process leads its own session (so the harness can kill its group at once)."""
    import time

    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        try:
            if os.getsid(pid) == pid:
                return
        except ProcessLookupError:
            return
        time.sleep(0.0005)


def _become_subreaper() -> bool:
    """Make this process the reaper of its orphaned descendants (Linux ``PR_SET_CHILD_SUBREAPER``).

    A method can leave its process group: a double fork with ``setsid`` makes a daemon that the
    harness's group kill misses. Its parent gone, the daemon becomes a child of the nearest subreaper:
    the zygote, which kills it when a sealed process ends (:func:`_kill_orphans`).
    """
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _own_children() -> list[int]:
    """The pids whose parent is this process (from ``/proc``)."""
    me, found = os.getpid(), []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat", "rb") as f:
                    ppid = int(f.read().rsplit(b")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
            if ppid == me:
                found.append(int(entry))
    return found


def _kill_orphans(children: dict[int, int]) -> None:
    """Kill this process's children that are not running sealed processes: what a method left behind.

    Repeated a few times: killing an orphan re-parents its own children here.
    """
    for _ in range(8):
        orphans = [pid for pid in _own_children() if pid not in children]
        if not orphans:
            return
        for pid in orphans:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
        for pid in orphans:
            with contextlib.suppress(ChildProcessError, OSError):
                os.waitpid(pid, 0)


def _reap(children: dict[int, int], orphans_too: bool = False) -> None:
    """Report the wait status of every ended sealed process on its status pipe; with ``orphans_too``, once one
    has ended, kill what the methods left behind (:func:`_kill_orphans`)."""
    ended = False
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            break
        if pid == 0:
            break
        fd = children.pop(pid, None)
        if fd is not None:
            ended = True
            with contextlib.suppress(OSError):  # the harness closed its end: nobody waits for this status
                os.write(fd, str(status).encode())
            os.close(fd)
    if ended and orphans_too:
        _kill_orphans(children)


def _drain(fd: int) -> None:
    """Read a non-blocking pipe until it is empty (the signal wake-up bytes carry no information)."""
    with contextlib.suppress(BlockingIOError):
        while os.read(fd, 4096):
            continue


def serve(control: socket.socket) -> None:
    """Answer spawn requests until the harness closes the control socket."""
    children: dict[int, int] = {}  # pid -> write end of its status pipe
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_r, False)
    os.set_blocking(wake_w, False)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the harness's to handle
    sel = selectors.DefaultSelector()
    sel.register(control, selectors.EVENT_READ, "control")
    sel.register(wake_r, selectors.EVENT_READ, "wake")
    subreaper = _become_subreaper()
    control.sendall(b'{"status": "ready"}\n')
    try:
        while True:
            for key, _ in sel.select():
                if key.data == "wake":
                    _drain(wake_r)
                    _reap(children, orphans_too=subreaper)
                    continue
                fds = array.array("i")
                try:
                    msg, ancdata, _flags, _addr = control.recvmsg(_MAX_REQUEST, socket.CMSG_LEN(3 * fds.itemsize))
                except InterruptedError:
                    continue
                if not msg:
                    return
                for level, kind, data in ancdata:
                    if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS:
                        fds.frombytes(data[: len(data) - (len(data) % fds.itemsize)])
                if len(fds) != 3:
                    for fd in fds:
                        os.close(fd)
                    control.sendall(b'{"error": "a request carries three descriptors"}\n')
                    continue
                conn_fd, log_fd, status_fd = fds
                request = json.loads(msg.decode("utf-8"))
                pid = os.fork()
                if pid == 0:
                    _child(conn_fd, log_fd, request["scratch"], request["env"],
                           [control.fileno(), sel.fileno(), wake_r, wake_w, status_fd, *children.values()])
                os.close(conn_fd)
                os.close(log_fd)
                _await_session(pid)
                children[pid] = status_fd
                control.sendall(json.dumps({"pid": pid}).encode() + b"\n")
                _reap(children)
    finally:
        for pid in list(children):  # the harness is gone: nothing it started survives
            with contextlib.suppress(ProcessLookupError, PermissionError):  # already gone
                os.killpg(pid, signal.SIGKILL)
        _reap(children)
        if subreaper:
            _kill_orphans({})


def main(argv: list[str]) -> None:
    control = socket.socket(fileno=int(argv[1]))
    _preload()
    serve(control)
    os._exit(0)


if __name__ == "__main__":
    main(sys.argv)
