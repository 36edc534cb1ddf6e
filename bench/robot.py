"""Benchmark of the robot's kinematics and collision check (core.robot, app.robot.collision) beside their anchors.

Run: .venv/bin/python bench/robot.py [--targets 100] [--seed 0]

Set-up: the bundled workcell's arm (scenes/workcell/arm.urdf: a UR5's kinematics, boxes and cylinders,
a two-finger gripper) at its scene pose, home = the scene's (UR's ready pose).

* FK, Jacobian: the tool's pose (and its geometric Jacobian) at random joint positions within the
  limits: ours (``RobotModel.tool_pose``, ``jacobian``; also per configuration in a batch of 200,
  ``tool_poses``) beside Pinocchio (``framesForwardKinematics``, ``computeFrameJacobian``) on the
  same URDF; the largest difference of the two tool poses is printed (a cross-check of ours).
* IK: targets = the tool's pose at random joint positions within the limits (all reachable), solved
  from home. Ours: ``solve_ik`` (8 seeds in one batch, the default; and 1 seed). Anchor: the
  closed-loop IK of Pinocchio's documentation (damped least squares on log6 of the pose error, the
  Jacobian through Jlog6; here with full steps, where its example's dt = 0.1 takes about ten times
  the iterations; damping 1e-6; joint limits by clipping), from home, then from 7 random seeds one
  after the other until one converges; the same tolerances (1e-5 m, 1e-4 rad), at most 200 steps
  a start.
* Preview: what a click on a target costs before the ghost robot is shown: IK from home, the straight
  joint path sampled at half the thinnest link (``joint_path``), its collision check against the
  scene's bodies (margin 1 cm) up to the first contact (``check_path``). Targets: 10 cm above each
  object's top (tool pointing down) and 5 cm above the table 22 cm before each (towards the front
  camera), at the parallelepiped's first and last poses. The narrow phase (python-fcl's signed
  distance) is replayed with coal (the maintained successor of hpp-fcl) on the same calls,
  geometries and poses.

Times: wall-clock per call (time.perf_counter_ns; best of 3 repeats for FK and the Jacobian, one run
for the rest), medians and maxima over the targets; one process pinned to one core, one BLAS thread;
the load average is printed (the machine is shared: times grow with it).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ["OMP_NUM_THREADS"] = "1"
os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ["MKL_NUM_THREADS"] = "1"

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchenv import pin_one_core  # noqa: E402

import app.robot.collision as collision  # noqa: E402
from app.robot.collision import CollisionChecker  # noqa: E402
from app.robot.urdf import load_scene_robot  # noqa: E402
from app.scene import default_scene_path, load_scene  # noqa: E402
from core.robot import joint_path, solve_ik  # noqa: E402
from core.transforms import invert_T, log_so3, make_T  # noqa: E402

POS_TOL, ROT_TOL = 1e-5, 1e-4


def wall_us(f, repeats: int = 3) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        f()
        best = min(best, time.perf_counter_ns() - t0)
    return best / 1e3


class Pinocchio:
    """The anchor: Pinocchio on the same URDF; q mapped from ours by joint name (the mimic finger follows)."""

    def __init__(self, urdf: Path, model):
        import pinocchio as pin

        self.pin = pin
        self.model = pin.buildModelFromUrdf(str(urdf))
        self.data = self.model.createData()
        self.frame = self.model.getFrameId(model.tool)
        self.ours = model
        self.index = []
        for name in self.model.names[1:]:
            j = model.joint(name)
            k = model.joint_names.index(j.mimic.joint if j.mimic else name)
            self.index.append((k, j.mimic.multiplier if j.mimic else 1.0, j.mimic.offset if j.mimic else 0.0))
        self.vary = np.array([model.moves_tool()[k] for k, _, _ in self.index])

    def q(self, q_ours: np.ndarray) -> np.ndarray:
        return np.array([m * q_ours[k] + o for k, m, o in self.index])

    def tool_pose(self, q: np.ndarray) -> np.ndarray:
        self.pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.frame].homogeneous

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        return self.pin.computeFrameJacobian(self.model, self.data, q, self.frame, self.pin.LOCAL_WORLD_ALIGNED)

    def clik(self, T_target: np.ndarray, q0: np.ndarray, max_iter: int = 200, damp: float = 1e-6) -> np.ndarray | None:
        """Pinocchio's documented CLIK (full steps, damped), limits by clipping: q on success, else None."""
        pin = self.pin
        target = pin.SE3(T_target[:3, :3], T_target[:3, 3])
        q = q0.copy()
        for _ in range(max_iter):
            pin.framesForwardKinematics(self.model, self.data, q)
            current = self.data.oMf[self.frame]
            iMd = current.actInv(target)
            err = pin.log(iMd).vector
            if (
                np.linalg.norm(current.translation - target.translation) < POS_TOL
                and np.linalg.norm(log_so3(current.rotation.T @ target.rotation)) < ROT_TOL
            ):
                return q
            J = pin.computeFrameJacobian(self.model, self.data, q, self.frame)
            J = -pin.Jlog6(iMd.inverse()) @ J
            J[:, ~self.vary] = 0.0
            v = -J.T @ np.linalg.solve(J @ J.T + damp * np.eye(6), err)
            q = np.clip(pin.integrate(self.model, q, v), self.model.lowerPositionLimit, self.model.upperPositionLimit)
        return None


