"""The live page of ``serve``: each valve's last hour, status ribbon and alarms, live.

`LiveHub` keeps, per valve, the last ``history_seconds`` of its records in engineering units
(measured X and F, their validated values and uncertainty bands, the status, the diagnosed fault
and its probability) and the alarm list (an alarm is a detection: it opens when DD rises, shows
the fault or group it is isolated as and its probability while it lasts, and closes when DD
falls; a BLIND second is no alarm). `live_app` is the Starlette application:

- ``/``: the page (``?valve=NAME`` draws one valve; the overview draws the first ``panels``);
- ``/api/state``: the history and alarms as JSON (what the page draws first);
- ``/events``: server-sent events, one message a second with the new records and the alarms;
- ``/static/plotly.min.js``: plotly.js as shipped inside the ``plotly`` Python package (the page
  needs no network).

The charts are plotly.js's (``Plotly.newPlot``, ``Plotly.extendTraces``); the page's own script
only feeds them. Served by uvicorn in ``serve``'s event loop, on 127.0.0.1 unless told otherwise.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
from collections import deque
from collections.abc import AsyncIterator, Mapping
from typing import Any

from bayes_fdi.datasets.units import to_physical

__all__ = ["LiveHub", "live_app", "plotly_js_path"]

_FIELDS = ("t", "X", "F", "X_vmv", "X_vu", "F_vmv", "F_vu", "status", "state", "p", "DD")
_MAX_ALARMS = 200


def plotly_js_path() -> str:
    """The plotly.js file shipped in the ``plotly`` package."""
    import plotly

    path = os.path.join(os.path.dirname(plotly.__file__), "package_data", "plotly.min.js")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"plotly.min.js not found in the plotly package ({path})")
    return path


def _clean(v: Any) -> Any:
    return None if isinstance(v, float) and not math.isfinite(v) else v


class LiveHub:
    """The live page's data (see the module docstring)."""

    def __init__(
        self, valves: Mapping[str, Mapping[str, str]], history_seconds: int = 3600, panels: int = 8
    ) -> None:
        self.units = {v: dict(u) for v, u in valves.items()}
        self.panels = int(panels)
        self.history = {v: deque(maxlen=int(history_seconds)) for v in self.units}
        self.fresh: dict[str, list[dict[str, Any]]] = {v: [] for v in self.units}
        self.alarms: deque[dict[str, Any]] = deque(maxlen=_MAX_ALARMS)
        self.active: dict[str, dict[str, Any]] = {}
        self.queues: set[asyncio.Queue] = set()
        self.sent = 0

    def add(self, valve: str, row: Mapping[str, Any]) -> None:
        """One record (a row of `bayes_fdi.deployment.serve.records`)."""
        units = self.units[valve]

        def phys(c: str, v: float) -> float | None:
            return _clean(float(to_physical(v, c, units[c])))

        def width(c: str, centre: float, half: float) -> float | None:
            return _clean(
                float(to_physical(centre + half, c, units[c]) - to_physical(centre, c, units[c]))
            )

        t = int(row["time"])
        point = {
            "t": t * 1000,
            "X": phys("X", row["X"]),
            "F": phys("F", row["F"]),
            "X_vmv": phys("X", row["VMV_X"]),
            "X_vu": width("X", row["VMV_X"], row["VU_X"]),
            "F_vmv": phys("F", row["VMV_F"]),
            "F_vu": width("F", row["VMV_F"], row["VU_F"]),
            "status": str(row["status"]),
            "state": str(row["state"]),
            "p": _clean(float(row["probability"])),
            "DD": bool(row["DD"]),
        }
        self.history[valve].append(point)
        self.fresh[valve].append(point)
        self._alarm(valve, point)

    def _alarm(self, valve: str, point: Mapping[str, Any]) -> None:
        alarm = self.active.get(valve)
        if point["DD"] and alarm is None:
            alarm = {
                "valve": valve,
                "start": point["t"],
                "end": None,
                "state": "",
                "probability": None,
                "status": point["status"],
                "active": True,
            }
            self.active[valve] = alarm
            self.alarms.appendleft(alarm)
        if alarm is None:
            return
        if not point["DD"]:
            alarm["end"], alarm["active"] = point["t"], False
            del self.active[valve]
            return
        if point["status"] in ("BLURRED", "DAZZLED"):
            alarm["status"] = point["status"]
            if point["state"] not in ("", "fn"):
                alarm["state"], alarm["probability"] = point["state"], point["p"]

    def snapshot(self) -> dict[str, Any]:
        """Everything the page draws first."""
        return {
            "valves": [
                {"name": v, "X_unit": u["X"], "F_unit": u["F"]} for v, u in self.units.items()
            ],
            "panels": self.panels,
            "history": {v: _columns(list(h)) for v, h in self.history.items()},
            "alarms": list(self.alarms),
        }

    def message(self) -> dict[str, Any] | None:
        """The new records since the last message, and the alarms (None: nothing new)."""
        fresh = {v: _columns(p) for v, p in self.fresh.items() if p}
        if not fresh:
            return None
        for v in fresh:
            self.fresh[v] = []
        return {"points": fresh, "alarms": list(self.alarms)}

    async def broadcast(self, period: float = 1.0) -> None:
        """Send a message to every connected page each ``period`` s (until cancelled)."""
        while True:
            await asyncio.sleep(period)
            message = self.message()
            if message is None:
                continue
            text = json.dumps(message, allow_nan=False)
            self.sent += 1
            for queue in list(self.queues):
                if queue.qsize() < 30:  # a page that stopped reading is not fed forever
                    queue.put_nowait(text)

    async def stream(self) -> AsyncIterator[str]:
        """Server-sent events of one page."""
        queue: asyncio.Queue = asyncio.Queue()
        self.queues.add(queue)
        try:
            yield "retry: 2000\n\n"
            while True:
                try:
                    text = await asyncio.wait_for(queue.get(), 15.0)
                except TimeoutError:
                    yield ": keep-alive\n\n"
                    continue
                yield f"data: {text}\n\n"
        finally:
            self.queues.discard(queue)


