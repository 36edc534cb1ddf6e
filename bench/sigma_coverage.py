"""Does a pose's stated σ cover its error? Tracking, update pose, one click (issue 27.1)

Run: .venv/bin/python bench/sigma_coverage.py [--draws 8] [--frames 40] [--model-sigma-mm 0.3]
     [--f-rel 0.003] [--c-px 1.0] [--exact-runs 6] [--castle-draws 20] [--only castle]

Per sequence and per world axis (translation x, y, z; rotation error R_est · R_trueᵀ as a rotation vector
about x, y, z): the share of frames whose |error| ≤ 2σ and the largest |error| / σ, with

* **old σ**: the tracker's σ before issue 27 (``PointLineFit.cov``: the residuals' variance times
  (Jᵀ W J)⁻¹, every edge sample an independent measurement), recomputed here at the same poses;
* **new σ**: ``app.vision.track.pose_covariance``: each edge's shared offset and tilt
  (``core.pose.uncertainty.edge_covariance``) plus, by first order, the camera's prior (a camera file:
  σ(f)/f = ``--f-rel``, σ(u0, v0) = ``--c-px``) and the model's (``--model-sigma-mm`` per edge, and √2 of it
  per extent: ``core.pose.uncertainty.model_scale_share``);
* **no-scale σ** (before the model's scale share, printed beside it in the same run): the new σ with the
  model's per-edge share alone (its extents given as 0 to the same code).

Target: 90–98 % within 2σ, never beyond 5σ (a σ too wide, 100 % and a largest ratio ≪ 2, is a defect too).
"RMS e/σ" is the RMS of error / σ (1 for a σ that is right on average). The frames of one run share one
camera and one model, so a run is about one draw, not as many as its frames: each row says what its frames
are worth in independent draws and the range of "within 2σ" that a right σ gives on so few (``spread``), and
the tracked rows the median χ²₆ = eᵀ Σ⁻¹ e of the full covariance (too wide below its 1 % point, 0.87).
Each tracked row prints its σ's shares per axis (``app.vision.track.pose_covariance_parts``).

Sequences (true poses):

* **rendered** (the tuning sequence): a 20 × 13 × 8 cm box on a smooth path at 0.8–1 m, rendered by the
  project's renderer (``app.vision.synthetic.render_poses``: 640×480, f = 600 px, blur σ = 0.5 px, noise
  σ = 2 grey levels). mcit is given a camera file and a model that differ from the truth by a realistic
  budget: fx, fy × (1 + ``--truth-f-rel``·N(0, 1)), u0, v0 + ``--truth-c-px``·N(0, 1) (a checkerboard
  calibration's error, the camera prior's values by default), each box dimension + ``--truth-dims-mm``·N(0, 1)
  (a box measured with a ruler, 0.5 mm); a new draw for each of ``--draws`` runs over the same frames. The
  model prior (``--model-sigma-mm``) was tuned here.
* **rendered, exact** (``--exact-runs``): the box along 6 stretches of path of 10 frames, tracked with its true
  camera and model, σ the edges' share alone: is that share too wide or too narrow on its own?
* **update pose** (held out): clicked edges (σ = 1 px) of the box at 300 random poses, each with its own draw
  of lens and sides, no image (``--click-draws``).
* **one-click** (held out): the one-click search on 30 rendered frames of the box in poses about the tracked
  one's, each with its own draw of camera file and model, from a start 2° / 1 cm off (``--clicks``).
* **Castle-simu** (ViSP's ``visp-images-data``, ``/usr/share/visp-images-data/ViSP-images/mbt-depth/
  Castle-simu``: 40 rendered 640×480 frames, ``CameraPose/Camera_NNN.txt`` the true cMo, ``Models/
  chateau.cao``, the camera of ``Config/chateau.xml``), tracked from its first true pose until lost;
  skipped when absent (``apt-get install visp-images-data``). As shipped: σ under each statement of its
  camera side by side on the same poses (a camera file's prior, the default, before; a renderer's camera,
  f exact and u0, v0 ± 0.5 px, ``mcit track --camera-sigma 0 0.5``, after; exact; exact with an exact
  model), the shares per axis, and where its images' edges sit against the model at the true poses (as a
  move of the file's principal point and focal length). Then ``--castle-draws`` runs with a camera file
  and a model drawn about its own by the ``rendered`` budget (the model's extents ± ``--truth-dims-mm``).
* **visp-cube** (``../shared/data``): real frames, no true pose but ViSP's own of frame 0
  (``cube.0.pos``): one frame, a reference rather than a truth. The teabox there has no pose at all.
"""

