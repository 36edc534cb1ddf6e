"""What Update pose shows the operator: its controls, the step (what to do now and which controls
apply), the marks on each camera's image, the click rows and their residuals, the summary, the
weaknesses said before Accept, and the sentences its actions leave.

Functions of an ``UpdatePose`` (app/workflows/update_pose.py) that read its state — its clicks
(``core.pose.PoseClicks``), its one-click search (``OneClickSearch``), its automatic match (``AutoMatch``),
its candidates and refined pose — and never change it. The workflow calls them under its lock.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.transforms import pose_error

from .base import CANCEL, Control, Ghost, Marks, Step, sigma_over
from .snapping import snap_marks, weak_snaps

__all__ = [
    "ACTIONS",
    "CONTROLS",
    "step",
    "marks",
    "summary",
    "click_choices",
    "candidate_labels",
    "weaknesses",
    "solve_message",
    "refine_message",
    "skipped_words",
    "unseen_outline",
    "history_record",
    "accepted_words",
    "no_pose_fits",
    "no_plausible",
    "AUTO_ASSIGN_WORDS",
    "choices",
]

# A refined pose is weak (Accept asks once more) when its σ exceed these, a click lies more than 3σ
# off, a snap fits the image poorly where it put a click (``ClickSnap.weak``), or the clicks fix the 6 unknowns
# just barely.
WEAK_SIGMA_DEG = 2.0
WEAK_SIGMA_MM = 20.0
# A refined pose whose outline lies on the image's edges for less than this share is said suspect (its clicks
# may fit a wrong assignment): the one-click search's own floor (app.vision.search.MIN_NEAR), which the right
# poses of 150 rendered placements, a fifth to a third of them hidden, all passed.
MIN_OUTLINE_SEEN = 0.40

# The actions a script may call (the controls' and the ones scripts use without a control).
ACTIONS = (
    "click",
    "assign_edge",
    "add_segment",
    "add_point",
    "start_point",
    "remove_last",
    "remove_click",
    "solve",
    "choose_candidate",
    "refine",
    "accept",
    "cancel",
    "refuse_snap",
    "set_snap",
    "auto_assign",
    "auto_match",
    "confirm_match",
    "find",
)
CONTROLS = (
    Control(
        "find",
        "Find",
        "G",
        kind="long",
        color="blue",
        hint="Find the object's pose from your one click on it (where it is now in the video)",
    ),
    Control(
        "auto_match",
        "Auto match",
        "M",
        kind="long",
        color="blue",
        hint="Find which model edge each clicked image edge is (3 or more edges, 4 is best)",
    ),
    Control("confirm_match", "Confirm match", "C", color="blue", hint="Adopt the assignment shown"),
    Control("solve", "Solve", "P", color="blue", hint="Large motion: the three-line solver's candidate poses"),
    Control("choose_candidate", "Candidate", kind="choice", hint="The candidate pose drawn in white"),
    Control(
        "refine",
        "Refine",
        "R",
        color="blue",
        hint="Least squares on every click, from the candidate or the database pose",
    ),
    Control("accept", "Accept", "enter", color="green", hint="Write the refined pose to the database"),
    Control("start_point", "Add point", "V", hint="Next clicks: a model corner, then where it is in the video"),
    Control("refuse_snap", "Refuse snap", "U", hint="Use the last click as clicked, not moved onto the image's edge"),
    Control("remove_last", "Remove last", "backspace", hint="Undo the last click or assignment"),
    Control("click_row", "Click", kind="choice", hint="A clicked edge or point (its residual after Refine)"),
    Control("remove_click", "Delete click", arg="click_row", hint="Delete the click chosen above"),
    CANCEL,
)


def counted(n_edges: int, n_points: int) -> str:
    """ "4 edges", "3 edges and 1 point", "no click": what a refinement used, or what was snapped."""
    parts = [f"{n} {w}{'s' if n != 1 else ''}" for n, w in ((n_edges, "edge"), (n_points, "point")) if n]
    return " and ".join(parts) or "no click"


# ---------------------------------------------------------------------------------------------- the step
def step(wf) -> Step:
    """Where Update pose stands: the prompt and the controls that apply."""
    if wf.finished:
        return wf._finished_step()
    c = wf.clicks
    if wf.progress is not None:  # Find under way (its click was taken: not "click a second point")
        return Step(
            "searching",
            f"Searching for the pose of {wf.object_name} from your click… " + "{cancel} stops the search.",
            frozenset({"cancel"}),
            clicks=False,
        )
    where = "on the white ghost" if (wf.chosen is not None or wf.last_refined is not None) else "on its wireframe"
    base = {"cancel"}
    if c.pending is not None or c.mode == "point" or c.undoable() or wf.match.matches is not None:
        base.add("remove_last")
    last = c.last_click()
    snap = None if last is None else (c.seg_snaps if last[0] == "segment" else c.point_snaps)[last[1]]
    if snap is not None and snap.applied and c.pending is None and c.mode == "edge":
        base.add("refuse_snap")
    if c.mode == "point":
        if c.pending_vertex is None:
            return Step(
                "click_point_model", f"Click a corner of {wf.object_name} {where} (the model vertex).", frozenset(base)
            )
        return Step(
            "click_point_image",
            f"Now click where vertex {c.pending_vertex} (circled) really is in the video.",
            frozenset(base),
        )
    if wf.search.alone(wf.clicks, wf.refined):
        return wf.search.step(wf.chosen or 0, base)
    first = wf.search.found is None and c.pending is not None and c.empty and wf.match.matches is None
    return _clicking_step(wf, base, where, first) or _estimate_step(wf, base)


def _clicking_step(wf, base: set, where: str, first: bool) -> Step | None:
    """The steps while clicks are under way or awaited; None once the estimate is what the operator acts on."""
    c, name, k = wf.clicks, wf.object_name, len(wf.clicks.segs)
    if first:
        also = "" if wf.search_only else f", or click a second point on the same image edge (edge {k + 1})"
        return Step(
            "click_edge_end",
            "{find} the pose of " + f"{name} from this {'' if wf.search_only else 'one '}click (or double-click "
            f"it){also}.",
            frozenset(base | {"find"}),
        )
    if wf.search_only:
        return Step(
            "click_edge",
            f"Double-click {name} where it is now in the video to find its pose (it has no straight edges to click).",
            frozenset(base),
        )
    if c.pending is not None:
        return Step("click_edge_end", f"Click a second point on the same image edge (edge {k + 1}).", frozenset(base))
    rows = {"click_row", "remove_click"} if c.rows() else set()
    if wf.match.matches is not None:
        e0 = int(wf.match.matches[wf.chosen or 0].edges[0])
        return Step(
            "match",
            f"Assignment {(wf.chosen or 0) + 1} of {len(wf.match.matches)} shown (1→e{e0}: clicked edge 1 is "
            f"model edge {e0}): " + "{confirm_match}, choose another {choose_candidate}, or {remove_last} to drop "
            "them and click more edges (to assign by hand instead: Cancel, start again and click each edge's model "
            "edge after it).",
            frozenset(base | {"confirm_match", "choose_candidate"}),
        )
    if c.waiting_for_edge():
        if c.assigned():  # a hand assignment under way goes on by hand
            return Step(
                "assign_edge", f"Which model edge is it? Click that edge of {name} {where}.", frozenset(base | rows)
            )
        return Step(  # the first edge: Auto match still takes over, as the instruction before the clicks said
            "assign_edge",
            f"Which model edge is it? Click that edge of {name} {where}; " + "or {auto_match} to let mcit match them.",
            frozenset(base | rows | {"auto_match"}),
        )
    n = len(c.assigned())
    if c.auto and (n < k or c.empty):  # automatic assignment: said from the start
        if k < 3:
            return Step(
                "auto_click",
                f"Automatic matching: click two points along an edge of {name} (edge {k + 1}; 3 or more, 4 is best).",
                frozenset(base | rows),
            )
        return Step(
            "auto_ready",
            f"{k} edges clicked: " + "{auto_match}, or click another edge (4 or more is best).",
            frozenset(base | rows | {"auto_match"}),
        )
    if n >= 3 or wf.refined:
        return None
    more = _more(wf, base | rows)
    tail = " Or {refine} from the database pose (a small motion)." if "refine" in more else ""
    if wf.search.found is not None and "refine" in more:
        tail = " Or {refine}: the clicks fit together with the found pose (one edge is enough)."
    one = (
        f"Double-click {name} where it is now in the video to find its pose from that point; or c"
        if c.empty and wf.search.found is None
        else "C"
    )
    spread = ", not all three through one corner" if n == 2 else ""
    edge = f"two points along an edge of {name} in the video (edge {n + 1} of 3{spread})"
    if "auto_match" in more:
        prompt = (
            one + f"lick {edge}, then click which model edge it is; " + "or {auto_match} to skip saying which is which."
        )
    else:
        prompt = f"Click {edge}."
    return Step("click_edge", prompt + tail, frozenset(more))


def _more(wf, base: set) -> set:
    """The controls that apply once clicks can be used: Refine with enough clicks, Solve with 3 edges in
    one camera, Auto match before 3 edges, Add point."""
    c = wf.clicks
    more = base | {"start_point"}
    constraints = 2 * (len(c.assigned()) + len(c.points_uv))
    if constraints >= 6 or (wf.search.found is not None and constraints >= 2):  # with a found pose one edge is enough
        more.add("refine")
    if c.most_in_one_view() >= 3:  # the three-line solver works in one camera
        more.add("solve")
    if not c.auto and len(c.segs) < 3:
        more.add("auto_match")
    return more


def _estimate_step(wf, base: set) -> Step:
    """The steps once 3 edges are assigned (or a pose is refined): candidates, ready, review."""
    c = wf.clicks
    more = _more(wf, base | ({"click_row", "remove_click"} if c.rows() else set()))
    if wf.last_refined is not None and wf.refined is None:
        return Step(
            "refine_again",
            "Clicks changed since Refine (the white ghost is the last refined pose): "
            "{refine} again to use them, then Accept.",
            frozenset(more - {"solve"} | {"refine"}),
        )
    if wf.candidates and wf.refined is None and len(wf.candidates) == 1:  # no other to pick
        return Step(
            "candidates",
            "The pose is drawn in white: add edges if it looks off, then {refine} — it uses "
            "every click and often corrects a pose that looks off.",
            frozenset(more),
        )
    if wf.candidates and wf.refined is None:
        return Step(
            "candidates",
            f"Candidate {(wf.chosen or 0) + 1} of {len(wf.candidates)} is drawn in white: pick "
            "another {choose_candidate} if it is clearly wrong, add edges, then {refine} — it uses every click and "
            "often corrects a candidate that looks off.",
            frozenset(more | {"choose_candidate"}),
        )
    if wf.refined is None:
        corner = c.one_corner()
        if corner is not None and not c.points_uv:  # said now, not after Solve
            return Step(
                "ready",
                f"Edges {', '.join(str(i + 1) for i in corner)} meet at one corner of "
                f"{wf.object_name}: they give its turn but not its distance. Click a fourth edge that does not "
                "pass through that corner, or {start_point} on another corner; or {refine} from the database "
                "pose for a small motion.",
                frozenset(more - {"solve"}),
            )
        if "solve" not in more:  # edges in several cameras, fewer than 3 in any one
            return Step(
                "ready",
                "{refine} from the database pose fits every camera's edges at once (a small motion); for a "
                "large one, click 3 edges in one camera, then Solve.",
                frozenset(more),
            )
        return Step(
            "ready",
            "{solve} for a large motion, or {refine} from the database pose for a small one; or click more edges.",
            frozenset(more),
        )
    extra = {"choose_candidate"} if wf.candidates else set()
    return Step(
        "review",
        f"Refined: RMS {wf.refined.rms_px:.2f} px. " + "{accept} to write it, or add clicks and {refine} again.",
        frozenset(more | extra | {"accept"}),
    )


# ---------------------------------------------------------------------------------------------- what is drawn
def marks(wf, view: str | None = None) -> Marks:
    """What to draw on camera ``view``'s image (the workflow's own for None): the clicks made in it, the
    estimate through its camera."""
    view = view or wf.view
    c, model = wf.clicks, wf.obj.model
    m = Marks(selected=wf.object_name)
    shown = None if wf.match.matches is None else wf.match.matches[wf.chosen or 0]  # awaiting confirmation
    here = [i for i, v in enumerate(c.seg_views) if v == view]  # the segments clicked in this camera
    pts_here = [i for i, v in enumerate(c.point_views) if v == view]
    if here:
        m.segments = np.array([c.segs[i] for i in here])
        ids = c.edge_ids if shown is None else [int(e) for e in shown.edges]
        m.labels = [
            (
                (c.segs[i][0] + c.segs[i][1]) / 2,
                f"{i + 1}" + (f"→e{ids[i]}" if ids[i] is not None else "?") + ("?" if shown is not None else ""),
            )
            for i in here
        ]
    if c.pending is not None and (c.pending_view or wf.view) == view:
        m.pending = c.pending.reshape(1, 2)
    if wf.search.click is not None and view == wf.view:  # the one click Find used
        m.circles = wf.search.click.reshape(1, 2)
        m.labels.append((wf.search.click + [8.0, -8.0], "click"))
    if pts_here:
        m.points = np.array([c.points_uv[i] for i in pts_here])
        m.labels += [(c.points_uv[i], f"v{c.vertex_ids[i]}") for i in pts_here]
    snaps = [c.seg_snaps[i] for i in here] + [c.point_snaps[i] for i in pts_here]
    m.raw_segments, m.raw_points, m.snap_lines, snap_labels = snap_marks(snaps)
    m.labels += snap_labels
    cam, T = wf.site.camera_of(view), wf.T_current
    if shown is None:  # the assigned model edges, orange, where the estimate draws them
        m.highlight = [(wf.object_name, e, T) for e in c.edge_ids if e is not None]
    else:  # the matched model edges, labelled where the shown candidate draws them
        S = model.edge_segments(shown.T_world_obj)[shown.edges]
        front = np.all(cam.depth(S.reshape(-1, 3)).reshape(-1, 2) > 0, axis=1)
        mids = cam.project(S.reshape(-1, 3)).reshape(-1, 2, 2).mean(axis=1)
        m.labels += [(mid + [0.0, -10.0], f"e{int(e)}") for mid, e, f in zip(mids, shown.edges, front) if f]
    if wf.refined is not None:
        m.ghosts = [Ghost(model, wf.refined.T_world_obj, "refined", chosen=True)]
    elif wf.last_refined is not None:  # clicks added since Refine: the estimate they are assigned on
        m.ghosts = [Ghost(model, wf.last_refined, "last refined", chosen=True)]
    else:
        m.ghosts = [Ghost(model, Tc, f"#{i + 1}", chosen=(i == wf.chosen)) for i, Tc in enumerate(wf.candidates)]
    if c.waiting_for_edge() and c.seg_views[-1] == view:  # which model edge: each visible one labelled
        wfm = model.wireframe(cam.center, T)
        vis = [int(k) for k, v, kind in zip(wfm.edge_index, wfm.visible, wfm.kind) if v and kind == "edge"]
        S = model.edge_segments(T)
        for k in vis:
            if k not in c.edge_ids and np.all(cam.depth(S[k]) > 0):
                m.labels.append((cam.project(S[k]).mean(axis=0) + [0.0, 8.0], f"e{k}"))
    if c.mode == "point" and c.pending_vertex is not None:
        X = T[:3, :3] @ model.vertices[c.pending_vertex] + T[:3, 3]
        m.pending = cam.project(X.reshape(1, 3))
    return m


# ---------------------------------------------------------------------------------------------- numbers and rows
def summary(wf) -> dict[str, Any]:
    """The numbers shown beside the workflow: clicks, snaps, candidates, assignments, the refined pose."""
    c = wf.clicks
    # edges clicked, and of them assigned to a model edge (an auto match assigns them all at once: it
    # showed "Edges: 0" beside "Clicked edges: 4")
    out: dict[str, Any] = {
        "object": wf.object_name,
        "edges clicked": len(c.segs),
        "edges assigned": len(c.assigned()),
        "points": len(c.points_uv),
    }
    snaps = [s for s in c.seg_snaps + c.point_snaps if s is not None]
    if snaps:
        n_seg = sum(1 for s in c.seg_snaps if s is not None)
        out["snapped"] = f"{sum(s.applied for s in snaps)} of {counted(n_seg, len(snaps) - n_seg)}"
    if wf.search.found is not None:
        out["found"] = wf.search.summary(wf.chosen or 0, wf.obj.T_world_obj)
    elif wf.candidates:  # the found poses' are in "found" (they were listed twice)
        out["candidates"] = len(wf.candidates)
        out["chosen"] = (wf.chosen or 0) + 1
    if wf.match.matches is not None:
        out["assignments"] = [
            {
                "candidate": i + 1,
                "edges": " ".join(f"e{int(e)}" for e in mt.edges),
                "rms_px": mt.rms_px,
                "image_px": mt.image_px,
            }
            for i, mt in enumerate(wf.match.matches)
        ]
    r = wf.refined
    if r is not None:
        out["rms_px"] = r.rms_px
        out["std_t_mm"] = [float(v) for v in 1000 * r.std_t_m]
        out["std_r_deg"] = [float(v) for v in r.std_r_deg]
        deg, m = pose_error(r.T_world_obj, wf.obj.T_world_obj)
        out["change"] = {"deg": float(deg), "mm": float(1000 * m)}
        out["clicks"] = [
            {"click": n, "residual_px": float(v), "weight": float(w)}
            for n, v, w in zip(_click_names(r.kinds), r.click_residuals_px, r.weights)
        ]
        seg_views, pt_views = c.click_views()
        cameras = seg_views + pt_views
        if len(set(cameras)) > 1 and len(cameras) == len(out["clicks"]):  # which camera each click was made in
            out["clicks"] = [{**row, "camera": v} for row, v in zip(out["clicks"], cameras)]
    return out


def _click_names(kinds) -> list[str]:
    return [f"edge {i + 1}" for i in range(kinds.count("segment"))] + [
        f"point {i + 1}" for i in range(kinds.count("point"))
    ]


def click_choices(wf) -> list[tuple[str, Any]]:
    """The Click chooser's rows: each clicked edge (its model edge, its camera when there are several) and
    point, with its residual after Refine."""
    c = wf.clicks
    res = None if wf.refined is None else list(wf.refined.click_residuals_px)
    several = len(set(c.seg_views + c.point_views)) > 1
    out, r = [], 0
    for kind, j in c.rows():
        if kind == "segment":
            e = c.edge_ids[j]
            text = f"edge {j + 1}" + (f" → e{e}" if e is not None else " (unassigned)")
            text += f" ({c.seg_views[j]})" if several else ""
            used = e is not None
        else:
            text = f"point {j + 1} (v{c.vertex_ids[j]}" + (f", {c.point_views[j]})" if several else ")")
            used = True
        if res is not None and used and r < len(res):
            text += f" · {res[r]:.1f} px"
        r += used
        out.append((text, len(out)))
    return out


def choices(wf, action: str) -> list[tuple[str, Any]]:
    """The options (text, value) of the chooser ``action``: the candidates, or the clicks."""
    if action == "choose_candidate":
        return [(label, i) for i, label in enumerate(candidate_labels(wf))]
    return click_choices(wf) if action == "click_row" else []


def choice_value(wf, action: str) -> Any:
    """The value a chooser shows now: the chosen candidate (None: the operator's last choice)."""
    return wf.chosen if action == "choose_candidate" else None


def candidate_labels(wf) -> list[str]:
    """One label per candidate for a chooser: "#1 (best)", "#2", ... (the found poses': how much matched)."""
    if wf.search.found is not None and len(wf.search.found) == len(wf.candidates):
        return wf.search.labels()
    return [f"#{i + 1}" + (" (best)" if i == 0 else "") for i in range(len(wf.candidates))]


def weaknesses(wf) -> list[str]:
    """Why the pose about to be accepted is weak (empty when it is not)."""
    r, c = wf.refined, wf.clicks
    if r is None:
        return wf.search.weaknesses(wf.chosen or 0) if wf.search.alone(wf.clicks, wf.refined) else []
    out = []
    sd, st = float(np.max(r.std_r_deg)), float(np.max(r.std_t_m)) * 1000
    if sd > WEAK_SIGMA_DEG or st > WEAK_SIGMA_MM:
        out.append(f"the pose is uncertain ({sigma_over(sd, st, WEAK_SIGMA_DEG, WEAK_SIGMA_MM)}); click more edges")
    names = [f"edge {j + 1}" for j in c.assigned()] + [f"point {j + 1}" for j in range(len(c.points_uv))]
    for name, res, sg in zip(names, r.click_residuals_px, c.sigmas()):
        if res > 3 * max(sg, 0.3):
            out.append(f"{name} is {res:.1f} px from the refined model (more than 3σ): a wrong click or assignment?")
    disagree = clicks_disagree(r, c.sigmas())
    if disagree:
        out.append(disagree)
    for what, snaps in (("edge", c.seg_snaps), ("point", c.point_snaps)):
        out += weak_snaps((f"{what} {j + 1}", sn) for j, sn in enumerate(snaps))
    if wf.refined_unseen:
        out.append(wf.refined_unseen)
    if len(r.kinds) * 2 <= 6 and wf.search.found is None:  # with a found pose the image's edges are the redundancy
        out.append(
            "no redundant click: the clicks fix the pose's 6 unknowns exactly, so a wrong one cannot show; "
            "click a fourth edge"
        )
    return out


def clicks_disagree(r, sigmas) -> str:
    """ "" when the refined clicks' residuals are as their σ say (χ² of the weighted residuals within its
    99.9 % quantile), else a sentence: the pose's σ is then understated. A new user's snapped clicks on
    real images landed on a neighbouring edge by 1-2 px, each within 3σ; the written pose was 7 σ off."""
    from scipy.stats import chi2

    sig = np.repeat(np.maximum(np.asarray(sigmas, float), 1e-6), 2)
    res, w = np.asarray(r.residuals_px, float), np.repeat(np.asarray(r.weights, float), 2)
    dof = len(res) - 6
    if dof <= 0:
        return ""
    q = float(np.sum(w * (res / sig) ** 2))
    if q <= chi2.ppf(0.999, dof):
        return ""
    return (
        f"the clicks disagree more than their σ says (RMS {r.rms_px:.2f} px against σ {float(np.median(sig)):.2f} px), "
        f"so the pose's σ is understated about {np.sqrt(q / dof):.1f}×: a snap may have landed on a neighbouring "
        "edge (Refuse snap on it), or a click is off (Delete click)"
    )


# ---------------------------------------------------------------------------------------------- sentences
AUTO_ASSIGN_WORDS = {
    True: "Automatic matching: click 3 or more image edges (4 is best), two points each, without assigning them; "
    "then Auto match.",
    False: "Assign each clicked edge by hand.",
}


def no_pose_fits(object_name: str, res) -> str:
    """Solve found nothing (``res``: ``core.pose.P3LCandidates``): why, for the first triples tried."""
    why = "; ".join(skipped_words(object_name, *s) for s in res.skipped[:3])
    return f"no pose fits these edges: {why}. Check the edge assignments (Remove last) or click other edges"


def no_plausible(starts, failures) -> str:
    """Refine found no plausible pose from any of its starts (``core.pose.pipeline.refine_starts``)."""
    if starts[0].prior is not None:
        return (
            f"the clicks do not agree with the found pose ({failures[0][1]}): check the edge assignments, or "
            "pick another found pose"
        )
    advice = "Check the edge assignments (Remove last and assign again), or add clicks (another edge, a point)"
    advice += "; for a large motion Solve first" if starts[-1].index is None else ""
    return "no plausible pose: " + "; ".join(f"{label}: {why}" for label, why in failures) + f". {advice}"


def history_record(wf) -> dict[str, Any]:
    """``site.update_pose``'s arguments for Accept: the found pose alone (method "search"), or the refined
    pose with the clicks, snaps, cameras and frames it used."""
    if wf.search.alone(wf.clicks, wf.refined):
        return wf.search.record(wf.chosen or 0, wf.frame_record())
    r, c = wf.refined, wf.clicks
    used = c.assigned()
    segs, _, pts, _ = c.arrays()
    other = {v: wf.frame_in(v) for v in c.all_views() if v != wf.view}
    clicks = {
        "segs_uv": segs,
        "edge_ids": [c.edge_ids[j] for j in used],
        "points_uv": pts,
        "vertex_ids": list(c.vertex_ids),
        "candidates": len(wf.candidates),
        "chosen": wf.chosen,
        # raw and snapped pixels of each segment and point above (None: snapping was off)
        "snaps": [None if c.seg_snaps[j] is None else c.seg_snaps[j].record() for j in used],
        "point_snaps": [None if s is None else s.record() for s in c.point_snaps],
        "assignment": "automatic" if wf.match.info is not None else "hand",
        "views": [c.seg_views[j] for j in used] + list(c.point_views),
        "frame": wf.frame_record(),  # the frozen frame the edges were clicked on
        "view_frames": {v: f.record() for v, f in other.items() if f is not None},
    }
    method = "match+refine" if wf.match.info is not None else ("p3l+refine" if wf.chosen is not None else "refine")
    if wf.match.info is not None:
        clicks["match"] = wf.match.info
    if wf.search.found is not None:
        method, clicks["search"] = "search+refine", wf.search.info
    residuals = {"rms_px": r.rms_px, "click_residuals_px": r.click_residuals_px, "kinds": list(r.kinds)}
    return dict(T_world_obj=r.T_world_obj, cov=r.cov, method=method, clicks=clicks, residuals=residuals)


def accepted_words(wf, version: int) -> str:
    """What Accept says once the pose is written."""
    if wf.refined is not None:
        return f"{wf.object_name} updated (version {version}): RMS {wf.refined.rms_px:.2f} px"
    c = wf.search.found[wf.chosen or 0]
    return f"{wf.object_name} updated (version {version}): found from one click, edges {c.fit_px:.1f} px off"


def solve_message(n_poses: int, n_triples: int, n_edges: int) -> str:
    every = f"all {n_edges} edges" if n_edges > 3 else "the 3 edges"
    return (
        f"{n_poses} candidate pose{'s' if n_poses > 1 else ''} from {n_triples} triple"
        f"{'s' if n_triples > 1 else ''} of edges, ranked by how well each fits {every}; the best is selected"
    )


def skipped_words(object_name: str, triple: tuple, kind: str, why: str) -> str:
    """Why a triple of clicked edges gave no pose, as the operator reads it."""
    edges = ", ".join(str(i + 1) for i in triple)
    if kind == "concurrent":
        return (
            f"edges {edges} meet at one corner of {object_name}: they give its turn but not its distance; "
            "click a fourth edge that does not pass through that corner, or Add point on another corner"
        )
    return f"edges {edges}: {why}"


def refine_message(wf, result, start, failures, unseen: str, views: list[str]) -> str:
    """What Refine says: the start used (and why earlier ones were not), RMS, the motion from the database
    (or the found) pose, σ, and a suspect outline."""
    sig_deg, sig_mm = float(np.max(result.std_r_deg)), 1000 * float(np.max(result.std_t_m))
    used = counted(result.kinds.count("segment"), result.kinds.count("point"))
    if start.prior is not None:  # the found pose and the clicks, together
        deg, m = pose_error(result.T_world_obj, start.T_world_obj)
        return (
            f"{start.label} refined with {used}: RMS {result.rms_px:.2f} px, moved {deg:.2f}° and "
            f"{1000 * m:.1f} mm from the found pose; σ up to {sig_deg:.2f}° and {sig_mm:.1f} mm"
            + (" (camera calibration included)" if "camera calibration" in result.cov_parts else "")
        )
    note = ""
    if failures and start.index is not None and start.index >= 0:
        note = (
            f"{'; '.join(f'{label}: {why}' for label, why in failures)} — not offered; {start.label} refined instead. "
        )
    if len(views) > 1:
        used += f" in cameras {', '.join(views)}"
    deg, m = pose_error(result.T_world_obj, wf.obj.T_world_obj)
    return (
        f"{note}RMS {result.rms_px:.2f} px over {used}; moved {deg:.2f}° and "
        f"{1000 * m:.1f} mm from the database pose; σ up to {sig_deg:.2f}° and {sig_mm:.1f} mm"
        + (" (camera calibration included)" if "camera calibration" in result.cov_parts else "")
        + (f". ⚠ {unseen}" if unseen else "")
    )


def unseen_outline(image, camera, model, T: np.ndarray) -> str:
    """ "" unless little of the model's visible outline at pose T lies on the frame's edges (less than
    ``MIN_OUTLINE_SEEN``, samples within 1.5 px of an edge of their orientation): then why the pose is
    suspect. The clicks can fit a wrong pose exactly — edges assigned as in a mirror, 4 edges for 6
    unknowns — while its drawing misses the object (a new operator: RMS 0.45 px, the box 40 px off).
    "" without a frame."""
    from app.vision.evaluate import outline_seen

    seen = None if image is None else outline_seen(image, camera, model, T)
    if seen is None or seen >= MIN_OUTLINE_SEEN:
        return ""
    return (
        f"only {100 * seen:.0f} % of the refined pose's outline lies on the image's edges, though the clicks fit: "
        "an edge assigned to the wrong model edge (a mirror image)? Compare the white ghost with the video, "
        "and Remove last to assign again"
    )