def pinocchio_or_none(urdf: Path, model):
    try:
        return Pinocchio(urdf, model)
    except ImportError:
        return None


def kinematics(model, pin, rng, n: int) -> list[tuple[str, float, float | None]]:
    Q = np.array([rng.uniform(model.lower, model.upper) for _ in range(n)])
    rows = []
    ours_fk = np.median([wall_us(lambda q=q: model.tool_pose(q)) for q in Q])
    ours_j = np.median([wall_us(lambda q=q: model.jacobian(q)) for q in Q])
    batch = wall_us(lambda: model.tool_poses(np.resize(Q, (200, model.n)))) / 200
    pin_fk = pin_j = None
    if pin is not None:
        P = [pin.q(q) for q in Q]
        pin_fk = np.median([wall_us(lambda p=p: pin.tool_pose(p)) for p in P])
        pin_j = np.median([wall_us(lambda p=p: pin.jacobian(p)) for p in P])
        diff = max(np.abs(model.tool_pose(q) - pin.tool_pose(p)).max() for q, p in zip(Q, P))
        rows.append(("FK: largest |ours − Pinocchio| of the tool pose", diff, None))
    rows += [
        ("FK per call, µs", ours_fk, pin_fk),
        ("FK per configuration in a batch of 200, µs", batch, None),
        ("Jacobian per call, µs", ours_j, pin_j),
    ]
    return rows


def inverse(model, pin, home, rng, n: int) -> list[tuple]:
    targets = [model.tool_pose(rng.uniform(model.lower, model.upper)) for _ in range(n)]
    out = []
    for label, seeds in (("ours, 8 seeds (default)", 8), ("ours, 1 seed", 1)):
        times, ok = [], 0
        for T in targets:
            t0 = time.perf_counter_ns()
            r = solve_ik(model, T, home, seeds=seeds)
            times.append((time.perf_counter_ns() - t0) / 1e6)
            ok += r.ok
        out.append((label, ok / n, np.median(times), np.max(times)))
    if pin is not None:
        seed_rng = np.random.default_rng(1)
        times, ok = [], 0
        for T in targets:
            starts = [home] + [seed_rng.uniform(model.lower, model.upper) for _ in range(7)]
            t0 = time.perf_counter_ns()
            found = next((q for s in starts if (q := pin.clik(T, pin.q(s))) is not None), None)
            times.append((time.perf_counter_ns() - t0) / 1e6)
            ok += found is not None
        out.append(("Pinocchio CLIK, home then up to 7 seeds", ok / n, np.median(times), np.max(times)))
    return out


