"""A text progress bar for long jobs (benchmarks, particle generation)."""

from __future__ import annotations

import sys
import time


class Progress:
    """A one-line text progress bar on stderr (one line per update when not a terminal)."""

    def __init__(self, total, stream=None, width=30):
        self.total = max(1, int(total))
        self.done = 0
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.start = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def _line(self, label):
        frac = self.done / self.total
        filled = int(round(frac * self.width))
        elapsed = time.perf_counter() - self.start
        return (f"[{'#' * filled}{'.' * (self.width - filled)}] {self.done}/{self.total} "
                f"{elapsed:6.1f}s  {label}")

    def begin(self, label):
        """Show what is being done now (before it is done)."""
        if self.tty:
            self.stream.write("\r\033[K" + self._line(label))
            self.stream.flush()

    def advance(self, label=""):
        """One more done. Off a terminal, a line is written only when the label's part
        before its colon changes, and at the end."""
        self.done += 1
        if self.tty:
            self.stream.write("\r\033[K" + self._line(label))
        else:
            group = label.split(":")[0]
            if group != getattr(self, "_group", None) or self.done == self.total:
                self._group = group
                self.stream.write(self._line(label) + "\n")
        self.stream.flush()

    def close(self):
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
