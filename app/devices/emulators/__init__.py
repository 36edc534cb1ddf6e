"""The device emulators: the range finder (``rangefinder``) and the turret (``turret``) speaking
their protocols from a scene's geometry, on the clocked line model they share (``line``), behind
the ports they listen on (``ports``: in process as ``mcit://NAME``, or a pseudo-terminal). Faults
are injected by ``app.devices.faults``. See docs/devices.md."""
