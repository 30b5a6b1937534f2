"""Engine worker process: `python -m impactval._worker PARENT_PID` (started by impactval.executor).

Reads length-prefixed pickled jobs `(spec, scene, settings)` on stdin, writes length-prefixed pickled
`ImpactResult`s on stdout, until stdin closes. Dies with its parent: `PR_SET_PDEATHSIG` (Linux) and
a thread polling the parent pid (everywhere). Engines' own prints go to /dev/null so they cannot
corrupt the protocol or the parent's terminal. SIGINT is ignored: the parent decides what a Ctrl-C
means and kills its workers itself.
"""
from __future__ import annotations

import os
import pickle
import signal
import struct
import sys
import threading
import time

_HEADER = struct.Struct("!Q")
#: written once on stdout after the imports: the worker is ready for jobs
READY = b"R"


def _preload(spec: str) -> None:
    """Import the adapter of `spec` and its engine module before reporting ready (a failure is left to the job)."""
    if not spec:
        return
    try:
        import importlib
        import importlib.util

        from impactval.engines.base import adapter_class

        module = getattr(adapter_class(spec), "module", None)
        if isinstance(module, str) and module and importlib.util.find_spec(module) is not None:
            importlib.import_module(module)
    except Exception:  # noqa: BLE001 - the job itself reports an unloadable engine
        pass


def _die_with_parent(parent_pid: int) -> None:
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)          # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        pass

    def watch() -> None:
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)
            time.sleep(0.5)

    if os.getppid() != parent_pid:                      # the parent died before prctl took effect
        os._exit(1)
    threading.Thread(target=watch, daemon=True).start()


def _read(fh, n: int) -> bytes | None:
    data = fh.read(n)
    return data if data is not None and len(data) == n else None


def main() -> None:
    parent_pid = int(sys.argv[1]) if len(sys.argv) > 1 else os.getppid()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent(parent_pid)
    extra = os.environ.get("IMPACTVAL_WORKER_SYS_PATH")
    if extra:
        sys.path[:] = [p for p in extra.split(os.pathsep)] + [p for p in sys.path if p not in extra.split(os.pathsep)]
    proto_in = os.fdopen(os.dup(0), "rb")          # buffered: read(n) returns n bytes or EOF
    proto_out = os.fdopen(os.dup(1), "wb")
    devnull = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(devnull, fd)
    os.close(devnull)
    from impactval.executor import execute_job

    _preload(sys.argv[2] if len(sys.argv) > 2 else "")
    proto_out.write(READY)          # the parent starts a job's clock here: start-up is not charged to a job
    proto_out.flush()
    while True:
        head = _read(proto_in, _HEADER.size)
        if head is None:
            return
        body = _read(proto_in, _HEADER.unpack(head)[0])
        if body is None:
            return
        spec, scene, settings = pickle.loads(body)
        result = execute_job(spec, scene, settings)
        out = pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)
        proto_out.write(_HEADER.pack(len(out)) + out)
        proto_out.flush()


if __name__ == "__main__":
    main()