class Recorder:
    """Records the narrow phase's calls (the two fcl objects' geometries and poses) for a replay with coal."""

    def __init__(self):
        self.calls = []
        self.original = collision._distance

    def __enter__(self):
        def record(a, b):
            self.calls.append((a, b))
            return self.original(a, b)

        collision._distance = record
        return self

    def __exit__(self, *exc):
        collision._distance = self.original


def coal_replay(checker, calls) -> tuple[float, float] | None:
    """(fcl µs per call, coal µs per call) on the recorded calls (geometries rebuilt in coal), or None."""
    try:
        import coal
    except ImportError:
        return None

    def make(part):
        kind, p = part.kind, part.params
        if kind in ("box", "cylinder", "cone", "sphere"):
            return {"box": coal.Box, "cylinder": coal.Cylinder, "cone": coal.Cone, "sphere": coal.Sphere}[kind](*p)
        V, T = p
        mesh = coal.BVHModelOBBRSS()
        mesh.beginModel(len(T), len(V))
        mesh.addVertices(V)
        mesh.addTriangles(T)
        mesh.endModel()
        if kind == "convex":
            mesh.buildConvexHull(True, "Qt")
            return mesh.convex
        return mesh

    geometry = {id(o): make(part) for o, part in zip(checker._objects, checker.parts)}
    geometry.update({id(o): make(part) for o, (part, _) in zip(checker._obstacles, checker.obstacle_parts)})
    poses = [(a.getRotation(), a.getTranslation(), b.getRotation(), b.getTranslation()) for a, b in calls]
    fcl_objects = [(a, b) for a, b in calls]
    request = coal.DistanceRequest()

    def run_coal():
        for (a, b), (Ra, ta, Rb, tb) in zip(fcl_objects, poses):
            coal.distance(
                geometry[id(a)], coal.Transform3s(Ra, ta), geometry[id(b)], coal.Transform3s(Rb, tb), request,
                coal.DistanceResult(),
            )  # fmt: skip

    def run_fcl():
        for (a, b), (Ra, ta, Rb, tb) in zip(fcl_objects, poses):
            a.setTransform(collision.fcl.Transform(Ra, ta))
            b.setTransform(collision.fcl.Transform(Rb, tb))
            collision.fcl.distance(a, b, collision.fcl.DistanceRequest(enable_signed_distance=True))

    n = max(len(calls), 1)
    return wall_us(run_fcl) / n, wall_us(run_coal) / n


def preview(scene, model, home) -> tuple[list, list]:
    checker = CollisionChecker(model, scene.robot.T_world_base)
    down = np.diag([1.0, -1.0, -1.0])
    rows, calls_all, replays = [], 0, []
    for t_s in (0.0, 26.0):
        checker.set_obstacles([(b.name, b.model, b.pose_at(t_s), 0.01) for b in scene.bodies if b.status != "scenery"])
        for name in ("unknown_box", "parallelepiped", "unknown_cylinder"):
            b = scene.body(name)
            p = b.pose_at(t_s)[:3, 3]
            for label, target in (
                (f"{name} top +10 cm", p + [0, 0, b.model.bounds()[1, 2] + 0.10]),
                (f"table 22 cm before {name}", p + [0, -0.22, 0.05]),
            ):
                T = invert_T(scene.robot.T_world_base) @ make_T(down, target)
                t0 = time.perf_counter_ns()
                r = solve_ik(model, T, home)
                t1 = time.perf_counter_ns()
                Q = joint_path(model, home, r.q, checker.path_step_m)
                t2 = time.perf_counter_ns()
                with Recorder() as rec:
                    result = checker.check_path(Q)
                t3 = time.perf_counter_ns()
                calls_all += len(rec.calls)
                replay = coal_replay(checker, rec.calls)
                if replay is not None:
                    replays.append((len(rec.calls), *replay))
                verdict = "free" if result.ok else f"{result.link}↔{result.other}"
                rows.append((f"t={t_s:4.1f} {label}", r.ok, len(Q), len(rec.calls), (t1 - t0) / 1e6,
                             (t2 - t1) / 1e6, (t3 - t2) / 1e6, (t3 - t0) / 1e6, verdict))  # fmt: skip
    return rows, replays


