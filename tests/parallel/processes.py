"""Processes that meet at a coordinator (`jax.distributed.initialize`), for the several-process
tests: a free port, and the commands run together until all exit or one fails."""

import os
import socket
import subprocess
import tempfile
import time


def free_port() -> int:
    """A TCP port on localhost that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def run_together(cmds, env, cwd, timeout: float = 600) -> list[tuple[str, str]]:
    """Start every command at once; where one fails, kill the others (they would wait at a
    collective), likewise after `timeout` seconds; assert each exited 0 (the message: the
    failed one's stderr and the others'). Returns each one's (stdout, stderr), read from files
    (a pipe's buffer, full, would stall a process that writes much)."""
    with tempfile.TemporaryDirectory() as folder:
        files = [(open(os.path.join(folder, f"{i}.out"), "w+"),
                  open(os.path.join(folder, f"{i}.err"), "w+")) for i in range(len(cmds))]
        procs = [subprocess.Popen(cmd, env=env, cwd=cwd, stdout=out, stderr=err, text=True)
                 for cmd, (out, err) in zip(cmds, files)]
        end = time.monotonic() + timeout
        try:
            while any(p.poll() is None for p in procs) and time.monotonic() < end:
                if any(p.poll() not in (None, 0) for p in procs):
                    break
                time.sleep(0.2)
        finally:
            for p in procs:
                if p.poll() is None:
                    p.kill()
                p.wait()
        outs = []
        for out, err in files:
            out.seek(0)
            err.seek(0)
            outs.append((out.read(), err.read()))
            out.close()
            err.close()
    for i, p in enumerate(procs):
        assert p.returncode == 0, (i, outs[i][1][-3000:],
                                   [e[-3000:] for j, (_, e) in enumerate(outs) if j != i])
    return outs
