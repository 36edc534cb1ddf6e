"""Object names are checked wherever they enter (app/names.py): the database, a scene file,
``mcit db import`` (--name and the file's stem) and a .cao file's ``name=``; each refusal is one
line that says the rule."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli import main
from app.db import Database
from app.names import check_object_name
from app.scene import SceneError, scene_from_dict
from core.brep import BRep

BAD = [
    "<img src=x onerror=alert(1)>",
    "<script>x</script>",
    "[x](javascript:alert(1))",
    "a\nb",
    "",
    " x",
    "x ",
    "_x",
    "a" * 65,
    "box/1",
    'say "hi"',
    None,
    3,
]
GOOD = ["table", "box_1", "Cylinder (2)", "crate-7.b", "boîte", "箱", "a" * 64, "part+1"]


@pytest.mark.parametrize("name", GOOD)
def test_names_of_words_are_accepted(name):
    assert check_object_name(name) == name


@pytest.mark.parametrize("name", BAD)
def test_names_with_markup_or_control_characters_are_refused(name):
    with pytest.raises(ValueError, match="must be 1 to 64 characters"):
        check_object_name(name)


def test_the_database_refuses_them(tmp_path):
    with Database.open(tmp_path / "site.sqlite") as db:
        with pytest.raises(ValueError, match="an object name must be"):
            db.add_object("<svg onload=alert(1)>", "box", BRep.box(0.1, 0.1, 0.1), np.eye(4))
        assert db.objects() == []


def test_a_scene_file_refuses_them(tmp_path):
    from tests.app.test_scene import minimal

    d = minimal()
    d["bodies"][1]["name"] = "<img src=x onerror=alert(1)>"
    with pytest.raises(SceneError, match=r"bodies\[1\]\.name: a body's name must be"):
        scene_from_dict(json.loads(json.dumps(d)), tmp_path)


_TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"


def test_db_import_refuses_a_hostile_file_name_or_name_and_writes_nothing(tmp_path, capsys):
    evil = tmp_path / "<img src=x onerror=alert(1)>.obj"
    evil.write_text(_TETRA)
    db = str(tmp_path / "site.sqlite")
    assert main(["db", "import", str(evil), "--db", db]) != 0
    err = capsys.readouterr().err
    assert "stem" in err and "--name" in err and len(err.strip().splitlines()) == 1
    assert main(["db", "import", str(evil), "--db", db, "--name", "a<b"]) != 0
    assert "--name must be" in capsys.readouterr().err
    assert main(["db", "import", str(evil), "--db", db, "--name", "tetra"]) == 0
    with Database.open(db) as d:
        assert [o.name for o in d.objects()] == ["tetra"]


def test_a_cao_name_option_with_markup_is_refused_without_quoting_it(tmp_path):
    from app.models_io import CaoError, read_cao

    f = tmp_path / "m.cao"
    f.write_text("V1\n2\n0 0 0\n0 0 1\n1\n0 1 name=<svg/onload=alert(1)>\n0\n0\n")
    with pytest.raises(CaoError, match=r"m\.cao:6: name= must be 1 to 64") as exc:
        read_cao(f)
    assert "onload" not in str(exc.value)