from __future__ import annotations

import argparse
import glob
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scipy.stats import binom, chi2  # noqa: E402

from app.models_io import load_model  # noqa: E402
from app.vision.sequence import iter_frames, read_visp_pose  # noqa: E402
from app.vision.synthetic import render_poses  # noqa: E402
from app.vision.track import EdgeTracker, pose_covariance_parts  # noqa: E402
from core.brep import BRep  # noqa: E402
from core.camera import Camera  # noqa: E402
from core.point_line_pose import point_line_residuals  # noqa: E402
from core.pose.uncertainty import (  # noqa: E402
    MODEL_EXTENT_PER_EDGE,
    MODEL_PRIOR_M,
    Priors,
    intrinsics_prior_cov,
)
from core.transforms import exp_so3, log_so3, make_T  # noqa: E402

CASTLE = Path("/usr/share/visp-images-data/ViSP-images/mbt-depth/Castle-simu")
DATA = (ROOT / ".." / "shared" / "data").resolve()
AXES = ("x", "y", "z", "rx", "ry", "rz")
SHARES = {"edges": "edges found on the image", "model": "model", "camera": "camera"}
NO_SCALE = np.zeros((2, 3))  # a model's bounds given as a point: its scale's share left out (the σ before it)


def old_cov(camera: Camera, T: np.ndarray, d) -> np.ndarray | None:
    """The tracker's σ before issue 27: PointLineFit's σ̂² (Jᵀ W J)⁻¹ at pose T on the last pass's samples."""
    keep = np.isfinite(d.matched_uv[:, 0]) & (d.weights > 0)
    if keep.sum() < 7:
        return None
    s, w = d.samples.subset(keep), d.weights[keep]
    r, J, _ = point_line_residuals(camera, T, s.X_obj, s.D_obj, d.matched_uv[keep])
    sigma2 = float(np.sum(w * r * r) / max(float(np.sum(w > 0)) - 6.0, 1.0))
    return sigma2 * np.linalg.inv((J * w[:, None]).T @ J)


def track_errors(camera, model, frames, truth, priors: Priors, stop_lost: bool = True, keep=None):
    """Per tracked frame: (error (6,), old σ (6,), new σ (6,), the new σ's shares by name (each (6,), σ per axis),
    χ²₆ = eᵀ Σ⁻¹ e with the new covariance Σ, the no-scale σ (6,));
    stops at the first lost frame. ``keep`` (a list): (T, diagnostics) of each frame appended to it."""
    tr = EdgeTracker(camera, model, truth[0])
    tr.priors = priors
    out = []
    for im, T_true in zip(frames, truth):
        T, _, lost = tr.track(im)
        d = tr.diagnostics
        if lost or d is None or d.cov is None:
            if stop_lost:
                break
            continue
        e = np.concatenate([T[:3, 3] - T_true[:3, 3], log_so3(T[:3, :3] @ T_true[:3, :3].T)])
        c_old = old_cov(camera, T, d)
        if c_old is None:
            continue
        parts = pose_covariance_parts(camera, T, d.samples, d.matched_uv, d.weights, priors, tr.bounds_m)
        shares = {k: np.sqrt(np.diag(v)) for k, v in parts.items()}
        chi2_6 = float(e @ np.linalg.solve(d.cov, e))
        before = sum(pose_covariance_parts(camera, T, d.samples, d.matched_uv, d.weights, priors, NO_SCALE).values())
        out.append((e, np.sqrt(np.diag(c_old)), np.sqrt(np.diag(d.cov)), shares, chi2_6, np.sqrt(np.diag(before))))
        if keep is not None:
            keep.append((T, d))
    return out


def _sd(cov: np.ndarray) -> np.ndarray:
    """σ per axis (6,) of a (6, 6) covariance."""
    return np.sqrt(np.diag(cov))