def _columns(points: list[dict[str, Any]]) -> dict[str, list[Any]]:
    return {k: [p[k] for p in points] for k in _FIELDS}


def live_app(hub: LiveHub) -> Any:
    """The Starlette application of the page."""
    from starlette.applications import Starlette
    from starlette.responses import FileResponse, HTMLResponse, JSONResponse, StreamingResponse
    from starlette.routing import Route

    plotly_path = plotly_js_path()

    async def page(request: Any) -> HTMLResponse:
        return HTMLResponse(_PAGE)

    async def state(request: Any) -> JSONResponse:
        return JSONResponse(hub.snapshot())

    async def events(request: Any) -> StreamingResponse:
        return StreamingResponse(
            hub.stream(), media_type="text/event-stream", headers={"Cache-Control": "no-cache"}
        )

    async def plotly_js(request: Any) -> FileResponse:
        return FileResponse(plotly_path, media_type="text/javascript")

    routes = [
        Route("/", page),
        Route("/api/state", state),
        Route("/events", events),
        Route("/static/plotly.min.js", plotly_js),
    ]
    return Starlette(routes=routes)


async def serve_page(hub: LiveHub, host: str, port: int, stopped: asyncio.Event) -> None:
    """Serve the page with uvicorn until ``stopped`` is set (signals are ``serve``'s)."""
    import uvicorn

    class _Server(uvicorn.Server):
        @contextlib.contextmanager
        def capture_signals(self):  # serve's own handlers stop everything
            yield

    config = uvicorn.Config(
        live_app(hub), host=host, port=port, log_level="warning", lifespan="off", access_log=False
    )
    server = _Server(config)
    task = asyncio.create_task(server.serve())
    await stopped.wait()
    server.should_exit = True
    server.force_exit = True  # open event streams would hold the shutdown
    with contextlib.suppress(asyncio.CancelledError):
        await asyncio.wait_for(task, 5.0)


