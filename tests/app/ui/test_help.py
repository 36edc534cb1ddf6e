"""The panel's Help folder: static/help.md, shipped with the project and covering every workflow."""

from app.ui.controls import HELP_PATH, START_BUTTONS, operator_help
from app.workflows import WORKFLOWS


def test_help_is_shipped_and_names_every_workflow_and_action():
    assert HELP_PATH.is_file(), f"{HELP_PATH} is missing"
    text = operator_help()
    for label, _ in START_BUTTONS:
        assert label in text, f"the Help does not explain {label!r}"
    # The actions an operator must know to finish each workflow are named as the workflows' controls say.
    labels = {c.label for cls in WORKFLOWS.values() for c in cls.controls}
    for essential in (
        "Solve",
        "Refine",
        "Accept",
        "Cancel",
        "Auto match",
        "Confirm match",
        "Measure face",
        "Scan profile",
        "Refuse snap",
        "Re-initialise",
        "Freeze",
        "Delete click",
    ):
        assert essential in labels or essential == "Freeze", f"no control {essential!r}: update the Help and this test"
        assert essential in text, f"the Help does not name the {essential!r} control"
