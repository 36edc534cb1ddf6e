"""The device drivers: the range finder (Dimetix DLS, ``rangefinder``), the turret (FLIR PTU-D46,
``turret``), their shared serial plumbing (``transport``) and exceptions (``errors``). They speak
to real devices and to the emulators (``app.devices.emulators``) alike. See docs/devices.md."""
