"""``mcit emulate``: the scene's range finder and turret emulated on pseudo-terminals with stable paths.

Point the interface at them exactly as at real devices::

    mcit emulate --scene scenes/workcell
    mcit serve --scene scenes/workcell --rangefinder /tmp/mcit-rangefinder --turret /tmp/mcit-turret

Only argparse is imported here; the emulators load when the command runs.
"""

from __future__ import annotations

import argparse
import signal
import threading

from app.exit_status import UsageError

__all__ = ["add_emulate_parser", "run_emulate", "parse_fault_rates"]

DEFAULT_RANGEFINDER_LINK = "/tmp/mcit-rangefinder"
DEFAULT_TURRET_LINK = "/tmp/mcit-turret"


def parse_fault_rates(text: str | None, rate: float) -> dict[str, float]:
    """Fault rates from ``--faults kind=p,kind=p`` or, failing that, ``--fault-rate p`` spread evenly
    over every kind but unplug; ValueError naming the option for an unknown kind or a rate out of [0, 1]."""
    from app.devices.faults import FAULT_KINDS, FaultInjector

    if text:
        rates = {}
        for item in text.split(","):
            kind, _, value = item.partition("=")
            kind = kind.strip()
            try:
                rates[kind] = float(value)
            except ValueError:
                raise ValueError(
                    f"--faults expects kind=probability pairs like 'drop=0.05,garble=0.02', got {item!r}"
                ) from None
        try:
            return FaultInjector.check_rates(rates)  # the emulators' own check, said before anything starts
        except ValueError as exc:
            raise ValueError(f"--faults: {exc}") from None
    if not 0.0 <= rate <= 1.0:
        raise ValueError(f"--fault-rate must be within [0, 1], got {rate}")
    kinds = [k for k in FAULT_KINDS if k != "unplug"]
    return {k: rate / len(kinds) for k in kinds} if rate > 0 else {}


def add_emulate_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "emulate",
        help="emulate the scene's range finder and turret on pseudo-terminals",
        description="Start the Dimetix DLS range-finder and FLIR PTU-D46 turret emulators of a scene on "
        "pseudo-terminals with stable symlinks, print them, and run until Ctrl-C.",
    )
    p.add_argument("--scene", default=None, help="scene folder (default: the bundled scenes/workcell)")
    p.add_argument(
        "--rangefinder-link",
        default=DEFAULT_RANGEFINDER_LINK,
        help=f"symlink to the range finder's pty (default {DEFAULT_RANGEFINDER_LINK})",
    )
    p.add_argument(
        "--turret-link",
        default=DEFAULT_TURRET_LINK,
        help=f"symlink to the turret's pty (default {DEFAULT_TURRET_LINK})",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the range noise and random faults (default 0)")
    p.add_argument(
        "--measure-delay-ms", type=float, default=100.0, help="range-finder measurement time (default 100 ms)"
    )
    p.add_argument(
        "--rangefinder-baud", type=int, default=19200, help="modelled range-finder line rate (default 19200)"
    )
    p.add_argument("--turret-baud", type=int, default=9600, help="modelled turret line rate (default 9600)")
    p.add_argument(
        "--fault-rate",
        type=float,
        default=0.0,
        help="probability that a reply is faulty, spread over every fault kind but unplug (default 0)",
    )
    p.add_argument("--faults", default=None, help="explicit fault rates, e.g. 'drop=0.05,garble=0.02,unplug=0.001'")
    p.add_argument(
        "--static",
        action="store_true",
        help="bodies stay at their t = 0 pose (default: they move with the scene's looping video time)",
    )
    p.add_argument(
        "--duration", type=float, default=None, help="stop after this many seconds (default: run until Ctrl-C)"
    )
    p.set_defaults(func=run_emulate)
    return p


def run_emulate(args: argparse.Namespace) -> int:
    from app.devices.site import EmulatedSite, scene_clock
    from app.scene import default_scene_path, load_scene

    try:
        rates = parse_fault_rates(args.faults, args.fault_rate)
    except ValueError as exc:  # --faults, --fault-rate: the command line's
        raise UsageError(str(exc)) from None
    # a scene that cannot be used, a pty that cannot be made: app.cli says it (status 1)
    scene = load_scene(args.scene or default_scene_path())
    clock = (lambda: 0.0) if args.static else scene_clock(scene)
    site = EmulatedSite(
        scene,
        clock=clock,
        seed=args.seed,
        rangefinder_baud=args.rangefinder_baud,
        turret_baud=args.turret_baud,
        measure_delay_s=args.measure_delay_ms / 1000.0,
        fault_rates=rates,
    )
    stop = threading.Event()
    previous = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        rf_path, turret_path = site.serve_pty(args.rangefinder_link, args.turret_link)
        scene_arg = f" --scene {args.scene}" if args.scene else ""
        print(f"scene: {scene.name} ({scene.root})")
        print(
            f"range finder (Dimetix DLS, {args.rangefinder_baud} baud "
            f"modelled): {rf_path} -> {site.rangefinder.port.device}"
        )
        print(f"turret (FLIR PTU-D46, {args.turret_baud} baud modelled): {turret_path} -> {site.turret.port.device}")
        if rates:
            print("fault rates per reply: " + ", ".join(f"{k}={v:g}" for k, v in rates.items()))
        print("point the interface at them with:")
        print(f"  mcit serve{scene_arg} --rangefinder {rf_path} --turret {turret_path}")
        print("Ctrl-C to stop.", flush=True)
        stop.wait(args.duration)
    finally:
        site.close()
        for s, handler in previous.items():
            signal.signal(s, handler)
    print("emulators stopped.", flush=True)
    return 0
