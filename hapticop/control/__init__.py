"""The control channel of a running system: a Unix socket, one JSON line in and one out."""
