"""The mock loom: the machine's actuators, sensors and faults behind real bus servers."""
