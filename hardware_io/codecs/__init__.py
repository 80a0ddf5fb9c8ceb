"""Pure codecs of the hardware-I/O layer (bytes <-> messages, no I/O)."""
