"""The DAMADICS (DABLib) actuator model and its 19 faults."""
