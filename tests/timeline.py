"""Run a command and log, every 0.5 s, the wall time and the CPU time (user + sys) of its whole process tree.

A developer's tool for issue 10 (where a command's wall time goes: idle cores, serial phases)::

    python tests/timeline.py fuelhm-bench paper --out /tmp/p --cache-dir "$(mktemp -d)" > timeline.log

Each line: ``<wall s> cpu <tree CPU s> cores <CPU used per wall second since the last line>``; the
command's stderr lines come time-stamped (``<wall s> ERR ...``; ``paper`` prints its stages there
when stderr is not a terminal). At the end, the CPU of each process of the tree as last seen
(``proc <first seen s> <CPU s> <pid> <command>``, those above 0.5 s; a process ending between two
polls loses its last half-second), then the wall time and the CPU of the finished tree.
Linux only (reads ``/proc``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time


def descendants(root: int) -> dict[int, list[str]]:
    """``{pid: fields of /proc/<pid>/stat after the command name}`` of ``root``'s descendants alive now."""
    children: dict[int, list[tuple[int, list[str]]]] = {}
    for p in os.listdir("/proc"):
        if not p.isdigit():
            continue
        try:
            with open(f"/proc/{p}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append((int(p), fields))
    out, stack = {}, [root]
    while stack:
        for pid, fields in children.get(stack.pop(), []):
            if pid not in out:
                out[pid] = fields
                stack.append(pid)
    return out


def cpu_s(fields: list[str], *, reaped: bool) -> float:
    """User + sys CPU seconds of a process (``reaped``: with those of its reaped children)."""
    return sum(int(fields[i]) for i in ((11, 12, 13, 14) if reaped else (11, 12))) / os.sysconf("SC_CLK_TCK")


def command_line(pid: int) -> str:
    """The process's command line ("" once it has ended)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().replace(b"\0", b" ").decode(errors="replace").strip()
    except OSError:
        return ""


def tree_cpu(root: int) -> float:
    """CPU seconds (user + sys, and those of reaped children) of ``root``'s descendants alive now."""
    return sum(cpu_s(fields, reaped=True) for fields in descendants(root).values())


def main(argv: list[str]) -> int:
    t0 = time.time()
    proc = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True)

    def echo() -> None:
        for line in proc.stderr:
            print(f"{time.time() - t0:7.2f} ERR {line.rstrip()[:150]}", flush=True)

    threading.Thread(target=echo, daemon=True).start()
    last_cpu = last_t = 0.0
    seen: dict[int, tuple[float, float, str]] = {}  # pid: (first seen, CPU, command)
    while proc.poll() is None:
        time.sleep(0.5)
        tree, now = descendants(os.getpid()), time.time() - t0
        cpu = sum(cpu_s(fields, reaped=True) for fields in tree.values())
        for pid, fields in tree.items():
            first, _, known = seen.get(pid, (now, 0.0, ""))
            seen[pid] = (first, cpu_s(fields, reaped=False), known or command_line(pid))
        print(f"{now:7.2f} cpu {cpu:7.2f} cores {(cpu - last_cpu) / (now - last_t):4.2f}", flush=True)
        last_cpu, last_t = cpu, now
    small = [v for v in seen.values() if v[1] <= 0.5]
    for pid, (first, pcpu, cmd) in sorted(seen.items(), key=lambda kv: kv[1][0]):
        if pcpu > 0.5:
            print(f"proc {first:7.2f} {pcpu:7.2f} {pid} {cmd[:120]}")
    print(f"proc {len(small)} more processes, {sum(v[1] for v in small):.2f} s CPU in all")
    r = os.times()
    print(f"wall {time.time() - t0:.2f} children user {r.children_user:.2f} sys {r.children_system:.2f}")
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