def clicks(scene) -> list[tuple]:
    """What the operator waits for after a click in Move robot: ``RobotCell.plan_approach`` (the tool's turn
    about the approach axis searched, IK, both legs of the path, the check against the database's objects)
    on the browser tests' targets, from home."""
    import tempfile

    from app.db import Database, seed_from_scene
    from app.robot.cell import obstacles_of
    from app.robot.setup import open_robot
    from app.workflows import Site

    robot = open_robot(scene)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        db = Database.open(Path(tmp) / "site.sqlite")
        seed_from_scene(db, scene)
        site = Site(scene, db, robot=robot.cell, frames=None)
        obstacles = obstacles_of(site.objects())
        box = site.object("parallelepiped").vertices_world()
        for label, X in (
            ("table (0.15, -0.25)", np.array([0.15, -0.25, 0.0])),
            ("parallelepiped's top", box[np.argsort(box[:, 2])[-4:]].mean(axis=0)),
            ("table against the parallelepiped", np.array([-0.02, 0.06, 0.0])),
            ("table's far corner (out of reach)", np.array([0.42, 0.65, 0.0])),
        ):
            t0 = time.perf_counter()
            plan = robot.cell.plan_approach(X, np.array([0.0, 0.0, 1.0]), 0.02, obstacles)
            rows.append((label, (time.perf_counter() - t0) * 1e3, plan.ok, plan.samples_checked, plan.reason))
        db.close()
    robot.close()
    return rows


