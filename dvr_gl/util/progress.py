"""Progress bars for long jobs (exact images, tiles, benchmarks, particle generation),
through tqdm, behind the small interface the callers share."""

from __future__ import annotations

import sys


class Progress:
    """A tqdm bar on stderr (or ``stream``): ``begin(label)`` says what is being done now,
    ``advance(label)`` counts one more done, ``close()`` ends the bar. Off a terminal tqdm
    redraws at most every few seconds, so logs stay short."""

    def __init__(self, total, stream=None, width=None):
        from tqdm import tqdm
        stream = stream if stream is not None else sys.stderr
        tty = hasattr(stream, "isatty") and stream.isatty()
        self.total = max(1, int(total))
        self.done = 0
        self.bar = tqdm(total=self.total, file=stream, ncols=width, mininterval=0.1 if tty else 5.0,
                        bar_format="{desc}: {percentage:3.0f}%|{bar:20}| {n_fmt}/{total_fmt} "
                                   "[{elapsed}<{remaining}]", dynamic_ncols=width is None and tty)

    def begin(self, label):
        """Show what is being done now (before it is done)."""
        self.bar.set_description_str(label, refresh=True)

    def advance(self, label=""):
        """One more done."""
        self.done += 1
        if label:
            self.bar.set_description_str(label, refresh=False)
        self.bar.update(1)

    def close(self):
        self.bar.close()
