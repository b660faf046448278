"""A small progress bar for long command-line runs (no dependency).

    bar = Progress(total=48, label="frames")
    for f in range(48):
        ...
        bar.update(f + 1, contacts=1234)
    bar.close()

On a terminal the bar is redrawn in place on stderr; to a file or pipe it
writes a line at most every ``interval`` seconds and at the end, so batch
logs stay short.  ``write(line)`` prints a line to stdout without breaking the bar.
The estimate of the time left assumes the remaining frames cost the mean of
those done in this run.
"""

from __future__ import annotations

import sys
import time


def format_seconds(s: float) -> str:
    """``h:mm:ss`` (or ``m:ss`` under an hour)."""
    s = max(0, int(round(s)))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m}:{sec:02d}"


class Progress:
    """Progress of ``total`` units starting at ``initial`` (e.g. after a resume).

    Attributes:
        total: units to reach [-].
        initial: units already done when the bar starts [-].
        label: what a unit is ("frames").
        enabled: False draws nothing (``--quiet``).
        interval: minimum seconds between two lines when the stream is not a terminal [s].
    """

    def __init__(self, total: int, initial: int = 0, label: str = "frames", enabled: bool = True,
                 stream=None, interval: float = 10.0, width: int = 24):
        self.total, self.initial, self.label = total, initial, label
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval, self.width = interval, width
        self.t0 = time.perf_counter()
        self.done = initial
        self.extra = ""
        self._last_line = -1e30
        self._drawn = False

    def text(self) -> str:
        elapsed = time.perf_counter() - self.t0
        frac = self.done / self.total if self.total else 1.0
        fill = int(round(self.width * frac))
        run = self.done - self.initial
        eta = elapsed / run * (self.total - self.done) if run > 0 else float("nan")
        eta_s = format_seconds(eta) if eta == eta else "?"
        return (f"{self.label} {self.done}/{self.total} [{'#' * fill}{'.' * (self.width - fill)}] {100 * frac:3.0f}% "
                f"elapsed {format_seconds(elapsed)} eta {eta_s}{self.extra}")

    def update(self, done: int, **fields) -> None:
        """Set the units done and extra fields shown after the bar (e.g. ``contacts=12``)."""
        self.done = done
        self.extra = "".join(f" {k} {v}" for k, v in fields.items())
        if not self.enabled:
            return
        now = time.perf_counter()
        if self.tty:
            self.stream.write("\r\033[K" + self.text())
            self.stream.flush()
            self._drawn = True
        elif now - self._last_line >= self.interval or done >= self.total:
            self.stream.write(self.text() + "\n")
            self.stream.flush()
            self._last_line = now

    def write(self, line: str, file=None) -> None:
        """Print ``line`` (stdout by default) above the bar."""
        if self.enabled and self.tty and self._drawn:
            self.stream.write("\r\033[K")
            self.stream.flush()
        print(line, file=file or sys.stdout, flush=True)
        if self.enabled and self.tty and self._drawn:
            self.stream.write(self.text())
            self.stream.flush()

    def close(self) -> None:
        if self.enabled and self.tty and self._drawn:
            self.stream.write("\n")
            self.stream.flush()
