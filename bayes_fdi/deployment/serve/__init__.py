"""``bayes-fdi serve`` and ``bayes-fdi simulate-plant``: the online diagnoser on the plant network.

A self-validating actuator reads its sensors every second and publishes its validated values,
their uncertainty and its status. ``serve`` does that for many valves at once, over OPC UA:

- `bayes_fdi.deployment.serve.config`: the TOML file (schema, defaults, validation with errors
  that name the file, the section and the key).
- `bayes_fdi.deployment.serve.alignment`: samples placed on the 1 s grid of the plant's clock;
  a second is diagnosed when its six channels are in, or BLIND when its time is up; duplicate,
  late and clock-jumped samples are reported, never merged.
- `bayes_fdi.deployment.serve.records`: one second's SEVA record as a flat row (the log's
  columns) from `OnlineDiagnoser.update` or from the batch ``run`` of a gap.
- `bayes_fdi.deployment.serve.valve_runner`: one valve's loop: alignment, diagnosis, resume
  from the log's last checkpoint, the seconds it was down filled as BLIND.
- `bayes_fdi.deployment.serve.durable_log`: the log (a journal of Parquet parts, one per commit,
  with every valve's stream state; per-valve netCDF segments; one netCDF file per valve and day).
- `bayes_fdi.deployment.serve.opcua_client`: the plant reader (subscriptions or polling,
  reconnection with back-off, the node checks at start).
- `bayes_fdi.deployment.serve.opcua_server`: the SEVA publisher (typed variables with
  engineering units and OPC UA quality, certificates, read-only, no anonymous access by
  default).
- `bayes_fdi.deployment.serve.live_page`: the live page (Starlette app, server-sent events,
  plotly.js served from the ``plotly`` package).
- `bayes_fdi.deployment.serve.service`: ``bayes-fdi serve``: everything above in one asyncio
  process.
- `bayes_fdi.deployment.serve.plant_simulator`: ``bayes-fdi simulate-plant``: the DAMADICS
  actuator model behind an OPC UA server, at 1 Hz or faster, with scheduled faults, outages and
  clock jumps.

Imports the library (`bayes_fdi.diagnosis`, `bayes_fdi.datasets`, `bayes_fdi.actuator`) and the
foundation only.
"""
