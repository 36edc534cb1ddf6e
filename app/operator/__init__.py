"""The recorded operator script: its format (``script``) and its generation from a scene's truth
(``generate``). See docs/operator-script.md."""

from .script import (
    FORMAT,
    WORKFLOWS,
    Action,
    OperatorScript,
    Run,
    ScriptError,
    load_script,
    save_script,
    script_from_dict,
)

__all__ = [
    "FORMAT",
    "WORKFLOWS",
    "Action",
    "OperatorScript",
    "Run",
    "ScriptError",
    "load_script",
    "save_script",
    "script_from_dict",
]
