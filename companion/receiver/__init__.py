"""The GNSS receiver a companion owns: its byte stream (serial, TCP, file) and a reader thread.
I/O edge: ``companion.gnss`` decodes and computes, this opens and reads."""
