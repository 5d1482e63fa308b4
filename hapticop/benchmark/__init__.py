"""`hapticop bench`: how well a composition keeps time on this machine, against the machine's own limit."""
