"""Progress of a run on stderr (issue 12): a live rich display on a terminal, one plain line per
job otherwise (CI logs). Presentation only; the runner calls `start`, `started`, `done`, `close`.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import Any, TextIO


def _fmt_s(s: float) -> str:
    s = max(0.0, s)
    return f"{s:.1f} s" if s < 60 else f"{int(s // 60)}:{int(s % 60):02d} min" if s < 3600 else \
        f"{int(s // 3600)}:{int(s % 3600 // 60):02d} h"


class PlainProgress:
    """One line per finished job: '[3/40] plate_steel / mujoco dt=1e-06: ok (0.21 s)', and every
    `heartbeat_s` [s] a 'still running' line for each job running that long (CI logs see it live)."""

    def __init__(self, stream: TextIO | None = None, heartbeat_s: float = 60.0) -> None:
        self.stream = stream or sys.stderr
        self.total = self.done_n = self.failed = 0
        self.t0 = time.monotonic()
        self._lock = threading.Lock()
        self.heartbeat_s = heartbeat_s
        self.running: dict[str, float] = {}
        self._next_beat: dict[str, float] = {}

    def start(self, total: int, reused: int) -> None:
        self.total, self.done_n, self.t0 = total, reused, time.monotonic()
        if reused:
            self._line(f"{reused} of {total} jobs reused from the store (--force recomputes them)")

    def started(self, label: str) -> None:
        with self._lock:
            now = time.monotonic()
            self.running[label] = now
            self._next_beat[label] = now + self.heartbeat_s

    def stopped(self, label: str) -> None:
        """The job's engine work ended (its row may still wait for the reference): no longer 'running'."""
        with self._lock:
            self.running.pop(label, None)
            self._next_beat.pop(label, None)

    def tick(self) -> None:
        """Called by the runner about twice a second: heartbeat lines for long jobs."""
        now = time.monotonic()
        with self._lock:
            due = [(lb, t) for lb, t in self.running.items() if now >= self._next_beat.get(lb, now + 1)]
            for lb, _ in due:
                self._next_beat[lb] = now + self.heartbeat_s
        for lb, t in due:
            self._line(f"  still running: {lb} ({_fmt_s(now - t)})")

    def done(self, label: str, row: dict[str, Any], seconds: float) -> None:
        with self._lock:
            self.running.pop(label, None)
            self._next_beat.pop(label, None)
            self.done_n += 1
            from impactval.reference.result import Status

            status = Status(row["status"])
            self.failed += status.failed
            self._line(f"[{self.done_n}/{self.total}] {label}: {_status_text(status, row)} ({seconds:.2f} s)")

    def note(self, text: str) -> None:
        self._line(text)

    def _line(self, text: str) -> None:
        print(text, file=self.stream, flush=True)

    def close(self) -> None:
        pass


class RichProgress(PlainProgress):
    """A rich live display: bar, done/total, failures, elapsed, ETA, and every running job with the
    time it has been running (so a 10-minute job visibly lives)."""

    def __init__(self, stream: TextIO | None = None) -> None:
        super().__init__(stream)
        from rich.console import Console
        from rich.live import Live

        self.console = Console(file=self.stream)
        self.reused = 0
        self.live = Live(console=self.console, refresh_per_second=4, transient=True,
                         get_renderable=self._render)

    def start(self, total: int, reused: int) -> None:
        super().start(total, reused)
        self.reused = reused
        self.live.start()

    def started(self, label: str) -> None:
        with self._lock:
            self.running[label] = time.monotonic()

    def tick(self) -> None:
        pass                            # the live display shows each running job's time

    def done(self, label: str, row: dict[str, Any], seconds: float) -> None:
        with self._lock:
            self.running.pop(label, None)
        from impactval.reference.result import Status

        status = Status(row["status"])
        if status != Status.OK:     # failures stay visible above the live display
            self.console.print(f"{label}: [bold red]{status}[/]: {row.get('message', '')}", highlight=False)
        with self._lock:
            self.done_n += 1
            self.failed += status.failed

    def _line(self, text: str) -> None:
        self.console.print(text, highlight=False)

    def _render(self):
        from rich.progress_bar import ProgressBar
        from rich.table import Table

        with self._lock:
            done, total, failed = self.done_n, self.total, self.failed
            running = sorted(self.running.items(), key=lambda kv: kv[1])
        now = time.monotonic()
        elapsed = now - self.t0
        fresh = done - self.reused
        left = total - done
        eta = elapsed / fresh * left if fresh > 0 else float("nan")
        grid = Table.grid(padding=(0, 1))
        head = Table.grid(padding=(0, 1))
        head.add_row(ProgressBar(total=max(total, 1), completed=done, width=30),
                     f"{done}/{total} jobs", f"[red]{failed} failed[/]" if failed else "0 failed",
                     f"elapsed {_fmt_s(elapsed)}", f"ETA {_fmt_s(eta)}" if eta == eta else "ETA -")
        grid.add_row(head)
        for label, t in running[:8]:
            grid.add_row(f"  [cyan]running[/] {label}  {_fmt_s(now - t)}")
        if len(running) > 8:
            grid.add_row(f"  ... and {len(running) - 8} more running")
        return grid

    def close(self) -> None:
        self.live.stop()
        elapsed = time.monotonic() - self.t0
        self.console.print(f"{self.done_n}/{self.total} jobs, {self.failed} failed, {_fmt_s(elapsed)}",
                           highlight=False)


def make_progress(kind: str | None = "auto", stream: TextIO | None = None):
    """'auto': rich on a terminal (when rich is installed), plain lines otherwise; 'plain'; 'rich';
    None or 'none': silent."""
    if kind in (None, "none"):
        return None
    stream = stream or sys.stderr
    if kind == "plain":
        return PlainProgress(stream)
    if kind == "rich" or (kind == "auto" and getattr(stream, "isatty", lambda: False)()):
        try:
            return RichProgress(stream)
        except ImportError:
            return PlainProgress(stream)
    return PlainProgress(stream)


def _status_text(status, row: dict[str, Any]) -> str:
    """A finished job's status for its progress line: "unstable (refused before stepping)" for a step refused above
    the predicted stability limit (never stepped, so nothing blew up), else the status."""
    from impactval.engines.base import REFUSED_MARKER

    if str(status) == "unstable" and REFUSED_MARKER in str(row.get("message", "") or ""):
        return f"{status} (refused before stepping: dt above the predicted limit)"
    return str(status)
