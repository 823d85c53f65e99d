"""A real Dask cluster as subprocesses on 127.0.0.1: one `dask scheduler` and N `dask worker`
(for the batch tests and benchmark, which must run against an external scheduler as a cluster would)."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
START_TIMEOUT_S = 120


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def repo_env() -> dict[str, str]:
    """The environment with this checkout first on the path, so that workers import its code."""
    return {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}


@contextlib.contextmanager
def external_cluster(workers: int = 1, log: Path | None = None) -> Iterator[str]:
    """Start the scheduler and ``workers`` x `dask worker --nthreads 1`; yield the address; always kill them."""
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    with open(log or os.devnull, "wb") as out:
        spawn = {"stdout": out, "stderr": subprocess.STDOUT, "env": repo_env(), "start_new_session": True}
        procs = [
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "distributed.cli.dask_scheduler",
                    "--host",
                    "127.0.0.1",
                    "--port",
                    str(port),
                    "--dashboard-address",
                    ":0",
                ],
                **spawn,
            )
        ]
        try:
            for _ in range(workers):
                procs.append(
                    subprocess.Popen(
                        [
                            sys.executable,
                            "-m",
                            "distributed.cli.dask_worker",
                            address,
                            "--nthreads",
                            "1",
                            "--host",
                            "127.0.0.1",
                            "--no-dashboard",
                            "--death-timeout",
                            "60",
                        ],
                        **spawn,
                    )
                )
            with Client(address, timeout=START_TIMEOUT_S) as client:
                client.wait_for_workers(workers, timeout=START_TIMEOUT_S)
            yield address
        finally:
            for proc in reversed(procs):
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=60)
