"""The robot on the site: its URDF (the bundled arm's, or any file's), its collision check."""