def spread(z: np.ndarray, groups: np.ndarray | None) -> tuple[float, int, int]:
    """(n_eff, lo %, hi %): the frames' worth in independent draws — n / (1 + (m − 1) ρ), ρ the share of
    e/σ's mean square that its runs' means hold (frames of one run share one camera file and one model), m the
    frames per run — and the range of "within 2σ" that 95 % of such sets give when σ is right (binomial,
    p = 95.4 %). ``groups``: each frame's run (None: one run)."""
    g = np.zeros(len(z), int) if groups is None else np.asarray(groups)
    _, inv, cnt = np.unique(g, return_inverse=True, return_counts=True)
    means = np.bincount(inv, weights=z) / cnt
    rho = min(1.0, float(np.sum(cnt * means**2) / max(float(np.sum(z**2)), 1e-300)))
    m = len(z) / len(cnt)
    n_eff = len(z) / (1.0 + (m - 1.0) * rho)
    n = max(int(round(n_eff)), 1)
    p = 0.9545
    return n_eff, int(round(100 * binom.ppf(0.025, n, p) / n)), int(round(100 * binom.ppf(0.975, n, p) / n))


def shares_table(rows, labels: dict[str, str]) -> None:
    """Median σ of each share of the new σ, per axis (a share's σ: the square root of its covariance's
    diagonal; the total's square is their squares' sum)."""
    print(f"  shares of the new σ (median over frames): {'':>13}" + " ".join(f"{a:>7}" for a in AXES))
    f = np.array([1e3] * 3 + [np.degrees(1.0)] * 3)
    for k, label in labels.items():
        if k in rows[0][3]:
            v = np.median([r[3][k] for r in rows], axis=0) * f
            print(f"    {label:<52}" + " ".join(f"{x:7.3f}" for x in v))
    print(f"    {'total':<52}" + " ".join(f"{x:7.3f}" for x in np.median([r[2] for r in rows], axis=0) * f))
    print(f"    {'RMS error':<52}" + " ".join(f"{x:7.3f}" for x in np.sqrt(np.mean([r[0] ** 2 for r in rows], 0)) * f))
    print("    (mm for x y z, degrees for rx ry rz)")


def table(name: str, rows, note: str = "", groups=None) -> None:
    """Per axis: RMS error, old, no-scale and new σ (median), within 2σ, largest |e|/σ, RMS e/σ; then the new σ's
    frames' worth in independent draws (``spread``) and the range of "within 2σ" that a right σ gives on so few.
    Rows: (e, old σ, new σ, shares or None, χ²₆ or None, no-scale σ)."""
    if not rows:
        print(f"{name}: no frame tracked{note}")
        return
    e = np.array([r[0] for r in rows])
    print(f"\n{name}: {len(rows)} frames{note}")
    head = f"{'σ':>9} {'≤2σ':>5} {'max/σ':>6} {'RMS e/σ':>7}"
    print(f"  {'axis':>4} | {'RMS error':>10} | old {head} | no scale {head} | new {head}")
    for k, ax in enumerate(AXES):
        unit, f = ("mm", 1e3) if k < 3 else ("°", np.degrees(1.0))
        cells = []
        for j in (1, 5, 2):
            s = np.array([r[j][k] for r in rows])
            z = np.abs(e[:, k]) / s
            within, rms_z = 100 * np.mean(z <= 2), np.sqrt(np.mean(z**2))
            cells.append(f"{f * np.median(s):7.3f}{unit:>2} {within:4.0f}% {z.max():6.1f} {rms_z:7.2f}")
        rms = f * np.sqrt(np.mean(e[:, k] ** 2))
        print(f"  {ax:>4} | {rms:8.3f}{unit:>2} | old {cells[0]} | no scale {cells[1]} | new {cells[2]}")
    z = e / np.array([r[2] for r in rows])
    sp = [spread(z[:, k], groups) for k in range(6)]
    print(
        f"  new σ: frames worth {min(s[0] for s in sp):.0f}–{max(s[0] for s in sp):.0f} independent draws per axis; "
        f"a right σ gives {min(s[1] for s in sp)}–{max(s[2] for s in sp)} % within 2σ in 95 % of such sets"
    )
    if rows[0][4] is not None:
        x2 = float(np.median([r[4] for r in rows]))
        print(
            f"  new σ: χ²₆ = eᵀ Σ⁻¹ e, median over frames, {x2:.2f}: "
            f"a right σ gives less in {100 * chi2.cdf(x2, 6):.1f} %"
        )


