"""How an ``mcit`` command ends: its exit status, one scheme for every command (app/cli.py applies it).

====  =========================================================================================
 0    done
 1    the command could not do its job: a file, device, database or value it was given is wrong
      or unavailable, or the machine refused (a full disk, no port to listen on); the line on stderr says
      which and what to do
 2    the command line is wrong: an unknown option, a bad value, options that do not go together
      (``UsageError``); ``mcit COMMAND --help`` says what it takes
 3    ``mcit track``: the object was lost; the line says at which frame and how to restart
70    a bug in mcit (the line says so; ``MCIT_TRACEBACK=1`` shows where)
130   stopped by Ctrl-C
141   the reader of the output left (``mcit db history | head``), as a shell reports it
====  =========================================================================================
"""

from __future__ import annotations

__all__ = ["OK", "FAILED", "USAGE", "LOST", "BUG", "INTERRUPTED", "PIPE_CLOSED", "UsageError"]

OK = 0
FAILED = 1
USAGE = 2
LOST = 3
BUG = 70  # sysexits.h's EX_SOFTWARE
INTERRUPTED = 130  # 128 + SIGINT
PIPE_CLOSED = 141  # 128 + SIGPIPE


class UsageError(ValueError):
    """The command line is wrong in a way argparse cannot see (``--init-points`` without
    ``--init-clicks``): said in one line, exit status 2 (``USAGE``) as for argparse's refusals."""
