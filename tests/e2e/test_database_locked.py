"""A database locked by another program when the operator presses Accept, in a real browser by
visible controls, keys and canvas clicks alone: the panel says so in a sentence (no "Internal error"),
nothing is written, the workflow stays with its result; once the other program has finished, the
same Accept writes.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from core.transforms import pose_error

from .flows import Operator
from .harness import Interface, panel_state, wait_until
from .test_workflows_pose import BOX, _select

pytestmark = pytest.mark.e2e

# Another program holding SQLite's write lock until it reads a line.
HOLDER = r"""
import sqlite3, sys
conn = sqlite3.connect(sys.argv[1], isolation_level=None)
conn.execute("BEGIN EXCLUSIVE")
conn.execute("UPDATE objects SET name = name")
print("locked", flush=True)
sys.stdin.readline()
conn.execute("ROLLBACK")
"""


@pytest.fixture
def quick_interface(scene, frame, tmp_path):
    """The interface whose writes wait 1 s (not 10) for another program holding the database."""
    ui = Interface(scene, frame, tmp_path / "site.sqlite", busy_timeout_s=1.0)
    yield ui
    ui.close()


def test_accept_while_another_program_locks_the_database(browser, quick_interface, scene):
    ui = quick_interface
    body = scene.body(BOX)
    T_true = body.pose_at(ui.frame_t_s)
    obj = ui.site.object(BOX)
    # a start within the tracker's reach (as in test_workflows_pose): an earlier update at 14.5 s
    from app.db import Database

    other = Database.open(ui.db.path)
    other.update_pose(obj.id, body.pose_at(14.5), None, expected_version=obj.version, method="test", client="other")
    other.close()
    wait_until(lambda: ui.site.object(BOX).version == obj.version + 1, what="the server to see the earlier update")
    obj = ui.site.object(BOX)
    page = ui.open(browser)
    op = Operator(ui, page)

    _select(op, page, obj, ui.site.camera)
    op.press("Track")
    wait_until(lambda: page.panel.session.workflow is not None, what="the workflow")
    wf = page.panel.session.workflow
    wait_until(
        lambda: wf.frames >= 10 and pose_error(wf.T_world_obj, T_true)[0] < 0.5,
        timeout_s=60,
        what="the tracker to converge",
        panel=page.panel,
    )
    op.key("Space")  # Pause: the tracked pose stays as it is between the two Accepts
    wait_until(lambda: wf.paused, what="the pause", panel=page.panel)
    T_tracked = wf.T_world_obj.copy()

    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(ui.db.path)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        said = page.get_by_text("is locked by another program", exact=False).first
        # Accept by its key, pressed again if it never reached the server (a loaded run's click on the button was
        # lost: nothing asked, nothing said); a tracked pose the panel thinks weak is asked about once more first
        op.key_until(
            "Enter",
            lambda: page.panel.asking == "accept" or "is locked by another program" in panel_state(page.panel),
            "the lock said, or Accept's question",
        )
        if page.panel.asking == "accept":
            op.press("Accept anyway")
        said.wait_for(state="visible", timeout=60_000)
        text = said.inner_text()
        assert f"pid {holder.pid}" in text and "nothing was written" in text and "try again" in text, text
        assert "Your work in Track is kept" in text, text
        assert page.get_by_text("Internal error").count() == 0 and page.get_by_text("Something went wrong").count() == 0
        assert page.panel.session.workflow is wf and not wf.finished and wf.paused
        assert (wf.T_world_obj == T_tracked).all()
        assert ui.db.get(BOX).version == obj.version  # read while the other program holds the lock
        op.check()  # Accept (and Resume, Cancel) still on the page
    finally:
        holder.stdin.write("\n")
        holder.stdin.close()
        holder.wait(30)
    assert holder.returncode == 0

    op.press("Accept")
    wait_until(lambda: wf.accepted, what="the second accept", panel=page.panel)
    rec = ui.db.get(BOX)
    assert rec.version == obj.version + 1 and (rec.T_world_obj == T_tracked).all()
    entry = ui.db.history(BOX)[-1]
    assert entry.method == "tracking" and entry.client.startswith("browser-")
    page.get_by_text("is locked by another program").first.wait_for(state="hidden", timeout=60_000)
    op.report("track, Accept refused by a lock, Accept")