def rendered(args) -> None:
    W, H, f = 640, 480, 600.0
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]])
    cam_true = Camera.from_intrinsics(K, np.eye(4), W, H)
    dims = np.array([0.2, 0.13, 0.08])
    R0 = exp_so3([2.2, 0.4, 0.3])
    truth = []
    for k in range(args.frames):
        r = np.radians(8.0) * np.array([np.sin(k / 23.0), np.cos(k / 31.0), np.sin(k / 17.0)])
        p = np.array([0.08 * np.sin(k / 40.0), 0.05 * np.sin(k / 27.0), 0.9 + 0.08 * np.sin(k / 35.0)])
        truth.append(make_T(exp_so3(r) @ R0, p))
    frames = render_poses(cam_true, BRep.box(*dims), truth, noise_sigma=2.0, blur_sigma_px=0.5, seed=0)
    rng = np.random.default_rng(27)
    rows, groups = [], []
    for i in range(args.draws):
        Kb = K.copy()
        Kb[0, 0] *= 1 + args.truth_f_rel * rng.standard_normal()
        Kb[1, 1] *= 1 + args.truth_f_rel * rng.standard_normal()
        Kb[:2, 2] += args.truth_c_px * rng.standard_normal(2)
        cam = Camera.from_intrinsics(Kb, np.eye(4), W, H)
        model = BRep.box(*(dims + args.truth_dims_mm / 1e3 * rng.standard_normal(3)))
        priors = Priors(intrinsics_prior_cov(cam, args.f_rel, args.c_px), args.model_sigma_mm / 1e3)
        got = track_errors(cam, model, frames, truth, priors)
        rows += got
        groups += [i] * len(got)
    what = f"f × (1 ± {args.truth_f_rel:g}), u0, v0 ± {args.truth_c_px:g} px; sides ± {args.truth_dims_mm:g} mm"
    table(
        "rendered box (tuning sequence)",
        rows,
        f", {args.draws} draws of camera file and model about the truth: {what}",
        groups,
    )
    shares_table(rows, SHARES)


def rendered_exact(args) -> None:
    """The edges' share alone against the rendered box tracked with its true camera and model (no prior to
    cover): ``--exact-runs`` runs of 10 frames, each along its own stretch of path and its own noise."""
    if args.exact_runs < 1:
        return
    W, H, f = 640, 480, 600.0
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]])
    cam = Camera.from_intrinsics(K, np.eye(4), W, H)
    box = BRep.box(0.2, 0.13, 0.08)
    R0 = exp_so3([2.2, 0.4, 0.3])
    rows, groups = [], []
    for i in range(args.exact_runs):
        truth = []
        for k in range(10):
            r = np.radians(8.0) * np.array([np.sin((k + 13 * i) / 23.0), np.cos((k + 7 * i) / 31.0), np.sin(k / 17.0)])
            p = np.array([0.08 * np.sin((k + 11 * i) / 40.0), 0.05 * np.sin(k / 27.0), 0.9 + 0.08 * np.sin(k / 35.0)])
            truth.append(make_T(exp_so3(r) @ R0, p))
        frames = render_poses(cam, box, truth, noise_sigma=2.0, blur_sigma_px=0.5, seed=i)
        got = track_errors(cam, box, frames, truth, Priors(None, 0.0))
        rows += got
        groups += [i] * len(got)
    table(
        "rendered box with its true camera and model: the edges' share alone",
        rows,
        f", {args.exact_runs} runs of 10 frames",
        groups,
    )


