"""The workflow tests' real site (the bundled scene seeded into a fresh database), reused here."""

from tests.app.workflows.conftest import db, scene, site, video_site  # noqa: F401
