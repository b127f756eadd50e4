"""A command's output and its terminal: the log takes everything, the terminal one line.

A workflow rule's job runs ``stringcast --log results/<c>/logs/<rule>_<k>.log <stage> ...``: what the
stage and the libraries under it print (file descriptors 1 and 2, so OpenCV's and FFmpeg's lines
too) goes to the log, and the terminal that Snakemake shows gets only the stage's verdict line
(status and first reason) or its error line, each naming where it wrote (:class:`JobLog`). So a
failed job says why where the person is looking, without a profile's ``--show-failed-logs``.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path


class JobLog:
    """Where a command's output goes: with ``--log FILE`` (the workflow's rules) everything the
    command and the libraries under it print (file descriptors 1 and 2) goes to FILE, and the
    terminal (the original standard error: Snakemake's) gets only :meth:`say`'s lines, the
    command's verdict or error, one each; without it, the usual streams."""

    def __init__(self, path: str | None = None):
        self.path, self.terminal, self._saved = path, None, ()
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            sys.stdout.flush()
            sys.stderr.flush()
            self._saved = (os.dup(1), os.dup(2))
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            os.close(fd)
            self.terminal = os.fdopen(os.dup(self._saved[1]), "w", buffering=1)
            self._streams = sys.stdout, sys.stderr      # Python's writers, on the same descriptors
            sys.stdout, sys.stderr = (open(fd, "w", buffering=1, closefd=False) for fd in (1, 2))

    def close(self) -> None:
        """Give the standard streams back (a command run in-process, as by the tests)."""
        if self._saved:
            sys.stdout.flush()
            sys.stderr.flush()
            sys.stdout, sys.stderr = self._streams
            for fd, saved in zip((1, 2), self._saved):
                os.dup2(saved, fd)
                os.close(saved)
            self.terminal.close()
            self._saved, self.terminal = (), None

    def say(self, line: str, error: bool = False) -> None:
        """``line`` into the log (stdout; stderr for an ``error``) and, with a log file, on the terminal."""
        print(line, file=sys.stderr if error else sys.stdout, flush=True)
        if self.terminal is not None:
            print(line + (f" (log: {self.path})" if error else ""), file=self.terminal, flush=True)


INTERNAL_ERROR_STATUS = 1
"""The exit status of a subcommand that ended in an unexpected exception (a defect of stringcast,
not of its input: bad input exits with 2)."""
TRACEBACK_DIR_ENV = "STRINGCAST_TRACEBACK_DIR"
"""Environment variable naming the folder an internal error's full traceback is written to
(default: the system's temporary folder)."""


def internal_error(command: str, exc: BaseException, in_log: bool = False) -> str:
    """The message for an unexpected exception ``exc`` in ``stringcast command``: its first line
    ``stringcast <command>: internal error: <type>: <message>`` (the message's first line, at most
    300 characters), its second where the full traceback was written: the command's log
    (``in_log``: standard error is the log, :class:`~stringcast.core.JobLog`), else a file
    ``stringcast-<command>-<time>-<pid>.traceback`` in ``$STRINGCAST_TRACEBACK_DIR`` or the
    system's temporary folder, or, where it cannot be written, the traceback itself."""
    import tempfile
    import time
    import traceback

    text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    first = (str(exc).strip().splitlines() or [""])[0]
    first = first if len(first) <= 300 else first[:297] + "..."
    head = f"stringcast {command}: internal error: {type(exc).__name__}: {first}"
    if in_log:
        print(text, file=sys.stderr, flush=True)
        return f"{head}\n  (unexpected: not an input error stringcast knows; the traceback is in the log)"
    folder = Path(os.environ.get(TRACEBACK_DIR_ENV) or tempfile.gettempdir())
    path = folder / f"stringcast-{command}-{time.strftime('%Y%m%dT%H%M%S')}-{os.getpid()}.traceback"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        path.write_text(f"stringcast {command}\n{text}")
    except OSError:
        return f"{head}\n  (the full traceback could not be written to {folder}; here it is)\n{text}"
    return f"{head}\n  (unexpected: not an input error stringcast knows; the full traceback is in {path})"
