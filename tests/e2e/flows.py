"""An operator at the page: every action goes through a visible control, a key or a canvas click,
and is counted (with the seconds the flow took) for the documentation's "clicks and seconds the
browser test measured". Nothing here calls the Python workflow API to drive a workflow; the
server-side panel is only read, to wait and to check the instruction's controls.
"""

from __future__ import annotations

import re
import time

import numpy as np

from .harness import assert_prompt_controls, click_control, key_until, press, wait_until


class Operator:
    """Drives one page like an operator and counts what they do.

    actions : canvas clicks + button presses + keys + chooser picks (a chooser pick counts once:
    open it and click the option)."""

    def __init__(self, ui, page):
        self.ui, self.page = ui, page
        self.actions = 0
        self.log: list[str] = []
        self.t0 = time.monotonic()

    @property
    def seconds(self) -> float:
        return time.monotonic() - self.t0

    def check(self) -> list[str]:
        """The instruction's named controls are visible and enabled on the page (the state walk's browser half)."""
        return assert_prompt_controls(self.page)

    def click(self, uv) -> None:
        self.ui.click_pixel(self.page, uv)
        self.actions += 1
        self.log.append("click")

    def double_click(self, uv) -> None:
        """A double click on video pixel uv (one gesture, one action)."""
        self.ui.double_click_pixel(self.page, uv)
        self.actions += 1
        self.log.append("double click")

    def press(self, label: str) -> None:
        press(self.page, label)
        self.actions += 1
        self.log.append(label)

    def key(self, key: str) -> None:
        self.page.keyboard.press(key)
        self.actions += 1
        self.log.append(f"key {key}")

    def key_until(self, key: str, predicate, what: str) -> None:
        """Press ``key`` until ``predicate()`` shows it was taken (harness.key_until: a key a loaded page had no
        shortcut for yet is pressed once more, as an operator would); one action."""
        key_until(self.page, key, predicate, what, panel=self.page.panel)
        self.actions += 1
        self.log.append(f"key {key}")

    def choose(self, chooser: str, option: str) -> None:
        """Pick ``option`` in the chooser labelled ``chooser`` (a Mantine select: click it, click the option)."""
        box = self.page.get_by_label(chooser, exact=True)
        box.wait_for(state="visible", timeout=60_000)
        click_control(box)
        click_control(self.page.get_by_role("option", name=option, exact=True))
        self.actions += 1
        self.log.append(f"{chooser}: {option}")

    def accept(self, wf, timeout_s: float = 10.0) -> None:
        """Accept; if the panel asks about a weak result ("Accept anyway"), press again. Pressed once the
        workflow's step offers it (a search under way on a loaded machine can take a while)."""
        wait_until(lambda: "accept" in wf.current_step().enabled, 60.0, "Accept to be offered", panel=self.page.panel)
        self.press("Accept")
        wait_until(lambda: wf.accepted or self.page.panel.asking == "accept", timeout_s, "the accept or its question")
        if not wf.accepted:
            self.page.get_by_role("button", name=re.compile("^Accept anyway")).wait_for(state="visible", timeout=60_000)
            self.check()
            self.press("Accept anyway")
            wait_until(lambda: wf.accepted, timeout_s, "the accept")

    def report(self, what: str) -> str:
        text = f"{what}: {self.actions} operator actions in {self.seconds:.1f} s ({', '.join(self.log)})"
        print(text)
        return text


def projected_edges(camera, model, T) -> np.ndarray:
    """(E, 2, 2) pixels of the model's edges at pose T."""
    return camera.project(model.edge_segments(T).reshape(-1, 3)).reshape(-1, 2, 2)


def visible_edges(camera, model, T) -> list[int]:
    """Model edges (true edges, not silhouettes) visible from the camera at pose T."""
    wf = model.wireframe(camera.center, T)
    return [int(k) for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind) if v and kind == "edge"]