def live_video(scene, frames: int = 48) -> dict:
    """The live site with the robot moving, front camera, 512×256: frames/s rendered (one core, every frame a
    new robot pose) and the robot's visible link edges in the noise-free frame against C's projection, beside
    the ray-cast renderer's (the recordings') on the same bodies."""
    import dataclasses

    from app.render.live import LiveRenderer, scene_bodies
    from app.render.measure import edge_offsets, visible_edges
    from app.render.renderer import Renderer
    from app.robot.setup import open_robot
    from app.scene import Body

    robot = open_robot(scene)
    model, world = robot.cell.model, robot.world
    q0 = robot.cell.state().q
    target = make_T(np.diag([1.0, -1.0, -1.0]), np.array([-0.05, -0.2, 0.15]))
    q1 = solve_ik(model, invert_T(scene.robot.T_world_base) @ target, q0).q
    from app.robot.controller import JointState

    with LiveRenderer(scene, scene.views[0].name) as live:
        c0 = time.process_time()
        for k in range(frames):
            q = q0 + (q1 - q0) * k / (frames - 1)
            world.on_state(JointState(model.joint_names, q, True, 0.0))
            live.render(world.bodies_at(0.0), k)
        fps = frames / (time.process_time() - c0)
        links = [Body(b.name, "robot", "known", b.brep, b.T_world, (), b.appearance)
                 for b in world.bodies_at(0.0) if b.name.startswith("robot/")]  # fmt: skip
        with_robot = dataclasses.replace(scene, bodies=tuple(scene.bodies) + tuple(links))
        ray = Renderer(with_robot)
        edges = [e for e in visible_edges(with_robot, ray, 0.0, min_px=15.0) if e[0].startswith("robot/")]
        img_live = live.render(scene_bodies(with_robot, 0.0), 0, noise=False, blur=False)
    img_ray = ray.render(0.0, noise=False, blur=False)
    robot.close()
    per, means = {}, {}
    for name, img in (("live (moderngl, 2x2 + MSAA 4)", img_live), ("ray-cast (the recordings')", img_ray)):
        means[name] = np.array([np.nanmean(edge_offsets(img.astype(float), uv)) for _, _, uv in edges])
        per[name] = (float(np.nanmedian(np.abs(means[name]))), float(np.nanmax(np.abs(means[name]))))
    diff = np.abs(np.subtract(*means.values()))  # the live renderer's own error (shading's effect on both removed)
    per["live − ray-cast, per edge"] = (float(np.nanmedian(diff)), float(np.nanmax(diff)))
    return {"fps": fps, "edges": len(edges), "offsets": per}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--targets", type=int, default=100, help="random IK targets and FK configurations")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    pinned = pin_one_core()
    scene = load_scene(default_scene_path())
    model, home = load_scene_robot(scene.robot)
    pin = pinocchio_or_none(scene.robot.urdf_path, model)
    rng = np.random.default_rng(args.seed)
    print(__doc__.split("\n\n")[0])
    print(
        f"\n{pinned}; numpy {np.__version__}; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
        f"Pinocchio {'absent (pip install pin): its columns are left empty' if pin is None else pin.pin.__version__}\n"
    )
    print(f"{'kinematics':52s}{'ours':>12s}{'Pinocchio':>12s}")
    for label, ours, anchor in kinematics(model, pin, rng, args.targets):
        fmt = (lambda v: f"{v:12.2e}") if "largest" in label else (lambda v: f"{v:12.1f}")
        print(f"{label:52s}{fmt(ours)}{fmt(anchor) if anchor is not None else f'{chr(8212):>12s}'}")
    print(f"\n{'inverse kinematics, ' + str(args.targets) + ' reachable targets from home':52s}"
          f"{'solved':>8s}{'median ms':>11s}{'max ms':>9s}")  # fmt: skip
    for label, ok, med, worst in inverse(model, pin, home, rng, args.targets):
        print(f"  {label:50s}{ok:8.0%}{med:11.1f}{worst:9.1f}")
    rows, replays = preview(scene, model, home)
    print("\npreview of a click: IK + joint path (step 7.5 mm) + collision check (margin 1 cm), ms")
    print(f"  {'target':42s}{'IK ok':>6s}{'samples':>8s}{'fcl calls':>10s}{'IK':>7s}{'path':>6s}"
          f"{'check':>7s}{'total':>7s}  first contact")  # fmt: skip
    for name, ok, k, calls, t_ik, t_path, t_check, total, verdict in rows:
        print(f"  {name:42s}{'yes' if ok else 'no':>6s}{k:8d}{calls:10d}{t_ik:7.1f}{t_path:6.1f}{t_check:7.1f}"
              f"{total:7.1f}  {verdict}")  # fmt: skip
    totals = np.array([r[7] for r in rows])
    print(f"  total: median {np.median(totals):.1f} ms, max {totals.max():.1f} ms (target: 100 ms)")
    if replays:
        n = sum(r[0] for r in replays)
        f_us = sum(r[0] * r[1] for r in replays) / n
        c_us = sum(r[0] * r[2] for r in replays) / n
        checks = sum(r[6] for r in rows)
        print(f"\nnarrow phase replayed on the same {n} calls (place both objects + signed distance), µs per call:"
              f" python-fcl {f_us:.2f}, coal {c_us:.2f}; python-fcl's share of the checks' time:"
              f" {n * f_us / 1e3:.1f} of {checks:.1f} ms")  # fmt: skip
    else:
        print("\ncoal absent (pip install coal): no replay of the narrow phase")
    print("\nthe operator's click in Move robot (RobotCell.plan_approach: turns, IK, both legs, check), ms")
    for label, ms, ok, samples, reason in clicks(scene):
        print(f"  {label:40s}{ms:8.1f}  {'passes' if ok else 'refused: ' + reason[:70]} ({samples} poses checked)")
    video = live_video(scene)
    print(f"\nlive video with the robot moving, front camera 512x256: {video['fps']:.1f} frames/s on one core "
          f"(the scene's 12 fps is the target); the robot's {video['edges']} visible link edges, |offset| from C's "
          "projection (px), median / max:")  # fmt: skip
    for name, (med, worst) in video["offsets"].items():
        print(f"  {name:36s}{med:7.3f} / {worst:.3f}")
    print(f"(load average {os.getloadavg()[0]:.2f} after the timings)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