def oneclick(args) -> None:
    """The one-click search (``app.vision.search.search_pose``, free pose) on rendered frames of the box, its camera
    file and model drawn about the truth as in ``rendered``, from a start 2° / 1 cm off, clicked at the box's
    projected centre. Old σ: the search's edges' share alone (its camera share needed a calibration in the
    database); new: with the camera file's and the model's priors; no scale: the same search again with the
    model's scale share left out (``app.vision.search.model_scale_share`` replaced here by a zero share)."""
    import app.vision.search as S
    from app.vision.search import NoPoseFits, search_pose

    W, H, f = 640, 480, 600.0
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]])
    cam_true = Camera.from_intrinsics(K, np.eye(4), W, H)
    dims = np.array([0.2, 0.13, 0.08])
    rng = np.random.default_rng(5)
    truth = [
        make_T(exp_so3(rng.normal(0, 0.3, 3)) @ exp_so3([2.2, 0.4, 0.3]), [0.0, 0.0, 0.9]) for _ in range(args.clicks)
    ]
    frames = render_poses(cam_true, BRep.box(*dims), truth, noise_sigma=2.0, blur_sigma_px=0.5, seed=1)
    rows = []
    for im, T_true in zip(frames, truth):
        Kb = K.copy()
        Kb[0, 0] *= 1 + args.truth_f_rel * rng.standard_normal()
        Kb[1, 1] *= 1 + args.truth_f_rel * rng.standard_normal()
        Kb[:2, 2] += args.truth_c_px * rng.standard_normal(2)
        cam = Camera.from_intrinsics(Kb, np.eye(4), W, H)
        model = BRep.box(*(dims + args.truth_dims_mm / 1e3 * rng.standard_normal(3)))
        start = make_T(exp_so3(np.radians(2.0) * rng.standard_normal(3) / np.sqrt(3)) @ T_true[:3, :3], T_true[:3, 3])
        start[:3, 3] += 0.01 * rng.standard_normal(3) / np.sqrt(3)
        click = cam_true.project_obj(T_true, model.vertices).mean(axis=0)
        found = []
        for share_fn in (S.model_scale_share, lambda J, *_: np.zeros((J.shape[1], J.shape[1]))):
            S.model_scale_share, keep_fn = share_fn, S.model_scale_share
            try:
                found.append(
                    search_pose(
                        cam,
                        model,
                        start,
                        click,
                        im,
                        camera_cov=intrinsics_prior_cov(cam, args.f_rel, args.c_px),
                        model_sigma_m=args.model_sigma_mm / 1e3,
                    ).candidates[0]
                )
            except NoPoseFits:
                break
            finally:
                S.model_scale_share = keep_fn
        if len(found) < 2 or found[0].cov is None or found[1].cov is None:
            continue
        c, b = found
        T = c.T_world_obj
        e = np.concatenate([T[:3, 3] - T_true[:3, 3], log_so3(T[:3, :3] @ T_true[:3, :3].T)])
        rows.append((e, np.sqrt(np.diag(c.cov - c.cov_camera)), np.sqrt(np.diag(c.cov)), None, None, _sd(b.cov)))
    table(
        "one-click search, rendered box (held out)",
        rows,
        f" of {args.clicks} clicks, one draw of camera and model each",
        np.arange(len(rows)),
    )


