"""EtherCAT for the ropod: the master side (pysoem bring-up, exchange, SOEM's slave recovery)
and, in `emulator/`, an emulated segment of the ropod's slaves for the master to talk to."""
