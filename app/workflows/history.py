"""History and undo: the database's changes, newest first, and undoing one of them.

``undo(change_id)`` brings the object (or the calibration) back to its state just before that
change; the undo is itself a recorded change (so it can be undone). Nothing else is written.
"""

from __future__ import annotations

import time
from typing import Any

from .base import Control, Step, Workflow, WorkflowError
from .site import is_redo, method_words

__all__ = ["History"]


class History(Workflow):
    name = "history"
    title = "History"
    actions = ("refresh", "undo", "restore", "accept", "cancel")
    controls = (
        Control("change", "Change", kind="choice", hint="A change of the database (newest first)"),
        Control(
            "undo",
            "Undo change",
            "Z",
            arg="change",
            color="orange",
            hint="Bring the object back to its state before the chosen change (the undo is recorded too)",
        ),
        Control("refresh", "Refresh", hint="Read the latest changes again"),
        Control("accept", "Close", "escape", hint="Close the history"),
    )

    def __init__(
        self, site, client: str = "operator", view: str | None = None, limit: int = 30, object_name: str | None = None
    ):
        super().__init__(site, client, view)
        self.limit = int(limit)
        self.object_name = object_name
        self.entries: list = []
        self.state = "browse"
        self.refresh()

    def refresh(self) -> None:
        """Re-read the last changes (of the selected object, or of all)."""
        with self.lock:
            self.entries = list(reversed(self.site.db.history(self.object_name, limit=self.limit)))
            self._versions = {o.name: o.version for o in self.site.objects()}

    def _seen_version(self, change_id: int) -> int | None:
        """The version of the change's object when the list was read (None: not an object, or unknown)."""
        entry = next((c for c in self.entries if c.id == change_id), None)
        return None if entry is None else self._versions.get(entry.object_name)

    def _revert(self, which: str, change_id: int):
        from app.db import ConflictError, NotFoundError

        with self.lock:
            self._check_open()
            if which == "undo":
                later = self._later_changes(int(change_id))
                if later and later[-1].method == "undo" and later[-1].undoes == int(change_id):
                    raise WorkflowError(
                        f"change {int(change_id)} is undone already (change {later[-1].id}): nothing to do; "
                        f"to bring it back, undo change {later[-1].id}"
                    )
            seen = self._seen_version(int(change_id))
            try:
                if which == "undo":
                    rec = self.site.undo(int(change_id), client=self.client, expected_version=seen)
                else:
                    rec = self.site.restore(int(change_id), client=self.client)
            except NotFoundError as exc:
                raise WorkflowError(f"{exc}; pick a change number from the list") from None
            except ConflictError as exc:
                raise WorkflowError(str(exc)) from None
            except ValueError as exc:
                raise WorkflowError(f"cannot {which} change {change_id}: {exc}") from None
            self.refresh()
            said = self.site.change_sentence(rec)  # "undid change #14 (box)", or a redo
            self.message = f"{said[0].upper()}{said[1:]}, recorded as change #{rec.id} (it can be undone in turn)"
            return rec

    def _later_changes(self, change_id: int) -> list:
        """Changes of the same object made after ``change_id`` (an undo discards them too); none for an unknown
        change (undoing it says so)."""
        from app.db import NotFoundError

        try:
            return self.site.db.later_changes(int(change_id))
        except NotFoundError:
            return []

    def question(self, action: str, *args: Any) -> str:
        if action == "undo" and args:
            later = self._later_changes(int(args[0]))
            if later and later[-1].method == "undo" and later[-1].undoes == int(args[0]):
                return ""  # undone already: the press says so (``_revert``), nothing to confirm
            if later:
                last = later[-1]
                when = time.strftime("%H:%M:%S", time.localtime(last.time))
                return (
                    f"Undoing change #{int(args[0])} brings {last.object_name} back to before it, and so also discards "
                    f"the {len(later)} later change{'s' if len(later) > 1 else ''} of it (the last by {last.client} at "
                    f"{when})."
                )
        return super().question(action, *args)

    def undo(self, change_id: int):
        """Bring the object back to its state before change ``change_id`` (itself recorded). Refused
        (nothing written) when the object changed after the list was read."""
        return self._revert("undo", change_id)

    def restore(self, change_id: int):
        """Bring the object back to its state just after change ``change_id`` (an earlier pose)."""
        return self._revert("restore", change_id)

    def accept(self) -> None:
        """Close the history."""
        with self.lock:
            self._check_open()
            self.accepted = True
            self.state = "closed"
            self.message = "History closed."

    def follows_live(self) -> str:
        return f"{self.title} follows the live video: nothing to freeze"

    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        if not self.entries:
            return Step(
                "empty", "No change is recorded yet. {accept} when done.", frozenset({"refresh", "accept"}), False
            )
        return Step(
            "browse",
            "The last changes, newest first: choose one under Change and {undo} (the undo is "
            "recorded too and can be undone); {accept} when done.",
            frozenset({"change", "undo", "refresh", "accept"}),
            clicks=False,
        )

    def choices(self, action: str) -> list[tuple[str, Any]]:
        if action != "change":
            return []
        with self.lock:
            # a change undone since says so (a new operator saw the chooser stay on one just undone, unmarked)
            undone = {
                int(c.undoes): int(c.id)
                for c in sorted(self.entries, key=lambda c: c.id)
                if c.method == "undo" and c.undoes is not None
            }
            return [
                (
                    f"#{c.id} {c.client} {self._sentence(c)} ({time.strftime('%H:%M:%S', time.localtime(c.time))})"
                    + (f" — undone by #{undone[int(c.id)]}" if undone.get(int(c.id)) not in (None, *undone) else ""),
                    int(c.id),
                )
                for c in self.entries
            ]

    def _undone(self, c):
        """The record change c undid (from the list when it is there), or None."""
        if c.undoes is None:
            return None
        return next((e for e in self.entries if int(e.id) == int(c.undoes)), None) or self.site.undone(c)

    def _sentence(self, c) -> str:
        return self.site.change_sentence(c, self._undone(c))

    def summary(self) -> dict[str, Any]:
        with self.lock:
            rows = []
            for c in self.entries:
                rows.append(
                    {
                        "#": c.id,
                        "when": time.strftime("%H:%M:%S", time.localtime(c.time)),
                        "who": c.client,
                        "what": self._sentence(c),
                        "how": "redo" if is_redo(c, self._undone(c)) else method_words(c.method),
                    }
                )
            return {"changes": rows}