def clicks(args) -> None:
    """Update pose from clicked edges (``core.pose.refine_views``, then the shares ``refine_starts`` adds), each
    draw independent: the box at a random pose 0.7–1.1 m away, its true sides and the true lens drawn as in
    ``rendered``, every visible edge clicked twice along its true image with σ = 1 px; solved with the file's
    lens and the nominal model. Old σ: the clicks' alone."""
    from core.pose.refine import ViewClicks, refine_views
    from core.pose.synthetic import clicks_on_edges
    from core.pose.uncertainty import with_views_camera_uncertainty

    W, H, f = 640, 480, 600.0
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]])
    cam = Camera.from_intrinsics(K, np.eye(4), W, H)
    dims = np.array([0.2, 0.13, 0.08])
    rng = np.random.default_rng(7)
    rows = []
    while len(rows) < args.click_draws:
        T_true = make_T(
            exp_so3(rng.normal(0, 0.4, 3)) @ exp_so3([2.2, 0.4, 0.3]),
            [*rng.uniform(-0.1, 0.1, 2), rng.uniform(0.7, 1.1)],
        )
        Kt = K.copy()
        Kt[0, 0] *= 1 + args.truth_f_rel * rng.standard_normal()
        Kt[1, 1] *= 1 + args.truth_f_rel * rng.standard_normal()
        Kt[:2, 2] += args.truth_c_px * rng.standard_normal(2)
        true_cam = Camera.from_intrinsics(Kt, np.eye(4), W, H)
        true_box = BRep.box(*(dims + args.truth_dims_mm / 1e3 * rng.standard_normal(3)))
        wf = true_box.wireframe(true_cam.center, T_true)
        idx = wf.edge_index[wf.visible & (wf.edge_index >= 0)]
        segs, _ = clicks_on_edges(rng, true_cam, T_true, true_box.edge_segments()[idx], sigma_px=1.0)
        edges = BRep.box(*dims).edge_segments()[idx]
        view = ViewClicks(cam, segs, edges, sigma_px=1.0)
        try:
            r = refine_views([view], T_true)
        except ValueError:
            continue
        new, before = (
            with_views_camera_uncertainty(
                r,
                [view],
                [intrinsics_prior_cov(cam, args.f_rel, args.c_px)],
                model_sigma_m=args.model_sigma_mm / 1e3,
                model_bounds_m=ext,
            )
            for ext in (BRep.box(*dims).bounds(), NO_SCALE)
        )
        T = r.T_world_obj
        e = np.concatenate([T[:3, 3] - T_true[:3, 3], log_so3(T[:3, :3] @ T_true[:3, :3].T)])
        rows.append((e, _sd(r.cov), _sd(new.cov), None, None, _sd(before.cov)))
    table(
        "update pose from clicked edges, σ = 1 px (held out)",
        rows,
        ", each an independent draw of pose, lens and sides",
        np.arange(len(rows)),
    )


# What an operator knows of a renderer's camera file (``mcit track --camera-sigma 0 0.5``): the focal length is the
# renderer's own, the principal point known to the half pixel by which the two pixel conventions (a pixel's centre
# at integers, as ViSP, OpenCV and mcit, or at halves, as OpenGL and Blender) differ when the renderer does not say.
RENDERER_F_REL, RENDERER_C_PX = 0.0, 0.5


def castle_data():
    """(camera file's camera, model, frames, true poses) of Castle-simu, or None when absent."""
    poses = sorted(glob.glob(str(CASTLE / "CameraPose" / "*.txt")))
    if not poses:
        print(f"\nCastle-simu: not found at {CASTLE} (apt-get install visp-images-data; skipped)")
        return None
    truth = [np.loadtxt(p) for p in poses]
    frames = [cv2.imread(p, cv2.IMREAD_GRAYSCALE) for p in sorted(glob.glob(str(CASTLE / "Images" / "*.pgm")))]
    model = load_model(str(CASTLE / "Models" / "chateau.cao"))
    cam = Camera.from_intrinsics(np.array([[700.0, 0, 320], [0, 700, 240], [0, 0, 1]]), np.eye(4), 640, 480)
    return cam, model, frames, truth


def image_against_file(cam: Camera, kept, truth) -> np.ndarray:
    """(du, dv, δf/f): how far the image's edges sit from the model projected at the true poses through the
    camera file, as a move of its principal point and a scale of its focal length (least squares over every
    edge sample the tracker found: r = n·(image edge − projection) ≈ n·(du, dv) + δf/f · n·(uv − c))."""
    K, _ = cam.decompose()
    A, b = [], []
    for (_, d), T_true in zip(kept, truth):
        ok = np.isfinite(d.matched_uv[:, 0]) & (d.weights > 0)
        s = d.samples.subset(ok)
        r, _, n = point_line_residuals(cam, T_true, s.X_obj, s.D_obj, d.matched_uv[ok])
        uv = cam.project_obj(T_true, s.X_obj)
        A.append(np.column_stack([n, np.sum(n * (uv - K[:2, 2]), axis=1)]))
        b.append(r)
    return np.linalg.lstsq(np.vstack(A), np.concatenate(b), rcond=None)[0]


