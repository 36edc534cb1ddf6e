"""pyserial URL handlers of mcit: ``mcit://NAME`` opens an in-process emulator (see ``protocol_mcit``)."""
