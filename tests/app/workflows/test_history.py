"""History and undo through the workflow: undo a pose update, and an unknown change number."""

from __future__ import annotations

import numpy as np
import pytest

from app.workflows import History, WorkflowError
from core.transforms import make_T


def test_undo_brings_the_old_pose_back_and_is_recorded(site, db):
    obj = site.object("parallelepiped")
    T_new = make_T(np.eye(3), obj.T_world_obj[:3, 3] + [0.05, 0, 0])
    change = db.update_pose(obj.id, T_new, None, expected_version=obj.version, method="test", client="bob")
    site.poll()
    assert np.allclose(site.object("parallelepiped").T_world_obj, T_new)
    wf = History(site, client="alice")
    rows = wf.summary()["changes"]
    assert rows[0]["what"] == "moved parallelepiped" and rows[0]["how"] == "test"  # a tag without words: as it is
    last_id = db.history()[-1].id
    rev = site.revision
    rec = wf.undo(last_id)
    assert rec.action == "undo" and rec.client == "alice"
    assert np.allclose(site.object("parallelepiped").T_world_obj, obj.T_world_obj)
    assert site.revision > rev  # every client redraws
    assert wf.summary()["changes"][0]["what"].startswith("undid change")
    with pytest.raises(WorkflowError, match="pick a change number"):
        wf.undo(10_000)
    assert change.version + 1 == site.object("parallelepiped").version
    n = len(db.history())
    assert wf.question("undo", last_id) == ""  # nothing to confirm: the press itself says it is undone already
    assert any(v == last_id and text.endswith(f"— undone by #{rec.id}") for text, v in wf.choices("change"))
    with pytest.raises(WorkflowError, match=f"change {last_id} is undone already .*undo change {rec.id}"):
        wf.undo(last_id)  # pressed again (the chooser still shows it): nothing recorded
    assert len(db.history()) == n
    redo = wf.undo(rec.id)  # the undo undone: said as a redo of the first change, in the list and to the others
    assert np.allclose(site.object("parallelepiped").T_world_obj, T_new)
    what = f"redid change #{last_id} (parallelepiped; undid undo #{rec.id})"
    assert wf.summary()["changes"][0]["what"] == what and wf.summary()["changes"][0]["how"] == "redo"
    assert wf.message == (
        f"Redid change #{last_id} (parallelepiped; undid undo #{rec.id}), "
        f"recorded as change #{redo.id} (it can be undone in turn)"
    )
    assert any(text.startswith(f"#{redo.id} alice {what}") for text, _ in wf.choices("change"))
    assert [c.what for c in site.changes_since(rec.id)] == [what]


def test_undo_asks_when_it_discards_later_changes_and_refuses_a_stale_list(site):
    from app.workflows import History, WorkflowError

    obj = site.object("parallelepiped")
    site.set_status("parallelepiped", "stale", client="alice")
    first = site.db.history("parallelepiped")[-1]
    h = History(site, client="alice")
    assert h.question("undo", first.id) == ""  # the object's latest change: nothing else is discarded
    T = obj.T_world_obj.copy()
    T[0, 3] += 0.01
    site.update_pose(site.object("parallelepiped"), T, None, method="test", client="bob", clicks={}, residuals={})
    h.refresh()
    q = h.question("undo", first.id)
    assert "also discards the 1 later change" in q and "bob" in q
    # bob changes it again after alice's list was read: her undo is refused, nothing written
    n = len(site.db.history("parallelepiped"))
    T[1, 3] += 0.01
    site.update_pose(site.object("parallelepiped"), T, None, method="test", client="bob", clicks={}, residuals={})
    with pytest.raises(WorkflowError, match="changed"):
        h.undo(first.id)
    assert len(site.db.history("parallelepiped")) == n + 1


def test_the_history_says_how_in_the_operators_words(site):
    """History's table says how each change was made in words ("solved from clicked edges, then refined"),
    not the database's tags ("p3l+refine", "search"), which a new operator read as jargon."""
    from app.workflows import History
    from app.workflows.site import method_words

    obj = site.object("parallelepiped")
    T = obj.T_world_obj.copy()
    T[0, 3] += 0.01
    site.update_pose(obj, T, None, method="p3l+refine", client="alice", clicks={}, residuals={})
    rows = History(site, client="alice").summary()["changes"]
    assert rows[0]["how"] == "solved from clicked edges, then refined"
    assert method_words("search") == "found from one click" and method_words("model box (fused)") == "model box (fused)"


def test_the_chooser_marks_a_change_undone_until_its_undo_is_undone(site):
    """The Change chooser says "undone by #k" after a change that is undone, and stops saying it when
    that undo is undone in turn (the change is back)."""
    from app.workflows import History

    site.set_status("parallelepiped", "stale", client="alice")
    c = site.db.history("parallelepiped")[-1]
    h = History(site, client="alice")
    u = h.undo(c.id)
    h.refresh()
    text = {v: t for t, v in h.choices("change")}
    assert text[c.id].endswith(f"— undone by #{u.id}") and "undone by" not in text[u.id]
    uu = h.undo(u.id)
    h.refresh()
    text = {v: t for t, v in h.choices("change")}
    assert "undone by" not in text[c.id] and text[u.id].endswith(f"— undone by #{uu.id}")