def castle(args) -> None:
    """Castle-simu tracked with its own camera file and model, the σ under several statements of what is known of
    them, side by side on the same poses; then draws of camera file and model about them (``castle_draws``)."""
    data = castle_data()
    if data is None:
        return
    cam, model, frames, truth = data
    msig = args.model_sigma_mm / 1e3
    ext = model.bounds()
    per_extent = MODEL_EXTENT_PER_EDGE * args.model_sigma_mm
    statements = {
        f"a camera file's prior ({100 * args.f_rel:g} %, {args.c_px:g} px; before)": Priors(
            intrinsics_prior_cov(cam, args.f_rel, args.c_px), msig
        ),
        f"a renderer's camera (--camera-sigma 0 {RENDERER_C_PX:g}; after)": Priors(
            intrinsics_prior_cov(cam, RENDERER_F_REL, RENDERER_C_PX), msig
        ),
        "camera exact (--camera-sigma 0 0)": Priors(None, msig),
        "camera exact, the model's per-edge share alone (no scale)": Priors(None, msig),
        "camera exact and model exact: the edges' share alone": Priors(None, 0.0),
    }
    kept: list = []
    rows = track_errors(cam, model, frames, truth, next(iter(statements.values())), keep=kept)
    if not rows:
        print("\nCastle-simu: no frame tracked")
        return
    table("Castle-simu (ViSP), its camera file and model as shipped", rows, f" of {len(frames)} (until lost)")
    e = np.array([r[0] for r in rows])
    f = np.array([1e3] * 3 + [np.degrees(1.0)] * 3)
    print(
        f"  mean error (mm, °): {' '.join(f'{x:.3f}' for x in e.mean(0) * f)}; its scatter about the mean: "
        f"{' '.join(f'{x:.3f}' for x in e.std(0) * f)} (a bias: the frames are about one draw)"
    )
    du, dv, df = image_against_file(cam, kept, truth[: len(kept)])
    print(
        f"  the images' edges against the model at the true poses through the camera file: as if u0 moved by "
        f"{du:+.2f} px, v0 by {dv:+.2f} px, f by {100 * df:+.3f} %"
    )
    by = {}
    for name, pr in statements.items():
        x = NO_SCALE if "no scale" in name else ext
        covs = [sum(pose_covariance_parts(cam, T, d.samples, d.matched_uv, d.weights, pr, x).values()) for T, d in kept]
        by[name] = covs
    sh = [
        {
            **r[3],
            "renderer camera": np.sqrt(
                np.diag(
                    pose_covariance_parts(
                        cam, T, d.samples, d.matched_uv, d.weights, statements[list(statements)[1]], ext
                    )["camera"]
                )
            ),
        }
        for r, (T, d) in zip(rows, kept)
    ]
    shares_table(
        [(r[0], r[1], r[2], s) for r, s in zip(rows, sh)],
        {
            "edges": "edges found on the image",
            "model": f"model ({args.model_sigma_mm:g} mm per edge, {per_extent:.2f} per extent)",
            "camera": f"camera: a camera file's prior ({100 * args.f_rel:g} %, {args.c_px:g} px)",
            "renderer camera": f"camera: a renderer's (f exact, u0 v0 ± {RENDERER_C_PX:g} px)",
        },
    )
    print("  the same poses, σ by statement (per axis x y z rx ry rz; χ²₆ = eᵀ Σ⁻¹ e, median over frames, and the")
    print("  chance P that a right σ gives less: below 1 % too wide, above 99 % too narrow)")
    print(f"    {'statement':<66} {'within 2σ %':<24} {'largest |e|/σ':<30} χ²₆ (P)")
    for name, covs in by.items():
        sg = np.sqrt(np.array([np.diag(c) for c in covs]))
        z = np.abs(e) / sg
        x2 = float(np.median([v @ np.linalg.solve(c, v) for v, c in zip(e, covs)]))
        print(
            f"    {name:<66} {' '.join(f'{x:3.0f}' for x in 100 * np.mean(z <= 2, 0)):<24} "
            f"{' '.join(f'{x:4.1f}' for x in z.max(0)):<30} {x2:5.2f} ({100 * chi2.cdf(x2, 6):.1f} %)"
        )
    castle_draws(args, cam, model, frames, truth)


