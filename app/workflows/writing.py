"""Writing a pose workflow's result: ``site.update_pose`` from the snapshot the workflow started on,
with what an operator needs to hear when the object changed meanwhile."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .base import WorkflowError

if TYPE_CHECKING:  # pragma: no cover
    from .base import Workflow

__all__ = ["write_pose"]


def write_pose(wf: Workflow, obj: Any, T_world_obj: np.ndarray, cov: Any, *, todo: str, **record: Any) -> tuple:
    """``site.update_pose`` by ``wf``'s operator from the snapshot ``obj`` the workflow started on. When the
    object changed meanwhile but not its pose or model (e.g. an undo of a status), the new pose is as valid
    as before: it is written over the fresh snapshot. Marked stale meanwhile: said, nothing written, and
    ``wf.obj`` becomes the fresh snapshot (a second Accept writes). Moved: nothing is written and
    WorkflowError says who moved it and ``todo``. Returns (record, snapshot used)."""
    from app.db import ConflictError

    site = wf.site
    record.setdefault("seen_at", wf.seen_at())  # the image's capture time: the pose's stamp on the feed, ROS 2
    try:
        return site.update_pose(obj, T_world_obj, cov, client=wf.client, **record), obj
    except ConflictError as first:
        conflict = first  # or the second conflict, below
        try:
            fresh = site.object(obj.name)
        except KeyError:
            raise WorkflowError(f"{obj.name} was removed from the database meanwhile: nothing was written") from None
        same_model = fresh.model is obj.model or np.array_equal(fresh.model.vertices, obj.model.vertices)
        same_pose = same_model and np.allclose(fresh.T_world_obj, obj.T_world_obj, rtol=0.0, atol=1e-12)
        last = site.db.history(obj.name, limit=1)
        who = f" by {last[-1].client}" if last else ""
        if same_pose and fresh.status == "stale" and obj.status != "stale":
            # Someone saw it move since this workflow started: maybe again, after the frame clicked on.
            # Said, not written; a second Accept writes over the fresh snapshot (the operator has looked).
            wf.obj = fresh
            raise WorkflowError(
                f"{obj.name} was marked stale{who} since you started: it may have moved after the "
                "frame you clicked on. Nothing was written; check the video, then Accept again to "
                f"write your pose, or {todo[0].lower() + todo[1:]}"
            ) from None
        if same_pose:
            try:
                return site.update_pose(fresh, T_world_obj, cov, client=wf.client, **record), fresh
            except ConflictError as again:
                conflict = again
        raise WorkflowError(
            f"{obj.name} was moved{who} since you started (version {conflict.expected_version} → "
            f"{conflict.actual_version}): nothing was written. {todo}"
        ) from None
    except ValueError as exc:
        raise WorkflowError(f"the database refused the pose: {exc}") from None
