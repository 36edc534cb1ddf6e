"""The site's 3D geometric database (SQLite): objects, history and undo, calibrations.

See ``docs/database.md``. The interface and the demo use ``Database``::

    db = Database.open(path)                     # default: ~/.local/share/mcit/mcit.sqlite
    seed_from_scene(db, scene)                   # a new site from a scene's known objects
    for rec in db.objects(): ...                 # the overlay's read (ObjectRecord)
    db.update_pose(rec.id, T_world_obj, cov, expected_version=rec.version, method="p3l+refine",
                   client="viser:3", clicks=..., residuals=...)      # ConflictError if it moved
    db.undo(change_id)
"""

from .database import Database, default_db_path
from .records import STATUSES, CalibrationRecord, ChangeRecord, ConflictError, NotFoundError, ObjectRecord
from .schema import LATEST_VERSION, DatabaseRefused
from .seed import dimensions_of, seed_from_scene
from .storage import DatabaseUnavailable

__all__ = [
    "Database",
    "default_db_path",
    "ObjectRecord",
    "ChangeRecord",
    "CalibrationRecord",
    "ConflictError",
    "NotFoundError",
    "DatabaseRefused",
    "DatabaseUnavailable",
    "STATUSES",
    "LATEST_VERSION",
    "seed_from_scene",
    "dimensions_of",
]