def castle_draws(args, cam0: Camera, model0, frames, truth) -> None:
    """Castle-simu with ``--castle-draws`` camera files and models drawn about its own (the budget of ``rendered``:
    f × (1 ± ``--truth-f-rel``), u0, v0 ± ``--truth-c-px``; the model's extents ± ``--truth-dims-mm``, each axis
    scaled), σ with the camera file's prior: the frames of one draw share its errors, so many draws show how
    often σ covers them."""
    from dataclasses import replace

    if args.castle_draws < 1:
        return
    K0, _ = cam0.decompose()
    V = np.asarray(model0.vertices)
    ext = V.max(0) - V.min(0)
    rng = np.random.default_rng(28)
    rows, groups = [], []
    for i in range(args.castle_draws):
        K = K0.copy()
        K[0, 0] *= 1 + args.truth_f_rel * rng.standard_normal()
        K[1, 1] *= 1 + args.truth_f_rel * rng.standard_normal()
        K[:2, 2] += args.truth_c_px * rng.standard_normal(2)
        cam = Camera.from_intrinsics(K, np.eye(4), cam0.width, cam0.height)
        model = replace(model0, vertices=V * (1 + args.truth_dims_mm / 1e3 * rng.standard_normal(3) / ext))
        priors = Priors(intrinsics_prior_cov(cam, args.f_rel, args.c_px), args.model_sigma_mm / 1e3)
        got = track_errors(cam, model, frames, truth, priors)
        rows += got
        groups += [i] * len(got)
    what = f"f × (1 ± {args.truth_f_rel:g}), u0, v0 ± {args.truth_c_px:g} px; extents ± {args.truth_dims_mm:g} mm"
    table(
        "Castle-simu, camera file and model drawn about its own (held out)",
        rows,
        f", {args.castle_draws} draws: {what}; σ with the camera file's prior",
        groups,
    )


def cube(args) -> None:
    d = DATA / "visp-cube"
    if not (d / "cube.0.pos").is_file():
        print(f"\nvisp-cube: not found at {d} (skipped)")
        return
    from app.camera_io import read_intrinsics

    K = read_intrinsics(d / "cube.xml").K
    cam = Camera.from_intrinsics(K, np.eye(4), 640, 480)
    _, im = next(iter_frames(d / "frames", 0, 1))
    priors = Priors(intrinsics_prior_cov(cam, args.f_rel, args.c_px), args.model_sigma_mm / 1e3)
    T0 = read_visp_pose(d / "cube.0.pos")
    rows = track_errors(cam, load_model(str(d / "cube.cao")), [cv2.cvtColor(im, cv2.COLOR_RGB2GRAY)], [T0], priors)
    table("visp-cube frame 0 against ViSP's cube.0.pos (a reference, not a truth)", rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--model-sigma-mm", type=float, default=1000 * MODEL_PRIOR_M)
    ap.add_argument("--f-rel", type=float, default=0.003)
    ap.add_argument("--c-px", type=float, default=1.0)
    ap.add_argument("--truth-f-rel", type=float, default=0.003)
    ap.add_argument("--truth-c-px", type=float, default=1.0)
    ap.add_argument("--truth-dims-mm", type=float, default=0.5)
    ap.add_argument("--exact-runs", type=int, default=6, help="rendered box runs with its true camera and model")
    ap.add_argument("--castle-draws", type=int, default=20, help="Castle-simu runs with a drawn camera and model")
    ap.add_argument("--clicks", type=int, default=30, help="one-click searches (each its own frame and draw)")
    ap.add_argument("--click-draws", type=int, default=300, help="update-pose draws")
    ap.add_argument("--only", choices=("rendered", "exact", "clicks", "oneclick", "castle", "cube"))
    args = ap.parse_args()
    print(
        f"σ coverage of poses; priors: camera σ(f)/f = {args.f_rel:g}, σ(u0, v0) = {args.c_px:g} px; "
        f"model {args.model_sigma_mm:g} mm per edge, √2 of it per extent. Target: 90–98 % within 2σ, none beyond 5σ."
    )
    for name, fn in (
        ("rendered", rendered),
        ("exact", rendered_exact),
        ("clicks", clicks),
        ("oneclick", oneclick),
        ("castle", castle),
        ("cube", cube),
    ):
        if args.only in (None, name):
            fn(args)


if __name__ == "__main__":
    main()
