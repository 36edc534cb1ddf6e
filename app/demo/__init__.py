"""The headless demo (``mcit demo``): the recorded operator session replayed through the
interface's workflows, the emulated devices and a real database, with the paper's tables beside
ours.

* ``replay`` — ``replay_script``: every action through ``Session.run_action``; the overlay
  timeline and the workflow runs; ``DemoStepError`` names a failing step;
* ``results`` — the run's numbers against the scene's truth (Tables III.1, III.2, V.1);
* ``simulation`` — the simulated sweeps one run cannot give (distances, statistics);
* ``overlay_video`` — the recorded frames with the interface's overlay;
* ``report`` — report.md and its figures; ``run`` — ``run_demo``, all of it; ``cli`` — the command.

Import from the submodules (``from app.demo.run import run_demo``): this package imports nothing,
so that ``mcit --help`` stays fast. See docs/demo.md.
"""
