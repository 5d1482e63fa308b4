"""An emulated EtherCAT segment (generic ESC, SII, AL states, FMMUs, SMs, watchdog) and the
ropod's slaves on it, served on a network interface for a real master to talk to."""
