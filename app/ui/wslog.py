"""One log line, not a traceback, for a browser message the interface cannot read.

viser reads each websocket message in ``_message_consumer``; a message that does not decode
(not MessagePack, a text frame, an unknown type, wrong fields) ends the connection, and websockets
logs "connection handler failed" with the whole traceback: 15 lines per message, which a faulty or
hostile client repeats at will. ``quiet_malformed_messages()`` installs a filter on the
``websockets.server`` logger that turns exactly those records (the exception passed through
viser's message reader) into one WARNING line saying who sent what; any other failure of a
connection keeps its traceback (it is a fault of the server, not of the message). A message viser
decodes but whose field has the wrong shape only raises viser's UserWarning (two lines, source
included); that warning becomes one WARNING line too (logger ``mcit.ui``). mcit's interface checks
each message before viser reads it (app/ui/inbound.py): these lines are the net for what passes it.
"""

from __future__ import annotations

import logging
import warnings

__all__ = ["MalformedMessageFilter", "quiet_malformed_messages"]

_READER = "_message_consumer"  # viser.infra._infra: the coroutine that decodes each incoming message


def _from_the_reader(tb) -> bool:
    while tb is not None:
        if tb.tb_frame.f_code.co_name == _READER:
            return True
        tb = tb.tb_next
    return False


class MalformedMessageFilter(logging.Filter):
    """Rewrites websockets' "connection handler failed" records whose exception came from viser's
    message reader into one line (level WARNING, no traceback)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and record.exc_info[1] is not None and record.msg == "connection handler failed":
            exc = record.exc_info[1]
            if _from_the_reader(exc.__traceback__):
                ws = getattr(record, "websocket", None)
                peer = getattr(ws, "remote_address", None)
                who = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) and len(peer) >= 2 else "a client"
                what = " ".join(str(exc).split())[:200]
                record.msg = "closed the connection of %s: it sent a message the interface cannot read (%s%s)"
                record.args = (who, type(exc).__name__, f": {what}" if what else "")
                record.levelno, record.levelname = logging.WARNING, "WARNING"
                record.exc_info = record.exc_text = None
        return True


_SHAPE_WARNING = "does not match annotation"  # viser.infra._messages._prepare_for_deserialization


def _show_shape_warnings_in_one_line(previous):
    def show(message, category, filename, lineno, file=None, line=None):
        text = str(message)
        if category is UserWarning and text.startswith("[viser]") and _SHAPE_WARNING in text:
            logging.getLogger("mcit.ui").warning(
                "a client sent a message with a field of the wrong shape (%s); viser passed it on as sent",
                " ".join(text[7:].split())[:200],
            )
            return
        previous(message, category, filename, lineno, file, line)

    show.mcit_one_line = True
    return show


def quiet_malformed_messages(logger_name: str = "websockets.server") -> None:
    """Install ``MalformedMessageFilter`` on the websockets server's logger and the one-line form of
    viser's wrong-shape warning (once)."""
    logger = logging.getLogger(logger_name)
    if not any(isinstance(f, MalformedMessageFilter) for f in logger.filters):
        logger.addFilter(MalformedMessageFilter())
    if not getattr(warnings.showwarning, "mcit_one_line", False):
        warnings.showwarning = _show_shape_warnings_in_one_line(warnings.showwarning)