_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<title>bayes-fdi serve: live SEVA</title>
<script src="/static/plotly.min.js"></script>
<style>
body{font-family:system-ui,sans-serif;margin:1em;color:#222}
table{border-collapse:collapse;margin:.5em 0}
td,th{border:1px solid #ccc;padding:2px 8px;font-size:90%}
.CLEAR{background:#c8e6c9}.BLURRED{background:#ffe0b2}
.DAZZLED{background:#ffcdd2}.BLIND{background:#cfd8dc}
.panel{border:1px solid #ddd;margin:.5em 0;padding:.3em}.row{display:flex;flex-wrap:wrap}
.chart{width:560px;height:230px}.ribbon{width:1120px;height:90px}
</style></head><body>
<h2>bayes-fdi serve: live SEVA status</h2>
<p>Last update: <span id="updated">waiting for data</span> &middot;
<span id="count">0</span> records received</p>
<h3>Valves</h3><table id="overview"><thead><tr><th>valve</th><th>status</th><th>fault</th>
<th>probability</th><th>time (UTC)</th></tr></thead><tbody></tbody></table>
<h3>Alarms</h3><table id="alarms"><thead><tr><th>valve</th><th>fault</th><th>probability</th>
<th>status</th><th>start (UTC)</th><th>end (UTC)</th></tr></thead><tbody></tbody></table>
<div id="panels"></div>
<script>
const STATUS = ["CLEAR", "BLURRED", "DAZZLED", "BLIND"];
const COLOUR = {CLEAR: "#2e7d32", BLURRED: "#ef6c00", DAZZLED: "#c62828", BLIND: "#607d8b"};
let KEEP = 3600, drawn = [], latest = {}, count = 0;
const fmt = t => t === null ? "" : new Date(t).toISOString().slice(0, 19).replace("T", " ");
const pct = p => p === null || p === undefined ? "" :
  (100 * p).toFixed(1) + " %";
const add = (a, b) => a.map((v, i) => v === null || b[i] === null ? null : v + b[i]);
const sub = (a, b) => a.map((v, i) => v === null || b[i] === null ? null : v - b[i]);
const date = ts => ts.map(t => new Date(t));
function bandTraces(h, q, unit) {
  const x = date(h.t), v = h[q + "_vmv"], u = h[q + "_vu"];
  return [
    {x: x, y: sub(v, u), mode: "lines", line: {width: 0}, showlegend: false, hoverinfo: "skip"},
    {x: x, y: add(v, u), mode: "lines", line: {width: 0}, fill: "tonexty",
     fillcolor: "rgba(33,150,243,0.25)", name: "VMV \u00b1 VU"},
    {x: x, y: v, mode: "lines", line: {color: "#1565c0", dash: "dot"}, name: "VMV"},
    {x: x, y: h[q], mode: "lines", line: {color: "#222", width: 1}, name: q + " measured"}];
}
function bandUpdate(h, q) {
  const x = date(h.t), v = h[q + "_vmv"], u = h[q + "_vu"];
  return {x: [x, x, x, x], y: [sub(v, u), add(v, u), v, h[q]]};
}
function ribbonTraces(h) {
  return STATUS.map(s => {
    const x = [], y = [], text = [];
    h.t.forEach((t, i) => { if (h.status[i] === s) { x.push(new Date(t)); y.push(0);
      text.push(h.state[i] + " " + pct(h.p[i])); } });
    return {x: x, y: y, text: text, mode: "markers", name: s, type: "scattergl",
            marker: {symbol: "square", size: 9, color: COLOUR[s]}};
  });
}
function ribbonUpdate(h) {
  const r = ribbonTraces(h);
  return {x: r.map(t => t.x), y: r.map(t => t.y), text: r.map(t => t.text)};
}
function panel(v) {
  const div = document.createElement("div");
  div.className = "panel"; div.id = "panel-" + v.name;
  div.innerHTML = "<b>" + v.name + "</b><div class='row'><div class='chart' id='X-" + v.name +
    "'></div><div class='chart' id='F-" + v.name + "'></div></div><div class='ribbon' id='S-" +
    v.name + "'></div>";
  document.getElementById("panels").appendChild(div);
}
function layout(title, unit) {
  return {title: {text: title, font: {size: 13}}, margin: {l: 50, r: 10, t: 30, b: 30},
          yaxis: {title: unit}, xaxis: {type: "date"}, legend: {orientation: "h", y: -0.25}};
}
function draw(v, h) {
  Plotly.newPlot("X-" + v.name, bandTraces(h, "X"), layout("X: stem position", v.X_unit));
  Plotly.newPlot("F-" + v.name, bandTraces(h, "F"), layout("F: flow", v.F_unit));
  Plotly.newPlot("S-" + v.name, ribbonTraces(h), {margin: {l: 50, r: 10, t: 10, b: 30},
    yaxis: {visible: false}, xaxis: {type: "date"}, showlegend: true,
    legend: {orientation: "h", y: 1.3}});
}
function overview() {
  const body = document.querySelector("#overview tbody");
  body.innerHTML = Object.keys(latest).sort().map(v => { const p = latest[v];
    return "<tr><td><a href='/?valve=" + encodeURIComponent(v) + "'>" + v +
      "</a></td><td class='" +
      p.status + "'>" + p.status + "</td><td>" + p.state + "</td><td>" + pct(p.p) + "</td><td>" +
      fmt(p.t) + "</td></tr>"; }).join("");
}
function alarms(list) {
  document.querySelector("#alarms tbody").innerHTML = list.map(a => "<tr class='alarm" +
    (a.active ? " active" : "") + "'><td>" + a.valve + "</td><td class='fault'>" +
    (a.state || "?") +
    "</td><td>" + pct(a.probability) + "</td><td class='" + a.status + "'>" + a.status +
    "</td><td>" + fmt(a.start) + "</td><td>" + (a.active ? "active" : fmt(a.end)) +
    "</td></tr>").join("");
}
function remember(v, h) {
  const n = h.t.length; if (!n) return;
  latest[v] = {status: h.status[n - 1], state: h.state[n - 1], p: h.p[n - 1], t: h.t[n - 1]};
  count += n;
}
function newer(h, after) {  // the points of a message later than what is drawn
  const keep = h.t.map(t => after === undefined || t > after);
  const out = {};
  for (const k in h) out[k] = h[k].filter((_, i) => keep[i]);
  return out;
}
async function start() {
  const queued = [];
  const source = new EventSource("/events");  // opened first: no message is missed
  source.onmessage = e => queued.push(JSON.parse(e.data));
  const state = await (await fetch("/api/state")).json();
  const want = new URLSearchParams(location.search).get("valve");
  drawn = state.valves.filter(v => want ? v.name === want : true).slice(0, want ? 1 : state.panels);
  for (const v of drawn) { panel(v); draw(v, state.history[v.name]); }
  for (const v of state.valves) remember(v.name, state.history[v.name]);
  overview(); alarms(state.alarms);
  const apply = m => {
    for (const v of drawn) { if (!m.points[v.name]) continue;
      const h = newer(m.points[v.name], latest[v.name] && latest[v.name].t);
      if (!h.t.length) continue;
      Plotly.extendTraces("X-" + v.name, bandUpdate(h, "X"), [0, 1, 2, 3], KEEP);
      Plotly.extendTraces("F-" + v.name, bandUpdate(h, "F"), [0, 1, 2, 3], KEEP);
      Plotly.extendTraces("S-" + v.name, ribbonUpdate(h), [0, 1, 2, 3], KEEP); }
    for (const v in m.points) remember(v, newer(m.points[v], latest[v] && latest[v].t));
    overview(); alarms(m.alarms);
    const now = new Date().toISOString().slice(11, 19);
    document.getElementById("updated").textContent = now + " UTC";
    document.getElementById("count").textContent = count;
  };
  queued.forEach(apply);
  source.onmessage = e => apply(JSON.parse(e.data));
}
start();
</script></body></html>
"""
