"""The wire protocols between the PROFIBUS master and the G2 controller card: v1 (one 14-byte target
record, the handshake, the master's sequencer states) and v2 (the streaming records). Imports only
the vocabulary modules (errors, poses, validate)."""
